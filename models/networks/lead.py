"""The lead's beat forecast: the beat tracker's phase ``L`` frames on (docs/listening.md, "Lead").

With ``--lead`` the stream reads every beat-tracker phase as the tracker's forecast for ``L``
frames (30 fps) later. Rotating the phase by ``2 pi L / P`` carries on the beats the
tracker has settled on; but at lead 0 each new onset pulls the phase onto itself as it
arrives (the newest frames weigh most in the tracker's window), and that is where lead 0's
speed dips land, which a rotation never does (brahms: docs/listening.md, "Lead").
:class:`PhaseForecast` instead runs the tracker's own arithmetic
(:func:`models.features.context._beat_columns`) on its onset window as it will stand ``L``
frames on: the onsets heard, then ``L`` more taken as those one tracker period ``P`` earlier
(linearly between frames), so the onsets the pulse expects pull the phase as real ones would;
and where the tracker's level is unsteady and the onsets its next-best level expects (one
runner-up period back, where larger) would change it, the changed level's phase and period
(:data:`RUNNER_UP`), where that level lies an octave or more from the tracker's
(:data:`RUNNER_UP_CHANGE`). What it earns on each shared recording: docs/listening.md, "Lead".

State: the last :data:`TEMPO_WINDOW` onset strengths twice over (a ring, as
:class:`models.features.context.ContextTracker` keeps them), a scratch window of the same
size and the tracker's scratch (``context.WORK_SIZE``): the compiled call allocates nothing. Cost,
a frame with a lead (one compiled call: the tracker's arithmetic once, on an unsteady level the
runner-up's autocorrelation besides, and the arithmetic once more where the runner-up's window
reads a level not taken; below, an unsteady level where the runner-up changes nothing; figures:
docs/listening.md, "Lead")::

    python -m timeit -s "from models.networks import lead; f = lead.PhaseForecast(); \
        [f.push(float(i % 15 == 0)) for i in range(400)]; f.phase(4, 15.0)" "f._since = 0; f.phase(4, 15.0)"
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from models.features.context import (LAGS, PRIOR_PERIOD, TEMPO_WINDOW, WORK_SIZE, ContextTracker, _beat_columns,
                                     _weighted_autocorrelation)

#: The stream's lead reads :class:`PhaseForecast`'s phase; False: the phase of now rotated by
#: ``2 pi L / P`` (the forecast before issue 43, kept to measure against: benchmarks/studies/lead.py
#: ``--rotation``).
ONSET_FORECAST: bool = True
#: Where the tracker's level is unsteady (it changed within :data:`UNSTEADY_FRAMES`), the forecast
#: also takes the onsets not heard yet as the larger of those one tracker period back and one
#: runner-up period back (the best-scoring lag of the tracker's at least :data:`APART` octave from
#: its period); where that window reads another level (at least :data:`RUNNER_UP_CHANGE` octave
#: off), the forecast is that level's phase and period, else the period-only one. The tracker's
#: level changes where onsets arrive that another level expects (brahms: within the lead of 90 of
#: its 995 frames); lead 0 follows each change as the onsets arrive, the period-only forecast
#: (False; benchmarks/studies/lead.py ``--period-only``) none. Measured: docs/listening.md, "Lead".
RUNNER_UP: bool = True
#: Octaves the runner-up's level must lie at least from the tracker's for the forecast to take
#: it: about an octave or more (2:1, 3:1), not the tracker's hesitation between a beat and its 3:2 or
#: 4:3 neighbour (0.58, 0.42 octave), where following lead 0's changes cost the lead hits
#: (DANCE_R_5, flipping 17 <-> 11 frames; docs/listening.md, "Lead"); 0: any change of level.
RUNNER_UP_CHANGE: float = 0.75
#: Octaves between two periods of the tracker that make a change of level.
LEVEL_CHANGE: float = 0.1
#: Octaves the runner-up period lies at least from the tracker's (its neighbouring lags are the
#: same peak of the autocorrelation).
APART: float = 0.2
#: Frames (30 fps) since the tracker last changed level within which its level counts as
#: unsteady, and the runner-up is read (3 s; on a steady level the forecast is the period's alone).
UNSTEADY_FRAMES: int = 90


class PhaseForecast:
    """The beat tracker's phase ``lead`` frames on, from the onset column (module docstring).

    ``push(onset)`` once per frame (the feature frame's onset strength, the column the
    tracker reads); ``phase(lead, period)``: the phase (radians, 0 on a beat) the tracker
    would read ``lead`` frames (1..6) after the last pushed frame, its period ``period``
    (frames, the tracker's now) carrying the onsets on; ``ahead`` also its period where
    that changes. ``reset()`` starts a new stream. State besides the onsets: the tracker's
    period at the last call and the frames since it last changed level.
    """

    __slots__ = ("_ring", "_buf", "_work", "_frames", "_w", "_w_sum", "_two_pi_j", "_lag_prior", "_level", "_since", "_seen")

    def __init__(self) -> None:
        ct = ContextTracker(1, 0.0, True)  # the tracker's window, weights and tempo prior
        self._w, self._w_sum, self._two_pi_j, self._lag_prior = ct._w, ct._w_sum, ct._two_pi_j, ct._lag_prior
        self._ring = np.zeros(2 * TEMPO_WINDOW)
        self._buf = np.zeros(2 * TEMPO_WINDOW)
        self._work = np.empty(WORK_SIZE)  # the tracker's scratch (context._beat_columns), no state
        self.reset()

    def reset(self) -> None:
        """No onsets heard (zeros, as the tracker starts)."""
        self._ring[:] = 0.0
        self._frames = 0
        self._level, self._since, self._seen = 0.0, 1 << 30, 0

    def push(self, onset: float) -> None:
        """Append one frame's onset strength."""
        pos = self._frames % TEMPO_WINDOW
        self._ring[pos] = self._ring[pos + TEMPO_WINDOW] = onset
        self._frames += 1

    def phase(self, lead: int, period: float) -> float:
        """The tracker's phase (radians) ``lead`` frames after the last pushed frame, the
        ``lead`` onsets not yet heard taken as those ``period`` frames before each (or, with
        :data:`RUNNER_UP` on an unsteady level, where the runner-up period's change the level,
        as those too). Call it every frame: it keeps count of the level's steadiness."""
        return self.ahead(lead, period)[0]

    def ahead(self, lead: int, period: float) -> tuple[float, float | None]:
        """(phase in radians, ``log2(P / 15)`` of the period P in frames) the tracker would read
        ``lead`` frames after the last pushed frame (see :meth:`phase`): the period where the
        runner-up changes the level by :data:`RUNNER_UP_CHANGE` or more (:data:`RUNNER_UP`), else
        None (the period as now)."""
        p = float(period)
        p = min(max(p, float(LAGS[0]) - 1.0), float(LAGS[-1]) + 1.0) if math.isfinite(p) else float(LAGS[0])
        args = (self._ring, (self._frames - 1) % TEMPO_WINDOW, int(lead), p, self._buf, self._work,
                self._w, self._w_sum, self._two_pi_j, self._lag_prior, int(LAGS[0]), int(LAGS[-1]))
        if self._frames != self._seen:  # the tracker's level: frames since it last changed
            self._since += self._frames - self._seen
            if self._level > 0.0 and abs(math.log2(p / self._level)) > LEVEL_CHANGE:
                self._since = 0
            self._level, self._seen = p, self._frames
        if RUNNER_UP and self._since <= UNSTEADY_FRAMES:  # the runner-up's level where it changes the level
            a, logp, changed = _forecast_phase(*args, APART, math.log2(p / PRIOR_PERIOD),
                                               max(LEVEL_CHANGE, RUNNER_UP_CHANGE))
            return a, logp if changed else None
        return _forecast_phase(*args, -1.0, 0.0, 0.0)[0], None


@njit(cache=True, nogil=True)
def _runner_up(ring, pos, w, w_sum, lag_prior, lag_lo, lag_hi, apart, work):  # pragma: no cover - compiled
    """The lag (frames) scoring best in the tracker's arithmetic (its weighted autocorrelation of
    the window ``ring[pos + 1: pos + n + 1]``, :func:`models.features.context._weighted_autocorrelation`,
    times the tempo prior) among those at least ``apart`` octave from the best lag; 0.0 where none
    scores above zero. ``work``: a (``context.WORK_SIZE``,) float64 scratch."""
    n = w.shape[0]
    ac = work[n:]
    _weighted_autocorrelation(ring, pos, w, w_sum, lag_lo, lag_hi, work[:n], ac)
    best, top = 0, ac[lag_lo] * lag_prior[0]
    for i in range(1, lag_hi - lag_lo + 1):
        score = ac[lag_lo + i] * lag_prior[i]
        if score > top:
            best, top = i, score
    second, top = 0.0, 0.0
    for i in range(lag_hi - lag_lo + 1):
        score = ac[lag_lo + i] * lag_prior[i]
        if abs(math.log2((lag_lo + i) / (lag_lo + best))) > apart and score > top:
            second, top = float(lag_lo + i), score
    return second


@njit(cache=True, nogil=True)
def _forecast_phase(ring, pos, lead, period, buf, work, w, w_sum, two_pi_j, lag_prior, lag_lo, lag_hi,
                    apart, now, change):  # pragma: no cover - compiled
    """Fill ``buf[n:]`` with the window ``lead`` frames on (the heard onsets ``ring[pos + 1 + lead:
    pos + n + 1]``, then ``lead`` of them one ``period`` back) and return its (phase, log2 of its
    period / 15, False); with ``apart`` >= 0, first the window whose ``lead`` onsets are, where
    larger, the onsets one :func:`_runner_up` period back: its (phase, log2 period / 15, True)
    where that differs from ``now`` (log2 of the tracker's period / 15) by more than ``change``
    octave (no onset larger: the period's window, True where its own level so differs). One
    pass: the tracker's arithmetic once, or twice where the runner-up reads a level not taken.
    ``work``: the tracker's scratch (``context.WORK_SIZE`` float64)."""
    n = w.shape[0]
    other = _runner_up(ring, pos, w, w_sum, lag_prior, lag_lo, lag_hi, apart, work) if apart >= 0.0 and lead > 0 else 0.0
    heard = n - lead
    for i in range(heard):
        buf[n + i] = ring[pos + 1 + lead + i]
    larger = False
    for k in range(lead):
        x = heard + k - period  # >= heard - 41 + k: already filled, a period is at least 9 frames
        i = int(math.floor(x))
        f = x - i
        v = (1.0 - f) * buf[n + i] + f * buf[n + i + 1]
        if other > 0.0:  # a whole lag (>= 10 frames): the heard onset that many frames back
            u = buf[n + heard + k - int(other)]
            if u > v:
                v, larger = u, True
        buf[n + heard + k] = v
    if larger:
        ccos, csin, _, logp = _beat_columns(buf, n - 1, w, w_sum, two_pi_j, lag_prior, lag_lo, lag_hi, work)
        if abs(logp - now) > change:
            return math.atan2(csin, ccos), logp, True
        for k in range(lead):  # back to the period's window
            x = heard + k - period
            i = int(math.floor(x))
            f = x - i
            buf[n + heard + k] = (1.0 - f) * buf[n + i] + f * buf[n + i + 1]
    ccos, csin, _, logp = _beat_columns(buf, n - 1, w, w_sum, two_pi_j, lag_prior, lag_lo, lag_hi, work)
    return math.atan2(csin, ccos), logp, apart >= 0.0 and not larger and abs(logp - now) > change
