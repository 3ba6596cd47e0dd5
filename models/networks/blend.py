"""Rotation-aware blending of overlapping generator windows, and a seam measure.

Poses are flat ``(…, POSE_DIM)`` vectors (root xyz in metres, then xyzw quaternions,
see :mod:`models.rig.motion`), at 30 fps.

Windows of ``window`` frames start every ``hop`` frames (at 0, hop, 2*hop, …). Window k
is kept in slot ``k % n_slots`` (``n_slots = ceil(window / hop)``), so at any frame
each slot holds at most one covering window. A window's weight at age a (frames since
its start) is a raised-cosine crossfade: it rises from ~0 over the first
``window - hop`` frames (a fresh window has no context yet) and falls to ~0 over the
last ``window - hop`` frames; for ``window = 2 * hop`` the two covering windows'
weights sum to exactly 1.

Blending (nlerp): every quaternion is sign-aligned to a reference candidate's
(the first covering slot), weighted-summed, renormalised; root positions are the
weighted mean. The blended track is then made sign-continuous over time
(:func:`align_sequence`), so q and -q never alternate between frames.
"""

from __future__ import annotations

import math

import numpy as np

from models.errors import DataError
from models.timebase import FPS

IDENTITY = np.array([0.0, 0.0, 0.0, 1.0], dtype=np.float32)


def _ramp(a: np.ndarray, length: int) -> np.ndarray:
    """Raised cosine from ~0 at a = 0 to 1 at a >= length; 1 everywhere if length == 0."""
    if length <= 0:
        return np.ones_like(a, dtype=np.float64)
    x = np.clip((a + 1.0) / (length + 1.0), 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * x)


def crossfade_weights(window: int, hop: int) -> np.ndarray:
    """(window,) float64 weight of a window at ages 0..window-1; all > 0."""
    a = np.arange(window, dtype=np.float64)
    overlap = window - hop
    return _ramp(a, overlap) * _ramp(window - 1 - a, overlap)


def num_slots(window: int, hop: int) -> int:
    """Windows that can cover one frame: ceil(window / hop)."""
    return math.ceil(window / hop)


def slot_weights(frames: np.ndarray, window: int, hop: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-slot window index and crossfade weight at the given frames.

    Returns ``(index, weight)``, each (n_slots, len(frames)): index[j, i] is the window
    in slot j at frame ``frames[i]`` (its start is ``index * hop``; -1 if none has
    started), weight is 0 where that window does not cover the frame.
    """
    frames = np.asarray(frames, dtype=np.int64)
    n = num_slots(window, hop)
    newest = frames // hop
    j = np.arange(n)[:, None]
    index = newest[None, :] - (newest[None, :] - j) % n
    age = frames[None, :] - index * hop
    covered = (index >= 0) & (age < window)
    w = np.where(covered, crossfade_weights(window, hop)[np.clip(age, 0, window - 1)], 0.0)
    return np.where(index >= 0, index, -1), w


def sanitize_quaternions(q: np.ndarray, eps: float = 1e-8) -> np.ndarray:
    """Unit quaternions (…, 4); non-finite or near-zero ones become the identity."""
    q = np.asarray(q)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    ok = np.isfinite(n) & (n > eps)
    return np.where(ok, q / np.where(ok, n, 1.0), IDENTITY.astype(q.dtype))


def blend_poses(poses: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """nlerp-blend K candidate pose tracks: poses (K, N, P), weights (K, N) -> (N, P).

    Weights need not be normalised; each frame needs one positive weight. The
    reference for sign alignment is, per frame, the first candidate (along K) with
    positive weight; for two candidates another choice only flips the result's sign,
    which :func:`align_sequence` then makes continuous.
    """
    k, n, p = poses.shape
    w = weights.astype(np.float64)
    total = w.sum(axis=0)
    ref = np.argmax(w > 0, axis=0)  # first positive candidate per frame
    q = poses[..., 3:].reshape(k, n, -1, 4).astype(np.float64)
    q_ref = q[ref, np.arange(n)]  # (N, J, 4)
    sign = np.where(np.einsum("knjc,njc->knj", q, q_ref) < 0.0, -1.0, 1.0)
    qs = np.einsum("kn,knj,knjc->njc", w, sign, q)
    root = np.einsum("kn,knc->nc", w, poses[..., :3].astype(np.float64)) / total[:, None]
    out = np.concatenate([root, sanitize_quaternions(qs).reshape(n, -1)], axis=1)
    return out.astype(poses.dtype)


def align_sequence(q: np.ndarray, prev: np.ndarray | None = None) -> np.ndarray:
    """Flip signs so consecutive quaternions have non-negative dot: q (T, J, 4) -> (T, J, 4).

    ``prev`` (J, 4) is the frame before q[0] (already aligned), for continuing a stream.
    Equivalent to aligning frame by frame: sign_t = prod_{i<=t} sign(q_i . q_{i-1}).
    """
    if len(q) == 0:
        return q.copy()
    before = q[:-1] if prev is None else np.concatenate([prev[None], q[:-1]])
    dots = np.einsum("tjc,tjc->tj", q[1:] if prev is None else q, before)
    s = np.where(dots < 0.0, -1.0, 1.0)
    if prev is None:
        s = np.concatenate([np.ones((1, q.shape[1])), s])
    return q * np.cumprod(s, axis=0)[..., None].astype(q.dtype)


def blend_track(poses: np.ndarray, weights: np.ndarray, prev_quat: np.ndarray | None = None) -> np.ndarray:
    """:func:`blend_poses` then :func:`align_sequence`; the engine's output for N frames (N, P).

    One frame (N = 1, every push of the live stream) goes through :func:`blend_frame`,
    the same blend without the frame-axis bookkeeping.
    """
    if poses.shape[1] == 1:
        return blend_frame(poses[:, 0], weights[:, 0], prev_quat)[None]
    out = blend_poses(poses, weights)
    n = out.shape[0]
    q = align_sequence(out[:, 3:].reshape(n, -1, 4), prev_quat)
    out[:, 3:] = q.reshape(n, -1)
    out[:, :3] = np.nan_to_num(out[:, :3], nan=0.0, posinf=0.0, neginf=0.0)
    return out


def blend_frame(poses: np.ndarray, weights: np.ndarray, prev_quat: np.ndarray | None = None) -> np.ndarray:
    """One frame of :func:`blend_track`: poses (K, P), weights (K,) -> (P,), in the poses' dtype.

    The engine's streaming generator emits one frame per push, and for one frame the
    general path spends most of its time on array bookkeeping for the frame axis (about
    35 NumPy calls). This is the same nlerp (sign-aligned to the first positive-weight
    candidate, weighted sum, renormalised, non-finite or near-zero quaternions become the
    identity, then sign-aligned to ``prev_quat`` (J, 4) if given; root = weighted mean,
    non-finite -> 0) in about 15 calls, computed in the poses' dtype instead of float64:
    for float32 poses it agrees with the many-frame path to float32 rounding
    (tests/test_networks_blend.py).
    """
    w = np.asarray(weights, dtype=poses.dtype)
    q = poses[:, 3:].reshape(len(poses), -1, 4)
    ref = q[int(np.argmax(w > 0))]
    sw = np.where(np.einsum("kjc,jc->kj", q, ref) < 0.0, -w[:, None], w[:, None])
    qs = np.einsum("kj,kjc->jc", sw, q)
    norm = np.sqrt(np.einsum("jc,jc->j", qs, qs))
    if np.isfinite(norm).all() and norm.min() > 1e-8:
        qs /= norm[:, None]
    else:  # a candidate produced NaN or cancelling quaternions: the general path
        qs = sanitize_quaternions(qs.astype(np.float64)).astype(poses.dtype)
    if prev_quat is not None:
        qs[np.einsum("jc,jc->j", qs, prev_quat) < 0.0] *= -1.0
    out = np.empty(poses.shape[1], dtype=poses.dtype)
    out[:3] = (w @ poses[:, :3]) / w.sum()
    if not np.isfinite(out[:3]).all():
        out[:3] = np.nan_to_num(out[:3], nan=0.0, posinf=0.0, neginf=0.0)
    out[3:] = qs.ravel()
    return out


def angular_acceleration(poses: np.ndarray, fps: float = FPS) -> np.ndarray:
    """Per-frame mean angular acceleration magnitude over bones, rad/s^2: (T, P) -> (T,).

    Angular velocity at frame t is the rotation vector of q_{t-1}^-1 q_t times fps
    (scipy); acceleration at t is |w_{t+1} - w_t| * fps. Frames 0 and T-1 are NaN.
    """
    from scipy.spatial.transform import Rotation

    t = poses.shape[0]
    q = poses[:, 3:].reshape(t, -1, 4).astype(np.float64)
    j = q.shape[1]
    out = np.full(t, np.nan)
    if t < 3:
        return out
    r_prev = Rotation.from_quat(q[:-1].reshape(-1, 4))
    r_next = Rotation.from_quat(q[1:].reshape(-1, 4))
    omega = (r_prev.inv() * r_next).as_rotvec().reshape(t - 1, j, 3) * fps  # omega[i]: frames i -> i+1
    acc = np.linalg.norm(omega[1:] - omega[:-1], axis=-1) * fps  # (T-2, J), centred on frames 1..T-2
    out[1:-1] = acc.mean(axis=1)
    return out


def seam_frames(num_frames: int, window: int, hop: int, radius: int = 2) -> np.ndarray:
    """Boolean (T,) mask of frames within ``radius`` of a window start or end (frame 0 excluded)."""
    edges = set()
    for s in range(0, num_frames, hop):
        edges.update((s, s + window))
    mask = np.zeros(num_frames, dtype=bool)
    for e in edges:
        if 0 < e < num_frames:
            mask[max(0, e - radius) : e + radius + 1] = True
    return mask


def seam_ratio(poses: np.ndarray, window: int, hop: int, radius: int = 2, fps: float = FPS) -> float:
    """Mean angular acceleration near window boundaries / elsewhere, for poses (T, P).

    ~1 means the boundaries are invisible; a blending seam makes it large. Frames
    within ``radius`` of a window start or end count as "near".
    """
    acc = angular_acceleration(poses, fps)
    near = seam_frames(len(poses), window, hop, radius)
    valid = np.isfinite(acc)
    a_near, a_far = acc[near & valid], acc[~near & valid]
    if a_near.size == 0 or a_far.size == 0:
        raise DataError(f"seam_ratio needs frames both near and away from window boundaries; got T={len(poses)}, hop={hop}")
    return float(a_near.mean() / max(a_far.mean(), 1e-12))
