"""What the engine does to a model's pose before it is sent, and the poses it uses.

:class:`PoseSmoother` (the NaN guard and exponential smoothing, one compiled call a frame,
:mod:`realtime.pose_jit`; state: the last smoothed pose), :class:`IdleFader` (the engine's own
idle crossfade for a model without ``set_idle``; state: the blend weight as a frame count), and
:func:`rest_pose` / :func:`idle_pose`. Each lane of the engine (:mod:`realtime.lanes`) owns one
smoother and one fader; both work in place, without allocation.
"""

from __future__ import annotations

import logging

import numpy as np

from models.rig.humanoid import NUM_BONES
from models.rig.motion import POSE_DIM
from realtime.pose_jit import guard_smooth

log = logging.getLogger("realtime.engine")  # the engine's log: these warnings are the engine's


def rest_pose() -> np.ndarray:
    """(POSE_DIM,) float32 T-pose: root at the origin, identity rotations."""
    pose = np.zeros(POSE_DIM, dtype=np.float32)
    pose[6::4] = 1.0  # w of every quaternion (layout: root xyz, then x y z w per bone)
    return pose


def idle_pose() -> np.ndarray:
    """(POSE_DIM,) float32 idle pose of the engine's own idle control: :func:`rest_pose`
    standing up, i.e. identity rotations (the T-pose) with the root (Hips) at the shipped
    rest skeleton's hips position (0, 0.93, 0) m instead of on the floor. Falls back to
    :func:`rest_pose` when that skeleton cannot be read."""
    pose = rest_pose()
    try:
        from models.rig.skeleton import load_default_skeleton

        hips = load_default_skeleton().offsets[0]
    except Exception as exc:  # noqa: BLE001 - a missing asset must not stop the engine
        log.warning("rest skeleton unavailable (%s); the idle pose stands at the origin", exc)
        return pose
    pose[:3] = hips
    return pose


class IdleFader:
    """Crossfades flat poses towards a fixed idle pose and back, in place, no allocation.

    ``idle`` (settable any time, from any thread) is the target: each call moves the
    blend weight ``w`` one step of ``1 / frames`` towards 1 (idle) or 0 (dance), so a
    full fade takes ``frames`` frames (30 = 1 s at 30 fps) and a reversal mid-fade
    continues from where it is. The blend uses ``e = smoothstep(w) = w^2 (3 - 2w)``
    (no jolt at either end; at most ``1.5 / frames`` per frame): the root moves linearly
    ``(1 - e) * root + e * idle_root`` (metres), each quaternion by hemisphere-aligned
    nlerp towards the idle one. At ``w == 0`` the pose is left untouched (bit-exact); at
    ``w == 1`` it becomes the idle pose exactly.
    """

    def __init__(self, idle: np.ndarray, frames: int = 30) -> None:
        idle = np.asarray(idle, dtype=np.float32)
        if idle.shape != (POSE_DIM,) or not np.isfinite(idle).all():
            raise ValueError(f"idle pose must be finite with shape ({POSE_DIM},), got {idle.shape}")
        if frames < 1:
            raise ValueError(f"fade frames must be >= 1, got {frames}")
        self.pose = idle.copy()
        self.frames = int(frames)
        self.idle = False
        self._k = 0  # weight w = _k / frames, an integer count so both ends are exact
        self._tmp = np.zeros(POSE_DIM, dtype=np.float32)
        self._dot = np.zeros(NUM_BONES, dtype=np.float32)
        self._norm = np.zeros(NUM_BONES, dtype=np.float32)

    @property
    def weight(self) -> float:
        """Current blend weight w in [0, 1] (0: the dance as is, 1: the idle pose)."""
        return self._k / self.frames

    @property
    def active(self) -> bool:
        """True while the output is not the dance untouched (idle, or fading back)."""
        return self.idle or self._k > 0

    def __call__(self, pose: np.ndarray) -> np.ndarray:
        """Step the weight, blend ``pose`` ((POSE_DIM,) float32, unit quaternions) in place, return it."""
        if self.idle:
            self._k = min(self._k + 1, self.frames)
        else:
            self._k = max(self._k - 1, 0)
        if self._k == 0:
            return pose
        if self._k == self.frames:
            pose[:] = self.pose
            return pose
        w = self._k / self.frames
        e = w * w * (3.0 - 2.0 * w)
        q = pose[3:].reshape(NUM_BONES, 4)
        np.einsum("ij,ij->i", q, self.pose[3:].reshape(NUM_BONES, 4), out=self._dot)
        q[self._dot < 0] *= -1.0
        pose *= 1.0 - e
        np.multiply(self.pose, e, out=self._tmp)
        pose += self._tmp
        # after the alignment the blend's norm is >= sqrt((1-e)^2 + e^2) >= 0.7: no zero
        np.einsum("ij,ij->i", q, q, out=self._norm)
        np.sqrt(self._norm, out=self._norm)
        q /= self._norm[:, None]
        return pose


class PoseSmoother:
    """Exponential smoothing of flat poses, rotation-aware, in place, no allocation.

    ``alpha`` in [0, 1) is the weight of the previous output (0 = off; the lag is
    about ``alpha / (1 - alpha)`` frames). Quaternions are blended by hemisphere-
    aligned nlerp (the result lies on the shortest arc between the two rotations;
    cheaper than slerp and indistinguishable at per-frame steps). Whether or not it
    smooths, it renormalises every quaternion (a zero one becomes identity). One compiled
    call a frame (:func:`realtime.pose_jit.guard_smooth`, NumPy's float32 arithmetic).
    """

    def __init__(self, alpha: float = 0.0) -> None:
        if not 0.0 <= alpha < 1.0:
            raise ValueError(f"smoothing must be in [0, 1), got {alpha}")
        self.alpha = float(alpha)
        self._state = np.zeros(POSE_DIM, dtype=np.float32)
        self._has_state = False

    def reset(self) -> None:
        self._has_state = False

    def smooth_into(self, row: np.ndarray, pose: np.ndarray) -> bool:
        """``pose`` (POSE_DIM,) float32 = ``row`` (POSE_DIM,) float32 smoothed; False, leaving both
        and the state untouched, when ``row`` is not finite (the engine's guard)."""
        if not guard_smooth(row, pose, self._state, self._has_state, self.alpha):
            return False
        self._has_state = True
        return True

    def __call__(self, pose: np.ndarray) -> np.ndarray:
        """Smooth ``pose`` ((POSE_DIM,) float32, finite) in place and return it."""
        if not self.smooth_into(pose, pose):
            raise ValueError("PoseSmoother needs a finite pose (the engine sends the last good pose instead)")
        return pose
