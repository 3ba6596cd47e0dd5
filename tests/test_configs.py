"""Every training config under configs/ loads, and the commands documented in it can be rerun.

docs/training.md cites these files with the command that trained each run, so a config
that no longer parses, or one whose starting checkpoint changes when the shipped default
is replaced, would silently break the documented reproduction.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from models.features.spectral import FeatureConfig
from models.training.config import TrainConfig

CONFIGS = sorted((Path(__file__).resolve().parents[1] / "configs").glob("*.toml"))


def test_there_are_configs() -> None:
    assert len(CONFIGS) >= 10


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.name)
def test_config_loads(path: Path) -> None:
    cfg = TrainConfig.from_toml(path)
    FeatureConfig(**cfg.features)  # raises on an unknown kind or a bad option


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.name)
def test_config_does_not_start_from_the_shipped_default(path: Path) -> None:
    """models/assets/default.pt is replaced when a better model ships; a run documented as
    starting from it would then start from another model. Configs name a run's output."""
    cfg = TrainConfig.from_toml(path)
    assert not (cfg.init_from and "models/assets" in str(cfg.init_from)), (
        f"{path.name}: init_from = {cfg.init_from!r} points at a shipped file; use the run "
        "that produced it (runs/NAME/best.pt)"
    )


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.name)
def test_documented_command_names_this_config(path: Path) -> None:
    """A `performer train --config configs/X.toml` line in a config's header names the file itself
    or another existing config (chains quote their first run's command)."""
    for match in re.finditer(r"performer train --config (configs/\S+\.toml)", path.read_text()):
        assert (path.parents[1] / match.group(1)).is_file(), f"{path.name} cites {match.group(1)}"
