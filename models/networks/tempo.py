"""The music's tempo as the dancing performer follows it: one beat period, octave-steady.

The feature extractor's causal beat tracker (models/features/context.py) gives, every
frame, a beat period ``P = 15 * 2 ** logp`` frames (30 fps; 45-180 beats per minute) and a
pulse clarity ``c`` in [0, 1]. Frame by frame its period may jump by an octave (the
autocorrelation at the beat and at the bar or the eighth note are close), and on swung or
compound rhythms to a level 3:2 or 4:3 away; a dancer does not switch metrical level every
second. :class:`TempoFollower` smooths the log period with an exponential mean (time
constant :data:`TEMPO_TAU` frames, weighted by the clarity) after moving each new estimate
by whole octaves to the nearest of the running one; an estimate still another level away
(:data:`LEVEL_JUMP`) is moved by 4:3 onto the running level or left out, until such
estimates hold for seconds (:data:`AWAY_FRAMES`). The first level is the one most of the
first 3 s read (:data:`VOTE_WIDTH`). So a change of tempo is followed within
about a second and a level jump of the tracker is not. The danced period is the octave of it
in :data:`TEMPO_RANGE` (faster music is danced at half time, slower at double time; a tempo
drifting over the range's edge keeps its octave for :data:`FOLD_HOLD`); where
two octaves are in the range, the faster when its beat is subdivided (:data:`SUBDIVIDED`
onsets a beat, :func:`onset_density`, a count stretching does not change) or when the
tracker itself reads the faster one most of the time (:data:`FAST_SHARE`), else the slower;
once settled, double time needs more of either (:data:`OCTAVE_HOLD`, :data:`FAST_HOLD`).
:func:`danced_beat` gives the beat warp the phase of the danced beats.

``DanceStream`` plays each movement of its choreographic memory at the ratio of this tempo
to the tempo of the song the movement was danced to (``DanceVQ.member_period``, measured on
the training songs with :func:`song_period` when the memory is fitted, the shipped
checkpoint's with this follower), so the same song faster gives the same dance, faster.
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
#: Onset-strength frames :func:`onset_density` reads (8 s).
DENSITY_WINDOW: int = 240
#: Largest step of the follower's log period towards a frame's estimate, per frame at full
#: weight, in octaves over TEMPO_TAU: a one-frame slip of the tracker does not move it.
OCTAVE_STEP: float = 0.25
#: A frame whose estimate lies more than this (octaves, after moving it by whole octaves to
#: the nearest of the running one) from the running one reads another metrical level (3:2 or
#: 4:3 are 0.42 octave away) and is not listened to, after the first :data:`SETTLE_FRAMES`
#: clear frames, unless such frames outweigh the others by :data:`AWAY_FRAMES` (frames at
#: full clarity, 8 s): then the follower takes the new level. A tempo that changes by a few
#: per cent a second is followed as before; a tracker that reads a 3:2 level for seconds at
#: a time (DANCE_R_5, fishin_karissahobbs) does not pull the tempo between the two.
LEVEL_JUMP: float = 0.3
#: A reading at a level 4:3 (or 3:2, an octave off) from the running one, within
#: THIRD_TOLERANCE octave, is moved to the running level and followed like one there.
THIRD: float = math.log2(4.0 / 3.0)
THIRD_TOLERANCE: float = 0.1
SETTLE_FRAMES: int = 90
#: At the end of :data:`SETTLE_FRAMES`, the running log period moves to the level most of
#: those frames read (their octave-folded log periods, weighted by clarity: the centre of
#: the densest cluster within this many octaves): in its first seconds the follower listens
#: to every reading, and a half second at a 3:2 level could carry it there for the rest of
#: the song (fishin_karissahobbs at 0.8x: 144 bpm for its 96). The vote is one 90 x 90
#: comparison on one frame of the stream (about 0.3 ms, once; the readings are kept in a
#: preallocated buffer, nothing is allocated on the other frames).
VOTE_WIDTH: float = 0.1
AWAY_FRAMES: float = 240.0
#: The octave: where two octaves of the tempo lie in :data:`TEMPO_RANGE` (a tempo T in
#: 60-85 bpm and 2T), the faster is danced when its beat is subdivided, at least this many
#: onsets a beat (:func:`onset_density` times its period), else the slower.
SUBDIVIDED: float = 1.2
#: Running mean (frames: about 2 s) of the octave score, log2 of the onsets a beat at the
#: faster octave over :data:`SUBDIVIDED`, and the margin it must cross to switch octave once
#: one is chosen (a steady choice on a borderline song instead of a flip every few seconds).
OCTAVE_MEAN: float = 64.0
OCTAVE_MARGIN: float = 0.15
#: Double time is not taken up mid-song on a busier passage: after OCTAVE_SETTLE clear frames
#: (8 s at full clarity) a move from the slower octave to the faster needs the octave score over
#: OCTAVE_HOLD (1.7 onsets a beat at the faster octave, not 1.33) or the tracker's share at the
#: faster octave over FAST_HOLD (not FAST_SHARE); back to the slower octave the margins are as
#: before. DANCE_R_5 at 0.8x, settled at 65 bpm, took 130 for 14 s of a busier passage (score
#: +0.30, share 0.91) and at 1.0x 160 for a while, never at 1.25x (200: out of range), so its
#: 0.8x was danced quicker than its 1.25x (stretch set, frequency centroid ratio 0.92 -> 1.71;
#: nutcracker at 1.25x, 140 bpm, now takes its faster octave later: 1.59 -> 1.49;
#: docs/listening.md "Tempo"). OCTAVE_HOLD = OCTAVE_MARGIN and FAST_HOLD = FAST_SHARE: no hold.
OCTAVE_SETTLE: int = 240
OCTAVE_HOLD: float = 0.5
FAST_HOLD: float = 0.95
#: The tracker's own octave, where two are in range: a frame whose estimate lies within this
#: many octaves of the faster one reads it; when such frames hold FAST_SHARE of the
#: clarity-weighted running mean over FAST_MEAN frames (8 s), the faster octave is danced
#: whatever the onsets a beat say. nutcracker_sugarplum_kevinmacleod at 1.25x (140 bpm, one
#: onset a beat) holds it (share 0.9-1.0); DANCE_W_31 at 0.8x (138 bpm, as many onsets a beat)
#: reads it half the time and a 4:3 level otherwise, DANCE_R_5 0.4-0.5 (docs/history-listening.md).
FAST_TOLERANCE: float = 0.1
FAST_SHARE: float = 0.8
FAST_MEAN: float = 240.0
#: The fold keeps its octave: where the running level drifts over the range's top (170 bpm),
#: its fastest octave stays where it was (danced at the top, 170) until it lies FOLD_HOLD octave
#: over it (about 188 bpm); only then, or on a level taken or voted, is it halved again (and the
#: same under 85 bpm, the fastest octave's bottom: kept down to 77). Before the first level is
#: voted (SETTLE_FRAMES) it is folded afresh every frame. A tempo read near the top no longer
#: flips between T and T / 2 with the tracker's wobble: vibeace_kevinmacleod at 1.25x (162 bpm)
#: read 4:5 of it for its last 6 s (129), moved by 4:3 to 172 bpm, and was danced at 86; the
#: waltz DANCE_W_28 (85 bpm) flipped to 165 for 4-8 s at a time (docs/listening.md "Tempo"). 0: none.
FOLD_HOLD: float = 0.15
#: The lead: a tempo that keeps changing is read late, the tracker's 6-s window reading the
#: tempo of about 1.8 s ago and the running mean adding 1.4 s (the listening ramp: 3.2 s in
#: all, docs/listening.md "Tempo"). So the followed period is moved on by its own drift: the
#: running mean (DRIFT_TAU frames) of the running log period's step a frame, times DRIFT_LEAD
#: frames, at most DRIFT_CAP octave (3.5 %; the ramp asks for 0.04) either way. On a steady
#: song the drift stays near 0 (the followed tempo wanders 0.7 % more); a level taken or voted
#: resets it. 0: no lead.
DRIFT_LEAD: float = 75.0
DRIFT_TAU: float = 120.0
DRIFT_CAP: float = 0.05


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
    :func:`onset_density` of the last seconds, 0: unknown);
    ``period`` (frames per beat, in :data:`TEMPO_RANGE`, or 0 before any clear pulse);
    ``confidence`` in [0, 1] (the running mean of the clarity over :data:`FULL_CLARITY`).
    """

    __slots__ = ("log_p", "conf", "score", "slow", "heard", "away", "votes", "fast_num", "fast_den", "drift", "fold",
                 "hold", "_a")

    def __init__(self, hold: float | None = None) -> None:
        self._a = 1.0 / TEMPO_TAU
        self.hold = FOLD_HOLD if hold is None else hold  # octaves the fold keeps its octave past the edges (0: none)
        self.reset()

    def reset(self) -> None:
        self.log_p = math.nan  # unwrapped log2(P / 15); NaN until the first clear pulse
        self.conf = 0.0
        self.score = math.nan  # running octave score (OCTAVE_MEAN), NaN until the first density
        self.slow = False  # where two octaves are in range: the slower one is danced
        self.heard = 0  # frames with a clear pulse
        self.away = 0.0  # weight of frames at another level, less that of frames at this one
        self.votes = np.zeros((SETTLE_FRAMES, 2))  # (log period, weight) of the first SETTLE_FRAMES clear frames
        self.fast_num = 0.0  # running (FAST_MEAN) clarity weight of the frames read at the faster octave
        self.fast_den = 0.0  # ... and of all clear frames
        self.drift = 0.0  # running mean (DRIFT_TAU) of the running log period's step a frame
        self.fold = math.nan  # whole octaves from the running log period to its fastest danced octave (FOLD_HOLD)

    def update(self, logp: float, clarity: float, density: float = 0.0) -> None:
        w = min(1.0, max(clarity, 0.0) / FULL_CLARITY)
        self.conf += self._a * (w - self.conf)
        if clarity < MIN_CLARITY or not math.isfinite(logp):
            self.drift -= self.drift / DRIFT_TAU  # no step this frame
            return
        before = self.log_p
        if self.log_p != self.log_p:  # NaN: the first clear pulse
            self.log_p = logp
        else:  # the nearest octave of the new estimate to the running one
            d = logp - self.log_p
            d -= math.floor(d + 0.5)
            if abs(d) <= LEVEL_JUMP or self.heard < SETTLE_FRAMES:
                self.away = max(0.0, self.away - w)
                self.log_p += self._a * w * min(max(d, -OCTAVE_STEP), OCTAVE_STEP)
            else:
                self.away += w
                if self.away >= AWAY_FRAMES:  # another level, held: take it
                    self.log_p += d
                    self.away = 0.0
                    before = math.nan  # a jump, not a drift
                else:  # a level 3:2 or 4:3 away still says how the tempo moves
                    r = d - math.copysign(THIRD, d)
                    if abs(r) <= THIRD_TOLERANCE:
                        self.log_p += self._a * w * min(max(r, -OCTAVE_STEP), OCTAVE_STEP)
        self.heard += 1
        if self.heard <= SETTLE_FRAMES:  # preallocated: nothing allocated per frame on the audio path
            self.votes[self.heard - 1] = logp, w
            if self.heard == SETTLE_FRAMES:
                self._vote()
                before = math.nan
        if before == before:  # the tempo's drift (DRIFT_LEAD)
            self.drift += (self.log_p - before - self.drift) / DRIFT_TAU
        else:
            self.drift = 0.0
            self.fold = math.nan  # a level taken or voted: folded afresh
        self._refold()
        fast = self._fast()
        at_fast = abs(logp - math.log2(fast / 15.0)) <= FAST_TOLERANCE
        self.fast_num += (w * at_fast - self.fast_num) / FAST_MEAN
        self.fast_den += (w - self.fast_den) / FAST_MEAN
        if density > 0.0:  # the octave: subdivided beats at the faster one, or the slower
            x = math.log2(max(density * fast / FPS, 1e-3) / SUBDIVIDED)
            first = self.score != self.score
            self.score = x if first else self.score + (x - self.score) / OCTAVE_MEAN
            margin = OCTAVE_HOLD if self.heard >= OCTAVE_SETTLE and self.score > 0.0 else OCTAVE_MARGIN
            if first or abs(self.score) > margin:
                self.slow = self.score < 0.0
        share = FAST_SHARE if self.heard < OCTAVE_SETTLE else FAST_HOLD
        if self.fast_num > share * self.fast_den:  # the tracker holds the faster octave: dance it
            self.slow = False

    def _vote(self) -> None:
        """Move the running log period to the level most of :attr:`votes` read (:data:`VOTE_WIDTH`)."""
        x, w = self.votes[:, 0], self.votes[:, 1]
        d = x[:, None] - x[None, :]
        d -= np.floor(d + 0.5)  # octave-folded differences
        near = np.abs(d) <= VOTE_WIDTH
        best = int(np.argmax(near.astype(np.float64) @ w))
        mine = near[:, best]  # the frames within VOTE_WIDTH of the best-supported one
        centre = x[best] + float(np.average(d[mine, best], weights=w[mine] + 1e-12))
        r = centre - self.log_p
        self.log_p += r - math.floor(r + 0.5)  # the voted level, at the octave nearest the running one
        self.away = 0.0

    def _refold(self) -> None:
        """Set :attr:`fold` so that the fastest octave lies in (85, 170] bpm, or keep it while that
        octave lies at most :attr:`hold` octave outside (:data:`FOLD_HOLD`: 77-188 bpm)."""
        lo = 60.0 * FPS / TEMPO_RANGE[1]  # frames a beat at the top
        if self.fold == self.fold and self.heard > SETTLE_FRAMES:  # before the vote: folded afresh
            q = 15.0 * 2.0 ** (self.log_p + self.fold)
            if lo * 2.0 ** -self.hold <= q < 2.0 * lo * 2.0 ** self.hold:
                return
        p = fold_period(15.0 * 2.0 ** self.log_p)
        p = 0.5 * p if 0.5 * p >= lo else p
        self.fold = float(round(math.log2(p / 15.0) - self.log_p))

    def _fast(self) -> float:
        """The fastest octave of the running period in :data:`TEMPO_RANGE` (frames; up to
        :data:`FOLD_HOLD` octave outside while the fold holds its octave)."""
        return 15.0 * 2.0 ** (self.log_p + self.fold)

    @property
    def period(self) -> float:
        if self.log_p != self.log_p:
            return 0.0
        p = self._fast()
        lo, hi = 60.0 * FPS / TEMPO_RANGE[1], 60.0 * FPS / TEMPO_RANGE[0]
        p = 2.0 * p if self.slow and 2.0 * p <= hi else max(p, lo)  # held at the top: danced at 170 bpm
        if DRIFT_LEAD == 0.0:
            return p
        lead = min(max(DRIFT_LEAD * self.drift, -DRIFT_CAP), DRIFT_CAP)  # the drift carried on (DRIFT_LEAD)
        return min(max(p * 2.0 ** lead, lo), hi)

    @property
    def confidence(self) -> float:
        return min(1.0, self.conf)


def danced_beat(theta: float, period: float, danced: float) -> tuple[float, float]:
    """(phase, period) of the beats the performer dances to, from the beat tracker's phase
    ``theta`` (radians, 0 on a beat) and ``period`` (frames): where the danced period
    ``danced`` (:attr:`TempoFollower.period`) is an octave or more shorter (2 ** k times,
    within 0.15 octave; vibeace_kevinmacleod: the tracker at 65 bpm, the dance at 129), the
    beats between the tracker's count too: ``theta * 2 ** k`` (mod 2 pi) and ``period / 2 ** k``.
    Elsewhere (the same level, a slower or a 3:2 level, no tempo yet) they are the tracker's."""
    if danced <= 0.0 or period <= 0.0:
        return theta, period
    x = math.log2(period / danced)
    k = round(x)
    if k < 1 or abs(x - k) > 0.15:
        return theta, period
    m = float(2 ** k)
    return (theta * m) % (2.0 * math.pi), period / m


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
