"""VMC protocol "Performer" encoding: one pose frame -> OSC bundles, Unity handedness.

The VMC protocol (https://protocol.vmc.info, reference receiver EVMC4U) is OSC over
UDP, default port 39539. Per frame a Performer sends, in order::

    /VMC/Ext/Root/Pos  ,sfffffff  "root" p.x p.y p.z q.x q.y q.z q.w
    /VMC/Ext/Bone/Pos  ,sfffffff  <HumanBodyBones name> p.x p.y p.z q.x q.y q.z q.w   (per bone)
    /VMC/Ext/OK        ,iiii      loaded=1 calibration_state=3 calibration_mode=0 tracking=1
    /VMC/Ext/T         ,f         sender time in seconds (the frame's audio time)

Positions are metres and rotations ``localPosition``/``localRotation`` of each bone
in Unity's LEFT-handed frame (Y up, character faces +Z, character's right = +X).
Where the performer stands and faces (``root``, :data:`VMC_ROOT_MODES`):

* ``world`` (default): ``/VMC/Ext/Root/Pos`` is the model root's absolute pose, as the
  protocol defines it (and as EVMC4U applies it to the model's transform, "room-scale
  movement"): the floor point under the Hips (x, 0, z) and the heading (the yaw of the
  Hips' forward axis, models.data.canonical.heading). The Hips' local position and rotation
  are then relative to that root: (0, hip height, 0), the heading taken out.
* ``in-place``: the same bones, the root at the origin with identity rotation: no travel,
  no turns (a receiver that ignores Root/Pos sees the same from ``world``).
* ``hips``: the root at the origin, identity; the Hips carry the world position and heading
  (what this encoder sent before issue 39; for receivers that ignore Root/Pos but apply the
  Hips' position).

Every other bone's local position is its rest offset from its parent. The messages travel as OSC bundles (time tag "immediately") of at most
``max_datagram`` bytes each, split between bones when one frame does not fit.

The encoder is hand-written rather than built with python-osc's builders because
it runs on the engine thread every 33 ms: addresses, type tags and bone names are
pre-encoded once, so a frame costs one numpy fill and a few ``bytes.join`` calls
(tests/test_vmc.py checks the bytes against python-osc's builders).
"""

from __future__ import annotations

import struct
import math
from collections.abc import Sequence

import numpy as np

from models.errors import ConfigError
from models.rig.humanoid import BONES, NUM_BONES, PARENT_INDEX

#: Default UDP port of VMC protocol receivers (EVMC4U, VSeeFace, VMC4B, VMC4UE).
VMC_PORT: int = 39539
#: Default upper bound on one UDP datagram, bytes. 1400 leaves room for IPv4/IPv6
#: and UDP headers (and a VPN/PPPoE header) under the usual 1500-byte Ethernet MTU,
#: so a bundle is never IP-fragmented on a LAN.
MAX_DATAGRAM: int = 1400
#: OSC time tag 1 = "immediately" (same bytes as python-osc's IMMEDIATELY).
IMMEDIATE: bytes = struct.pack(">Q", 1)
BUNDLE_HEADER: bytes = b"#bundle\x00" + IMMEDIATE

#: Where the root goes (module docstring): the first is the default.
VMC_ROOT_MODES: tuple[str, ...] = ("world", "in-place", "hips")

#: Arguments of /VMC/Ext/OK: loaded=1, calibration state 3 (calibrated; EVMC4U hides
#: an uncalibrated model when asked to), calibration mode 0 (normal, not MR),
#: tracking status 1 (ok, protocol v2.7).
VMC_OK_ARGS: tuple[int, int, int, int] = (1, 3, 0, 1)


def osc_string(text: str) -> bytes:
    """OSC string: UTF-8, NUL-terminated, zero-padded to a multiple of 4 bytes."""
    raw = text.encode("utf-8")
    return raw + b"\x00" * (4 - len(raw) % 4)


def osc_message(address: str, *args: int | float | str) -> bytes:
    """One OSC message with int32 (``i``), float32 (``f``) and string (``s``) arguments."""
    tags, payload = ",", []
    for arg in args:
        if isinstance(arg, bool) or not isinstance(arg, (int, float, str)):
            raise TypeError(f"unsupported OSC argument {arg!r}")
        if isinstance(arg, str):
            tags += "s"
            payload.append(osc_string(arg))
        elif isinstance(arg, int):
            tags += "i"
            payload.append(struct.pack(">i", arg))
        else:
            tags += "f"
            payload.append(struct.pack(">f", arg))
    return osc_string(address) + osc_string(tags) + b"".join(payload)


def to_unity_position(p: np.ndarray) -> np.ndarray:
    """Project frame (right-handed, +X = character's left) -> Unity (left-handed): (-x, y, z).

    ``p``: (..., 3). The map is its own inverse (:func:`from_unity_position`).
    """
    out = np.array(p, dtype=np.float64, copy=True)
    out[..., 0] *= -1.0
    return out


def to_unity_quaternion(q: np.ndarray) -> np.ndarray:
    """Project-frame rotation -> Unity rotation, x, y, z, w order: (x, -y, -z, w).

    Mirroring X (``M = diag(-1, 1, 1)``) turns a rotation ``R`` into ``M R M``; its
    axis is a pseudo-vector, ``det(M) M axis = (ax, -ay, -az)``, and the angle is
    unchanged. ``q``: (..., 4). The map is its own inverse (:func:`from_unity_quaternion`).
    """
    out = np.array(q, dtype=np.float64, copy=True)
    out[..., 1:3] *= -1.0
    return out


from_unity_position = to_unity_position
from_unity_quaternion = to_unity_quaternion


def check_root_mode(mode) -> str:
    """``mode`` if it is one of :data:`VMC_ROOT_MODES`, else ConfigError (one line)."""
    if mode not in VMC_ROOT_MODES:
        raise ConfigError(f"VMC root must be one of {', '.join(VMC_ROOT_MODES)}, got {mode!r}")
    return mode


def split_root(pose: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The model root under a pose's Hips, project frame: (root (7,) position x, 0, z in metres
    and rotation Ry(heading) x y z w; the Hips' position (3,) relative to it, (0, y, 0); the
    Hips' rotation (4,) relative to it, Ry(-heading) * q). ``pose``: (POSE_DIM,) flat pose of
    :mod:`models.rig.motion`. The heading is the yaw of the Hips' forward (+Z) axis, as
    models.data.canonical.heading defines it, so root * hips gives the pose's Hips back."""
    x, y, z = (float(v) for v in pose[:3])
    qx, qy, qz, qw = (float(v) for v in pose[3:7])
    h = math.atan2(2.0 * (qx * qz + qw * qy), 1.0 - 2.0 * (qx * qx + qy * qy))
    s, c = math.sin(0.5 * h), math.cos(0.5 * h)
    # Ry(-h) * q, Ry(-h) = (0, -s, 0, c)
    hips = np.array([c * qx - s * qz, c * qy - s * qw, c * qz + s * qx, c * qw + s * qy])
    return np.array([x, 0.0, z, 0.0, s, 0.0, c]), np.array([0.0, y, 0.0]), hips


class BundleLayout:
    """The fixed shape of one frame's OSC traffic, split into datagrams once.

    Each slot is one message: a constant head (address, type tags, leading string
    arguments) followed by a per-frame tail of fixed length (its numeric
    arguments, big-endian). Because every size is fixed, the split into bundles
    of at most ``max_datagram`` bytes is computed here, not per frame.
    """

    def __init__(self, heads: Sequence[bytes], tail_sizes: Sequence[int], max_datagram: int = MAX_DATAGRAM) -> None:
        if len(heads) != len(tail_sizes) or not heads:
            raise ConfigError("an OSC bundle layout needs one tail size per message head")
        sizes = [len(h) + t for h, t in zip(heads, tail_sizes)]
        largest = len(BUNDLE_HEADER) + 4 + max(sizes)
        if max_datagram < largest:
            raise ConfigError(
                f"max_datagram={max_datagram} bytes is too small: one bundled OSC message needs {largest}"
            )
        # Each element of a bundle is its int32 size, then the message.
        self._heads = [struct.pack(">i", s) + h for s, h in zip(sizes, heads)]
        self.tail_sizes = tuple(tail_sizes)
        self.max_datagram = max_datagram
        self.groups: list[range] = []
        start, used = 0, len(BUNDLE_HEADER)
        for i, s in enumerate(sizes):
            if used + 4 + s > max_datagram:
                self.groups.append(range(start, i))
                start, used = i, len(BUNDLE_HEADER)
            used += 4 + s
        self.groups.append(range(start, len(sizes)))
        self.datagram_sizes = tuple(
            len(BUNDLE_HEADER) + sum(4 + sizes[i] for i in g) for g in self.groups
        )

    def tail_offsets(self) -> list[int]:
        """Byte offset of each message's tail, in slot order, in the datagrams of :meth:`pack`
        laid end to end."""
        offsets, at = [0] * len(self._heads), 0
        for group, size in zip(self.groups, self.datagram_sizes):
            pos = at + len(BUNDLE_HEADER)
            for i in group:
                pos += len(self._heads[i])
                offsets[i] = pos
                pos += self.tail_sizes[i]
            at += size
        return offsets

    def pack(self, tails: Sequence[bytes]) -> list[bytes]:
        """Datagrams (OSC bundles) of one frame from its per-message tails, in slot order."""
        heads = self._heads
        out = []
        for group in self.groups:
            parts = [BUNDLE_HEADER]
            for i in group:
                parts.append(heads[i])
                parts.append(tails[i])
            out.append(b"".join(parts))
        return out


class VmcEncoder:
    """Encodes one pose per call as VMC Performer bundles (see the module docstring).

    Every byte of a frame's datagrams but its 88 numbers (the Hips' position, the bones'
    rotations, the time; with the world root also the root's 7) is the same from frame to frame, so the datagrams are built once
    as a template and a frame writes its numbers into their big-endian float slots with one
    NumPy fancy assignment (about 15 NumPy calls and the joins per frame before, 0.13 ms a
    frame on the live path; an ensemble pays it per performer). The bytes are those the
    message-by-message packing gives (tests/test_vmc.py checks them against python-osc).

    Args:
        offsets: (NUM_BONES, 3) rest offset of each bone from its parent, metres, project
            frame, bones in :data:`models.rig.humanoid.BONES` order (the root's row is unused:
            the Hips' local position comes from the frame's root position).
        max_datagram: upper bound on each datagram, bytes.
        root: ``"world"``, ``"in-place"`` or ``"hips"`` (:data:`VMC_ROOT_MODES`, module docstring).
    """

    def __init__(self, offsets: np.ndarray, *, max_datagram: int = MAX_DATAGRAM, root: str = "world") -> None:
        self.root = check_root_mode(root)
        offsets = np.asarray(offsets, dtype=np.float64)
        if offsets.shape != (NUM_BONES, 3):
            raise ConfigError(f"VMC rest offsets must have shape ({NUM_BONES}, 3), got {offsets.shape}")
        self._root = PARENT_INDEX.index(-1)
        root_pos = osc_string("/VMC/Ext/Root/Pos") + osc_string(",sfffffff") + osc_string("root")
        bone_addr = osc_string("/VMC/Ext/Bone/Pos") + osc_string(",sfffffff")
        heads = [root_pos] + [bone_addr + osc_string(name) for name in BONES]
        heads += [osc_message("/VMC/Ext/OK", *VMC_OK_ARGS), osc_string("/VMC/Ext/T") + osc_string(",f")]
        self.layout = BundleLayout(heads, [28] * (1 + NUM_BONES) + [0, 4], max_datagram)
        # Row 0: the model root (origin, identity); rows 1..: bones (position, rotation), Unity handedness.
        values = np.zeros((1 + NUM_BONES, 7), dtype=">f4")
        values[:, 6] = 1.0
        values[1:, :3] = to_unity_position(offsets)
        raw = values.tobytes()
        tails = [raw[i : i + 28] for i in range(0, len(raw), 28)] + [b"", bytes(4)]
        grams = self.layout.pack(tails)
        self._buf = bytearray(b"".join(grams))
        ends = np.cumsum([len(g) for g in grams])
        self._spans = [(int(e) - len(g), int(e)) for g, e in zip(grams, ends)]
        starts = self.layout.tail_offsets()  # where each message's numbers start in the template
        # The frame's numbers: Hips position (-x, y, z), then per bone its rotation (x, -y, -z, w),
        # then (world) the root's position and rotation, read from ``_vals`` (the pose, the root).
        hips = 1 + self._root
        slots = [starts[hips] + 4 * c for c in range(3)]
        src, sign = [0, 1, 2], [-1.0, 1.0, 1.0]
        for b in range(NUM_BONES):
            slots += [starts[1 + b] + 12 + 4 * k for k in range(4)]
            src += [3 + 4 * b + k for k in range(4)]
            sign += [1.0, -1.0, -1.0, 1.0]
        pose_dim = 3 + 4 * NUM_BONES
        if self.root == "world":
            slots += [starts[0] + 4 * k for k in range(7)]
            src += [pose_dim + k for k in range(7)]
            sign += [-1.0, 1.0, 1.0, 1.0, -1.0, -1.0, 1.0]
        self._vals = np.zeros(pose_dim + 7, np.float64)
        self._slots = np.array(slots) // 4  # float32 slots of the template viewed as ">f4"
        self._src = np.array(src)
        self._sign = np.array(sign, np.float32)
        self._time_slot = starts[-1] // 4
        self._view = np.frombuffer(self._buf, dtype=">f4")

    def encode(self, pose: np.ndarray, time_s: float) -> list[bytes]:
        """Datagrams for one pose.

        Args:
            pose: (POSE_DIM,) flat pose of :mod:`models.rig.motion` (root metres, then
                local xyzw quaternions, project frame).
            time_s: sender time in seconds for /VMC/Ext/T.
        """
        if self.root == "hips":
            self._view[self._slots] = np.asarray(pose)[self._src] * self._sign
        else:
            v = self._vals
            v[: len(v) - 7] = pose
            root, v[:3], v[3:7] = split_root(v)
            v[len(v) - 7 :] = root
            self._view[self._slots] = v[self._src] * self._sign
        self._view[self._time_slot] = time_s
        buf = self._buf
        return [bytes(buf[a:b]) for a, b in self._spans]
