"""OSC control input: show-control desks (QLab, TouchOSC, lighting consoles) steer a running engine.

``performer run --control-osc [HOST:]PORT`` opens one UDP socket (host 127.0.0.1 unless
one is given) and a daemon thread that reads it. Every OSC message is checked and
turned into one :meth:`realtime.engine.Engine.control` action, the code path the
WebSocket control channel uses too (docs/show.md has the desk setups)::

    /performer/reset                  restart the streaming state (frame indices from 0)
    /performer/reset      n           the same when n != 0; n == 0 does nothing (a button's release)
    /performer/offset     n           stage offset, ms, -10000..10000         -> set_offset
    /performer/smoothing  n           pose smoothing, [0, 1)                  -> set_smoothing
    /performer/idle       n           1: settle to the idle pose and hold it; 0: dance again
    /performer/style      s           a style name, for models that offer styles
    /performer/energy     n           a number, for models that offer it
    /performer/lead       n           ms, 0..200, for models that offer it (send poses ahead)
    /performer/stage      s           "WxD" metres (e.g. "3x2") or "0" (in place), for models that offer it
    /performer/facing     s           free or audience, for models that offer it
    /performer/home                   walk back to the centre of the stage (n == 0 does nothing)

In an ensemble (several performers in one ``performer run``) each of these addresses acts
on every performer, and ``/performer/NAME/reset``, ``/performer/NAME/offset``, ... on the
performer called NAME only (its reset restarts that performer's dance; the shared input
and the others go on). An unknown NAME is a bad message like any other.

``n`` is a number of any OSC numeric type (``i``, ``h``, ``f``, ``d``; QLab sends
``/performer/offset 40`` as ``i``, a TouchOSC fader sends ``f``); ``idle`` also takes
``T``/``F``; ``s`` is ``s`` or ``S``. Bundles are unpacked and their messages applied
on arrival, one by one (time tags are ignored).

Every message is applied whole or not at all: the value is checked first (by the
engine's own checks, or the model's for a style), and a bad message changes nothing.
Bad messages (an unknown address, a wrong number or type of arguments, a value out of
range or NaN, a control the model does not offer, an undecodable datagram) are counted
in ``bad`` and logged once per address; datagrams from a sender outside ``allow`` are
counted in ``refused`` and logged once per sender; beyond ``max_messages_per_s`` they
are dropped and counted in ``rate_limited``. Nothing raises into the engine, and the
engine's audio path never waits on this thread.
"""

from __future__ import annotations

import ipaddress
import logging
import math
import socket
import struct
import threading
import time
from collections.abc import Callable, Sequence

from models.errors import ConfigError, NetworkError, PerformerError, short_repr
from realtime.endpoints import IpNetwork

log = logging.getLogger(__name__)

ControlHandler = Callable[..., None]
"""Applies one control action, ``control(action, value)``, or for one performer of an
ensemble ``control(action, value, performer=NAME)`` (:meth:`realtime.engine.Engine.control`);
raises :class:`PerformerError` for a bad value. Called on the control thread."""

#: OSC address -> (engine control action, kind of argument).
ADDRESSES: dict[str, tuple[str, str]] = {
    "/performer/reset": ("reset", "trigger"),
    "/performer/offset": ("set_offset", "number"),
    "/performer/smoothing": ("set_smoothing", "number"),
    "/performer/idle": ("idle", "switch"),
    "/performer/style": ("style", "name"),
    "/performer/energy": ("energy", "number"),
    "/performer/lead": ("lead", "number"),
    "/performer/stage": ("stage", "name"),
    "/performer/facing": ("facing", "name"),
    "/performer/home": ("home", "trigger"),
}
_WANT = {"number": "one number", "switch": "one number (0 or 1)", "name": "one string", "trigger": "at most one number"}

#: Most distinct addresses / senders whose first problem is logged (the count stays exact).
MAX_LOGGED_KEYS: int = 256
#: Deepest nesting of bundles accepted.
MAX_BUNDLE_DEPTH: int = 4
_INT32 = struct.Struct(">i")
_INT64 = struct.Struct(">q")
_FLOAT32 = struct.Struct(">f")
_FLOAT64 = struct.Struct(">d")


def _osc_string(data: bytes, pos: int) -> tuple[str, int]:
    end = data.find(b"\x00", pos)
    if end < 0:
        raise NetworkError("unterminated OSC string")
    try:
        text = data[pos:end].decode("utf-8")
    except UnicodeDecodeError:
        raise NetworkError("OSC string is not UTF-8") from None
    return text, (end + 4) & ~3


def parse_message(data: bytes) -> tuple[str, str, list]:
    """One OSC message -> (address, type tags without the comma, arguments).

    Arguments: ``i``/``h`` -> int, ``f``/``d`` -> float, ``s``/``S`` -> str, ``T``/``F``
    -> bool, ``N`` -> None. Raises :class:`NetworkError` saying what is wrong (another
    type tag, truncated data, bytes left over).
    """
    address, pos = _osc_string(data, 0)
    if not address.startswith("/"):
        raise NetworkError(f"OSC address must start with '/', got {short_repr(address)}")
    if pos >= len(data):
        return address, "", []
    tags, pos = _osc_string(data, pos)
    if not tags.startswith(","):
        raise NetworkError(f"{address}: OSC type tags must start with ',', got {short_repr(tags)}")
    tags = tags[1:]
    args: list = []
    for tag in tags:
        if tag in "ihfd":
            fmt = {"i": _INT32, "h": _INT64, "f": _FLOAT32, "d": _FLOAT64}[tag]
            if pos + fmt.size > len(data):
                raise NetworkError(f"{address}: OSC message truncated")
            args.append(fmt.unpack_from(data, pos)[0])
            pos += fmt.size
        elif tag in "sS":
            text, pos = _osc_string(data, pos)
            args.append(text)
        elif tag in "TFN":
            args.append({"T": True, "F": False, "N": None}[tag])
        else:
            raise NetworkError(f"{address}: unsupported OSC argument type {tag!r} (use i, h, f, d, s, S, T, F or N)")
    if pos != len(data):
        raise NetworkError(f"{address}: {len(data) - pos} bytes after the OSC arguments")
    return address, tags, args


def parse_packet(data: bytes, depth: int = 0) -> list[tuple[str, str, list]]:
    """The messages of one OSC packet (a message, or a bundle of messages and bundles, flattened)."""
    if not data.startswith(b"#bundle\x00"):
        if len(data) % 4:
            raise NetworkError(f"OSC packet of {len(data)} bytes (not a multiple of 4)")
        return [parse_message(data)]
    if depth >= MAX_BUNDLE_DEPTH:
        raise NetworkError(f"OSC bundles nested deeper than {MAX_BUNDLE_DEPTH}")
    if len(data) < 16:
        raise NetworkError("OSC bundle truncated (no time tag)")
    out: list[tuple[str, str, list]] = []
    pos = 16  # "#bundle\0" + time tag
    while pos < len(data):
        if pos + 4 > len(data):
            raise NetworkError("OSC bundle truncated")
        (size,) = _INT32.unpack_from(data, pos)
        pos += 4
        if size <= 0 or size % 4 or pos + size > len(data):
            raise NetworkError(f"OSC bundle element of bad size {size}")
        out.extend(parse_packet(data[pos : pos + size], depth + 1))
        pos += size
    return out


class OscControl:
    """Reads OSC control messages on ``host:port`` (UDP) and applies them through ``control``.

    Args:
        host: address to bind (default loopback; ``"0.0.0.0"`` or ``"::"`` for every interface).
        port: UDP port (0 picks a free one; see :attr:`port`).
        control: the handler, usually :meth:`realtime.engine.Engine.control`.
        allow: sender networks allowed to steer; ``None`` = any sender that reaches the
            socket (a warning is logged when the socket is not loopback-only).
        max_messages_per_s: messages per second accepted from allowed senders (bursts up
            to twice that); beyond, dropped and counted.

    The socket is bound here (:class:`NetworkError` naming the address when it cannot
    be); :meth:`start` starts the reading thread, :meth:`close` stops it.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 0, *, control: ControlHandler,
                 allow: Sequence[IpNetwork] | None = None, max_messages_per_s: float = 200.0) -> None:
        from realtime.ws_server import TokenBucket, is_loopback

        if not max_messages_per_s > 0:
            raise ConfigError(f"max_messages_per_s must be > 0, got {max_messages_per_s!r}")
        self.host = host
        self.control = control
        self.allow = None if allow is None else list(allow)
        self.max_messages_per_s = float(max_messages_per_s)
        try:
            family = socket.AF_INET6 if ":" in host else socket.AF_INET
            self._sock = socket.socket(family, socket.SOCK_DGRAM)
            self._sock.bind((host, port))
        except OSError as exc:
            raise NetworkError(f"cannot listen for OSC control on {host}:{port}: {exc.strerror or exc}") from None
        self._sock.settimeout(0.2)
        self.port: int = self._sock.getsockname()[1]
        self.name = f"osc-control:{host}:{self.port}"
        if self.allow is None and not is_loopback(host):
            log.warning("OSC control listens on %s:%d without --control-allow: anyone who can send it UDP "
                        "can steer the performer", host, self.port)
        self.messages = self.applied = self.bad = self.refused = self.rate_limited = 0
        self._logged: set[str] = set()
        self._rate = TokenBucket(self.max_messages_per_s, time.monotonic())
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # ---- lifecycle -------------------------------------------------------------------

    def start(self) -> None:
        """Start reading on a daemon thread (no-op if running)."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="osc control", daemon=True)
            self._thread.start()

    def close(self) -> None:
        """Stop the thread and close the socket."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5)
            self._thread = None
        self._sock.close()

    def __enter__(self) -> "OscControl":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def stats(self) -> dict[str, float]:
        """messages (OSC messages received from allowed senders), applied, bad, refused
        (datagrams from senders outside ``allow``), rate_limited (datagrams dropped)."""
        return {"messages": self.messages, "applied": self.applied, "bad": self.bad,
                "refused": self.refused, "rate_limited": self.rate_limited}

    # ---- the reading thread ------------------------------------------------------------

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                data, peer = self._sock.recvfrom(65536)
            except TimeoutError:
                continue
            except OSError as exc:  # e.g. ICMP errors surfacing on some platforms: keep reading
                if self._stop.is_set():
                    return
                self._note("(socket)", f"OSC control socket error: {exc}")
                continue
            try:
                self.handle(data, peer)
            except Exception as exc:  # noqa: BLE001 - a bug here must not end control for the show
                self.bad += 1
                self._note("(internal)", f"OSC control failed on a datagram: {type(exc).__name__}: {exc}")

    def handle(self, data: bytes, peer: tuple) -> None:
        """Check and apply one datagram from ``peer`` ((host, port, ...)); never raises for bad input."""
        host = str(peer[0])
        if not self._allowed(host):
            self.refused += 1
            self._note(f"refused {host}", f"OSC control from {host} refused: not in --control-allow "
                                          f"(further datagrams from it are counted silently)")
            return
        if not self._rate.take(time.monotonic()):  # a datagram needs one token to be read
            self.rate_limited += 1
            self._note("(rate)", f"OSC control: more than {self.max_messages_per_s:g} messages/s; "
                                 "dropping the excess (counted)")
            return
        try:
            messages = parse_packet(data)
        except NetworkError as exc:
            self.messages += 1
            self.bad += 1
            self._note("(malformed)", f"OSC control from {host}: bad datagram of {len(data)} bytes: {exc}; "
                                      "ignored (further bad datagrams are counted, not logged)")
            return
        self._rate.tokens -= len(messages) - 1  # a bundle costs one token per message (may overdraw)
        for address, tags, args in messages:
            self.messages += 1
            try:
                if self._apply(address, tags, args):
                    self.applied += 1
            except PerformerError as exc:
                self.bad += 1
                self._note(address, f"OSC control {short_repr(address)} from {host}: {exc}; ignored "
                                    "(further bad messages to this address are counted, not logged)")

    def _apply(self, address: str, tags: str, args: list) -> bool:
        """Check one message and apply it; True if applied, False if it asked for nothing."""
        performer = None
        entry = ADDRESSES.get(address)
        if entry is None:  # /performer/NAME/<control>: one performer of an ensemble
            parts = address.split("/")
            if len(parts) == 4 and parts[1] == "performer" and parts[2]:
                entry = ADDRESSES.get(f"/performer/{parts[3]}")
                performer = parts[2]
        if entry is None:
            raise ConfigError(f"unknown address (known: {', '.join(ADDRESSES)}, and /performer/NAME/... "
                              "in an ensemble)")
        action, kind = entry
        control = self.control if performer is None else (
            lambda action, value: self.control(action, value, performer=performer))
        if kind == "trigger":
            if len(args) > 1:
                raise ConfigError(f"takes {_WANT[kind]}, got {len(args)} arguments ({tags})")
            if args:
                value = args[0]
                if value is None or isinstance(value, str) or not (isinstance(value, bool) or math.isfinite(value)):
                    raise ConfigError(f"takes {_WANT[kind]}, got {short_repr(value)}")
                if not value:
                    return False  # a button's release
            control(action, None)
            return True
        if len(args) != 1:
            raise ConfigError(f"takes {_WANT[kind]}, got {len(args)} arguments ({tags or 'none'})")
        control(action, args[0])
        return True

    def _allowed(self, host: str) -> bool:
        if self.allow is None:
            return True
        try:
            addr = ipaddress.ip_address(host.split("%", 1)[0])
        except ValueError:
            return False
        if isinstance(addr, ipaddress.IPv6Address) and addr.ipv4_mapped is not None:
            addr = addr.ipv4_mapped
        return any(addr in net for net in self.allow)

    def _note(self, key: str, text: str) -> None:
        """Log ``text`` the first time ``key`` has a problem (at most MAX_LOGGED_KEYS keys)."""
        if key in self._logged:
            return
        if len(self._logged) >= MAX_LOGGED_KEYS:
            if "(more)" not in self._logged:
                self._logged.add("(more)")
                log.warning("OSC control: problems from more than %d addresses or senders; "
                            "counting further ones silently", MAX_LOGGED_KEYS)
            return
        self._logged.add(key)
        log.warning("%s", text)
