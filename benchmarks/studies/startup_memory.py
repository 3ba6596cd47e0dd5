"""Where a performer's start-up memory goes: peak RSS (VmHWM, MB) and seconds of each step.

Loads the checkpoint, applies ``--library`` if given (``models.generate.load_library_model``),
then builds the stream's shared tables one by one (``models/networks/dance_stream.py``: the
smoothed exemplars, the predictor, the member tables of one FK pass, the bone cap) and a
``DanceStream``. Before each step the process's peak is reset (``/proc/self/clear_refs``, 5),
so each row shows the RSS before it, its own peak, and the RSS after it (what it keeps, plus
what the allocator kept). Linux only. One torch thread, as a performer runs::

    nice -n 5 .venv/bin/python benchmarks/studies/startup_memory.py
    nice -n 5 .venv/bin/python benchmarks/studies/startup_memory.py --library big.npz
    nice -n 5 .venv/bin/python benchmarks/studies/startup_memory.py --checkpoint /tmp/big.pt

(docs/library.md, "A 30-minute library", says how to make one.)
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path


def _status() -> tuple[int, int]:
    """(VmHWM, VmRSS) of this process, MB."""
    d = dict(line.split(":", 1) for line in Path("/proc/self/status").read_text().splitlines() if ":" in line)
    return int(d["VmHWM"].split()[0]) // 1024, int(d["VmRSS"].split()[0]) // 1024


def _step(name: str, fn):
    Path("/proc/self/clear_refs").write_text("5")  # the peak (VmHWM) starts again from the RSS now
    before, t = _status()[1], time.perf_counter()
    out = fn()
    peak, after = _status()
    print(f"| {name} | {before} | {peak} (+{peak - before}) | {after} | {time.perf_counter() - t:.2f} |", flush=True)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--checkpoint", help="a dance_vq checkpoint (default: the packaged default)")
    ap.add_argument("--library", help="a motion library (performer library build) danced by the checkpoint")
    a = ap.parse_args(argv)
    if not Path("/proc/self/clear_refs").exists():
        print("startup_memory: needs Linux's /proc/self/clear_refs", file=sys.stderr)
        return 2
    for path in (a.checkpoint, a.library):
        if path and not Path(path).is_file():
            print(f"startup_memory: no such file: {path}", file=sys.stderr)
            return 2
    import torch

    torch.set_num_threads(1)
    from models.generate import load_library_model, load_model
    from models.networks import dance_stream as ds

    print("| step | RSS before, MB | peak, MB | RSS after, MB | s |\n|---|---:|---:|---:|---:|")
    t0 = time.perf_counter()
    model = _step("load_model", lambda: load_model(a.checkpoint)).model
    if a.library:
        model = _step("load_library_model", lambda: load_library_model(model, a.library))
    mem = _step("_cached_members", lambda: ds._cached_members(model))
    _step("_cached_predictor", lambda: ds._cached_predictor(model))
    _step("_cached_tables (one FK pass)", lambda: ds._cached_tables(model, mem))
    _step("_cached_bone_cap", lambda: ds._cached_bone_cap(model, mem, model.member_count.numpy()))
    _step("DanceStream (the rest)", lambda: ds.DanceStream(model))
    print(f"\n{time.perf_counter() - t0:.1f} s in all; members a code {model.config.members}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
