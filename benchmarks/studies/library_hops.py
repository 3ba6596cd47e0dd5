"""What a library's own choice costs the stream: per-frame compute, its stream against one code a step.

A library model (``models.generate.load_library_model``) draws up to ``LIBRARY_DRAWS`` codes a
code step where a handover would bend the motion far, then searches every exemplar for the
nearest (models/networks/library_player.py). A checkpoint cannot carry that choice, so
``performer bench latency --checkpoint`` (library_play.py ``--save-checkpoint``) measures one code
a step. Under ``auto`` a library of two or more folders keeps to one folder at a time
(models/networks/library_folders.py), which the third stream leaves out (``FOLDER_CHOICE`` off:
every folder's exemplars). This runs the streams of the same library over the same audio in one
process, frame by frame and rotating which goes first (the same load for each), and prints each
one's compute per frame (``DanceStream.push`` of one feature frame, wall ms, or with ``--cpu`` the
thread's own CPU ms: median and p99) over all frames and over the code steps (every ``seg``
frames), after the first 2 s, and how often the library's stream ran the nearest search::

    nice -n 5 .venv/bin/python benchmarks/studies/library_hops.py --library big.npz

(docs/library.md, "A 30-minute library", says how to make one.) Exit status 2 on a missing input.
"""

from __future__ import annotations

import argparse
import copy
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

SETTLE = 60  # frames (2 s) left out: the stream's first movements and compilation


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--library", type=Path, required=True, metavar="FILE.npz", help="the library (performer library build)")
    p.add_argument("--audio", type=Path, default=REPO / "models" / "assets" / "clip.ogg",
                   help="recording to stream (default: the bundled 32-s clip)")
    p.add_argument("--cpu", action="store_true", help="time the thread's own CPU (time.thread_time), not the wall")
    a = p.parse_args(argv)
    import torch

    from models.errors import PerformerError
    from models.features.audio_io import load_audio
    from models.features.spectral import extract_features
    from models.generate import load_library_model, load_model
    import models.networks.library_folders as lf
    from models.networks.dance_stream import DanceStream

    torch.set_num_threads(1)
    try:
        lm = load_model(None)
        lib = load_library_model(lm.model, a.library)
        y, _ = load_audio(a.audio, 22050)
    except (PerformerError, OSError) as e:
        print(f"library_hops.py: {e}", file=sys.stderr)
        return 2
    one = copy.copy(lib)  # the same memory and tables, the choice of a checkpoint: one code a step
    one.code_draws, one.handover_guard, one.exemplar_tilt = 1, 0.0, 0.0
    feats = extract_features(y, lm.features)
    streams = {"library": DanceStream(lib, seed=0), "one code": DanceStream(one, seed=0)}
    lf.FOLDER_CHOICE = False
    streams["no folder choice"] = DanceStream(lib, seed=0)
    lf.FOLDER_CHOICE = True
    clock = time.thread_time if a.cpu else time.perf_counter
    ms: dict[str, list[float]] = {k: [] for k in streams}
    searches = []  # frames on which the library's stream searched every exemplar (its last resort)
    own = streams["library"]._chooser.nearest
    streams["library"]._chooser.nearest = lambda pose: searches.append(streams["library"].frame) or own(pose)
    order = list(streams)
    for t in range(len(feats)):
        for k in order[t % 3:] + order[: t % 3]:
            t0 = clock()
            streams[k].push(feats[t: t + 1])
            ms[k].append((clock() - t0) * 1e3)
    step = (np.arange(SETTLE, len(feats)) % lib.config.seg) == 0
    print(f"{a.library}: {lib.config.members} exemplars a code, {len(feats)} frames; "
          f"{'CPU' if a.cpu else 'wall'} ms a frame, median / p99")
    for k, v in ms.items():
        x = np.array(v[SETTLE:])
        print(f"  {k:<16} all frames {np.median(x):.3f} / {np.percentile(x, 99):.3f}; code steps "
              f"{np.median(x[step]):.3f} / {np.percentile(x[step], 99):.3f}")
    print(f"  the library's stream ran the nearest search (its folder's exemplars under auto) on {len(searches)} of "
          f"{len(streams['library'].codes_drawn)} code steps")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
