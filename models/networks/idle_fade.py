"""The performer's idle and the fade into it: a calm pose that sways, and each bone turned from
the dance towards it (used by :class:`models.networks.dance_stream.DanceStream`).

The idle is a base pose (the dancers' mean pose, or a library's) with a slow sway of hips, spine,
chest and head (:data:`SWAY`, :class:`IdleSway`). :class:`IdleFade` turns a dance pose towards the
idle by a weight in (0, 1]; its one piece of state is the rotation it followed on the last frame
(``prev``), so a bone that turns far round keeps the arc it started on. Both run on the audio
path while the performer idles or fades (30 fps): NumPy over all bones at once and one compiled
quaternion product, no SciPy ``Rotation`` (0.2-0.5 ms a frame there).
"""

from __future__ import annotations

import math

import numpy as np

from models.networks.dance_jit import qmul_rows
from models.rig.humanoid import BONE_INDEX
from models.timebase import FPS

#: A fade that follows a bone's rotation to the idle the long way round (past 180 degrees,
#: :class:`IdleFade`) goes back to the shorter way when that moves the bone by at most
#: this much (radians: 10 degrees), near the fade's start or end.
FADE_SWITCH: float = math.radians(10.0)
#: Idle sway: (bone, axis, amplitude in degrees, period in s, phase in rad).
SWAY: tuple[tuple[str, int, float, float, float], ...] = (
    ("Hips", 1, 4.0, 6.0, 0.0),  # a slow turn about the vertical
    ("Spine", 2, 2.5, 4.0, 0.0),  # side to side
    ("Chest", 0, 1.5, 4.0, 1.0),  # breathing-like forward lean
    ("Head", 2, 2.0, 5.0, 2.0),
)


class IdleSway:
    """:func:`idle_pose` for one ``base`` pose (P,), with everything that does not depend on time computed once.

    Each swaying bone's rotation is its base rotation composed with a rotation of the
    sway's angle ``a`` about one local axis ``e``: the Hamilton product
    ``q_base * (sin(a/2) e, cos(a/2))``, written out in NumPy for all bones at once
    (float64, the same arithmetic as SciPy's ``Rotation`` composition, which this
    replaces: that took 0.2-0.5 ms a frame while idle).
    """

    def __init__(self, base: np.ndarray) -> None:
        self.base = np.asarray(base, np.float64)
        self.cols = np.array([3 + 4 * BONE_INDEX[b] for b, *_ in SWAY])[:, None] + np.arange(4)  # (B, 4)
        q = self.base[self.cols]
        self.q = q / np.linalg.norm(q, axis=1, keepdims=True)  # (B, 4) unit, as Rotation.from_quat
        self.axis = np.array([a for _, a, *_ in SWAY])
        self.amp = np.deg2rad(np.array([d for _, _, d, _, _ in SWAY]))
        self.period = np.array([p for *_, p, _ in SWAY], np.float64)
        self.phase = np.array([ph for *_, ph in SWAY], np.float64)
        self.onehot = np.eye(3)[self.axis]  # (B, 3)

    def __call__(self, t: np.ndarray) -> np.ndarray:
        """Idle poses (len(t), P) float32 at frame times ``t`` (frames)."""
        sec = np.asarray(t, np.float64)[:, None] / FPS
        half = 0.5 * (self.amp * np.sin(2 * np.pi * sec / self.period + self.phase))  # (T, B)
        s, c = np.sin(half), np.cos(half)
        v = s[..., None] * self.onehot  # (T, B, 3): the sway rotation's vector part
        p, pw = self.q[:, :3], self.q[:, 3]
        cross = np.stack([p[:, 1] * v[..., 2] - p[:, 2] * v[..., 1], p[:, 2] * v[..., 0] - p[:, 0] * v[..., 2],
                          p[:, 0] * v[..., 1] - p[:, 1] * v[..., 0]], axis=-1)
        out = np.repeat(self.base[None], len(sec), axis=0)
        out[:, self.cols[:, :3]] = pw[:, None] * v + c[..., None] * p + cross
        out[:, self.cols[:, 3]] = pw * c - p[np.arange(len(p)), self.axis] * s
        return out.astype(np.float32)


def idle_pose(base: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Idle poses (len(t), P): ``base`` (P,) with the :data:`SWAY` rotations at frame times ``t`` (frames)."""
    return IdleSway(base)(t)


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton products a b of quaternion rows (n, 4) float64, (x, y, z, w) order (SciPy's), for
    :class:`IdleFade`, which runs on the audio path while fading: SciPy's ``Rotation`` took
    0.2-0.5 ms a frame there (see :class:`IdleSway`), NumPy's expression of all rows at once 35 µs,
    one compiled call (:func:`models.networks.dance_jit.qmul_rows`, NumPy's sums bit for bit) 2 µs."""
    return qmul_rows(np.ascontiguousarray(a, np.float64), np.ascontiguousarray(b, np.float64))


def _row_norms(x: np.ndarray, keepdims: bool = False) -> np.ndarray:
    """``np.linalg.norm(x, axis=1, keepdims=keepdims)`` of float64 rows (n, k), the same arithmetic
    (the square root of ``add.reduce`` of the squares) without its Python wrapper: for
    :class:`IdleFade`, which runs on the audio path while fading (7 of them a frame)."""
    return np.sqrt(np.add.reduce(x * x, axis=1, keepdims=keepdims))


def _nlerp(a: np.ndarray, b: np.ndarray, w: float) -> np.ndarray:
    """Pose a -> b by weight w in [0, 1]: root lerped, every quaternion nlerped on b's hemisphere of a."""
    out = (1 - w) * a + w * b
    qa, qb = a[3:].reshape(-1, 4), b[3:].reshape(-1, 4)
    qb = qb * np.where((qa * qb).sum(1, keepdims=True) < 0, -1.0, 1.0)
    q = (1 - w) * qa + w * qb
    out[3:] = (q / np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-9)).reshape(-1)
    return out


class IdleFade:
    """A dance pose turned towards the idle by a weight, frame by frame (see :meth:`__call__`).

    State: ``prev``, the rotation vectors (J, 3) it turned each bone by on the last fading frame
    (None when not fading); :meth:`reset` when the performer is fully dancing again."""

    def __init__(self) -> None:
        self.prev: np.ndarray | None = None

    def reset(self) -> None:
        """Forget the followed rotations: the next fade starts the shorter way round."""
        self.prev = None

    def __call__(self, pose: np.ndarray, idle: np.ndarray, e: float) -> np.ndarray:
        """The dance ``pose`` (P,) -> the ``idle`` pose by weight ``e`` in (0, 1]: the root lerped,
        each bone turned from its dance rotation towards the idle's by ``e`` of the rotation
        between them, ``qa exp(e w)``, where ``w`` (a rotation vector) is that rotation taken
        the shorter way when the fade starts and then followed continuously, however far round
        it goes. Choosing the shorter way anew each frame flips it where the two pass 180
        degrees apart (the head, 99 degrees in a frame, early in a validation dance); blending
        the two quaternions (nlerp) with their signs fixed at the start whips a bone that turns
        back towards the idle (91 degrees, a fade-in of DANCE_W_22), and with their signs put on
        the last output's hemisphere one that passes 90 degrees from it (107 degrees, the soak).
        Followed continuously, a bone turns no faster than the dance plus the fade's own step
        (at most 1.5 / FADE_FRAMES of the rotation between them a frame, a full turn at most);
        near the fade's ends it goes back to the shorter way (:data:`FADE_SWITCH`)."""
        if e >= 1.0:  # fully idle: no fade to follow
            self.prev = None
            return _nlerp(pose, idle, e)
        qa, qb = pose[3:].reshape(-1, 4).astype(np.float64), idle[3:].reshape(-1, 4).astype(np.float64)
        qa = qa / np.maximum(_row_norms(qa, True), 1e-12)
        qb = qb / np.maximum(_row_norms(qb, True), 1e-12)
        rel = _qmul(qa * [-1.0, -1.0, -1.0, 1.0], qb)  # qa^-1 qb
        rel = rel * np.where(rel[:, 3:] < 0, -1.0, 1.0)  # the shorter way: angle <= pi
        vn = _row_norms(rel[:, :3])
        angle = 2.0 * np.arctan2(vn, rel[:, 3])
        axis = rel[:, :3] / np.maximum(vn, 1e-12)[:, None]
        w = angle[:, None] * axis
        if self.prev is not None:  # the same rotation the long way round, where that is nearer the last
            other = w - (2.0 * np.pi) * axis
            far = _row_norms(other - self.prev) < _row_norms(w - self.prev)
            w[far] = other[far]
            if min(e, 1.0 - e) * 2.0 * np.pi <= FADE_SWITCH:  # near either end the shorter way costs a small step
                long = _row_norms(w) > np.pi
                w[long] = (angle[:, None] * axis)[long]
        self.prev = w
        wn = _row_norms(w)
        h = 0.5 * e * wn
        turn = np.concatenate([np.sin(h)[:, None] * (w / np.maximum(wn, 1e-12)[:, None]), np.cos(h)[:, None]], axis=1)
        q = _qmul(qa, turn)
        out = (1 - e) * pose + e * idle
        out[3:] = q.reshape(-1).astype(np.float32)
        return out
