"""Broker output: every pose frame and the viewer's JSON messages to a NATS broker, for a web audience.

A :class:`BrokerPublisher` is one NATS connection with an asyncio loop in its own daemon
thread, and a :class:`BrokerRoute` per performer (a :class:`realtime.frame.Sink`).
``performer run --publish nats://HOST:4222`` runs it in a process of its own
(:mod:`realtime.publish_process`: the engine's process then has no publishing thread to take
the interpreter lock from its worker). A performer called NAME publishes on two subjects
(``PREFIX`` is ``performer`` unless ``publish_subject`` says otherwise; one performer alone is
called ``main``):

* ``PREFIX.NAME.frames``: one message per frame, the WebSocket binary frame
  (:func:`realtime.wire.encode_frame`, 380 bytes, its ``send_time`` the Unix time of
  :meth:`BrokerRoute.send`), 30 per second;
* ``PREFIX.NAME.meta``: JSON text, the hello (:func:`realtime.wire.hello_message`, with
  ``"performer"`` and ``"subject"``) and the latest ``state`` message, at once when they
  change and again every :data:`META_PERIOD_S` seconds, so a viewer that joins late has what
  it needs to draw within that time (NATS keeps no messages for late subscribers).

The engine's worker never waits on the broker: :meth:`BrokerRoute.send` encodes the frame
(about 1 us), appends it to a bounded deque that drops its OLDEST frame when full (counted as
``drops``) and wakes the loop at most once per hop (held between ``begin_hop`` and
``end_hop``). On the loop, a frame is handed to nats-py's buffer while the connection is up;
while it is down, or while :data:`PENDING_BYTES` wait to be written (a broker that does not read;
the kernel's send buffer is capped at :data:`SOCKET_BUFFER`), frames are dropped and counted
(``drops_down``), never stored. The connection
reconnects by itself every :data:`RECONNECT_WAIT_S` seconds without limit; the first loss and
the return are each logged once.

Security (docs/audience.md): the publisher authenticates with a token or a user and password
(:func:`load_credentials`: environment variables or a TOML file, never a flag), and a
``tls://`` URL (or a CA file) makes the connection TLS.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import os
import socket
import ssl
import threading
import time
import tomllib
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlsplit

import numpy as np

from models.errors import ConfigError, NetworkError
from models.timebase import FPS
from realtime.frame import PoseFrame
from realtime.wire import encode_frame, hello_message, rest_offsets

log = logging.getLogger(__name__)

#: Seconds between repeats of the hello and state on the meta subject (late viewers wait at most this).
META_PERIOD_S: float = 1.0
#: Seconds between reconnection attempts while the broker is away.
RECONNECT_WAIT_S: float = 0.25
#: nats-py's outgoing buffer, bytes (about 80 frames); past it a frame is dropped, not queued.
PENDING_BYTES: int = 32 * 1024
#: The connection's kernel send buffer, bytes (SO_SNDBUF; Linux doubles it).
SOCKET_BUFFER: int = 32 * 1024
#: Frames held between the worker and the loop, per publisher (drop oldest when full).
QUEUE_FRAMES: int = 64
#: Environment variables read by :func:`load_credentials` (they do not show in the process list).
TOKEN_ENV = "PERFORMER_PUBLISH_TOKEN"
USER_ENV = "PERFORMER_PUBLISH_USER"
PASSWORD_ENV = "PERFORMER_PUBLISH_PASSWORD"
_SUBJECT_CHARS = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-.")


@dataclass(frozen=True)
class Credentials:
    """The publisher's login: a token, or a user and password (all None: no authentication)."""

    token: str | None = None
    user: str | None = None
    password: str | None = None


def load_credentials(path: str | Path | None = None, env: dict | None = None) -> Credentials:
    """The publisher's credentials from a TOML file (``token = "..."``, or ``user`` and
    ``password``) when ``path`` is given, else from ``$PERFORMER_PUBLISH_TOKEN`` or
    ``$PERFORMER_PUBLISH_USER`` / ``$PERFORMER_PUBLISH_PASSWORD``. ConfigError naming the file
    or variable when unreadable or incomplete."""
    if path is not None:
        p = Path(path)
        try:
            raw = tomllib.loads(p.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise ConfigError("publish credentials file not found", source=p) from None
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
            raise ConfigError(f"cannot read publish credentials: {exc}", source=p) from None
        unknown = set(raw) - {"token", "user", "password"}
        if unknown or not all(isinstance(v, str) and v for v in raw.values()):
            raise ConfigError("publish credentials take non-empty strings token, or user and password", source=p)
        creds, where = Credentials(raw.get("token"), raw.get("user"), raw.get("password")), str(p)
    else:
        env = os.environ if env is None else env
        creds = Credentials(env.get(TOKEN_ENV) or None, env.get(USER_ENV) or None, env.get(PASSWORD_ENV) or None)
        where = f"${TOKEN_ENV} / ${USER_ENV} / ${PASSWORD_ENV}"
    if creds.token and (creds.user or creds.password):
        raise ConfigError(f"publish credentials ({where}): give a token or a user and password, not both")
    if bool(creds.user) != bool(creds.password):
        raise ConfigError(f"publish credentials ({where}): a user needs a password and a password a user")
    return creds


def check_broker_url(url: object) -> str:
    """A broker URL ``nats://HOST:PORT`` or ``tls://HOST:PORT`` with no password in it; ConfigError otherwise."""
    if not isinstance(url, str):
        raise ConfigError(f"publish must be a URL like nats://127.0.0.1:4222, got {url!r}")
    try:
        parts = urlsplit(url)
        host, _ = parts.hostname, parts.port
    except ValueError:  # an unclosed [IPv6 address, a port that is not a number
        raise ConfigError(f"publish must be a URL like nats://HOST:4222 or tls://HOST:4222, got {url!r}") from None
    if parts.scheme not in ("nats", "tls") or not host:
        raise ConfigError(f"publish must be a URL like nats://HOST:4222 or tls://HOST:4222, got {url!r}")
    if parts.password is not None:
        raise ConfigError("publish URL must not hold a password (it shows in the process list): "
                          f"use ${PASSWORD_ENV} or publish_credentials")
    return url


def check_subject(subject: object) -> str:
    """A subject prefix: dot-separated tokens of letters, digits, ``_`` and ``-``; ConfigError otherwise."""
    if not isinstance(subject, str) or not subject or not set(subject) <= _SUBJECT_CHARS \
            or any(not t for t in subject.split(".")) or len(subject) > 200:
        raise ConfigError(f"publish_subject must be like performer or show.performers (letters, digits, _ -, "
                          f"dots between), got {subject!r}")
    return subject


class RouteBase:
    """What a performer's route shares with its publisher (``owner``: ``stats()``, ``notice()``,
    ``_route_closed()``): its counters, the status-line notice, and ``close()``, which releases
    the route (the publisher closes with its last)."""

    def __init__(self, owner) -> None:
        self.owner = owner
        self.frames = self.skipped = 0
        self._closed = False

    def stats(self) -> dict[str, float]:
        """frames (handed over by the engine), skipped (non-finite), and the publisher's counters."""
        return {"frames": self.frames, "skipped": self.skipped, **self.owner.stats()}

    def notice(self) -> str | None:
        return self.owner.notice()

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self.owner._route_closed()


class OwnerBase:
    """A publisher's count of open routes: it closes itself when the last route is closed."""

    _open_routes = 0

    def _route_closed(self) -> None:
        self._open_routes -= 1
        if self._open_routes <= 0:
            self.close()

    def close(self) -> None: ...


class BrokerRoute(RouteBase):
    """One performer's frames and meta messages on the broker (a :class:`realtime.frame.Sink`):
    subjects ``SUBJECT.frames`` and ``SUBJECT.meta``."""

    def __init__(self, publisher: "BrokerPublisher", performer: str, subject: str, hello: str | None = None) -> None:
        super().__init__(publisher)
        self.publisher = publisher
        self.performer = performer
        self.subject = subject
        self.frames_subject = f"{subject}.frames"
        self.meta_subject = f"{subject}.meta"
        self.name = f"publish:{publisher.display}/{subject}"
        self.hello = hello or json.dumps({**publisher._hello, "performer": performer, "subject": subject})
        self.state: str | None = None

    def send(self, frame: PoseFrame) -> None:
        """Encode one frame and hand it to the publisher's thread; returns at once (drops the oldest when full)."""
        if not np.isfinite(frame.pose).all():
            self.skipped += 1
            return
        self.frames += 1
        self.publisher._hand_over(self.frames_subject,
                                  encode_frame(frame.index, frame.audio_time, time.time(), frame.pose))

    def set_state(self, state: dict) -> None:
        """The performer's stage and facing as a ``state`` message on the meta subject (now and every period)."""
        self.state = json.dumps({"type": "state", **state})
        self.publisher._meta_changed()

    def begin_hop(self) -> None:
        self.publisher.begin_hop()

    def end_hop(self) -> None:
        self.publisher.end_hop()


class BrokerPublisher(OwnerBase):
    """One NATS connection publishing every route's frames from a daemon thread.

    Args:
        url: ``nats://HOST:PORT`` or ``tls://HOST:PORT`` (:func:`check_broker_url`).
        credentials: the publisher's login (:func:`load_credentials`).
        tls_ca: a CA file to verify the broker's certificate (implies TLS).
        offsets: (NUM_BONES, 3) rest offsets in metres for the hello; None: the default skeleton.
        queue_frames: frames held between the worker and the loop; the oldest is dropped when full.
        connect_wait: seconds the constructor waits for the first connection; a broker that
            refuses the credentials is a NetworkError, one that is not there yet is logged and
            retried in the background (the show does not wait for it).
    """

    def __init__(self, url: str, *, credentials: Credentials | None = None, tls_ca: str | Path | None = None,
                 offsets: np.ndarray | None = None, queue_frames: int = QUEUE_FRAMES,
                 connect_wait: float = 2.0, fps: float = FPS, hello: dict | None = None) -> None:
        try:
            import nats  # noqa: F401
        except ImportError:
            raise ConfigError("--publish needs the nats-py package (pip install nats-py)") from None
        self.url = check_broker_url(url)
        parts = urlsplit(url)
        self.display = f"{parts.scheme}://{parts.hostname}:{parts.port or 4222}"
        self.credentials = credentials or Credentials()
        self.tls_ca = None if tls_ca is None else Path(tls_ca)
        if self.tls_ca is not None and not self.tls_ca.is_file():
            raise ConfigError(f"publish_tls_ca {str(self.tls_ca)!r} is not a file")
        if queue_frames < 1:
            raise ConfigError(f"publish queue_frames must be at least 1, got {queue_frames}")
        self._hello = hello if hello is not None else hello_message(rest_offsets(offsets), fps=fps)
        self._routes: dict[str, BrokerRoute] = {}
        self._open_routes = 0
        self._queue: deque[tuple[str, bytes]] = deque()
        self.queue_frames = queue_frames
        self._wake_pending = False
        self._holding = False
        self._closed = False
        self.published = self.drops = self.drops_down = self.errors = 0
        self.disconnects = self.reconnects = 0
        self.connected = False
        self.down_since: float | None = time.monotonic()
        self._first_error: str | None = None
        self._logged_down = False
        self._loop = asyncio.new_event_loop()
        self._event: asyncio.Event | None = None
        self._nc = None
        self._first = threading.Event()
        self._fatal: str | None = None
        self._thread = threading.Thread(target=self._run, name=f"publish {self.display}", daemon=True)
        self._thread.start()
        self._first.wait(connect_wait)
        if self._fatal is not None:
            self.close()
            raise NetworkError(f"broker {self.display} refused the publisher: {self._fatal}")
        if not self.connected:
            log.warning("broker %s not reachable yet (%s); publishing starts when it is", self.display,
                        self._first_error or "no answer")
            self._logged_down = True

    # ---- engine thread -------------------------------------------------------------

    def route(self, performer: str, subject: str, hello: str | None = None) -> BrokerRoute:
        """Add a performer publishing on ``subject``.frames / .meta (ConfigError for a subject given twice);
        ``hello``: its hello as JSON text (default: made from this publisher's offsets)."""
        subject = check_subject(subject)
        if subject in self._routes:
            raise ConfigError(f"publish subject {subject!r} is given twice; give each performer its own")
        r = BrokerRoute(self, performer, subject, hello)
        self._routes[subject] = r
        self._open_routes += 1
        self._meta_changed()
        return r

    def _hand_over(self, subject: str, data: bytes) -> None:
        if self._closed:
            return
        q = self._queue
        if len(q) >= self.queue_frames:
            with contextlib.suppress(IndexError):  # the loop may have emptied it meanwhile
                q.popleft()
                self.drops += 1
                if self.drops == 1:
                    log.warning("publishing to %s fell %d frames behind; dropping the oldest (counted as drops)",
                                self.display, self.queue_frames)
        q.append((subject, data))
        if not (self._wake_pending or self._holding):
            self._wake()

    def begin_hop(self) -> None:
        """Hold the wake-up of the publishing thread until :meth:`end_hop` (one per hop, as WebSocketSink)."""
        self._holding = True

    def end_hop(self) -> None:
        self._holding = False
        if self._queue and not self._wake_pending:
            self._wake()

    def _wake(self) -> None:
        self._wake_pending = True
        with contextlib.suppress(RuntimeError):  # loop closed
            self._loop.call_soon_threadsafe(self._set_event)

    def _meta_changed(self) -> None:
        with contextlib.suppress(RuntimeError):
            self._loop.call_soon_threadsafe(self._set_event, True)

    def stats(self) -> dict[str, float]:
        """published (frames), drops (queue full: oldest dropped), drops_down (broker away or not
        reading), errors, disconnects, reconnects, connected (1/0), queued."""
        return {"published": self.published, "drops": self.drops, "drops_down": self.drops_down,
                "errors": self.errors, "disconnects": self.disconnects, "reconnects": self.reconnects,
                "connected": int(self.connected), "queued": len(self._queue)}

    def notice(self) -> str | None:
        """A status-line note while the broker is away."""
        if self.connected or self._closed:
            return None
        return f"broker {self.display} away ({self.drops_down} frames not published)"

    def close(self) -> None:
        """Stop publishing: drain what nats-py holds (at most 2 s) and end the thread."""
        if self._closed:
            return
        self._closed = True
        with contextlib.suppress(RuntimeError):
            self._loop.call_soon_threadsafe(self._set_event)
        self._thread.join(timeout=5)

    # ---- publishing thread ---------------------------------------------------------

    def _set_event(self, meta: bool = False) -> None:
        if meta:
            self._meta_due = True
        if self._event is not None:
            self._event.set()

    def _tick(self) -> None:
        """On the loop, every META_PERIOD_S: the hello and state are due again."""
        self._ticker = self._loop.call_later(META_PERIOD_S, self._tick)
        self._set_event(True)

    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._main())
        except BaseException as exc:  # noqa: BLE001 - a bug must not reach the engine
            log.error("publisher %s stopped: %s: %s", self.display, type(exc).__name__, exc)
        finally:
            self.connected = False
            self._first.set()
            self._loop.close()

    def _tls(self) -> ssl.SSLContext | None:
        if self.tls_ca is not None:
            return ssl.create_default_context(cafile=str(self.tls_ca))
        return ssl.create_default_context() if self.url.startswith("tls://") else None

    async def _connect(self):
        import nats

        c = self.credentials

        async def on_error(exc: Exception) -> None:
            text = f"{type(exc).__name__}: {exc}".strip()
            if isinstance(exc, ssl.SSLCertVerificationError) and self.reconnects == self.disconnects == 0 \
                    and not self.connected:
                self._fatal = str(exc).strip()  # the broker's certificate is not trusted: retrying cannot help
            elif "authorization" in text.lower() or "permissions violation" in text.lower():
                if not self.connected and self.reconnects == 0 and self.disconnects == 0:
                    self._fatal = str(exc).strip() or type(exc).__name__
                elif self.errors == 0:
                    log.warning("broker %s: %s", self.display, text)
                self.errors += 1
            elif self._first_error is None:
                self._first_error = text

        async def on_disconnect() -> None:
            if self.connected:
                self.connected = False
                self.down_since = time.monotonic()
                self.disconnects += 1
                if not self._logged_down:
                    self._logged_down = True
                    log.warning("broker %s went away; frames are dropped (counted) and it is retried every "
                                "%.2f s", self.display, RECONNECT_WAIT_S)

        async def on_reconnect() -> None:
            _limit_socket(self._nc)
            self.connected = True
            self.reconnects += 1
            self._meta_due = True
            if self._logged_down:
                self._logged_down = False
                log.warning("broker %s back after %.1f s; publishing again (%d frames dropped meanwhile)",
                            self.display, time.monotonic() - (self.down_since or time.monotonic()),
                            self.drops_down)
            if self._event is not None:
                self._event.set()

        kwargs = dict(servers=[self.url], name="performer-publish", allow_reconnect=True, max_reconnect_attempts=-1,
                      reconnect_time_wait=RECONNECT_WAIT_S, connect_timeout=1, pending_size=PENDING_BYTES,
                      flush_timeout=0.5, error_cb=on_error, disconnected_cb=on_disconnect,
                      reconnected_cb=on_reconnect, verbose=False, pedantic=False, ping_interval=5,
                      max_outstanding_pings=2)
        if c.token:
            kwargs["token"] = c.token
        if c.user:
            kwargs["user"], kwargs["password"] = c.user, c.password
        tls = self._tls()
        if tls is not None:
            kwargs["tls"] = tls
        while not self._closed:
            try:
                return await nats.connect(**kwargs)
            except Exception as exc:  # noqa: BLE001 - not there yet (NoServersError, OSError, timeout): retried
                if self._fatal is None and ("authorization" in str(exc).lower()
                                            or isinstance(exc, ssl.SSLCertVerificationError)):
                    self._fatal = str(exc).strip()  # a wrong login or certificate: retrying cannot help
                if self._fatal is not None:
                    self._first.set()
                    return None
                if self._first_error is None:
                    self._first_error = f"{type(exc).__name__}: {exc}".strip()
                self._first.set()
                await asyncio.sleep(RECONNECT_WAIT_S)
        return None

    async def _main(self) -> None:
        self._event = asyncio.Event()
        self._meta_due = True
        nc = self._nc = await self._connect()
        if nc is None:
            return
        _limit_socket(nc)
        self.connected = True
        if self._logged_down:
            self._logged_down = False
            log.warning("broker %s reached; publishing", self.display)
        self.down_since = None
        self._first.set()
        self._ticker = self._loop.call_soon(self._tick)  # the meta messages' period: a timer, not a time-out per wake
        try:
            while not self._closed:
                await self._event.wait()  # one plain wait per wake-up (the engine's end_hop, the timer)
                self._event.clear()
                self._wake_pending = False  # before popping: a frame appended from now on wakes the loop
                if self._meta_due:
                    self._meta_due = False
                    for r in list(self._routes.values()):
                        for text in (r.hello, r.state):
                            if text is not None:
                                await self._publish(nc, r.meta_subject, text.encode(), frame=False)
                while self._queue:
                    subject, data = self._queue.popleft()
                    await self._publish(nc, subject, data)
        finally:
            self._ticker.cancel()
            self.connected = False
            with contextlib.suppress(Exception):
                await asyncio.wait_for(nc.drain(), 2.0)
            with contextlib.suppress(Exception):
                await nc.close()

    async def _publish(self, nc, subject: str, data: bytes, frame: bool = True) -> None:
        if not nc.is_connected or _buffered(nc) + len(data) > PENDING_BYTES:
            if frame:
                self.drops_down += 1
            return
        try:
            await nc.publish(subject, data)
        except Exception as exc:  # noqa: BLE001 - counted; the connection's callbacks say why
            if frame:
                self.drops_down += 1
            if self.errors == 0:
                log.warning("publishing to %s failed: %s: %s", self.display, type(exc).__name__, exc)
            self.errors += 1
            return
        if frame:
            self.published += 1


def _socket_writer(nc):
    """nats-py's asyncio StreamWriter of the connection (private attributes; None if they change)."""
    return getattr(getattr(nc, "_transport", None), "_io_writer", None)


def _limit_socket(nc) -> None:
    """Cap the connection's kernel send buffer at SOCKET_BUFFER bytes. Loopback and LAN sockets
    otherwise grow to megabytes (tcp_wmem): a broker that stops reading would hold a minute of
    stale frames before anything counted a drop."""
    writer = _socket_writer(nc)
    sock = None if writer is None else writer.get_extra_info("socket")
    if sock is not None:
        with contextlib.suppress(OSError):
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SOCKET_BUFFER)


def _buffered(nc) -> int:
    """Bytes waiting to go to the broker: nats-py's pending commands and asyncio's write buffer
    (private counters of nats-py; 0 for either when they are not found)."""
    writer = _socket_writer(nc)
    size = getattr(nc, "_pending_data_size", 0)
    if writer is not None:
        with contextlib.suppress(Exception):
            size += writer.transport.get_write_buffer_size()
    return size

