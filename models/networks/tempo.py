"""The music's tempo as the dancing performer follows it: one beat period, octave-steady.

The feature extractor's causal beat tracker (models/features/context.py) gives, every
frame, a beat period ``P = 15 * 2 ** logp`` frames (30 fps; 45-180 beats per minute) and a
pulse clarity ``c`` in [0, 1]. Frame by frame its period may jump by an octave (the
autocorrelation at the beat and at the bar or the eighth note are close); a dancer does not
switch between double and half time every second. :class:`TempoFollower` smooths the log
period with an exponential mean (time constant :data:`TEMPO_TAU` frames, weighted by the
clarity) after moving each new estimate by whole octaves to the nearest of the running one,
so a change of tempo is followed within about a second and an octave jump of the tracker is
not. :func:`fold_period` then brings it into the range the performer dances at,
:data:`TEMPO_RANGE`: faster music is danced at half time, slower at double time.

``DanceStream`` plays each movement of its choreographic memory at the ratio of this tempo
to the tempo of the song the movement was danced to (``DanceVQ.member_period``, measured on
the training songs with :func:`track_periods`, the same arithmetic), so the same song faster
gives the same dance, faster.
"""

from __future__ import annotations

import math

import numpy as np

from models.timebase import FPS

#: Tempi the performer dances at, beats per minute: music outside is danced at half or double time.
TEMPO_RANGE: tuple[float, float] = (60.0, 170.0)
#: Time constant of the follower's mean of the log period, frames (0.5 s) at full clarity.
TEMPO_TAU: float = 15.0
#: Pulse clarity below which the tracker's period is not listened to (silence, no pulse).
MIN_CLARITY: float = 0.05
#: Pulse clarity at which a frame counts fully in the mean (a clean click track gives about 0.5).
FULL_CLARITY: float = 0.3
#: The octave of the beat: the one with about this many onsets per beat (:func:`onset_density`),
#: a count that stretching the music does not change, so the same song faster or slower is
#: danced at the same metrical level (the tracker's own choice moves with its tempo prior).
ONSETS_PER_BEAT: float = 1.5
#: Onset-strength frames :func:`onset_density` reads (8 s).
DENSITY_WINDOW: int = 240
#: Largest step of the follower's log period towards a frame an octave or more away, per
#: frame at full weight, in octaves over TEMPO_TAU: a sustained change of metrical level is
#: followed in about 2 s, a one-frame octave slip of the tracker is not.
OCTAVE_STEP: float = 0.25


def onset_density(onset: np.ndarray) -> float:
    """Onsets per second (30 fps) in an onset-strength window (n,): local maxima over +-2 frames
    above the window's mean plus half its standard deviation; 0 for fewer than 2 s."""
    w = np.asarray(onset, np.float64)
    if len(w) < 2 * FPS:
        return 0.0
    thr = w.mean() + 0.5 * w.std()
    c = w[2:-2]
    peaks = (c >= thr) & (c >= w[1:-3]) & (c >= w[:-4]) & (c >= w[3:-1]) & (c >= w[4:])
    return float(peaks.sum()) * FPS / len(w)


def fold_period(period: float) -> float:
    """``period`` (frames per beat, > 0) moved by whole octaves into :data:`TEMPO_RANGE`."""
    lo, hi = 60.0 * FPS / TEMPO_RANGE[1], 60.0 * FPS / TEMPO_RANGE[0]  # (10.6, 30] frames
    p = float(period)
    while p < lo:
        p *= 2.0
    while p > hi:
        p *= 0.5
    return p


class TempoFollower:
    """An octave-steady running beat period from the beat tracker's columns (module docstring).

    ``update(logp, clarity, density)`` per frame (``logp = log2(P / 15)``, ``density`` the
    :func:`onset_density` of the last seconds, 0: unknown); ``period`` (frames per beat,
    folded into :data:`TEMPO_RANGE`, or 0 before any clear pulse); ``confidence`` in [0, 1]
    (the running mean of the clarity over :data:`FULL_CLARITY`).
    """

    __slots__ = ("log_p", "conf", "_a")

    def __init__(self) -> None:
        self._a = 1.0 / TEMPO_TAU
        self.reset()

    def reset(self) -> None:
        self.log_p = math.nan  # unwrapped log2(P / 15); NaN until the first clear pulse
        self.conf = 0.0

    def update(self, logp: float, clarity: float, density: float = 0.0) -> None:
        w = min(1.0, max(clarity, 0.0) / FULL_CLARITY)
        self.conf += self._a * (w - self.conf)
        if clarity < MIN_CLARITY or not math.isfinite(logp):
            return
        if density > 0.0:  # the octave with ONSETS_PER_BEAT onsets a beat
            logp += math.floor(math.log2(ONSETS_PER_BEAT * FPS / (density * 15.0)) - logp + 0.5)
        if self.log_p != self.log_p:  # NaN: the first clear pulse
            self.log_p = logp
            return
        d = logp - self.log_p
        if density <= 0.0:  # no octave cue: the nearest octave of the new estimate to the running one
            d -= math.floor(d + 0.5)
        self.log_p += self._a * w * min(max(d, -OCTAVE_STEP), OCTAVE_STEP)

    @property
    def period(self) -> float:
        if self.log_p != self.log_p:
            return 0.0
        return fold_period(15.0 * 2.0 ** self.log_p)

    @property
    def confidence(self) -> float:
        return min(1.0, self.conf)


def track_periods(logp: np.ndarray, clarity: np.ndarray, onset: np.ndarray | None = None,
                  every: int = 8) -> np.ndarray:
    """Frame by frame :attr:`TempoFollower.period` (T,) float64 over a whole stream's beat columns
    (T,) and onset strength (T,) (0 before the first clear pulse), the onset density taken
    every ``every`` frames as the live stream does: the offline form of the same arithmetic."""
    f = TempoFollower()
    out = np.zeros(len(logp))
    dens = 0.0
    for t, (lp, c) in enumerate(zip(np.asarray(logp, np.float64), np.asarray(clarity, np.float64))):
        if onset is not None and t % every == 0:
            dens = onset_density(onset[max(0, t + 1 - DENSITY_WINDOW): t + 1])
        f.update(float(lp), float(c), dens)
        out[t] = f.period
    return out


def song_period(logp: np.ndarray, clarity: np.ndarray, onset: np.ndarray | None = None) -> float:
    """One beat period (frames) for a whole song's beat columns and onset strength: the median
    of :func:`track_periods` over its frames after the first 6 s (the tracker's window), 0 if
    the pulse is never clear."""
    p = track_periods(logp, clarity, onset)
    p = p[min(len(p) // 2, 6 * FPS):]
    p = p[p > 0]
    return float(np.median(p)) if len(p) else 0.0
