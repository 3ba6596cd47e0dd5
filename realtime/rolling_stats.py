"""Percentiles of the last N values of one measurement: the engine's compute and latency buffers.

State: a preallocated ring of float64 values and how many were added.
"""

from __future__ import annotations

import numpy as np


class RollingStats:
    """Last ``size`` values of one measurement, preallocated, for percentiles."""

    def __init__(self, size: int = 2048) -> None:
        self._buf = np.zeros(size, dtype=np.float64)
        self._n = 0

    def add(self, value: float) -> None:
        self._buf[self._n % len(self._buf)] = value
        self._n += 1

    def clear(self) -> None:
        self._n = 0

    @property
    def count(self) -> int:
        return self._n

    def values(self) -> np.ndarray:
        return self._buf[: min(self._n, len(self._buf))].copy()

    def percentile(self, q: float) -> float:
        """q-th percentile of the kept values (NaN when empty)."""
        vals = self._buf[: min(self._n, len(self._buf))]
        return float(np.percentile(vals, q)) if len(vals) else float("nan")
