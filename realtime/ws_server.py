"""WebSocket output: broadcasts pose frames to any number of clients, and serves the web viewer.

One port carries both: ``http://HOST:PORT/`` serves the web client's static files
and ``ws://HOST:PORT/ws`` (or ``/``) is the pose stream. An ensemble (several performers
in one process) shares one server: :meth:`WebSocketSink.route` adds one performer's
stream at its own path (``/ws/NAME`` by default), and ``/ws`` and ``/`` carry the first
performer's (:class:`WebSocketRoute`). The server runs an asyncio
loop in its own daemon thread; :meth:`WebSocketSink.send`, called on the engine
thread, encodes the frame (:mod:`realtime.wire`), appends it to an outbox the loop
empties, waking the loop with ``call_soon_threadsafe`` only when it is not already due
to run (an ensemble's performers hand over a frame each per hop: one wake-up serves
them all), and returns at once. The loop's thread runs under ``SCHED_BATCH``
(:mod:`realtime.sched`), so that wake-up never preempts the worker. On the loop, a frame goes straight into
a client's socket buffer while that buffer is under ``write_limit`` and nothing is
queued for the client; otherwise into the client's bounded queue, which drops its
OLDEST frame when full, so a slow or stalled client only loses its own frames. The protocol (query string, client messages, close codes) is in
docs/protocol.md.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import hmac
import ipaddress
import json
import logging
import mimetypes
import os
import socket
import sysconfig
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import parse_qs, unquote, urlsplit

import numpy as np
from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.exceptions import ConnectionClosed
from websockets.protocol import State
from websockets.http11 import Request, Response

from models.errors import ConfigError, NetworkError, PerformerError
from models.errors import short_repr as _short
from models.timebase import FPS
from realtime import sched
from realtime.controls import CONTROL_ACTIONS as ENGINE_CONTROL_ACTIONS
from realtime.frame import PoseFrame
from realtime.wire import decode_frame, encode_frame, frame_json, hello_message, rest_offsets

log = logging.getLogger(__name__)

#: Default port of the WebSocket/HTTP server.
WS_PORT: int = 8765
FORMATS: tuple[str, ...] = ("binary", "json")
WS_PATHS: tuple[str, ...] = ("/", "/ws")
#: The show desk's path (realtime/desk.py): status messages, no frames; the viewers' token rules.
DESK_PATH: str = "/desk"
#: Longest a WebSocket client waits, seconds, while the caller still adds routes (``routes_pending``).
ROUTES_WAIT_S: float = 10.0
_DESK = "#desk"  # the route key of desk clients (no performer's path can be it)
#: Close codes (RFC 6455) sent to refused clients.
CLOSE_POLICY = 1008  # bad or missing token, unknown format, message rate exceeded
CLOSE_FULL = 1013  # client cap reached ("try again later")
#: Control actions a token-authenticated client may send (docs/protocol.md): the engine's,
#: :data:`realtime.controls.CONTROL_ACTIONS` (the OSC control input sends the same).
CONTROL_ACTIONS: tuple[str, ...] = ENGINE_CONTROL_ACTIONS
ControlHandler = Callable[[str, object], None]
"""Applies one control action (e.g. :meth:`realtime.engine.Engine.control`); raises
:class:`PerformerError` for a bad value. Called on the server thread: must not block."""

_REPO = Path(__file__).resolve().parents[1]
_CONTENT_TYPES = {
    ".html": "text/html; charset=utf-8",
    ".js": "text/javascript; charset=utf-8",
    ".mjs": "text/javascript; charset=utf-8",
    ".css": "text/css; charset=utf-8",
    ".json": "application/json",
    ".map": "application/json",
    ".txt": "text/plain; charset=utf-8",
    ".wasm": "application/wasm",
    ".svg": "image/svg+xml",
    ".png": "image/png",
    ".ico": "image/x-icon",
    ".glb": "model/gltf-binary",
    ".vrm": "model/gltf-binary",
    ".gltf": "model/gltf+json",
    ".woff2": "font/woff2",
}


def default_static_dir() -> Path:
    """The built web client: ``clients/web/dist`` in a checkout; in a pip-installed package,
    ``<prefix>/share/live-performer/web`` (pyproject.toml's data-files); else ``clients/web``."""
    dist = _REPO / "clients" / "web" / "dist"
    if dist.is_dir():
        return dist
    installed = Path(sysconfig.get_path("data")) / "share" / "live-performer" / "web"
    return installed if installed.is_dir() else _REPO / "clients" / "web"


def content_type(path: Path) -> str:
    """HTTP Content-Type for a static file, by suffix."""
    suffix = path.suffix.lower()
    return _CONTENT_TYPES.get(suffix) or mimetypes.guess_type(path.name)[0] or "application/octet-stream"


@dataclass(eq=False)
class _Client:
    ws: ServerConnection
    fmt: str
    queue: deque
    peer: str
    wakeup: asyncio.Event = field(default_factory=asyncio.Event)
    sent: int = 0
    drops: int = 0
    progress: float = 0.0  # loop time of the last completed send
    aborted: bool = False
    sending: bool = False  # the writer task is inside ws.send (a direct write now would reorder)
    controller: bool = False  # authenticated with the token: may send control messages
    rate: TokenBucket | None = None  # message-rate limit, set when the client is served
    route: str | None = None  # the path of the performer it watches (None: the server's own stream)


def parse_client_message(message: str | bytes) -> dict:
    """Check one client message (docs/protocol.md) and return it as a dict with a known ``type``.

    Raises :class:`NetworkError` saying what is wrong (binary, not JSON, not an object,
    unknown type, a field of the wrong type). Field values are only type-checked here;
    ``format`` and control values are checked where they are used.
    """
    if isinstance(message, bytes):
        raise NetworkError("binary messages are not accepted; send JSON text")
    try:
        msg = json.loads(message)
    except (ValueError, RecursionError):
        raise NetworkError("message is not JSON") from None
    if not isinstance(msg, dict):
        raise NetworkError("message must be a JSON object with a 'type'")
    kind = msg.get("type")
    if kind not in ("subscribe", "ping", "auth", "control"):
        raise NetworkError(f"unknown message type {_short(kind)}; expected subscribe, ping, auth or control")
    if kind == "auth" and not isinstance(msg.get("token"), str):
        raise NetworkError("auth needs a string 'token'")
    if kind == "control" and msg.get("action") not in CONTROL_ACTIONS:
        raise NetworkError(f"unknown control action {_short(msg.get('action'))}; use {', '.join(CONTROL_ACTIONS)}")
    if kind == "ping" and not isinstance(msg.get("id"), str | int | float | bool | None):
        raise NetworkError("ping 'id' must be a string, number or null")
    if kind == "control" and not isinstance(msg.get("performer", ""), str):
        raise NetworkError("control 'performer' must be a performer's name or \"*\"")
    return msg


#: Characters allowed in a performer's WebSocket path (after its leading "/").
_PATH_CHARS = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-./")


def check_ws_path(path: object) -> str:
    """A performer's WebSocket path: ``/`` then letters, digits, ``_ - . /`` (at most 100
    characters), not ``/`` or ``/ws`` (the first performer's), no ``..``; ConfigError otherwise."""
    if not isinstance(path, str) or not path.startswith("/") or len(path) > 100 or not set(path) <= _PATH_CHARS \
            or path in WS_PATHS or ".." in path or "//" in path:
        raise ConfigError(f"ws_path must be a path like /ws/NAME (letters, digits, _ - . /; not / or /ws), "
                          f"got {_short(path)}")
    return path


class WebSocketRoute:
    """One performer's pose stream on a shared :class:`WebSocketSink` (a :class:`realtime.frame.Sink`):
    clients that connect to ``ws://HOST:PORT<path>`` get this performer's hello (with
    ``"performer": NAME``) and frames, and their control messages act on this performer.
    ``close()`` releases the route; the server closes with its last route."""

    def __init__(self, server: "WebSocketSink", path: str, performer: str | None) -> None:
        self.server = server
        self.path = path
        self.performer = performer
        self.name = f"ws:{server.host}:{server.port}{path}"
        self.frames = self.skipped = 0
        self._closed = False

    @property
    def ws_url(self) -> str:
        """The stream's WebSocket address: the server's with this performer's path."""
        return self.server.ws_url.removesuffix("/ws") + self.path

    @property
    def url(self) -> str:
        """The web viewer's address, showing this performer (its ``?ws=`` parameter)."""
        return f"{self.server.url}?ws={self.ws_url}"

    def send(self, frame: PoseFrame) -> None:
        """Encode one frame and hand it to the server thread for this route's clients; returns at once."""
        self.server._send(frame, self.path, self)

    def set_state(self, state: dict) -> None:
        """This performer's state (``{"stage": [W, D], "facing": ...}``) to its clients: :meth:`WebSocketSink.set_state`."""
        self.server._set_state(state, self.path)

    def begin_hop(self) -> None:
        """The server's :meth:`WebSocketSink.begin_hop` (the engine calls it for each route)."""
        self.server.begin_hop()

    def end_hop(self) -> None:
        self.server.end_hop()

    def stats(self) -> dict[str, float]:
        """clients (on this path), frames (sent by the engine), drops (of its clients), skipped."""
        return self.server._route_stats(self)

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self.server._route_closed()


class WebSocketSink:
    """Pose frames to WebSocket clients, plus static HTTP for the viewer (a :class:`realtime.frame.Sink`).

    Args:
        host, port: where to listen (``port=0`` picks a free port; see :attr:`port`).
        offsets: (NUM_BONES, 3) rest offsets in metres for the hello message; ``None``
            loads :func:`models.rig.skeleton.load_default_skeleton`.
        static_dir: directory served over HTTP; ``None`` = :func:`default_static_dir`.
        token: shared secret; when set, a client must pass ``?token=`` or send
            ``{"type": "auth", "token": ...}`` as its first message. Only clients that
            presented it may send control messages; without a token there is no control.
        viewers_open: with a token, also let clients connect without it, as read-only
            viewers (they may authenticate later with an ``auth`` message to control).
        control: applies control messages (``Engine.control``); ``None`` = no control.
        max_messages_per_s: incoming messages per second per client (bursts up to twice
            that); a client sending faster is closed with code 1008.
        allowed_origins: accepted ``Origin`` headers (browsers); requests without an
            Origin header (non-browser clients) are accepted. ``None`` = no check.
        max_clients: connections beyond this are closed with code 1013.
        queue_frames: per-client queue length, frames; the oldest is dropped when full.
        max_message_bytes: largest accepted incoming message (bigger -> close 1009).
        write_limit: per-connection user-space write buffer high-water mark, bytes.
        socket_buffer: per-connection kernel send buffer (SO_SNDBUF), bytes. With
            ``write_limit`` and ``queue_frames`` it bounds how far behind a slow client
            can fall before its oldest frames are dropped.
        auth_timeout: seconds a client has to send its auth message.
        stall_timeout: a client whose queue is full and that has taken no message for
            this many seconds is disconnected (TCP abort; it frees its slot).
        rig, names, fps: described to clients in the hello message.
        routes_pending: the caller adds its performers' routes after the server listens and
            calls :meth:`routes_done` when all are in; until then (at most
            :data:`ROUTES_WAIT_S`) a client of a path not yet routed waits instead of a 404,
            so a receiver that connects early to ``/ws/bob`` gets bob's hello.
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = WS_PORT,
        *,
        offsets: np.ndarray | None = None,
        static_dir: str | Path | None = None,
        token: str | None = None,
        viewers_open: bool = False,
        control: ControlHandler | None = None,
        max_messages_per_s: float = 20.0,
        allowed_origins: Sequence[str] | None = None,
        max_clients: int = 16,
        queue_frames: int = 8,
        max_message_bytes: int = 4096,
        write_limit: int = 4096,
        socket_buffer: int = 8192,
        auth_timeout: float = 5.0,
        stall_timeout: float = 10.0,
        rig: str = "humanoid",
        names: Mapping[str, str] | None = None,
        fps: float = FPS,
        routes_pending: bool = False,
    ) -> None:
        if max_clients < 1 or queue_frames < 1:
            raise ConfigError("WebSocket max_clients and queue_frames must be at least 1")
        if token is not None and not token:
            raise ConfigError("WebSocket token must not be empty")
        if not max_messages_per_s > 0:
            raise ConfigError(f"WebSocket max_messages_per_s must be > 0, got {max_messages_per_s}")
        self.name = f"ws:{host}:{port}"
        self.host = host
        self.static_dir = None if static_dir is None else Path(static_dir)
        self.max_clients = max_clients
        self.queue_frames = queue_frames
        self.auth_timeout = auth_timeout
        self.stall_timeout = stall_timeout
        self._token = None if token is None else token.encode()
        self.viewers_open = bool(viewers_open)
        self.control = control
        self.max_messages_per_s = float(max_messages_per_s)
        self._origins = None if allowed_origins is None else [*allowed_origins, None]
        self._max_message_bytes = max_message_bytes
        self._write_limit = write_limit
        self._socket_buffer = socket_buffer
        self._hello = hello_message(rest_offsets(offsets), rig=rig, names=names, fps=fps)
        self._clients: dict[ServerConnection, _Client] = {}
        self._lock = threading.Lock()
        self._slots = 0
        self._closed = False
        self._frames = self._messages = self._bytes = self._drops = self._refused = self._skipped = 0
        self._stalled = 0
        self._connections = 0
        self._rate_limited = self._controls = 0
        self._routes: dict[str, WebSocketRoute] = {}
        self._states: dict[str | None, str] = {}  # the latest state message per route path (None: own stream)
        self._default_route: str | None = None  # the route "/" and "/ws" clients get (None: the server's own)
        self._open_routes = 0
        self._routes_in = threading.Event()  # set: every route the caller will add is in
        if not routes_pending:
            self._routes_in.set()
        self._route_drops: dict[str | None, int] = {}
        self._outbox: deque[tuple[bytes, str | None]] = deque()  # engine thread -> loop (deque ops are atomic)
        self._wake_pending = False
        self._holding = False  # between begin_hop and end_hop: frames queue without waking the loop
        self.on_desk_control: Callable[[], None] | None = None  # called after a desk's control applied

        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._start_error: BaseException | None = None
        self._server: Server | None = None
        self._stop: asyncio.Event | None = None
        self._thread = threading.Thread(target=self._run, args=(port,), name=self.name, daemon=True)
        self._thread.start()
        self._ready.wait()
        if self._start_error is not None:
            self._thread.join()
            err = self._start_error
            code = getattr(err, "errno", None)
            reason = os.strerror(code) if code else str(err)
            if code == errno.EADDRINUSE:
                reason += " (another program or performer listens there; choose another port)"
            raise NetworkError(f"cannot serve WebSocket/HTTP on {host}:{port}: {reason}")
        assert self._server is not None
        self.port: int = self._server.sockets[0].getsockname()[1]
        self.name = f"ws:{host}:{self.port}"
        if token is None and not is_loopback(host):
            log.warning("WebSocket server listens on %s:%d without a token: anyone on the network can watch "
                        "(control is off without a token); set a token to restrict it", host, self.port)

    # ---- engine thread -------------------------------------------------------------

    @property
    def url(self) -> str:
        """The viewer's HTTP address."""
        return f"http://{self.host}:{self.port}/"

    @property
    def ws_url(self) -> str:
        """The stream's WebSocket address."""
        return f"ws://{self.host}:{self.port}/ws"

    def send(self, frame: PoseFrame) -> None:
        """Encode one frame and hand it to the server thread; returns immediately."""
        self._send(frame, None, None)

    def _send(self, frame: PoseFrame, key: str | None, route: WebSocketRoute | None) -> None:
        if self._closed:
            return
        if not np.isfinite(frame.pose).all():
            self._skipped += 1
            if route is not None:
                route.skipped += 1
            return
        data = encode_frame(frame.index, frame.audio_time, time.time(), frame.pose)
        self._frames += 1
        if route is not None:
            route.frames += 1
        self._outbox.append((data, key))
        if self._wake_pending or self._holding:  # the loop will take this frame with the pending or held wake-up
            return
        self._wake()

    def set_state(self, state: dict) -> None:
        """The performer's state, a small JSON object (``{"stage": [W, D], "facing": "free"}``,
        docs/protocol.md), sent as ``{"type": "state", ...}`` to every client now and to each
        new one right after its hello; the engine calls it at start and when a control changes
        the stage. Returns at once (the server thread sends it)."""
        self._set_state(state, None)

    def _set_state(self, state: dict, key: str | None) -> None:
        text = json.dumps({"type": "state", **state})
        self._states[key] = text
        self._post_text(text, key)

    def desk_clients(self) -> int:
        """Show desks connected now (clients of :data:`DESK_PATH`)."""
        return sum(1 for c in tuple(self._clients.values()) if c.route == _DESK)

    def send_status(self, text: str) -> None:
        """One JSON status message (realtime/desk.py) to every desk, each through its bounded
        drop-oldest queue; returns at once."""
        self._post_text(text, _DESK)

    def _post_text(self, text: str, key: str | None) -> None:
        if self._closed:
            return
        try:
            self._loop.call_soon_threadsafe(self._broadcast_text, text, key)
        except RuntimeError:  # loop already closed
            pass

    def _broadcast_text(self, text: str, key: str | None) -> None:
        """On the loop: one JSON text message to the clients of ``key`` (a route's path, or None:
        the server's own stream and its default route's clients), queued like frames."""
        with self._lock:
            clients = [c for c in self._clients.values() if c.route == key]
        for c in clients:
            if not self._write_now(c, text):  # straight into its socket when nothing is queued, as frames
                self._enqueue(c, text)

    def begin_hop(self) -> None:
        """Hold the hand-off to the server thread until :meth:`end_hop` (the engine's worker, around
        each hop's performers): frames queue, the server thread is not woken. Woken mid-hop, it
        took the interpreter lock for its broadcasts whenever a performer released it (every
        socket send, BLAS and compiled call), and the performers after it waited; at the end of
        the hop one wake-up sends every performer's frame."""
        self._holding = True

    def end_hop(self) -> None:
        """Wake the server thread for the frames queued since :meth:`begin_hop` (once)."""
        self._holding = False
        if self._outbox and not self._wake_pending:
            self._wake()

    def _wake(self) -> None:
        self._wake_pending = True
        try:
            self._loop.call_soon_threadsafe(self._flush)
        except RuntimeError:  # loop already closed
            pass

    def _flush(self) -> None:
        """On the loop: broadcast every frame handed over since the last flush, in order. An
        ensemble's performers hand over one frame each per hop; one wake-up of the server
        thread (a self-pipe write, a GIL hand-off) then serves all of them."""
        self._wake_pending = False  # before popping: a frame appended from now on schedules a flush
        while self._outbox:
            self._broadcast(*self._outbox.popleft())

    def route(self, path: str, performer: str | None = None, *, default: bool = False) -> WebSocketRoute:
        """Add one performer's stream at ``path`` (:func:`check_ws_path`; ConfigError naming a
        path given twice). ``default``: clients of ``/ws`` and ``/`` get this stream too. Call
        before the engine starts sending."""
        path = check_ws_path(path)
        if path in self._routes:
            raise ConfigError(f"ws_path {path!r} is given twice; give each performer its own")
        route = WebSocketRoute(self, path, performer)
        self._routes[path] = route
        self._open_routes += 1
        if default:
            self._default_route = path
        return route

    def routes_done(self) -> None:
        """Every route is in: clients of unknown paths get their 404 now (``routes_pending``)."""
        self._routes_in.set()

    @property
    def routes(self) -> dict[str, WebSocketRoute]:
        return dict(self._routes)

    def _route_closed(self) -> None:
        self._open_routes -= 1
        if self._open_routes <= 0:
            self.close()

    def _route_stats(self, route: WebSocketRoute) -> dict[str, float]:
        with self._lock:
            clients = [c for c in self._clients.values() if c.route == route.path]
        out: dict[str, float] = {"clients": len(clients), "frames": route.frames, "skipped": route.skipped,
                                 "drops": self._route_drops.get(route.path, 0)}
        out.update({f"drops.{c.peer}": c.drops for c in clients})
        return out

    def stats(self) -> dict[str, float]:
        """clients, frames (sent by the engine), messages and bytes delivered, drops
        (total, and ``drops.<peer>`` per connected client), refused connections, stalled
        clients disconnected, skipped (non-finite) poses."""
        with self._lock:
            clients = tuple(self._clients.values())
        out: dict[str, float] = {
            "clients": len(clients),
            "frames": self._frames,
            "messages": self._messages,
            "bytes": self._bytes,
            "drops": self._drops,
            "refused": self._refused,
            "stalled": self._stalled,
            "skipped": self._skipped,
            "rate_limited": self._rate_limited,
            "controls": self._controls,
        }
        out.update({f"drops.{c.peer}": c.drops for c in clients})
        return out

    def close(self) -> None:
        """Close every connection (code 1001) and stop the server thread."""
        if self._closed:
            return
        self._closed = True
        with contextlib.suppress(RuntimeError):
            self._loop.call_soon_threadsafe(self._stop.set)  # type: ignore[union-attr]
        self._thread.join(timeout=10)

    def __enter__(self) -> "WebSocketSink":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---- server thread ---------------------------------------------------------------

    def _run(self, port: int) -> None:
        # SCHED_BATCH: the engine's hand-off (call_soon_threadsafe) wakes this thread, and the
        # kernel ran it at once on the worker's CPU, preempting the worker mid-hop (146 of 200
        # hand-offs, tests/test_ws_wakeup.py); a batch thread waits for the CPU to free up
        sched.batch()
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._main(port))
        except BaseException as exc:  # noqa: BLE001 - reported to the constructor
            if not self._ready.is_set():
                self._start_error = exc
            else:
                log.exception("WebSocket server %s stopped", self.name)
        finally:
            self._ready.set()
            tasks = asyncio.all_tasks(self._loop)
            for task in tasks:
                task.cancel()
            if tasks:
                self._loop.run_until_complete(asyncio.gather(*tasks, return_exceptions=True))
            self._loop.close()

    async def _main(self, port: int) -> None:
        self._stop = asyncio.Event()
        self._server = await serve(
            self._handle,
            self.host,
            port,
            process_request=self._process_request,
            origins=self._origins,
            max_size=self._max_message_bytes,
            max_queue=4,
            write_limit=self._write_limit,
            compression=None,
            close_timeout=2,
        )
        self._ready.set()
        await self._stop.wait()
        self._server.close()
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(self._server.wait_closed(), 5)

    def _broadcast(self, data: bytes, key: str | None = None) -> None:
        text = None
        for c in self._clients.values():
            if c.route != key:
                continue
            if c.fmt == "json":
                if text is None:
                    text = frame_json(decode_frame(data))
                message: bytes | str = text
            else:
                message = data
            if not self._write_now(c, message):
                self._enqueue(c, message)

    def _write_now(self, c: _Client, message: bytes | str) -> bool:
        """Write ``message`` to the socket at once if nothing is queued or being sent for ``c``
        and its write buffer is under ``write_limit``; False (not written) otherwise.

        The common case with many viewers: one buffered socket write per client and
        frame instead of waking the client's writer task (a task switch per client and
        frame made 200 served viewers raise the engine's per-hop p99 2.5x, through the
        interpreter lock; docs/reliability.md). A client that falls behind fills its
        buffer, and from then on goes through its drop-oldest queue and the stall check.
        The same calls as ``websockets.broadcast``.
        """
        ws = c.ws
        if c.queue or c.sending or ws.send_in_progress is not None or ws.protocol.state is not State.OPEN:
            return False
        if ws.transport.get_write_buffer_size() > self._write_limit:
            return False
        try:
            if isinstance(message, str):
                ws.protocol.send_text(message.encode())
            else:
                ws.protocol.send_binary(message)
            ws.send_data()
        except Exception:  # noqa: BLE001 - a connection going away; its reader ends it
            return True
        c.progress = self._loop.time()
        c.sent += 1
        self._messages += 1
        self._bytes += len(message)
        return True

    def _enqueue(self, c: _Client, message: bytes | str) -> None:
        if len(c.queue) == c.queue.maxlen:
            c.drops += 1
            self._drops += 1
            if c.route is not None:
                self._route_drops[c.route] = self._route_drops.get(c.route, 0) + 1
            if not c.aborted and self._loop.time() - c.progress > self.stall_timeout:
                # Not reading at all: a close frame could not get through either.
                c.aborted = True
                self._stalled += 1
                log.info("WebSocket client %s took no frame for %.1f s; disconnecting it", c.peer, self.stall_timeout)
                c.ws.transport.abort()
        c.queue.append(message)
        c.wakeup.set()

    async def _handle(self, ws: ServerConnection) -> None:
        self._connections += 1
        url = urlsplit(ws.request.path)  # type: ignore[union-attr]
        query = parse_qs(url.query)
        route = _DESK if url.path == DESK_PATH else url.path if url.path in self._routes else self._default_route
        fmt = query.get("format", ["binary"])[-1]
        if fmt not in FORMATS:
            await ws.close(CLOSE_POLICY, f"unknown format {fmt!r}; use binary or json")
            return
        if self._slots >= self.max_clients:
            self._refused += 1
            await ws.close(CLOSE_FULL, f"server full: {self.max_clients} clients")
            return
        self._slots += 1
        try:
            controller = False
            if self._token is not None and (not self.viewers_open or "token" in query):
                if not await self._authenticate(ws, query):
                    self._refused += 1
                    await ws.close(CLOSE_POLICY, "invalid or missing token")
                    return
                controller = True
            await self._serve_client(ws, fmt, controller, route)
        except ConnectionClosed:
            pass
        finally:
            self._slots -= 1

    async def _authenticate(self, ws: ServerConnection, query: dict[str, list[str]]) -> bool:
        given = query.get("token", [None])[-1]
        if given is None:
            try:
                first = await asyncio.wait_for(ws.recv(), self.auth_timeout)
                msg = json.loads(first)
                given = msg.get("token") if isinstance(msg, dict) and msg.get("type") == "auth" else None
            except (TimeoutError, ValueError, TypeError):
                return False
        return self._token_ok(given)

    def _token_ok(self, given: object) -> bool:
        """Constant-time comparison with the server token (False without one)."""
        if self._token is None or not isinstance(given, str):
            return False
        return hmac.compare_digest(given.encode("utf-8", "surrogatepass"), self._token)

    async def _serve_client(self, ws: ServerConnection, fmt: str, controller: bool = False,
                            route: str | None = None) -> None:
        host, port, *_ = ws.remote_address
        client = _Client(ws, fmt, deque(maxlen=self.queue_frames), f"{host}:{port}", controller=controller,
                         route=route)
        sock = ws.transport.get_extra_info("socket")
        if sock is not None:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, self._socket_buffer)
        hello = {**self._hello, "format": fmt, "control": controller and self.control is not None}
        if route == _DESK:
            hello["desk"] = True
        elif route is not None and self._routes[route].performer is not None:
            hello["performer"] = self._routes[route].performer
        hello = json.dumps(hello)
        await ws.send(hello)
        self._messages += 1
        self._bytes += len(hello)
        state = self._states.get(route)
        if state is not None:  # the performer's stage, right after the hello
            await ws.send(state)
            self._messages += 1
            self._bytes += len(state)
        client.progress = self._loop.time()
        client.rate = TokenBucket(self.max_messages_per_s, client.progress)
        with self._lock:
            self._clients[ws] = client
        writer = asyncio.create_task(self._write(client))
        try:
            async for message in ws:
                if not client.rate.take(self._loop.time()):
                    self._rate_limited += 1
                    log.info("WebSocket client %s sent more than %g messages/s; closing it", client.peer,
                             self.max_messages_per_s)
                    await ws.close(CLOSE_POLICY, f"message rate limit exceeded ({self.max_messages_per_s:g}/s)")
                    break
                reply = self._reply(client, message)
                if reply is None:
                    continue
                if reply.get("close"):
                    await ws.close(CLOSE_POLICY, reply["error"])
                    break
                self._enqueue(client, json.dumps(reply))
        finally:
            with self._lock:
                del self._clients[ws]
            writer.cancel()
            with contextlib.suppress(asyncio.CancelledError, ConnectionClosed):
                await writer

    async def _write(self, c: _Client) -> None:
        while True:
            await c.wakeup.wait()
            c.wakeup.clear()
            while c.queue:
                message = c.queue.popleft()
                c.sending = True
                try:
                    await c.ws.send(message)
                finally:
                    c.sending = False
                c.progress = self._loop.time()
                c.sent += 1
                self._messages += 1
                self._bytes += len(message)

    def _reply(self, c: _Client, message: str | bytes) -> dict | None:
        """Answer one client message (docs/protocol.md); errors become an error message.

        A reply with ``"close": True`` asks the caller to close the connection (code 1008,
        the error as reason): a wrong token.
        """
        try:
            msg = parse_client_message(message)
        except NetworkError as exc:
            return _error(str(exc))
        kind = msg["type"]
        if kind == "subscribe":
            fmt = msg.get("format")
            if fmt not in FORMATS:
                return _error(f"unknown format {_short(fmt)}; use binary or json")
            c.fmt = fmt
            return {"type": "subscribed", "format": fmt}
        if kind == "ping":
            return {"type": "pong", "id": msg.get("id"), "server_time": time.time()}
        if kind == "auth":
            if self._token is None:
                return _error("this server has no token; nothing to authenticate")
            if not self._token_ok(msg["token"]):
                self._refused += 1
                return {**_error("invalid or missing token"), "close": True}
            c.controller = True
            return {"type": "auth_ok", "control": self.control is not None}
        return self._control(c, msg)

    def _control(self, c: _Client, msg: dict) -> dict:
        """Apply a control message for an authenticated client."""
        if self.control is None or self._token is None:
            return _error("control is not enabled on this server (it needs a token and an engine)")
        if not c.controller:
            return _error("control needs the server token (send an auth message first)")
        action = msg["action"]
        target = msg.get("performer")
        if target is None and c.route in self._routes:
            target = self._routes[c.route].performer
        try:
            if target is None:
                self.control(action, msg.get("value"))
            else:  # a performer's path, or a "performer" field (its name, or "*": every performer)
                self.control(action, msg.get("value"), performer=target)
        except PerformerError as exc:
            return _error(f"control {action}: {exc}")
        except Exception as exc:  # noqa: BLE001 - a bug in the handler must not end the server
            log.warning("control %s from %s failed: %s: %s", action, c.peer, type(exc).__name__, exc)
            return _error(f"control {action} failed")
        self._controls += 1
        log.info("control %s %s from %s", action, _short(msg.get("value", "")), c.peer)
        if c.route == _DESK and self.on_desk_control is not None:
            self.on_desk_control()
        reply = {"type": "control_ok", "action": action, "value": msg.get("value")}
        if target is not None:
            reply["performer"] = target
        return reply

    async def _process_request(self, connection: ServerConnection, request: Request) -> Response | None:
        url = urlsplit(request.path)
        if "websocket" in request.headers.get("Upgrade", "").lower():
            if not self._routes_in.is_set():  # the caller is still adding routes (and /ws's default)
                await asyncio.to_thread(self._routes_in.wait, ROUTES_WAIT_S)
            if url.path in WS_PATHS or url.path in self._routes or url.path == DESK_PATH:
                return None
            known = ", ".join(["/ws", *self._routes])
            return connection.respond(404, f"no pose stream at {url.path}; connect to {known}\n")
        return await self._static(connection, url.path)

    async def _static(self, connection: ServerConnection, path: str) -> Response:
        root = (self.static_dir or default_static_dir()).resolve()
        rel = unquote(path).lstrip("/")
        if not rel or rel.endswith("/"):
            rel += "index.html"
        parts = rel.split("/")
        if "\x00" in rel or "\\" in rel or ".." in parts:
            return connection.respond(403, "forbidden path\n")
        full = (root / rel).resolve()
        if not full.is_relative_to(root):
            return connection.respond(403, "forbidden path\n")
        if not full.is_file():
            if not root.is_dir():
                return connection.respond(404, f"web client not found: {root} does not exist\n")
            return connection.respond(404, f"not found: {path}\n")
        body = await asyncio.to_thread(full.read_bytes)
        response = connection.respond(200, "")
        response.body = body
        headers = response.headers
        del headers["Content-Length"], headers["Content-Type"]
        headers["Content-Length"] = str(len(body))
        headers["Content-Type"] = content_type(full)
        headers["Cache-Control"] = "no-cache"
        headers["X-Content-Type-Options"] = "nosniff"
        return response


def _error(text: str) -> dict:
    return {"type": "error", "error": text}



class TokenBucket:
    """A rate limit: ``rate`` tokens per second, holding at most ``2 * rate`` (the burst).

    ``take(now, cost)`` (``now`` in seconds of any monotonic clock) refills the bucket for
    the time since the last call, then takes ``cost`` tokens if at least one is there
    (True) or nothing (False); a cost above 1 may overdraw, delaying what comes next.
    """

    def __init__(self, rate: float, now: float) -> None:
        self.rate = float(rate)
        self.tokens = 2.0 * self.rate
        self._last = now

    def take(self, now: float, cost: float = 1.0) -> bool:
        self.tokens = min(2.0 * self.rate, self.tokens + (now - self._last) * self.rate)
        self._last = now
        if self.tokens < 1.0:
            return False
        self.tokens -= cost
        return True


def is_loopback(host: str) -> bool:
    """True if ``host`` names only this machine (``localhost``, 127.0.0.0/8, ``::1``)."""
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False
