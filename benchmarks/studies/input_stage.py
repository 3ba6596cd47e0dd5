"""What the engine's input stage costs in real time: the feature extractor and the bench's
run-queue clock, each block after a wait for audio (cold caches), thread CPU time.

The shipped default's extractor is fed the bundled clip at 44.1 kHz in 512-sample blocks
(as ``performer run`` and ``performer bench`` push them), sleeping one block's duration
(11.6 ms) before each push, in one thread; printed: the thread's CPU time per frame of the
pushes (all blocks up to and including the one that completes the frame: p50, p99), and of
one read of ``realtime.runqueue_clock.RunQueueClock`` (the bench's own-time clock, read around
every block when ``EngineConfig(runqueue_wait=True)``) made just before each push (p50).
The first 30 frames are left out (warm-up).

Two checkouts compare as with ``lane_parts.py``: run this once per checkout, alternately, the
other one's with ``--tree ../old-checkout`` (same load, interleaved).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tree", default=None, help="checkout whose code is measured (default: this script's)")
    p.add_argument("--seconds", type=float, default=15.0, help="seconds of the clip, in real time (default 15)")
    args = p.parse_args(argv)
    if not 5.0 <= args.seconds <= 30.0:
        p.error("--seconds must be 5..30 (the bundled clip is 32 s)")
    tree = Path(args.tree).resolve() if args.tree else Path(__file__).resolve().parents[2]
    if not (tree / "realtime" / "engine.py").is_file():
        p.error(f"--tree {tree} is not a checkout of this project (no realtime/engine.py)")
    sys.path.insert(0, str(tree))

    import numpy as np

    from models.features.audio_io import bundled_clip_path, load_audio
    from realtime.pipeline import build_pipeline

    try:
        from realtime.runqueue_clock import RunQueueClock
    except ImportError:  # a checkout before the clock had its own module (--tree)
        from realtime.engine import _RunQueueClock as RunQueueClock

    sr, block = 44100, 512
    audio, _ = load_audio(bundled_clip_path(), sr, mono=False)
    ext = build_pipeline(None).extractor_factory(sr)
    clock = RunQueueClock()
    per_frame, reads, acc = [], [], 0
    for lo in range(0, int(args.seconds * sr), block):
        chunk = audio[lo:lo + block].copy()
        time.sleep(block / sr)
        c0 = time.thread_time_ns()
        clock()
        c1 = time.thread_time_ns()
        frames = ext.push(chunk)
        acc += time.thread_time_ns() - c1
        reads.append(c1 - c0)
        if len(frames):
            per_frame.append(acc / len(frames) / 1e6)
            acc = 0
    f = np.asarray(per_frame[30:])
    r = np.asarray(reads[90:]) / 1e6
    print(f"code: {tree}; the clip at {sr} Hz in blocks of {block}, real time, {len(f)} frames; thread CPU ms: "
          f"features a frame p50 {np.median(f):.3f} p99 {np.percentile(f, 99):.3f}; one run-queue clock read "
          f"p50 {np.median(r):.3f} (3 blocks a frame)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
