"""What the show desk's traffic costs the audio path: per-hop p99 with N desks open against none (docs/show.md).

Each run is the live engine of ``performer run`` in this process (the shipped model, the bundled
clip replayed in real time, a WebSocket server with its desk feed at 5 Hz, no OSC); in the "desks"
runs, another process holds ``--desks`` connections to ``/desk`` reading every status message (a
browser's tab is another process too). Runs alternate, none first, ``--reps`` of each; each
reports the engine's per-hop p50/p99 (compute_ms, wall) and the hop's own p99 (less the time
other processes held the CPU: ``performer bench``'s "own", realtime/bench/suite.py) over
``--seconds`` of audio after a 5-s settle. Prints one line per run and the medians; ``--json`` writes them.

    .venv/bin/python benchmarks/studies/desk_ab.py --reps 3 --seconds 40 --desks 4
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

READER = """
import sys, threading
from websockets.sync.client import connect
n = [0]
def read():
    with connect(sys.argv[1]) as ws:
        for _ in ws:
            n[0] += 1
ts = [threading.Thread(target=read, daemon=True) for _ in range(int(sys.argv[2]))]
for t in ts: t.start()
sys.stdin.read()
print(n[0], flush=True)
"""


def one_run(desks: int, seconds: float) -> dict:
    from models.features.audio_io import bundled_clip_path
    from realtime.audio_input import FileSource
    from realtime.bench.suite import own_hop_ms
    from realtime.desk import start_desk
    from realtime.engine import Engine
    from realtime.engine_config import EngineConfig
    from realtime.pipeline import build_pipeline
    from realtime.ws_server import WebSocketSink

    pipe = build_pipeline(None, seed=0)
    sink = WebSocketSink("127.0.0.1", 0)
    source = FileSource.open(bundled_clip_path(), realtime=True, loop=True)
    engine = Engine(source, pipe.extractor_factory, pipe.model, [sink], EngineConfig(warmup_s=0.5, runqueue_wait=True))
    sink.control = engine.control
    engine.start()
    feed = start_desk(engine, [sink])
    reader = None
    if desks:
        reader = subprocess.Popen([sys.executable, "-c", READER, f"ws://127.0.0.1:{sink.port}/desk?format=json",
                                   str(desks)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    time.sleep(5.0)
    engine.compute_ms.clear()
    engine.compute_wait_ms.clear()
    time.sleep(seconds)
    own = own_hop_ms(engine.compute_ms.values(), engine.compute_wait_ms.values())
    out = {"desks": desks, "hop_p50_ms": engine.compute_ms.percentile(50),
           "hop_p99_ms": engine.compute_ms.percentile(99), "own_p50_ms": float(np.nanpercentile(own, 50)),
           "own_p99_ms": float(np.nanpercentile(own, 99)), "frames": engine.compute_ms.count,
           "desk_clients": sink.desk_clients(), "statuses_sent": feed.sent}
    if reader is not None:
        out["statuses_read"] = int(reader.communicate("", timeout=10)[0].strip() or 0)
    feed.close()
    engine.close()
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--reps", type=int, default=3, help="runs of each condition (default 3)")
    p.add_argument("--seconds", type=float, default=40.0, help="seconds measured per run (default 40)")
    p.add_argument("--desks", type=int, default=4, help="desks open in the desk runs (default 4)")
    p.add_argument("--json", metavar="FILE", help="write every run and the medians here")
    a = p.parse_args(argv)
    if a.reps < 1 or a.seconds <= 0 or a.desks < 1:
        p.error("--reps and --desks must be at least 1, --seconds above 0")
    runs = []
    for _ in range(a.reps):
        for desks in (0, a.desks):
            runs.append(one_run(desks, a.seconds))
            print(json.dumps(runs[-1]), flush=True)
    summary = {}
    for desks in (0, a.desks):
        mine = [r for r in runs if r["desks"] == desks]
        summary[desks] = {k: statistics.median(r[k] for r in mine)
                           for k in ("hop_p50_ms", "hop_p99_ms", "own_p50_ms", "own_p99_ms")}
    ratio = summary[a.desks]["hop_p99_ms"] / summary[0]["hop_p99_ms"]
    own_ratio = summary[a.desks]["own_p99_ms"] / summary[0]["own_p99_ms"]
    none, some = summary[0], summary[a.desks]
    print(f"medians, no desk / {a.desks} desks: hop p99 {none['hop_p99_ms']:.3f} / {some['hop_p99_ms']:.3f} ms "
          f"(ratio {ratio:.3f}), own p99 {none['own_p99_ms']:.3f} / {some['own_p99_ms']:.3f} ms (ratio "
          f"{own_ratio:.3f}), hop p50 {none['hop_p50_ms']:.3f} / {some['hop_p50_ms']:.3f} ms")
    if a.json:
        Path(a.json).write_text(json.dumps({"runs": runs, "median": summary, "p99_ratio": ratio,
                                            "own_p99_ratio": own_ratio}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
