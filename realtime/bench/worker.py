"""One performer under test: a separate process running the real engine with its real outputs.

``python -m realtime.bench.worker SPEC_JSON`` (started by :mod:`realtime.bench.harness`):

1. loads the checkpoint (:func:`realtime.pipeline.build_pipeline`) and its audio segment
   (a ``.npy`` of float32 samples, (n,) or (n, channels), at ``sample_rate``);
2. opens an :class:`~realtime.osc_out.OscSink` (VMC, the default output) to the
   receiver's UDP port and a :class:`~realtime.ws_server.WebSocketSink` on a free port;
3. prints ``{"ready": ..., "ws_port": ...}`` on stdout and waits for ``{"warm_up": true}``
   on stdin (sent once the receiver connected);
4. starts :class:`~realtime.engine.Engine`: its warm-up, then ``{"warmed": true}`` on
   stdout and a wait for ``{"start_at": T}`` (a ``time.monotonic()`` instant), then the
   paced file source from exactly ``T`` until ``seconds`` of audio were processed;
5. writes ``out`` (JSON): per frame its index, completing input sample, the release
   instant of the block holding that sample, the send instant and the per-hop compute
   time; and the process's CPU time and peak RSS. Prints ``{"done": out}``.

SPEC keys: checkpoint, audio_npy, sample_rate, block_size, seconds, threads, warmup_s,
model ("streaming" or "naive"), osc_port, out, name, lead_ms (the performer's lead, default 0);
optional inject_ms and inject_every
(:class:`~realtime.bench.reference.InjectedWork` in the first performer's lane: a planted
regression). Every run also times the reference workload once per hop
(:class:`~realtime.bench.reference.ReferenceProbe`): ``reference_ms`` (wall) and
``reference_cpu_ms`` (its thread's CPU time) in ``out``.

An ensemble (``performer bench ensemble``): SPEC has ``performers``, a list of
``{"name", "osc_port", "seed", "phase"}`` (phase null: the engine's stagger), instead of
``osc_port`` and ``name``. One engine runs them all on the one audio input, each with its
own VMC target and its own path ``/ws/NAME`` on one WebSocket server; ``ready`` carries
``ws_paths``; ``out`` holds ``streams`` (one record as above per performer, its own
compute: model to sends, wall ``compute_ms`` and the worker thread's CPU ``lane_cpu_ms``)
and the process's figures: the whole hop per frame
(``compute_ms``), the input stage's share (``features_ms``), CPU, RSS, extractors.
"""

from __future__ import annotations

import json
import logging
import os
import resource
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from realtime.audio_input import FileSource, RingBuffer
from realtime.frame import PoseFrame

log = logging.getLogger("realtime.bench.worker")


class ScheduledSource:
    """An :class:`~realtime.audio_input.AudioSource` whose first ``start`` waits for a start instant.

    The engine calls ``start`` after its warm-up; the first call asks ``schedule()`` for a
    ``time.monotonic()`` instant (the harness answers once every performer has warmed
    up), sleeps until then and starts the wrapped source. Everything else is the
    wrapped source's.
    """

    def __init__(self, inner: FileSource, schedule: Callable[[], float]) -> None:
        self.inner = inner
        self.schedule = schedule
        self.start_at: float | None = None
        self.started_at: float | None = None

    name = property(lambda self: self.inner.name)
    sample_rate = property(lambda self: self.inner.sample_rate)
    channels = property(lambda self: self.inner.channels)
    error = property(lambda self: self.inner.error)
    finished = property(lambda self: self.inner.finished)

    def start(self, ring: RingBuffer) -> None:
        if self.started_at is None:
            self.start_at = float(self.schedule())
            wait = self.start_at - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            self.started_at = time.monotonic()
        self.inner.start(ring)

    def stop(self) -> None:
        self.inner.stop()

    def stats(self) -> dict[str, float]:
        return self.inner.stats()


class TimingSink:
    """Records, per frame sent, its index, completing sample, block release and send instants.

    Runs on the engine's worker thread; the release instant is the one the engine stamped
    on the frame (``PoseFrame.released``). Preallocated arrays of ``capacity`` frames;
    frames beyond it are counted in ``overflow``.
    """

    name = "timing"

    def __init__(self, capacity: int) -> None:
        self.index = np.zeros(capacity, dtype=np.int64)
        self.sample = np.zeros(capacity, dtype=np.int64)
        self.released = np.zeros(capacity, dtype=np.float64)
        self.sent = np.zeros(capacity, dtype=np.float64)
        self.count = 0
        self.overflow = 0

    def send(self, frame: PoseFrame) -> None:
        n = self.count
        if n >= len(self.index):
            self.overflow += 1
            return
        self.index[n] = frame.index
        self.sample[n] = frame.audio_sample
        self.released[n] = frame.released
        self.sent[n] = frame.wall_time
        self.count = n + 1

    def close(self) -> None:
        pass

    def stats(self) -> dict[str, float]:
        return {"frames": float(self.count), "overflow": float(self.overflow)}


def peak_rss_mb() -> float:
    """Peak resident set size of this process, MB (VmHWM, else ``ru_maxrss``)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # KiB on Linux


def _cpu_s() -> float:
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime


def _model(pipeline, kind: str, checkpoint: str):
    """The engine's pose model: the pipeline's streaming model, or the naive baseline
    (:func:`realtime.bench.suite.naive_baseline`; ConfigError for a model without one)."""
    if kind == "streaming":
        return pipeline.model
    from models.errors import ConfigError
    from realtime.bench.suite import naive_baseline

    naive, reason = naive_baseline(pipeline.model.model)
    if naive is None:
        raise ConfigError(reason)
    return naive


def _library_of(model) -> str | None:
    """The library file the streaming model dances (``library_path`` of its network), else None."""
    path = getattr(getattr(model, "model", None), "library_path", None)
    return None if path is None else str(path)


def _say(obj: dict) -> None:
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


def _hear(key: str) -> dict:
    line = sys.stdin.readline()
    msg = json.loads(line) if line.strip() else {}
    if key not in msg:
        raise SystemExit(f"expected {key!r} from the harness, got {line.strip()!r}")
    return msg


def run(spec: dict) -> dict:
    """Steps 1-5 of the module docstring; returns what it wrote to ``spec["out"]``."""
    import torch

    from realtime.engine import Engine
    from realtime.engine_config import EngineConfig
    from realtime.osc_out import OscSink
    from realtime.performer import Performer
    from realtime.pipeline import build_pipeline
    from realtime.ws_server import WebSocketSink

    from realtime.bench.reference import InjectedWork, ReferenceProbe

    threads = int(spec.get("threads", 1))
    torch.set_num_threads(threads)
    samples = np.load(spec["audio_npy"])
    sr, block = int(spec["sample_rate"]), int(spec["block_size"])
    seconds = float(spec["seconds"])
    frames_max = int(seconds * 30) + 64
    ensemble = spec.get("performers")
    server = WebSocketSink("127.0.0.1", 0)
    cfg = EngineConfig(threads=threads, warmup_s=float(spec.get("warmup_s", 3.0)), duration_s=seconds,
                       stats_size=frames_max, runqueue_wait=True)
    inject = (InjectedWork(float(spec["inject_ms"]), int(spec.get("inject_every", 8)))
              if spec.get("inject_ms") else None)
    probe = ReferenceProbe()
    if ensemble is None:
        pipeline = build_pipeline(spec["checkpoint"], lead=float(spec.get("lead_ms", 0.0)),
                                  library=spec.get("library"))
        model = _model(pipeline, spec.get("model", "streaming"), spec["checkpoint"])
        lanes = [(spec.get("name", "audio"), [OscSink("127.0.0.1", int(spec["osc_port"]), mode="vmc"), server,
                                               TimingSink(frames_max)])]
        sinks = ([inject] if inject else []) + lanes[0][1] + [probe]
        _say({"ready": True, "ws_port": server.port, "pid": os.getpid()})
    else:
        loaded: dict = {}
        performers = []
        lanes = []
        for k, p in enumerate(ensemble):
            # each on its own spot of performer run's default 3x2 stage, as performer run's ensembles
            pipe = build_pipeline(spec["checkpoint"], seed=int(p.get("seed", 0)), loaded=loaded,
                                  spot=(k, len(ensemble)))
            mine = [OscSink("127.0.0.1", int(p["osc_port"]), mode="vmc"),
                    server.route(f"/ws/{p['name']}", p["name"], default=k == 0), TimingSink(frames_max)]
            lanes.append((p["name"], mine))
            extra_first = [inject] if inject and k == 0 else []
            extra_last = [probe] if k == len(ensemble) - 1 else []
            performers.append(Performer(p["name"], pipe.model, pipe.extractor_factory,
                                        extra_first + mine + extra_last,
                                        feature_key=pipe.feature_key, phase=p.get("phase")))
        _say({"ready": True, "ws_port": server.port, "ws_paths": [f"/ws/{p['name']}" for p in ensemble],
              "pid": os.getpid()})

    _hear("warm_up")
    source = ScheduledSource(FileSource(samples, sr, name=spec.get("name", "audio"), block_size=block),
                             lambda: (_say({"warmed": True}), _hear("start_at")["start_at"])[1])
    if ensemble is None:
        engine = Engine(source, pipeline.extractor_factory, model, sinks, cfg)
    else:
        engine = Engine(source, config=cfg, performers=performers)
    engine.start()
    cpu0, wall0 = _cpu_s(), time.monotonic()
    try:
        engine.wait()
    finally:
        cpu1, wall1 = _cpu_s(), time.monotonic()
        stats = engine.stats()
        engine.close()
        server.close()
        probe.close()
    process = {
        "sample_rate": sr,
        "block_size": block,
        "threads": threads,
        "start_at": source.start_at,
        "started_at": source.started_at,
        "cpu_s": cpu1 - cpu0,
        "wall_s": wall1 - wall0,
        "peak_rss_mb": peak_rss_mb(),
        "late_blocks": int(source.inner.late_blocks),
        "overruns": int(stats["overruns"]),
        "reference_ms": probe.times_ms(),
        "reference_cpu_ms": probe.cpu_times_ms(),  # the probe thread's CPU time per run
        # per frame, the whole hop's run-queue wait (ms): other threads held the CPU
        "compute_wait_ms": engine.compute_wait_ms.values()[: lanes[0][1][2].count].tolist(),
        "compute_cpu_ms": engine.compute_cpu_ms.values()[: lanes[0][1][2].count].tolist(),  # the worker's CPU
        "injected": None if inject is None else {"ms": inject.seconds * 1000.0, "every": inject.every,
                                                 "frames": inject.injected},
        # the library the single performer danced, as its model reports it (performer run --library)
        "library": None if ensemble is not None else _library_of(pipeline.model),
    }
    records = []
    for name, (osc, ws, timing) in lanes:
        lane = stats["performers"][engine.performers[len(records)]]
        n = timing.count
        records.append({
            "name": name,
            "model": spec.get("model", "streaming"),
            **process,
            "index": timing.index[:n].tolist(),
            "audio_sample": timing.sample[:n].tolist(),
            "released": timing.released[:n].tolist(),
            "sent": timing.sent[:n].tolist(),
            # one performer: the whole hop (the engine's own timer); in an ensemble: this performer's part
            "compute_ms": (engine.compute_ms if ensemble is None else
                           engine.performer_compute_ms(engine.performers[len(records)])).values()[:n].tolist(),
            # the worker thread's CPU time in it (one performer: in its model and sends only)
            "lane_cpu_ms": engine.performer_compute_cpu_ms(engine.performers[len(records)]).values()[:n].tolist(),
            "nan_frames": int(lane["nan_frames"]),
            "sink_errors": int(lane["sink_errors"]),
            "ws_drops": int(lane["sinks"].get(ws.name, {}).get("drops", 0)),
            "osc_errors": int(lane["sinks"].get(osc.name, {}).get("errors", 0)),
            "timing_overflow": timing.overflow,
            "phase": int(lane["phase"]),
        })
    if ensemble is None:
        result = records[0]
    else:
        frames = len(records[0]["index"])
        result = {"streams": records, **process, "compute_ms": engine.compute_ms.values()[:frames].tolist(),
                  "features_ms": engine.features_ms.values()[:frames].tolist(), "extractors": stats["extractors"]}
    Path(spec["out"]).write_text(json.dumps(result))
    return result


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr, format="bench worker: %(message)s")
    spec = json.loads(argv[0])
    run(spec)
    _say({"done": spec["out"]})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
