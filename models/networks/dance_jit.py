"""Compiled (numba) kernels for the dance_vq code step's one-row pass.

Why not NumPy here: on the live path the code step runs once every 8 frames, after
11.6 ms of waiting for audio, and every NumPy call then costs 5-10 µs of dispatch with
cold caches, not its arithmetic. The newest token's row through 3 Transformer layers and
the 512-way head is about 90 such calls (0.9 ms paced, docs/latency.md) for 0.7 M
multiply-adds; as one compiled call per layer it is a few tens of µs. numba comes with
librosa already (no new dependency); ``cache=True`` keeps the machine code in
``__pycache__`` so a second start does not compile again (the first compiles in about
a second, inside the engine's warm-up).

Every kernel takes float32 arrays and computes in float32 in the order a reader would
(sums left to right); results agree with the NumPy/BLAS path to float32 rounding
(``tests/test_dance_vq.py``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_SQRT_HALF = math.sqrt(0.5)


@njit(cache=True, nogil=True)
def _layer_norm_row(x, w, b, eps):  # pragma: no cover - compiled
    d = x.shape[0]
    mean = np.float32(0.0)
    for i in range(d):
        mean += x[i]
    mean /= d
    var = np.float32(0.0)
    for i in range(d):
        c = x[i] - mean
        var += c * c
    inv = np.float32(1.0 / math.sqrt(var / d + eps))
    out = np.empty(d, np.float32)
    for i in range(d):
        out[i] = (x[i] - mean) * inv * w[i] + b[i]
    return out


@njit(cache=True, nogil=True)
def _vec_mat(x, w, b):  # pragma: no cover - compiled
    """x (n,) @ w (n, k) + b (k,), as axpy rows (w is row-major: contiguous inner loop)."""
    out = b.copy()
    for i in range(x.shape[0]):
        xi = x[i]
        for j in range(w.shape[1]):
            out[j] += xi * w[i, j]
    return out


@njit(cache=True, nogil=True)
def row_layer(h, kh, vh, m, n1w, n1b, eps1, w_qkv, b_qkv, w_o, b_o, n2w, n2b, eps2, w_1, b_1, w_2, b_2,
              scale):  # pragma: no cover - compiled
    """The newest token's row ``h`` (d,) through one pre-norm Transformer layer (GELU).

    Its key and value go into slot ``m`` of ``kh`` (H, hd, m + 1) and ``vh`` (H, m + 1, hd)
    (the earlier slots hold the window's other tokens); its query attends to all m + 1.
    Returns the new row (d,).
    """
    d = h.shape[0]
    nh = kh.shape[0]
    hd = d // nh
    qkv = _vec_mat(_layer_norm_row(h, n1w, n1b, eps1), w_qkv, b_qkv)
    for a in range(nh):
        for j in range(hd):
            kh[a, j, m] = qkv[d + a * hd + j]
            vh[a, m, j] = qkv[2 * d + a * hd + j]
    att = np.zeros(d, np.float32)
    s = np.empty(m + 1, np.float32)
    for a in range(nh):
        top = np.float32(-np.inf)
        for t in range(m + 1):
            acc = np.float32(0.0)
            for j in range(hd):
                acc += qkv[a * hd + j] * kh[a, j, t]
            s[t] = acc * scale
            top = max(top, s[t])
        total = np.float32(0.0)
        for t in range(m + 1):
            s[t] = np.float32(math.exp(s[t] - top))
            total += s[t]
        for t in range(m + 1):
            p = s[t] / total
            for j in range(hd):
                att[a * hd + j] += p * vh[a, t, j]
    h = h + _vec_mat(att, w_o, b_o)
    u = _vec_mat(_layer_norm_row(h, n2w, n2b, eps2), w_1, b_1)
    for i in range(u.shape[0]):
        u[i] = np.float32(0.5 * u[i] * (1.0 + math.erf(u[i] * _SQRT_HALF)))
    return h + _vec_mat(u, w_2, b_2)


@njit(cache=True, nogil=True)
def head(h, nw, nb, eps, w_head, b_head):  # pragma: no cover - compiled
    """Final layer norm and the code head: row (d,) -> logits (K,)."""
    return _vec_mat(_layer_norm_row(h, nw, nb, eps), w_head, b_head)


@njit(cache=True, nogil=True)
def _unit_rows(p):  # pragma: no cover - compiled
    """Renormalise every quaternion (columns 3.., groups of 4) of poses ``p`` (F, P), in place."""
    for f in range(p.shape[0]):
        for c in range(3, p.shape[1], 4):
            n = np.float32(0.0)
            for k in range(4):
                n += p[f, c + k] * p[f, c + k]
            n = max(np.float32(math.sqrt(n)), np.float32(1e-9))
            for k in range(4):
                p[f, c + k] /= n


@njit(cache=True, nogil=True)
def match_exemplar(cands, dips, cont, decay, beat_frame, beat_bonus, seg):  # pragma: no cover - compiled
    """Motion matching of the chosen code's exemplars, then inertialization (dance_stream.py).

    ``cands`` (n, F, P) exemplar windows, ``dips`` (n, seg) their speed dips, ``cont`` (2, P)
    the two frames the motion would play next, ``decay`` (2, D) Hermite weights,
    ``beat_frame`` the frame of the coming movement the beat tracker expects a beat on (-1:
    none), ``beat_bonus`` the cost taken off an exemplar that dips there. Each exemplar's
    bones are sign-flipped onto ``cont[0]``'s hemisphere; the cost is the L1 distance of
    its first pose to ``cont[0]`` plus 4x that of its first velocity, over the median cost,
    less the beat bonus. Returns (index of the best, its window (F, P) bent to continue
    from ``cont`` over D frames, every quaternion renormalised).
    """
    n, nf, p = cands.shape
    a = cands.copy()
    for i in range(n):
        for c in range(3, p, 4):
            dot = np.float32(0.0)
            for k in range(4):
                dot += a[i, 0, c + k] * cont[0, c + k]
            if dot < 0:
                for f in range(nf):
                    for k in range(4):
                        a[i, f, c + k] = -a[i, f, c + k]
    cost = np.empty(n)
    for i in range(n):
        pos = np.float32(0.0)
        vel = np.float32(0.0)
        for c in range(p):
            pos += abs(a[i, 0, c] - cont[0, c])
            vel += abs((a[i, 1, c] - a[i, 0, c]) - (cont[1, c] - cont[0, c]))
        cost[i] = pos + np.float32(4.0) * vel
    cost /= max(np.median(cost), 1e-9)
    if beat_frame >= 0:
        for i in range(n):
            cost[i] -= beat_bonus * dips[i, beat_frame]
    best = int(np.argmin(cost))
    out = a[best].copy()
    for j in range(decay.shape[1]):
        for c in range(p):
            d0 = cont[0, c] - a[best, 0, c]
            d1 = (cont[1, c] - cont[0, c]) - (a[best, 1, c] - a[best, 0, c])
            out[j, c] += decay[0, j] * d0 + decay[1, j] * d1
    _unit_rows(out)
    return best, out
