"""The lead's beat forecast: the beat tracker's phase ``L`` frames on (docs/listening.md, "Lead").

With ``--lead`` the stream reads every beat-tracker phase as the tracker's forecast for ``L``
frames (30 fps) later. Rotating the phase by ``2 pi L / P`` carries on the beats the
tracker has settled on; but at lead 0 each new onset pulls the phase onto itself as it
arrives (the newest frames weigh most in the tracker's window), and that is where lead 0's
speed dips land, which a rotation never does (brahms in rubato: docs/listening.md, "Lead").
:class:`PhaseForecast` instead runs the tracker's own arithmetic
(:func:`models.features.context._beat_columns`) on its onset window as it will stand ``L``
frames on: the onsets heard, then ``L`` more taken as those one tracker period ``P`` earlier
(linearly between frames), so the onsets the pulse expects pull the phase as real ones would;
where larger, those one runner-up period back (:data:`RUNNER_UP`: the tracker's next-best level,
whose onsets flip the tracker to it where the two nearly tie), the forecast's phase then read
with the period its window reads. What it earns on each shared recording: docs/listening.md, "Lead".

State: the last :data:`TEMPO_WINDOW` onset strengths twice over (a ring, as
:class:`models.features.context.ContextTracker` keeps them) and a scratch window of the same
size; nothing is allocated per frame outside the compiled arithmetic. Cost, a
frame with a lead: 14 µs (10 µs with ``RUNNER_UP`` off, the rotation 0.4 µs; interleaved, a
loaded machine)::

    python -m timeit -s "from models.networks import lead; lead.RUNNER_UP = True; \
        f = lead.PhaseForecast(); [f.push(i % 7 / 7) for i in range(400)]; f.phase(4, 15.3)" "f.phase(4, 15.3)"
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
#: The onsets not heard yet are taken as the larger of those one tracker period back and one
#: runner-up period back (the best-scoring lag of the tracker's at least :data:`APART` octave from
#: its period), and the forecast's period is the one its window reads; False: one tracker period
#: back only, the period as now (benchmarks/studies/lead.py ``--period-only``). The tracker's level
#: changes where onsets arrive that another level expects (brahms: at 90 of its 995 frames one
#: comes within 4 frames); lead 0 follows each change as the onsets arrive, and the runner-up's
#: expected onsets let the forecast change with it (52 of the 90 caught; a wrong level forecast at
#: 72 other frames). Measured: docs/listening.md, "Lead".
RUNNER_UP: bool = True
#: Octaves the runner-up period lies at least from the tracker's (its neighbouring lags are the
#: same peak of the autocorrelation).
APART: float = 0.2


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
        ``lead`` onsets not yet heard taken as those ``period`` frames before each (and, with
        :data:`RUNNER_UP`, the runner-up period's where larger)."""
        return self.ahead(lead, period)[0]

    def ahead(self, lead: int, period: float) -> tuple[float, float | None]:
        """(phase in radians, ``log2(P / 15)`` of the period P in frames) the tracker would read
        ``lead`` frames after the last pushed frame (see :meth:`phase`): with :data:`RUNNER_UP`
        the period the forecast window reads, else None (the period as now)."""
        p = float(period)
        p = min(max(p, float(LAGS[0]) - 1.0), float(LAGS[-1]) + 1.0) if math.isfinite(p) else float(LAGS[0])
        a, logp = _forecast_phase(self._ring, (self._frames - 1) % TEMPO_WINDOW, int(lead), p, self._buf,
                                  self._w, self._w_sum, self._two_pi_j, self._lag_prior, int(LAGS[0]),
                                  int(LAGS[-1]), APART if RUNNER_UP else -1.0)
        return a, (logp if RUNNER_UP else None)


@njit(cache=True, nogil=True)
def _runner_up(ring, pos, w, w_sum, lag_prior, lag_lo, lag_hi, apart):  # pragma: no cover - compiled
    """The lag (frames) scoring best in the tracker's arithmetic (its weighted autocorrelation of
    the window ``ring[pos + 1: pos + n + 1]`` times the tempo prior) among those at least ``apart``
    octave from the best lag; 0.0 where none scores above zero."""
    n = w.shape[0]
    mean = 0.0
    for j in range(n):
        mean += ring[pos + n - j] * w[j]
    mean /= w_sum
    xw = np.empty(n)
    for j in range(n):
        xw[j] = (ring[pos + n - j] - mean) * w[j]
    score = np.empty(lag_hi - lag_lo + 1)
    best = 0
    for i in range(lag_hi - lag_lo + 1):
        acc = 0.0
        for j in range(n - lag_lo - i):
            acc += xw[j] * xw[j + lag_lo + i]
        score[i] = acc * lag_prior[i]
        if score[i] > score[best]:
            best = i
    second, top = 0.0, 0.0
    for i in range(lag_hi - lag_lo + 1):
        if abs(math.log2((lag_lo + i) / (lag_lo + best))) > apart and score[i] > top:
            second, top = float(lag_lo + i), score[i]
    return second


@njit(cache=True, nogil=True)
def _forecast_phase(ring, pos, lead, period, buf, w, w_sum, two_pi_j, lag_prior, lag_lo, lag_hi,
                    apart):  # pragma: no cover - compiled
    """Fill ``buf[n:]`` with the window ``lead`` frames on (the heard onsets ``ring[pos + 1 + lead:
    pos + n + 1]``, then ``lead`` of them one ``period`` back, or where larger, with ``apart`` >= 0,
    one :func:`_runner_up` period back) and return its (phase, log2 of its period / 15)."""
    n = w.shape[0]
    other = _runner_up(ring, pos, w, w_sum, lag_prior, lag_lo, lag_hi, apart) if apart >= 0.0 and lead > 0 else 0.0
    heard = n - lead
    for i in range(heard):
        buf[n + i] = ring[pos + 1 + lead + i]
    for k in range(lead):
        x = heard + k - period  # >= heard - 41 + k: already filled, a period is at least 10 frames
        i = int(math.floor(x))
        f = x - i
        v = (1.0 - f) * buf[n + i] + f * buf[n + i + 1]
        if other > 0.0:  # a whole lag: the onset that many frames back
            v = max(v, buf[n + heard + k - int(other)])
        buf[n + heard + k] = v
    ccos, csin, _, logp = _beat_columns(buf, n - 1, w, w_sum, two_pi_j, lag_prior, lag_lo, lag_hi)
    return math.atan2(csin, ccos), logp
