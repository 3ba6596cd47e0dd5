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
def _qmul(ax, ay, az, aw, bx, by, bz, bw):  # pragma: no cover - compiled
    """Quaternion product a b, x y z w order, of float64 components; a tuple (no array made)."""
    return (aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz)


@njit(cache=True, nogil=True)
def qmul_rows(a, b):  # pragma: no cover - compiled
    """Quaternion products a b of rows (n, 4) float64, x y z w order: idle_fade's ``_qmul`` (the
    idle fade's), each component's sum in the same order as its NumPy expression, bit for bit."""
    out = np.empty((a.shape[0], 4))
    for i in range(a.shape[0]):
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = _qmul(a[i, 0], a[i, 1], a[i, 2], a[i, 3],
                                                           b[i, 0], b[i, 1], b[i, 2], b[i, 3])
    return out


@njit(cache=True, nogil=True)
def _qlog(x, y, z, w):  # pragma: no cover - compiled
    """Rotation vector (axis times angle, radians; a tuple) of unit quaternion (x y z w), the short way."""
    if w < 0:
        x, y, z, w = -x, -y, -z, -w
    s = math.sqrt(x * x + y * y + z * z)
    k = 2.0 * math.atan2(s, w) / s if s > 1e-12 else 2.0
    return k * x, k * y, k * z


@njit(cache=True, nogil=True)
def _qexp(rx, ry, rz):  # pragma: no cover - compiled
    """Unit quaternion (x y z w; a tuple) of rotation vector (rx, ry, rz), radians."""
    a = math.sqrt(rx * rx + ry * ry + rz * rz)
    k = math.sin(0.5 * a) / a if a > 1e-12 else 0.5
    return k * rx, k * ry, k * rz, math.cos(0.5 * a)


@njit(cache=True, nogil=True)
def match_exemplar(cands, dips, cont, decay, beat_frame, beat_bonus, seg, vel_cap, bias):  # pragma: no cover - compiled
    """Motion matching of the chosen code's exemplars, then inertialization (dance_stream.py).

    ``cands`` (n, F, P) exemplar windows, ``dips`` (n, seg) their speed dips, ``cont`` (2, P)
    the two frames the motion would play next, ``decay`` (2, D) Hermite weights,
    ``beat_frame`` the frame of the coming movement the beat tracker expects a beat on (-1:
    none), ``beat_bonus`` the cost taken off an exemplar that dips there, ``bias`` (n,) a cost
    taken off each exemplar (a library's liveliness at the tempo; zeros: none). Each exemplar's
    bones are sign-flipped onto ``cont[0]``'s hemisphere; the cost is the L1 distance of
    its first pose to ``cont[0]`` plus 4x that of its first velocity, over the median cost,
    less the beat bonus and the bias. Returns (index of the best, its window (F, P) bent to continue
    from ``cont`` over D frames).

    The bend is inertialization in rotation space: per bone, the rotation from the
    exemplar's first frame to ``cont[0]`` and the difference of their angular velocities
    (rotation vectors, radians per frame; each bone's capped at ``vel_cap``) decay with the
    Hermite weights and are applied as a rotation before the exemplar's own; the root's
    position offsets decay the same way. (Adding the differences to the quaternions'
    components and renormalising, as before, whipped a bone through 100+ degrees in a
    frame when a large offset met a fast exemplar: the sum passed near zero.)
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
    for i in range(n):
        cost[i] -= bias[i]
    best = int(np.argmin(cost))
    w = a[best]
    out = w.copy()
    nd = min(decay.shape[1], nf)
    for c in range(3):  # the root's position
        d0 = cont[0, c] - w[0, c]
        d1 = (cont[1, c] - cont[0, c]) - (w[1, c] - w[0, c])
        for j in range(nd):
            out[j, c] += decay[0, j] * d0 + decay[1, j] * d1
    for c in range(3, p, 4):  # each bone, in float64 scalars (no array made per bone or frame)
        c0x, c0y, c0z, c0w = np.float64(cont[0, c]), np.float64(cont[0, c + 1]), np.float64(cont[0, c + 2]), \
            np.float64(cont[0, c + 3])
        c1x, c1y, c1z, c1w = np.float64(cont[1, c]), np.float64(cont[1, c + 1]), np.float64(cont[1, c + 2]), \
            np.float64(cont[1, c + 3])
        w0x, w0y, w0z, w0w = np.float64(w[0, c]), np.float64(w[0, c + 1]), np.float64(w[0, c + 2]), \
            np.float64(w[0, c + 3])
        w1x, w1y, w1z, w1w = np.float64(w[1, c]), np.float64(w[1, c + 1]), np.float64(w[1, c + 2]), \
            np.float64(w[1, c + 3])
        r0x, r0y, r0z = _qlog(*_qmul(c0x, c0y, c0z, c0w, -w0x, -w0y, -w0z, w0w))
        ax, ay, az = _qlog(*_qmul(c1x, c1y, c1z, c1w, -c0x, -c0y, -c0z, c0w))
        bx, by, bz = _qlog(*_qmul(w1x, w1y, w1z, w1w, -w0x, -w0y, -w0z, w0w))
        d1x, d1y, d1z = ax - bx, ay - by, az - bz
        norm = math.sqrt(d1x * d1x + d1y * d1y + d1z * d1z)
        if norm > vel_cap:
            cap = vel_cap / norm
            d1x, d1y, d1z = d1x * cap, d1y * cap, d1z * cap
        for j in range(nd):
            e0, e1 = np.float64(decay[0, j]), np.float64(decay[1, j])
            wx, wy, wz, ww = np.float64(w[j, c]), np.float64(w[j, c + 1]), np.float64(w[j, c + 2]), \
                np.float64(w[j, c + 3])
            ex, ey, ez, ew = _qexp(e0 * r0x + e1 * d1x, e0 * r0y + e1 * d1y, e0 * r0z + e1 * d1z)
            qx, qy, qz, qw = _qmul(ex, ey, ez, ew, wx, wy, wz, ww)
            qn = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
            if qx * wx + qy * wy + qz * wz + qw * ww < 0:  # keep the exemplar's signs
                qn = -qn
            out[j, c], out[j, c + 1], out[j, c + 2], out[j, c + 3] = qx / qn, qy / qn, qz / qn, qw / qn
    _unit_rows(out)
    return best, out


@njit(cache=True, nogil=True)
def embed_token(audio_row, w_a1, b_a1, w_a2, b_a2, code_row):  # pragma: no cover - compiled
    """A token's input (d,): the audio MLP (GELU) of its standardised frames ``audio_row``
    (seg * D,) plus ``code_row`` (d,), the previous code's embedding."""
    return _embed_out(_vec_mat(audio_row, w_a1, b_a1), w_a2, b_a2, code_row)


@njit(cache=True, nogil=True)
def add_rows(acc, x, w, lo):  # pragma: no cover - compiled
    """In place: ``acc`` (k,) += ``x`` (n,) @ ``w[lo:lo + n]`` (k,), row by row in order: with ``acc``
    started at the bias, ``_vec_mat``'s sums for rows ``lo..lo + n - 1`` of its input, so a token's
    first layer can be summed a frame at a time, bit for bit the same (:func:`embed_finish`)."""
    for i in range(x.shape[0]):
        xi = x[i]
        for j in range(w.shape[1]):
            acc[j] += xi * w[lo + i, j]


@njit(cache=True, nogil=True)
def embed_finish(acc, last, lo, w_a1, w_a2, b_a2, code_row):  # pragma: no cover - compiled
    """:func:`embed_token` of a token whose first layer ``acc`` (hidden,) holds its bias plus every
    input but the ``last`` ones (:func:`add_rows`), those starting at input ``lo``: the same values.
    ``acc`` is used up (written in place)."""
    add_rows(acc, last, w_a1, lo)
    return _embed_out(acc, w_a2, b_a2, code_row)


@njit(cache=True, nogil=True)
def _embed_out(u, w_a2, b_a2, code_row):  # pragma: no cover - compiled
    """The audio MLP's GELU (in place on its first layer ``u``) and second layer, plus ``code_row``."""
    for i in range(u.shape[0]):
        u[i] = np.float32(0.5 * u[i] * (1.0 + math.erf(u[i] * _SQRT_HALF)))
    out = _vec_mat(u, w_a2, b_a2)
    for i in range(out.shape[0]):
        out[i] += code_row[i]
    return out


@njit(cache=True, nogil=True)
def draw_code(logits, temperature, u):  # pragma: no cover - compiled
    """The code whose interval of ``softmax(logits / temperature)``'s cumulative sum holds the
    uniform variate ``u``: ``Generator.choice(p=...)``'s search, in float64 (the total is summed
    in order, NumPy's pairwise: the two may differ in the last bit, which moves a draw only
    when ``u`` lies within ~1e-16 of a boundary)."""
    n = logits.shape[0]
    z = np.empty(n)
    top = -np.inf
    for i in range(n):
        z[i] = np.float64(logits[i]) / temperature
        top = max(top, z[i])
    total = 0.0
    for i in range(n):
        z[i] = math.exp(z[i] - top)
        total += z[i]
    acc = 0.0
    for i in range(n):  # the cumulative sum of p / p.sum(), as NumPy's cumsum adds it
        acc += z[i] / total
        z[i] = acc
    last = z[n - 1]
    lo, hi = 0, n  # searchsorted(cdf / cdf[-1], u, side="right")
    while lo < hi:
        mid = (lo + hi) // 2
        if u < z[mid] / last:
            hi = mid
        else:
            lo = mid + 1
    return lo


# -- the frames between code steps -------------------------------------------------------------
# A lane's ordinary frame (no code step) was about 30 small NumPy calls (sanitising, the feature
# history, the idle gate, the renormalisation) and a prefix piece 10-20 more around its matrix
# products, each 5-10 µs on the live path's cold caches. These kernels do the same arithmetic in
# the same order (float32 where NumPy computes in float32, sums paired as NumPy pairs them), so
# the poses and codes are those of the NumPy code they replace, bit for bit
# (tests/test_dance_vq.py); the matrix products stay NumPy's (BLAS).


@njit(cache=True, nogil=True)
def sanitize_rows(x, out, limit):  # pragma: no cover - compiled
    """``out`` (k, D) float32 = ``x`` (k, D) with non-finite values -> 0, clipped to +-limit
    (``sanitize_features``'s values); returns how many rows held a non-finite value."""
    lim = np.float32(limit)
    bad_rows = 0
    for r in range(x.shape[0]):
        bad = False
        for c in range(x.shape[1]):
            v = np.float32(x[r, c])
            if not np.isfinite(v):
                bad = True
                v = np.float32(0.0)
            out[r, c] = min(max(v, -lim), lim)
        if bad:
            bad_rows += 1
    return bad_rows


@njit(cache=True, nogil=True)
def push_history(hist, row, mean, std):  # pragma: no cover - compiled
    """Shift the feature history ``hist`` (seg, D) up one frame and append ``(row - mean) / std`` (D,)."""
    n, d = hist.shape
    for i in range(n - 1):
        for c in range(d):
            hist[i, c] = hist[i + 1, c]
    for c in range(d):
        hist[n - 1, c] = (row[c] - mean[c]) / std[c]


@njit(cache=True, nogil=True)
def gate_ema(row, cols, mean, std, ema, a):  # pragma: no cover - compiled
    """The music detector's running mean, in place: ``ema = a ema + (1 - a) z`` with
    ``z = (row[cols] - mean) / std`` (float64, (G,))."""
    b = 1.0 - a
    for i in range(cols.shape[0]):
        z = (np.float64(row[cols[i]]) - mean[i]) / std[i]
        ema[i] = a * ema[i] + b * z


@njit(cache=True, nogil=True)
def _sq4(q, j):  # pragma: no cover - compiled
    """|q_j|^2 of quaternion row j (float32), paired as NumPy's einsum adds four products."""
    return (q[j, 0] * q[j, 0] + q[j, 1] * q[j, 1]) + (q[j, 2] * q[j, 2] + q[j, 3] * q[j, 3])


@njit(cache=True, nogil=True)
def renorm_pose(pose, prev, out):  # pragma: no cover - compiled
    """``out`` (P,) = ``pose`` (P,) with unit quaternions, each on the hemisphere of ``prev`` (J, 4)
    (J = 0: no previous frame). Returns False, writing nothing, when the root or a norm is not
    finite or a norm is at most 1e-8 (the caller takes the general path then)."""
    q = pose[3:].reshape(-1, 4)
    nj = q.shape[0]
    norm = np.empty(nj, np.float32)
    for j in range(nj):
        norm[j] = np.float32(math.sqrt(_sq4(q, j)))
        if not (np.isfinite(norm[j]) and norm[j] > np.float32(1e-8)):
            return False
    for c in range(3):
        if not np.isfinite(pose[c]):
            return False
        out[c] = pose[c]
    o = out[3:].reshape(-1, 4)
    for j in range(nj):
        for k in range(4):
            o[j, k] = q[j, k] / norm[j]
    if prev.shape[0] == nj:
        for j in range(nj):
            dot = (o[j, 0] * prev[j, 0] + o[j, 1] * prev[j, 1]) + (o[j, 2] * prev[j, 2] + o[j, 3] * prev[j, 3])
            if dot < 0:
                for k in range(4):
                    o[j, k] = -o[j, k]
    return True


@njit(cache=True, nogil=True)
def _block_sum(x, lo, n):  # pragma: no cover - compiled
    """Sum of x[lo:lo + n], n <= 128, as NumPy sums such a block: eight running sums combined
    pairwise, then the rest in order (fewer than 8: in order)."""
    if n < 8:
        s = np.float32(0.0)
        for i in range(lo, lo + n):
            s += x[i]
        return s
    r0, r1, r2, r3 = x[lo], x[lo + 1], x[lo + 2], x[lo + 3]
    r4, r5, r6, r7 = x[lo + 4], x[lo + 5], x[lo + 6], x[lo + 7]
    i = 8
    stop = n - n % 8
    while i < stop:
        j = lo + i
        r0 += x[j]
        r1 += x[j + 1]
        r2 += x[j + 2]
        r3 += x[j + 3]
        r4 += x[j + 4]
        r5 += x[j + 5]
        r6 += x[j + 6]
        r7 += x[j + 7]
        i += 8
    s = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        s += x[lo + i]
        i += 1
    return s


@njit(cache=True, nogil=True)
def _pairwise_sum(x):  # pragma: no cover - compiled
    """Sum of x (n,) float32 as NumPy's ``add.reduce`` sums a contiguous row (pairwise): blocks
    of up to 128 by :func:`_block_sum`; a longer range splits in two halves (the first a
    multiple of 8) and adds their sums. Written with an explicit stack (numba's cache does
    not keep recursive functions)."""
    n = x.shape[0]
    if n <= 128:
        return _block_sum(x, 0, n)
    # post-order walk of the split tree: (lo, n, state) with state 0 = not split yet, 1 = children summed
    lo_s = np.empty(64, np.int64)
    n_s = np.empty(64, np.int64)
    st_s = np.empty(64, np.int64)
    val = np.empty(64, np.float32)
    nv = 0
    top = 0
    lo_s[0], n_s[0], st_s[0] = 0, n, 0
    while top >= 0:
        lo, m, st = lo_s[top], n_s[top], st_s[top]
        if m <= 128:
            val[nv] = _block_sum(x, lo, m)
            nv += 1
            top -= 1
        elif st == 1:
            val[nv - 2] = val[nv - 2] + val[nv - 1]
            nv -= 1
            top -= 1
        else:
            half = m // 2
            half -= half % 8
            st_s[top] = 1
            lo_s[top + 1], n_s[top + 1], st_s[top + 1] = lo + half, m - half, 0
            lo_s[top + 2], n_s[top + 2], st_s[top + 2] = lo, half, 0
            top += 2
    return val[0]


@njit(cache=True, nogil=True)
def layer_norm_rows(x, w, b, eps):  # pragma: no cover - compiled
    """LayerNorm of rows x (m, d) float32 over the last axis: dance_numpy's ``_layer_norm``."""
    m, d = x.shape
    out = np.empty_like(x)
    xc = np.empty(d, np.float32)
    sq = np.empty(d, np.float32)
    e = np.float32(eps)
    df = np.float32(d)
    for r in range(m):
        mean = _pairwise_sum(x[r]) / df
        for c in range(d):
            xc[c] = x[r, c] - mean
            sq[c] = xc[c] * xc[c]
        s = np.float32(math.sqrt(_pairwise_sum(sq) / df + e))
        for c in range(d):
            out[r, c] = xc[c] / s * w[c] + b[c]
    return out


@njit(cache=True, nogil=True)
def gelu_bias(u, b):  # pragma: no cover - compiled
    """In place: ``u = gelu(u + b)`` for rows u (m, n) float32 and bias b (n,); the exact (erf)
    GELU as dance_numpy's ``_gelu`` computes it (erf in float64, rounded to float32)."""
    c = np.float32(_SQRT_HALF)
    for r in range(u.shape[0]):
        for i in range(u.shape[1]):
            x = u[r, i] + b[i]
            e = np.float32(math.erf(np.float64(x * c)))
            u[r, i] = np.float32(0.5) * x * (np.float32(1.0) + e)


@njit(cache=True, nogil=True)
def warp_pose(played, x):  # pragma: no cover - compiled
    """The pose (P,) at fractional frame ``x`` of ``played`` (F, P) float32: frame ``i = floor(x)``
    itself when ``x`` is within 1e-6 above it, else the root lerped and every quaternion
    nlerped (onto frame i's hemisphere, renormalised) from frame i to i + 1 by ``x - i``.
    The beat warp's read-out (dance_stream.py); as ``_nlerp`` there, compiled because it
    runs every frame of every performer (about 50 µs a frame in NumPy, 1-2 µs here)."""
    i = int(math.floor(x))
    f = np.float32(x - i)
    p = played.shape[1]
    out = played[i].copy()
    if f < 1e-6:
        return out
    a, b = played[i], played[i + 1]
    for c in range(3):
        out[c] = (np.float32(1.0) - f) * a[c] + f * b[c]
    for c in range(3, p, 4):
        dot = np.float32(0.0)
        for k in range(4):
            dot += a[c + k] * b[c + k]
        s = np.float32(-1.0) if dot < 0 else np.float32(1.0)
        n = np.float32(0.0)
        for k in range(4):
            out[c + k] = (np.float32(1.0) - f) * a[c + k] + f * s * b[c + k]
            n += out[c + k] * out[c + k]
        n = max(np.float32(math.sqrt(n)), np.float32(1e-9))
        for k in range(4):
            out[c + k] /= n
    return out


@njit(cache=True, nogil=True)
def bone_rotations(window, f, parents, g):  # pragma: no cover - compiled
    """Each bone's world rotation in frame ``f`` of poses ``window`` (F, P) float32 into ``g`` (J, 4)
    float64: its quaternion renormalised, composed with its parent's (``parents``: bones first, each
    after its parent, -1 the root). On float64 scalars, no array made per bone (joint_speed's FK)."""
    for j in range(g.shape[0]):
        c = 3 + 4 * j
        qx, qy, qz, qw = np.float64(window[f, c]), np.float64(window[f, c + 1]), np.float64(window[f, c + 2]), \
            np.float64(window[f, c + 3])
        s = qx * qx + qy * qy + qz * qz + qw * qw
        s = math.sqrt(s) if s > 1e-18 else 1.0
        qx, qy, qz, qw = qx / s, qy / s, qz / s, qw / s
        p = parents[j]
        if p >= 0:
            qx, qy, qz, qw = _qmul(g[p, 0], g[p, 1], g[p, 2], g[p, 3], qx, qy, qz, qw)
        g[j, 0], g[j, 1], g[j, 2], g[j, 3] = qx, qy, qz, qw


@njit(cache=True, nogil=True)
def joint_speed(window, n, parents, offsets):  # pragma: no cover - compiled
    """Mean joint speed (m a frame) of the first ``n`` frames of pose ``window`` (F, P) float32
    by forward kinematics: ``parents`` (J + E,) int64 each point's parent (bones first, -1 the
    root), ``offsets`` (J + E, 3) float64 the points' offsets (m); quaternions renormalised.
    The speed is np.gradient's along the frames (central, one-sided at the ends), its norm
    averaged over points and frames: what ``dance_stream.member_speed`` gives, without its
    scipy calls (a 13-frame window: median 1.2 ms there, 11 µs here, p99 18 µs; on the code step's path)."""
    npt = parents.shape[0]
    nb = (window.shape[1] - 3) // 4
    pos = np.zeros((n, npt, 3))
    g = np.zeros((nb, 4))
    for f in range(n):
        bone_rotations(window, f, parents, g)
        for i in range(npt):
            p = parents[i]
            if p < 0:
                for k in range(3):
                    pos[f, i, k] = window[f, k]
                continue
            x, y, z, w = g[p, 0], g[p, 1], g[p, 2], g[p, 3]
            vx, vy, vz = offsets[i, 0], offsets[i, 1], offsets[i, 2]
            tx, ty, tz = 2.0 * (y * vz - z * vy), 2.0 * (z * vx - x * vz), 2.0 * (x * vy - y * vx)
            pos[f, i, 0] = pos[f, p, 0] + vx + w * tx + (y * tz - z * ty)
            pos[f, i, 1] = pos[f, p, 1] + vy + w * ty + (z * tx - x * tz)
            pos[f, i, 2] = pos[f, p, 2] + vz + w * tz + (x * ty - y * tx)
    total = 0.0
    for f in range(n):
        a, b = (max(f - 1, 0), min(f + 1, n - 1)) if n > 1 else (0, 0)
        d = float(b - a) if b > a else 1.0
        for i in range(npt):
            e = 0.0
            for k in range(3):
                c = (pos[b, i, k] - pos[a, i, k]) / d
                e += c * c
            total += math.sqrt(e)
    return total / (n * npt)


# -- the stage's track at a handover (models/networks/stage.py, Stage.handover) --------------------


@njit(cache=True, nogil=True)
def place_travel(tr, s, rows, base0, base1, base2, c, sn, travel, carry, carried):  # pragma: no cover - compiled
    """The stage track ``tr`` (R, 3) float64 from row ``s``: ``rows`` rows of the new movement's
    ``travel`` (rows, 3; none: its rows all ``base``) turned by the base heading (``c``, ``sn`` its
    cosine and sine) and carried on from ``base``; with ``carried``, the last movement's velocity
    where they meet blended in (``carry`` (rows, 3)); the rows after repeat the last. Stage.handover's
    NumPy arithmetic, element by element in float64 (the same values, bit for bit)."""
    e = s + rows
    for f in range(rows):
        if travel.shape[0]:
            tr[s + f, 0] = base0 + c * travel[f, 0] + sn * travel[f, 1]
            tr[s + f, 1] = base1 - sn * travel[f, 0] + c * travel[f, 1]
            tr[s + f, 2] = base2 + travel[f, 2]
        else:
            tr[s + f, 0], tr[s + f, 1], tr[s + f, 2] = base0, base1, base2
    if carried:
        d0 = base0 - tr[s - 1, 0] - (tr[s + 1, 0] - tr[s, 0])
        d1 = base1 - tr[s - 1, 1] - (tr[s + 1, 1] - tr[s, 1])
        d2 = base2 - tr[s - 1, 2] - (tr[s + 1, 2] - tr[s, 2])
        for f in range(rows):
            tr[s + f, 0] += carry[f, 0] * d0
            tr[s + f, 1] += carry[f, 1] * d1
            tr[s + f, 2] += carry[f, 2] * d2
    for r in range(e, tr.shape[0]):
        tr[r, 0], tr[r, 1], tr[r, 2] = tr[e - 1, 0], tr[e - 1, 1], tr[e - 1, 2]


@njit(cache=True, nogil=True)
def reorigin_track(tr, p0, p1, p2, c, sn):  # pragma: no cover - compiled
    """The track ``tr`` (R, 3) float64 in place with (``p0``, ``p1``) its origin and ``p2`` its zero
    heading (``c``, ``sn`` that heading's cosine and sine): Stage.handover's NumPy arithmetic, bit for bit."""
    for r in range(tr.shape[0]):
        dx, dz = tr[r, 0] - p0, tr[r, 1] - p1
        tr[r, 0], tr[r, 1] = c * dx - sn * dz, sn * dx + c * dz
        tr[r, 2] -= p2
