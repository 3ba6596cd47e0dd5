"""Training configuration: one TOML file, every field with a default.

Example (``configs/default.toml`` style)::

    model = "causal"             # causal | unet_gan | unet_plain | lstm
    seed = 0
    stage1_steps = 3000          # regression losses only
    stage2_steps = 1500          # regression + GAN
    [model_config]               # the model's own config fields
    channels = [32, 48, 64, 96, 128]
    [features]                   # models.features.spectral.FeatureConfig fields
    n_mels = 64
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from models.errors import ConfigError

LR_SCHEDULES: tuple[str, ...] = ("constant", "noam")


@dataclass
class TrainConfig:
    """Hyper-parameters of :func:`models.training.train.train` (paper values where given)."""

    model: str = "causal"
    model_config: dict[str, Any] = field(default_factory=dict)
    features: dict[str, Any] = field(default_factory=dict)
    seed: int = 0
    segment: int = 128  # frames per training segment (4.27 s at 30 fps)
    batch_size: int = 16
    lr: float = 1e-4  # Adam, as in the paper
    beta1: float = 0.5
    # "constant": lr throughout. "noam": the Transformer warm-up schedule (Vaswani et al. 2017),
    # lr = d_model**-0.5 * min(step**-0.5, step * warmup_steps**-1.5) with the model's d_model;
    # ``lr`` is then unused (models/training/schedule.py).
    lr_schedule: str = "constant"
    warmup_steps: int = 500
    stage1_steps: int = 3000
    stage2_steps: int = 1500
    w_rot: float = 100.0
    w_fk: float = 100.0
    w_gan: float = 1.0
    w_vel: float = 0.0  # velocity L1 (rotations + end effectors); not in the paper, see docs/training.md
    w_acc: float = 0.0  # acceleration L1 (rotations + end effectors); not in the paper, see docs/training.md
    # Beat loss: mean joint speed on the beats the causal beat-phase feature columns predict,
    # over the mean speed (losses.beat_speed_ratio); needs features.beat_phase. Not in the paper.
    w_beat: float = 0.0
    init_from: str | None = None  # start from this checkpoint's weights (fine-tuning)
    # Exponential moving average of the generator's weights (and batch-norm statistics), per
    # step; 0 = off. When on, validation, best.pt and last.pt use the averaged weights.
    ema_decay: float = 0.0
    # Train only the generator parameters whose names start with one of these prefixes
    # (e.g. ["head"] or ["head.bias"]); every other parameter stays frozen and every
    # batch-norm layer with no trainable parameter runs in eval mode (its running
    # statistics are kept). Empty = train everything.
    train_only: list[str] = field(default_factory=list)
    disc_width: int = 64
    # The discriminator also sees velocities and accelerations of the poses (DiscriminatorConfig.motion)
    disc_motion: bool = False
    tempos: list[float] = field(default_factory=lambda: [0.75, 0.875, 1.0, 1.125, 1.25])
    exclude_unverified: bool = True  # train only on dances whose audio alignment is verified
    eval_every: int = 250
    threads: int = 2
    dtm: dict[str, Any] = field(default_factory=dict)  # model "dtm": loss weights etc. (models.training.dtm)
    dance: dict[str, Any] = field(default_factory=dict)  # model "dance_vq": options (models.training.dance_vq)

    @property
    def total_steps(self) -> int:
        return self.stage1_steps + self.stage2_steps

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any], source: str | None = None) -> "TrainConfig":
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ConfigError(f"unknown training config key(s) {unknown}; known: {sorted(known)}", source=source)
        defaults = cls()
        for name, v in d.items():  # the type of each default, so a typo never trains silently
            want = getattr(defaults, name)
            if name == "init_from":
                ok = v is None or isinstance(v, str)
            elif isinstance(want, bool):
                ok = isinstance(v, bool)
            elif isinstance(want, float):
                ok = isinstance(v, (int, float)) and not isinstance(v, bool) and not (
                    isinstance(v, float) and not math.isfinite(v))
            else:
                ok = isinstance(v, type(want)) and not isinstance(v, bool)
            if not ok:
                raise ConfigError(f"{name} must be {type(want).__name__}, got {type(v).__name__} {v!r:.60}",
                                  source=source)
        if not all(isinstance(t, (int, float)) and not isinstance(t, bool) for t in d.get("tempos", [])):
            raise ConfigError(f"tempos must be a list of numbers, got {d['tempos']!r:.60}", source=source)
        if not all(isinstance(t, str) and t for t in d.get("train_only", [])):
            raise ConfigError(f"train_only must be a list of parameter-name prefixes, got {d['train_only']!r:.60}",
                              source=source)
        cfg = cls(**d)
        for name in ("segment", "batch_size", "stage1_steps", "stage2_steps", "eval_every", "threads", "warmup_steps"):
            v = getattr(cfg, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < (0 if name in ("stage1_steps", "stage2_steps") else 1):
                raise ConfigError(f"{name} must be a positive integer, got {v!r}", source=source)
        if not 0.0 <= cfg.ema_decay < 1.0:
            raise ConfigError(f"ema_decay must be in [0, 1), got {cfg.ema_decay!r}", source=source)
        if cfg.lr_schedule not in LR_SCHEDULES:
            raise ConfigError(f"lr_schedule must be one of {LR_SCHEDULES}, got {cfg.lr_schedule!r:.60}", source=source)
        from models.networks.checkpoint import MODELS  # the registry (imports torch); checked before any data work

        if cfg.model not in MODELS:
            raise ConfigError(f"model must be one of {sorted(MODELS)}, got {cfg.model!r:.60}", source=source)
        if cfg.total_steps < 1:
            raise ConfigError("stage1_steps + stage2_steps must be at least 1", source=source)
        if cfg.segment % 16:
            raise ConfigError(f"segment must be a multiple of 16 frames, got {cfg.segment}", source=source)
        if not all(0.5 <= t <= 2.0 for t in cfg.tempos) or not cfg.tempos:
            raise ConfigError(f"tempos must be factors in [0.5, 2], got {cfg.tempos}", source=source)
        if cfg.features.get("steadiness"):  # a column for the idle gate alone, added to a trained dance_vq checkpoint
            raise ConfigError("features.steadiness is not for training: add the steadiness column to a trained "
                              "dance_vq checkpoint (python -m models.training.music_gate --steadiness)", source=source)
        return cfg

    @classmethod
    def from_toml(cls, path: str | Path) -> "TrainConfig":
        path = Path(path)
        if not path.is_file():
            raise ConfigError("training config not found", source=path)
        try:
            data = tomllib.loads(path.read_text())
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
            raise ConfigError(f"not valid TOML ({e})", source=path) from None
        except RecursionError:
            raise ConfigError("not valid TOML (nested too deeply)", source=path) from None
        return cls.from_dict(data, source=str(path))
