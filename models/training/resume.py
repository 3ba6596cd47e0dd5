"""A training run's ``state.pt``: everything needed to resume it exactly where it stopped.

Every trainer (``train.py``, ``dtm.py``, ``gcn_train.py``) saves its networks and
optimisers (``parts``: name -> object with ``state_dict()``/``load_state_dict()``), the
NumPy and torch random states, and a few values of its own (``step`` and the like)
whenever it writes ``last.pt``, and restores them when ``OUT/state.pt`` exists.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch


def save_state(path: str | Path, parts: Mapping[str, Any], rng: np.random.Generator, **values: Any) -> None:
    """Write ``path`` atomically (a temporary file renamed over it, so an interrupted save
    leaves the previous state): every part's ``state_dict()``, both random states, ``values``."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    torch.save({**{name: p.state_dict() for name, p in parts.items()}, **values,
                "rng": rng.bit_generator.state, "torch_rng": torch.get_rng_state()}, tmp)
    os.replace(tmp, path)


def load_state(path: str | Path, parts: Mapping[str, Any], rng: np.random.Generator) -> dict[str, Any]:
    """Restore what :func:`save_state` wrote into ``parts`` and the random states; returns
    the saved dict, whose other keys are the ``values`` (``step``, ...)."""
    st = torch.load(path, weights_only=False)
    for name, p in parts.items():
        p.load_state_dict(st[name])
    rng.bit_generator.state = st["rng"]
    torch.set_rng_state(st["torch_rng"])
    return st


def resume_or_start(state_path: str | Path, parts: Mapping[str, Any], rng: np.random.Generator, runlog) -> dict:
    """Resume from ``state_path`` if it exists (its log cut back to the saved step), else
    start ``runlog`` afresh. Returns the saved values (``{"step": 0}`` for a new run)."""
    if not Path(state_path).exists():
        runlog.start()
        return {"step": 0}
    st = load_state(state_path, parts, rng)
    runlog.start(resume_step=st["step"])  # drops rows logged after the saved state
    print(f"resuming from step {st['step']} ({state_path})")
    return st
