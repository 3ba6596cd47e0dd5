"""Compiled (numba) kernels for the engine's per-frame pose guard and smoothing.

Each performer's frame passed through about ten small NumPy calls here (the finite
check, a copy, the smoother's einsums, comparisons and division, the state copy), each
5-10 µs on the live path's cold caches; an ensemble pays them once per performer per
hop. :func:`guard_smooth` does the same arithmetic in one call, in float32 and in the
order NumPy computes it (a quaternion's squared norm paired as ``einsum`` adds its four
products), so the poses are those of :class:`realtime.pose_filters.PoseSmoother`'s NumPy code
bit for bit (tests/test_engine.py). ``make setup`` compiles it ahead (realtime/kernels.py).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _normalize(q):  # pragma: no cover - compiled
    """Unit quaternions (J, 4) float32, in place; one of squared norm below 1e-12 becomes identity."""
    for j in range(q.shape[0]):
        n = (q[j, 0] * q[j, 0] + q[j, 1] * q[j, 1]) + (q[j, 2] * q[j, 2] + q[j, 3] * q[j, 3])
        if n < np.float32(1e-12):
            q[j, 0] = q[j, 1] = q[j, 2] = np.float32(0.0)
            q[j, 3] = np.float32(1.0)
            n = np.float32(1.0)
        s = np.float32(math.sqrt(n))
        for k in range(4):
            q[j, k] /= s


@njit(cache=True, nogil=True)
def guard_smooth(row, pose, state, has_state, alpha):  # pragma: no cover - compiled
    """``pose`` (P,) = ``row`` (P,) renormalised and, with ``alpha`` > 0 and ``has_state``,
    blended towards ``state`` (P,) by hemisphere-aligned nlerp (weight ``alpha`` on the state),
    renormalised again; then ``state`` = ``pose``. Returns False, touching nothing, when
    ``row`` holds a non-finite value. All float32; ``pose`` may be ``row`` itself."""
    for c in range(row.shape[0]):
        if not np.isfinite(row[c]):
            return False
    for c in range(row.shape[0]):
        pose[c] = row[c]
    q = pose[3:].reshape(-1, 4)
    _normalize(q)
    if alpha > 0.0 and has_state:
        prev = state[3:].reshape(-1, 4)
        for j in range(q.shape[0]):
            dot = (q[j, 0] * prev[j, 0] + q[j, 1] * prev[j, 1]) + (q[j, 2] * prev[j, 2] + q[j, 3] * prev[j, 3])
            if dot < 0:
                for k in range(4):
                    q[j, k] = -q[j, k]
        keep = np.float32(1.0 - alpha)
        a = np.float32(alpha)
        for c in range(pose.shape[0]):
            pose[c] = pose[c] * keep + a * state[c]
        _normalize(q)
    for c in range(pose.shape[0]):
        state[c] = pose[c]
    return True
