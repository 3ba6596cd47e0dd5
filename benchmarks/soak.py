"""Soak and load runs of the real-time engine (results in docs/reliability.md).

    .venv/bin/python benchmarks/soak.py --minutes 60                 # the full soak (make soak)
    .venv/bin/python benchmarks/soak.py --minutes 2 --json out.json  # the short one tests/test_soak.py runs
    .venv/bin/python benchmarks/soak.py --minutes 60 --data ../shared/data/dwm   # + the stability check
    .venv/bin/python benchmarks/soak.py --minutes 60 --data ../shared/data/dwm --songs DANCE_C_2 DANCE_R_5 DANCE_W_5
    .venv/bin/python benchmarks/soak.py load --clients 200 --max-clients 16 --seconds 8 --repeat 2
    .venv/bin/python benchmarks/soak.py crowd --url ws://127.0.0.1:8765/ws --clients 200 --seconds 3

*soak*: the bundled clip (or ``--audio FILE`` / ``--songs NAME`` songs back to back), looped,
replayed as fast as possible for ``--minutes`` of audio
through the full engine (the default checkpoint, or a default-size causal generator with
random weights when none is packaged: the same compute) with a VMC receiver (UDP) and two
WebSocket clients attached, each in another process. Checks: no non-finite pose anywhere
(engine, every frame handed to the outputs, every frame the receivers decoded), the exact
frame count (``minutes * 1800``), resident memory growth under 5 % from the end of the
warm-up (the first 10 % of the audio, at least 30 s) to the end, and no growth in open file
descriptors. Optional (``--stability-ref-m M`` or ``--data DIR``): the stability check of
issue 18 (:mod:`models.evaluation.stability`) on every frame handed to the outputs: in every
30-s stretch the dance-scale amplitude between 0.5x and 1.5x the real dances' (``M`` metres,
or computed from the validation dances under ``DIR``), the root within 0.5 m of its start,
no freeze, no explosion. Exit status 1 if a check fails.

*load*: the engine paced in real time (the clip, looped) with a WebSocket server, first
with no client, then while ``--clients`` clients (another process) connect at once to a
server capped at ``--max-clients`` and stay connected; prints the per-hop compute p50/p99
of both runs, their ratio, how many clients were served or refused, and the RSS change.

*crowd*: the load's client process: opens ``--clients`` WebSocket connections at once (``--wait-go``: after a stdin line),
prints ``{"connected": ...}`` once every attempt got its hello or its refusal, reads
binary frames for ``--seconds`` (0: until the server closes), then prints a JSON summary
(hellos, close codes, frames and non-finite frames per client).

*udp*: the soak's VMC receiver process: prints its port, counts datagrams and frames
(``/VMC/Ext/T`` messages, whose float must be finite) until its stdin closes.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import select
import socket
import subprocess
import sys
import threading
import time
from collections import Counter, deque
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from models.rig.humanoid import BONES  # noqa: E402
from models.timebase import FPS, HOP, SAMPLE_RATE  # noqa: E402

_VMC_T = b"/VMC/Ext/T\x00\x00,f\x00\x00"  # address + type tag of a VMC frame's last message


# ---------------------------------------------------------------------------- process probes


def rss_bytes() -> int:
    """Resident set size of this process, bytes (Linux /proc)."""
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def open_fds() -> int:
    """Number of open file descriptors of this process (Linux /proc)."""
    return len(os.listdir("/proc/self/fd"))


def rotation_steps_deg(poses: np.ndarray) -> np.ndarray:
    """(T-1, J) angle in degrees between consecutive local rotations of (T, POSE_DIM) poses."""
    q = np.asarray(poses, dtype=np.float64)[:, 3:].reshape(len(poses), -1, 4)
    dot = np.abs(np.einsum("tjk,tjk->tj", q[1:], q[:-1]))
    return np.degrees(2.0 * np.arccos(np.clip(dot, 0.0, 1.0)))


class FrameCheck:
    """A sink that checks every frame handed to the outputs, keeping O(1) state.

    Counts frames and non-finite poses, checks that indices follow each other, and keeps
    the largest frame-to-frame rotation change (degrees, any bone).
    """

    name = "check"

    def __init__(self) -> None:
        self.frames = self.nonfinite = self.index_gaps = 0
        self.max_step_deg = 0.0
        self.max_step_at = self.max_step_bone = -1  # frame index and bone of the largest change
        self._prev: np.ndarray | None = None
        self._next_index = 0

    def send(self, frame) -> None:
        self.frames += 1
        if frame.index != self._next_index:
            self.index_gaps += 1
        self._next_index = frame.index + 1
        if not np.isfinite(frame.pose).all():
            self.nonfinite += 1
            return
        if self._prev is not None:
            steps = rotation_steps_deg(np.stack([self._prev, frame.pose]))[0]
            j = int(steps.argmax())
            if steps[j] > self.max_step_deg:
                self.max_step_deg, self.max_step_at, self.max_step_bone = float(steps[j]), frame.index, j
        self._prev = frame.pose.copy()

    def close(self) -> None:
        pass

    def stats(self) -> dict[str, float]:
        return {"frames": self.frames, "nonfinite": self.nonfinite}


class PoseTap:
    """A sink that hands the poses it is sent to another thread in chunks of ``chunk`` frames.

    ``send`` (engine thread) only copies the pose; full chunks wait in ``ready`` until
    :meth:`drain` (another thread) feeds them to a consumer, so slow analysis (the
    stability check's forward kinematics) never counts as engine compute time, and
    memory stays at the chunks in flight.
    """

    name = "stability"

    def __init__(self, chunk: int = 900) -> None:
        from models.rig.motion import POSE_DIM

        self._buf = np.empty((chunk, POSE_DIM), np.float32)
        self._fill = 0
        self.frames = 0
        self.ready: deque[np.ndarray] = deque()

    def send(self, frame) -> None:
        self._buf[self._fill] = frame.pose
        self._fill += 1
        self.frames += 1
        if self._fill == len(self._buf):
            self.ready.append(self._buf)
            self._buf = np.empty_like(self._buf)
            self._fill = 0

    def drain(self, consume, final: bool = False) -> None:
        """``consume(poses (n, POSE_DIM))`` every full chunk; with ``final`` (engine stopped) the rest too."""
        while self.ready:
            consume(self.ready.popleft())
        if final and self._fill:
            consume(self._buf[: self._fill].copy())
            self._fill = 0

    def close(self) -> None:
        pass

    def stats(self) -> dict[str, float]:
        return {"frames": self.frames}


def stability_reference_m(data_root: str, cache_dir: str | None, checkpoint: str | None = None) -> float:
    """The real validation dances' dance-band RMS, m (:func:`models.evaluation.stability.real_reference_m`);
    the corpus cache entries of ``checkpoint``'s (default: the packaged one's) features are used."""
    from models.evaluation.stability import real_reference_m
    from models.generate import load_model
    from realtime.pipeline import default_checkpoint_path

    path = checkpoint or default_checkpoint_path()
    features = load_model(path).features if Path(path).is_file() else None
    return real_reference_m(data_root, cache_dir, features)


def default_pipeline(checkpoint: str | None = None):
    """(Pipeline, trained): the given or packaged checkpoint, else random default-size weights."""
    from realtime.pipeline import build_pipeline, default_checkpoint_path, random_pipeline

    if checkpoint is None and not default_checkpoint_path().is_file():
        return random_pipeline(), False
    return build_pipeline(checkpoint), True


def clip_audio() -> tuple[np.ndarray, int]:
    """The bundled clip, mono float32 at 22050 Hz."""
    from models.features.audio_io import bundled_clip_path, load_audio

    audio, sr = load_audio(bundled_clip_path(), SAMPLE_RATE)
    return audio.astype(np.float32), sr


def playlist(paths: list[str | Path]) -> tuple[np.ndarray, list[dict]]:
    """The songs ``paths`` back to back, mono float32 at 22050 Hz, and where each lies in it.

    Returns ``(audio, segments)``; a segment is ``{"name", "path", "start", "samples",
    "start_s", "seconds"}`` (``start``/``samples`` in samples at 22050 Hz; ``name``: the
    file's parent folder for a DWM ``audio.mp3``, else its stem). The soak loops the whole
    list: songs follow each other with no gap, so every 30-s stretch is music (a pause
    between songs is the idle's case, docs/reliability.md). AudioError if a file is
    missing or unreadable.
    """
    from models.features.audio_io import load_audio

    parts, segments, start = [], [], 0
    for path in map(Path, paths):
        audio, _ = load_audio(path, SAMPLE_RATE)
        name = path.parent.name if path.stem == "audio" else path.stem
        segments.append({"name": name, "path": str(path), "start": start, "samples": len(audio),
                         "start_s": start / SAMPLE_RATE, "seconds": len(audio) / SAMPLE_RATE})
        parts.append(audio.astype(np.float32))
        start += len(audio)
    return np.concatenate(parts), segments


def playlist_pieces(start_s: float, end_s: float, segments: list[dict]) -> list[str]:
    """What of a looped playlist plays between ``start_s`` and ``end_s`` of the stream:
    ``["DANCE_C_2 84.0-114.0 s", ...]`` (times within each song). Counted in whole samples
    at 22050 Hz, so every piece is at least a sample long and the walk always ends."""
    total = sum(g["samples"] for g in segments)
    n, end = int(round(start_s * SAMPLE_RATE)), int(round(end_s * SAMPLE_RATE))
    out = []
    while n < end:
        pos = n % total
        seg = next(g for g in segments if g["start"] <= pos < g["start"] + g["samples"])
        a = pos - seg["start"]
        take = min(seg["samples"] - a, end - n)
        out.append(f"{seg['name']} {a / SAMPLE_RATE:.1f}-{(a + take) / SAMPLE_RATE:.1f} s")
        n += take
    return out


# ---------------------------------------------------------------------------- helper processes


def _spawn(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, str(Path(__file__).resolve()), *args], cwd=REPO,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)


def _read_json_line(proc: subprocess.Popen, timeout: float) -> dict:
    """Next JSON line the helper prints (TimeoutError if none within ``timeout`` s)."""
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], timeout)
    if not ready:
        raise TimeoutError(f"helper process printed nothing within {timeout} s")
    line = proc.stdout.readline()
    if not line:
        raise RuntimeError(f"helper process exited with status {proc.wait()}")
    return json.loads(line)


class _Helper:
    """A helper process started from this file (``proc``)."""

    proc: subprocess.Popen

    def kill(self) -> None:
        """Ends the helper if it is still running (a no-op after a normal finish)."""
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()


class Crowd(_Helper):
    """``crowd`` in another process: ``clients`` WebSocket connections opened at once."""

    def __init__(self, url: str, clients: int, seconds: float = 0.0, fmt: str = "binary", check_every: int = 1,
                 wait_go: bool = False) -> None:
        self.proc = _spawn("crowd", "--url", url, "--clients", str(clients), "--seconds", str(seconds),
                           "--format", fmt, "--check-every", str(check_every), *(["--wait-go"] if wait_go else []))
        if wait_go:  # started and imported: its start-up cost is paid before the measurement
            _read_json_line(self.proc, 60)

    def go(self) -> None:
        """With ``wait_go``: open the connections now."""
        assert self.proc.stdin is not None
        self.proc.stdin.write("go\n")
        self.proc.stdin.flush()

    def connected(self, timeout: float = 60.0) -> dict:
        """Blocks until every connection attempt got its hello or its refusal."""
        return _read_json_line(self.proc, timeout)

    def result(self, timeout: float = 60.0) -> dict:
        """The final summary (after ``seconds``, or once the server closed every connection)."""
        out = _read_json_line(self.proc, timeout)
        self.proc.wait(timeout)
        return out


class UdpCounter(_Helper):
    """``udp`` in another process: counts VMC frames sent to ``port``."""

    def __init__(self) -> None:
        self.proc = _spawn("udp")
        self.port = int(_read_json_line(self.proc, 30)["port"])

    def result(self, timeout: float = 30.0) -> dict:
        assert self.proc.stdin is not None
        time.sleep(0.3)  # the last datagrams are in flight
        self.proc.stdin.close()
        out = _read_json_line(self.proc, timeout)
        self.proc.wait(timeout)
        return out


async def _crowd(url: str, clients: int, seconds: float, fmt: str, check_every: int = 1,
                 wait_go: bool = False) -> dict:
    from websockets.asyncio.client import connect
    from websockets.exceptions import ConnectionClosed

    from realtime.wire import decode_frame

    loop = asyncio.get_running_loop()
    if wait_go:
        print(json.dumps({"ready": True}), flush=True)
        await loop.run_in_executor(None, sys.stdin.readline)
    closes: Counter = Counter()
    errors: Counter = Counter()
    frames: list[int] = []
    nonfinite = 0
    hellos = 0
    resolved = 0
    all_resolved = asyncio.Event()

    def settle() -> None:
        nonlocal resolved
        resolved += 1
        if resolved == clients:
            all_resolved.set()

    async def one() -> None:
        nonlocal hellos, nonfinite
        settled = False
        n = 0
        try:
            async with connect(f"{url}?format={fmt}", open_timeout=60, close_timeout=2, max_size=1 << 20,
                               compression=None) as ws:
                hello = json.loads(await asyncio.wait_for(ws.recv(), 60))
                if hello.get("type") != "hello":
                    raise RuntimeError(f"first message is {hello.get('type')!r}, not hello")
                hellos += 1
                settled = True
                settle()
                await all_resolved.wait()
                end = math.inf if seconds <= 0 else loop.time() + seconds
                while (left := end - loop.time()) > 0:
                    try:
                        msg = await asyncio.wait_for(ws.recv(), min(left, 3600.0))
                    except TimeoutError:
                        break
                    if isinstance(msg, bytes):
                        n += 1
                        if n % check_every == 0:
                            nonfinite += not bool(np.isfinite(decode_frame(msg).pose).all())
                    else:
                        doc = json.loads(msg)
                        if doc.get("type") == "frame":
                            n += 1
                            nonfinite += not all(map(math.isfinite, [*doc["root"], *sum(doc["rotations"], [])]))
        except ConnectionClosed as exc:
            closes[str(exc.rcvd.code if exc.rcvd else 1006)] += 1
        except Exception as exc:  # noqa: BLE001 - reported in the summary
            errors[f"{type(exc).__name__}: {exc}"[:120]] += 1
        finally:
            frames.append(n)
            if not settled:
                settle()

    async def report_connected() -> None:
        await all_resolved.wait()
        print(json.dumps({"connected": hellos, "refused": dict(closes), "errors": dict(errors)}), flush=True)

    reporter = asyncio.create_task(report_connected())
    await asyncio.gather(*(one() for _ in range(clients)))
    await reporter
    return {"clients": clients, "hellos": hellos, "closes": dict(closes), "errors": dict(errors),
            "frames": frames, "nonfinite": nonfinite}


def _udp_main() -> int:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.2)
    print(json.dumps({"port": sock.getsockname()[1]}), flush=True)
    done = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
    datagrams = frames = nonfinite = 0
    last_time = -math.inf
    backwards = 0
    while not done.is_set():
        try:
            data = sock.recv(65536)
        except TimeoutError:
            continue
        datagrams += 1
        at = data.rfind(_VMC_T)
        if at >= 0 and at + len(_VMC_T) + 4 <= len(data):
            (t,) = np.frombuffer(data, ">f4", 1, at + len(_VMC_T))
            frames += 1
            if not math.isfinite(t):
                nonfinite += 1
            elif t < last_time:
                backwards += 1
            last_time = max(last_time, float(t))
    print(json.dumps({"datagrams": datagrams, "frames": frames, "nonfinite": nonfinite, "time_backwards": backwards}),
          flush=True)
    return 0


# ---------------------------------------------------------------------------- engine runs


def paced_run(pipeline, audio: np.ndarray, sr: int, seconds: float, sinks, during=None) -> dict:
    """Replay ``audio`` (looped) in real time for ``seconds`` through a fresh engine; ``during(engine)``
    runs on this thread once the engine started. Returns ``Engine.stats()`` plus ``rss_delta``."""
    from realtime.audio_input import FileSource
    from realtime.engine import Engine
    from realtime.engine_config import EngineConfig

    src = FileSource(audio, sr, realtime=True, loop=True, name="clip")
    eng = Engine(src, pipeline.extractor_factory, pipeline.model, sinks,
                 EngineConfig(warmup_s=1.0, duration_s=seconds, stats_size=int(seconds * FPS) + 1))
    rss0 = rss_bytes()
    eng.start()
    try:
        if during is not None:
            during(eng)
        eng.wait(seconds + 60)
    finally:
        eng.stop()
    return {**eng.stats(), "rss_delta": rss_bytes() - rss0}


def measure_load(clients: int, max_clients: int, seconds: float, repeat: int = 1, pipeline=None,
                 engine_cpus: set[int] | None = None, client_cpus: set[int] | None = None) -> dict:
    """Per-hop compute p99 without clients and with ``clients`` connecting at once (cap ``max_clients``).

    Runs are interleaved (unloaded, loaded, unloaded, ...); the figures are the medians
    over repeats. Clients stay connected for the whole loaded run. ``engine_cpus`` pins
    this process (engine, WebSocket server) and ``client_cpus`` the client process, so the
    clients' own CPU use, which on a stage is spent on the viewers' machines, does not
    count as engine load (None: no pinning, both share every CPU).
    """
    from realtime.ws_server import WebSocketSink

    if engine_cpus:
        os.sched_setaffinity(0, engine_cpus)
    if pipeline is None:
        pipeline, _ = default_pipeline()
    audio, sr = clip_audio()
    runs: dict[str, list[dict]] = {"unloaded": [], "loaded": []}
    crowds: list[dict] = []
    rss_start = rss_bytes()
    rss_first = None  # after the first (unloaded, loaded) pair: one-time costs paid
    for _ in range(repeat):
        if rss_first is None and runs["loaded"]:
            rss_first = rss_bytes()
        for kind in ("unloaded", "loaded"):
            ws = WebSocketSink("127.0.0.1", 0, max_clients=max_clients, offsets=np.tile([0.0, 0.1, 0.0], (21, 1)))
            check = FrameCheck()
            # the client process starts before the engine; each client checks every 10th frame
            crowd = None if kind == "unloaded" else Crowd(ws.ws_url, clients, seconds=max(1.0, seconds - 2.0),
                                                          check_every=10, wait_go=True)
            if crowd is not None and client_cpus:
                os.sched_setaffinity(crowd.proc.pid, client_cpus)

            def during(_eng, crowd=crowd) -> None:
                if crowd is not None:
                    crowd.go()
                    crowds.append({"connected": crowd.connected()})

            try:
                st = paced_run(pipeline, audio, sr, seconds, [ws, check], during)
                if crowd is not None:
                    crowds[-1].update(crowd.result())
            finally:
                if crowd is not None:
                    crowd.kill()
                ws.close()
            runs[kind].append({"p50": st["compute_ms_p50"], "p99": st["compute_ms_p99"], "frames": st["frames"],
                               "nonfinite": check.nonfinite, "refused": st["sinks"][ws.name]["refused"]})
    med = {k: {q: float(np.median([r[q] for r in v])) for q in ("p50", "p99")} for k, v in runs.items()}
    return {
        "clients": clients, "max_clients": max_clients, "seconds": seconds, "repeat": repeat,
        "engine_cpus": sorted(engine_cpus or []), "client_cpus": sorted(client_cpus or []),
        "unloaded": med["unloaded"], "loaded": med["loaded"],
        "p99_ratio": med["loaded"]["p99"] / med["unloaded"]["p99"],
        "runs": runs, "crowds": crowds, "rss_growth_mb": (rss_bytes() - rss_start) / 2**20,
        "rss_growth_after_first_mb": None if rss_first is None else (rss_bytes() - rss_first) / 2**20,
    }


def soak(minutes: float, checkpoint: str | None = None, progress: bool = True,
         stability_ref_m: float | None = None, audio_paths: list[str | Path] | None = None) -> dict:
    """The soak (module docstring); returns the figures and ``ok``/``failures``.

    ``stability_ref_m``: the real dances' dance-band RMS in metres; when given, every frame
    sent goes through :class:`models.evaluation.stability.StabilityMonitor` (result under
    ``"stability"``, a failing stretch fails the soak; each stretch lists the songs it
    covers under ``"songs"``). ``audio_paths``: songs played back to back and looped
    (:func:`playlist`) instead of the bundled clip.
    """
    from models.evaluation.stability import StabilityMonitor
    from realtime.audio_input import FileSource
    from realtime.engine import Engine
    from realtime.engine_config import EngineConfig
    from realtime.osc_out import OscSink
    from realtime.ws_server import WebSocketSink

    pipeline, trained = default_pipeline(checkpoint)
    if audio_paths:
        audio, segments = playlist(audio_paths)
        sr, name = SAMPLE_RATE, f"{len(segments)} songs (looped)"
    else:
        audio, sr = clip_audio()
        segments, name = [{"name": "clip", "path": "models/assets/clip.ogg", "start": 0, "samples": len(audio),
                           "start_s": 0.0, "seconds": len(audio) / sr}], "clip (looped)"
    seconds = minutes * 60.0
    expected = int(round(seconds * sr)) // HOP
    warm_s = max(30.0, 0.1 * seconds)
    udp = UdpCounter()
    ws = WebSocketSink("127.0.0.1", 0)
    osc = OscSink("127.0.0.1", udp.port, "vmc")
    check = FrameCheck()
    stage = getattr(pipeline.model, "stage", None)  # the dancing default travels on performer run's 3x2 stage
    stage = (stage.width, stage.depth) if stage is not None and getattr(stage, "active", False) else None
    monitor = None if stability_ref_m is None else StabilityMonitor(stability_ref_m, stage=stage)
    tap = None if monitor is None else PoseTap()
    src = FileSource(audio, sr, realtime=False, loop=True, name=name)
    eng = Engine(src, pipeline.extractor_factory, pipeline.model, [osc, ws, check] + ([tap] if tap else []),
                 EngineConfig(warmup_s=3.0, duration_s=seconds))
    crowd = Crowd(ws.ws_url, 2, seconds=0)  # until the server closes
    samples: list[tuple[float, float, int, int]] = []  # (wall s, audio s, rss, fds)
    t0 = time.monotonic()
    try:
        crowd.connected()
        eng.start()
        next_print = 0.0
        while not eng.wait(1.0):
            if tap is not None:
                tap.drain(monitor.add)
            a = eng.stats()["audio_seconds"]
            samples.append((time.monotonic() - t0, a, rss_bytes(), open_fds()))
            if progress and a >= next_print:
                print(f"  {a / 60:6.1f} of {minutes:g} min of audio, RSS {samples[-1][2] / 2**20:.1f} MiB, "
                      f"{samples[-1][3]} fds, {check.frames} frames", file=sys.stderr, flush=True)
                next_print = a + max(30.0, seconds / 20)
        samples.append((time.monotonic() - t0, eng.stats()["audio_seconds"], rss_bytes(), open_fds()))
        wall = time.monotonic() - t0
        if tap is not None:
            tap.drain(monitor.add, final=True)
        st = eng.stats()
        eng.close()  # closes the WebSocket clients: the crowd reports
        crowd_out = crowd.result()
        udp_out = udp.result()
    finally:
        eng.stop()
        crowd.kill()
        udp.kill()
    warm = next((s for s in samples if s[1] >= warm_s), samples[-1])
    end = samples[-1]
    out = {
        "minutes": minutes, "model": "trained" if trained else "random weights (default size)",
        "audio": segments, "playlist_s": len(audio) / sr,
        "expected_frames": expected, "frames": st["frames"], "checked_frames": check.frames,
        "nan_frames": st["nan_frames"], "nonfinite_sent": check.nonfinite, "index_gaps": check.index_gaps,
        "max_rotation_step_deg": check.max_step_deg,
        "max_rotation_step_at": {"frame": check.max_step_at, "audio_s": round(check.max_step_at / 30.0, 2),
                                 "bone": BONES[check.max_step_bone] if check.max_step_bone >= 0 else None},
        "wall_s": wall, "speed": seconds / wall,
        "compute_ms_p50": st["compute_ms_p50"], "compute_ms_p99": st["compute_ms_p99"],
        "warm_audio_s": warm[1], "rss_warm_mib": warm[2] / 2**20, "rss_end_mib": end[2] / 2**20,
        "rss_max_after_warm_mib": max(s[2] for s in samples if s[1] >= warm[1]) / 2**20,
        "rss_growth_pct": 100.0 * (end[2] - warm[2]) / warm[2],
        "fds_warm": warm[3], "fds_end": end[3],
        "osc": {k: v for k, v in st["sinks"][osc.name].items()}, "udp_receiver": udp_out,
        "ws": {k: v for k, v in st["sinks"][ws.name].items() if not k.startswith("drops.")},
        "ws_clients": crowd_out,
    }
    failures = []
    if out["frames"] != expected or out["checked_frames"] != expected:
        failures.append(f"frame count {out['frames']} (checked {out['checked_frames']}), expected {expected}")
    if out["nan_frames"] or out["nonfinite_sent"] or udp_out["nonfinite"] or crowd_out["nonfinite"]:
        failures.append("non-finite frames")
    if out["index_gaps"]:
        failures.append(f"{out['index_gaps']} gaps in frame indices")
    if out["rss_growth_pct"] >= 5.0:
        failures.append(f"RSS grew {out['rss_growth_pct']:.2f} % after warm-up")
    if out["fds_end"] > out["fds_warm"]:
        failures.append(f"open file descriptors grew from {out['fds_warm']} to {out['fds_end']}")
    if monitor is not None:
        report = monitor.result()
        out["stability"] = report.to_dict()
        for st in out["stability"]["stretches"]:
            st["songs"] = playlist_pieces(st["start_s"], st["end_s"], segments)
        if not report.ok:
            failures.append("stability: " + report.summary())
    out["failures"] = failures
    out["ok"] = not failures
    return out


def _print_soak(r: dict) -> None:
    songs = ", ".join(f"{g['name']} ({g['seconds']:.0f} s)" for g in r.get("audio", []))
    print(f"soak: {r['minutes']:g} min of audio ({r['model']}) in {r['wall_s']:.0f} s ({r['speed']:.1f}x real time)"
          + (f"; looped: {songs}" if songs else ""))
    print(f"  frames {r['frames']} of {r['expected_frames']} expected; checked {r['checked_frames']}, "
          f"non-finite sent {r['nonfinite_sent']}, engine NaN guard {r['nan_frames']}, index gaps {r['index_gaps']}")
    print(f"  per-hop compute p50 {r['compute_ms_p50']:.2f} ms p99 {r['compute_ms_p99']:.2f} ms (last 2048 frames)")
    print(f"  RSS {r['rss_warm_mib']:.1f} MiB after {r['warm_audio_s']:.0f} s of audio -> {r['rss_end_mib']:.1f} MiB "
          f"at the end ({r['rss_growth_pct']:+.2f} %; max after warm-up {r['rss_max_after_warm_mib']:.1f} MiB)")
    print(f"  open fds {r['fds_warm']} -> {r['fds_end']}")
    u, o = r["udp_receiver"], r["osc"]
    print(f"  VMC: {o['frames']:.0f} frames, {o['sent']:.0f} datagrams sent, {o['errors']:.0f} errors; receiver got "
          f"{u['frames']} frames ({u['nonfinite']} non-finite, {u['time_backwards']} out of order)")
    c = r["ws_clients"]
    print(f"  WebSocket: {r['ws']['frames']:.0f} frames, {r['ws']['drops']:.0f} dropped for slow clients; "
          f"clients got {c['frames']} ({c['nonfinite']} non-finite), closes {c['closes']}")
    at = r.get("max_rotation_step_at", {})
    print(f"  largest frame-to-frame rotation change {r['max_rotation_step_deg']:.1f} deg"
          + (f" ({at['bone']}, frame {at['frame']}, {at['audio_s']:.1f} s of audio)" if at.get("bone") else ""))
    if "stability" in r:
        _print_stability(r["stability"])
    print("  OK" if r["ok"] else "  FAILED: " + "; ".join(r["failures"]))


def _print_stability(st: dict) -> None:
    rows = [s for s in st["stretches"] if s["amp_ratio"] is not None]
    failing = sum(bool(s["reasons"]) for s in st["stretches"])
    line = f"  stability: {len(st['stretches'])} stretches of {st['stretch_s']:g} s, {failing} failing"
    if rows:
        amps = [s["amp_ratio"] for s in rows]
        horizontal = max(s["root_horizontal_m"] for s in rows)
        where = (f"root {horizontal:.2f} m outside the {st['stage'][0]:g}x{st['stage'][1]:g} m stage and "
                 if st.get("stage") else f"root within {horizontal:.2f} m horizontally and ")
        line += (f"; amplitude {min(amps):.2f}-{max(amps):.2f}x the real {st['ref_m'] * 100:.2f} cm (0.5-1.5x), "
                 f"{where}{max(s['root_vertical_m'] for s in rows):.2f} m vertically (0.5), longest still "
                 f"{max(s['still_s'] for s in rows):.1f} s, fastest point {max(s['max_speed'] for s in rows):.1f} m/s")
    print(line)
    for s in st["stretches"]:
        if s["reasons"]:
            print(f"    stretch {s['index']} ({s['start_s']:g}-{s['end_s']:g} s; {', '.join(s.get('songs', []))}): "
                  + "; ".join(s["reasons"]))


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["udp"]:
        return _udp_main()
    if argv[:1] == ["crowd"]:
        p = argparse.ArgumentParser(prog="soak.py crowd")
        p.add_argument("--url", required=True)
        p.add_argument("--clients", type=int, default=200)
        p.add_argument("--seconds", type=float, default=3.0, help="0: until the server closes")
        p.add_argument("--format", default="binary", choices=("binary", "json"))
        p.add_argument("--check-every", type=int, default=1, help="decode and check every Nth binary frame")
        p.add_argument("--wait-go", action="store_true", help="print {\"ready\": true}, connect on a stdin line")
        a = p.parse_args(argv[1:])
        out = asyncio.run(_crowd(a.url, a.clients, a.seconds, a.format, a.check_every, a.wait_go))
        print(json.dumps(out), flush=True)
        return 0
    if argv[:1] == ["load"]:
        p = argparse.ArgumentParser(prog="soak.py load")
        p.add_argument("--clients", type=int, default=200)
        p.add_argument("--max-clients", type=int, default=16)
        p.add_argument("--seconds", type=float, default=8.0)
        p.add_argument("--repeat", type=int, default=2)
        p.add_argument("--engine-cpus", help="pin the engine (this process) to these CPUs, e.g. 0")
        p.add_argument("--client-cpus", help="pin the client process to these CPUs, e.g. 1")
        a = p.parse_args(argv[1:])
        cpus = [None if c is None else {int(x) for x in c.split(",")} for c in (a.engine_cpus, a.client_cpus)]
        r = measure_load(a.clients, a.max_clients, a.seconds, a.repeat, engine_cpus=cpus[0], client_cpus=cpus[1])
        print(f"load: {a.clients} clients at once, cap {a.max_clients}, {a.seconds:g} s runs x {a.repeat}: "
              f"per-hop compute p50 {r['unloaded']['p50']:.2f} -> {r['loaded']['p50']:.2f} ms, "
              f"p99 {r['unloaded']['p99']:.2f} -> {r['loaded']['p99']:.2f} ms (ratio {r['p99_ratio']:.2f}); "
              f"served {[c.get('hellos') for c in r['crowds']]}, closes {[c.get('closes') for c in r['crowds']]}, "
              f"RSS {r['rss_growth_mb']:+.1f} MiB in all"
              + ("" if r["rss_growth_after_first_mb"] is None else
                 f", {r['rss_growth_after_first_mb']:+.1f} MiB after the first pair"))
        return 0
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--minutes", type=float, default=60.0, help="minutes of audio (default 60)")
    p.add_argument("--checkpoint", help="checkpoint (default: the packaged one, else random weights)")
    p.add_argument("--json", help="also write the figures to this JSON file")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.add_argument("--audio", action="append", metavar="FILE",
                   help="a song to play instead of the bundled clip (repeatable: the songs play back to back, "
                        "looped)")
    p.add_argument("--songs", nargs="+", metavar="NAME",
                   help="songs of the DWM dataset under --data (DIR/NAME/audio.mp3), after any --audio")
    g = p.add_argument_group("stability check (issue 18; off unless one of these is given)")
    g.add_argument("--stability-ref-m", type=float, metavar="M",
                   help="the real dances' dance-scale amplitude (band RMS 0.25-3 Hz, metres) every 30-s stretch "
                        "is judged against")
    g.add_argument("--data", metavar="DIR", help="compute that amplitude from the validation dances of the DWM "
                                                 "dataset under DIR")
    g.add_argument("--cache", metavar="DIR", default=".cache/corpus",
                   help="corpus cache for --data (default .cache/corpus)")
    a = p.parse_args(argv)
    ref = a.stability_ref_m
    if ref is not None and a.data:
        p.error("give --stability-ref-m or --data, not both")
    if ref is not None and not (math.isfinite(ref) and ref > 0):
        p.error(f"--stability-ref-m must be a positive number of metres, got {ref}")
    if a.songs and not a.data:
        p.error("--songs needs --data DIR (the dataset the names are in)")
    paths = [Path(f) for f in a.audio or []] + [Path(a.data) / n / "audio.mp3" for n in a.songs or []]
    missing = [str(f) for f in paths if not f.is_file()]
    if missing:
        p.error(f"audio file(s) not found: {', '.join(missing)}")
    if a.data:
        from models.errors import PerformerError

        try:
            ref = stability_reference_m(a.data, a.cache, a.checkpoint)
        except PerformerError as exc:
            p.error(f"--data: {exc}")
        if not a.quiet:
            print(f"  stability reference: {ref * 100:.2f} cm band RMS (0.25-3 Hz) of the validation dances under "
                  f"{a.data}", file=sys.stderr)
    r = soak(a.minutes, a.checkpoint, progress=not a.quiet, stability_ref_m=ref, audio_paths=paths or None)
    if a.json:
        Path(a.json).write_text(json.dumps(r, indent=1))
    _print_soak(r)
    return 0 if r["ok"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
