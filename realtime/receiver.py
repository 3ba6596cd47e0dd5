"""Reference receivers for the engine's outputs, and a checker for what they receive.

:class:`OscReceiver` (VMC or plain OSC over UDP) and :class:`WsReceiver` (the
WebSocket stream) decode the wire formats of docs/protocol.md back into
:class:`ReceivedFrame` s in the project frame (right-handed, Y up, metres, faces
+Z), each stamped with its arrival time (``time.monotonic()``, taken right after
the datagram or message was read, before decoding). :class:`StreamCheck` checks
format and continuity and measures arrival jitter and delay. ``performer listen``
(:mod:`realtime.commands.listen`) and the latency benchmarks use them.

Receivers never raise on bad input from the network: a datagram or message that
cannot be decoded is counted and described in :attr:`problems`, and receiving goes on.
"""

from __future__ import annotations

import contextlib
import json
import math
import socket
import time
from collections import deque
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from urllib.parse import parse_qsl, urlencode, urlsplit, urlunsplit

import numpy as np

from models.errors import ConfigError, NetworkError
from models.rig.humanoid import BONES
from models.timebase import FPS
from realtime.vmc import VMC_PORT, from_unity_position, from_unity_quaternion
from realtime.wire import decode_frame

#: How many problem descriptions a receiver keeps (the count is exact).
MAX_PROBLEMS = 100


@dataclass(slots=True)
class ReceivedFrame:
    """One pose as received, in the project frame.

    Attributes:
        index: frame index from the wire (WebSocket, plain OSC). VMC carries none: it is
            ``round(audio_time * fps) - 1``, the engine's frame index when it runs without
            ``--offset-ms`` (frame ``i`` ends at audio time ``(i + 1) / fps``).
        audio_time: the frame's audio time, seconds (VMC: /VMC/Ext/T).
        root: (3,) float64 root (Hips) position, metres.
        rotations: (J, 4) float64 local rotations x, y, z, w, in ``names`` order.
        names: bone names of ``rotations``' rows.
        arrival: ``time.monotonic()`` when the frame's last datagram/message was read.
        arrival_wall: ``time.time()`` at the same moment.
        send_time: server wall clock when sent, Unix seconds (WebSocket only, else None).
        missing: expected bones absent from this frame (their rows are NaN).
    """

    index: int
    audio_time: float
    root: np.ndarray
    rotations: np.ndarray
    names: tuple[str, ...]
    arrival: float
    arrival_wall: float
    send_time: float | None = None
    missing: tuple[str, ...] = ()

    @property
    def pose(self) -> np.ndarray:
        """(3 + 4J,) flat pose, the :mod:`models.rig.motion` layout when ``names`` are BONES."""
        return np.concatenate([self.root, self.rotations.ravel()])

    @property
    def delay(self) -> float | None:
        """Arrival minus send time, seconds (WebSocket; meaningful on the sender's machine)."""
        return None if self.send_time is None else self.arrival_wall - self.send_time


class _Problems:
    """Counts problems and keeps the first :data:`MAX_PROBLEMS` descriptions."""

    def __init__(self) -> None:
        self.count = 0
        self.items: deque[str] = deque(maxlen=MAX_PROBLEMS)

    def add(self, text: str) -> None:
        self.count += 1
        self.items.append(text)


# -- OSC -----------------------------------------------------------------------------------


class _FrameBuilder:
    """Collects one frame's bones from OSC messages (shared by the VMC and plain assemblers)."""

    def __init__(self, names: Sequence[str]) -> None:
        self.names = tuple(names)
        self.row = {n: i for i, n in enumerate(self.names)}
        self.reset()

    def reset(self) -> None:
        self.active = False
        self.index = 0
        self.time = math.nan
        self.root = np.full(3, np.nan)
        self.rot = np.full((len(self.names), 4), np.nan)
        self.seen: set[str] = set()

    def finish(self, arrival: tuple[float, float]) -> ReceivedFrame:
        missing = tuple(n for n in self.names if n not in self.seen)
        frame = ReceivedFrame(self.index, self.time, self.root, self.rot, self.names, *arrival, missing=missing)
        self.reset()
        return frame


def _floats(params: Sequence, n: int, start: int = 0) -> np.ndarray | None:
    vals = params[start : start + n]
    if len(vals) != n or not all(isinstance(v, float) for v in vals):
        return None
    return np.array(vals, dtype=np.float64)


def compose_root(base: np.ndarray, position: np.ndarray, rotation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A bone's local ``position`` (3,) and ``rotation`` (4,) xyzw under a parent ``base`` (7,):
    position then rotation xyzw -> the bone's (position (3,), rotation (4,)) in the parent's frame."""
    (bx, by, bz, bw), (qx, qy, qz, qw) = base[3:], rotation
    v = np.asarray(position, np.float64)
    t = 2.0 * np.cross([bx, by, bz], v)
    moved = v + bw * t + np.cross([bx, by, bz], t)  # base rotation applied to the position
    rot = np.array([bw * qx + bx * qw + by * qz - bz * qy, bw * qy - bx * qz + by * qw + bz * qx,
                    bw * qz + bx * qy - by * qx + bz * qw, bw * qw - bx * qx - by * qy - bz * qz])
    return base[:3] + moved, rot


class VmcAssembler:
    """VMC protocol messages -> frames (docs/protocol.md, "VMC protocol").

    A frame starts at ``/VMC/Ext/Root/Pos`` (or at the first bone after the previous
    frame, when the datagram holding Root/Pos was lost) and ends at ``/VMC/Ext/T``; bone positions
    and rotations are converted from Unity's left-handed frame. The frame's root position and
    Hips rotation are the Hips' local ones under the model root of ``/VMC/Ext/Root/Pos``
    (root * Hips: the world pose whichever ``--vmc-root`` the sender used; a frame whose
    Root/Pos was lost takes the Hips as they are). Other addresses are ignored, as the
    protocol requires.
    """

    def __init__(self, names: Sequence[str] = BONES, problems: _Problems | None = None, fps: float = FPS) -> None:
        self.frame = _FrameBuilder(names)
        self.problems = problems or _Problems()
        self.fps = fps
        self.count = 0
        self.last_time = math.nan
        self._base: np.ndarray | None = None  # this frame's model root (7,): position, rotation xyzw

    def feed(self, address: str, params: Sequence, arrival: tuple[float, float]) -> ReceivedFrame | None:
        f = self.frame
        if address == "/VMC/Ext/Root/Pos":
            if f.active:
                self.problems.add(f"a VMC frame after audio time {self.last_time:.3f} s ended without /VMC/Ext/T (datagram lost?)")
            f.reset()
            f.active = True
            vals = _floats(params, 7, 1)  # v2.1 adds scale and offset after these: ignored
            self._base = None if vals is None else np.concatenate(
                [from_unity_position(vals[:3]), from_unity_quaternion(vals[3:])])
        elif address == "/VMC/Ext/Bone/Pos":
            f.active = True  # also when the frame's first datagram (with Root/Pos) was lost
            vals = _floats(params, 7, 1)
            name = params[0] if params else None
            if not isinstance(name, str) or vals is None:
                self.problems.add(f"/VMC/Ext/Bone/Pos needs a name and 7 floats, got {list(params)!r}")
            elif name in f.row:
                if name == "Hips":
                    f.root = from_unity_position(vals[:3])
                f.rot[f.row[name]] = from_unity_quaternion(vals[3:])
                f.seen.add(name)
        elif address == "/VMC/Ext/T":
            if not f.active:
                self.problems.add("/VMC/Ext/T without a preceding /VMC/Ext/Root/Pos (datagram lost?)")
                return None
            t = _floats(params, 1)
            if t is None:
                self.problems.add(f"/VMC/Ext/T needs one float, got {list(params)!r}")
                f.reset()
                return None
            f.time = float(t[0])
            f.index = round(f.time * self.fps) - 1
            self.count += 1
            self.last_time = f.time
            base, self._base = self._base, None
            hips = f.row.get("Hips")
            if base is not None and hips is not None and "Hips" in f.seen:
                f.root, f.rot[hips] = compose_root(base, f.root, f.rot[hips])
            return f.finish(arrival)
        return None


class PlainAssembler:
    """Plain ``/performer/...`` messages -> frames (docs/protocol.md, "Plain OSC").

    A frame starts at ``/performer/frame`` and is complete when every expected bone has
    arrived; a frame still incomplete when the next one starts is emitted with
    ``missing`` set.
    """

    def __init__(self, names: Sequence[str] = BONES, problems: _Problems | None = None, prefix: str = "/performer"):
        self.frame = _FrameBuilder(names)
        self.problems = problems or _Problems()
        self.prefix = prefix
        self._bone = f"{prefix}/bone/"

    def feed(self, address: str, params: Sequence, arrival: tuple[float, float]) -> ReceivedFrame | None:
        f = self.frame
        out = None
        if address == f"{self.prefix}/frame":
            if f.active:
                out = f.finish(arrival)
            if len(params) != 2 or not isinstance(params[0], int) or not isinstance(params[1], float):
                self.problems.add(f"{address} needs an int and a float, got {list(params)!r}")
                return out
            f.active = True
            f.index, f.time = params[0], params[1]
        elif not f.active:
            return None
        elif address == f"{self.prefix}/root":
            vals = _floats(params, 3)
            if vals is None:
                self.problems.add(f"{address} needs 3 floats, got {list(params)!r}")
            else:
                f.root = vals
        elif address.startswith(self._bone):
            name = address[len(self._bone) :]
            vals = _floats(params, 4)
            if vals is None:
                self.problems.add(f"{address} needs 4 floats, got {list(params)!r}")
            elif name not in f.row:
                self.problems.add(f"unexpected bone {name!r} in {address}")
            else:
                f.rot[f.row[name]] = vals
                f.seen.add(name)
                if len(f.seen) == len(f.names):
                    return f.finish(arrival)
        return out


class OscReceiver:
    """Receives the engine's OSC output on a UDP port and yields frames.

    Args:
        port: UDP port to listen on (0 picks a free one; see :attr:`port`).
        mode: ``"vmc"`` or ``"plain"``, as the sender's ``--osc-mode``.
        host: address to bind (``"0.0.0.0"`` for every interface).
        names: expected bone names (default: the humanoid BONES).
    """

    def __init__(self, port: int = VMC_PORT, mode: str = "vmc", *, host: str = "127.0.0.1",
                 names: Sequence[str] = BONES) -> None:
        from pythonosc.osc_packet import OscPacket, ParseError

        if mode not in ("vmc", "plain"):
            raise ConfigError(f"unknown OSC mode {mode!r}; use 'vmc' or 'plain'")
        self.mode = mode
        self.names: tuple[str, ...] = tuple(names)
        self.problems = _Problems()
        self.datagrams = 0
        self._packet, self._parse_error = OscPacket, ParseError
        assembler = VmcAssembler if mode == "vmc" else PlainAssembler
        self._assembler = assembler(names, self.problems)
        try:
            self._sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_DGRAM)
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
            self._sock.bind((host, port))
        except OSError as exc:
            raise NetworkError(f"cannot listen for OSC on {host}:{port}: {exc.strerror or exc}") from None
        self.host = host
        self.port: int = self._sock.getsockname()[1]
        self.name = f"osc-{mode}:{host}:{self.port}"

    def poll(self, timeout: float) -> list[ReceivedFrame]:
        """Wait up to ``timeout`` s for a datagram, then read every queued one; the frames they completed."""
        frames: list[ReceivedFrame] = []
        self._sock.settimeout(timeout)
        while True:
            try:
                data = self._sock.recv(65536)
            except (TimeoutError, BlockingIOError):
                return frames
            arrival = (time.monotonic(), time.time())
            self._sock.settimeout(0)
            self.datagrams += 1
            try:
                messages = self._packet(data).messages
            except self._parse_error as exc:
                self.problems.add(f"malformed OSC datagram of {len(data)} bytes: {exc}")
                continue
            for m in messages:
                frame = self._assembler.feed(m.message.address, m.message.params, arrival)
                if frame is not None:
                    frames.append(frame)

    def __iter__(self) -> Iterator[ReceivedFrame]:
        while True:
            yield from self.poll(1.0)

    def close(self) -> None:
        self._sock.close()

    def __enter__(self) -> "OscReceiver":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# -- WebSocket -----------------------------------------------------------------------------


def _with_query(url: str, **params: str | None) -> str:
    parts = urlsplit(url)
    query = dict(parse_qsl(parts.query))
    query.update({k: v for k, v in params.items() if v is not None})
    return urlunsplit(parts._replace(query=urlencode(query)))


class WsReceiver:
    """Connects to the engine's WebSocket stream and yields frames.

    Args:
        url: ``ws://HOST:PORT/ws`` (``http://`` is accepted and turned into ``ws://``).
        fmt: ``"binary"`` (380-byte frames) or ``"json"``.
        token: shared secret, when the server has one.
        open_timeout: seconds to connect and receive the hello.

    Raises:
        NetworkError: the server cannot be reached, refuses, or does not send a hello.
    """

    def __init__(self, url: str, fmt: str = "binary", *, token: str | None = None, open_timeout: float = 5.0) -> None:
        from websockets.exceptions import WebSocketException
        from websockets.sync.client import connect

        if fmt not in ("binary", "json"):
            raise ConfigError(f"unknown WebSocket format {fmt!r}; use binary or json")
        if url.startswith(("http://", "https://")):
            url = "ws" + url[4:]
        self.url = _with_query(url, format=fmt, token=token)
        self.fmt = fmt
        self.problems = _Problems()
        self.messages = 0
        self.closed: str | None = None
        self._stack = contextlib.ExitStack()
        try:
            self._ws = self._stack.enter_context(
                connect(self.url, open_timeout=open_timeout, max_size=1 << 20, compression=None))
            hello = json.loads(self._ws.recv(timeout=open_timeout))
        except (OSError, TimeoutError, WebSocketException, ValueError) as exc:
            self._stack.close()
            raise NetworkError(f"cannot receive the pose stream from {url}: {exc}") from None
        if not isinstance(hello, dict) or hello.get("type") != "hello" or hello.get("protocol") != "live-performer":
            self._stack.close()
            raise NetworkError(f"{url} did not start with a live-performer hello message: {str(hello)[:200]}")
        self.hello: dict = hello
        self.names: tuple[str, ...] = tuple(hello.get("bones", ()))
        self.name = f"ws:{url}"

    def _decode(self, message: bytes | str, arrival: tuple[float, float]) -> ReceivedFrame | None:
        if isinstance(message, bytes):
            w = decode_frame(message)
            root, rot, index, audio_time, send_time = w.root, w.rotations, w.index, w.audio_time, w.send_time
        else:
            msg = json.loads(message)
            if not isinstance(msg, dict) or msg.get("type") != "frame":
                if isinstance(msg, dict) and msg.get("type") == "error":
                    self.problems.add(f"server error message: {msg.get('error')}")
                return None
            root, rot = np.array(msg["root"], float), np.array(msg["rotations"], float)
            index, audio_time, send_time = int(msg["index"]), float(msg["audio_time"]), float(msg["send_time"])
        if rot.shape != (len(self.names), 4) or root.shape != (3,):
            raise NetworkError(f"frame has {rot.shape} rotations and {root.shape} root; hello has {len(self.names)} bones")
        return ReceivedFrame(index, audio_time, root.astype(np.float64), rot.astype(np.float64), self.names,
                             *arrival, send_time=send_time)

    def poll(self, timeout: float) -> list[ReceivedFrame]:
        """Wait up to ``timeout`` s for a message, then take every queued one; the frames decoded.

        When the server closes the stream, :attr:`closed` says why and later calls return [].
        """
        from websockets.exceptions import ConnectionClosed

        frames: list[ReceivedFrame] = []
        wait = timeout
        while self.closed is None:
            try:
                message = self._ws.recv(timeout=wait)
            except TimeoutError:
                break
            except ConnectionClosed as exc:
                self.closed = f"code {exc.rcvd.code} {exc.rcvd.reason}".strip() if exc.rcvd else "connection lost"
                break
            arrival = (time.monotonic(), time.time())
            wait = 0
            self.messages += 1
            try:
                frame = self._decode(message, arrival)
            except (NetworkError, ValueError, KeyError, TypeError) as exc:
                self.problems.add(f"malformed {type(message).__name__} message of {len(message)} bytes: {exc}")
                continue
            if frame is not None:
                frames.append(frame)
        return frames

    def __iter__(self) -> Iterator[ReceivedFrame]:
        while self.closed is None:
            yield from self.poll(1.0)

    def close(self) -> None:
        self._stack.close()

    def __enter__(self) -> "WsReceiver":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# -- checks ----------------------------------------------------------------------------------


def rotation_angles_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle in degrees between corresponding unit quaternions of (..., 4) arrays (q and -q equal)."""
    dot = np.abs(np.sum(a * b, axis=-1))
    return np.degrees(2.0 * np.arccos(np.clip(dot, 0.0, 1.0)))


def _percentiles(values: Sequence[float], scale: float = 1.0) -> dict[str, float]:
    if len(values) == 0:
        return {}
    v = np.asarray(values, dtype=np.float64) * scale
    return {"mean": float(v.mean()), "std": float(v.std()), "p50": float(np.percentile(v, 50)),
            "p99": float(np.percentile(v, 99)), "max": float(v.max())}


@dataclass
class StreamCheck:
    """Checks received frames for format and continuity, and measures their timing.

    Format (counted as ``format_errors``): every expected bone present, finite values,
    unit quaternions (``| |q| - 1 | <= unit_tol``), frame index and audio time
    increasing. Continuity (warnings): index gaps (frames lost), audio-time steps other
    than 1/fps, rotation jumps above ``jump_deg`` degrees between consecutive frames.
    Timing: inter-arrival intervals (ms; the stream's nominal interval is 1000/fps) and,
    for WebSocket frames, delay = arrival wall time - send time (ms).

    Args:
        fps: nominal frame rate.
        jump_deg: a bone rotating more than this between consecutive frames is a jump.
        unit_tol: tolerance on quaternion norms.
        index_bits: width of the wire's frame index (32 for WebSocket, 31 for plain OSC).
    """

    fps: float = FPS
    jump_deg: float = 60.0
    unit_tol: float = 1e-3
    index_bits: int = 32
    frames: int = 0
    format_errors: int = 0
    gaps: int = 0
    lost: int = 0
    time_steps: int = 0
    jumps: int = 0
    max_jump: tuple[float, str] = (0.0, "")
    problems: deque = field(default_factory=lambda: deque(maxlen=MAX_PROBLEMS))
    intervals: list = field(default_factory=list)
    delays: list = field(default_factory=list)
    _prev: ReceivedFrame | None = None

    def _problem(self, frame: ReceivedFrame, text: str) -> str:
        self.problems.append(f"frame {frame.index}: {text}")
        return text

    def add(self, frame: ReceivedFrame) -> list[str]:
        """Check one frame; returns its problems (also counted and kept in :attr:`problems`)."""
        out = []
        self.frames += 1
        bad = False
        if frame.missing:
            bad = True
            out.append(self._problem(frame, f"missing bones {', '.join(frame.missing)}"))
        present = ~np.isnan(frame.rotations).all(axis=1)
        rot = frame.rotations[present]
        if not (np.isfinite(rot).all() and np.isfinite(frame.root).all() and math.isfinite(frame.audio_time)):
            bad = True
            out.append(self._problem(frame, "non-finite values"))
        else:
            norms = np.linalg.norm(rot, axis=1)
            off = np.abs(norms - 1.0) > self.unit_tol
            if off.any():
                bad = True
                names = [n for n, p in zip(frame.names, present) if p]
                worst = int(np.argmax(np.abs(norms - 1.0)))
                out.append(self._problem(frame, f"{int(off.sum())} non-unit quaternions (worst {names[worst]}: |q| = {norms[worst]:.4f})"))
        prev = self._prev
        if prev is not None:
            step = (frame.index - prev.index) % (1 << self.index_bits)
            if step == 0 or step >= 1 << (self.index_bits - 1) or frame.audio_time <= prev.audio_time:
                bad = True
                out.append(self._problem(frame, f"not after frame {prev.index} (audio time {prev.audio_time:.4f} -> {frame.audio_time:.4f} s)"))
            else:
                if step > 1:
                    self.gaps += 1
                    self.lost += step - 1
                    out.append(self._problem(frame, f"{step - 1} frames lost after frame {prev.index}"))
                dt = frame.audio_time - prev.audio_time
                if abs(dt * self.fps - step) > 0.05:  # float32 times (OSC) over hours of running
                    self.time_steps += 1
                    out.append(self._problem(frame, f"audio time step {dt * 1000:.2f} ms for {step} frame(s)"))
                self.intervals.append(frame.arrival - prev.arrival)
                both = present & ~np.isnan(prev.rotations).all(axis=1)
                if both.any() and step == 1:
                    angles = rotation_angles_deg(prev.rotations[both], frame.rotations[both])
                    j = int(np.argmax(angles))
                    name = [n for n, b in zip(frame.names, both) if b][j]
                    if angles[j] > self.max_jump[0]:
                        self.max_jump = (float(angles[j]), name)
                    if angles[j] > self.jump_deg:
                        self.jumps += 1
                        out.append(self._problem(frame, f"{name} turned {angles[j]:.1f} degrees in one frame"))
        if frame.delay is not None:
            self.delays.append(frame.delay)
        if bad:
            self.format_errors += 1
        self._prev = frame
        return out

    def summary(self) -> dict:
        """Counts, ``interval_ms`` and ``delay_ms`` statistics (mean/std/p50/p99/max) and the
        jitter ``jitter_ms_p99``: the 99th percentile of |interval - 1000/fps|."""
        out: dict = {"frames": self.frames, "format_errors": self.format_errors, "gaps": self.gaps,
                     "lost": self.lost, "time_steps": self.time_steps, "jumps": self.jumps,
                     "max_jump_deg": round(self.max_jump[0], 2), "max_jump_bone": self.max_jump[1]}
        out["interval_ms"] = _percentiles(self.intervals, 1000.0)
        if self.intervals:
            dev = np.abs(np.asarray(self.intervals) * 1000.0 - 1000.0 / self.fps)
            out["jitter_ms_p99"] = float(np.percentile(dev, 99))
        out["delay_ms"] = _percentiles(self.delays, 1000.0)
        return out
