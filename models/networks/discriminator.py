"""Multi-scale patch discriminator of Chen et al. (TVCG 2021) for (audio, motion) pairs.

Input: audio features (B, D, T) and poses (B, POSE_DIM, T) at 30 fps, concatenated
along channels. Four sub-discriminators see patches of exactly 1, 12, 48 and 128
frames (their receptive fields); each is 4, 3, 5 and 5 conv1d + BatchNorm + ReLU
layers, then a kernel-1 conv to one score per patch (a score gets no BN/ReLU; the
projection does not widen the receptive field). Convs are unpadded ("valid"), so
every patch score sees real frames only and T must be >= 128.

Layer (kernel, stride) per sub-discriminator; receptive field
RF = 1 + sum_i (k_i - 1) * prod_{j<i} s_j::

    RF   1: (1,1) (1,1) (1,1) (1,1)          one patch per frame
    RF  12: (4,1) (5,1) (5,1)                one patch per frame
    RF  48: (3,1) (4,2) (4,2) (4,2) (4,1)    one patch every 8 frames
    RF 128: (4,2) (3,2) (3,2) (5,2) (6,1)    one patch every 16 frames

Averaging: ``forward`` returns the four patch maps (B, N_i) (use them for per-patch
losses); :func:`mean_score` is the mean over the four sub-discriminators of each
map's mean over its patches, so every scale counts equally whatever its patch count.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from models.errors import ConfigError
from models.rig.motion import POSE_DIM

SUB_LAYERS: tuple[tuple[tuple[int, int], ...], ...] = (
    ((1, 1), (1, 1), (1, 1), (1, 1)),
    ((4, 1), (5, 1), (5, 1)),
    ((3, 1), (4, 2), (4, 2), (4, 2), (4, 1)),
    ((4, 2), (3, 2), (3, 2), (5, 2), (6, 1)),
)
RECEPTIVE_FIELDS: tuple[int, ...] = (1, 12, 48, 128)
#: Scales of the velocity and acceleration channels (config ``motion``): per-frame differences
#: of the pose vector are ~0.01-0.05, so these bring them to the poses' order of magnitude.
MOTION_SCALES: tuple[float, float] = (10.0, 30.0)


def receptive_field(layers: tuple[tuple[int, int], ...]) -> int:
    """Frames seen by one output of a stack of (kernel, stride) convs."""
    rf, jump = 1, 1
    for k, s in layers:
        rf += (k - 1) * jump
        jump *= s
    return rf


@dataclass(frozen=True)
class DiscriminatorConfig:
    """feature_dim: D; pose_dim: POSE_DIM; width: channels of every hidden layer.

    motion: also feed the pose's velocity and acceleration (first and second differences
    per frame, scaled by :data:`MOTION_SCALES`, the first frame's repeated), so every
    patch judges how the pose moves as well as where it is (not in the paper; issue 18).
    """

    feature_dim: int = 65
    pose_dim: int = POSE_DIM
    width: int = 64
    motion: bool = False


class SubDiscriminator(nn.Module):
    """conv1d+BN+ReLU layers (valid padding) then a kernel-1 score conv: (B, C, T) -> (B, N)."""

    def __init__(self, c_in: int, width: int, layers: tuple[tuple[int, int], ...]) -> None:
        super().__init__()
        mods: list[nn.Module] = []
        for k, s in layers:
            mods += [nn.Conv1d(c_in, width, k, stride=s, bias=False), nn.BatchNorm1d(width), nn.ReLU()]
            c_in = width
        mods.append(nn.Conv1d(width, 1, 1))
        self.net = nn.Sequential(*mods)
        self.receptive_field = receptive_field(layers)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)[:, 0]


class MultiScaleDiscriminator(nn.Module):
    """Four patch discriminators with receptive fields 1, 12, 48, 128 frames."""

    def __init__(self, config: DiscriminatorConfig | None = None) -> None:
        super().__init__()
        self.config = cfg = config or DiscriminatorConfig()
        c_in = cfg.feature_dim + cfg.pose_dim * (3 if cfg.motion else 1)
        self.subs = nn.ModuleList(SubDiscriminator(c_in, cfg.width, layers) for layers in SUB_LAYERS)

    def forward(self, features: torch.Tensor, motion: torch.Tensor) -> list[torch.Tensor]:
        """features (B, D, T), motion (B, POSE_DIM, T) -> four patch-score maps (B, N_i)."""
        cfg = self.config
        if features.shape[1] != cfg.feature_dim or motion.shape[1] != cfg.pose_dim:
            raise ConfigError(
                f"discriminator wants (B, {cfg.feature_dim}, T) features and (B, {cfg.pose_dim}, T) motion; "
                f"got {tuple(features.shape)} and {tuple(motion.shape)}"
            )
        if features.shape[-1] != motion.shape[-1] or motion.shape[-1] < max(RECEPTIVE_FIELDS):
            raise ConfigError(
                f"discriminator needs equal lengths >= {max(RECEPTIVE_FIELDS)} frames; "
                f"got {features.shape[-1]} and {motion.shape[-1]}"
            )
        if cfg.motion:
            v = torch.diff(motion, dim=-1, prepend=motion[..., :1])
            a = torch.diff(v, dim=-1, prepend=v[..., :1])
            motion = torch.cat((motion, MOTION_SCALES[0] * v, MOTION_SCALES[1] * a), dim=1)
        x = torch.cat((features, motion), dim=1)
        return [sub(x) for sub in self.subs]


def mean_score(maps: list[torch.Tensor]) -> torch.Tensor:
    """(B,) mean over sub-discriminators of each patch map's mean over patches."""
    return torch.stack([m.mean(dim=-1) for m in maps]).mean(dim=0)
