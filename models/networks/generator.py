"""The U-Net GAN generator of Chen et al., "A Music-driven Deep Generative Adversarial
Model for Guzheng Playing Animation" (IEEE TVCG 2021), and its configuration.

Input: audio features ``(B, D, T)`` at 30 fps (D = ``feature_dim``, 65 by default:
64 log-mel + onset). Output: poses ``(B, POSE_DIM, T)`` in the flat layout of
:mod:`models.rig.motion` (root xyz in metres, then one xyzw quaternion per bone,
each normalised to unit length).

Shape (level L runs at 30 / 2**L fps, widths ``channels = (c0, c1, c2, c3, c4)``)::

    encoder  L=0..3:  s_L = ResBlock(h -> c_L);  h = maxpool2(s_L)
    bottom   L=4:     d = ResBlock(c3 -> c4)
    decoder  L=3..0:  u = ConvBNReLU(upsample2(d) -> c_L)          (no transposed convs)
                      d = ResBlock(concat[u, gate(s_L, u)] -> c_L)
    output:           kernel-1 conv c0 -> POSE_DIM, per-bone quaternion normalisation

That is 4 encoder and 5 decoder residual blocks, as in the paper. The same class
builds the causal variant (``causal=True``, see :mod:`models.networks.causal` for its
streaming step) and the plain U-Net baseline (``residual=False, attention=False``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

from models.errors import ConfigError
from models.networks.blocks import AttentionGate, ConvBNAct, ResBlock, causal_upsample, offline_upsample
from models.rig.motion import POSE_DIM

LEVELS = 4  # pooling steps; T must be a multiple of 2**LEVELS = 16 offline


@dataclass(frozen=True)
class GeneratorConfig:
    """Hyper-parameters of the U-Net generators (all widths in channels).

    feature_dim: D, audio feature channels per frame.
    pose_dim: output channels (root xyz + 4 per bone); (pose_dim - 3) % 4 == 0.
    channels: (c0, c1, c2, c3, c4): widths of levels 0..3 and of the bottom level 4.
    kernel: conv kernel size (odd) in frames of the level it runs at.
    convs_per_block: convs stacked on each residual block's residual path.
    causal: output frame t depends on input frames <= t only; any T accepted.
    residual / attention: identity paths and attention gates (False, False = plain U-Net).
    gate_ratio: attention gate inner width = c_L // gate_ratio.
    dropout: training-only dropout probability on every encoder skip, the bottom and every
        decoder block output (0 = none; not in the paper). Eval mode, and so streaming,
        is unaffected.
    input_norm: standardise every input feature before the first block (not in the
        paper): a BatchNorm1d without affine parameters, batch statistics while
        training, its running mean/variance in eval mode, where it is a fixed
        per-feature ``(x - mean) / sqrt(var + eps)``. It is applied before any padding,
        so the causal convs' left zero padding and the streaming state's zero history
        both stand for the mean feature frame. Needed for inputs with wildly different
        column scales (MFCC c0 spans O(1000); MFCC column spreads differ by 35x).
    """

    feature_dim: int = 65
    pose_dim: int = POSE_DIM
    channels: tuple[int, ...] = (64, 96, 128, 160, 192)
    kernel: int = 3
    convs_per_block: int = 2
    causal: bool = True
    residual: bool = True
    attention: bool = True
    gate_ratio: int = 2
    dropout: float = 0.0
    input_norm: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "channels", tuple(int(c) for c in self.channels))
        if len(self.channels) != LEVELS + 1 or min(self.channels) < 1:
            raise ConfigError(f"channels must be {LEVELS + 1} positive widths, got {self.channels}")
        if self.feature_dim < 1 or self.pose_dim < 3 or (self.pose_dim - 3) % 4:
            raise ConfigError(
                f"need feature_dim >= 1 and pose_dim = 3 + 4*bones; got {self.feature_dim}, {self.pose_dim}"
            )
        if self.kernel < 1 or self.kernel % 2 == 0 or self.convs_per_block < 1 or self.gate_ratio < 1:
            raise ConfigError(f"kernel must be odd >= 1, convs_per_block and gate_ratio >= 1; got {self}")
        if not 0.0 <= self.dropout < 1.0:
            raise ConfigError(f"dropout must be in [0, 1), got {self.dropout}")
        if not isinstance(self.input_norm, bool):
            raise ConfigError(f"input_norm must be true or false, got {self.input_norm!r}")

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["channels"] = list(self.channels)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "GeneratorConfig":
        return config_from_dict(cls, d)


def config_from_dict(cls: type, d: dict[str, Any]) -> Any:
    """Build config dataclass ``cls`` from a dict; ConfigError naming any unknown keys."""
    unknown = set(d) - {f.name for f in dataclasses.fields(cls)}
    if unknown:
        raise ConfigError(f"unknown {cls.__name__} keys {sorted(unknown)}")
    return cls(**d)


def normalize_pose(y: torch.Tensor, dim: int = 1, eps: float = 1e-6) -> torch.Tensor:
    """Unit-normalise every xyzw quaternion of a pose tensor; root xyz untouched.

    y: poses with channel axis ``dim`` of size 3 + 4J. A quaternion with norm < eps is
    divided by eps (training keeps gradients finite); use
    :func:`models.networks.blend.sanitize_quaternions` where exact unit norm matters.
    """
    y = y.movedim(dim, -1)
    root, q = y[..., :3], y[..., 3:]
    q = q.unflatten(-1, (-1, 4))
    q = q / q.norm(dim=-1, keepdim=True).clamp_min(eps)
    return torch.cat((root, q.flatten(-2)), dim=-1).movedim(-1, dim)


def init_pose_head(conv: nn.Conv1d) -> None:
    """Start the output near the rest pose: small weights, bias = identity quaternions."""
    with torch.no_grad():
        conv.weight.mul_(0.1)
        conv.bias.zero_()
        conv.bias[3 + 3 :: 4] = 1.0  # w component of every bone


class UNetGenerator(nn.Module):
    """The paper's U-Net generator (see module docstring); ``(B, D, T) -> (B, POSE_DIM, T)``.

    Offline (``causal=False``) T must be a multiple of 16. Causal: any T; the input is
    zero-padded on the right to a multiple of 16 and the output cropped, which
    changes nothing because no output frame reads later input frames.
    """

    output_delay: int = 0  # output frame t is the pose of music frame t - output_delay

    def __init__(self, config: GeneratorConfig) -> None:
        super().__init__()
        self.config = cfg = config
        c, k, causal = cfg.channels, cfg.kernel, cfg.causal

        def res(a: int, b: int) -> ResBlock:
            return ResBlock(a, b, k, causal=causal, n_convs=cfg.convs_per_block, residual=cfg.residual)

        self.in_norm = nn.BatchNorm1d(cfg.feature_dim, affine=False) if cfg.input_norm else None
        ins = [cfg.feature_dim, *c[: LEVELS - 1]]
        self.enc = nn.ModuleList(res(ins[i], c[i]) for i in range(LEVELS))
        self.bottom = res(c[LEVELS - 1], c[LEVELS])
        # Decoder modules are indexed by the level L they produce (0 = full rate).
        self.up = nn.ModuleList(ConvBNAct(c[i + 1], c[i], k, causal=causal) for i in range(LEVELS))
        self.gate = nn.ModuleList(
            AttentionGate(c[i], c[i], max(1, c[i] // cfg.gate_ratio)) if cfg.attention else nn.Identity()
            for i in range(LEVELS)
        )
        self.dec = nn.ModuleList(res(2 * c[i], c[i]) for i in range(LEVELS))
        self.head = nn.Conv1d(c[0], cfg.pose_dim, 1)
        init_pose_head(self.head)

    def input_affine(self) -> tuple[torch.Tensor, torch.Tensor] | None:
        """Eval-mode input standardisation as ``x * scale + shift`` (each (D,)), None without it."""
        if self.in_norm is None:
            return None
        n = self.in_norm
        scale = torch.rsqrt(n.running_var.detach() + n.eps)
        return scale, -n.running_mean.detach() * scale

    def _upsample(self, u: torch.Tensor) -> torch.Tensor:
        return causal_upsample(u) if self.config.causal else offline_upsample(u)

    def _gated(self, level: int, skip: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        return self.gate[level](skip, u) if self.config.attention else skip

    def _dropout(self, h: torch.Tensor) -> torch.Tensor:
        """Training-mode dropout of ``config.dropout``; the identity otherwise (no RNG draw)."""
        p = self.config.dropout
        return F.dropout(h, p, training=True) if self.training and p > 0 else h

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        cfg = self.config
        if x.ndim != 3 or x.shape[1] != cfg.feature_dim:
            raise ConfigError(f"generator input must be (B, {cfg.feature_dim}, T), got {tuple(x.shape)}")
        if self.in_norm is not None:
            x = self.in_norm(x)
        t = x.shape[-1]
        mult = 2**LEVELS
        if t % mult:
            if not cfg.causal:
                raise ConfigError(f"the offline generator needs T a multiple of {mult}, got T={t}")
            x = F.pad(x, (0, mult - t % mult))
        drop = self._dropout
        skips = []
        h = x
        for enc in self.enc:
            s = drop(enc(h))
            skips.append(s)
            h = F.max_pool1d(s, 2)
        d = drop(self.bottom(h))
        for level in reversed(range(LEVELS)):
            u = self.up[level](self._upsample(d))
            d = drop(self.dec[level](torch.cat((u, self._gated(level, skips[level], u)), dim=1)))
        return normalize_pose(self.head(d))[..., :t]


def count_parameters(model: nn.Module) -> int:
    """Number of trainable parameters."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)


def paper_config(**overrides: Any) -> GeneratorConfig:
    """The offline paper generator's config (non-causal), with optional overrides."""
    return GeneratorConfig(**{"causal": False, **overrides})


__all__ = ["GeneratorConfig", "UNetGenerator", "normalize_pose", "count_parameters", "paper_config", "LEVELS"]
