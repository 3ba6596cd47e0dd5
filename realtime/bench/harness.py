"""Runs N performer processes against one loopback receiver process and joins their records.

Sequence (every step has a timeout; a failed child raises :class:`BenchError` with the
tail of its stderr, and every child process this module started is killed):

1. the receiver binds one UDP port per performer;
2. each performer loads its model and audio, opens its outputs and reports its WebSocket port;
3. the receiver connects one WebSocket client per performer;
4. every performer runs its engine warm-up; once all have, each gets its start instant
   ``T0 + j * period / N`` (stream ``j`` of N: independent streams have unrelated
   phases, so they are spread evenly over a frame period rather than all computing at
   the same instant) and replays from then on;
5. the receiver's logs are matched to each performer's frames by frame index.

With ``ensemble=True`` the N performers run in ONE process instead, one engine on the
first spec's audio (an ensemble: one input, N performers, each its own VMC port and
WebSocket path ``/ws/pJ`` on one server, seed J), and the result adds that process's
whole-hop figures under ``process``.

CPU affinity is inherited: pin the calling process first (``performer bench --cores``).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from models.errors import PerformerError
from models.timebase import FPS
from realtime.bench.measure import match_receipts


class BenchError(PerformerError):
    """A benchmark child process failed or timed out."""


@dataclass
class StreamSpec:
    """One performer: its audio (``.npy`` float32 samples at ``sample_rate``) and a label."""

    name: str
    audio_npy: Path
    sample_rate: int


@dataclass
class RunSettings:
    """What every performer of one run shares."""

    checkpoint: Path
    seconds: float
    block_size: int = 512
    threads: int = 1
    warmup_s: float = 3.0
    model: str = "streaming"  # or "naive" (NaiveWindowGenerator)
    lead_ms: float = 0.0  # the single performer's lead (`performer run --lead`)
    inject_ms: float = 0.0  # testing hook: extra work in the first performer's lane (realtime/bench/reference.py)
    inject_every: int = 8  # ... on every this many frames
    library: Path | None = None  # the single performer dances this library (`performer run --library`)


class _Child:
    """A child process speaking JSON lines on stdin/stdout; stderr goes to a file."""

    def __init__(self, args: list[str], log: Path, env: dict) -> None:
        self.log = log
        self._err = open(log, "w")
        self.proc = subprocess.Popen(args, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._err,
                                     text=True, env=env)

    def tell(self, obj: dict) -> None:
        self.proc.stdin.write(json.dumps(obj) + "\n")
        self.proc.stdin.flush()

    def hear(self, key: str) -> dict:
        """Next stdout line as JSON; it must hold ``key`` (else the child failed)."""
        line = self.proc.stdout.readline()
        try:
            msg = json.loads(line) if line else {}
        except ValueError:
            msg = {}
        if key not in msg:
            self.proc.wait(5) if self.proc.poll() is None else None
            tail = self.log.read_text()[-1500:].strip() if self.log.exists() else ""
            raise BenchError(f"benchmark child {' '.join(self.proc.args[1:3])} failed "
                             f"(exit {self.proc.poll()}): {tail or line.strip() or 'no output'}")
        return msg

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        if not self._err.closed:
            self._err.close()


def child_env(threads: int) -> dict:
    """Environment of the children: BLAS/OpenMP pools sized to ``threads``, repo importable."""
    env = dict(os.environ)
    env["OMP_NUM_THREADS"] = str(threads)
    env["MKL_NUM_THREADS"] = str(threads)
    root = str(Path(__file__).resolve().parents[2])
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def run_performers(specs: list[StreamSpec], settings: RunSettings, workdir: Path | None = None, *,
                   ensemble: bool = False, stagger: bool = True) -> dict:
    """Run ``len(specs)`` performers concurrently; returns per-stream frame records.

    ``ensemble``: all in one process on ``specs[0]``'s audio (see the module docstring);
    ``stagger`` False gives them all phase 0 (their code steps on the same hops).

    Result: ``{"streams": [record, ...], "wall_s", "machine_busy_percent", "receiver_cpu_s"}``
    where a record is the worker's JSON (:mod:`realtime.bench.worker`) plus
    ``osc_received`` / ``ws_received`` (receipt instant per sent frame, NaN if lost);
    ``machine_busy_percent`` is the share of all CPUs busy (any process) from the
    common start to the last performer's end, from /proc/stat.
    """
    n = len(specs)
    tmp = None
    if workdir is None:
        tmp = tempfile.TemporaryDirectory(prefix="performer-bench-")
        workdir = Path(tmp.name)
    workdir.mkdir(parents=True, exist_ok=True)
    env = child_env(settings.threads)
    children: list[_Child] = []
    # A hung child would block a readline forever: kill everything after a generous deadline
    # (the blocked readline then returns, and the failure is reported with the child's stderr).
    watchdog = threading.Timer(120.0 + 10.0 * n + 2.0 * settings.seconds, lambda: [c.kill() for c in children])
    watchdog.daemon = True
    watchdog.start()
    try:
        rx = _Child([sys.executable, "-m", "realtime.bench.receiver", str(n)], workdir / "receiver.log", env)
        children.append(rx)
        ports = rx.hear("udp_ports")["udp_ports"]
        workers = []
        common = {"checkpoint": str(settings.checkpoint), "block_size": settings.block_size,
                  "seconds": settings.seconds, "threads": settings.threads, "warmup_s": settings.warmup_s,
                  "model": settings.model, "lead_ms": settings.lead_ms,
                  "library": None if settings.library is None else str(settings.library)}
        if settings.inject_ms > 0:
            common.update(inject_ms=settings.inject_ms, inject_every=settings.inject_every)
        if ensemble:
            wspecs = [{**common, "audio_npy": str(specs[0].audio_npy), "sample_rate": specs[0].sample_rate,
                       "name": specs[0].name, "out": str(workdir / "ensemble.json"),
                       "performers": [{"name": f"p{j}", "osc_port": port, "seed": j, "phase": None if stagger else 0}
                                      for j, port in enumerate(ports)]}]
        else:
            wspecs = [{**common, "audio_npy": str(spec.audio_npy), "sample_rate": spec.sample_rate,
                       "osc_port": port, "out": str(workdir / f"stream{j:02d}.json"), "name": spec.name}
                      for j, (spec, port) in enumerate(zip(specs, ports))]
        for j, wspec in enumerate(wspecs):
            w = _Child([sys.executable, "-m", "realtime.bench.worker", json.dumps(wspec)],
                       workdir / f"stream{j:02d}.log", env)
            children.append(w)
            workers.append((w, Path(wspec["out"])))
        ready = [w.hear("ready") for w, _ in workers]
        if ensemble:
            rx.tell({"connect": [[ready[0]["ws_port"], path] for path in ready[0]["ws_paths"]]})
        else:
            rx.tell({"connect": [r["ws_port"] for r in ready]})
        rx.hear("connected")
        for w, _ in workers:
            w.tell({"warm_up": True})
        for w, _ in workers:
            w.hear("warmed")
        t0 = time.monotonic() + 0.5
        for j, (w, _) in enumerate(workers):
            w.tell({"start_at": t0 + j / (FPS * n)})
        time.sleep(max(0.0, t0 - time.monotonic()))
        cpu0 = _machine_cpu()
        records = []
        for w, out in workers:
            w.hear("done")
            records.append(json.loads(out.read_text()))
        cpu1 = _machine_cpu()
        process = None
        if ensemble:
            process = records[0]
            records = process.pop("streams")
        rx.tell({"stop": str(workdir / "receiver.json")})
        rx.hear("done")
        rx.proc.wait(10)
        received = json.loads((workdir / "receiver.json").read_text())
        if received["errors"]:
            raise BenchError(f"loopback WebSocket client failed: {received['errors'][0]}")
        for j, rec in enumerate(records):
            for kind in ("osc", "ws"):
                log = np.asarray(received[kind][j], dtype=np.float64).reshape(-1, 2)
                rec[f"{kind}_received"] = match_receipts(rec["index"], log[:, 0], log[:, 1]).tolist()
        result = {
            "streams": records,
            "wall_s": max(r["wall_s"] for r in records),
            "machine_busy_percent": _busy_percent(cpu0, cpu1),
            "receiver_cpu_s": received["cpu_s"],
        }
        if process is not None:
            result["process"] = process
        return result
    finally:
        watchdog.cancel()
        for c in children:
            c.kill()
        if tmp is not None:
            tmp.cleanup()


def _machine_cpu() -> tuple[float, float] | None:
    """(busy, total) jiffies of all CPUs from /proc/stat, or None off Linux."""
    try:
        fields = [float(x) for x in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    except (OSError, ValueError):
        return None
    idle = fields[3] + (fields[4] if len(fields) > 4 else 0.0)
    return sum(fields) - idle, sum(fields)


def _busy_percent(a, b) -> float:
    """Share of all CPUs busy between two :func:`_machine_cpu` readings (any process), percent."""
    if a is None or b is None or b[1] <= a[1]:
        return float("nan")
    return 100.0 * (b[0] - a[0]) / (b[1] - a[1])
