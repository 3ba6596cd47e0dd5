"""An ensemble's outputs on the engine's worker thread, or on an output thread of their own?

Run:  .venv/bin/python benchmarks/studies/ensemble_outputs.py [--performers 4] [--seconds 15] [--repeat 2] [--breakdown]

N performers of the packaged checkpoint (seeds 0..N-1, staggered) on the bundled clip,
replayed in real time at 44.1 kHz in blocks of 512, in one engine; each performer sends
VMC to a loopback UDP socket (drained by a thread) and to its path on one WebSocket server
(no client). Two ways, interleaved ``--repeat`` times:

* ``worker``: the engine calls each performer's sinks itself (what ``performer run`` does);
* ``thread``: each performer's sinks are called by one output thread, fed through a queue,
  so the worker's hop holds only the models and the hand-off.

Printed per run: the engine's whole hop p50/p99 (ms) and, per frame, block release -> the
last of its performer's sinks returned (p50/p99/max, ms): how late the frames reach the
sockets. ``--breakdown`` adds a third run, sinks on the worker, with every performer's model
push and each OSC and WebSocket send timed per call (p50/p99/mean, ms): a performer's part
of the hop, piece by piece (and, for a dance_vq model, its code step, a prefix piece and the
idle gate; the engine's guard and smoothing). On 2 cores the output thread needs the interpreter lock the worker holds: its
work lands inside the worker's hop (the worker releases the lock for every socket send and
BLAS call), and frames reach the sockets later. docs/latency.md quotes a run.
"""

from __future__ import annotations

import argparse
import collections
import socket
import threading
import time

import numpy as np


class _Outputs:
    """One output thread calling sinks for (sinks, frame) pairs queued by the worker."""

    def __init__(self, done: list) -> None:
        self.queue: collections.deque = collections.deque()
        self.ready = threading.Event()
        self.done = done
        threading.Thread(target=self._run, daemon=True).start()

    def _run(self) -> None:
        while True:
            self.ready.wait()
            self.ready.clear()
            while self.queue:
                sinks, frame = self.queue.popleft()
                for s in sinks:
                    s.send(frame)
                self.done.append((time.monotonic() - frame.released) * 1000.0)


class _Fanout:
    """A performer's one sink: its real sinks, called here (``out`` None) or by the output thread."""

    name = "fanout"

    def __init__(self, sinks: list, done: list, out: _Outputs | None) -> None:
        self.sinks, self.done, self.out = sinks, done, out

    def send(self, frame) -> None:
        if self.out is not None:
            self.out.queue.append((self.sinks, frame))
            self.out.ready.set()
            return
        for s in self.sinks:
            s.send(frame)
        self.done.append((time.monotonic() - frame.released) * 1000.0)

    def stats(self) -> dict:
        return {}

    def close(self) -> None:
        for s in self.sinks:
            s.close()


class _Timed:
    """Wraps an object's method, keeping the seconds of every call in ``spent[key]``."""

    def __init__(self, obj, method: str, key: str, spent: dict) -> None:
        fn = getattr(obj, method)

        def timed(*args, **kwargs):
            t = time.perf_counter()
            out = fn(*args, **kwargs)
            spent.setdefault(key, []).append(time.perf_counter() - t)
            return out

        setattr(obj, method, timed)


def run(mode: str, performers: int, seconds: float, audio: np.ndarray, sr: int, loaded: dict) -> str:
    from realtime.audio_input import FileSource
    from realtime.engine import Engine
    from realtime.engine_config import EngineConfig
    from realtime.osc_out import OscSink
    from realtime.performer import Performer
    from realtime.pipeline import build_pipeline
    from realtime.ws_server import WebSocketSink

    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(0.5)

    def drain() -> None:
        while True:
            try:
                rx.recv(65536)
            except TimeoutError:
                continue
            except OSError:
                return

    threading.Thread(target=drain, daemon=True).start()
    server = WebSocketSink("127.0.0.1", 0)
    done: list[float] = []
    out = _Outputs(done) if mode == "thread" else None
    spent: dict[str, list[float]] = {}
    perfs = []
    for i in range(performers):
        p = build_pipeline(None, seed=i, loaded=loaded)
        sinks = [OscSink("127.0.0.1", rx.getsockname()[1]), server.route(f"/ws/p{i}", f"p{i}")]
        if mode == "breakdown":
            _Timed(p.model, "push", "model push", spent)
            for method, key in (("_next_code", "model: code step"), ("_gate", "model: idle gate")):
                if hasattr(p.model, method):  # a dance_vq stream
                    _Timed(p.model, method, key, spent)
            _Timed(sinks[0], "send", "OSC (VMC) encode + send", spent)
            _Timed(sinks[1], "send", "WebSocket encode + hand-off", spent)
        perfs.append(Performer(f"p{i}", p.model, p.extractor_factory, [_Fanout(sinks, done, out)],
                               feature_key=p.feature_key))
    src = FileSource(audio, sr, block_size=512, realtime=True, name="clip")
    eng = Engine(src, config=EngineConfig(duration_s=seconds, stats_size=int(seconds * 30) + 10), performers=perfs)
    if mode == "breakdown":
        for lane in eng._lanes:
            if hasattr(lane.smoother, "smooth_into"):
                _Timed(lane.smoother, "smooth_into", "engine: guard + smoothing", spent)
        import models.networks.dance_numpy as dance_numpy  # the prefix pieces: made anew every code step

        if not hasattr(dance_numpy.Prefix.step, "timed"):
            step = dance_numpy.Prefix.step

            def timed_step(self) -> None:
                t = time.perf_counter()
                step(self)
                spent.setdefault("model: prefix piece", []).append(time.perf_counter() - t)

            timed_step.timed = True
            dance_numpy.Prefix.step = timed_step
    eng.start()
    done.clear()
    spent.clear()
    eng.wait()
    time.sleep(0.2)
    eng.close()
    server.close()
    rx.close()
    hop, lat = eng.compute_ms.values(), np.array(done)
    text = (f"{mode:>6}, {performers} performers: hop p50 {np.percentile(hop, 50):.2f} p99 {np.percentile(hop, 99):.2f}"
            f" ms | block release -> sinks done p50 {np.percentile(lat, 50):.2f} p99 {np.percentile(lat, 99):.2f}"
            f" max {lat.max():.2f} ms")
    for key, values in spent.items():
        ms = np.array(values) * 1000.0
        text += (f"\n    {key}: {len(ms)} calls, p50 {np.percentile(ms, 50):.3f} p99 {np.percentile(ms, 99):.3f}"
                 f" mean {ms.mean():.3f} ms")
    return text


def main() -> None:
    from models.features.audio_io import bundled_clip_path, load_audio

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--performers", type=int, default=4)
    p.add_argument("--seconds", type=float, default=15.0)
    p.add_argument("--repeat", type=int, default=2)
    p.add_argument("--breakdown", action="store_true", help="also time each model push and send (sinks on the worker)")
    args = p.parse_args()
    x, sr = load_audio(bundled_clip_path(), 44100, mono=False)
    audio = np.asarray(x, dtype=np.float32)
    loaded: dict = {}
    for _ in range(args.repeat):
        for mode in ("worker", "thread"):
            print(run(mode, args.performers, args.seconds, audio, sr, loaded), flush=True)
    if args.breakdown:
        print(run("breakdown", args.performers, args.seconds, audio, sr, loaded), flush=True)


if __name__ == "__main__":
    main()
