"""A web audience through a NATS broker: N subscribers on the broker's WebSocket port, one performer.

For each audience size, a fresh nats-server (realtime/nats_server.py: the publisher and the
subscribe-only viewer accounts) and N asyncio subscribers in ``--procs`` processes, each a
lean NATS-over-WebSocket client (:class:`_Subscriber`: CONNECT as the viewer, SUB
``performer.main.frames``, answer PINGs), as the browser's nats.ws speaks it. The real engine
(the packaged checkpoint, the bundled clip looped in real time, VMC to a local UDP socket) then
plays ``--seconds`` of audio with the broker output (``realtime/publish_process.py``, as ``performer run --publish``) behind a gate
that passes every other block of ``--block`` frames (2 s): one run holds both conditions in
turns, so the machine's changing load (other programs) falls on both alike. Reported:

* delivery: for every frame published, the share of subscribers that received it, in order
  (the least over frames, and the share of subscribers that got every frame in order);
* publish-to-receive: the subscriber's ``time.time()`` minus the frame's ``send_time``
  (stamped in ``ProcessRoute.send``), p50 and p99 over every frame of every subscriber, and
  the same for a probe: one more subscriber in a process of its own (no other subscriber of
  its process to wait for);
* the performer's per-hop compute (the engine's own timer, per frame: all of it, and its own
  part less the run-queue wait), p99 without and with publishing, and their ratio;
* the broker's CPU (share of one core over the publishing phases) and peak RSS, and the
  subscriber processes' CPU, from /proc.

    .venv/bin/python benchmarks/audience.py --subscribers 100 500 1000 --seconds 60
    .venv/bin/python benchmarks/audience.py --subscribers 300 --cluster 3 --procs 3   # 3 routed nodes

Everything runs on this machine: the subscribers' and the broker's CPU compete with the
engine's, which an audience served from other machines would not. ``--performer-cpus 0
--audience-cpus 1`` stands in for that: the engine's process (and the publisher process it
starts, as ``performer run --publish`` does) on CPU 0, the broker and every subscriber on CPU
1 (sched_setaffinity, inherited by every thread and child; the affinities are read back from
/proc and reported). Other programs on the machine are not pinned and still use both.
``--unpinned-too`` runs each size unpinned first, then pinned, in the same session. The
publisher process goes where ``performer run`` puts it (publish_cpus = auto: off the engine's
CPUs when those are pinned; SCHED_BATCH); ``--publisher-cpus`` and ``--publisher-normal`` place
it otherwise, ``--beside-too`` adds a mode with it beside the engine as a normal process (as
before). ``--runs K`` repeats each size, the modes in turns, and sums the runs up: one run's
p99 over 840 hops moves by tens of percent on a shared machine. Each frame's hand-over
(``route.send``: encode, one ``os.write`` to the publisher's pipe) is timed, wall and the
worker's CPU time, ms: their gap is the worker waiting while the publisher it woke runs.

    .venv/bin/python benchmarks/audience.py --subscribers 100 500 1000 --performer-cpus 0 --audience-cpus 1 --unpinned-too
    .venv/bin/python benchmarks/audience.py --subscribers 500 1000 100 --performer-cpus 0 --audience-cpus 1 \
        --beside-too --runs 3
"""

from __future__ import annotations

import argparse
import asyncio
import base64
import json
import os
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from realtime import sched  # noqa: E402

SUBJECT = "performer.main"


# ---- subscriber process -------------------------------------------------------------------


class _Subscriber(asyncio.Protocol):
    """One audience member: a WebSocket client (RFC 6455 by hand: the upgrade request, unmasked
    server frames, masked client frames) speaking the NATS protocol as nats.ws does: CONNECT
    as the viewer, SUB to the frames, PONG to the server's PING. Lean on purpose (about 5 us a
    message): a thousand of them share two cores with the broker and the performer."""

    received_at = 0.0  # monotonic time of the last data, any subscriber of the process

    def __init__(self, host: str, port: int, user: tuple[str, str], ready: asyncio.Event) -> None:
        self.host, self.port, self.user, self.ready = host, port, user, ready
        self.index: list[int] = []
        self.latency: list[float] = []
        self.errors: list[str] = []
        self.buf = bytearray()
        self.nats = bytearray()
        self.upgraded = False

    def connection_made(self, transport) -> None:
        self.tr = transport
        key = base64.b64encode(os.urandom(16)).decode()
        transport.write(f"GET / HTTP/1.1\r\nHost: {self.host}:{self.port}\r\nUpgrade: websocket\r\n"
                        f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n"
                        .encode())

    def send(self, data: bytes) -> None:
        """One masked binary frame (a zero mask key: the XOR leaves the data as it is)."""
        n = len(data)
        head = bytes([0x82, 0x80 | n]) if n < 126 else bytes([0x82, 0x80 | 126]) + n.to_bytes(2, "big")
        self.tr.write(head + b"\0\0\0\0" + data)

    def data_received(self, data: bytes) -> None:
        now = time.time()
        _Subscriber.received_at = time.monotonic()
        buf = self.buf
        buf += data
        if not self.upgraded:
            end = buf.find(b"\r\n\r\n")
            if end < 0:
                return
            if b" 101 " not in buf[:end].split(b"\r\n", 1)[0]:
                self.errors.append(bytes(buf[:end]).decode(errors="replace")[:200])
                self.tr.close()
                return
            del buf[:end + 4]
            self.upgraded = True
        while len(buf) >= 2:
            opcode, n, off = buf[0] & 0x0F, buf[1] & 0x7F, 2
            if n == 126:
                if len(buf) < 4:
                    return
                n, off = int.from_bytes(buf[2:4], "big"), 4
            elif n == 127:
                if len(buf) < 10:
                    return
                n, off = int.from_bytes(buf[2:10], "big"), 10
            if len(buf) < off + n:
                return
            payload = bytes(buf[off:off + n])
            del buf[:off + n]
            if opcode in (0, 1, 2):
                self._nats(payload, now)
            elif opcode == 9:  # ping -> pong
                self.tr.write(bytes([0x8A, 0x80 | len(payload)]) + b"\0\0\0\0" + payload)

    def _nats(self, data: bytes, now: float) -> None:
        nb = self.nats
        nb += data
        while True:
            end = nb.find(b"\r\n")
            if end < 0:
                return
            if nb.startswith(b"MSG "):
                size = int(nb[:end].rsplit(b" ", 1)[1])
                if len(nb) < end + 4 + size:
                    return
                start = end + 2
                self.index.append(int.from_bytes(nb[start + 8:start + 12], "little"))
                self.latency.append(now - struct.unpack_from("<d", nb, start + 24)[0])
                del nb[:end + 4 + size]
                continue
            line = bytes(nb[:end])
            del nb[:end + 2]
            if line.startswith(b"INFO "):
                login = json.dumps({"user": self.user[0], "pass": self.user[1], "verbose": False,
                                    "pedantic": False, "protocol": 1, "name": "audience-bench"})
                self.send(f"CONNECT {login}\r\nSUB {SUBJECT}.frames 1\r\nPING\r\n".encode())
            elif line == b"PING":
                self.send(b"PONG\r\n")
            elif line == b"PONG":
                self.ready.set()
            elif line.startswith(b"-ERR"):
                self.errors.append(line.decode(errors="replace"))


async def _subscribers_main(url: str, count: int, folder: Path, user: tuple[str, str], kind: str = "subs") -> None:
    from urllib.parse import urlsplit

    u = urlsplit(url)
    loop = asyncio.get_running_loop()
    subs = [_Subscriber(u.hostname, u.port, user, asyncio.Event()) for _ in range(count)]
    for k, sub in enumerate(subs):
        await loop.create_connection(lambda sub=sub: sub, u.hostname, u.port)
        if k % 50 == 49:
            await asyncio.sleep(0.05)  # do not storm the broker's accept queue
    await asyncio.wait_for(asyncio.gather(*(s.ready.wait() for s in subs)), 120)
    (folder / f"ready-{os.getpid()}").write_text("1")
    while not (folder / "stop").exists():
        await asyncio.sleep(0.2)
    while time.monotonic() - _Subscriber.received_at < 2.0:  # what the broker still holds arrives
        await asyncio.sleep(0.2)
    for s in subs:
        s.tr.close()
    np.savez(folder / f"{kind}-{os.getpid()}.npz",
             index=np.array([np.array(s.index, np.int64) for s in subs], dtype=object),
             latency=np.array([np.array(s.latency, np.float64) for s in subs], dtype=object),
             errors=np.array([e for s in subs for e in s.errors]))


# ---- the benchmark ----------------------------------------------------------------------------


def _proc_cpu(pid: int) -> float:
    stat = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(stat[11]) + int(stat[12])) / os.sysconf("SC_CLK_TCK")


def _peak_rss(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024
    return 0


def _affinity(pid: int) -> list[int]:
    """The CPUs every thread of ``pid`` may run on (the union over its threads), read back."""
    cpus: set[int] = set()
    for tid in os.listdir(f"/proc/{pid}/task"):
        try:
            cpus |= os.sched_getaffinity(int(tid))
        except OSError:
            pass
    return sorted(cpus)


def _policy(pid: int) -> str:
    """The scheduling policy of every thread of ``pid``: "batch", "normal" or "mixed"."""
    from realtime.sched import is_batch

    kinds = {is_batch(int(tid)) for tid in os.listdir(f"/proc/{pid}/task")}
    return "mixed" if len(kinds) > 1 else "batch" if kinds == {True} else "normal"


class _Gate:
    """A Sink in front of the broker route: passes frames only in every other block of ``block``
    frames (the first block off), and remembers the indices it passed. One engine run then holds
    both conditions, alternating every couple of seconds, so a change in the machine's load
    (other programs) falls on both alike."""

    def __init__(self, route, block: int) -> None:
        self.route, self.block, self.name = route, block, route.name
        self.passed: list[int] = []
        self.send_ms: list[tuple[float, float]] = []  # per frame passed: route.send's wall and CPU time, ms

    def on(self, index: int) -> bool:
        return (index // self.block) % 2 == 1

    def send(self, frame) -> None:
        if self.on(frame.index):
            self.passed.append(frame.index)
            t, c = time.perf_counter(), time.thread_time()
            self.route.send(frame)
            self.send_ms.append(((time.perf_counter() - t) * 1e3, (time.thread_time() - c) * 1e3))

    def stats(self) -> dict:
        return self.route.stats()

    def close(self) -> None:
        self.route.close()


def _play(seconds: float, block: int, broker_url: str, publisher_cpus: set[int] | None = None,
          batch: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray, _Gate, dict]:
    """One engine run of ``seconds`` of the clip (looped) in real time, VMC to a local socket and the
    broker route behind a :class:`_Gate`. Returns per frame the hop compute (ms), its own part (less
    the run-queue wait, as ``performer bench latency`` reports it) and whether publishing was on;
    the gate; the publisher's stats. The publisher process runs on ``publisher_cpus`` (None: as
    ``performer run`` places it, publish_cpus = "auto"), under SCHED_BATCH unless ``batch`` is False."""
    import socket

    from models.features.audio_io import bundled_clip_path, load_audio
    from realtime.audio_input import FileSource
    from realtime.engine import Engine
    from realtime.engine_config import EngineConfig
    from realtime.nats_server import PUBLISHER
    from realtime.osc_out import OscSink
    from realtime.pipeline import build_pipeline
    from realtime.publish import Credentials
    from realtime.publish_process import BrokerProcess
    from realtime.sched import publisher_cpus as auto_cpus

    pipe = build_pipeline(None)
    audio, sr = load_audio(bundled_clip_path(), 44100, mono=False)
    n = int(seconds * sr)
    audio = np.concatenate([audio] * (n // len(audio) + 1))[:n]
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    pub = BrokerProcess(broker_url, credentials=Credentials(user=PUBLISHER[0], password=PUBLISHER[1]),
                        cpus=auto_cpus(None) if publisher_cpus is None else publisher_cpus, batch=batch,
                        cpus_quiet=publisher_cpus is None)
    gate = _Gate(pub.route("main", SUBJECT), block)
    eng = Engine(FileSource(audio, sr, realtime=True), pipe.extractor_factory, pipe.model,
                 [OscSink("127.0.0.1", rx.getsockname()[1], "vmc"), gate],
                 EngineConfig(warmup_s=1.0, stats_size=1 << 17, runqueue_wait=True))
    eng.start()
    eng.wait(seconds + 120)
    hop = eng.compute_ms.values()
    own = hop - eng.compute_wait_ms.values()
    cpu = eng.compute_cpu_ms.values()
    stats = gate.stats()
    stats["publisher_cpus"] = _affinity(pub._proc.pid)
    stats["publisher_batch"] = _policy(pub._proc.pid)
    eng.close()
    rx.close()
    on = np.array([gate.on(i) for i in range(len(hop))])
    return hop, own, cpu, on, gate, stats


def run_size(n: int, seconds: float, procs: int, cluster: int, block: int,
             performer_cpus: set[int] | None = None, audience_cpus: set[int] | None = None,
             publisher_cpus: set[int] | None = None, batch: bool = True) -> dict:
    """One audience size; with ``performer_cpus`` and ``audience_cpus`` the broker and subscribers
    are started on the audience's CPUs and the engine (and its publisher child) runs on the performer's."""
    from realtime.nats_server import LocalBroker, free_port

    every_cpu = os.sched_getaffinity(0)
    if audience_cpus is not None:
        os.sched_setaffinity(0, audience_cpus)  # this thread: the broker and subscribers inherit it
    folder = Path(tempfile.mkdtemp(prefix=f"audience-{n}-"))
    if cluster > 1:
        cports = [free_port() for _ in range(cluster)]
        brokers = [LocalBroker(folder / f"n{i}", name=f"n{i}", cluster_port=cports[i],
                               routes=[p for j, p in enumerate(cports) if j != i]) for i in range(cluster)]
    else:
        brokers = [LocalBroker(folder)]
    for b in brokers:
        b.start()
    time.sleep(1.0 if cluster > 1 else 0.1)  # routes connect
    subs: list = []
    probe = None
    try:
        per = [n // procs + (1 if k < n % procs else 0) for k in range(procs)]
        for k, count in enumerate(per):
            url = brokers[k % len(brokers)].ws_url
            subs.append(subprocess.Popen([sys.executable, __file__, "--subscriber-process", str(count), "--url", url,
                                          "--folder", str(folder)]))
        # The probe: one more subscriber with a process of its own, so its publish-to-receive
        # has no other subscriber of its process before it (the broker's fan-out and scheduling).
        probe = subprocess.Popen([sys.executable, __file__, "--subscriber-process", "1", "--url", brokers[-1].ws_url,
                                  "--folder", str(folder), "--probe"])
        deadline = time.monotonic() + 180
        while len(list(folder.glob("ready-*"))) < procs + 1:
            if time.monotonic() > deadline or any(p.poll() is not None for p in subs):
                raise RuntimeError("subscribers did not connect")
            time.sleep(0.2)
        time.sleep(1.0)
        if performer_cpus is not None:
            sched.pin(os.getpid(), performer_cpus)  # every thread; the engine's and the publisher child inherit it
        pinned = {"performer": _affinity(os.getpid()), "broker": sorted({c for b in brokers for c in _affinity(b.proc.pid)}),
                  "subscribers": sorted({c for p in [*subs, probe] for c in _affinity(p.pid)})}
        c0 = sum(b.cpu_rss()[0] for b in brokers)
        sub_cpu0 = sum(_proc_cpu(p.pid) for p in subs)
        t0 = time.monotonic()
        load0 = os.getloadavg()[0]
        hop, own, cpu, on, gate, stats = _play(seconds, block, brokers[0].url, publisher_cpus, batch)
        load1 = os.getloadavg()[0]
        pinned["publisher"] = stats["publisher_cpus"]
        pinned["publisher_policy"] = stats["publisher_batch"]
        wall = time.monotonic() - t0
        broker_cpu = (sum(b.cpu_rss()[0] for b in brokers) - c0) / wall
        sub_cpu = (sum(_proc_cpu(p.pid) for p in subs) - sub_cpu0) / wall
        time.sleep(1.0)  # the last frames reach every subscriber
        rss = [_peak_rss(b.proc.pid) for b in brokers]
        (folder / "stop").write_text("1")
        for p in [*subs, probe]:
            p.wait(120)
    finally:
        sched.pin(os.getpid(), every_cpu)
        (folder / "stop").write_text("1")
        for p in [*subs, *([probe] if probe is not None else [])]:
            if p.poll() is None:
                p.kill()
        for b in brokers:
            b.stop()
    index, latency, errors = [], [], []
    for f in sorted(folder.glob("subs-*.npz")):
        d = np.load(f, allow_pickle=True)
        index += list(d["index"])
        latency += list(d["latency"])
        errors += list(d["errors"])
    passed = np.array(gate.passed, np.int64)
    got = np.zeros(len(passed), np.int64)
    where = {int(i): k for k, i in enumerate(passed)}
    complete = 0
    for ix in index:
        ix = np.asarray(ix, np.int64)
        in_order = bool(np.all(np.diff(ix) > 0))
        for i in ix:
            k = where.get(int(i))
            if k is not None:
                got[k] += 1
        complete += in_order and len(ix) == len(passed) and bool(np.array_equal(ix, passed))
    per_frame = got / max(1, len(index))
    probe_ms = np.concatenate([np.asarray(x) for f in folder.glob("probe-*.npz")
                               for x in np.load(f, allow_pickle=True)["latency"]]) * 1e3
    lat_ms = np.concatenate([np.asarray(x) for x in latency]) * 1e3 if latency else np.array([np.nan])
    skip = 2 * block  # the first off and on blocks: the engine's first code steps, the first subscribers' wake-ups
    hop, own, cpu, on = hop[skip:], own[skip:], cpu[skip:], on[skip:len(hop) + skip]
    p99 = lambda x: float(np.percentile(x, 99))  # noqa: E731
    # the noise floor: the off blocks in two halves (blocks 0, 4, 8, ... against 2, 6, 10, ...), neither published
    off_a = ~on & ((np.arange(skip, skip + len(on)) // (2 * block)) % 2 == 0)
    off_b = ~on & ~off_a
    send = np.array(gate.send_ms[block:] or gate.send_ms or [(np.nan, np.nan)], np.float64)  # less the first on block
    return {
        "subscribers": n, "pinned": not (performer_cpus is None and audience_cpus is None and publisher_cpus is None),
        "cpus": pinned, "load_average": [load0, load1], "connected": len(index), "cluster_nodes": len(brokers), "procs": procs,
        "frames_published": int(stats["published"]), "frames_dropped": int(stats["drops"]) + int(stats["drops_down"]),
        "min_share_of_subscribers_per_frame": float(per_frame.min()) if per_frame.size else float("nan"),
        "share_of_subscribers_complete_in_order": complete / max(1, len(index)),
        "latency_ms_p50": float(np.percentile(lat_ms, 50)), "latency_ms_p99": p99(lat_ms),
        "probe_latency_ms_p50": float(np.percentile(probe_ms, 50)), "probe_latency_ms_p99": p99(probe_ms),
        "probe_frames": int(probe_ms.size),
        "hop_ms_p99_without": p99(hop[~on]), "hop_ms_p99_with": p99(hop[on]),
        "hop_ratio_p99": p99(hop[on]) / p99(hop[~on]),
        "hop_own_ms_p99_without": p99(own[~on]), "hop_own_ms_p99_with": p99(own[on]),
        "hop_own_ratio_p99": p99(own[on]) / p99(own[~on]),
        "hop_own_ratio_p99_off_off": p99(own[off_b]) / p99(own[off_a]),
        "hop_ratio_p99_off_off": p99(hop[off_b]) / p99(hop[off_a]),
        "send_ms_p50": float(np.median(send[:, 0])), "send_ms_p99": p99(send[:, 0]),
        "send_cpu_ms_p50": float(np.median(send[:, 1])), "send_cpu_ms_p99": p99(send[:, 1]),
        "hop_cpu_ms_p99_without": p99(cpu[~on]), "hop_cpu_ms_p99_with": p99(cpu[on]),
        "hop_cpu_ratio_p99": p99(cpu[on]) / p99(cpu[~on]),
        "hop_ms_p50_without": float(np.median(hop[~on])), "hop_ms_p50_with": float(np.median(hop[on])),
        "hop_own_ms_p50_without": float(np.median(own[~on])), "hop_own_ms_p50_with": float(np.median(own[on])),
        "hops": [int((~on).sum()), int(on.sum())],
        # what own time leaves out: the hop's run-queue wait (other processes, the publisher beside it included)
        "hop_wait_ms_mean_without": float(np.mean(hop[~on] - own[~on])), "hop_wait_ms_mean_with": float(np.mean(hop[on] - own[on])),
        "own_ms": {"off": own[~on].round(4).tolist(), "on": own[on].round(4).tolist()},  # per hop, for --runs
        "broker_cpu_share": broker_cpu, "broker_peak_rss_mb": [r / 2**20 for r in rss],
        "subscriber_procs_cpu_share": sub_cpu, "errors": [str(e) for e in errors[:5]],
    }


def _mode(r: dict) -> str:
    c = r["cpus"]
    if not r["pinned"]:
        return "unpinned"
    return f"pinned, publisher on {','.join(map(str, c['publisher']))} ({c.get('publisher_policy', '?')})"


def _print_runs(results: list[dict]) -> None:
    """Per size and mode over its runs: the own-time p99 ratio (with / without publishing) as the
    median and range of the runs, and pooled (every run's hops together); the same for the two
    halves of the unpublished blocks (the noise floor); send() wall p50 / p99 and the hop's mean
    run-queue wait (what own time leaves out), medians of the runs."""
    p99 = lambda x: float(np.percentile(x, 99))  # noqa: E731
    print("\n| subscribers | mode | runs | own p99 ratio: median [min, max] of runs | pooled own p99 ms without / with "
          "(ratio) | off/off ratio: median [min, max] (noise floor) | send() wall p50 / p99 ms | run-queue wait per hop, "
          "mean ms without / with | load average |")
    print("|---|---|---|---|---|---|---|---|---|")
    groups: dict[tuple[int, str], list[dict]] = {}
    for r in results:
        groups.setdefault((r["subscribers"], _mode(r)), []).append(r)
    for (n, mode), rs in groups.items():
        ratio = [r["hop_own_ratio_p99"] for r in rs]
        noise = [r["hop_own_ratio_p99_off_off"] for r in rs]
        off = np.concatenate([r["own_ms"]["off"] for r in rs])
        on = np.concatenate([r["own_ms"]["on"] for r in rs])
        loads = [x for r in rs for x in r["load_average"]]
        print(f"| {n} | {mode} | {len(rs)} | {np.median(ratio):.3f} [{min(ratio):.3f}, {max(ratio):.3f}] | "
              f"{p99(off):.2f} / {p99(on):.2f} ({p99(on) / p99(off):.3f}) | {np.median(noise):.3f} "
              f"[{min(noise):.3f}, {max(noise):.3f}] | {np.median([r['send_ms_p50'] for r in rs]):.3f} / "
              f"{np.median([r['send_ms_p99'] for r in rs]):.3f} | "
              f"{np.median([r.get('hop_wait_ms_mean_without', np.nan) for r in rs]):.3f} / "
              f"{np.median([r.get('hop_wait_ms_mean_with', np.nan) for r in rs]):.3f} | {min(loads):.1f}-{max(loads):.1f} |")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--subscribers", type=int, nargs="+", default=[100, 500, 1000], metavar="N",
                   help="audience sizes, one run each (default 100 500 1000)")
    p.add_argument("--seconds", type=float, default=60.0,
                   help="seconds of audio per audience size, publishing on and off in turns (default 60)")
    p.add_argument("--block", type=int, default=60, help="frames per on or off block (default 60: 2 s)")
    p.add_argument("--procs", type=int, default=2, help="subscriber processes (default 2)")
    p.add_argument("--cluster", type=int, default=1, metavar="K", help="K routed nats-server nodes (default 1); "
                   "the performer publishes to the first, subscriber process k connects to node k mod K")
    p.add_argument("--performer-cpus", metavar="CPUS", help="pin the engine's process and its publisher child to "
                   "these CPUs (e.g. 0, or 0-1, or 0,2); default: not pinned")
    p.add_argument("--audience-cpus", metavar="CPUS", help="pin the broker node(s) and the subscriber processes to "
                   "these CPUs (e.g. 1); default: not pinned")
    p.add_argument("--publisher-cpus", metavar="CPUS", help="the publisher process's CPUs (default: as performer "
                   "run places it, publish_cpus = auto: the CPUs the engine is not pinned to; 0 with "
                   "--performer-cpus 0: beside the engine)")
    p.add_argument("--publisher-normal", action="store_true", help="the publisher process under SCHED_OTHER, not "
                   "SCHED_BATCH (as before; to measure what SCHED_BATCH does)")
    p.add_argument("--beside-too", action="store_true", help="with --performer-cpus: also run each size with the "
                   "publisher beside the engine under SCHED_OTHER (as performer run placed it before publish_cpus "
                   "and SCHED_BATCH), in turns with the other modes")
    p.add_argument("--runs", type=int, default=1, metavar="K", help="repeat each size K times, the modes in turns "
                   "within each repeat; a second table gives per mode the median and range of the runs' own-time "
                   "p99 ratios, the ratio over every run's hops pooled, and the same for two halves of the "
                   "unpublished blocks (the noise floor: no difference but chance) (default 1)")
    p.add_argument("--unpinned-too", action="store_true", help="with the pinning options: run each size unpinned "
                   "first, then pinned, in the same session (the same machine load for both)")
    p.add_argument("--json", metavar="FILE", help="also write the results as JSON")
    p.add_argument("--subscriber-process", type=int, help=argparse.SUPPRESS)
    p.add_argument("--url", help=argparse.SUPPRESS)
    p.add_argument("--folder", help=argparse.SUPPRESS)
    p.add_argument("--probe", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.subscriber_process is not None:
        from realtime.nats_server import VIEWER

        asyncio.run(_subscribers_main(args.url, args.subscriber_process, Path(args.folder), VIEWER,
                                      "probe" if args.probe else "subs"))
        return 0
    from realtime.nats_server import find_nats_server

    if find_nats_server() is None:
        print("audience: nats-server is not installed (apt-get install nats-server; make setup)", file=sys.stderr)
        return 2
    if not 1 <= args.procs <= 16 or args.cluster < 1 or not 10 <= args.seconds <= 3600 \
            or any(n < 1 for n in args.subscribers) or not 1 <= args.runs <= 100:
        p.error("--procs 1..16, --cluster >= 1, --seconds 10..3600 (the first two 2-s blocks warm up), --subscribers >= 1, "
                "--runs 1..100")
    usable = os.sched_getaffinity(0)
    pins = []
    for flag, text in (("--performer-cpus", args.performer_cpus), ("--audience-cpus", args.audience_cpus),
                       ("--publisher-cpus", args.publisher_cpus)):
        try:
            cpus = None if text is None else sched.parse_cpus(text)
        except ValueError:
            p.error(f"{flag} {text!r}: give CPU numbers such as 0, 0-1 or 0,2")
        if cpus is not None and not cpus <= usable:
            p.error(f"{flag} {text!r}: this machine lets this process use CPUs {sorted(usable)}")
        pins.append(cpus)
    pinned = pins != [None, None, None]
    if args.unpinned_too and not pinned:
        p.error("--unpinned-too needs --performer-cpus and/or --audience-cpus")
    if args.beside_too and pins[0] is None:
        p.error("--beside-too needs --performer-cpus (the publisher goes beside the engine on those CPUs)")
    batch = not args.publisher_normal
    modes = ([(None, None, None, batch)] if not pinned or args.unpinned_too else []) + \
        ([(*pins, batch)] if pinned else []) + ([(pins[0], pins[1], pins[0], False)] if args.beside_too else [])
    results = []
    for n in args.subscribers:
        for k in range(args.runs):
            for perf, aud, pub, bat in modes:
                r = run_size(n, args.seconds, args.procs, args.cluster, args.block, perf, aud, pub, batch=bat)
                r["run"] = k
                results.append(r)
                print(json.dumps({key: v for key, v in r.items() if key != "own_ms"}), flush=True)
    print("\n| subscribers | CPUs: performer+publisher / broker / subscribers | load average (start, end) | nodes | frames | delivered in order (min share per frame / complete subscribers) "
          "| publish-to-receive p50 / p99 ms (probe) | hop p99 ms without / with (ratio) | hop own p99 ms without / with "
          "(ratio) | hop CPU p99 ms without / with (ratio) | send() wall / CPU p50, p99 ms | broker CPU, peak RSS | subscribers' CPU |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    cpus = lambda c: ",".join(map(str, c))  # noqa: E731
    for r in results:
        c = r["cpus"]
        print(f"| {r['subscribers']} | {cpus(c['performer'])}+{cpus(c['publisher'])} ({c['publisher_policy']}) / {cpus(c['broker'])} / "
              f"{cpus(c['subscribers'])}{' (pinned)' if r['pinned'] else ''} | {r['load_average'][0]:.1f}, "
              f"{r['load_average'][1]:.1f} | {r['cluster_nodes']} | {r['frames_published']} "
              f"(+{r['frames_dropped']} dropped) | {100 * r['min_share_of_subscribers_per_frame']:.2f} % / "
              f"{100 * r['share_of_subscribers_complete_in_order']:.2f} % | {r['latency_ms_p50']:.1f} / "
              f"{r['latency_ms_p99']:.1f} ({r['probe_latency_ms_p50']:.1f} / {r['probe_latency_ms_p99']:.1f}) | "
              f"{r['hop_ms_p99_without']:.2f} / {r['hop_ms_p99_with']:.2f} "
              f"({r['hop_ratio_p99']:.3f}) | {r['hop_own_ms_p99_without']:.2f} / {r['hop_own_ms_p99_with']:.2f} "
              f"({r['hop_own_ratio_p99']:.3f}) | {r['hop_cpu_ms_p99_without']:.2f} / {r['hop_cpu_ms_p99_with']:.2f} "
              f"({r['hop_cpu_ratio_p99']:.3f}) | {r['send_ms_p50']:.3f} / {r['send_cpu_ms_p50']:.3f}, "
              f"{r['send_ms_p99']:.3f} / {r['send_cpu_ms_p99']:.3f} | {100 * r['broker_cpu_share']:.0f} % of a core, "
              f"{max(r['broker_peak_rss_mb']):.0f} MB | {100 * r['subscriber_procs_cpu_share']:.0f} % |")
    if args.runs > 1:
        _print_runs(results)
    if args.json:
        Path(args.json).write_text(json.dumps(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
