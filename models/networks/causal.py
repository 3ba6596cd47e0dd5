"""The causal U-Net generator and its one-frame streaming step.

:class:`CausalGenerator` is :class:`~models.networks.generator.UNetGenerator` with
``causal=True``: its batched ``forward`` is causal (output frame t depends on input
frames <= t; see :mod:`models.networks.blocks` for how each block keeps that) and it
adds :meth:`CausalGenerator.step`, which advances a :class:`StreamState` by ONE input
frame and returns that frame's pose, doing only the work that frame makes due:
level L (30 / 2**L fps) runs when ``(n + 1) % 2**L == 0`` for window-relative frame n,
so level 0 runs every frame, level 1 every second frame, ..., level 4 every 16th.

A state started with :meth:`init_stream_state` is the zero state: stepping it through
frames ``x[0..n]`` gives exactly ``forward(x[None, :, :n+1])[..., n]`` (up to float
rounding), eval mode assumed (batch norm uses running statistics, folded into the
convs when the state is made).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import torch

from models.errors import ConfigError
from models.networks.blocks import ConvState, GateState, ResState, UpState, upsample_push, upsample_read
from models.networks.generator import LEVELS, GeneratorConfig, UNetGenerator


@dataclass
class StreamState:
    """Everything one causal U-Net needs between frames, for a batch of B streams.

    Row b of every tensor belongs to stream b (the streaming wrapper runs one row per
    active window). frame: frames consumed so far (all rows share it, so all rows
    share the pooling phase). enc/dec/up_conv/bottom: conv history ring buffers;
    pool_even[L]: level-L frame waiting for its odd partner before the max pool;
    ups[L]: last two frames of level L+1 for upsampling into level L; skips[L]:
    the newest level-L encoder frame. in_affine: the input standardisation as
    (scale, shift), None when the model has none.
    """

    frame: int
    enc: list[ResState]
    bottom: ResState
    up_conv: list[ConvState]
    gates: list[GateState | None]
    dec: list[ResState]
    head: ConvState
    pool_even: list[torch.Tensor]
    ups: list[UpState]
    skips: list[torch.Tensor]
    scratch: list[torch.Tensor]
    buffers: list[torch.Tensor] = field(default_factory=list)
    in_affine: tuple[torch.Tensor, torch.Tensor] | None = None

    def zero_rows(self, rows: slice | int | list[int]) -> None:
        """Reset the given streams to the zero state (buffers only; ``frame`` is shared)."""
        for b in self.buffers:
            b[rows] = 0.0


def _level_depth(n: int) -> int:
    """Deepest level that completes a frame at window-relative frame n (trailing zeros of n+1)."""
    m = n + 1
    return min(LEVELS, (m & -m).bit_length() - 1)


class CausalGenerator(UNetGenerator):
    """Causal U-Net generator, ``(B, D, T) -> (B, POSE_DIM, T)`` for any T, plus a streaming step."""

    def __init__(self, config: GeneratorConfig) -> None:
        if not config.causal:
            raise ConfigError("CausalGenerator needs a config with causal=True")
        super().__init__(config)

    @torch.no_grad()
    def init_stream_state(self, batch: int = 1) -> StreamState:
        """Zero state for ``batch`` independent streams, with eval-mode weights folded in."""
        c = self.config.channels
        z = [torch.zeros(batch, ch) for ch in c]
        head = ConvState(
            buf=None, pos=0, weight=self.head.weight.detach()[:, :, 0].contiguous(),
            bias=self.head.bias.detach().clone(),
        )
        st = StreamState(
            frame=0,
            enc=[m.init_state(batch) for m in self.enc],
            bottom=self.bottom.init_state(batch),
            up_conv=[m.init_state(batch) for m in self.up],
            gates=[g.init_state(batch) if self.config.attention else None for g in self.gate],
            dec=[m.init_state(batch) for m in self.dec],
            head=head,
            pool_even=[torch.zeros(batch, c[i]) for i in range(LEVELS)],
            ups=[UpState(prev=torch.zeros(batch, c[i + 1]), last=torch.zeros(batch, c[i + 1])) for i in range(LEVELS)],
            skips=z[:LEVELS],
            scratch=[torch.zeros(batch, c[i + 1]) for i in range(LEVELS)],
            in_affine=self.input_affine(),
        )
        convs = [cs for r in (*st.enc, st.bottom, *st.dec) for cs in r.convs] + st.up_conv
        st.buffers = [cs.buf for cs in convs if cs.buf is not None] + st.pool_even
        st.buffers += [t for u in st.ups for t in (u.prev, u.last)]
        return st

    @torch.inference_mode()
    def step(self, x: torch.Tensor, st: StreamState) -> torch.Tensor:
        """Advance every stream by one frame: x (B, D) features -> (B, POSE_DIM) poses."""
        n = st.frame
        st.frame = n + 1
        depth = _level_depth(n)
        h = x if st.in_affine is None else torch.addcmul(st.in_affine[1], x, st.in_affine[0])
        for level in range(LEVELS):
            s = self.enc[level].step(h, st.enc[level])
            st.skips[level] = s
            if level + 1 > depth:  # this level-L frame is even: hold it for the pool
                st.pool_even[level].copy_(s)
                break
            h = torch.maximum(st.pool_even[level], s)
        if depth == LEVELS:
            upsample_push(st.ups[LEVELS - 1], self.bottom.step(h, st.bottom))
        d = h
        for level in reversed(range(min(depth, LEVELS - 1) + 1)):
            fine = ((n + 1) >> level) - 1
            u = self.up[level].step(upsample_read(st.ups[level], fine, st.scratch[level]), st.up_conv[level])
            skip = st.skips[level]
            g = self.gate[level].step(skip, u, st.gates[level]) if self.config.attention else skip
            d = self.dec[level].step(torch.cat((u, g), dim=1), st.dec[level])
            if level > 0:
                upsample_push(st.ups[level - 1], d)
        y = torch.addmm(st.head.bias, d, st.head.weight.t())
        q = y[:, 3:].unflatten(1, (-1, 4))
        q.div_(q.norm(dim=-1, keepdim=True).clamp_min_(1e-6))
        return y
