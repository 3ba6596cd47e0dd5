"""The show desk's feed: what a running engine hears and does, as a JSON status message a few times a second.

``performer run`` serves the desk page (``http://HOST:PORT/desk.html``, clients/web) on its
WebSocket port; the page connects to ``ws://HOST:PORT/desk`` (:data:`realtime.ws_server.DESK_PATH`)
under the viewer's token rules, receives one ``{"type": "status", ...}`` message every
``1 / rate_hz`` seconds (5 Hz) and steers with the control messages of docs/protocol.md,
which reach :meth:`realtime.engine.Engine.control` (realtime/controls.py) as OSC's do.

:class:`DeskFeed` runs on its own daemon thread. While no desk is connected it only checks
that every ``1 / rate_hz`` s; with desks it reads :meth:`Engine.stats`, :meth:`Engine.applied`,
the pose models' public state (tempo, beat phase, music present, what the gate heard, playback
rate) and the input level from the engine's audio ring (its newest ``level_s`` seconds, read,
never locked or waited on), builds one message and hands it to the server, which queues it
per desk in the same bounded drop-oldest queue as frames. The audio path never waits on it.

State: the last frame count and time (for frames/s); ``sent`` (messages handed over).
"""

from __future__ import annotations

import json
import logging
import math
import threading
import time
from collections.abc import Callable

import numpy as np

log = logging.getLogger(__name__)

#: Status messages a second sent to the desks.
DESK_HZ: float = 5.0
#: Seconds of the newest input the level meter reads.
LEVEL_S: float = 0.3
#: Level shown for digital silence, dBFS.
FLOOR_DBFS: float = -120.0


def ring_level(ring, seconds: float, sample_rate: int) -> tuple[float, float]:
    """(RMS, peak) in dBFS of the newest ``seconds`` of ``ring`` (a :class:`realtime.audio_input.RingBuffer`),
    its channels mixed down to mono as the engine does (full scale 1.0 = 0 dBFS). Reads
    without locking: a block written meanwhile may be half in the window, which a meter allows."""
    end = ring.write_position
    n = min(int(seconds * sample_rate), ring.capacity, end)
    if n <= 0:
        return FLOOR_DBFS, FLOOR_DBFS
    a, b = (end - n) % ring.capacity, end % ring.capacity  # the window: one slice, or two across the wrap
    parts = [ring._buf[a:b]] if a < b else [ring._buf[a:], ring._buf[:b]]
    x = np.concatenate(parts).mean(axis=1) if ring.channels > 1 else np.concatenate(parts)[:, 0]
    rms, peak = math.sqrt(float(np.dot(x, x)) / n), float(np.abs(x).max())
    db = lambda v: max(FLOOR_DBFS, 20.0 * math.log10(v)) if v > 0 else FLOOR_DBFS  # noqa: E731
    return db(rms), db(peak)


def _finite(value: object) -> float | None:
    return float(value) if isinstance(value, (int, float)) and math.isfinite(value) else None


def receiver_state(name: str, stats: dict) -> str:
    """One output in a word or two: OSC ``sending`` / ``no receiver``, WebSocket ``N clients``, a
    recorder ``recording``, anything with errors ``N errors``."""
    if stats.get("no_receiver"):
        return "no receiver"
    if name.startswith("ws:"):
        n = int(stats.get("clients", 0))
        return f"{n} client{'s' if n != 1 else ''}"
    if stats.get("errors"):
        return f"{int(stats['errors'])} errors"
    return "recording" if name.startswith("record") else "sending"


def style_now(model, prior: np.ndarray | None) -> str | None:
    """The style the dance is in now: the most likely style of the last four movements drawn by
    ``model`` (``prior``: its codes' dancers' styles, (K, 4), ``style_prior``); None without styles."""
    from models.networks.dance_vq import STYLES

    codes = list(getattr(model, "codes_drawn", ()))[-4:]
    if prior is None or not codes or prior.shape[1] != len(STYLES) + 1:
        return None
    return STYLES[int(np.argmax(prior[codes, 1:].sum(axis=0)))]


def _prior(model) -> np.ndarray | None:
    prior = getattr(getattr(model, "model", None), "style_prior", None)
    return None if prior is None else np.asarray(prior.numpy() if hasattr(prior, "numpy") else prior)


class DeskFeed:
    """Status of ``engine`` to the desks of ``server`` (:meth:`realtime.ws_server.WebSocketSink.send_status`)
    at ``rate_hz``. ``extra()`` adds fields (``performer run``: the OSC control input's counters).

    Each message reads the level, the models' state and the applied controls; the engine's
    counters (:meth:`Engine.stats`: percentiles, outputs, 0.5 ms) are read every ``slow_every``-th
    message only (once a second at 5 Hz). Between its parts the thread yields the interpreter
    lock, so the engine's worker never waits behind a whole message."""

    def __init__(self, engine, server, rate_hz: float = DESK_HZ, level_s: float = LEVEL_S,
                 extra: Callable[[], dict] | None = None, slow_every: int = 5) -> None:
        self.engine, self.server, self.extra = engine, server, extra
        self.slow_every = int(slow_every)
        self._priors = {name: _prior(m) for name, m in engine.models.items()}
        self._stats: dict | None = None  # the last Engine.stats()
        self._tick = 0
        self.interval = 1.0 / float(rate_hz)
        self.level_s = float(level_s)
        self.sent = 0
        self.url: str | None = None  # the desk page's address (start_desk)
        self._last: tuple[float, int] | None = None
        self._stop = threading.Event()
        self._poke = threading.Event()
        self._thread: threading.Thread | None = None
        server.on_desk_control = self._poke.set  # a control from a desk: its result at once

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="desk feed", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        self._poke.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
            self._thread = None

    def _run(self) -> None:
        while not self._stop.is_set():
            self._poke.wait(self.interval)
            self._poke.clear()
            if self._stop.is_set() or not self.server.desk_clients():
                self._last = None
                continue
            try:
                self.server.send_status(json.dumps(self.snapshot(), allow_nan=False))
                self.sent += 1
            except Exception as exc:  # noqa: BLE001 - the desk must never take the show down
                log.warning("desk status failed: %s: %s", type(exc).__name__, exc)
                self._stop.wait(1.0)

    def snapshot(self) -> dict:
        """The status message (docs/protocol.md, "Desk")."""
        engine = self.engine
        if self._stats is None or self._tick % self.slow_every == 0:
            self._stats = engine.stats()
            time.sleep(0)  # let the worker have the interpreter lock
        self._tick += 1
        stats = self._stats
        now, frames = time.monotonic(), engine.frames_out
        fps = None
        if self._last is not None and now > self._last[0]:
            fps = max(0.0, (frames - self._last[1]) / (now - self._last[0]))
        self._last = (now, frames)
        rms, peak = ring_level(engine.ring, self.level_s, engine.active_source.sample_rate)
        applied = engine.applied()
        time.sleep(0)
        performers = []
        for name, model in engine.models.items():
            per = stats["performers"][name]
            sinks = per.get("sinks", {})
            drops = sum(float(s.get(k, 0.0)) for s in sinks.values() for k in ("drops", "dropped", "errors"))
            performers.append({
                "name": name,
                **applied[name],
                "music": getattr(model, "music_present", None),
                "heard": getattr(model, "heard", None),
                "idle_weight": _finite(getattr(model, "idle_weight", None)),
                "tempo_bpm": _finite(getattr(model, "tempo_bpm", None)),
                "beat_phase": _finite(getattr(model, "beat_phase", None)),
                "rate": _finite(getattr(model, "playback_rate", None)),
                "style_now": style_now(model, self._priors.get(name)),
                "frames": per["frames"],
                "hop_p99_ms": _finite(per["compute_ms_p99"]),
                "latency_p99_ms": _finite(per["latency_ms_p99"]),
                "drops": int(drops + per["sink_errors"]),
                "receivers": [{"name": k, "state": receiver_state(k, v)} for k, v in sinks.items()],
            })
        out = {
            "type": "status",
            "time": time.time(),
            "state": stats["state"],
            "input": stats["input"],
            "level_dbfs": rms,
            "peak_dbfs": peak,
            "fps": fps,
            "hop_p99_ms": _finite(stats["compute_ms_p99"]),
            "latency_p99_ms": _finite(stats["latency_ms_p99"]),
            "overruns": int(stats["overruns"]),
            "notices": list(stats.get("notices", ())),
            "performers": performers,
        }
        if self.extra is not None:
            out.update(self.extra())
        return out


def start_desk(engine, outputs, extra: Callable[[], dict] | None = None) -> DeskFeed | None:
    """A started :class:`DeskFeed` on the WebSocket server among ``outputs`` (a server, or a list of
    sinks holding one), or None without one (``--no-ws``)."""
    from realtime.ws_server import WebSocketSink

    servers = [outputs] if isinstance(outputs, WebSocketSink) else \
        [s for s in outputs or () if isinstance(s, WebSocketSink)]
    if not servers:
        return None
    feed = DeskFeed(engine, servers[0], extra=extra)
    feed.url = f"{servers[0].url}desk.html"
    feed.start()
    return feed
