"""The dance stream's player: per frame, the pose of the movement being played.

:class:`Player` holds what :class:`~models.networks.dance_stream.DanceStream` plays between two
code steps (8 frames at 30 fps): the chosen exemplar's window (the movement and its continuation,
bent by the inertialization to continue the motion) behind the rows the last movement still plays
(:mod:`models.networks.handover`), read out at the tempo's rate and under the beat warp, with each
foot's contact along. A code step hands it a new window (:meth:`Player.play`) at a rate it works
out: the rate the followed tempo asks (:meth:`Player.asked_rate`, :data:`FOLLOW_TEMPO`), under the
speed caps (:meth:`Player.rate_for`, :data:`SPEED_CAP`, :data:`SPEED_CAP_TEMPO`), matched to the
bend's speed (:meth:`Player.speed_matched`, :data:`SPEED_MATCH`) and the bone cap
(:meth:`Player.bone_limit`, :data:`BONE_CAP`). Each frame then reads one pose
(:meth:`Player.warped`, :data:`BEAT_WARP`), allocation-free but for the pose it returns.

Also here: the memory's mean tempo (:func:`reference_period`) and the tempo input a predictor that
hears the tempo is trained on (:func:`tempo_inputs`), both the rate's arithmetic.
"""

from __future__ import annotations

import math

import numpy as np

from models.networks import feet as feet_part
from models.networks import tempo as tempo_mod
from models.networks.dance_jit import joint_speed, warp_pose
from models.networks.dance_vq import DanceVQ
from models.networks.handover import Handover
from models.networks.tempo import DENSITY_WINDOW, TEMPO_RANGE, TempoFollower, danced_beat, onset_density
from models.rig.skeleton import POINT_PARENT_INDEX, load_default_skeleton
from models.timebase import FPS

#: Frames over which a new movement's difference from the last one decays (inertialization), at 8 frames a code.
DECAY_FRAMES: int = 16
#: Largest angular-velocity mismatch (per bone, radians per frame: 23 degrees) that the
#: inertialization carries into a new movement (models/networks/dance_jit.py: match_exemplar).
VEL_CAP: float = 0.4
#: Beat warp: the playback rate of the chosen movement is ``1 - BEAT_WARP * w * cos(theta)``,
#: theta the beat tracker's phase (0 on a beat) and w its pulse clarity over
#: :data:`WARP_CLARITY` (at most 1), so the motion slows into every expected beat and
#: catches up between them: speed dips (kinematic beats) move onto the music's beats, as
#: Dancing to Music warps its dance units to the beat. 0 plays every movement at its own pace.
#: With the handover on an exemplar's recorded frames (handover.ON_FRAMES, not shipped) 0.5 keeps
#: today's jerk and beat hit (docs/history.md, "The amplitude gap").
BEAT_WARP: float = 0.45
#: Frames after the tracker's beat that the warp slows into and the motion matching places a
#: movement's speed dip on. The whole chain (the tracker's phase, the warp, the movements'
#: own dips) put the dips early: over the first minute of the 34 training dances, whose
#: motion no target judges, most fell 1 frame before the music's beat (librosa's, as the
#: evaluation scores them; mean -0.49 frames within +-4), on the waltzes of the listening
#: set 2-3 frames at 0.8x. 1 centres them (mean +0.12; the training dances' hit rate 0.498
#: -> 0.522; benchmarks/studies/beat_control.py --split train --max-frames 1800
#: --beat-delay 0 1). 0: on the tracker's beat.
BEAT_DELAY: float = 1.0
#: Pulse clarity at which the beat warp is at full depth (a clean click track gives about 0.5).
WARP_CLARITY: float = 0.3
#: The warp plays the movement this many frames late on average (the slack it slows into
#: and catches up from), and never more than twice that.
WARP_LAG: float = 1.5
#: Pull of the warp's lag back to :data:`WARP_LAG` per frame, so a drifting phase estimate
#: cannot run it into either bound.
WARP_PULL: float = 0.05
#: Tempo following: each movement plays at ``r = T / T_ref``, T the music's tempo
#: (:class:`models.networks.tempo.TempoFollower`, in the range the performer dances at) and
#: T_ref the memory's mean tempo (the geometric mean over its exemplars of the tempo of the
#: song each was danced to, ``DanceVQ.member_period``: 89.8 bpm for the shipped model),
#: blended towards 1 as the pulse fades (the follower's confidence), within
#: :data:`RATE_RANGE`, and no movement is sped up past the memory's 90th-percentile speed
#: (:data:`SPEED_CAP`; one faster on its own plays at its own pace); the rate moves from the last movement's to the new one's over the
#: movement, so a change of tempo never jerks. Each exemplar's own song tempo as the
#: reference (``T / T_src``) was measured too (docs/history-listening.md, "Listening"): the rate then jumps
#: between exemplars of different styles at every handover (jerk 2.1x the dancers',
#: bone steps up to 49.6 degrees), for no gain in how the pace follows the music. False
#: plays every movement at its own pace.
FOLLOW_TEMPO: bool = True
#: Playback rates a movement may take (a movement plays ``r * seg`` of its exemplar's frames
#: over its ``seg`` frames; its window holds ``2 seg``).
RATE_RANGE: tuple[float, float] = (0.55, 1.75)
#: Follower confidence (:attr:`~models.networks.tempo.TempoFollower.confidence`) below which the
#: rate is blended towards 1 (no clear pulse: the movements' own pace).
RATE_CONFIDENCE: float = 0.15
#: Quantile of the exemplars' mean joint speeds that no movement is sped up past (a movement already faster
#: plays at rate 1 at most). Above energy 1 (:meth:`~models.networks.dance_stream.DanceStream.set_energy`) the
#: quantile rises with the energy, to the memory's fastest exemplar at 2: at a fast tempo the capped livelier
#: movements would otherwise play no faster than energy 1's. Above the memory's tempo it rises with the tempo
#: too (:data:`SPEED_CAP_TEMPO`).
SPEED_CAP: float = 0.9
#: The speed cap follows the tempo: from :data:`SPEED_CAP` at the memory's tempo T_ref to the
#: memory's fastest exemplar (quantile 1: never faster than the fastest dancer) at the top of
#: the danced range (:data:`models.networks.tempo.TEMPO_RANGE`, 170 bpm), linearly in
#: ln(T / T_ref). Without it the cap held every fast song's movements to one speed: on the
#: listening ramp (110-155 bpm) the joint speed stopped following the tempo (correlation
#: 0.32 against 0.60 with it, docs/history.md). Below energy 1 it rises less, not at all at
#: energy 0 (above 1 the energy's own cap is the higher). False: :data:`SPEED_CAP` at every tempo.
SPEED_CAP_TEMPO: bool = True
#: Quantile of the memory's per-frame largest bone rotation (over all its exemplars' frames:
#: 26.7 degrees for the shipped model, the dancers' own 99.9th percentile) that no bone of a
#: sped-up movement passes: a movement whose fastest bone, over the frames it is about to
#: play, would turn faster at the tempo's rate plays slower (at its own pace at least), and
#: the rate it takes over from the last movement is held to the same bound. The mean-speed
#: cap alone let a fast head turn (37 degrees a frame in its exemplar) play at 1.37x under
#: the beat warp: 58 degrees in one frame, once in the hour's soak (docs/reliability.md).
BONE_CAP: float = 0.999
#: Speed matching: the playback rate of a movement handed over to is multiplied by
#: ``(v_own / v_bent) ** SPEED_MATCH`` within :data:`SPEED_MATCH_RANGE`, v_own the mean joint
#: speed of the exemplar frames it is about to play and v_bent that of the same frames bent by
#: the inertialization (:func:`~models.networks.dance_jit.match_exemplar`). The bend carries
#: the last movement's offset and velocity into the new one and adds or cancels motion at
#: every handover: the played speed followed the rate times the bent window's speed (per
#: movement, correlation 0.9) far more than the rate times the chosen exemplar's own (0.3-0.4),
#: so the speed the tempo and the choice ask for was lost in handover noise (tempo ramp,
#: 48 seeds: speed-tempo correlation 0.63, with the matching alone 0.74; validation dances'
#: jerk 1.90x -> 1.48x the dancers'). 0: every movement at its tempo rate, whatever the bend adds.
SPEED_MATCH: float = 1.0
SPEED_MATCH_RANGE: tuple[float, float] = (0.5, 2.0)
#: Steps of the tempo's speed-cap table (:data:`SPEED_CAP_TEMPO`).
_CAP_STEPS = 64


def hermite_decay(frames: int) -> np.ndarray:
    """Cubic Hermite weights (2, frames) that carry an offset and its velocity (per frame) to
    zero over ``frames`` frames: ``offset(j) = w[0, j] x0 + w[1, j] v0``, with zero value and
    slope at j = frames."""
    s = np.arange(frames) / frames
    return np.stack([2 * s**3 - 3 * s**2 + 1, frames * (s**3 - 2 * s**2 + s)]).astype(np.float32)



def reference_period(model: DanceVQ) -> float:
    """The memory's mean tempo T_ref as a beat period (frames at 30 fps): the geometric mean of its
    exemplars' songs' periods (``DanceVQ.member_period``; 0 where none is known)."""
    period = model.member_period.numpy().astype(np.float64)  # (K, M) each exemplar's song; 0 unknown
    real = np.arange(period.shape[1])[None, :] < model.member_count.numpy()[:, None]
    known = period[real & (period > 0)]
    return float(np.exp(np.log(known).mean())) if len(known) else 0.0


def tempo_inputs(model: DanceVQ, features: np.ndarray) -> np.ndarray:
    """(T,) float32: what :attr:`~models.networks.dance_stream.DanceStream.tempo_input` reads after each frame of a fresh stream fed
    ``features`` (T, D) under auto, ln(T / T_ref) within ln :data:`RATE_RANGE` faded with the pulse, from the
    same tempo follower: the tempo a predictor that hears it is trained on (models/training/tempo_predictor.py)."""
    c = model.config
    cc, oc = c.clarity_col, c.onset_col
    out = np.zeros(len(features), np.float32)
    ref = reference_period(model)
    if not (FOLLOW_TEMPO and 0 <= cc and cc + 1 < c.feature_dim) or ref <= 0.0:
        return out
    follower = TempoFollower(tempo_mod.FOLD_HOLD)
    x = np.asarray(features, np.float64)
    dens = 0.0
    lo, hi = RATE_RANGE
    for t in range(len(x)):
        if 0 <= oc < c.feature_dim and t % c.seg == 0:  # the stream's onset density, taken at its code steps
            dens = onset_density(x[max(0, t + 1 - DENSITY_WINDOW): t + 1, oc])
        follower.update(float(x[t, cc + 1]), float(x[t, cc]), dens)
        if follower.period > 0.0:
            w = min(1.0, follower.confidence / RATE_CONFIDENCE)
            out[t] = w * math.log(min(max(ref / follower.period, lo), hi))
    return out



def danced_phase(ccos: float, csin: float, logp: float, followed: float) -> tuple[float, float]:
    """(phase in [0, 2 pi), 0 :data:`BEAT_DELAY` frames after a danced beat; the danced period,
    frames) from the beat tracker's columns (``c cos``, ``c sin``, ``log2 P/15``) and the period
    the tempo follower follows (``followed``, frames; 0 none yet)."""
    theta, period = danced_beat(math.atan2(csin, ccos) % (2 * math.pi), 15.0 * 2.0 ** logp, followed)
    return (theta - 2.0 * math.pi * BEAT_DELAY / period) % (2 * math.pi), period


class Player:
    """Plays the chosen movements frame by frame (see the module docstring).

    Shared, read-only: ``member_speed`` (K, M) each exemplar's mean joint speed (m/frame), the bone
    cap (degrees a frame), the memory's mean tempo (``ref_period``, frames a beat; 0 unknown) and
    the beat tracker's feature columns (``beat_cols``: cos, sin, clarity, log period; None: no
    tracker). The tempo follower is the stream's, handed to each call that reads it.

    State (:meth:`reset`): ``handover`` (:class:`~models.networks.handover.Handover`: where the
    playing exemplar stands in the buffer); ``_played`` (4 seg, P) the buffer of poses read out and
    ``_played_contact`` (4 seg, 3) each row's foot contacts and lift; ``rate`` and ``rate_from``
    (exemplar frames a frame at the end and the start of the current movement); ``own_speed`` (the
    playing exemplar's own mean joint speed, m/frame; 0 none or decoded); ``has_cont`` (the playing
    movement has a real continuation to match the next one to); ``_lag`` (exemplar frames the beat
    warp plays behind); ``at`` (the buffer row the last frame read); ``_rows_ahead`` (what the
    coming handover reads, :meth:`read_ahead`). ``energy`` and ``_speed_cap`` follow the stream's
    energy control (:meth:`set_energy`).
    """

    def __init__(self, seg: int, pose_dim: int, member_speed: np.ndarray, real: np.ndarray, bone_cap: float,
                 ref_period: float, beat_cols: tuple[int, int, int, int] | None) -> None:
        self.seg, self.pose_dim = seg, pose_dim
        self._member_speed = member_speed  # (K, M) m/frame, shared: never written
        self._speeds = member_speed[real]  # every exemplar's mean joint speed (m/frame): the speed cap's quantiles
        self.energy = 1.0
        self._speed_cap = self.speed_cap_at(1.0)
        # the speed cap at each step of the tempo's rise above T_ref (SPEED_CAP_TEMPO): quantiles
        # SPEED_CAP .. 1 of the exemplars' speeds, looked up, not computed, on the audio path
        self._tempo_caps = (np.quantile(self._speeds, np.linspace(SPEED_CAP, 1.0, _CAP_STEPS + 1))
                            if len(self._speeds) else np.full(_CAP_STEPS + 1, np.inf))
        self._bone_cap = bone_cap  # degrees a frame
        self._ref_period = ref_period
        self._beat_cols = beat_cols
        self._fk_parents = np.array(POINT_PARENT_INDEX, np.int64)  # joint_speed's skeleton (SPEED_MATCH)
        self._fk_offsets = load_default_skeleton().point_offsets().astype(np.float64)
        self.decay = hermite_decay(DECAY_FRAMES * self.seg // 8)  # (2, D): the inertialization's (match_exemplar)
        self.handover = Handover(self.seg)  # when the playing exemplar hands over (models/networks/handover.py)
        self.reset()

    def reset(self) -> None:
        """Nothing played: the first movement starts from its own first pose."""
        # what plays: seg frames before the current movement (up to seg more while the last exemplar
        # plays out its frames: handover.py), then its exemplar's window (the movement and its
        # continuation, bent to continue the motion), read at row base + rate * j - lag of frame j
        self._played = np.zeros((4 * self.seg, self.pose_dim), np.float32)
        self._played_contact = np.zeros((4 * self.seg, 3), np.float32)  # each foot's contact and the lift, as _played
        self.rate = 1.0  # exemplar frames per frame at the end of the current movement (tempo following)
        self.rate_from = 1.0  # ... and at its start
        self.own_speed = 0.0  # the current movement's exemplar's own mean joint speed, m/frame (0: none)
        self._lag = WARP_LAG  # exemplar frames the beat warp plays behind the movement
        self.has_cont = False  # the playing movement has a real continuation to match the next one to
        self.handover.reset()
        self.at = float(self.seg)  # where in _played the last frame was read
        self._rows_ahead: tuple | None = None  # what the next handover reads of the playing movement (read_ahead)

    def set_energy(self, energy: float) -> None:
        """The stream's energy control (0..2, checked there): the speed cap it sets (:meth:`speed_cap_at`)."""
        self._speed_cap = self.speed_cap_at(energy)
        self.energy = energy

    def speed_cap_at(self, energy: float) -> float:
        """The speed (m/frame) no movement is sped up past at ``energy``: the memory's
        :data:`SPEED_CAP` quantile up to energy 1, rising linearly to its fastest exemplar at 2
        (inf without exemplars)."""
        if not len(self._speeds):
            return np.inf
        q = SPEED_CAP + (1.0 - SPEED_CAP) * min(1.0, max(0.0, energy - 1.0))
        return float(np.quantile(self._speeds, q))

    # -- the rate, at a code step ----------------------------------------------------------------
    def asked_rate(self, tempo: TempoFollower) -> float:
        """The playback rate the followed tempo (``tempo``) asks for now, within :data:`RATE_RANGE`,
        before the speed cap (1 without a tempo; towards 1 as the pulse fades)."""
        src = self._ref_period
        period = tempo.period
        if not FOLLOW_TEMPO or src <= 0.0 or period <= 0.0:
            return 1.0
        lo, hi = RATE_RANGE
        return min(max(src / period, lo), hi) ** min(1.0, tempo.confidence / RATE_CONFIDENCE)

    def rate_for(self, code: int, member: int, tempo: TempoFollower, asked: float | None = None) -> float:
        """The playback rate of exemplar ``member`` of ``code`` now (:data:`FOLLOW_TEMPO`): the asked
        rate (``asked``, else :meth:`asked_rate`; 1 without a tempo) under the speed cap, which
        only slows a rate over 1 (so a rate over 1 implies a followed tempo and a period)."""
        r = self.asked_rate(tempo) if asked is None else asked
        if r <= 1.0:
            return r
        v = self._member_speed[code, member]
        return min(r, max(1.0, self.cap_now(tempo.period) / v)) if v > 0 else r

    def speed_matched(self, own: np.ndarray, bent: np.ndarray, rate: float) -> float:
        """``rate`` times ``(v_own / v_bent) ** SPEED_MATCH`` (within :data:`SPEED_MATCH_RANGE`, then
        :data:`RATE_RANGE`): v the mean joint speed of the frames a movement at ``rate`` plays of
        the exemplar window ``own`` (2 seg, P) and of ``bent``, the same bent to continue the motion
        (``rate`` itself with :data:`SPEED_MATCH` 0)."""
        if SPEED_MATCH <= 0.0:
            return rate
        n = min(len(bent), int(math.ceil(self.seg * rate)) + 1)
        v_own = joint_speed(own, n, self._fk_parents, self._fk_offsets)
        v_bent = joint_speed(bent, n, self._fk_parents, self._fk_offsets)
        if v_own <= 0.0 or v_bent <= 0.0:
            return rate
        lo, hi = SPEED_MATCH_RANGE
        f = min(max((v_own / v_bent) ** SPEED_MATCH, lo), hi)
        return min(max(rate * f, RATE_RANGE[0]), RATE_RANGE[1])

    def cap_now(self, period: float) -> float:
        """The speed cap (m/frame) at the followed tempo's ``period`` (frames): the energy's
        (:meth:`speed_cap_at`) or, above the memory's tempo, the tempo's (:data:`SPEED_CAP_TEMPO`), the higher."""
        cap = self._speed_cap
        if SPEED_CAP_TEMPO and 0.0 < period < self._ref_period:
            top = math.log(self._ref_period * TEMPO_RANGE[1] / (60.0 * FPS))  # ln(170 bpm / T_ref)
            x = min(1.0, math.log(self._ref_period / period) / top) if top > 0.0 else 1.0
            x *= min(1.0, self.energy)  # below energy 1 the cap rises less: energy 0 stays calm at any tempo
            cap = max(cap, float(self._tempo_caps[int(round(x * _CAP_STEPS))]))
        return cap

    def bone_limit(self, window: np.ndarray, rate: float) -> float:
        """The fastest rate (>= 1) at which no bone of ``window`` (2 seg, P) turns faster than
        :data:`BONE_CAP`'s bound over the frames a movement at ``rate`` plays (inf: no limit)."""
        if not FOLLOW_TEMPO or rate <= 1.0:
            return np.inf
        n = min(len(window), int(math.ceil(self.seg * rate + 2 * WARP_LAG)) + 1)
        q = window[:n, 3:]  # unit quaternions (match_exemplar's, or _unit's): rotation_jumps_deg without its norms
        dot = float(np.abs(np.add.reduce((q[1:] * q[:-1]).reshape(n - 1, -1, 4), axis=-1)).min())
        peak = math.degrees(2.0 * math.acos(min(dot, 1.0)))
        return max(1.0, self._bone_cap / peak) if peak > 0.0 else np.inf

    # -- a code step's handover ------------------------------------------------------------------
    def play(self, window: np.ndarray, rate: float, limit: float = np.inf, contact: np.ndarray | None = None,
             shift: float = 0.0, d: int = 0, ahead: tuple | None = None, first: bool = False) -> None:
        """Start playing ``window`` (2 seg, P), the next movement and its continuation, at ``rate``
        (and the rate it takes over from the current movement) at most ``limit``: the ``seg + d``
        rows before it are those the current movement would have played next from row ``seg +
        shift`` (``d``: the rows its exemplar plays on to its own frame seg, handover.py).
        ``contact`` (2 seg, 3): its exemplar's foot contacts and lift
        (:func:`models.networks.feet.member_contacts`; None: none known). ``ahead``: those rows,
        contacts and lifts (:meth:`rows_from`) as :meth:`read_ahead` read them on the frame before
        (None: read them now). ``first``: the stream's first movement (nothing played before it)."""
        n, e = self.seg + d, self.seg + d + len(window)  # the window's rows: n .. e
        if first:  # before the first movement there is only its first pose
            self._played[:n] = window[0]
            self._played_contact[:n] = contact[0] if contact is not None else 0.0
        else:
            self._played[:n], self._played_contact[:n], lift = ahead if ahead is not None else self.rows_from(shift, n)
        self._played[n:e] = window
        self._played[e:] = window[-1]
        self._played_contact[n:e] = contact if contact is not None else 0.0
        self._played_contact[e:] = self._played_contact[e - 1]
        if not first and self.has_cont and contact is not None:  # bent as the root's height (feet.bend_lift)
            feet_part.bend_lift(self._played_contact[n:e], *lift, self.decay)
        rate = min(rate, limit)
        self.rate_from = rate if first else min(self.rate, limit)
        self.rate = rate

    def hold(self) -> None:
        """A code step without a handover (handover.py): the playing exemplar plays on at its rate."""
        self.handover.hold(self.advance(self.seg))
        self.rate_from = self.rate

    def advance(self, j: int) -> float:
        """Exemplar frames the current movement has played by its frame ``j``: the rate moves
        linearly from ``rate_from`` (frame 0) towards ``rate`` (frame seg)."""
        return j * self.rate_from + (self.rate - self.rate_from) * j * (j - 1) / (2 * self.seg)

    def reached(self) -> float:
        """The buffer row the playing movement gets to by the next code step."""
        return self.handover.base + self.advance(self.seg)

    def read_ahead(self, frame: int, reached: float) -> None:
        """On the frame before the code step of stream frame ``frame`` (after its own read): what the
        coming handover reads of the playing movement, which no frame changes until then: the ``seg``
        rows before the new movement (from row ``reached - seg``: :meth:`play`'s), their contacts and
        the two lifts after them, and the motion's next two poses at ``reached`` (the matching's). The
        code step then only takes them (:meth:`ahead_for`); the values are those it would read itself.
        Only for a handover at once (``d`` = 0)."""
        self._rows_ahead = (frame, reached, self.rows_from(reached - self.seg, self.seg), self.next_two(reached))

    def ahead_for(self, frame: int, reached: float, d: int) -> tuple | None:
        """((rows, contacts, lifts) of :meth:`rows_from`, the next two poses) as :meth:`read_ahead`
        read them, when that reading is for the code step of stream frame ``frame``, at ``reached``,
        for a handover at once (``d`` 0); else None."""
        ahead = self._rows_ahead
        if ahead is None or d != 0 or ahead[0] != frame or ahead[1] != reached:
            return None
        return ahead[2:]

    def rows_from(self, shift: float, n: int) -> tuple[list, list, tuple[float, float]]:
        """The playing movement's ``n`` rows from row ``shift`` (poses, as warp_pose reads them), their
        contacts and the lifts of the two rows after them: what a handover keeps before the new movement."""
        rows = [warp_pose(self._played, shift + i) for i in range(n)]
        contact = [self.contact_at(shift + i) for i in range(n)]
        return rows, contact, (self.contact_at(shift + n)[2], self.contact_at(shift + n + 1)[2])

    def next_two(self, at: float) -> np.ndarray:
        """The playing motion's poses (2, P) at rows ``at`` and ``at + 1``: the motion matching's continuation."""
        return np.stack([warp_pose(self._played, at), warp_pose(self._played, at + 1.0)])

    def next_beat(self, row: np.ndarray, tempo: TempoFollower, rate: float = 1.0,
                  d: int = 0) -> tuple[int, float] | None:
        """(frame of the coming movement's exemplar, 0..seg-1, that plays when the beat tracker
        expects a beat (the tracker's columns of feature ``row``), the movement played at ``rate``
        from ``d`` exemplar rows on; its pulse clarity), or None when no beat falls in it or the
        features have no beat columns."""
        if self._beat_cols is None:
            return None
        ccos, csin, clarity, logp = (float(row[j]) for j in self._beat_cols)
        if clarity <= 0.0:
            return None
        theta, period = danced_phase(ccos, csin, logp, tempo.period)
        ahead = rate * (period * (1 - theta / (2 * np.pi)) % max(period, 1.0)) - d
        if ahead < -0.5:  # that beat comes before the exemplar starts: the one after it
            ahead += rate * max(period, 1.0)
        ahead = int(round(ahead))
        return (ahead, clarity) if 0 <= ahead < self.seg else None

    # -- every frame -----------------------------------------------------------------------------
    def warped(self, j: int, row: np.ndarray, tempo: TempoFollower) -> np.ndarray:
        """The pose (P,) of frame ``j`` of the current movement at its tempo rate and under the
        beat warp (the tracker's columns of feature ``row``): row ``base + rate * j - lag`` of
        ``_played`` (handover.py), between two frames nlerped (``warp_pose``; the lag moves by
        ``rate * BEAT_WARP * w * cos(theta)`` a frame; see :data:`BEAT_WARP`); :attr:`at` the row read."""
        x = self.handover.base + self.advance(j)
        if self._beat_cols is None or BEAT_WARP <= 0.0:  # no beat tracker, or no warp: the movement as it is
            self.at = x
            return warp_pose(self._played, x)
        ccos, csin, clarity, logp = (float(row[c]) for c in self._beat_cols)
        depth = BEAT_WARP * min(1.0, max(clarity, 0.0) / WARP_CLARITY)
        theta, _ = danced_phase(ccos, csin, logp, tempo.period)  # 0 BEAT_DELAY frames after a danced beat
        cos = math.cos(theta) if clarity > 1e-9 else 0.0
        rate = self.advance(j + 1) - self.advance(j)  # exemplar frames this frame plays
        lag = self._lag + rate * depth * cos - WARP_PULL * (self._lag - WARP_LAG)
        self._lag = min(max(lag, 0.0), 2.0 * WARP_LAG)
        self.at = x - self._lag
        return warp_pose(self._played, self.at)

    def contact_at(self, x: float) -> tuple[float, float, float]:
        """Each foot's contact (left, right; 0..1) and the exemplar's lift (m) at fractional frame
        ``x`` of ``_played`` (:func:`models.networks.feet.member_contacts`), linearly between
        two frames (as ``warp_pose`` reads the poses)."""
        c = self._played_contact
        i = min(max(int(math.floor(x)), 0), len(c) - 1)
        f = min(max(x - i, 0.0), 1.0) if i + 1 < len(c) else 0.0
        if f < 1e-6:
            return float(c[i, 0]), float(c[i, 1]), float(c[i, 2])
        a, b = c[i], c[i + 1]
        return (float(a[0] + f * (b[0] - a[0])), float(a[1] + f * (b[1] - a[1])), float(a[2] + f * (b[2] - a[2])))
