"""BVH (Biovision hierarchy) export and a strict reader for the humanoid rig.

Written files: ``ROOT Hips`` with ``OFFSET 0 0 0`` and 6 channels
``Xposition Yposition Zposition Zrotation Xrotation Yrotation`` (the position
channels hold the root's absolute position), one ``JOINT`` per bone in
:data:`~models.rig.humanoid.BONES` order with 3 channels
``Zrotation Xrotation Yrotation``, and an ``End Site`` under each leaf bone
(:data:`~models.rig.skeleton.LEAF_END_SITE`). Lengths are in **centimetres**
(import into Blender with Scale 0.01 to get metres); axes are the project frame (Y
up, character faces +Z), so Blender's default import axes (Forward -Z, Up Y) show
the character facing the front view. Rotations are the local rotations relative to
the T-pose rest (the OFFSETs), as intrinsic Z, then X, then Y Euler angles in
degrees, i.e. ``R = Rz @ Rx @ Ry``; each channel is unwrapped over time. ``Frame
Time`` is ``1 / motion.fps`` (0.0333333 at 30 fps).
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from models.errors import DataError, RigError
from models.rig.humanoid import BONE_INDEX, BONES, NUM_BONES, PARENT, PARENT_INDEX
from models.rig.motion import Motion
from models.rig.skeleton import END_SITE_PARENT, END_SITES, LEAF_END_SITE, Skeleton, load_default_skeleton

CM_PER_M = 100.0
ROTATION_CHANNELS = ("Zrotation", "Xrotation", "Yrotation")
POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
_VALID_CHANNELS = set(ROTATION_CHANNELS + POSITION_CHANNELS)


def _children() -> dict[str, list[str]]:
    kids: dict[str, list[str]] = {b: [] for b in BONES}
    for b in BONES:
        if PARENT[b] is not None:
            kids[PARENT[b]].append(b)  # type: ignore[index]
    return kids


def _fmt(v: np.ndarray) -> str:
    return " ".join(f"{x:.6f}" for x in v)


def write_bvh(path: str | Path, motion: Motion, skeleton: Skeleton | None = None) -> None:
    """Write ``motion`` on ``skeleton`` (default: :func:`load_default_skeleton`) as BVH.

    The skeleton must not be per-frame (BVH has one rest pose).
    """
    skeleton = load_default_skeleton() if skeleton is None else skeleton
    if skeleton.per_frame:
        raise RigError("BVH needs one rest pose; got a per-frame skeleton")
    off = skeleton.offsets * CM_PER_M
    end = dict(zip(END_SITES, skeleton.end_offsets * CM_PER_M))
    kids = _children()
    lines = ["HIERARCHY"]

    def joint(name: str, depth: int) -> None:
        pad = "\t" * depth
        is_root = PARENT[name] is None
        lines.append(f"{pad}{'ROOT' if is_root else 'JOINT'} {name}")
        lines.append(pad + "{")
        lines.append(f"{pad}\tOFFSET {_fmt(np.zeros(3) if is_root else off[BONE_INDEX[name]])}")
        chans = (POSITION_CHANNELS if is_root else ()) + ROTATION_CHANNELS
        lines.append(f"{pad}\tCHANNELS {len(chans)} {' '.join(chans)}")
        for child in kids[name]:
            joint(child, depth + 1)
        if not kids[name]:
            site = end[LEAF_END_SITE[name]]
            lines.extend([f"{pad}\tEnd Site", f"{pad}\t{{", f"{pad}\t\tOFFSET {_fmt(site)}", f"{pad}\t}}"])
        lines.append(pad + "}")

    joint(BONES[0], 0)
    order = [ln.split()[1] for ln in lines if ln.strip().startswith(("ROOT", "JOINT"))]
    assert order == list(BONES), "BONES must be a depth-first order of the hierarchy"
    t = motion.num_frames
    with warnings.catch_warnings():  # gimbal lock only means the split between angles is arbitrary
        warnings.simplefilter("ignore", UserWarning)
        euler = Rotation.from_quat(motion.rotations.reshape(-1, 4)).as_euler("ZXY", degrees=True)
    euler = np.unwrap(euler.reshape(t, NUM_BONES, 3), period=360.0, axis=0)
    values = np.concatenate([motion.root_pos * CM_PER_M, euler.reshape(t, -1)], axis=1)
    lines += ["MOTION", f"Frames: {t}", f"Frame Time: {1.0 / motion.fps:.7f}"]
    lines += [_fmt(row) for row in values]
    Path(path).write_text("\n".join(lines) + "\n")


@dataclass
class BvhFile:
    """A parsed BVH file: joints in file order with their parents, offsets and channels.

    ``offsets`` (J, 3) and ``frames`` (F, C) are in the file's units; ``end_sites``
    maps a joint index to its End Site offset.
    """

    path: Path
    names: list[str]
    parents: list[int]
    offsets: np.ndarray
    channels: list[tuple[str, ...]]
    end_sites: dict[int, np.ndarray]
    frame_time: float
    frames: np.ndarray

    @property
    def fps(self) -> float:
        """1 / Frame Time, snapped to a whole number when the file rounded it (0.0333333 -> 30)."""
        rate = 1.0 / self.frame_time
        return float(round(rate)) if abs(rate - round(rate)) < 1e-3 else rate

    def channel_values(self, joint: int) -> np.ndarray:
        """(F, len(channels[joint])) values of one joint's channels."""
        start = sum(len(c) for c in self.channels[:joint])
        return self.frames[:, start : start + len(self.channels[joint])]

    def _check_humanoid(self) -> None:
        unknown = [n for n in self.names if n not in BONE_INDEX]
        if unknown:
            raise RigError(f"unknown humanoid bone(s) {unknown}; expected {', '.join(BONES)}", source=self.path)
        missing = [b for b in BONES if b not in self.names]
        if missing:
            raise RigError(f"missing humanoid bone(s) {missing}", source=self.path)
        for i, n in enumerate(self.names):
            parent = self.names[self.parents[i]] if self.parents[i] >= 0 else None
            if parent != PARENT[n]:
                raise RigError(f"bone {n!r} has parent {parent!r}, the rig expects {PARENT[n]!r}", source=self.path)

    def to_motion(self, units_per_m: float = CM_PER_M) -> Motion:
        """The humanoid motion stored in the file (positions divided by ``units_per_m``)."""
        self._check_humanoid()
        f = self.frames.shape[0]
        root = np.zeros((f, 3))
        quats = np.zeros((f, NUM_BONES, 4))
        for i, name in enumerate(self.names):
            chans, vals = self.channels[i], self.channel_values(i)
            rot = [k for k, c in enumerate(chans) if c in ROTATION_CHANNELS]
            if len(rot) != 3:
                raise DataError(f"joint {name!r} needs 3 rotation channels, has {chans}", source=self.path)
            order = "".join(chans[k][0] for k in rot)
            quats[:, BONE_INDEX[name]] = Rotation.from_euler(order, vals[:, rot], degrees=True).as_quat()
            if PARENT[name] is None:
                pos = [chans.index(c) if c in chans else -1 for c in POSITION_CHANNELS]
                if min(pos) < 0:
                    raise DataError(f"root {name!r} needs Xposition Yposition Zposition channels", source=self.path)
                root = vals[:, pos] / units_per_m  # absolute, as Blender reads it
        return Motion(root_pos=root, rotations=quats, fps=self.fps)

    def to_skeleton(self, fallback: Skeleton, units_per_m: float = CM_PER_M) -> Skeleton:
        """Rest skeleton from the OFFSETs and End Sites; end sites a BVH cannot hold
        (those not in LEAF_END_SITE) are taken from ``fallback``."""
        self._check_humanoid()
        off = np.zeros((NUM_BONES, 3))
        for i, name in enumerate(self.names):
            off[BONE_INDEX[name]] = self.offsets[i] / units_per_m
        off[0] = fallback.offsets[0] if fallback.offsets.ndim == 2 else fallback.offsets[0, 0]
        end = np.array(fallback.end_offsets if fallback.end_offsets.ndim == 2 else fallback.end_offsets[0])
        for i, name in enumerate(self.names):
            if name in LEAF_END_SITE:
                if i not in self.end_sites:
                    raise DataError(f"leaf joint {name!r} has no End Site", source=self.path)
                end[END_SITES.index(LEAF_END_SITE[name])] = self.end_sites[i] / units_per_m
        return Skeleton(offsets=off, end_offsets=end)


_TOKEN = re.compile(r"\S+")
_MAX_DEPTH = 200  # joint nesting read_bvh accepts (it recurses once per level)


class _Tokens:
    def __init__(self, text: str, path: Path) -> None:
        self.items: list[tuple[str, int]] = [
            (m.group(), n) for n, line in enumerate(text.splitlines(), 1) for m in _TOKEN.finditer(line)
        ]
        self.i = 0
        self.path = path

    def error(self, what: str) -> DataError:
        line = self.items[min(self.i, len(self.items) - 1)][1] if self.items else 0
        return DataError(f"line {line}: {what}", source=self.path)

    def next(self) -> str:
        if self.i >= len(self.items):
            raise self.error("unexpected end of file")
        self.i += 1
        return self.items[self.i - 1][0]

    def expect(self, *words: str) -> None:
        for w in words:
            got = self.next()
            if got != w:
                self.i -= 1
                raise self.error(f"expected {w!r}, found {got!r}")

    def number(self) -> float:
        tok = self.next()
        try:
            v = float(tok)
        except ValueError:
            self.i -= 1
            raise self.error(f"expected a number, found {tok!r}") from None
        if not np.isfinite(v):
            self.i -= 1
            raise self.error(f"non-finite number {tok!r}")
        return v

    def integer(self) -> int:
        tok = self.next()
        if not (tok.isascii() and tok.isdigit()):  # "\u00b2".isdigit() is True, int() refuses it
            self.i -= 1
            raise self.error(f"expected a non-negative integer, found {tok!r}")
        return int(tok)


def read_bvh(path: str | Path) -> BvhFile:
    """Parse a BVH file strictly; :class:`DataError` naming the file and line on any defect."""
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise DataError("BVH file not found", source=path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"cannot read BVH file ({exc})", source=path) from None
    # The tokenizer reads the hierarchy and the three MOTION header lines; the frame rows, which
    # are most of a long file, are split line by line and converted by numpy in one go.
    motion = re.search(r"^[ \t]*MOTION\b", text, re.M)
    cut = len(text) if motion is None else motion.start()
    head_lines = text[:cut].count("\n")
    tail = text[cut:].splitlines()
    n_head = 0
    while n_head < len(tail) and sum(len(ln.split()) for ln in tail[:n_head]) < 6:
        n_head += 1  # MOTION, Frames: N, Frame Time: x
    tok = _Tokens(text[:cut] + "\n".join(tail[:n_head]), path)
    names: list[str] = []
    parents: list[int] = []
    offsets: list[list[float]] = []
    channels: list[tuple[str, ...]] = []
    end_sites: dict[int, np.ndarray] = {}

    def offset() -> list[float]:
        tok.expect("OFFSET")
        return [tok.number() for _ in range(3)]

    def joint(parent: int, depth: int = 0) -> None:
        if depth > _MAX_DEPTH:
            raise tok.error(f"joints nested more than {_MAX_DEPTH} deep")
        name = tok.next()
        if name in names:
            raise tok.error(f"duplicate joint name {name!r}")
        idx = len(names)
        names.append(name)
        parents.append(parent)
        tok.expect("{")
        offsets.append(offset())
        tok.expect("CHANNELS")
        n = tok.integer()
        chans = tuple(tok.next() for _ in range(n))
        bad = [c for c in chans if c not in _VALID_CHANNELS]
        if bad or len(set(chans)) != n:
            raise tok.error(f"bad channel list {chans} for joint {name!r}")
        channels.append(chans)
        while True:
            word = tok.next()
            if word == "}":
                return
            if word == "JOINT":
                joint(idx, depth + 1)
            elif word == "End":
                tok.expect("Site", "{")
                if idx in end_sites:
                    raise tok.error(f"joint {name!r} has more than one End Site")
                end_sites[idx] = np.array(offset())
                tok.expect("}")
            else:
                tok.i -= 1
                raise tok.error(f"expected JOINT, End Site or '}}', found {word!r}")

    tok.expect("HIERARCHY", "ROOT")
    joint(-1)
    tok.expect("MOTION", "Frames:")
    num_frames = tok.integer()
    tok.expect("Frame", "Time:")
    frame_time = tok.number()
    if not frame_time >= 1e-6:  # also keeps 1 / frame_time (the fps) finite
        raise tok.error(f"Frame Time must be at least 1e-6 s, got {frame_time}")
    width = sum(len(c) for c in channels)
    rows: dict[int, list[str]] = {}
    for word, line in tok.items[tok.i :]:  # anything after Frame Time on its own line
        rows.setdefault(line, []).append(word)
    for n, ln in enumerate(tail[n_head:], head_lines + n_head + 1):
        words = ln.split()
        if words:
            rows[n] = words
    if len(rows) != num_frames:
        raise DataError(f"'Frames: {num_frames}' but {len(rows)} frame lines follow", source=path)
    for line, words in rows.items():
        if len(words) != width:
            raise DataError(f"line {line}: {len(words)} values, the hierarchy has {width} channels", source=path)
    try:
        values = np.array([w for words in rows.values() for w in words], dtype=np.float64).reshape(num_frames, width)
    except ValueError:
        for f, (line, words) in enumerate(rows.items()):
            try:
                [float(w) for w in words]
            except ValueError:
                raise DataError(f"line {line}: non-numeric value in frame {f}", source=path) from None
        raise
    if not np.isfinite(values).all():
        raise DataError("non-finite channel values", source=path)
    return BvhFile(
        path=path,
        names=names,
        parents=parents,
        offsets=np.array(offsets, dtype=np.float64).reshape(-1, 3),
        channels=channels,
        end_sites=end_sites,
        frame_time=frame_time,
        frames=values,
    )


assert set(LEAF_END_SITE.values()) <= set(END_SITE_PARENT)
