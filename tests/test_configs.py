"""Every training config under configs/ and configs/experiments/ loads, and the commands
documented in it can be rerun; configs/README.md lists them all.

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

REPO = Path(__file__).resolve().parents[1]
#: The shipped and baseline models' configs at the top level, the tried ones under experiments/.
TOP = sorted((REPO / "configs").glob("*.toml"))
EXPERIMENTS = sorted((REPO / "configs" / "experiments").glob("*.toml"))
CONFIGS = TOP + EXPERIMENTS


def _id(path: Path) -> str:
    return str(path.relative_to(REPO / "configs"))


def test_there_are_configs() -> None:
    assert len(TOP) >= 10 and len(EXPERIMENTS) >= 10


def test_readme_has_one_line_per_config() -> None:
    """configs/README.md names every config once, in a table row of its own, with a doc link;
    every config path it names exists."""
    readme = (REPO / "configs" / "README.md").read_text()
    rows = [line for line in readme.splitlines() if line.startswith("| `")]
    named = [re.match(r"\| `([^`]+\.toml)`", row).group(1) for row in rows]
    assert sorted(named) == sorted(_id(p) for p in CONFIGS)
    for row in rows:
        links = re.findall(r"\]\((\.\./docs/[^)#]+\.md)(?:#[^)]*)?\)", row)
        assert links or "no result" in row, f"configs/README.md: no doc link in {row[:60]}..."
        for link in links:
            assert (REPO / "configs" / link).resolve().is_file(), f"configs/README.md links {link}"


@pytest.mark.parametrize("path", CONFIGS, ids=_id)
def test_config_loads(path: Path) -> None:
    cfg = TrainConfig.from_toml(path)
    FeatureConfig(**cfg.features)  # raises on an unknown kind or a bad option


@pytest.mark.parametrize("path", CONFIGS, ids=_id)
def test_config_does_not_start_from_the_shipped_default(path: Path) -> None:
    """models/assets/default.pt is replaced when a better model ships; a run documented as
    starting from it would then start from another model. Configs name a run's output."""
    cfg = TrainConfig.from_toml(path)
    assert not (cfg.init_from and "models/assets" in str(cfg.init_from)), (
        f"{_id(path)}: init_from = {cfg.init_from!r} points at a shipped file; use the run "
        "that produced it (runs/NAME/best.pt)"
    )


@pytest.mark.parametrize("path", CONFIGS, ids=_id)
def test_documented_command_names_this_config(path: Path) -> None:
    """A `performer train --config configs/X.toml` line in a config's header names the file itself
    or another existing config (chains quote their first run's command)."""
    for match in re.finditer(r"performer train --config (configs/\S+\.toml)", path.read_text()):
        assert (REPO / match.group(1)).is_file(), f"{_id(path)} cites {match.group(1)}"


def test_every_config_path_named_in_the_repo_exists() -> None:
    """Docs, configs' comments and code cite configs by path (configs/X.toml or
    configs/experiments/X.toml); a moved or renamed config must take its citations along."""
    texts = [REPO / "README.md", *(REPO / "docs").glob("*.md"), *CONFIGS, *(REPO / "configs").glob("*.md")]
    for folder in ("realtime", "models", "benchmarks", "tests"):
        texts += (REPO / folder).rglob("*.py")
    cited = {}
    for path in texts:
        # config names are lower case; configs/X.toml in this file's docstrings is a placeholder
        for name in re.findall(r"(?<![\w/])configs/[a-z0-9_/]+\.toml", path.read_text(encoding="utf-8")):
            cited.setdefault(name, path.relative_to(REPO))
    assert len(cited) >= 20
    missing = {name: str(where) for name, where in cited.items() if not (REPO / name).is_file()}
    assert not missing, f"cited config paths that do not exist (path: first file citing it): {missing}"
