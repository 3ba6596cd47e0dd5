"""Where an ensemble lane's time goes: the parts of one performer's push, per call.

Four performers of the shipped default on their own spots of the 3x2 stage (as
``performer bench ensemble`` and ``performer run --performer`` place them; code steps
staggered 0, 2, 4, 6; ``--stage 0``: all in place, the stage's part off), fed the bundled
clip's features one frame at a time, unpaced, in one thread; the thread's CPU time of each
frame's pushes (all lanes) is printed first, then each code step's thread CPU time and the
pushes' by frame index mod 8 (with 4 lanes the code steps fall on the even ones). Each part is timed per call (``time.perf_counter_ns`` around the method: about
0.3 µs added to each); printed: calls, median and p99 µs, and µs per frame summed over the
four lanes (``--lanes``). The pushes run with BLAS held to one thread as the engine's
worker holds it (``dance_numpy.hold_single_thread_blas``; a tree without it: none, as its
engine). Then ``Stage.step`` and ``Stage.handover`` alone on a synthetic track (no other work
between calls: their cost with warm caches).

A comparison of two checkouts runs this script once per checkout, alternately, each
importing its own code (``--tree``; same load, interleaved)::

    for i in 1 2 3; do
      .venv/bin/python benchmarks/studies/lane_parts.py --tree ../old-checkout
      .venv/bin/python benchmarks/studies/lane_parts.py
    done

Medians only mean something interleaved: the machine's load moves them by 2x between runs.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from collections import defaultdict
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tree", default=None, help="checkout whose code is measured (default: this script's)")
    p.add_argument("--frames", type=int, default=900, help="feature frames (30 fps) pushed to each lane (default 900)")
    p.add_argument("--lanes", type=int, default=4, help="performers, each on its spot of the stage (default 4)")
    p.add_argument("--stage", default="3x2", metavar="WxD",
                   help="the whole stage the spots are cut from (default 3x2; 0: every performer in place)")
    args = p.parse_args(argv)
    if args.frames < 100 or args.lanes < 1:
        p.error("--frames must be >= 100 and --lanes >= 1")
    tree = Path(args.tree).resolve() if args.tree else Path(__file__).resolve().parents[2]
    if not (tree / "models" / "networks" / "stage.py").is_file():
        p.error(f"--tree {tree} is not a checkout of this project (no models/networks/stage.py)")
    sys.path.insert(0, str(tree))

    import numpy as np

    import models.networks.dance_numpy as dance_numpy
    import models.networks.dance_stream as ds
    import models.networks.feet as feet
    import models.networks.player as player
    import models.networks.stage as stage
    from models.errors import PerformerError
    from models.features.audio_io import bundled_clip_path, load_audio
    from realtime.performer import stagger_lead
    from realtime.pipeline import build_pipeline

    times: dict[str, list[float]] = defaultdict(list)

    def wrap(owner, name: str) -> None:
        fn = getattr(owner, name)
        label = f"{owner.__name__}.{name}"

        def timed(*a, **k):
            t0 = time.perf_counter_ns()
            try:
                return fn(*a, **k)
            finally:
                times[label].append((time.perf_counter_ns() - t0) / 1e3)

        setattr(owner, name, timed)

    code_cpu: list[float] = []  # each code step's thread CPU time (µs), any lane
    next_code = ds.DanceStream._next_code

    def code_step(self):
        c0 = time.thread_time_ns()
        try:
            return next_code(self)
        finally:
            code_cpu.append((time.thread_time_ns() - c0) / 1e3)

    ds.DanceStream._next_code = code_step
    for owner, name in ((ds.DanceStream, "push"), (ds.DanceStream, "_next_code"), (player.Player, "warped"),
                        (player.Player, "contact_at"), (player.Player, "play"), (stage.SpotStage, "step"),
                        (stage.Stage, "handover"), (stage.Stage, "inwards"), (feet.FeetLock, "step")):
        wrap(owner, name)
    loaded: dict = {}
    try:
        pipes = [build_pipeline(None, seed=k, loaded=loaded, spot=(k, args.lanes), stage=args.stage)
                 for k in range(args.lanes)]
    except PerformerError as exc:
        p.error(f"--stage: {exc}")
    audio, sr = load_audio(bundled_clip_path(), 44100, mono=False)
    ext = pipes[0].extractor_factory(sr)
    feats = np.concatenate([f for i in range(0, len(audio) - 512, 512) if len(f := ext.push(audio[i:i + 512]))])
    feats = feats[: args.frames]
    models = [pp.model for pp in pipes]
    for k, m in enumerate(models):
        lead = stagger_lead(m, pipes[0].extractor_factory, k * 8 // args.lanes)
        if lead is not None:
            m.push(lead)
    times.clear()
    code_cpu.clear()
    lanes_cpu = np.zeros(len(feats))  # the thread's CPU time of each frame's pushes, all lanes (ms)
    hold = getattr(dance_numpy, "hold_single_thread_blas", contextlib.nullcontext)  # older trees: none
    with hold():  # BLAS as the engine's worker holds it
        for t in range(len(feats)):
            c0 = time.thread_time_ns()
            for m in models:
                m.push(feats[t:t + 1])
            lanes_cpu[t] = (time.thread_time_ns() - c0) / 1e6
    print(f"code: {tree}; {args.lanes} performers on their spots of the stage {args.stage}, {len(feats)} frames "
          f"each, unpaced; all lanes' pushes a frame, thread CPU ms: p50 {np.median(lanes_cpu):.3f}, "
          f"p99 {np.percentile(lanes_cpu, 99):.3f}")
    print(f"the code step (any lane), thread CPU µs: p50 {np.median(code_cpu):.0f}, p99 {np.percentile(code_cpu, 99):.0f} "
          f"({len(code_cpu)} steps)")
    pos = np.arange(len(feats)) % 8  # lane k's code steps fall where pos == 8 - 8k/lanes (mod 8)
    print("all lanes' pushes a frame by frame index mod 8, thread CPU ms p50: "
          + " ".join(f"{np.median(lanes_cpu[pos == k]):.2f}" for k in range(8))
          + "; p99: " + " ".join(f"{np.percentile(lanes_cpu[pos == k], 99):.2f}" for k in range(8)))
    print("| part | calls | p50 µs | p99 µs | µs a frame, all lanes |")
    print("|---|---:|---:|---:|---:|")
    for label, v in sorted(times.items(), key=lambda kv: -sum(kv[1])):
        a = np.asarray(v)
        print(f"| {label} | {len(a)} | {np.median(a):.1f} | {np.percentile(a, 99):.1f} | {a.sum() / len(feats):.1f} |")

    # Stage.step and Stage.handover alone: a random travel of 2 seg rows, read at 0.9-1.1 rows a frame
    st = stage.SpotStage(8, "3x2", "free", (1, 4))
    rng = np.random.default_rng(0)
    track = np.cumsum(rng.normal(0.0, 0.01, (16, 3)), axis=0)
    track -= track[0]
    st.handover(0.0, track, True)
    pose = np.zeros(87, np.float32)
    pose[6::4] = 1.0
    step, hand, read = [], [], 8.0
    for k in range(20000):
        if k % 8 == 0:
            t0 = time.perf_counter_ns()
            st.handover(read - 8.0, track, False)
            hand.append(time.perf_counter_ns() - t0)
            read = 8.0
        read += 1.0 + 0.1 * float(np.sin(k))
        t0 = time.perf_counter_ns()
        st.step(pose, read, 0.0)
        step.append(time.perf_counter_ns() - t0)
    print(f"alone: SpotStage.step p50 {np.median(step[1000:]) / 1e3:.2f} µs, Stage.handover p50 "
          f"{np.median(hand[100:]) / 1e3:.2f} µs")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
