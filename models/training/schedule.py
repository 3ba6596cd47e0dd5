"""Learning-rate schedules of :func:`models.training.train.train` (``TrainConfig.lr_schedule``).

* ``"constant"``: ``TrainConfig.lr`` at every step (the default; all configs but the
  violinist model's use it).
* ``"noam"``: the Transformer warm-up schedule of Vaswani et al. (2017), used by Kao &
  Su (2020) for the violinist model::

      lr(step) = d_model**-0.5 * min(step**-0.5, step * warmup_steps**-1.5),  step = 1, 2, ...

  It rises linearly for ``warmup_steps`` steps to ``(d_model * warmup_steps)**-0.5``,
  then decays as ``step**-0.5``. ``d_model`` is the model's width (``model.config.d_model``).
"""

from __future__ import annotations

from models.errors import ConfigError


def noam_lr(step: int, d_model: int, warmup_steps: int) -> float:
    """Learning rate of optimiser step ``step`` (1-based) under the Transformer schedule."""
    if step < 1 or d_model < 1 or warmup_steps < 1:
        raise ConfigError(f"noam schedule needs step, d_model, warmup_steps >= 1; got {step}, {d_model}, {warmup_steps}")
    return d_model**-0.5 * min(step**-0.5, step * warmup_steps**-1.5)


def learning_rate(schedule: str, step: int, base_lr: float, d_model: int | None, warmup_steps: int) -> float:
    """Learning rate of 1-based optimiser step ``step`` for a ``TrainConfig.lr_schedule``."""
    if schedule == "constant":
        return base_lr
    if schedule == "noam":
        if d_model is None:
            raise ConfigError("lr_schedule 'noam' needs a model with a d_model (its width); this model has none")
        return noam_lr(step, int(d_model), warmup_steps)
    raise ConfigError(f"unknown lr_schedule {schedule!r}")
