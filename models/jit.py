"""Compile the live path's numba kernels ahead: ``python -m models.jit`` (``make setup`` runs it).

The kernels (the banded log-mel in :mod:`models.features.spectral`, the beat tracker in
:mod:`models.features.context`, the dance_vq code step in
:mod:`models.networks.dance_jit`, the engine's pose guard in :mod:`realtime.pose_jit`)
compile on their first call, about 4 s on a 2-core
machine, and keep the machine code in ``__pycache__`` (numba's ``cache=True``): a later
process loads it in milliseconds. Run once after an install or an edit of a kernel's
module, so that the first ``performer run`` does not spend that time in its warm-up.
It compiles them by what the engine does: the default checkpoint's extractor and model
fed 2 s of noise at 44.1 kHz, so every kernel gets the argument types it will see live.
"""

from __future__ import annotations

import time

import numpy as np


def compile_live_kernels(checkpoint: str | None = None, input_sr: int = 44100) -> float:
    """Run the default (or ``checkpoint``'s) extractor and pose model on 2 s of noise; seconds taken."""
    from realtime.engine import PoseSmoother, rest_pose
    from realtime.pipeline import build_pipeline

    t0 = time.perf_counter()
    pipe = build_pipeline(checkpoint)
    extractor = pipe.extractor_factory(input_sr)
    noise = (0.1 * np.random.default_rng(0).standard_normal((2 * input_sr, 2))).astype(np.float32)
    feats = extractor.push(noise)
    pipe.model.push(feats)
    pipe.model.push(feats[:1])  # one frame a push, as the engine pushes: its own kernels
    PoseSmoother(0.5)(rest_pose())  # the engine's guard and smoothing (realtime/pose_jit.py)
    return time.perf_counter() - t0


def main() -> int:
    took = compile_live_kernels()
    print(f"live-path kernels compiled and cached ({took:.1f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
