"""Test helpers: a tone-burst test signal and streaming a signal in random block sizes."""

from __future__ import annotations

import numpy as np

from models.timebase import SAMPLE_RATE


def music(seconds: float, sr: int = SAMPLE_RATE, seed: int = 0) -> np.ndarray:
    """440 Hz bursts switching at 2 Hz plus faint noise, float32 at ``sr`` Hz: clear onsets."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * sr)) / sr
    env = (np.sin(2 * np.pi * 2 * t) > 0).astype(float)
    return (0.3 * env * np.sin(2 * np.pi * 440 * t) + 0.02 * rng.standard_normal(t.size)).astype(np.float32)


def stream_in_random_blocks(extractor, x: np.ndarray, seed: int = 0, max_block: int = 3000) -> np.ndarray:
    """Push ``x`` through a StreamingFeatureExtractor in random blocks of 1..max_block-1
    samples, then flush; returns every emitted feature row, (T, D)."""
    rng = np.random.default_rng(seed)
    out, lo = [], 0
    while lo < x.size:
        n = int(rng.integers(1, max_block))
        out.append(extractor.push(x[lo : lo + n]))
        lo += n
    out.append(extractor.flush())
    return np.concatenate(out)
