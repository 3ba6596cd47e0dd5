"""Helpers for the live streams' tests."""

from __future__ import annotations

import numpy as np


def push_in_chunks(stream, x: np.ndarray, seed: int = 0, most: int = 20) -> np.ndarray:
    """``stream.push`` over the rows of ``x`` in random chunks of 0..``most - 1`` rows (the
    generator seeded with ``seed``), the poses concatenated: what a live run hands over."""
    rng = np.random.default_rng(seed)
    parts, i = [], 0
    while i < len(x):
        k = int(rng.integers(0, most))
        parts.append(stream.push(x[i: i + k]))
        i += k
    return np.concatenate(parts)
