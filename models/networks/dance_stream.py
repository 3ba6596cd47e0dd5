"""The dancing performer, live: :class:`DanceStream` runs a ``dance_vq`` model frame by frame.

The engine's contract (:class:`realtime.engine.PoseModel`): ``push(features (k, D)) ->
poses (k, POSE_DIM)``, one pose per feature frame at once, 30 fps, no look-ahead.

Every ``seg`` frames (frame ``t = seg * k``) the stream appends audio token ``k`` to its
window of the last ``window_codes`` tokens (128 frames), asks the code predictor for the
next code, draws it from the stream's own seeded generator, and decodes that code's
``seg`` poses from the last ``decoder_context`` codes; the frames in between read them
out. :meth:`DanceVQ.generate` pushes a whole song through a fresh stream, so offline and
live give the same poses for the same seed and style, however the frames are chunked.

**Idle between songs.** A gate decides whether music is playing: the log frame energy
must be above a threshold (silence), and a logistic music detector on a 0.5-s running
mean of the spectral shape (MFCC 1-12) and the beat tracker's pulse clarity must say
music (applause, crowd, room noise: energy without music). Both are fitted on the
training songs against synthetic noise (:func:`models.training.dance_vq.fit_music_gate`); after
:data:`ABSENT_FRAMES` frames without music the performer fades over
:data:`FADE_FRAMES` into a calm idle (the dancers' mean pose with a slow sway of hips,
spine and head, :func:`idle_pose`), and after :data:`PRESENT_FRAMES` frames of music it
fades back into the dance, which has kept running underneath, so nothing jumps.
``set_idle(True)`` holds the idle whatever the music (the show control's
``/performer/idle``).
"""

from __future__ import annotations

from collections import deque

import numpy as np
from scipy.spatial.transform import Rotation

from models.errors import ConfigError
from models.networks.blend import blend_track
from models.networks.dance_vq import GATE_MFCC, GATE_TAU, DanceVQ, style_token
from models.networks.streaming import sanitize_features
from models.rig.humanoid import BONE_INDEX
from models.timebase import FPS

#: Frames without music before the performer starts to settle (0.5 s).
ABSENT_FRAMES: int = 15
#: Frames of music before it starts to dance again (0.2 s).
PRESENT_FRAMES: int = 6
#: Frames of the crossfade between dance and idle (0.67 s), eased with a smoothstep.
FADE_FRAMES: int = 20
#: Idle sway: (bone, axis, amplitude in degrees, period in s, phase in rad).
SWAY: tuple[tuple[str, int, float, float, float], ...] = (
    ("Hips", 1, 4.0, 6.0, 0.0),  # a slow turn about the vertical
    ("Spine", 2, 2.5, 4.0, 0.0),  # side to side
    ("Chest", 0, 1.5, 4.0, 1.0),  # breathing-like forward lean
    ("Head", 2, 2.0, 5.0, 2.0),
)


def idle_pose(base: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Idle poses (len(t), P): ``base`` (P,) with the :data:`SWAY` rotations at frame times ``t`` (frames)."""
    out = np.repeat(base[None].astype(np.float64), len(t), axis=0)
    sec = np.asarray(t, np.float64) / FPS
    for bone, axis, deg, period, phase in SWAY:
        i = 3 + 4 * BONE_INDEX[bone]
        vec = np.zeros((len(t), 3))
        vec[:, axis] = np.deg2rad(deg) * np.sin(2 * np.pi * sec / period + phase)
        out[:, i: i + 4] = (Rotation.from_quat(out[:, i: i + 4]) * Rotation.from_rotvec(vec)).as_quat()
    return out.astype(np.float32)


def _nlerp(a: np.ndarray, b: np.ndarray, w: float) -> np.ndarray:
    """Pose a -> b by weight w in [0, 1]: root lerped, every quaternion nlerped on b's hemisphere of a."""
    out = (1 - w) * a + w * b
    qa, qb = a[3:].reshape(-1, 4), b[3:].reshape(-1, 4)
    qb = qb * np.where((qa * qb).sum(1, keepdims=True) < 0, -1.0, 1.0)
    q = (1 - w) * qa + w * qb
    out[3:] = (q / np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-9)).reshape(-1)
    return out


class DanceStream:
    """Frame-by-frame generation with a :class:`DanceVQ` (see the module docstring).

    seed: the sampling generator's seed (``reset`` restarts it). style: None/"auto"
    (the music decides), "chacha", "rumba" or "waltz"; ``set_style`` changes it from the
    next code (within 267 ms).
    """

    def __init__(self, model: DanceVQ, seed: int = 0, style: str | None = None) -> None:
        if not isinstance(model, DanceVQ):
            raise ConfigError(f"DanceStream needs a dance_vq model, got {type(model).__name__}")
        self.model = model.eval()
        c = model.config
        self.seg, self.feature_dim, self.pose_dim = c.seg, c.feature_dim, c.pose_dim
        self.seed = int(seed)
        self.style = style_token(style)
        self._feat_mean = model.feat_mean.numpy().astype(np.float32)
        self._feat_std = model.feat_std.numpy().astype(np.float32)
        self._energy_min, self._gate_b = (float(v) for v in model.gate)
        self._ecol = c.energy_col if 0 <= c.energy_col < c.feature_dim else None
        self._gcols = [*GATE_MFCC, c.clarity_col] if 0 <= c.clarity_col < c.feature_dim else []
        self._gate_w = model.gate_w.numpy().astype(np.float64)[: len(self._gcols)]
        self._gate_mean = self._feat_mean[self._gcols].astype(np.float64)
        self._gate_std = self._feat_std[self._gcols].astype(np.float64)
        self._gate_a = float(np.exp(-1.0 / GATE_TAU))
        base = model.destandardize_poses(model.pose_mean * 0)  # the mean pose, unit quaternions
        self._idle_base = base.numpy().astype(np.float32)
        self.forced_idle = False
        self.reset()

    # -- controls ----------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget all history: the next pushed frame is frame 0 of a new stream (same seed)."""
        c = self.model.config
        self.rng = np.random.default_rng(self.seed)
        self.frame = 0
        self.nonfinite_frames = 0
        self._hist = np.zeros((self.seg, self.feature_dim), np.float32)
        self._tokens: deque[np.ndarray] = deque(maxlen=c.window_codes)
        self._prevs: deque[int] = deque(maxlen=c.window_codes)
        self._codes: deque[int] = deque(maxlen=c.decoder_context)
        self._last = c.codebook  # "no code yet"
        self._segment = np.zeros((self.seg, self.pose_dim), np.float32)
        self._music = False
        self._ema = np.zeros(len(self._gcols))  # the music detector's running mean
        self._run = 0  # frames the gate's input has disagreed with its state
        self._w_idle = 1.0  # 1 = idle, 0 = dancing; a stream starts at rest and fades in on music
        self._prev_quat: np.ndarray | None = None
        self.codes_drawn: list[int] = []

    def set_style(self, style: str | None) -> None:
        """Dance this style from the next code on: None/"auto", "chacha", "rumba", "waltz" (ConfigError otherwise)."""
        self.style = style_token(style)

    def set_idle(self, idle: bool) -> None:
        """True: settle into the idle and hold it whatever the music; False: dance to the music again."""
        self.forced_idle = bool(idle)

    @property
    def idle_weight(self) -> float:
        """Current blend towards the idle pose: 0 dancing, 1 idle."""
        return self._w_idle

    @property
    def music_present(self) -> bool:
        return self._music

    # -- generation ----------------------------------------------------------------------------
    def _gate(self, row: np.ndarray) -> None:
        present = True
        if self._ecol is not None and row[self._ecol] <= self._energy_min:
            present = False
        if self._gcols:  # noise without music: the logistic detector on the running mean
            z = (row[self._gcols] - self._gate_mean) / self._gate_std
            self._ema = self._gate_a * self._ema + (1 - self._gate_a) * z
            if float(self._ema @ self._gate_w) + self._gate_b <= 0.0:
                present = False
        self._run = self._run + 1 if present != self._music else 0
        if self._run >= (PRESENT_FRAMES if present else ABSENT_FRAMES):
            self._music, self._run = present, 0
        target = 1.0 if (self.forced_idle or not self._music) else 0.0
        step = 1.0 / FADE_FRAMES
        self._w_idle = min(target, self._w_idle + step) if target > self._w_idle else max(target, self._w_idle - step)

    def _next_code(self) -> None:
        m = self.model
        self._tokens.append(self._hist.reshape(-1).copy())
        self._prevs.append(self._last)
        logits = m.next_logits(np.stack(self._tokens), np.fromiter(self._prevs, np.int64), self.style)
        code = m.sample(logits, self.rng)
        self._codes.append(code)
        self._last = code
        self.codes_drawn.append(code)
        self._segment = m.decode_last(np.fromiter(self._codes, np.int64))

    def push(self, features: np.ndarray) -> np.ndarray:
        """Consume k >= 0 feature frames (k, D); return their k poses (k, POSE_DIM) float32."""
        x = np.asarray(features)
        if x.ndim != 2 or x.shape[1] != self.feature_dim:
            raise ConfigError(f"features must have shape (frames, {self.feature_dim}) for this model, got {x.shape}")
        x, n_bad = sanitize_features(x)
        self.nonfinite_frames += n_bad
        k = len(x)
        out = np.empty((k, self.pose_dim), np.float32)
        for i in range(k):
            t = self.frame
            self._hist[:-1] = self._hist[1:]
            self._hist[-1] = (x[i] - self._feat_mean) / self._feat_std
            if t % self.seg == 0:
                self._next_code()
            pose = self._segment[t % self.seg]
            self._gate(x[i])
            w = self._w_idle
            if w > 0.0:
                e = w * w * (3 - 2 * w)  # smoothstep: no kink where the fade starts or ends
                pose = _nlerp(pose, idle_pose(self._idle_base, np.array([t]))[0], e)
            out[i] = pose
            self.frame += 1
        if k == 0:
            return out
        out = blend_track(out[None], np.ones((1, k)), self._prev_quat)
        self._prev_quat = out[-1, 3:].reshape(-1, 4).copy()
        return out
