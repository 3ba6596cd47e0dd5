"""The lead's beat forecast: the beat tracker's phase ``L`` frames on (docs/listening.md, "Lead").

With ``--lead`` the stream reads every beat-tracker phase as the tracker's forecast for ``L``
frames (30 fps) later. Rotating the phase by ``2 pi L / P`` carries on the beats the
tracker has settled on; but at lead 0 each new onset pulls the phase onto itself as it
arrives (the newest frames weigh most in the tracker's window), and that is where lead 0's
speed dips land, which a rotation never does (brahms in rubato: docs/listening.md, "Lead").
:class:`PhaseForecast` instead runs the tracker's own arithmetic
(:func:`models.features.context._beat_columns`) on its onset window as it will stand ``L``
frames on: the onsets heard, then ``L`` more taken as those one tracker period ``P`` earlier
(linearly between frames), so the onsets the pulse expects pull the phase as real ones would.
What it earns on each shared recording: docs/listening.md, "Lead".

State: the last :data:`TEMPO_WINDOW` onset strengths twice over (a ring, as
:class:`models.features.context.ContextTracker` keeps them) and a scratch window of the same
size; nothing is allocated per frame. Cost, a frame with a lead (the rotation: 0.4 µs)::

    python -m timeit -s "from models.networks.lead import PhaseForecast; f = PhaseForecast(); \
        [f.push(i % 7 / 7) for i in range(400)]; f.phase(4, 15.3)" "f.phase(4, 15.3)"
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from models.features.context import LAGS, TEMPO_WINDOW, ContextTracker, _beat_columns

#: The stream's lead reads :class:`PhaseForecast`'s phase; False: the phase of now rotated by
#: ``2 pi L / P`` (the forecast before issue 43, kept to measure against: benchmarks/studies/lead.py
#: ``--rotation``).
ONSET_FORECAST: bool = True


class PhaseForecast:
    """The beat tracker's phase ``lead`` frames on, from the onset column (module docstring).

    ``push(onset)`` once per frame (the feature frame's onset strength, the column the
    tracker reads); ``phase(lead, period)``: the phase (radians, 0 on a beat) the tracker
    would read ``lead`` frames (1..6) after the last pushed frame, its period ``period``
    (frames, the tracker's now) carrying the onsets on. ``reset()`` starts a new stream.
    """

    __slots__ = ("_ring", "_buf", "_frames", "_w", "_w_sum", "_two_pi_j", "_lag_prior")

    def __init__(self) -> None:
        ct = ContextTracker(1, 0.0, True)  # the tracker's window, weights and tempo prior
        self._w, self._w_sum, self._two_pi_j, self._lag_prior = ct._w, ct._w_sum, ct._two_pi_j, ct._lag_prior
        self._ring = np.zeros(2 * TEMPO_WINDOW)
        self._buf = np.zeros(2 * TEMPO_WINDOW)
        self._frames = 0

    def reset(self) -> None:
        """No onsets heard (zeros, as the tracker starts)."""
        self._ring[:] = 0.0
        self._frames = 0

    def push(self, onset: float) -> None:
        """Append one frame's onset strength."""
        pos = self._frames % TEMPO_WINDOW
        self._ring[pos] = self._ring[pos + TEMPO_WINDOW] = onset
        self._frames += 1

    def phase(self, lead: int, period: float) -> float:
        """The tracker's phase (radians) ``lead`` frames after the last pushed frame, the
        ``lead`` onsets not yet heard taken as those ``period`` frames before each."""
        p = float(period)
        p = min(max(p, float(LAGS[0]) - 1.0), float(LAGS[-1]) + 1.0) if math.isfinite(p) else float(LAGS[0])
        return _forecast_phase(self._ring, (self._frames - 1) % TEMPO_WINDOW, int(lead), p, self._buf,
                               self._w, self._w_sum, self._two_pi_j, self._lag_prior, int(LAGS[0]), int(LAGS[-1]))


@njit(cache=True, nogil=True)
def _forecast_phase(ring, pos, lead, period, buf, w, w_sum, two_pi_j, lag_prior, lag_lo, lag_hi):  # pragma: no cover - compiled
    """Fill ``buf[n:]`` with the window ``lead`` frames on (the heard onsets ``ring[pos + 1 + lead:
    pos + n + 1]``, then ``lead`` of them one ``period`` back) and return its phase."""
    n = w.shape[0]
    heard = n - lead
    for i in range(heard):
        buf[n + i] = ring[pos + 1 + lead + i]
    for k in range(lead):
        x = heard + k - period  # >= heard - 41 + k: already filled, a period is at least 10 frames
        i = int(math.floor(x))
        f = x - i
        buf[n + heard + k] = (1.0 - f) * buf[n + i] + f * buf[n + i + 1]
    ccos, csin, _, _ = _beat_columns(buf, n - 1, w, w_sum, two_pi_j, lag_prior, lag_lo, lag_hi)
    return math.atan2(csin, ccos)
