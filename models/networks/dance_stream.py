"""The dancing performer, live: :class:`DanceStream` runs a ``dance_vq`` model frame by frame.

The engine's contract (:class:`realtime.contracts.PoseModel`): ``push(features (k, D)) ->
poses (k, POSE_DIM)``, one pose per feature frame at once, 30 fps, no look-ahead.

Every ``seg`` frames (frame ``t = seg * k``) the stream appends audio token ``k`` to its
window of the last ``window_codes`` tokens (128 frames), asks the code predictor for the
next code, draws it from the stream's own seeded generator, and plays one of that code's
real exemplars (the choreographic memory), matched to the motion so far (at once, or with
:data:`models.networks.handover.ON_FRAMES` once the playing exemplar has played its own ``seg``
recorded frames); the frames in between read it out. (A code without exemplars would have
its ``seg`` poses decoded from the last ``decoder_context`` codes; the shipped memory has
exemplars for every code.)

**What it composes.** Each frame of :meth:`DanceStream.push` goes through its parts in turn:
the idle gate (:class:`models.networks.idle_gate.IdleGate`: music or not, the idle weight), the
tempo follower (:class:`models.networks.tempo.TempoFollower`), the chooser when a code step is due
(:class:`models.networks.chooser.Chooser`: the predictor's context, the logits and their tilts, the
draw; :meth:`DanceStream._next_code` matches the drawn codes' exemplars to the motion and hands the
chosen one over), the player (:class:`models.networks.player.Player`: the movement playing, its
rate and the beat warp), the idle fade (:mod:`models.networks.idle_fade`), the stage
(:class:`models.networks.stage.Stage`) and the feet (:class:`models.networks.feet.FeetLock`). This
module keeps what joins them: the memory's shared tables (loaded from the model's caches and
handed to the parts), the code step, the lead's forecast, the controls and the code history.

**At the music's tempo.** A movement's exemplar is read at ``r`` of its frames a frame,
``r`` the music's tempo (:class:`models.networks.tempo.TempoFollower`) over the memory's
mean tempo (:data:`models.networks.player.FOLLOW_TEMPO`), and the faster the tempo, the livelier the
movements drawn (:data:`models.networks.chooser.TEMPO_ENERGY`). The memory is read through a light low-pass
(:data:`MEMBER_SMOOTH`), so a sped-up movement does not speed up its mocap noise.

:func:`generate` pushes a whole song through a fresh stream, so offline and
live give the same poses for the same seed and style, however the frames are chunked.

**On the beat.** The decided movement is played back through a beat warp: slower into
every beat the causal beat tracker expects, faster between them (:data:`models.networks.player.BEAT_WARP`),
read between frames about :data:`models.networks.player.WARP_LAG` frames late, so its speed dips land on the beats.

**Idle between songs.** The idle gate (:class:`models.networks.idle_gate.IdleGate`) decides
whether music is playing (its presence detector, :mod:`models.networks.music_gate`, or an older
checkpoint's logistic one) and holds through a song's breaks of up to 2 s; without music the
performer fades into a calm idle (the dancers' mean pose with a slow sway of hips, spine and
head, :mod:`models.networks.idle_fade`) and back into the dance, which has kept running underneath, so nothing
jumps. ``set_idle(True)`` holds the idle whatever the music (the show control's ``/performer/idle``).
"""


from __future__ import annotations

import math
import numbers

import numpy as np

from models.errors import ConfigError
from models.networks import chooser as chooser_part
from models.networks import feet as feet_part
from models.networks import lead as lead_part
from models.networks import player as player_part
from models.networks import tempo as tempo_mod
from models.networks.blend import blend_track
from models.networks.chooser import Chooser
from models.networks.dance_jit import match_exemplar, renorm_pose, sanitize_rows
from models.networks.dance_numpy import NumpyPredictor
from models.networks.dance_vq import DanceVQ
from models.networks.feet import FeetLock
from models.networks.idle_fade import IdleFade, IdleSway
from models.networks.idle_gate import IdleGate
from models.networks.lead import PhaseForecast
from models.networks.library_player import bend_deg, resolve_style
from models.networks.member_tables import (CHUNK_FRAMES, MemberTables, code_energy, code_frequency, member_dips,  # noqa: F401
                                          member_positions, member_speed, member_tables)
from models.networks.player import Player, danced_phase, reference_period
from models.networks.stage import SpotStage, Stage, cached_travel
from models.networks.streaming import FEATURE_LIMIT
from models.networks.tempo import DENSITY_WINDOW, TempoFollower, onset_density
from models.rig.kinematics import rotation_jumps_deg
from models.timebase import FPS

#: Gaussian sigma (frames) of the low-pass each exemplar window of the memory is read through
#: (:func:`_cached_members`; per track, then renormalised): the mocap's frame-to-frame noise,
#: which a movement sped up by the tempo rate r turns into jerk as r cubed, is taken out
#: (dance-scale motion, up to 2 Hz, keeps 87 % or more of its amplitude). 0: as recorded.
MEMBER_SMOOTH: float = 1.25
#: Feet on the floor (:mod:`models.networks.feet`, the stream's last step on every frame): the
#: feet the played exemplar has on the floor stay put in the world by two-bone leg IK, no knee
#: bends past straight, no foot goes under the floor, while the performer travels on a stage
#: (in place: :data:`FEET_IN_PLACE`). Validation songs on a 6x5 stage, foot-skating ratio 0.81
#: -> 0.20 (benchmarks/studies/foot_skating.py, docs/feet.md). The stream's ``feet`` argument overrides it.
#: False: the legs as the memory plays them.
FEET_LOCK: bool = True
#: What the feet part does while the performer dances in place (no stage, the canonical
#: frame every evaluation scores): "off" (the dance's legs bit for bit, as before it), "floor"
#: (knees never past straight, no foot under the floor, nothing held) or "hold" (as on a
#: stage). performer evaluate's headline on the validation songs (band amplitude, jitter, jerk,
#: beat hit rate, FD; tests/test_eval_reference.py's default_headline at 136023d): "off" 0.856,
#: 1.001, 135.7, 0.543, 6.50; "floor" 0.856, 1.006, 136.7, 0.542, 6.67; "hold" 0.681, 1.003,
#: 120.8, 0.502, 9.48: in place the held feet stop the dancers' own sliding steps, which the
#: canonical dancers it is scored against have (docs/feet.md). A memory without travel dances in place
#: on a stage too. Once the part has stepped (a stage was set), it keeps stepping in place with
#: nothing held, so nothing it held jumps back.
FEET_IN_PLACE: str = "off"
#: The energy control's range.
ENERGY_RANGE: tuple[float, float] = (0.0, 2.0)
#: The lead control's range, ms (:meth:`DanceStream.set_lead`): a display chain's delay
#: (renderer, projector, LED wall, encoder) that the motion is sent ahead of.
LEAD_RANGE_MS: tuple[float, float] = (0.0, 200.0)

#: Codes :attr:`DanceStream.codes_drawn` keeps, the newest (65,536: 4.9 hours at 8 frames a
#: code); past that it drops the oldest :data:`CODES_TRIM` at once, so a stream that runs for
#: days holds at most 2.4 MB of history (one trim moves 0.5 MB in memory, every 4.5 minutes).
CODES_KEPT: int = 65536
CODES_TRIM: int = 1024


def _real(value: object) -> float | None:
    """``value`` as a float if it is a real number (a Python or numpy int or float), else None:
    a string such as ``"1.5"`` or a bool is not a number a control takes."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        return None
    return float(value)


def _renorm_frame(pose: np.ndarray, prev_quat: np.ndarray | None) -> np.ndarray:
    """``blend_track(pose[None, None], [[1]], prev_quat)[0]`` for one pose (P,): its quaternions
    renormalised and sign-aligned to ``prev_quat`` (J, 4), without the blend of one candidate
    with itself (the engine pushes one frame at a time: 50-80 µs a frame there). One compiled
    call (:func:`models.networks.dance_jit.renorm_pose`, NumPy's arithmetic bit for bit; a zero
    may change sign against ``blend_track``); non-finite or near-zero quaternions take the
    general path."""
    out = np.empty(len(pose), np.float32)
    if renorm_pose(np.ascontiguousarray(pose, np.float32), _NO_PREV if prev_quat is None else prev_quat, out):
        return out
    return blend_track(pose[None, None], np.ones((1, 1)), prev_quat)[0]


#: ``renorm_pose``'s "no previous frame" (no quaternion to align the signs to).
_NO_PREV = np.zeros((0, 4), np.float32)


def _unit(p: np.ndarray) -> np.ndarray:
    q = p[..., 3:].reshape(*p.shape[:-1], -1, 4)
    norm = np.sqrt(np.add.reduce(q * q, axis=-1, keepdims=True))  # np.linalg.norm's arithmetic, without its wrapper
    p[..., 3:] = (q / np.maximum(norm, 1e-9)).reshape(*p.shape[:-1], -1)
    return p


def sign_continuous(windows: np.ndarray) -> np.ndarray:
    """Poses (..., F, P) with each quaternion's sign chosen frame by frame to follow the
    previous frame's (the corpus stores w >= 0 per frame, which flips a bone whose rotation
    crosses w = 0: a fake jump of the quaternion, not of the bone)."""
    out = windows.copy()
    q = out[..., 3:].reshape(*out.shape[:-1], -1, 4)
    for t in range(1, q.shape[-3]):
        dot = (q[..., t, :, :] * q[..., t - 1, :, :]).sum(-1, keepdims=True)
        q[..., t, :, :] *= np.where(dot < 0, -1.0, 1.0).astype(q.dtype)
    out[..., 3:] = q.reshape(*out.shape[:-1], -1)
    return out


def _weights_key(tensors) -> tuple:
    """Where each tensor's memory is and how often it was written in place (its version
    counter): a key that changes whenever the weights do."""
    return tuple((t.data_ptr(), t._version, tuple(t.shape)) for t in tensors)


def _cached_predictor(model: DanceVQ) -> NumpyPredictor:
    """The :class:`NumpyPredictor` of ``model``'s predictor, kept on the model and shared by
    every stream of it: an ensemble's performers of one checkpoint hold one copy of the
    predictor's weights (it is read-only: each stream keeps its own :class:`Prefix`; 8
    performers' peak memory 531 -> 458 MB with :func:`_cached_members`, their hop time
    unchanged, docs/latency.md). Rebuilt when a weight changes (a training step writes
    them in place: their version counters move)."""
    key = _weights_key(model.predictor.parameters())
    cached = getattr(model, "_numpy_predictor", None)
    if cached is None or cached[0] != key:
        cached = (key, NumpyPredictor(model.predictor))
        model._numpy_predictor = cached
    return cached[1]


def smooth_members(members: np.ndarray, counts: np.ndarray, sigma: float) -> np.ndarray:
    """Exemplar windows (K, M, F, P), sign-continuous (:func:`sign_continuous`), with each of the
    ``counts`` (K,) real ones low-passed along its frames by a Gaussian of ``sigma`` frames
    (edges: the nearest frame) and its quaternions renormalised; empty slots as they are.
    sigma 0: unchanged (a copy)."""
    out = members.copy()
    real = np.arange(members.shape[1])[None, :] < np.asarray(counts)[:, None]
    if sigma <= 0.0 or not real.any():
        return out
    from scipy.ndimage import gaussian_filter1d

    out[real] = _unit(gaussian_filter1d(members[real], sigma, axis=1, mode="nearest").astype(np.float32))
    return out


def _members_key(model: DanceVQ) -> tuple:
    """What :func:`_cached_members` and the tables read from it depend on: the memory's tensors and its filters."""
    return _weights_key([model.member_poses, model.member_count]), MEMBER_SMOOTH


def _cached_members(model: DanceVQ) -> np.ndarray:
    """``model``'s exemplars as :func:`sign_continuous` makes them, low-passed by
    :func:`smooth_members` (:data:`MEMBER_SMOOTH`), (K, M, 2 seg, P), kept on the model like
    :func:`_cached_predictor`; streams only read it. (Not flagged read-only: the compiled
    :func:`match_exemplar` would compile again, in the audio path, for read-only slices.)"""
    key = _members_key(model)
    cached = getattr(model, "_members_cache", None)
    if cached is None or cached[0] != key:
        model._members_cache = None  # the old copy goes before the new one is built
        poses, counts = model.member_poses, model.member_count.numpy()
        mem = np.empty(tuple(poses.shape), np.float32)
        step = max(1, CHUNK_FRAMES // max(1, poses.shape[1] * poses.shape[2]))  # codes at a time: bounded transients
        for a in range(0, len(mem), step):
            mem[a: a + step] = smooth_members(sign_continuous(poses[a: a + step].float().numpy()), counts[a: a + step],
                                              MEMBER_SMOOTH)
        cached = (key, mem)
        model._members_cache = cached
    return cached[1]


def _cached_tables(model: DanceVQ, members: np.ndarray) -> MemberTables:
    """:func:`~models.networks.member_tables.member_tables` of ``model``'s exemplars ``members``
    (:func:`_cached_members`): their beats, speeds, energy, quickness and contacts from one FK
    pass, kept on the model like :func:`_cached_members` (the FK of every exemplar took
    0.4-0.6 s a table, paid by every new stream otherwise). Recomputed when ``member_poses`` or
    ``member_count`` changes (another tensor, or the same one written in place) or a feet constant does."""
    key = (_members_key(model), model.config.seg, feet_part.CONTACT_HEIGHT, feet_part.CONTACT_SPEED,
           feet_part.FLOOR_PERCENTILE)
    cached = getattr(model, "_tables_cache", None)
    if cached is None or cached[0] != key:
        model._tables_cache = None  # the old tables go before the new ones are built
        cached = (key, member_tables(members, model.member_count.numpy(), model.config.seg))
        model._tables_cache = cached
    return cached[1]


def _cached_dips(model: DanceVQ, members: np.ndarray, seg: int) -> np.ndarray:
    """(K, M, seg) :func:`member_dips` of ``model``'s exemplars (:func:`_cached_tables`; ``seg`` the model's)."""
    return _cached_tables(model, members).dips


def _cached_frequency(model: DanceVQ, members: np.ndarray) -> np.ndarray:
    """:func:`code_frequency` (K,) of ``model``'s exemplars (:func:`_cached_tables`)."""
    return _cached_tables(model, members).frequency


def _cached_energy(model: DanceVQ, members: np.ndarray, seg: int) -> tuple[np.ndarray, np.ndarray]:
    """(:func:`code_energy` (K,), each exemplar's mean joint speed over its movement (K, M),
    m/frame) of ``model``'s exemplars (:func:`_cached_tables`; ``seg`` the model's)."""
    t = _cached_tables(model, members)
    return t.energy, t.speed


def _cached_contacts(model: DanceVQ, members: np.ndarray) -> tuple[np.ndarray, float]:
    """(:func:`models.networks.feet.member_contacts` of ``model``'s exemplars ``members`` (K, M, 2 seg, 3);
    the memory's floor, m) (:func:`_cached_tables`)."""
    t = _cached_tables(model, members)
    return t.contacts, t.floor


def _cached_bone_cap(model: DanceVQ, members: np.ndarray, counts: np.ndarray) -> float:
    """The :data:`models.networks.player.BONE_CAP` quantile (degrees a frame) of every exemplar frame's largest bone
    rotation (:func:`models.rig.kinematics.rotation_jumps_deg`) in ``model``'s memory (inf
    without exemplars), kept on the model like :func:`_cached_members`."""
    key = (_members_key(model), player_part.BONE_CAP)
    cached = getattr(model, "_bone_cap_cache", None)
    if cached is None or cached[0] != key:
        steps = [rotation_jumps_deg(w[:, 3:].reshape(len(w), -1, 4)).max(axis=1)
                 for k, n in enumerate(counts) for w in members[k, :n]]  # no copy of the real windows
        cached = (key, float(np.quantile(np.concatenate(steps), player_part.BONE_CAP)) if steps else np.inf)
        model._bone_cap_cache = cached
    return cached[1]



class DanceStream:
    """Frame-by-frame generation with a :class:`DanceVQ` (see the module docstring).

    seed: the sampling generator's seed (``reset`` restarts it). style: None/"auto"
    (the music decides), "chacha", "rumba" or "waltz"; ``set_style`` changes it from the
    next code (within 267 ms). energy: 0..2, 1 = as the music asks; ``set_energy`` changes
    it the same way. lead_ms: 0..200, the display chain's delay the poses are sent ahead of
    (``set_lead``, from the next code step on). ``codes_drawn``: the codes drawn, one a code
    step, oldest first (the newest :data:`CODES_KEPT` of a long stream; with
    ``handover.ON_FRAMES`` a step that holds draws one that is not played).

    **Parts.** Each frame (:meth:`push`) goes through the idle gate (``_idle``), the tempo
    follower (``_tempo``), the chooser when a code step is due (``_chooser``: which movement,
    models/networks/chooser.py; :meth:`_next_code` matches its exemplars to the motion and hands
    the chosen one to the player), the player (``_player``: the pose of the movement playing,
    models/networks/player.py), the idle fade, the stage (``_stage``) and the feet (``_feet``).

    **Lead.** With a lead of L frames (``round(lead_ms * 30 / 1000)``, 0..6) the pose sent
    at audio frame t is the one the performer takes at t + L: every beat-tracker phase
    the stream reads (the predictor's audio tokens, the beat placement of the next
    movement, the beat warp) is the tracker's own forecast for L frames on, phase and period
    (models/networks/lead.py); the rest of each frame is the audio heard so far. A
    movement played from audio frame t (shown at t + L) is so decided with audio up to L
    frames before it is seen, and its speed dips aim at the beats expected at t + L.
    The code steps stay on frames ``t % seg == 0`` whatever the lead, so an ensemble's
    stagger and the prefix schedule (the chooser's ``_pieces_by``) are those of lead 0.
    """

    def __init__(self, model: DanceVQ, seed: int = 0, style: str | None = None, energy: float = 1.0,
                 lead_ms: float = 0.0, feet: bool | None = None, stage=0, facing: str = "free",
                 spot: tuple[int, int] | None = None) -> None:
        if not isinstance(model, DanceVQ):
            raise ConfigError(f"DanceStream needs a dance_vq model, got {type(model).__name__}")
        self.model = model.eval()
        c = model.config
        self.seg, self.pose_dim = c.seg, c.pose_dim
        self.feature_dim = c.input_dim  # columns push() takes: the predictor's, + the gate's steadiness column
        self.seed = int(seed)
        feat_mean = model.feat_mean.numpy().astype(np.float32)
        feat_std = model.feat_std.numpy().astype(np.float32)
        self._idle = IdleGate(model, feat_mean, feat_std)  # music present or not, the idle weight
        # the memory's tables, shared by every stream of the model (never written): the parts read them
        members = _cached_members(model)  # (K, M, 2 seg, P)
        self._counts = model.member_count.numpy()
        # feet on the floor (models/networks/feet.py): each exemplar frame's contacts, played along
        self._contacts, floor = _cached_contacts(model, members)  # (K, M, 2 seg, 3): contacts, lift (m)
        self._feet = FeetLock(floor) if (FEET_LOCK if feet is None else feet) else None
        energy_z, speed = _cached_energy(model, members, self.seg)  # (K,) z-scores, (K, M) m/frame
        self._member_speed = speed
        real = np.arange(speed.shape[1])[None, :] < self._counts[:, None]
        ref_period = reference_period(model)  # the memory's mean tempo (frames per beat)
        # travel and turns on the stage (models/networks/stage.py): each exemplar's, played along
        self._travel = cached_travel(model, MEMBER_SMOOTH)  # (K, M, 2 seg, 3), shared: never written
        # spot (i, n): performer i of an ensemble of n, on its own part of the stage (SpotStage)
        self._stage = Stage(self.seg, stage, facing) if spot is None else SpotStage(self.seg, stage, facing, spot)
        self._travels = bool(self._travel.any())  # a memory without travel dances in place on any stage
        cc = c.clarity_col
        self._beat_cols = (cc - 2, cc - 1, cc, cc + 1) if 0 <= cc and cc + 1 < c.feature_dim else None
        self._onset_col = c.onset_col if 0 <= c.onset_col < c.feature_dim else None
        self._forecast = PhaseForecast()  # the lead's beat forecast (models/networks/lead.py), fed the onsets
        # the chooser (which movement, per code step) and the player (its poses, per frame)
        self._chooser = Chooser(model, _cached_predictor(model), self.seed, resolve_style(model, style), feat_mean,
                                feat_std, members, _cached_dips(model, members, self.seg), self._travel, energy_z,
                                _cached_frequency(model, members), speed, real, ref_period)
        self._player = Player(self.seg, self.pose_dim, speed, real, _cached_bone_cap(model, members, self._counts),
                              ref_period, self._beat_cols)
        self._handover = self._player.handover  # (models/networks/handover.py), the player's
        self.energy = 1.0
        self.set_energy(energy)
        self.lead_ms = 0.0
        self._lead_next = 0  # lead in frames from the next code step on (set_lead)
        self.set_lead(lead_ms)
        base = getattr(model, "idle_base", None)  # a library's own mean pose (library_player), else the dancers'
        base = model.destandardize_poses(model.pose_mean * 0) if base is None else base  # unit quaternions
        self._idle_base = base.numpy().astype(np.float32)
        self._sway = IdleSway(self._idle_base)
        self._idle_lift = self._feet.lift_of(self._idle_base) if self._feet is not None else 0.0
        self.reset()

    # -- controls ----------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget all history: the next pushed frame is frame 0 of a new stream (same seed)."""
        self.frame = 0
        self.nonfinite_frames = 0
        self._chooser.reset()
        self._player.reset()
        # the last movement handed to's rate as the tempo asked it (Player.asked_rate) and under the speed cap
        # (Player.rate_for), before the speed matching and the bone cap: where the tempo's rate goes (a study's figure)
        self.rate_split: tuple[float, float] = (1.0, 1.0)
        self._tempo = TempoFollower(self._fold_hold())
        self._onsets = np.zeros(DENSITY_WINDOW, np.float64)  # the last DENSITY_WINDOW onset strengths, a ring
        self._forecast.reset()
        self._density = 0.0  # their onset density (per s), taken at each code step
        self.playing_member: tuple[int, int] | None = None  # (code, exemplar) of the playing movement; None: decoded
        self._idle.reset()  # no music, fully idle: a stream starts at rest and fades in on music
        if self._feet is not None:
            self._feet.reset()
        self._feet_used = False  # the feet part has stepped since the reset (FEET_IN_PLACE)
        self._idle_fade = IdleFade()  # dance -> idle, following each bone's rotation (models/networks/idle_fade.py)
        self._prev_quat: np.ndarray | None = None
        self.codes_drawn: list[int] = []
        self._lead = self._lead_next  # the lead in frames now (taken up at code steps)
        self._stage.reset()  # the centre of the stage, facing the audience

    @property
    def style(self) -> int:
        """The style token danced (0 auto; models/networks/library_player.py: resolve_style)."""
        return self._chooser.style

    def set_style(self, style: str | None) -> None:
        """Dance this style from the next code on: None/"auto", "chacha", "rumba", "waltz", or a library
        folder (models/networks/library_player.py); ConfigError otherwise."""
        self._chooser.set_style(*resolve_style(self.model, style))
        self._tempo.hold = self._fold_hold()

    def _fold_hold(self) -> float:
        """The tempo fold's hold (:data:`models.networks.tempo.FOLD_HOLD`) under auto; none for a requested
        style or folder, whose dance kept its earlier tempo reading (a requested cha-cha on the waltz songs
        at the held 170 bpm won 2 of 6 by 0.15, 3 or more without: tests/test_style_control_script.py)."""
        return tempo_mod.FOLD_HOLD if self.style == 0 else 0.0

    def set_energy(self, energy: float) -> None:
        """How lively the movements are, from the next code on: 0 (the calmest the music
        allows) .. 1 (as the music asks, the default) .. 2 (the liveliest); ConfigError
        outside :data:`ENERGY_RANGE` or not a number. See :data:`models.networks.chooser.ENERGY_GAIN`
        and :data:`models.networks.player.SPEED_CAP`."""
        lo, hi = ENERGY_RANGE
        e = _real(energy)
        if e is None:
            raise ConfigError(f"energy must be a number in [{lo:g}, {hi:g}] (1: as the music asks), "
                              f"got {energy!r}")
        if not lo <= e <= hi:  # NaN fails too
            raise ConfigError(f"energy must be in [{lo:g}, {hi:g}] (1: as the music asks), got {energy!r}")
        self._chooser.set_energy(e)  # the codes' tilt
        self._player.set_energy(e)  # the speed cap
        self.energy = e

    def set_lead(self, lead_ms: float) -> None:
        """Send the poses ``lead_ms`` (0..200 ms, rounded to whole 30 fps frames) ahead of the
        audio, from the next code step on (see the class docstring, "Lead"); ConfigError
        outside :data:`LEAD_RANGE_MS` or not a number."""
        lo, hi = LEAD_RANGE_MS
        ms = _real(lead_ms)
        if ms is None:
            raise ConfigError(f"lead must be a number of ms in [{lo:g}, {hi:g}], got {lead_ms!r}")
        if not lo <= ms <= hi:  # NaN fails too
            raise ConfigError(f"lead must be in [{lo:g}, {hi:g}] ms, got {lead_ms!r}")
        self._lead_next = int(round(ms * FPS / 1000.0))
        self.lead_ms = ms

    def set_stage(self, stage) -> None:
        """The stage, ``"WxD"`` metres centred on the origin or 0 (in place, facing +Z), from the
        next frame on (models/networks/stage.py); ConfigError on a bad value."""
        self._stage.set_stage(stage)

    def set_facing(self, facing: str) -> None:
        """``"free"`` (turn as the dancers did) or ``"audience"`` (come back to face +Z); ConfigError otherwise."""
        self._stage.set_facing(facing)

    def home(self) -> None:
        """Walk back to the centre of the stage."""
        self._stage.home()

    @property
    def stage(self) -> Stage:
        """The stage part: its size, facing and the performer's place on it (read-only use)."""
        return self._stage

    def _ahead(self, row: np.ndarray) -> np.ndarray:
        """``row`` (D,) with the beat tracker's phase as it will read ``self._lead`` frames on
        (a copy; its clarity as now): :class:`PhaseForecast` on the onsets (and the period it
        reads), or without an onset column (or ``ONSET_FORECAST`` off) ``theta + 2 pi L / period``."""
        ccos, csin, _, logp = self._beat_cols
        x, y, period = float(row[ccos]), float(row[csin]), 15.0 * 2.0 ** float(row[logp])
        out = row.copy()
        if self._onset_col is not None and lead_part.ONSET_FORECAST:
            (a, ahead_logp), r = self._forecast.ahead(self._lead, period), math.hypot(x, y)
            out[ccos], out[csin] = r * math.cos(a), r * math.sin(a)
            if ahead_logp is not None:  # the period the forecast's phase is of (lead.RUNNER_UP)
                out[logp] = ahead_logp
            return out
        a = 2.0 * math.pi * self._lead / period
        c, s = math.cos(a), math.sin(a)
        out[ccos], out[csin] = x * c - y * s, x * s + y * c
        return out

    def set_idle(self, idle: bool) -> None:
        """True: settle into the idle and hold it whatever the music; False: dance to the music again."""
        self._idle.forced_idle = bool(idle)

    @property
    def forced_idle(self) -> bool:
        """The idle is held whatever the music (:meth:`set_idle`)."""
        return self._idle.forced_idle

    @property
    def idle_weight(self) -> float:
        """Current blend towards the idle pose: 0 dancing, 1 idle."""
        return self._idle.w_idle

    @property
    def music_present(self) -> bool:
        return self._idle.music

    @property
    def heard(self) -> str:
        """What the idle gate heard in the last frame: music, silence, quiet or not music (IdleGate.heard)."""
        return self._idle.heard()

    @property
    def beat_phase(self) -> float:
        """Where the last frame lies between the danced beats, 0..1 (0: on a beat); NaN without a pulse."""
        raw = getattr(self, "_raw", None)
        if self._beat_cols is None or raw is None or float(raw[self._beat_cols[2]]) <= 0.0:
            return math.nan
        theta, _ = danced_phase(*(float(raw[j]) for j in (self._beat_cols[0], self._beat_cols[1], self._beat_cols[3])),
                                self._tempo.period)
        return (theta / (2.0 * math.pi)) % 1.0

    @property
    def tempo_bpm(self) -> float:
        """The tempo the performer follows (beats per minute, in the danced range), 0 before a clear pulse."""
        period = self._tempo.period
        return 60.0 * FPS / period if period > 0.0 else 0.0

    @property
    def tempo_input(self) -> float:
        """What a predictor that hears the tempo (``DanceVQConfig.tempo_input``) is given: ln(T / T_ref),
        T the followed tempo, T_ref the memory's, within ln :data:`models.networks.player.RATE_RANGE` and faded
        to 0 as the pulse fades, as the playback rate is (:meth:`Player.asked_rate`); 0 without a tempo."""
        return math.log(self._player.asked_rate(self._tempo))

    @property
    def playback_rate(self) -> float:
        """Exemplar frames a frame the current movement ends at (1: its own pace; tempo following)."""
        return self._player.rate

    @property
    def movement_speed(self) -> float:
        """The current movement's exemplar's own mean joint speed (m/s at its own pace; 0 before
        the first, or for a decoded movement): what the choice of movement, not the tempo, sets."""
        return self._player.own_speed * FPS

    # -- generation ----------------------------------------------------------------------------
    def listen(self, features: np.ndarray) -> np.ndarray:
        """Run only the idle gate on feature frames (k, D), no poses: the idle weight after each
        frame (k,), as :attr:`idle_weight` reads after :meth:`push` of the same frames (the gate
        reads the features alone). For measuring the gate on long recordings."""
        x = np.asarray(features, np.float32)
        out = np.empty(len(x))
        for i in range(len(x)):
            out[i] = self._idle.step(x[i])
        return out


    def _next_code(self) -> None:
        """A code step: the chooser draws the next code; where the playing exemplar is due to hand over,
        the drawn codes' exemplars (:meth:`Chooser.candidates`) are matched to the motion so far and placed
        on the beat (one compiled call, :func:`~models.networks.dance_jit.match_exemplar`), and the player
        plays the best, bent to continue the motion, at its rate (:meth:`Player.rate_for`)."""
        chooser, player, handover, tempo = self._chooser, self._player, self._handover, self._tempo
        heard = self.tempo_input if chooser.predictor.tempo is not None else 0.0  # a predictor that hears the tempo
        draws, tilt = chooser.draw(tempo, self.codes_drawn, heard)
        if int(self._counts[draws[0]]) == 0:  # no exemplars (members = 0): the decoder writes the movement
            segment = chooser.decoded(draws[0])
            window = np.concatenate([segment, np.repeat(segment[-1:], self.seg, axis=0)])
            shift = handover.base + player.advance(self.seg) - self.seg  # the rows the last movement moved on
            self._stage.handover(shift, None, not self.codes_drawn)  # in place
            ahead = self._ahead_for(shift + self.seg, 0)  # no continuation to play into: its own pace, no contacts
            player.play(window, 1.0, shift=shift, ahead=ahead[0] if ahead is not None else None,
                        first=not self.codes_drawn)
            handover.handed(self.seg, shift + self.seg)
            self.playing_member = None
            player.own_speed = 0.0
            self.rate_split = (1.0, 1.0)
            self._commit(draws[0])
            player.has_cont = False
            return
        chooser.follow_folder(draws[0], not player.has_cont or self.idle_weight >= 1.0, tilt)
        reached = handover.base + player.advance(self.seg)  # the row the playing movement has got to
        d = handover.due(reached, self.seg * player.rate, player.has_cont)
        if d is None:  # the playing exemplar has not played its own frames: it plays on (handover.py)
            player.hold()
            self._commit(draws[0])
            return
        codes = list(dict.fromkeys(draws))
        # a library (guard > 0): the next drawn code's exemplars join only where the best so far would
        # bend the motion past the guard, and where none of the drawn codes' does, the nearest of any code's
        tries = [codes[:n] for n in range(1, len(codes) + 1)] + [None] if chooser.guard > 0.0 else [codes]
        pairs, cands, dips, z = chooser.candidates(chooser.pairs(tries[0]), self._stage)
        asked = player.asked_rate(tempo)  # the rate the followed tempo asks now, before each exemplar's speed cap
        ahead = self._ahead_for(reached, d)  # what _read_ahead read on the frame before, if it is this step's
        if not player.has_cont:  # the first movement starts from its own pose
            i = 0
            best = _unit(cands[0].copy())
        else:  # motion matching among the drawn codes' exemplars, placed on the beat (one compiled call)
            c0 = pairs[0]
            beat = player.next_beat(self._raw, tempo, player.rate_for(*c0, tempo, asked), d)
            frame, clarity = beat if beat is not None else (-1, 0.0)
            at = reached + d  # where the playing movement hands over
            cont = ahead[1] if ahead is not None else player.next_two(at)
            for k, use in enumerate(tries):
                if k:
                    pairs, cands, dips, z = chooser.candidates(chooser.pairs(use) if use else chooser.nearest(cont[0]),
                                                               self._stage)
                bias = np.zeros(len(pairs)) if z is None else z * max(tilt, 0.0)  # livelier ones at a faster tempo
                i, best = match_exemplar(cands, dips, cont, player.decay, frame, chooser_part.BEAT_WEIGHT * clarity,
                                         self.seg, player_part.VEL_CAP, bias)  # its quaternions are unit already
                if k + 1 == len(tries) or bend_deg(cands[i, 0], cont[0]) <= chooser.guard:
                    break
        rate = player.rate_for(*pairs[i], tempo, asked)
        self.rate_split = (asked, rate)  # what the speed matching and the bone cap start from
        if player.has_cont:  # the speed the bend adds or takes away, undone (SPEED_MATCH)
            rate = player.speed_matched(cands[i], best, rate)
        self._stage.handover(reached - self.seg, self._travel[pairs[i]], not self.codes_drawn, self.seg + d)
        self.playing_member = pairs[i]
        player.play(best, rate, player.bone_limit(best, max(rate, player.rate)), self._contacts[pairs[i]],
                    reached - self.seg, d, ahead[0] if ahead is not None else None, first=not self.codes_drawn)
        handover.handed(self.seg + d, reached + d)
        player.own_speed = float(self._member_speed[pairs[i]])
        self._commit(pairs[i][0])
        player.has_cont = True

    def _commit(self, code: int) -> None:
        """Record ``code`` as played (the player has started its movement, or holds)."""
        self._chooser.commit(code)
        self.codes_drawn.append(code)
        if len(self.codes_drawn) > CODES_KEPT + CODES_TRIM:  # bounded history (CODES_KEPT)
            del self.codes_drawn[:CODES_TRIM]

    def _read_ahead(self) -> None:
        """On the frame before a code step (after its own read): what the coming handover reads of
        the playing movement and of the stage, which no frame changes until then
        (:meth:`Player.read_ahead`, :meth:`Stage.read_ahead`). Only for a handover at once."""
        reached = self._player.reached()
        self._stage.read_ahead(reached - self.seg, self.seg)
        self._player.read_ahead(self.frame + 1, reached)

    def _ahead_for(self, reached: float, d: int) -> tuple | None:
        """What :meth:`_read_ahead` read for this code step's handover at ``reached`` (``d`` 0), else None."""
        return self._player.ahead_for(self.frame, reached, d)

    def push(self, features: np.ndarray) -> np.ndarray:
        """Consume k >= 0 feature frames (k, D); return their k poses (k, POSE_DIM) float32: each frame
        through the idle gate, the tempo follower, the chooser (a code step every ``seg`` frames,
        :meth:`_next_code`; its pieces ahead between them), the player, the idle fade, the stage and the feet."""
        x = np.asarray(features, np.float32)
        if x.ndim != 2 or x.shape[1] != self.feature_dim:
            raise ConfigError(f"features must have shape (frames, {self.feature_dim}) for this model, got {x.shape}")
        clean = np.empty(x.shape, np.float32)
        self.nonfinite_frames += sanitize_rows(x, clean, FEATURE_LIMIT)  # sanitize_features' values, one call
        x = clean
        k = len(x)
        out = np.empty((k, self.pose_dim), np.float32)
        player = self._player
        hear, think, warped = self._chooser.hear, self._chooser.think, player.warped  # the parts' per-frame steps
        for i in range(k):
            t = self.frame
            if t % self.seg == 0:
                self._lead = self._lead_next  # a new lead starts with a movement
            if self._onset_col is not None:
                self._forecast.push(float(x[i, self._onset_col]))
            row = self._ahead(x[i]) if self._lead and self._beat_cols is not None else x[i]
            j = t % self.seg
            hear(row, j)  # the chooser's context: the row's first columns, standardised
            self._raw = row
            if self._beat_cols is not None:  # the tempo (the period is the same ahead or not)
                if self._onset_col is not None:
                    self._onsets[t % DENSITY_WINDOW] = x[i, self._onset_col]
                    if t % self.seg == 0:  # the window up to t, in time order
                        n = (t + 1) % DENSITY_WINDOW
                        self._density = onset_density(self._onsets[:n] if t < DENSITY_WINDOW else
                                                      np.concatenate((self._onsets[n:], self._onsets[:n])))
                self._tempo.update(float(x[i, self._beat_cols[3]]), float(x[i, self._beat_cols[2]]), self._density)
            if t % self.seg == 0:
                self._next_code()
            else:  # this frame's share of the next code step's pieces ahead
                think(j)
            pose = warped(j, row, self._tempo)  # the player's pose of the movement playing
            w = self._idle.step(x[i])
            e = 0.0
            if w <= 0.0:
                self._idle_fade.reset()
            else:
                e = w * w * (3 - 2 * w)  # smoothstep: no kink where the fade starts or ends
                pose = self._idle_fade(pose, self._sway(np.array([t]))[0], e)
            self._stage.step(pose, player.at, e)  # travel and turns, inside the stage (models/networks/stage.py)
            if self._feet is not None:  # the last step: planted feet stay put (models/networks/feet.py)
                mode = "hold" if self._stage.active and self._travels else FEET_IN_PLACE
                if mode == "hold":
                    left, right, lift = player.contact_at(player.at)  # the idle stands on both feet
                    pose = self._feet.step(pose, left + e * (1.0 - left), right + e * (1.0 - right),
                                           lift + e * (self._idle_lift - lift))
                    self._feet_used = True
                elif mode == "floor" or self._feet_used:  # knees and floor; what was held is handed back
                    pose = self._feet.step(pose, 0.0, 0.0, 0.0)
                    self._feet_used = True
            out[i] = pose
            if (t + 1) % self.seg == 0 and self.codes_drawn:  # the next frame is a code step
                self._read_ahead()
            self.frame += 1
        if k == 0:
            return out
        out = _renorm_frame(out[0], self._prev_quat)[None] if k == 1 else \
            blend_track(out[None], np.ones((1, k)), self._prev_quat)
        self._prev_quat = out[-1, 3:].reshape(-1, 4).copy()
        return out


def generate(model: DanceVQ, features: np.ndarray, seed: int = 0, style: str | None = None,
             energy: float = 1.0, lead: float = 0.0, stage=0, facing: str = "free") -> np.ndarray:
    """Poses (T, P) float32 for features (T, D) at 30 fps: a fresh stream's frames, all at once
    (``seed``, ``style``, ``energy``, ``lead`` in ms, ``stage``, ``facing``: as :class:`DanceStream` takes them)."""
    return DanceStream(model, seed=seed, style=style, energy=energy, lead_ms=lead, stage=stage,
                       facing=facing).push(features)
