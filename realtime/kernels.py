"""The live path's numba kernels: compiled, or loaded from numba's cache, before the first frame.

The kernels (the banded log-mel in :mod:`models.features.spectral`, the beat tracker in
:mod:`models.features.context`, the steadiness column in :mod:`models.features.steadiness`,
the dance_vq code step in :mod:`models.networks.dance_jit`,
the engine's pose guard in :mod:`realtime.pose_jit`) compile on their first call and keep
the machine code in numba's cache (``__pycache__`` beside each module, or
``$NUMBA_CACHE_DIR``): a later process loads it in milliseconds. The engine's warm-up
(:meth:`realtime.engine.Engine._warm_up`: noise, then silence) calls every one of them
with the argument types it sees live, so none compiles inside a streamed frame.

* :func:`uncached_kernels` names the kernels the cache does not hold yet (a first run:
  ``performer run`` then says that it is compiling them);
* ``python -m realtime.kernels [--checkpoint CKPT]`` (``make setup``) runs that warm-up
  once ahead, on the default (or given) checkpoint, so that the first ``performer run``
  loads the kernels instead of compiling them.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

#: Packages whose modules' kernels :func:`uncached_kernels` looks at.
PACKAGES: tuple[str, ...] = ("models", "realtime")


def _live_dispatchers() -> list:
    """Every cached numba kernel (``@njit(cache=True)``) of an imported module of :data:`PACKAGES`,
    but those numba inlines into their callers (``inline="always"``, models/networks/feet.py's
    quaternion helpers): their code lives in the callers' cache entries, never in their own, so
    they would read as uncached forever (every run announcing a compile, ``make setup``'s
    ``python -m realtime.kernels`` failing)."""
    if "numba" not in sys.modules:
        return []
    from numba.core.dispatcher import Dispatcher

    found, seen = [], set()
    for name, module in list(sys.modules.items()):
        if module is None or name.split(".")[0] not in PACKAGES:
            continue
        for obj in list(vars(module).values()):
            if isinstance(obj, Dispatcher) and id(obj) not in seen and type(obj._cache).__name__ != "NullCache" \
                    and obj.targetoptions.get("inline") != "always":
                seen.add(id(obj))
                found.append(obj)
    return found


def _cached(dispatcher) -> bool:
    """Whether numba's cache holds machine code of ``dispatcher`` for its current source."""
    try:
        return bool(dispatcher._cache._cache_file._load_index())  # {} when absent or stale
    except Exception:  # noqa: BLE001 - numba's private cache API: a change there must not stop a run
        return True


def uncached_kernels() -> list[str]:
    """``module.function`` of every kernel of the imported project modules that numba's cache
    does not hold for its current source: each compiles on its first call."""
    return sorted(f"{d.py_func.__module__}.{d.py_func.__qualname__}" for d in _live_dispatchers() if not _cached(d))


def compile_live_kernels(checkpoint: str | Path | None = None, sample_rate: int = 44100) -> float:
    """Warm an engine up on the default (or ``checkpoint``'s) pipeline as ``performer run`` does,
    then stream 1 s of noise at ``sample_rate`` Hz through it; seconds taken."""
    from realtime.audio_input import FileSource
    from realtime.engine import Engine
    from realtime.engine_config import EngineConfig
    from realtime.pipeline import build_pipeline

    t0 = time.perf_counter()
    pipe = build_pipeline(checkpoint)
    noise = (0.1 * np.random.default_rng(0).standard_normal(sample_rate)).astype(np.float32)
    engine = Engine(FileSource(noise, sample_rate, name="noise", realtime=False), pipe.extractor_factory,
                    pipe.model, [], EngineConfig(warmup_s=0.5))
    try:
        engine.start()
        engine.wait()  # re-raises what failed on the worker
    finally:
        engine.close()
    compile_unreached_kernels()
    return time.perf_counter() - t0


def compile_unreached_kernels() -> None:
    """Compile the kernels a live path may use that a warm-up of the shipped default does not
    reach: the logistic music gate's, which checkpoints without a presence detector run on
    every frame of sound (the default's detector does not call it), with the argument types
    ``DanceStream._gate`` passes; the lead's beat forecast, which only ``--lead`` calls (the
    warm-up runs at lead 0). Milliseconds when numba's cache holds them."""
    from models.networks.dance_jit import gate_ema
    from models.networks.lead import PhaseForecast

    cols = np.arange(3, dtype=np.int64)
    gate_ema(np.zeros(8, np.float32), cols, np.zeros(3), np.ones(3), np.zeros(3), 0.9)
    PhaseForecast().phase(4, 15.0)


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m realtime.kernels", description=__doc__.split("\n")[0])
    p.add_argument("--checkpoint", metavar="CKPT", help="model checkpoint (default: the packaged one)")
    args = p.parse_args(argv)
    took = compile_live_kernels(args.checkpoint)
    left = uncached_kernels()
    print(f"live-path kernels compiled and cached ({took:.1f} s)" + (f"; not cached: {', '.join(left)}" if left else ""))
    return 1 if left else 0


if __name__ == "__main__":
    raise SystemExit(main())
