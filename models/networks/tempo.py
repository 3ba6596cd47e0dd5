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
#: Onset-strength frames :func:`octave_cue` reads (8 s).
DENSITY_WINDOW: int = 240
#: Largest step of the follower's log period towards a frame's estimate, per frame at full
#: weight, in octaves over TEMPO_TAU (0.1 octave a second): the running value settles on the
#: period most frames give (a median), not on a mean pulled by the frames where the tracker
#: reads a level 3:2 or an octave away; a change of tempo is followed at up to 7 % a second.
#: For the first :data:`SETTLE_FRAMES` clear frames the step is :data:`SETTLE_STEP`, so a
#: first reading at another level does not hold for long.
OCTAVE_STEP: float = 0.05
SETTLE_STEP: float = 0.25
SETTLE_FRAMES: int = 90
#: The octave: where two octaves of the tempo lie in :data:`TEMPO_RANGE` (a tempo T in
#: 60-85 bpm and 2T), the faster is danced when its beat is subdivided, at least this many
#: onsets a beat (:func:`onset_density` times its period) ...
SUBDIVIDED: float = 1.2
#: ... or when its pulse is about as strong as the slower one's: the onset strength's
#: autocorrelation at its period at least this share of that at twice the period.
PULSE_SHARE: float = 0.9
#: Running mean (updates, one per code step of 8 frames: about 2 s) of the octave score, and
#: the margin it must cross to switch octave once one is chosen (a steady choice on a
#: borderline song instead of a flip every few seconds).
OCTAVE_MEAN: float = 8.0
OCTAVE_MARGIN: float = 0.15


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


class OctaveCue:
    """What an onset-strength window (n,) at 30 fps says about the metrical level:
    ``density`` (:func:`onset_density`, onsets per second; 0: under 2 s, unknown) and
    ``pulse(period)``, the autocorrelation of the mean-removed window at a lag of ``period``
    frames (the largest within +-6 %, linear between lags) over its value at lag 0.
    Stretching the music leaves both, per beat, as they are."""

    __slots__ = ("density", "_acf")

    def __init__(self, onset: np.ndarray) -> None:
        w = np.asarray(onset, np.float64)
        self.density = onset_density(w)
        self._acf = np.zeros(0)
        if self.density > 0.0:
            x = w - w.mean()
            n = len(x)
            f = np.fft.rfft(x, 2 * n)
            a = np.fft.irfft(f * np.conj(f))[: n // 2]
            self._acf = a / np.maximum(n - np.arange(len(a)), 1) / max(a[0] / n, 1e-12)

    def pulse(self, period: float) -> float:
        a = self._acf
        lags = period * np.linspace(0.94, 1.06, 7)
        lags = lags[lags < len(a) - 1]
        return float(np.interp(lags, np.arange(len(a)), a).max()) if len(lags) else 0.0

    def faster(self, period: float) -> float:
        """Score (> 0: yes) that the beat is at ``period`` frames rather than twice it:
        subdivided at ``period`` (:data:`SUBDIVIDED`) or its pulse as strong (:data:`PULSE_SHARE`)."""
        opb = self.density * period / FPS
        return max(math.log2(max(opb, 1e-3) / SUBDIVIDED), self.pulse(period) - PULSE_SHARE * self.pulse(2 * period))


def octave_cue(onset: np.ndarray) -> OctaveCue:
    """The :class:`OctaveCue` of the last :data:`DENSITY_WINDOW` onset strengths (n,)."""
    return OctaveCue(onset)


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

    ``update(logp, clarity, cue)`` per frame (``logp = log2(P / 15)``, ``cue`` the
    :class:`OctaveCue` of the last seconds, new at each code step, or None: unknown);
    ``period`` (frames per beat, in :data:`TEMPO_RANGE`, or 0 before any clear pulse);
    ``confidence`` in [0, 1] (the running mean of the clarity over :data:`FULL_CLARITY`).
    """

    __slots__ = ("log_p", "conf", "score", "slow", "heard", "_a", "_cue")

    def __init__(self) -> None:
        self._a = 1.0 / TEMPO_TAU
        self.reset()

    def reset(self) -> None:
        self.log_p = math.nan  # unwrapped log2(P / 15); NaN until the first clear pulse
        self.conf = 0.0
        self.score = math.nan  # running octave score (OctaveCue.faster), NaN until the first cue
        self.slow = False  # where two octaves are in range: the slower one is danced
        self.heard = 0  # frames with a clear pulse
        self._cue = None

    def update(self, logp: float, clarity: float, cue: OctaveCue | None = None) -> None:
        w = min(1.0, max(clarity, 0.0) / FULL_CLARITY)
        self.conf += self._a * (w - self.conf)
        if clarity < MIN_CLARITY or not math.isfinite(logp):
            return
        if self.log_p != self.log_p:  # NaN: the first clear pulse
            self.log_p = logp
        else:  # the nearest octave of the new estimate to the running one
            d = logp - self.log_p
            d -= math.floor(d + 0.5)
            step = SETTLE_STEP if self.heard < SETTLE_FRAMES else OCTAVE_STEP
            self.log_p += self._a * w * min(max(d, -step), step)
        self.heard += 1
        if cue is not None and cue is not self._cue and cue.density > 0.0:
            self._cue = cue
            s = cue.faster(self._fast())
            first = self.score != self.score
            self.score = s if first else self.score + (s - self.score) / OCTAVE_MEAN
            if first or abs(self.score) > OCTAVE_MARGIN:
                self.slow = self.score < 0.0

    def _fast(self) -> float:
        """The fastest octave of the running period in :data:`TEMPO_RANGE` (frames)."""
        p = fold_period(15.0 * 2.0 ** self.log_p)
        return 0.5 * p if 0.5 * p >= 60.0 * FPS / TEMPO_RANGE[1] else p

    @property
    def period(self) -> float:
        if self.log_p != self.log_p:
            return 0.0
        p = self._fast()
        return 2.0 * p if self.slow and 2.0 * p <= 60.0 * FPS / TEMPO_RANGE[0] else p

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
    cue = None
    for t, (lp, c) in enumerate(zip(np.asarray(logp, np.float64), np.asarray(clarity, np.float64))):
        if onset is not None and t % every == 0:
            cue = octave_cue(onset[max(0, t + 1 - DENSITY_WINDOW): t + 1])
        f.update(float(lp), float(c), cue)
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
