"""The dancing performer, live: :class:`DanceStream` runs a ``dance_vq`` model frame by frame.

The engine's contract (:class:`realtime.engine.PoseModel`): ``push(features (k, D)) ->
poses (k, POSE_DIM)``, one pose per feature frame at once, 30 fps, no look-ahead.

Every ``seg`` frames (frame ``t = seg * k``) the stream appends audio token ``k`` to its
window of the last ``window_codes`` tokens (128 frames), asks the code predictor for the
next code, draws it from the stream's own seeded generator, and plays one of that code's
real exemplars (the choreographic memory), matched to the motion so far (at once, or with
:data:`models.networks.handover.ON_FRAMES` once the playing exemplar has played its own ``seg``
recorded frames); the frames in between read it out. (A code without exemplars would have
its ``seg`` poses decoded from the last ``decoder_context`` codes; the shipped memory has
exemplars for every code.)

**At the music's tempo.** A movement's exemplar is read at ``r`` of its frames a frame,
``r`` the music's tempo (:class:`models.networks.tempo.TempoFollower`) over the memory's
mean tempo (:data:`FOLLOW_TEMPO`), and the faster the tempo, the livelier the movements
drawn (:data:`TEMPO_ENERGY`). The memory is read through a light low-pass
(:data:`MEMBER_SMOOTH`), so a sped-up movement does not speed up its mocap noise.

:func:`generate` pushes a whole song through a fresh stream, so offline and
live give the same poses for the same seed and style, however the frames are chunked.

**On the beat.** The decided movement is played back through a beat warp: slower into
every beat the causal beat tracker expects, faster between them (:data:`BEAT_WARP`), read
between frames about :data:`WARP_LAG` frames late, so its speed dips land on the beats.

**Idle between songs.** The idle gate (:class:`models.networks.idle_gate.IdleGate`) decides
whether music is playing (its presence detector, :mod:`models.networks.music_gate`, or an older
checkpoint's logistic one) and holds through a song's breaks of up to 2 s; without music the
performer fades into a calm idle (the dancers' mean pose with a slow sway of hips, spine and
head, :mod:`models.networks.idle_fade`) and back into the dance, which has kept running underneath, so nothing
jumps. ``set_idle(True)`` holds the idle whatever the music (the show control's ``/performer/idle``).
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from models.errors import ConfigError
from models.networks.blend import blend_track
from models.networks.dance_jit import (joint_speed, match_exemplar, push_history, renorm_pose,
                                       sanitize_rows, warp_pose)
from models.networks.dance_numpy import NumpyPredictor, Prefix, single_thread_blas
from models.networks.dance_vq import DanceVQ
from models.networks import feet as feet_part
from models.networks.feet import FeetLock
from models.networks.handover import Handover
from models.networks.stage import SpotStage, Stage, cached_travel
from models.networks.idle_fade import IdleFade, IdleSway
from models.networks.idle_gate import ABSENT_FRAMES, FADE_FRAMES, PRESENT_FRAMES, IdleGate
from models.networks import lead as lead_part
from models.networks.lead import PhaseForecast
from models.networks.library_folders import folder_choice
from models.networks.library_player import NEAREST, STYLE_BASE, bend_deg, member_choice, resolve_style
from models.networks.member_tables import (CHUNK_FRAMES, MemberTables, code_energy, code_frequency, member_dips,  # noqa: F401
                                          member_positions, member_speed, member_tables)
from models.networks.streaming import FEATURE_LIMIT
from models.networks import tempo as tempo_mod
from models.networks.tempo import DENSITY_WINDOW, TEMPO_RANGE, TempoFollower, danced_beat, onset_density
from models.rig.kinematics import rotation_jumps_deg
from models.rig.skeleton import POINT_PARENT_INDEX, load_default_skeleton
from models.timebase import FPS

#: Frames over which a new movement's difference from the last one decays (inertialization), at 8 frames a code.
DECAY_FRAMES: int = 16
#: Largest angular-velocity mismatch (per bone, radians per frame: 23 degrees) that the
#: inertialization carries into a new movement (models/networks/dance_jit.py: match_exemplar).
VEL_CAP: float = 0.4
#: Codes drawn from the predictor at each step; the exemplar of theirs that best continues the
#: motion and dips in speed where the beat tracker expects the next beat is played.
DRAWS: int = 1
#: Weight of a speed dip on the expected beat against the continuity cost (median-normalised).
BEAT_WEIGHT: float = 1.0
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
#: Quantile of the exemplars' mean joint speeds that no movement is sped up past (a movement
#: already faster plays at rate 1 at most). Above energy 1 (:meth:`DanceStream.set_energy`)
#: the quantile rises with the energy, to the memory's fastest exemplar at 2: at a fast
#: tempo the capped livelier movements would otherwise play no faster than energy 1's. Above
#: the memory's tempo it rises with the tempo too (:data:`SPEED_CAP_TEMPO`).
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
#: Classifier-free guidance of a requested style (Ho & Salimans 2021): the logits move from
#: the music-only ones ("auto") past the style-conditioned ones by this factor. The predictor
#: was trained with the style token dropped to "auto" 40 % of the time, which is what it needs.
#: It costs a second prefix (the window in "auto"); cha-cha wins 15 of the 30 validation
#: song-seeds with it, 11 at 1.0 (benchmarks/studies/style_control.py --guidance; docs/training.md).
STYLE_GUIDANCE: float = 3.0
#: Weight of the style prior (``DanceVQ.style_prior``: how much likelier each code is in the
#: requested style's training dances) added to a requested style's logits.
STYLE_PRIOR: float = 3.0
#: With a requested style, play only exemplars from that style's dancers where the drawn
#: code has any (``DanceVQ.member_style``; a code without: all of its exemplars).
STYLE_MEMBERS: bool = True
#: The energy control (:meth:`DanceStream.set_energy`, 0..2, 1 = as the music asks): the code
#: logits move by ``ENERGY_GAIN * (energy - 1) * z``, z each code's movement speed
#: (:func:`code_energy`; above 1 plus :data:`TEMPO_FREQ` times its quickness, as the tempo's
#: tilt reads it, so that at a fast tempo 2 stays livelier than 1), so energy 0 favours the
#: calmest movements and 2 the liveliest
#: (benchmarks/studies/energy_control.py: the validation dances' motion energy 0.51x, 0.97x and 1.56x
#: the dancers' at 0, 1 and 2, rising from 0 to 1 to 2 on every song; docs/show.md, "Energy").
ENERGY_GAIN: float = 3.0
#: Tempo and liveliness: the code logits also move by ``TEMPO_ENERGY * ln(T / T_ref) * z`` (T the
#: followed tempo, T_ref the memory's, z :func:`code_energy` plus :data:`TEMPO_FREQ` times
#: :func:`code_frequency`), blended out as the pulse fades
#: like the rate: at a faster tempo livelier movements, at a slower one calmer ones, as the
#: dancers chose (over the memory's exemplars, their own speed grows with the tempo of the song
#: they were danced to: as its 0.64th power, correlation 0.25). Without it the choice of
#: movement ignores the tempo and only the playback rate follows it; the speed caps hold the
#: rate back at fast tempos (docs/history-listening.md, "Listening": stretch-set speed ratio 1.24 at 0,
#: 1.42 at 4 with :data:`SPEED_CAP_TEMPO`). Away from energy 1 (:meth:`DanceStream.set_energy`)
#: it shrinks, to nothing at 0 and at 2: the show's energy setting takes over (at full
#: strength energy 0 moved as much as energy 1 on DANCE_R_5, and energy 2 less than 1 on
#: DANCE_C_2). 0: the choice ignores the tempo.
TEMPO_ENERGY: float = 4.0
#: The same tilt for a predictor that hears the tempo itself (``DanceVQConfig.tempo_input``,
#: models/training/tempo_predictor.py), which chooses by the tempo as the dancers did at it.
TEMPO_ENERGY_HEARD: float = 0.0
#: Tempo and frequency: the tempo's logit tilt (:data:`TEMPO_ENERGY`) reads each code's liveliness
#: plus this times its movements' frequency (:func:`code_frequency`'s z-score: mean joint
#: acceleration over mean joint speed, the root's travel taken out). At a faster tempo the
#: performer then picks quicker movements, not only livelier ones, so the motion's frequency
#: follows the tempo and not only its speed; at a slower one broader, slower ones. With
#: :data:`SPEED_MATCH` and without it, the stretch set's frequency centroid ratio (1.25x over
#: 0.8x, seeds 0-5) was 1.25; with it 1.30 (docs/history.md, "Speed matching and quicker movements").
#: 0: the tilt reads liveliness only.
TEMPO_FREQ: float = 1.0
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
#: Gaussian sigma (frames) of the low-pass each exemplar window of the memory is read through
#: (:func:`_cached_members`; per track, then renormalised): the mocap's frame-to-frame noise,
#: which a movement sped up by the tempo rate r turns into jerk as r cubed, is taken out
#: (dance-scale motion, up to 2 Hz, keeps 87 % or more of its amplitude). 0: as recorded.
MEMBER_SMOOTH: float = 1.25
#: Repeats: a code drawn n >= :data:`REPEAT_FREE` times among the last :data:`REPEAT_WINDOW`
#: draws has its logit lowered by ``REPEAT_PENALTY * (n - REPEAT_FREE + 1)`` (a 5th time in
#: 8 draws 1 lower, a 6th 2, ...). Without it the predictor, its window (16 codes) full of
#: one code, kept drawing it: runs of up to 27 movements (7 s), where the dancers' longest
#: is 22 and 0.5 % of their movements are in runs of 12 or more (4.2 % of the performer's).
#: Each repeat restarts a movement of that kind near where the last one started and the
#: inertialization cancels most of it: the performer shuffles in place, at under half the
#: speed of the movements it plays, in loud music (1.4 % of the dancing frames on the listening
#: recordings and validation songs, DANCE_W_5 5.4 %; benchmarks/studies/repeats.py). A run
#: broken by one other code (354 354 354 139 354 354 354) shuffles as much, hence a window,
#: not only a run. Calm codes repeat freely: the penalty is scaled by ``z + REPEAT_CALM``
#: within [0, 1], z each code's liveliness (:func:`code_energy`'s z-score): none at z <= -1,
#: full at z >= 0. Holding still is no shuffle, and at energy 0 (only the calmest codes
#: drawn) the penalty moved the calm performer between still poses: DANCE_W_5 at energy 0
#: moved more than at 1 (1.64 against 1.47, benchmarks/studies/energy_control.py).
#: REPEAT_PENALTY 0: no limit.
REPEAT_FREE: int = 4
REPEAT_WINDOW: int = 8
REPEAT_PENALTY: float = 1.0
REPEAT_CALM: float = 1.0
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
#: The next code step's pieces ahead (:class:`~models.networks.dance_numpy.Prefix`: 7 for the
#: 3-layer predictor, in order the attention block of layer 0, its feed-forward's two halves, the
#: same for layer 1, layer 2's keys and values) done by the end of frame j of an 8-frame cycle,
#: in sevenths of them (rounded up; a prefix of other length takes the same shares): one on
#: frames 1, 2 and 7, two on 3 and 5, none on the code step, on frame 4 (the code step of a
#: performer staggered by half a cycle) and on 6. 4 staggered performers (phases 0, 2, 4, 6) put
#: every code step on an even hop and every lane at an odd position on the odd hops, which also
#: carry the handover's reads (frame 7): layer 0's first feed-forward half (the costliest piece
#: but one) on frame 2 and nothing on 6 make an even hop (a code step, frame 2) cost what an odd
#: one does, within 0.03 ms of CPU (p50; two pieces on frame 1, one on 2 and 6: 0.04 the other
#: way; layer 1's second half on 6 too: 0.12; benchmarks/studies/lane_parts.py, docs/latency.md),
#: and one performer's or two's costliest frame but the code step is lighter than with two pieces
#: on frame 1. Which frame computes a piece changes no value.
PIECES_BY_8: tuple[int, ...] = (0, 1, 2, 4, 4, 6, 6, 7)
#: Steps of the tempo's speed-cap table (:data:`SPEED_CAP_TEMPO`).
_CAP_STEPS = 64


def hermite_decay(frames: int) -> np.ndarray:
    """Cubic Hermite weights (2, frames) that carry an offset and its velocity (per frame) to
    zero over ``frames`` frames: ``offset(j) = w[0, j] x0 + w[1, j] v0``, with zero value and
    slope at j = frames."""
    s = np.arange(frames) / frames
    return np.stack([2 * s**3 - 3 * s**2 + 1, frames * (s**3 - 2 * s**2 + s)]).astype(np.float32)


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
    """The :data:`BONE_CAP` quantile (degrees a frame) of every exemplar frame's largest bone
    rotation (:func:`models.rig.kinematics.rotation_jumps_deg`) in ``model``'s memory (inf
    without exemplars), kept on the model like :func:`_cached_members`."""
    key = (_members_key(model), BONE_CAP)
    cached = getattr(model, "_bone_cap_cache", None)
    if cached is None or cached[0] != key:
        steps = [rotation_jumps_deg(w[:, 3:].reshape(len(w), -1, 4)).max(axis=1)
                 for k, n in enumerate(counts) for w in members[k, :n]]  # no copy of the real windows
        cached = (key, float(np.quantile(np.concatenate(steps), BONE_CAP)) if steps else np.inf)
        model._bone_cap_cache = cached
    return cached[1]


def reference_period(model: DanceVQ) -> float:
    """The memory's mean tempo T_ref as a beat period (frames at 30 fps): the geometric mean of its
    exemplars' songs' periods (``DanceVQ.member_period``; 0 where none is known)."""
    period = model.member_period.numpy().astype(np.float64)  # (K, M) each exemplar's song; 0 unknown
    real = np.arange(period.shape[1])[None, :] < model.member_count.numpy()[:, None]
    known = period[real & (period > 0)]
    return float(np.exp(np.log(known).mean())) if len(known) else 0.0


def tempo_inputs(model: DanceVQ, features: np.ndarray) -> np.ndarray:
    """(T,) float32: what :attr:`DanceStream.tempo_input` reads after each frame of a fresh stream fed
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


class DanceStream:
    """Frame-by-frame generation with a :class:`DanceVQ` (see the module docstring).

    seed: the sampling generator's seed (``reset`` restarts it). style: None/"auto"
    (the music decides), "chacha", "rumba" or "waltz"; ``set_style`` changes it from the
    next code (within 267 ms). energy: 0..2, 1 = as the music asks; ``set_energy`` changes
    it the same way. lead_ms: 0..200, the display chain's delay the poses are sent ahead of
    (``set_lead``, from the next code step on). ``codes_drawn``: the codes drawn, one a code
    step, oldest first (the newest :data:`CODES_KEPT` of a long stream; with
    ``handover.ON_FRAMES`` a step that holds draws one that is not played).

    **Lead.** With a lead of L frames (``round(lead_ms * 30 / 1000)``, 0..6) the pose sent
    at audio frame t is the one the performer takes at t + L: every beat-tracker phase
    the stream reads (the predictor's audio tokens, the beat placement of the next
    movement, the beat warp) is the tracker's own forecast for L frames on, phase and period
    (models/networks/lead.py); the rest of each frame is the audio heard so far. A
    movement played from audio frame t (shown at t + L) is so decided with audio up to L
    frames before it is seen, and its speed dips aim at the beats expected at t + L.
    The code steps stay on frames ``t % seg == 0`` whatever the lead, so an ensemble's
    stagger and the prefix schedule (``_pieces_by``) are those of lead 0.
    """

    def __init__(self, model: DanceVQ, seed: int = 0, style: str | None = None, energy: float = 1.0,
                 lead_ms: float = 0.0, feet: bool | None = None, stage=0, facing: str = "free",
                 spot: tuple[int, int] | None = None) -> None:
        if not isinstance(model, DanceVQ):
            raise ConfigError(f"DanceStream needs a dance_vq model, got {type(model).__name__}")
        self.model = model.eval()
        c = model.config
        self._predictor = _cached_predictor(model)  # the torch predictor's logits, in NumPy (dance_numpy)
        self._chooser = getattr(model, "code_chooser", None)  # (hist, period) -> logits (K,), or the predictor's
        self.seg, self.pose_dim = c.seg, c.pose_dim
        self.feature_dim = c.input_dim  # columns push() takes: the predictor's, + the gate's steadiness column
        self._fd = c.feature_dim  # the predictor's columns, the first of each row
        self.seed = int(seed)
        self.style, self._pstyle = resolve_style(model, style)  # exemplars' token, predictor's (library_player)
        self._feat_mean = model.feat_mean.numpy().astype(np.float32)
        self._feat_std = model.feat_std.numpy().astype(np.float32)
        self._idle = IdleGate(model, self._feat_mean, self._feat_std)  # music present or not, the idle weight
        self._members = _cached_members(model)  # (K, M, 2 seg, P), shared: never written
        self._counts = model.member_count.numpy()
        self._style_prior = model.style_prior.numpy().astype(np.float32)  # (K, 4)
        self._member_style = model.member_style.numpy()  # (K, M): 0 unknown, else a style token
        self._dips = _cached_dips(model, self._members, self.seg)  # (K, M, seg)
        # feet on the floor (models/networks/feet.py): each exemplar frame's contacts, played along
        self._contacts, floor = _cached_contacts(model, self._members)  # (K, M, 2 seg, 3): contacts, lift (m)
        self._feet = FeetLock(floor) if (FEET_LOCK if feet is None else feet) else None
        self._code_energy, speed = _cached_energy(model, self._members, self.seg)  # (K,) z-scores, (K, M) m/frame
        real = np.arange(speed.shape[1])[None, :] < self._counts[:, None]
        # how fast a movement may be sped up to (m/frame), and the memory's mean tempo (frames per beat)
        self._speeds = speed[real]  # every exemplar's mean joint speed (m/frame): the speed cap's quantiles
        self._speed_cap = self._speed_cap_at(1.0)
        # the speed cap at each step of the tempo's rise above T_ref (SPEED_CAP_TEMPO): quantiles
        # SPEED_CAP .. 1 of the exemplars' speeds, looked up, not computed, on the audio path
        self._tempo_caps = (np.quantile(self._speeds, np.linspace(SPEED_CAP, 1.0, _CAP_STEPS + 1))
                            if len(self._speeds) else np.full(_CAP_STEPS + 1, np.inf))
        self._bone_cap = _cached_bone_cap(model, self._members, self._counts)  # degrees a frame
        self._member_speed = speed
        # what the tempo's tilt reads (TEMPO_ENERGY, TEMPO_FREQ): liveliness and quickness
        self._tempo_z = (self._code_energy + np.float32(TEMPO_FREQ) * _cached_frequency(model, self._members)
                         if TEMPO_FREQ != 0.0 else self._code_energy)
        # a library (library_player): codes drawn a step, the bend that draws the next, the tempo's tilt by exemplar
        self._draws, self._guard, self._member_tilt = member_choice(model, speed, real, DRAWS)
        where = np.argwhere(real)  # (n, 2) every exemplar's (code, slot); its first pose's quaternions (n, 4 J)
        self._first = (self._members[:, :, 0, 3:][real], where) if self._guard > 0.0 else None
        tok = self._member_style[where[:, 0], where[:, 1]]  # the same by member style token: a folder's own search
        self._first_of = {int(t): (self._first[0][tok == t], where[tok == t]) for t in np.unique(tok)} if self._first else {}
        self._folders = folder_choice(model, speed, real)  # under auto, the library folder the drawn codes choose; None: any
        self._fk_parents = np.array(POINT_PARENT_INDEX, np.int64)  # joint_speed's skeleton (SPEED_MATCH)
        self._fk_offsets = load_default_skeleton().point_offsets().astype(np.float64)
        # how much a repeat of each code is penalised (REPEAT_PENALTY): calm codes repeat freely
        self._repeat_weight = np.clip(self._code_energy + REPEAT_CALM, 0.0, 1.0).astype(np.float32)
        self._ref_period = reference_period(model)
        self.energy = 1.0
        self._energy_bias: np.ndarray | None = None  # ENERGY_GAIN * (energy - 1) * z; None at 1
        self.set_energy(energy)
        self.lead_ms = 0.0
        self._lead_next = 0  # lead in frames from the next code step on (set_lead)
        self.set_lead(lead_ms)
        # travel and turns on the stage (models/networks/stage.py): each exemplar's, played along
        self._travel = cached_travel(model, MEMBER_SMOOTH)  # (K, M, 2 seg, 3), shared: never written
        # spot (i, n): performer i of an ensemble of n, on its own part of the stage (SpotStage)
        self._stage = Stage(self.seg, stage, facing) if spot is None else SpotStage(self.seg, stage, facing, spot)
        self._travels = bool(self._travel.any())  # a memory without travel dances in place on any stage
        cc = c.clarity_col
        self._beat_cols = (cc - 2, cc - 1, cc, cc + 1) if 0 <= cc and cc + 1 < c.feature_dim else None
        self._onset_col = c.onset_col if 0 <= c.onset_col < c.feature_dim else None
        self._forecast = PhaseForecast()  # the lead's beat forecast (models/networks/lead.py), fed the onsets
        self._decay = hermite_decay(DECAY_FRAMES * self.seg // 8)  # (2, D): match_exemplar's
        self._handover = Handover(self.seg)  # when the playing exemplar hands over (models/networks/handover.py)
        # Frames of the cycle the next code step's prefix (its pieces ahead) is computed on: all but
        # the code step and the frame half a cycle from it, where the code step of a performer
        # staggered by half a cycle falls (an ensemble of 2 or 4: realtime.engine's stagger).
        # _pieces_by[j] / _pieces_den: the share of a prefix's pieces done by the end of frame j.
        # seg 8 (PIECES_BY_8): levelled for 4 staggered performers, whose code steps all fall on
        # even hops (frame 6 left free too); else spread evenly over those frames.
        skip = {0, self.seg // 2} if self.seg > 2 else {0}
        if self.seg == 8:
            self._pieces_by, self._pieces_den = PIECES_BY_8, PIECES_BY_8[-1]
        else:
            self._pieces_by = tuple(sum(1 for i in range(1, j + 1) if i not in skip) for j in range(self.seg))
            self._pieces_den = max(self._pieces_by[-1], 1)
        base = getattr(model, "idle_base", None)  # a library's own mean pose (library_player), else the dancers'
        base = model.destandardize_poses(model.pose_mean * 0) if base is None else base  # unit quaternions
        self._idle_base = base.numpy().astype(np.float32)
        self._sway = IdleSway(self._idle_base)
        self._idle_lift = self._feet.lift_of(self._idle_base) if self._feet is not None else 0.0
        self.reset()

    # -- controls ----------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget all history: the next pushed frame is frame 0 of a new stream (same seed)."""
        c = self.model.config
        self.rng = np.random.default_rng(self.seed)
        self.frame = 0
        self.nonfinite_frames = 0
        self._hist = np.zeros((self.seg, self._fd), np.float32)
        # the coming token's audio MLP first layer, summed a frame at a time (its bias + _embed_rows frames)
        self._embed_acc = self._predictor.embed_start()
        self._embed_rows = 0
        self._tokens: deque[np.ndarray] = deque(maxlen=c.window_codes)  # embedded (audio + previous code)
        self._prefix: Prefix | None = None  # the next code step's window but its last token, computed ahead
        self._prefix_auto: Prefix | None = None  # the same with the "auto" style, while a style is guided
        self._codes: deque[int] = deque(maxlen=c.decoder_context)
        self._last = c.codebook  # "no code yet"
        # what plays: seg frames before the current movement (up to seg more while the last exemplar
        # plays out its frames: handover.py), then its exemplar's window (the movement and its
        # continuation, bent to continue the motion), read at row base + rate * j - lag of frame j
        self._played = np.zeros((4 * self.seg, self.pose_dim), np.float32)
        self._rate = 1.0  # exemplar frames per frame at the end of the current movement (tempo following)
        self._own_speed = 0.0  # the current movement's exemplar's own mean joint speed, m/frame (0: none)
        self._rate_from = 1.0  # ... and at its start
        # the last movement handed to's rate as the tempo asked it (_asked_rate) and under the speed cap
        # (_rate_for), before the speed matching and the bone cap: where the tempo's rate goes (a study's figure)
        self.rate_split: tuple[float, float] = (1.0, 1.0)
        self._tempo = TempoFollower(self._fold_hold())
        self._onsets = np.zeros(DENSITY_WINDOW, np.float64)  # the last DENSITY_WINDOW onset strengths, a ring
        self._forecast.reset()
        self._density = 0.0  # their onset density (per s), taken at each code step
        self._lag = WARP_LAG  # exemplar frames the beat warp plays behind the movement
        self._has_cont = False  # the playing movement has a real continuation to match the next one to
        self._own = 0  # member style token the exemplars are kept to under auto (self._folders); 0 any
        if self._folders is not None:
            self._folders.reset()
        self.playing_member: tuple[int, int] | None = None  # (code, exemplar) of the playing movement; None: decoded
        self._idle.reset()  # no music, fully idle: a stream starts at rest and fades in on music
        self._played_contact = np.zeros((4 * self.seg, 3), np.float32)  # each foot's contact and the lift, as _played
        self._handover.reset()
        self._at = float(self.seg)  # where in _played the last frame was read
        self._rows_ahead: tuple | None = None  # what the next handover reads of the playing movement (_read_ahead)
        if self._feet is not None:
            self._feet.reset()
        self._feet_used = False  # the feet part has stepped since the reset (FEET_IN_PLACE)
        self._idle_fade = IdleFade()  # dance -> idle, following each bone's rotation (models/networks/idle_fade.py)
        self._prev_quat: np.ndarray | None = None
        self.codes_drawn: list[int] = []
        self._lead = self._lead_next  # the lead in frames now (taken up at code steps)
        self._stage.reset()  # the centre of the stage, facing the audience

    def set_style(self, style: str | None) -> None:
        """Dance this style from the next code on: None/"auto", "chacha", "rumba", "waltz", or a library
        folder (models/networks/library_player.py); ConfigError otherwise."""
        self.style, self._pstyle = resolve_style(self.model, style)
        self._tempo.hold = self._fold_hold()

    def _fold_hold(self) -> float:
        """The tempo fold's hold (:data:`models.networks.tempo.FOLD_HOLD`) under auto; none for a requested
        style or folder, whose dance kept its earlier tempo reading (a requested cha-cha on the waltz songs
        at the held 170 bpm won 2 of 6 by 0.15, 3 or more without: tests/test_style_control_script.py)."""
        return tempo_mod.FOLD_HOLD if self.style == 0 else 0.0

    def set_energy(self, energy: float) -> None:
        """How lively the movements are, from the next code on: 0 (the calmest the music
        allows) .. 1 (as the music asks, the default) .. 2 (the liveliest); ConfigError
        outside :data:`ENERGY_RANGE` or not a number. See :data:`ENERGY_GAIN` and :data:`SPEED_CAP`."""
        lo, hi = ENERGY_RANGE
        try:
            e = float(energy)
        except (TypeError, ValueError):
            raise ConfigError(f"energy must be a number in [{lo:g}, {hi:g}] (1: as the music asks), "
                              f"got {energy!r}") from None
        if not lo <= e <= hi:  # NaN fails too
            raise ConfigError(f"energy must be in [{lo:g}, {hi:g}] (1: as the music asks), got {energy!r}")
        # above 1 livelier and quicker (what the tempo's tilt asks for at a fast tempo, so energy 2
        # stays above energy 1 there), below 1 calmer
        z = self._tempo_z if e > 1.0 else self._code_energy
        self._energy_bias = None if e == 1.0 else (ENERGY_GAIN * (e - 1.0) * z).astype(np.float32)
        self._speed_cap = self._speed_cap_at(e)
        self.energy = e

    def _speed_cap_at(self, energy: float) -> float:
        """The speed (m/frame) no movement is sped up past at ``energy``: the memory's
        :data:`SPEED_CAP` quantile up to energy 1, rising linearly to its fastest exemplar at 2
        (inf without exemplars)."""
        if not len(self._speeds):
            return np.inf
        q = SPEED_CAP + (1.0 - SPEED_CAP) * min(1.0, max(0.0, energy - 1.0))
        return float(np.quantile(self._speeds, q))

    def set_lead(self, lead_ms: float) -> None:
        """Send the poses ``lead_ms`` (0..200 ms, rounded to whole 30 fps frames) ahead of the
        audio, from the next code step on (see the class docstring, "Lead"); ConfigError
        outside :data:`LEAD_RANGE_MS` or not a number."""
        lo, hi = LEAD_RANGE_MS
        try:
            ms = float(lead_ms)
        except (TypeError, ValueError):
            raise ConfigError(f"lead must be a number of ms in [{lo:g}, {hi:g}], got {lead_ms!r}") from None
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
        theta, _ = self._danced_phase(*(float(raw[j]) for j in (self._beat_cols[0], self._beat_cols[1],
                                                                 self._beat_cols[3])))
        return (theta / (2.0 * math.pi)) % 1.0

    @property
    def tempo_bpm(self) -> float:
        """The tempo the performer follows (beats per minute, in the danced range), 0 before a clear pulse."""
        period = self._tempo.period
        return 60.0 * FPS / period if period > 0.0 else 0.0

    @property
    def tempo_input(self) -> float:
        """What a predictor that hears the tempo (``DanceVQConfig.tempo_input``) is given: ln(T / T_ref),
        T the followed tempo, T_ref the memory's, within ln :data:`RATE_RANGE` and faded to 0 as the
        pulse fades, as the playback rate is (:meth:`_asked_rate`); 0 without a tempo."""
        return math.log(self._asked_rate())

    @property
    def playback_rate(self) -> float:
        """Exemplar frames a frame the current movement ends at (1: its own pace; tempo following)."""
        return self._rate

    @property
    def movement_speed(self) -> float:
        """The current movement's exemplar's own mean joint speed (m/s at its own pace; 0 before
        the first, or for a decoded movement): what the choice of movement, not the tempo, sets."""
        return self._own_speed * FPS

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
        m, pred = self.model, self._predictor
        guided = bool(self._pstyle) and STYLE_GUIDANCE != 1.0
        if self._embed_rows == self.seg - 1:  # its first seg - 1 frames were added as they came
            token = pred.embed_last(self._embed_acc, self._hist[-1], self._last)
        else:  # the stream's first token
            token = pred.embed(self._hist.reshape(-1), self._last)
        self._embed_rows = 0
        if pred.tempo is not None:  # a predictor that hears the tempo (DanceVQConfig.tempo_input)
            token = pred.with_tempo(token, self.tempo_input)
        prefix = self._prefix
        if prefix is None or prefix.style != self._pstyle:  # the first step, or the style changed since
            prefix = Prefix(pred, list(self._tokens), self._pstyle)
        auto = (self._prefix_auto if self._prefix_auto is not None else Prefix(pred, list(self._tokens), 0)) \
            if guided else None
        if prefix.done and (auto is None or auto.done) and self._chooser is None:  # the new rows: compiled, no BLAS
            logits = self._logits(token, prefix, auto)
        else:  # a window's pieces not computed ahead, or a library's chooser: BLAS products
            with single_thread_blas():
                logits = self._logits(token, prefix, auto)
        if self.style and STYLE_PRIOR != 0.0:  # codes the requested style's dancers use
            logits = logits + STYLE_PRIOR * self._style_prior[:, self.style]
        bias = self._energy_bias  # read once: the control thread may swap it
        if bias is not None:  # livelier or calmer codes (set_energy)
            logits = logits + bias
        tilt = self._tempo_tilt()
        if tilt != 0.0:  # livelier codes at a faster tempo, calmer at a slower one (TEMPO_ENERGY)
            logits = logits + np.float32(tilt) * self._tempo_z
        if REPEAT_PENALTY > 0.0 and len(self.codes_drawn) >= REPEAT_FREE:
            logits = self._repeat_penalty(logits)
        self._tokens.append(token)
        # the next step's window but its newest token is known now: its layers run on the frames between
        nxt = list(self._tokens)[-(pred.window - 1):]
        self._prefix = Prefix(pred, nxt, self._pstyle)
        self._prefix_auto = Prefix(pred, nxt, 0) if guided else None
        draws = [m.sample(logits, self.rng) for _ in range(self._draws)]
        if int(self._counts[draws[0]]) == 0:  # no exemplars (members = 0): the decoder writes the movement
            self._codes.append(draws[0])  # the decoder reads the new code
            segment = m.decode_last(np.fromiter(self._codes, np.int64))
            self._codes.pop()
            window = np.concatenate([segment, np.repeat(segment[-1:], self.seg, axis=0)])
            shift = self._handover.base + self._advance(self.seg) - self.seg  # the rows the last movement moved on
            self._stage.handover(shift, None, not self.codes_drawn)  # in place
            ahead = self._ahead_for(shift + self.seg, 0)  # no continuation to play into: its own pace, no contacts
            self._play(window, 1.0, shift=shift, ahead=ahead[0] if ahead is not None else None)
            self._handover.handed(self.seg, shift + self.seg)
            self.playing_member = None
            self._own_speed = 0.0
            self.rate_split = (1.0, 1.0)
            self._commit(draws[0])
            self._has_cont = False
            return
        if self._folders is not None and self.style:  # a requested folder plays: auto takes over from it
            self._folders.follow(self.style - STYLE_BASE)
        elif self._folders is not None:  # the folder the drawn code chooses, at once where no dance is seen
            self._own = STYLE_BASE + self._folders.step(draws[0], not self._has_cont or self.idle_weight >= 1.0, tilt)
        reached = self._handover.base + self._advance(self.seg)  # the row the playing movement has got to
        d = self._handover.due(reached, self.seg * self._rate, self._has_cont)
        if d is None:  # the playing exemplar has not played its own frames: it plays on (handover.py)
            self._handover.hold(self._advance(self.seg))
            self._rate_from = self._rate
            self._commit(draws[0])
            return
        codes = list(dict.fromkeys(draws))
        # a library (self._guard > 0): the next drawn code's exemplars join only where the best so far would
        # bend the motion past the guard, and where none of the drawn codes' does, the nearest of any code's
        tries = [codes[:n] for n in range(1, len(codes) + 1)] + [None] if self._guard > 0.0 else [codes]
        pairs, cands, dips, z = self._candidates(self._pairs(tries[0]))
        asked = self._asked_rate()  # the rate the followed tempo asks now, before each exemplar's speed cap
        ahead = self._ahead_for(reached, d)  # what _read_ahead read on the frame before, if it is this step's
        if not self._has_cont:  # the first movement starts from its own pose
            i = 0
            best = _unit(cands[0].copy())
        else:  # motion matching among the drawn codes' exemplars, placed on the beat (one compiled call)
            c0 = pairs[0]
            beat = self._next_beat(self._rate_for(*c0, asked), d)
            frame, clarity = beat if beat is not None else (-1, 0.0)
            at = reached + d  # where the playing movement hands over
            cont = ahead[1] if ahead is not None else self._next_two(at)
            for k, use in enumerate(tries):
                if k:
                    pairs, cands, dips, z = self._candidates(self._pairs(use) if use else self._nearest(cont[0]))
                bias = np.zeros(len(pairs)) if z is None else z * max(tilt, 0.0)  # livelier ones at a faster tempo
                i, best = match_exemplar(cands, dips, cont, self._decay, frame, BEAT_WEIGHT * clarity,
                                         self.seg, VEL_CAP, bias)  # match_exemplar's quaternions are unit already
                if k + 1 == len(tries) or bend_deg(cands[i, 0], cont[0]) <= self._guard:
                    break
        rate = self._rate_for(*pairs[i], asked)
        self.rate_split = (asked, rate)  # what the speed matching and the bone cap start from
        if self._has_cont and SPEED_MATCH > 0.0:  # the speed the bend adds or takes away, undone
            rate = self._speed_matched(cands[i], best, rate)
        self._stage.handover(reached - self.seg, self._travel[pairs[i]], not self.codes_drawn, self.seg + d)
        self.playing_member = pairs[i]
        self._play(best, rate, self._bone_limit(best, max(rate, self._rate)), self._contacts[pairs[i]],
                   reached - self.seg, d, ahead[0] if ahead is not None else None)
        self._handover.handed(self.seg + d, reached + d)
        self._own_speed = float(self._member_speed[pairs[i]])
        self._commit(pairs[i][0])
        self._has_cont = True

    def _logits(self, token: np.ndarray, prefix: Prefix, auto: Prefix | None) -> np.ndarray:
        """The predictor's logits (K,) of the window ``prefix`` + ``token``, guided away from ``auto``'s
        (the same window in "auto": classifier-free guidance; None: unguided), or a library's chooser's."""
        pred = self._predictor
        logits = pred.logits_after(prefix, token)
        if auto is not None:  # classifier-free guidance towards the requested style
            base = pred.logits_after(auto, token)
            logits = base + STYLE_GUIDANCE * (logits - base)
        if self._chooser is not None:  # library_player chooser="match": the music's descriptors choose
            logits = self._chooser(self._hist, self._tempo.period)
        return logits

    def _pairs(self, codes: list[int]) -> list[tuple[int, int]]:
        """(code, exemplar) of every exemplar of ``codes``."""
        return [(c, j) for c in codes for j in range(int(self._counts[c]))]

    def _nearest(self, pose: np.ndarray) -> list[tuple[int, int]]:
        """(code, exemplar) of the :data:`~models.networks.library_player.NEAREST` exemplars of any code (of the
        requested style's) whose first pose is nearest ``pose`` (P,) (mean over the bones of sqrt(1 - |q . q'|))."""
        tok = self.style or self._own  # a requested style (or auto's folder): its own exemplars, where it has any
        first, where = self._first_of.get(tok, self._first) if tok and STYLE_MEMBERS else self._first  # (n, 4 J), (n, 2)
        q = pose[3:].reshape(-1, 4)
        block = np.zeros((q.size, len(q)), np.float32)  # each bone's quaternion in its own column: one matmul
        block[np.arange(q.size), np.repeat(np.arange(len(q)), 4)] = q.ravel()
        with single_thread_blas():
            dot = first @ block  # (n, J)
        d = np.sqrt(np.maximum(1.0 - np.abs(dot), 0.0)).mean(1)
        k = min(NEAREST, len(d))
        return [(int(where[n, 0]), int(where[n, 1])) for n in np.argpartition(d, k - 1)[:k]]

    def _candidates(self, pairs: list[tuple[int, int]]) -> tuple[list, np.ndarray, np.ndarray, np.ndarray | None]:
        """(pairs (code, exemplar), their windows (n, 2 seg, P), dips (n, seg), liveliness weights (n,)
        or None) of ``pairs`` as the style and the stage allow."""
        tok = self.style or self._own
        if tok and STYLE_MEMBERS:  # a requested style (or auto's folder): its own exemplars where the codes have some
            own = [(c, j) for c, j in pairs if self._member_style[c, j] == tok]
            pairs = own or pairs
        if self._travels:  # near an edge: exemplars whose own travel heads inwards (stage.INWARDS)
            keep = self._stage.inwards([(float(self._travel[c, j, self.seg, 0]), float(self._travel[c, j, self.seg, 1]))
                                        for c, j in pairs])
            pairs = pairs if keep is None else [p for p, k in zip(pairs, keep) if k]
        tilt = self._member_tilt
        c, a = pairs[0] if pairs else (-1, 0)
        if pairs == [(c, j) for j in range(a, a + len(pairs))]:  # a run of one code's (a folder's): a slice, no gathering
            b = a + len(pairs)
            return pairs, self._members[c, a:b], self._dips[c, a:b], None if tilt is None else tilt[c, a:b]
        return (pairs, np.stack([self._members[c, j] for c, j in pairs]), np.stack([self._dips[c, j] for c, j in pairs]),
                None if tilt is None else np.array([tilt[p] for p in pairs]))

    def _repeat_penalty(self, logits: np.ndarray) -> np.ndarray:
        """``logits`` (K,) with each code drawn n >= :data:`REPEAT_FREE` times among the last
        :data:`REPEAT_WINDOW` lowered by ``REPEAT_PENALTY * (n - REPEAT_FREE + 1)``, times its
        liveliness weight (:data:`REPEAT_CALM`); a copy where any is lowered. Once per code
        step (every 8 frames)."""
        recent = self.codes_drawn[-REPEAT_WINDOW:]
        out = None
        for c in set(recent):
            n = recent.count(c)
            if n >= REPEAT_FREE:
                out = logits.copy() if out is None else out
                out[c] -= np.float32(REPEAT_PENALTY * (n - REPEAT_FREE + 1) * self._repeat_weight[c])
        return logits if out is None else out

    def _tempo_tilt(self) -> float:
        """:data:`TEMPO_ENERGY` (:data:`TEMPO_ENERGY_HEARD` for a predictor that hears the tempo) times
        ln(T / T_ref), blended to 0 as the pulse fades and as the energy control goes from 1 to 0 or
        to 2 (0 without a tempo)."""
        period = self._tempo.period
        gain = TEMPO_ENERGY if self._predictor.tempo is None else TEMPO_ENERGY_HEARD
        if not FOLLOW_TEMPO or gain == 0.0 or self._ref_period <= 0.0 or period <= 0.0:
            return 0.0
        w = min(1.0, self._tempo.confidence / RATE_CONFIDENCE) * max(0.0, 1.0 - abs(self.energy - 1.0))  # the energy control set away from 1 takes over
        return gain * w * math.log(self._ref_period / period)

    def _asked_rate(self) -> float:
        """The playback rate the followed tempo asks for now, within :data:`RATE_RANGE`, before the
        speed cap (1 without a tempo; towards 1 as the pulse fades)."""
        src = self._ref_period
        period = self._tempo.period
        if not FOLLOW_TEMPO or src <= 0.0 or period <= 0.0:
            return 1.0
        lo, hi = RATE_RANGE
        return min(max(src / period, lo), hi) ** min(1.0, self._tempo.confidence / RATE_CONFIDENCE)

    def _rate_for(self, code: int, member: int, asked: float | None = None) -> float:
        """The playback rate of exemplar ``member`` of ``code`` now (:data:`FOLLOW_TEMPO`): the asked
        rate (``asked``, else :meth:`_asked_rate`; 1 without a tempo) under the speed cap, which
        only slows a rate over 1 (so a rate over 1 implies a followed tempo and a period)."""
        r = self._asked_rate() if asked is None else asked
        if r <= 1.0:
            return r
        v = self._member_speed[code, member]
        return min(r, max(1.0, self._cap_now(self._tempo.period) / v)) if v > 0 else r

    def _speed_matched(self, own: np.ndarray, bent: np.ndarray, rate: float) -> float:
        """``rate`` times ``(v_own / v_bent) ** SPEED_MATCH`` (within :data:`SPEED_MATCH_RANGE`, then
        :data:`RATE_RANGE`): v the mean joint speed of the frames a movement at ``rate`` plays of
        the exemplar window ``own`` (2 seg, P) and of ``bent``, the same bent to continue the motion."""
        n = min(len(bent), int(math.ceil(self.seg * rate)) + 1)
        v_own = joint_speed(own, n, self._fk_parents, self._fk_offsets)
        v_bent = joint_speed(bent, n, self._fk_parents, self._fk_offsets)
        if v_own <= 0.0 or v_bent <= 0.0:
            return rate
        lo, hi = SPEED_MATCH_RANGE
        f = min(max((v_own / v_bent) ** SPEED_MATCH, lo), hi)
        return min(max(rate * f, RATE_RANGE[0]), RATE_RANGE[1])

    def _cap_now(self, period: float) -> float:
        """The speed cap (m/frame) at the followed tempo's ``period`` (frames): the energy's
        (:meth:`_speed_cap_at`) or, above the memory's tempo, the tempo's (:data:`SPEED_CAP_TEMPO`), the higher."""
        cap = self._speed_cap
        if SPEED_CAP_TEMPO and 0.0 < period < self._ref_period:
            top = math.log(self._ref_period * TEMPO_RANGE[1] / (60.0 * FPS))  # ln(170 bpm / T_ref)
            x = min(1.0, math.log(self._ref_period / period) / top) if top > 0.0 else 1.0
            x *= min(1.0, self.energy)  # below energy 1 the cap rises less: energy 0 stays calm at any tempo
            cap = max(cap, float(self._tempo_caps[int(round(x * _CAP_STEPS))]))
        return cap

    def _bone_limit(self, window: np.ndarray, rate: float) -> float:
        """The fastest rate (>= 1) at which no bone of ``window`` (2 seg, P) turns faster than
        :data:`BONE_CAP`'s bound over the frames a movement at ``rate`` plays (inf: no limit)."""
        if not FOLLOW_TEMPO or rate <= 1.0:
            return np.inf
        n = min(len(window), int(math.ceil(self.seg * rate + 2 * WARP_LAG)) + 1)
        q = window[:n, 3:]  # unit quaternions (match_exemplar's, or _unit's): rotation_jumps_deg without its norms
        dot = float(np.abs(np.add.reduce((q[1:] * q[:-1]).reshape(n - 1, -1, 4), axis=-1)).min())
        peak = math.degrees(2.0 * math.acos(min(dot, 1.0)))
        return max(1.0, self._bone_cap / peak) if peak > 0.0 else np.inf

    def _play(self, window: np.ndarray, rate: float, limit: float = np.inf, contact: np.ndarray | None = None,
              shift: float = 0.0, d: int = 0, ahead: tuple | None = None) -> None:
        """Start playing ``window`` (2 seg, P), the next movement and its continuation, at ``rate``
        (and the rate it takes over from the current movement) at most ``limit``: the ``seg + d``
        rows before it are those the current movement would have played next from row ``seg +
        shift`` (``d``: the rows its exemplar plays on to its own frame seg, handover.py).
        ``contact`` (2 seg, 3): its exemplar's foot contacts and lift
        (:func:`models.networks.feet.member_contacts`; None: none known). ``ahead``: those rows,
        contacts and lifts (:meth:`_rows_from`) as :meth:`_read_ahead` read them on the frame before
        (None: read them now)."""
        n, e = self.seg + d, self.seg + d + len(window)  # the window's rows: n .. e
        if not self.codes_drawn:  # before the first movement there is only its first pose
            self._played[:n] = window[0]
            self._played_contact[:n] = contact[0] if contact is not None else 0.0
        else:
            self._played[:n], self._played_contact[:n], lift = ahead if ahead is not None else self._rows_from(shift, n)
        self._played[n:e] = window
        self._played[e:] = window[-1]
        self._played_contact[n:e] = contact if contact is not None else 0.0
        self._played_contact[e:] = self._played_contact[e - 1]
        if self.codes_drawn and self._has_cont and contact is not None:  # bent as the root's height (feet.bend_lift)
            feet_part.bend_lift(self._played_contact[n:e], *lift, self._decay)
        rate = min(rate, limit)
        self._rate_from = min(self._rate, limit) if self.codes_drawn else rate
        self._rate = rate

    def _advance(self, j: int) -> float:
        """Exemplar frames the current movement has played by its frame ``j``: the rate moves
        linearly from ``_rate_from`` (frame 0) towards ``_rate`` (frame seg)."""
        return j * self._rate_from + (self._rate - self._rate_from) * j * (j - 1) / (2 * self.seg)

    def _read_ahead(self) -> None:
        """On the frame before a code step (after its own read): what the coming handover reads of
        the playing movement, which no frame changes until then: the ``seg`` rows before the new
        movement (from row ``reached - seg``: ``_play``'s), their contacts and the two lifts after
        them, the motion's next two poses at ``reached`` (the matching's), and the stage's rows
        (:meth:`Stage.read_ahead`). The code step then only takes them (:meth:`_ahead_for`); the
        values are those it would read itself. Only for a handover at once (``d`` = 0)."""
        reached = self._handover.base + self._advance(self.seg)
        self._stage.read_ahead(reached - self.seg, self.seg)
        self._rows_ahead = (self.frame + 1, reached, self._rows_from(reached - self.seg, self.seg), self._next_two(reached))

    def _ahead_for(self, reached: float, d: int) -> tuple | None:
        """((rows, contacts, lifts) of :meth:`_rows_from`, the next two poses) as :meth:`_read_ahead`
        read them, when that reading is this code step's, at ``reached``, for a handover at once (``d``
        0); else None."""
        ahead = self._rows_ahead
        if ahead is None or d != 0 or ahead[0] != self.frame or ahead[1] != reached:
            return None
        return ahead[2:]

    def _rows_from(self, shift: float, n: int) -> tuple[list, list, tuple[float, float]]:
        """The playing movement's ``n`` rows from row ``shift`` (poses, as warp_pose reads them), their
        contacts and the lifts of the two rows after them: what a handover keeps before the new movement."""
        rows = [warp_pose(self._played, shift + i) for i in range(n)]
        contact = [self._contact_at(shift + i) for i in range(n)]
        return rows, contact, (self._contact_at(shift + n)[2], self._contact_at(shift + n + 1)[2])

    def _next_two(self, at: float) -> np.ndarray:
        """The playing motion's poses (2, P) at rows ``at`` and ``at + 1``: the motion matching's continuation."""
        return np.stack([warp_pose(self._played, at), warp_pose(self._played, at + 1.0)])

    def _commit(self, code: int) -> None:
        """Record ``code`` as played (``self._play`` has started its movement)."""
        self._codes.append(code)
        self._last = code
        self.codes_drawn.append(code)
        if len(self.codes_drawn) > CODES_KEPT + CODES_TRIM:  # bounded history (CODES_KEPT)
            del self.codes_drawn[:CODES_TRIM]

    def _danced_phase(self, ccos: float, csin: float, logp: float) -> tuple[float, float]:
        """(phase in [0, 2 pi), 0 :data:`BEAT_DELAY` frames after a danced beat; the danced period,
        frames) from the beat tracker's columns (``c cos``, ``c sin``, ``log2 P/15``) and the tempo followed."""
        theta, period = danced_beat(math.atan2(csin, ccos) % (2 * math.pi), 15.0 * 2.0 ** logp, self._tempo.period)
        return (theta - 2.0 * math.pi * BEAT_DELAY / period) % (2 * math.pi), period

    def _next_beat(self, rate: float = 1.0, d: int = 0) -> tuple[int, float] | None:
        """(frame of the coming movement's exemplar, 0..seg-1, that plays when the beat tracker
        expects a beat, the movement played at ``rate`` from ``d`` exemplar rows on; its pulse
        clarity), or None when no beat falls in it or the features have no beat columns."""
        if self._beat_cols is None:
            return None
        ccos, csin, clarity, logp = (float(self._raw[j]) for j in self._beat_cols)
        if clarity <= 0.0:
            return None
        theta, period = self._danced_phase(ccos, csin, logp)
        ahead = rate * (period * (1 - theta / (2 * np.pi)) % max(period, 1.0)) - d
        if ahead < -0.5:  # that beat comes before the exemplar starts: the one after it
            ahead += rate * max(period, 1.0)
        ahead = int(round(ahead))
        return (ahead, clarity) if 0 <= ahead < self.seg else None

    def _warped(self, j: int) -> np.ndarray:
        """The pose (P,) of frame ``j`` of the current movement at its tempo rate and under the
        beat warp: row ``base + rate * j - lag`` of ``self._played`` (handover.py), between two
        frames nlerped (``warp_pose``; the lag moves by ``rate * BEAT_WARP * w * cos(theta)`` a frame; see
        :data:`BEAT_WARP`)."""
        x = self._handover.base + self._advance(j)
        if self._beat_cols is None or BEAT_WARP <= 0.0:  # no beat tracker, or no warp: the movement as it is
            self._at = x
            return warp_pose(self._played, x)
        ccos, csin, clarity, logp = (float(self._raw[c]) for c in self._beat_cols)
        depth = BEAT_WARP * min(1.0, max(clarity, 0.0) / WARP_CLARITY)
        theta, _ = self._danced_phase(ccos, csin, logp)  # 0 BEAT_DELAY frames after a danced beat
        cos = math.cos(theta) if clarity > 1e-9 else 0.0
        rate = self._advance(j + 1) - self._advance(j)  # exemplar frames this frame plays
        lag = self._lag + rate * depth * cos - WARP_PULL * (self._lag - WARP_LAG)
        self._lag = min(max(lag, 0.0), 2.0 * WARP_LAG)
        self._at = x - self._lag
        return warp_pose(self._played, self._at)

    def _contact_at(self, x: float) -> tuple[float, float, float]:
        """Each foot's contact (left, right; 0..1) and the exemplar's lift (m) at fractional frame
        ``x`` of ``self._played`` (:func:`models.networks.feet.member_contacts`), linearly between
        two frames (as ``warp_pose`` reads the poses)."""
        c = self._played_contact
        i = min(max(int(math.floor(x)), 0), len(c) - 1)
        f = min(max(x - i, 0.0), 1.0) if i + 1 < len(c) else 0.0
        if f < 1e-6:
            return float(c[i, 0]), float(c[i, 1]), float(c[i, 2])
        a, b = c[i], c[i + 1]
        return (float(a[0] + f * (b[0] - a[0])), float(a[1] + f * (b[1] - a[1])), float(a[2] + f * (b[2] - a[2])))

    def push(self, features: np.ndarray) -> np.ndarray:
        """Consume k >= 0 feature frames (k, D); return their k poses (k, POSE_DIM) float32."""
        x = np.asarray(features, np.float32)
        if x.ndim != 2 or x.shape[1] != self.feature_dim:
            raise ConfigError(f"features must have shape (frames, {self.feature_dim}) for this model, got {x.shape}")
        clean = np.empty(x.shape, np.float32)
        self.nonfinite_frames += sanitize_rows(x, clean, FEATURE_LIMIT)  # sanitize_features' values, one call
        x = clean
        k = len(x)
        out = np.empty((k, self.pose_dim), np.float32)
        for i in range(k):
            t = self.frame
            if t % self.seg == 0:
                self._lead = self._lead_next  # a new lead starts with a movement
            if self._onset_col is not None:
                self._forecast.push(float(x[i, self._onset_col]))
            row = self._ahead(x[i]) if self._lead and self._beat_cols is not None else x[i]
            push_history(self._hist, row, self._feat_mean, self._feat_std)  # its first _fd columns, standardised
            j = t % self.seg
            if j:  # the coming token's first layer, a frame at a time (NumpyPredictor.embed_frame)
                if j == 1:
                    self._embed_acc, self._embed_rows = self._predictor.embed_start(), 0
                if self._embed_rows == j - 1:
                    self._predictor.embed_frame(self._embed_acc, self._hist[-1], j - 1)
                    self._embed_rows = j
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
            elif self._pieces_by[j] > self._pieces_by[j - 1]:  # this frame's share of the pieces ahead
                for pre in (self._prefix, self._prefix_auto):
                    if pre is not None and not pre.done:
                        keep = pre.pieces - -(-pre.pieces * self._pieces_by[j] // self._pieces_den)  # left after it
                        if pre.left > keep:
                            with single_thread_blas():  # (models/networks/dance_numpy.py)
                                while pre.left > keep:
                                    pre.step()
            pose = self._warped(t % self.seg)
            w = self._idle.step(x[i])
            e = 0.0
            if w <= 0.0:
                self._idle_fade.reset()
            else:
                e = w * w * (3 - 2 * w)  # smoothstep: no kink where the fade starts or ends
                pose = self._idle_fade(pose, self._sway(np.array([t]))[0], e)
            self._stage.step(pose, self._at, e)  # travel and turns, inside the stage (models/networks/stage.py)
            if self._feet is not None:  # the last step: planted feet stay put (models/networks/feet.py)
                mode = "hold" if self._stage.active and self._travels else FEET_IN_PLACE
                if mode == "hold":
                    left, right, lift = self._contact_at(self._at)  # the idle stands on both feet
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
