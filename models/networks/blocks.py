"""Building blocks of the music-to-motion U-Nets, offline and causal, with streaming steps.

All tensors are ``(B, C, T)`` for whole sequences (T frames at one level of the U-Net:
level L runs at ``30 / 2**L`` fps) and ``(B, C)`` for one streaming step.

Causality, block by block (``causal=True``):

* :class:`ConvBNAct` pads ``(k - 1) * dilation`` zero frames on the LEFT only, so
  output frame t sees input frames ``t - (k-1)d .. t``. Batch norm in eval mode is a
  per-channel affine map and ReLU is pointwise, so neither looks across time.
* :func:`causal_upsample` is linear interpolation with a fixed lag: fine frame t reads
  the coarse signal at position ``t / 2 - 1`` (``u[c-1]`` at t = 2c,
  ``(u[c-1] + u[c]) / 2`` at t = 2c + 1, ``u[-1] = 0``). Coarse frame c needs fine
  frames up to 2c + 1, and ``t / 2 - 1 <= floor((t + 1) / 2) - 1`` for every t, so
  fine frame t never reads a coarse frame that depends on fine frames after t.
* Max pooling by 2 (coarse c = max(fine 2c, 2c+1)) only looks back within a pair.
* :class:`AttentionGate` and kernel-1 convs are pointwise in time.

Streaming (audiocraft-style): every causal block has ``init_state(batch)`` and
``step(x, state)``; a step consumes one frame ``(B, C_in)`` and returns one frame.
A conv keeps its last ``(k - 1) * dilation`` input frames in a doubled ring buffer
(no allocation per step) and applies the conv with batch norm folded into its
weights, as a single matrix product. Folded weights are taken when the state is
made: make a new state after changing the weights.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn


def fold_bn(conv: nn.Conv1d, bn: nn.BatchNorm1d | None) -> tuple[torch.Tensor, torch.Tensor]:
    """Conv weight (C_out, C_in, k) and bias (C_out,) with eval-mode batch norm folded in."""
    w = conv.weight.detach()
    b = conv.bias.detach() if conv.bias is not None else torch.zeros(w.shape[0], dtype=w.dtype)
    if bn is None:
        return w.clone(), b.clone()
    scale = bn.weight.detach() / torch.sqrt(bn.running_var + bn.eps)
    return w * scale[:, None, None], (b - bn.running_mean) * scale + bn.bias.detach()


@dataclass
class ConvState:
    """Streaming state of one conv: a doubled ring buffer of its last ``span`` inputs.

    buf: (B, 2 * span, C_in); frame written at ring slot p lives at rows p and p + span,
    so ``buf[:, pos + 1 : pos + 1 + span]`` is always the newest ``span`` frames, oldest
    first, as a view. weight: (C_out, span_taps * C_in) folded weight; bias: (C_out,).
    """

    buf: torch.Tensor | None
    pos: int
    weight: torch.Tensor
    bias: torch.Tensor


class ConvBNAct(nn.Module):
    """conv1d (kernel k, dilation d, stride 1) + BatchNorm1d + optional ReLU, length-preserving.

    Offline (``causal=False``): symmetric zero padding, needs odd ``(k-1)*d`` split evenly.
    Causal: ``(k-1)*d`` zero frames on the left; output t depends on inputs <= t.
    """

    def __init__(
        self, c_in: int, c_out: int, kernel: int = 3, *, causal: bool, dilation: int = 1,
        bn: bool = True, act: bool = True,
    ) -> None:
        super().__init__()
        self.causal = causal
        self.pad = (kernel - 1) * dilation
        self.conv = nn.Conv1d(c_in, c_out, kernel, dilation=dilation, bias=not bn)
        self.bn = nn.BatchNorm1d(c_out) if bn else None
        self.act = act

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        left = self.pad if self.causal else self.pad // 2
        x = F.pad(x, (left, self.pad - left))
        x = self.conv(x)
        if self.bn is not None:
            x = self.bn(x)
        return F.relu(x) if self.act else x

    def init_state(self, batch: int) -> ConvState:
        assert self.causal, "only causal convs stream"
        w, b = fold_bn(self.conv, self.bn)
        c_out, c_in, k = w.shape
        span = self.pad + 1
        # (C_out, k, C_in) flattened matches the (span, C_in) row-major window layout.
        wf = w.permute(0, 2, 1).reshape(c_out, k * c_in).contiguous()
        buf = torch.zeros(batch, 2 * span, c_in, dtype=w.dtype) if span > 1 else None
        return ConvState(buf=buf, pos=0, weight=wf, bias=b.contiguous())

    def step(self, x: torch.Tensor, st: ConvState) -> torch.Tensor:
        """One causal frame: x (B, C_in) -> (B, C_out)."""
        if st.buf is None:
            win = x
        else:
            span = self.pad + 1
            p = st.pos
            st.buf[:, p] = x
            st.buf[:, p + span] = x
            st.pos = p + 1 if p + 1 < span else 0
            win = st.buf[:, p + 1 : p + 1 + span]
            d = self.conv.dilation[0]
            if d > 1:
                win = win[:, ::d]
            win = win.reshape(x.shape[0], -1)
        y = torch.addmm(st.bias, win, st.weight.t())
        return torch.relu_(y) if self.act else y


@dataclass
class ResState:
    convs: list[ConvState]
    skip: ConvState | None


class ResBlock(nn.Module):
    """``n_convs`` stacked ConvBNAct (kernel k) plus a kernel-1 conv identity path, added.

    out = convs(x) + W_id x. The paper's block has one conv on the residual path; we
    stack ``n_convs`` (default 2) for a wider receptive field per level. With
    ``residual=False`` (the plain U-Net baseline) the identity path is dropped.
    Causal when its convs are (the identity path is pointwise).
    """

    def __init__(
        self, c_in: int, c_out: int, kernel: int, *, causal: bool, n_convs: int = 2, residual: bool = True
    ) -> None:
        super().__init__()
        chans = [c_in] + [c_out] * n_convs
        self.convs = nn.ModuleList(
            ConvBNAct(a, b, kernel, causal=causal) for a, b in zip(chans[:-1], chans[1:])
        )
        self.skip = nn.Conv1d(c_in, c_out, 1) if residual else None

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = x
        for conv in self.convs:
            h = conv(h)
        return h + self.skip(x) if self.skip is not None else h

    def init_state(self, batch: int) -> ResState:
        skip = None
        if self.skip is not None:
            w = self.skip.weight.detach()[:, :, 0].contiguous()
            skip = ConvState(buf=None, pos=0, weight=w, bias=self.skip.bias.detach().clone())
        return ResState(convs=[c.init_state(batch) for c in self.convs], skip=skip)

    def step(self, x: torch.Tensor, st: ResState) -> torch.Tensor:
        h = x
        for conv, cs in zip(self.convs, st.convs):
            h = conv.step(h, cs)
        if st.skip is not None:
            h = torch.addmm(h, x, st.skip.weight.t(), beta=1, alpha=1).add_(st.skip.bias)
        return h


@dataclass
class GateState:
    w_d: torch.Tensor
    w_u: torch.Tensor
    b_u: torch.Tensor
    psi_w: torch.Tensor
    psi_b: torch.Tensor


class AttentionGate(nn.Module):
    """Additive attention gate over time: o = f_d * sigmoid(psi(relu(W_d f_d + W_u f_u))).

    f_d: skip (encoder) features (B, C_d, T); f_u: upsampled decoder features
    (B, C_u, T); W_d, W_u, psi are kernel-1 convs, psi to ONE channel, so the gate is
    one weight per frame shared across channels. Pointwise in time, hence causal.
    """

    def __init__(self, c_d: int, c_u: int, c_mid: int) -> None:
        super().__init__()
        self.w_d = nn.Conv1d(c_d, c_mid, 1, bias=False)
        self.w_u = nn.Conv1d(c_u, c_mid, 1)
        self.psi = nn.Conv1d(c_mid, 1, 1)

    def forward(self, f_d: torch.Tensor, f_u: torch.Tensor) -> torch.Tensor:
        return f_d * torch.sigmoid(self.psi(F.relu(self.w_d(f_d) + self.w_u(f_u))))

    def init_state(self, batch: int) -> GateState:
        def w(conv: nn.Conv1d) -> torch.Tensor:
            return conv.weight.detach()[:, :, 0].t().contiguous()

        return GateState(
            w_d=w(self.w_d), w_u=w(self.w_u), b_u=self.w_u.bias.detach().clone(),
            psi_w=w(self.psi), psi_b=self.psi.bias.detach().clone(),
        )

    def step(self, f_d: torch.Tensor, f_u: torch.Tensor, st: GateState) -> torch.Tensor:
        a = torch.addmm(st.b_u, f_u, st.w_u).addmm_(f_d, st.w_d).relu_()
        return f_d * torch.sigmoid_(torch.addmm(st.psi_b, a, st.psi_w))


def causal_upsample(u: torch.Tensor) -> torch.Tensor:
    """Causal x2 linear upsampling (B, C, N) -> (B, C, 2N): fine t reads coarse position t/2 - 1.

    fine 2c = u[c-1], fine 2c+1 = (u[c-1] + u[c]) / 2, with u[-1] = 0 (zero state).
    """
    prev = F.pad(u, (1, 0))[..., :-1]
    return torch.stack((prev, 0.5 * (prev + u)), dim=-1).flatten(-2)


def offline_upsample(u: torch.Tensor) -> torch.Tensor:
    """Non-causal x2 linear upsampling (align_corners=False), (B, C, N) -> (B, C, 2N)."""
    return F.interpolate(u, scale_factor=2, mode="linear", align_corners=False)


@dataclass
class UpState:
    """The last two coarse frames seen by a causal upsampler, (B, C) each, newest ``last``."""

    prev: torch.Tensor
    last: torch.Tensor


def upsample_push(st: UpState, coarse: torch.Tensor) -> None:
    """Record a new coarse frame (B, C) in place."""
    st.prev, st.last = st.last, st.prev
    st.last.copy_(coarse)


def upsample_read(st: UpState, fine_index: int, out: torch.Tensor) -> torch.Tensor:
    """Fine frame ``fine_index`` of :func:`causal_upsample`, written into ``out`` (B, C)."""
    if fine_index % 2 == 0:
        return out.copy_(st.last)
    return torch.add(st.prev, st.last, out=out).mul_(0.5)


def randomize_batchnorm(model: nn.Module, seed: int = 0) -> nn.Module:
    """Give every BatchNorm1d random running stats and affine parameters (in place).

    For tests and benchmarks of untrained models: fresh BN layers are identity maps in
    eval mode, which would hide mistakes in folding or in eval-mode paths.
    """
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for m in model.modules():
            if isinstance(m, nn.BatchNorm1d):
                n = m.num_features
                m.running_mean.copy_(0.2 * torch.randn(n, generator=g))
                m.running_var.copy_(0.5 + 1.5 * torch.rand(n, generator=g))
                if m.affine:  # an input standardisation (affine=False) has running stats only
                    m.weight.copy_(0.5 + torch.rand(n, generator=g))
                    m.bias.copy_(0.2 * torch.randn(n, generator=g))
    return model
