"""OSC outputs over UDP: the VMC protocol "Performer" role, or the project's plain address space.

One :class:`OscSink` is one target (``host:port``); the engine makes one per
``--osc HOST:PORT``. Sending never blocks and never raises into the engine: the
socket is non-blocking, and errors (full buffer -> EAGAIN, unreachable network) are
counted per kind and logged once per kind. No receiver listening is not an error: the
connected socket learns it from the kernel (ICMP port unreachable -> ECONNREFUSED on a
later send), counts the refused datagrams apart (``refused``) and says so in
:meth:`OscSink.notice` until frames go out unrefused again.

Plain mode (for custom receivers, TouchDesigner, Max/MSP; see docs/protocol.md),
one bundle sequence per frame, project frame (right-handed, Y up, faces +Z)::

    /performer/frame        ,if    frame index, audio time (s)
    /performer/root         ,fff   root (Hips) position, metres
    /performer/bone/<Name>  ,ffff  local rotation x y z w, per bone
"""

from __future__ import annotations

import errno
import logging
import socket
import struct
from collections.abc import Mapping

import numpy as np

from models.errors import ConfigError, NetworkError, RigError
from models.rig.humanoid import BONES, NUM_BONES, bone_index
from realtime.frame import PoseFrame
from realtime.vmc import MAX_DATAGRAM, VMC_PORT, BundleLayout, VmcEncoder, osc_string
from realtime.wire import rest_offsets

log = logging.getLogger(__name__)

#: Characters OSC 1.0 forbids in an address part.
_OSC_RESERVED = set(" #*,/?[]{}")


class PlainOscEncoder:
    """Encodes one pose per call in the plain ``/performer/...`` address space.

    Args:
        names: optional humanoid bone -> output name mapping (e.g. a Guzheng rig's joint
            names); when given, exactly the mapped bones are sent, under their new names.
        prefix: address prefix.
        max_datagram: upper bound on each datagram, bytes.
    """

    def __init__(
        self, names: Mapping[str, str] | None = None, *, prefix: str = "/performer", max_datagram: int = MAX_DATAGRAM
    ) -> None:
        if names is None:
            self.bones = list(range(NUM_BONES))
            self.names = list(BONES)
        else:
            chosen = sorted((bone_index(b), str(n)) for b, n in names.items())
            self.bones = [i for i, _ in chosen]
            self.names = [n for _, n in chosen]
        for name in self.names:
            if not name or _OSC_RESERVED & set(name):
                raise RigError(f"joint name {name!r} cannot be an OSC address part (no spaces or #*,/?[]{{}})")
        heads = [
            osc_string(f"{prefix}/frame") + osc_string(",if"),
            osc_string(f"{prefix}/root") + osc_string(",fff"),
        ] + [osc_string(f"{prefix}/bone/{n}") + osc_string(",ffff") for n in self.names]
        self.layout = BundleLayout(heads, [8, 12] + [16] * len(self.names), max_datagram)
        self._take = np.array([3 + 4 * i + k for i in self.bones for k in range(4)])

    def encode(self, index: int, time_s: float, pose: np.ndarray) -> list[bytes]:
        """Datagrams for one pose: ``pose`` (POSE_DIM,) flat layout, project frame."""
        pose = np.asarray(pose)
        raw = pose[self._take].astype(">f4").tobytes()
        tails = [struct.pack(">if", index & 0x7FFFFFFF, time_s), pose[:3].astype(">f4").tobytes()]
        tails += [raw[i : i + 16] for i in range(0, len(raw), 16)]
        return self.layout.pack(tails)


#: Frames sent whole, with no refusal, after which a target that refused is taken to
#: have a receiver again (10 frames = 0.33 s at 30 fps). Without one, on loopback every
#: frame of two datagrams (VMC) and every second frame of one (plain) is refused.
RECEIVER_BACK_FRAMES = 10


def format_target(host: str, port: int) -> str:
    """``HOST:PORT``, with an IPv6 host in brackets."""
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


class OscSink:
    """Streams pose frames to one OSC receiver over UDP (a :class:`realtime.frame.Sink`).

    Args:
        host, port: the receiver.
        mode: ``"vmc"`` (VMC protocol Performer, Unity handedness) or ``"plain"``.
        offsets: (NUM_BONES, 3) rest offsets in metres for VMC bone positions; ``None``
            loads :func:`models.rig.skeleton.load_default_skeleton`. Unused in plain mode.
        names: plain mode only: humanoid bone -> output name mapping.
        max_datagram: upper bound on each UDP datagram, bytes.
        vmc_root: VMC mode only: ``"world"`` (/VMC/Ext/Root/Pos carries the position and heading),
            ``"in-place"`` or ``"hips"`` (:data:`realtime.vmc.VMC_ROOT_MODES`).
    """

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = VMC_PORT,
        mode: str = "vmc",
        *,
        offsets: np.ndarray | None = None,
        names: Mapping[str, str] | None = None,
        max_datagram: int = MAX_DATAGRAM,
        vmc_root: str = "world",
    ) -> None:
        if mode == "vmc":
            if names is not None:
                raise ConfigError("OSC mode 'vmc' sends Unity HumanBodyBones names; joint name mappings need mode 'plain'")
            vmc = VmcEncoder(rest_offsets(offsets), max_datagram=max_datagram, root=vmc_root)
            self._encode = lambda f: vmc.encode(f.pose, f.audio_time)
        elif mode == "plain":
            plain = PlainOscEncoder(names, max_datagram=max_datagram)
            self._encode = lambda f: plain.encode(f.index, f.audio_time, f.pose)
        else:
            raise ConfigError(f"unknown OSC mode {mode!r}; use 'vmc' or 'plain'")
        self.name = f"osc-{mode}:{host}:{port}"
        self.mode = mode
        self.target = (host, port)
        try:
            family, _, _, _, addr = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)[0]
            self._sock = socket.socket(family, socket.SOCK_DGRAM)
        except (OSError, UnicodeError) as exc:
            raise NetworkError(f"cannot open an OSC target at {host}:{port}: {exc}") from None
        self._sock.setblocking(False)
        if family == socket.AF_INET:
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
        try:
            # Connected UDP: the kernel reports ICMP port-unreachable as ECONNREFUSED.
            self._sock.connect(addr)
        except OSError as exc:
            self._sock.close()
            raise NetworkError(f"cannot open an OSC target at {host}:{port}: {exc}") from None
        self._closed = False
        self._frames = self._datagrams = self._bytes = self._skipped = 0
        self._errors: dict[str, int] = {}
        self._refused = 0  # datagrams the kernel refused: no receiver listening
        self._no_receiver = False  # set by a refusal, cleared after RECEIVER_BACK_FRAMES clean frames
        self._clean_frames = 0  # frames sent whole since the last refusal
        self._refusal_logged = False

    def send(self, frame: PoseFrame) -> None:
        """Encode and send one frame; never blocks, never raises on network errors."""
        if self._closed:
            return
        if not np.isfinite(frame.pose).all():
            self._count_error("nonfinite", "pose has non-finite values; frame skipped")
            return
        self._frames += 1
        refused = False
        for datagram in self._encode(frame):
            try:
                self._bytes += self._sock.send(datagram)
                self._datagrams += 1
            except ConnectionRefusedError:
                self._refused += 1
                refused = True
            except OSError as exc:
                kind = errno.errorcode.get(exc.errno or 0, type(exc).__name__)
                self._count_error(kind, str(exc))
        self._track_receiver(refused)

    def _track_receiver(self, refused: bool) -> None:
        """Follow whether a receiver listens: one refusal says none does; RECEIVER_BACK_FRAMES
        frames in a row without one say one does again. Each change is logged."""
        where = format_target(*self.target)
        if refused:
            self._clean_frames = 0
            if not self._no_receiver:
                self._no_receiver = True
                level = logging.INFO if self._refusal_logged else logging.WARNING
                log.log(level, "OSC: no receiver at %s (connection refused); frames keep going out and are "
                        "counted as refused, not as drops", where)
                self._refusal_logged = True
        elif self._no_receiver:
            self._clean_frames += 1
            if self._clean_frames >= RECEIVER_BACK_FRAMES:
                self._no_receiver = False
                log.info("OSC: a receiver listens at %s again", where)

    def notice(self) -> str | None:
        """``"no receiver at HOST:PORT (connection refused)"`` while none listens, else None."""
        if self._no_receiver:
            return f"no receiver at {format_target(*self.target)} (connection refused)"
        return None

    def _count_error(self, kind: str, detail: str) -> None:
        n = self._errors.get(kind, 0)
        self._errors[kind] = n + 1
        if n == 0:
            log.warning(
                "OSC %s:%d: %s (%s); sending continues, further %s errors are only counted",
                *self.target, detail, kind, kind,
            )

    def stats(self) -> dict[str, float]:
        """frames, datagrams, bytes sent; errors (total) and ``errors.<KIND>`` per kind; refused
        (datagrams refused for want of a receiver, not errors) and no_receiver (1 while none listens)."""
        out: dict[str, float] = {
            "frames": self._frames,
            "sent": self._datagrams,
            "bytes": self._bytes,
            "errors": sum(self._errors.values()),
            "refused": self._refused,
            "no_receiver": float(self._no_receiver),
        }
        out.update({f"errors.{k}": v for k, v in self._errors.items()})
        return out

    def close(self) -> None:
        """Close the socket; later ``send`` calls do nothing."""
        self._closed = True
        self._sock.close()

    def __enter__(self) -> "OscSink":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
