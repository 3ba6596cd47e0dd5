"""The causal U-Net's one-frame streaming step in NumPy, for the real-time path.

:class:`NumpyStep` does exactly what :meth:`models.networks.causal.CausalGenerator.step`
does (same levels, same ring buffers, same batch-norm-folded weights, taken from the
torch model once through ``init_stream_state``), with NumPy arrays instead of torch
tensors. The torch step stays the reference: results agree to float32 rounding
(``tests/test_networks_numpy_step.py``).

Why a second implementation: one streamed frame is about 130 tiny operations on
arrays of 2 rows and at most 384 columns. Their arithmetic is a few microseconds in
all; what costs is the per-call dispatch, about 4 µs for a torch ``addmm`` and 1 µs for
``np.dot`` into a preallocated output (2 µs against 0.5 µs for a row copy). The torch
step takes about 0.3 ms per frame, this one about half (``benchmarks/studies/model_cost.py``
reports both, side by side). Every output and scratch array is allocated once, when
the step is made; a frame allocates only a few small temporaries (window views).

Arrays are ``(B, C)`` float32, one row per window slot (the streaming wrapper runs all
slots of one stream as a batch).
"""

from __future__ import annotations

import numpy as np
from scipy.special import expit

from models.networks.blocks import ConvState, GateState, ResState
from models.networks.generator import LEVELS


def _np(t) -> np.ndarray:
    return np.ascontiguousarray(t.detach().cpu().numpy(), dtype=np.float32)


class _Conv:
    """Causal conv (batch norm folded) on a doubled ring buffer of its last ``span`` inputs."""

    def __init__(self, st: ConvState, act: bool, dilation: int, batch: int) -> None:
        self.wt = np.ascontiguousarray(_np(st.weight).T)  # (span_taps * C_in, C_out)
        self.b = _np(st.bias)
        self.buf = None if st.buf is None else np.zeros(tuple(st.buf.shape), np.float32)  # (B, 2 span, C_in)
        self.span = 1 if st.buf is None else st.buf.shape[1] // 2
        self.pos = 0
        self.dilation = dilation
        self.act = act
        self.out = np.zeros((batch, self.wt.shape[1]), np.float32)

    def step(self, x: np.ndarray) -> np.ndarray:
        if self.buf is None:
            win = x
        else:
            p, span = self.pos, self.span
            self.buf[:, p] = x
            self.buf[:, p + span] = x
            self.pos = p + 1 if p + 1 < span else 0
            win = self.buf[:, p + 1 : p + 1 + span]
            if self.dilation > 1:
                win = win[:, :: self.dilation]
            win = win.reshape(x.shape[0], -1)
        np.dot(win, self.wt, out=self.out)
        self.out += self.b
        if self.act:
            np.maximum(self.out, 0.0, out=self.out)
        return self.out


class _Res:
    """Residual block: stacked causal convs plus the kernel-1 identity path."""

    def __init__(self, block, st: ResState, batch: int) -> None:
        self.convs = [_Conv(cs, m.act, m.conv.dilation[0], batch) for m, cs in zip(block.convs, st.convs)]
        self.skip_wt = None if st.skip is None else np.ascontiguousarray(_np(st.skip.weight).T)
        self.skip_b = None if st.skip is None else _np(st.skip.bias)
        self.out = np.zeros((batch, self.convs[-1].out.shape[1]), np.float32)

    def step(self, x: np.ndarray) -> np.ndarray:
        h = x
        for c in self.convs:
            h = c.step(h)
        if self.skip_wt is None:
            return h
        np.dot(x, self.skip_wt, out=self.out)
        self.out += h
        self.out += self.skip_b
        return self.out


class _Gate:
    """Attention gate: f_d * sigmoid(psi(relu(W_u f_u + W_d f_d))), one weight per frame."""

    def __init__(self, st: GateState, batch: int) -> None:
        self.w_u, self.w_d, self.b_u = _np(st.w_u), _np(st.w_d), _np(st.b_u)
        self.psi_w, self.psi_b = _np(st.psi_w), _np(st.psi_b)
        self.a = np.zeros((batch, self.w_u.shape[1]), np.float32)
        self.tmp = np.zeros_like(self.a)
        self.g = np.zeros((batch, 1), np.float32)

    def step(self, f_d: np.ndarray, f_u: np.ndarray, out: np.ndarray) -> None:
        """Write the gated f_d into ``out`` (B, C_d), which may be a column slice."""
        np.dot(f_u, self.w_u, out=self.a)
        np.dot(f_d, self.w_d, out=self.tmp)
        self.a += self.tmp
        self.a += self.b_u
        np.maximum(self.a, 0.0, out=self.a)
        np.dot(self.a, self.psi_w, out=self.g)
        self.g += self.psi_b
        expit(self.g, out=self.g)
        np.multiply(f_d, self.g, out=out)


class NumpyStep:
    """:meth:`CausalGenerator.step` for ``batch`` streams, in NumPy (module docstring).

    ``step(x (B, D) float32) -> (B, POSE_DIM)``: the returned array is reused by the
    next call, so copy it to keep it. :meth:`zero_rows` resets streams to the zero state.
    The model's weights are read once here (eval mode, batch norm folded): make a new
    step after changing them.
    """

    def __init__(self, model, batch: int) -> None:
        import torch

        model.eval()
        with torch.inference_mode():
            st = model.init_stream_state(batch)
        self.batch = batch
        self.frame = 0
        self.attention = model.config.attention
        aff = st.in_affine
        self.in_scale = None if aff is None else _np(aff[0])
        self.in_shift = None if aff is None else _np(aff[1])
        self.x_norm = np.zeros((batch, model.config.feature_dim), np.float32)
        self.enc = [_Res(m, s, batch) for m, s in zip(model.enc, st.enc)]
        self.bottom = _Res(model.bottom, st.bottom, batch)
        self.up = [_Conv(s, m.act, m.conv.dilation[0], batch) for m, s in zip(model.up, st.up_conv)]
        self.gates = [_Gate(s, batch) if s is not None else None for s in st.gates]
        self.dec = [_Res(m, s, batch) for m, s in zip(model.dec, st.dec)]
        self.head_wt = np.ascontiguousarray(_np(st.head.weight).T)
        self.head_b = _np(st.head.bias)
        c = model.config.channels
        self.pool_even = [np.zeros((batch, c[i]), np.float32) for i in range(LEVELS)]
        self.pooled = [np.zeros((batch, c[i]), np.float32) for i in range(LEVELS)]
        # Upsampler state per level L: the last two level-(L+1) frames, [older, newer].
        self.ups = [np.zeros((2, batch, c[i + 1]), np.float32) for i in range(LEVELS)]
        self.up_newest = [1] * LEVELS
        self.fine = [np.zeros((batch, c[i + 1]), np.float32) for i in range(LEVELS)]
        self.cat = [np.zeros((batch, 2 * c[i]), np.float32) for i in range(LEVELS)]
        self.skips: list[np.ndarray | None] = [None] * LEVELS
        self.y = np.zeros((batch, model.config.pose_dim), np.float32)
        self.norm = np.zeros((batch, (model.config.pose_dim - 3) // 4, 1), np.float32)
        convs = [cv for r in (*self.enc, self.bottom, *self.dec) for cv in r.convs] + self.up
        self._row_buffers = [cv.buf for cv in convs if cv.buf is not None] + self.pool_even  # rows on axis 0

    def zero_rows(self, rows: slice | int | list[int]) -> None:
        """Reset the given streams to the zero state (``frame`` is shared by all rows)."""
        for b in self._row_buffers:
            b[rows] = 0.0
        for u in self.ups:  # (2, B, C): rows on axis 1
            u[:, rows] = 0.0

    def _push_up(self, level: int, coarse: np.ndarray) -> None:
        newest = 1 - self.up_newest[level]
        self.ups[level][newest] = coarse
        self.up_newest[level] = newest

    def _read_up(self, level: int, fine_index: int) -> np.ndarray:
        newest = self.up_newest[level]
        out = self.fine[level]
        if fine_index % 2 == 0:
            out[...] = self.ups[level][newest]
        else:
            np.add(self.ups[level][0], self.ups[level][1], out=out)
            out *= 0.5
        return out

    def step(self, x: np.ndarray) -> np.ndarray:
        """Advance every stream by one frame: x (B, D) float32 -> poses (B, POSE_DIM)."""
        n = self.frame
        self.frame = n + 1
        m = n + 1
        depth = min(LEVELS, (m & -m).bit_length() - 1)
        h = x
        if self.in_scale is not None:  # input standardisation (GeneratorConfig.input_norm)
            h = np.multiply(x, self.in_scale, out=self.x_norm)
            h += self.in_shift
        for level in range(LEVELS):
            s = self.enc[level].step(h)
            self.skips[level] = s
            if level + 1 > depth:  # an even frame at this level: hold it for the pool
                self.pool_even[level][...] = s
                break
            h = np.maximum(self.pool_even[level], s, out=self.pooled[level])
        if depth == LEVELS:
            self._push_up(LEVELS - 1, self.bottom.step(h))
        d = h
        for level in reversed(range(min(depth, LEVELS - 1) + 1)):
            fine = ((n + 1) >> level) - 1
            u = self.up[level].step(self._read_up(level, fine))
            cat = self.cat[level]
            c = u.shape[1]
            cat[:, :c] = u
            skip = self.skips[level]
            if self.attention:
                self.gates[level].step(skip, u, cat[:, c:])
            else:
                cat[:, c:] = skip
            d = self.dec[level].step(cat)
            if level > 0:
                self._push_up(level - 1, d)
        y = self.y
        np.dot(d, self.head_wt, out=y)
        y += self.head_b
        q = y[:, 3:].reshape(self.batch, -1, 4)
        np.sqrt(np.einsum("bjc,bjc->bj", q, q)[..., None], out=self.norm)
        np.maximum(self.norm, 1e-6, out=self.norm)
        q /= self.norm
        return y
