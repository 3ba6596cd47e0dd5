"""Baselines: an LSTM audio-to-motion regressor and a plain U-Net.

Both map audio features (B, D, T) at 30 fps to poses (B, POSE_DIM, T) with the
same per-bone quaternion normalisation as the GAN generator.

* :class:`LSTMRegressor`, after the A2B model of Shlizerman et al., "Audio to Body
  Dynamics" (CVPR 2018): one LSTM layer then a linear layer. A2B predicts the pose of
  frame t from audio up to t + delay (a time delay). Here it is causal: output frame t
  is computed from audio frames <= t and stands for the pose of frame t - delay, so
  the motion lags the music by ``delay`` frames (``output_delay``); train it with
  ``loss(y[..., delay:], target[..., :T - delay])``. ``input_norm`` standardises the
  features first (BatchNorm1d without affine parameters, running statistics of the
  training set); configs/lstm_mfcc.toml uses it on the 28 MFCC features, whose c0
  spans O(1000), where the A2B code fed them unscaled.
* :func:`plain_unet`: the paper's U-Net shape with no residual identity paths and no
  attention gates (plain skip concatenation).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import torch
from torch import nn

from models.errors import ConfigError
from models.networks.causal import CausalGenerator
from models.networks.generator import GeneratorConfig, UNetGenerator, config_from_dict, init_pose_head, normalize_pose
from models.rig.motion import POSE_DIM


@dataclass(frozen=True)
class LSTMConfig:
    """feature_dim: D; pose_dim: POSE_DIM; hidden: LSTM units; delay: output lag in frames (>= 0);
    input_norm: standardise the input features (BatchNorm1d, no affine)."""

    feature_dim: int = 65
    pose_dim: int = POSE_DIM
    hidden: int = 256
    delay: int = 6
    input_norm: bool = False

    @property
    def causal(self) -> bool:
        return True

    def __post_init__(self) -> None:
        if self.feature_dim < 1 or self.hidden < 1 or self.delay < 0 or (self.pose_dim - 3) % 4:
            raise ConfigError(f"invalid LSTM config {self}")

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "LSTMConfig":
        return config_from_dict(cls, d)


class LSTMRegressor(nn.Module):
    """One-layer LSTM + linear, causal: (B, D, T) -> (B, POSE_DIM, T); frame t is pose t - delay."""

    def __init__(self, config: LSTMConfig) -> None:
        super().__init__()
        self.config = config
        self.output_delay = config.delay
        self.norm = nn.BatchNorm1d(config.feature_dim, affine=False) if config.input_norm else nn.Identity()
        self.lstm = nn.LSTM(config.feature_dim, config.hidden, num_layers=1, batch_first=True)
        self.head = nn.Conv1d(config.hidden, config.pose_dim, 1)
        init_pose_head(self.head)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if x.ndim != 3 or x.shape[1] != self.config.feature_dim:
            raise ConfigError(f"LSTM input must be (B, {self.config.feature_dim}, T), got {tuple(x.shape)}")
        h, _ = self.lstm(self.norm(x).transpose(1, 2))
        return normalize_pose(self.head(h.transpose(1, 2)))


def make_unet(config: GeneratorConfig) -> UNetGenerator:
    """A :class:`CausalGenerator` (streamable) if ``config.causal``, else an offline U-Net."""
    return CausalGenerator(config) if config.causal else UNetGenerator(config)


def plain_unet(config: GeneratorConfig | None = None) -> UNetGenerator:
    """Plain U-Net baseline: ``config`` (default: offline) with residual and attention off."""
    config = config or GeneratorConfig(causal=False)
    return make_unet(dataclasses.replace(config, residual=False, attention=False))
