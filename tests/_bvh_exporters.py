"""Write a rig motion as BVH the way other exporters would: their names, units, up axis, rest pose,
frame rate, rotation order, extra joints (fingers, CMU's LHipJoint, Mixamo's Spine2 ...).

A file joint follows a rig bone (its *carrier*: the bone itself, or for an extra joint its
parent's carrier). With a constant rest correction C per rig bone, the file's global rotation
is ``G_file = G_rig @ C`` and every offset is the rig's rest vector expressed in the carrier's
corrected frame, ``C^-1 (rest_child - rest_parent)``, so the file's FK puts every joint where
the rig's FK puts it while its rest pose is a T-pose, an A-pose or bones along X (Bandai style).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from models.rig.humanoid import BONE_INDEX, BONES, PARENT
from models.rig.kinematics import global_rotations
from models.rig.motion import Motion
from models.rig.skeleton import Skeleton

RIG = {b: b for b in BONES}


@dataclass
class Convention:
    names: dict[str, str]  # rig bone -> file joint name (every rig bone)
    units_per_m: float = 100.0
    up: str = "y"  # "y" or "z" (Z up, Blender's forward -Y)
    rest: str = "T"  # "T", "A" (arms 45 degrees down) or "x" (every bone's frame along its bone, not upright)
    fps: float = 30.0
    order: str = "ZXY"
    #: extra joints inserted between a rig bone and some of its children: name -> (rig parent, children, fraction)
    insert: dict[str, tuple[str, tuple[str, ...], float]] = field(default_factory=dict)
    #: extra leaves: name -> (file parent name, rest offset in metres in the rig's rest frame)
    leaves: dict[str, tuple[str, tuple[float, float, float]]] = field(default_factory=dict)
    #: End Site offsets (rig rest frame, metres) under leaf joints; default: none written as 0 0 0
    end_sites: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    root: str | None = None  # an extra motionless root above Hips (Bandai's joint_Root)
    positions_everywhere: bool = False  # 6 channels on every joint (Bandai)


def _corrections(conv: Convention, rest: np.ndarray) -> dict[str, Rotation]:
    c = {b: Rotation.identity() for b in BONES}
    if conv.rest == "A":
        for side, sign in (("Left", 1.0), ("Right", -1.0)):
            for b in ("UpperArm", "LowerArm", "Hand"):
                c[side + b] = Rotation.from_euler("z", sign * 45, degrees=True)
    elif conv.rest == "x":
        kids = {b: [k for k in BONES if PARENT[k] == b] for b in BONES}
        for b in BONES:
            child = kids[b][0] if kids[b] else None
            v = rest[BONE_INDEX[child]] - rest[BONE_INDEX[b]] if child else np.array([0.0, 0.0, 1.0])
            c[b] = Rotation.align_vectors([v], [[1.0, 0.0, 0.0]])[0]
    return c


def resample(motion: Motion, fps: float) -> Motion:
    """The motion at another frame rate (slerp, linear root), over the same time span."""
    if fps == motion.fps:
        return motion
    t = np.arange(motion.num_frames) / motion.fps
    tn = np.arange(int(np.floor(t[-1] * fps + 1e-9)) + 1) / fps
    q = np.stack([Slerp(t, Rotation.from_quat(motion.rotations[:, j]))(tn).as_quat() for j in range(len(BONES))], 1)
    root = np.stack([np.interp(tn, t, motion.root_pos[:, k]) for k in range(3)], 1)
    return Motion(root_pos=root, rotations=q, fps=fps)


def write_convention(path: Path, motion: Motion, skeleton: Skeleton, conv: Convention) -> Path:
    """Write ``motion`` on ``skeleton`` as ``conv``'s exporter would; returns ``path``."""
    motion = resample(motion, conv.fps)
    rest = skeleton.rest_positions()
    corr = _corrections(conv, rest)
    glob = dict(zip(BONES, global_rotations(motion)))
    axes = np.eye(3) if conv.up == "y" else Rotation.from_euler("x", 90, degrees=True).as_matrix()
    a = Rotation.from_matrix(axes)
    # file joints: name -> (parent name, carrier rig bone, rest world position)
    joints: dict[str, tuple[str | None, str, np.ndarray]] = {}
    order: list[str] = []
    inserted_above: dict[str, str] = {}
    for name, (parent, children, frac) in conv.insert.items():
        for ch in children:
            inserted_above[ch] = name

    def add(name: str, parent: str | None, carrier: str, pos: np.ndarray) -> None:
        joints[name] = (parent, carrier, pos)
        order.append(name)

    if conv.root:
        add(conv.root, None, "Hips", np.zeros(3))
    for b in BONES:
        p = PARENT[b]
        fp = None if p is None else conv.names[p]
        if p is None:
            fp = conv.root
        if b in inserted_above:
            ins = inserted_above[b]
            if ins not in joints:
                parent, children, frac = conv.insert[ins]
                pos = rest[BONE_INDEX[parent]] + frac * (rest[BONE_INDEX[children[0]]] - rest[BONE_INDEX[parent]])
                add(ins, conv.names[parent], parent, pos)
            fp = ins
        add(conv.names[b], fp, b, rest[BONE_INDEX[b]])
    for name, (parent, off) in conv.leaves.items():
        add(name, parent, joints[parent][1], joints[parent][2] + np.array(off))
    kids = {n: [m for m in order if joints[m][0] == n] for n in order}

    def offset(name: str) -> np.ndarray:
        parent, _, pos = joints[name]
        if parent is None:
            return np.zeros(3)
        if parent == conv.root:
            return axes @ (pos - joints[parent][2]) * conv.units_per_m
        return axes @ corr[joints[parent][1]].inv().apply(pos - joints[parent][2]) * conv.units_per_m

    t = motion.num_frames

    def file_global(name: str) -> Rotation:
        carrier = joints[name][1]
        if name == conv.root:
            return Rotation.identity(t)
        return a * glob[carrier] * corr[carrier] * a.inv()

    def depth_first(name: str) -> list[str]:
        return [name] + [d for k in kids[name] for d in depth_first(k)]

    order = depth_first(order[0])  # the order of the MOTION columns
    channels: dict[str, list[str]] = {}
    values: list[np.ndarray] = []
    rot_names = [f"{ax}rotation" for ax in conv.order]
    for name in order:
        parent = joints[name][0]
        has_pos = parent is None or conv.positions_everywhere or (conv.root and parent == conv.root)
        chans = (["Xposition", "Yposition", "Zposition"] if has_pos else []) + rot_names
        channels[name] = chans
        g = file_global(name)
        local = g if parent is None else file_global(parent).inv() * g
        cols = []
        if has_pos:
            if name == conv.root:
                cols.append(np.zeros((t, 3)))
            elif parent is None or name == conv.names["Hips"]:
                cols.append((motion.root_pos @ axes.T) * conv.units_per_m)
            else:
                cols.append(np.repeat(offset(name)[None], t, 0))
        cols.append(local.as_euler(conv.order, degrees=True))
        values.append(np.concatenate(cols, 1))
    lines = ["HIERARCHY"]

    def write(name: str, depth: int) -> None:
        pad = "  " * depth
        lines.append(f"{pad}{'ROOT' if joints[name][0] is None else 'JOINT'} {name}")
        lines.append(pad + "{")
        lines.append(f"{pad}  OFFSET {' '.join(f'{v:.6f}' for v in offset(name))}")
        lines.append(f"{pad}  CHANNELS {len(channels[name])} {' '.join(channels[name])}")
        for k in kids[name]:
            write(k, depth + 1)
        if not kids[name]:
            carrier = joints[name][1]
            site = np.array(conv.end_sites.get(name, (0.0, 0.0, 0.0)))
            site = axes @ corr[carrier].inv().apply(site) * conv.units_per_m
            lines.extend([f"{pad}  End Site", f"{pad}  {{", f"{pad}    OFFSET {' '.join(f'{v:.6f}' for v in site)}", f"{pad}  }}"])
        lines.append(pad + "}")

    write(order[0], 0)
    data = np.concatenate(values, 1)
    lines += ["MOTION", f"Frames: {t}", f"Frame Time: {1.0 / conv.fps:.7f}"]
    lines += [" ".join(f"{v:.5f}" for v in row) for row in data]
    path.write_text("\n".join(lines) + "\n")
    return path


def _sided(bones: dict[str, str]) -> dict[str, str]:
    """Rig names for both sides from ``pattern`` with {s} (Left/Right), {S} (L/R), {l} (left/right)."""
    out = {}
    for rig, name in bones.items():
        for side in ("Left", "Right"):
            out[side + rig] = name.format(s=side, S=side[0], l=side.lower())
    return out


LIMBS = ("Shoulder", "UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot", "Toes")


def mixamo() -> Convention:
    names = {"Hips": "Hips", "Spine": "Spine", "Chest": "Spine1", "Neck": "Neck", "Head": "Head",
             **_sided(dict(zip(LIMBS, ("{s}Shoulder", "{s}Arm", "{s}ForeArm", "{s}Hand", "{s}UpLeg", "{s}Leg", "{s}Foot", "{s}ToeBase"))))}
    leaves = {"HeadTop_End": ("Head", (0.0, 0.18, 0.0))}
    for s, sx in (("Left", 1.0), ("Right", -1.0)):
        leaves[f"{s}HandMiddle1"] = (f"{s}Hand", (sx * 0.09, 0.0, 0.0))
        leaves[f"{s}HandMiddle2"] = (f"{s}HandMiddle1", (sx * 0.04, 0.0, 0.0))
        leaves[f"{s}HandThumb1"] = (f"{s}Hand", (sx * 0.03, -0.01, 0.03))
        leaves[f"{s}Toe_End"] = (f"{s}ToeBase", (0.0, 0.0, 0.05))
    conv = Convention(names=names, units_per_m=100.0, fps=30.0, order="ZXY",
                      insert={"Spine2": ("Chest", ("Neck", "LeftShoulder", "RightShoulder"), 0.5)}, leaves=leaves)
    return _prefixed(conv, "mixamorig:")


def _prefixed(conv: Convention, prefix: str) -> Convention:
    conv.names = {k: prefix + v for k, v in conv.names.items()}
    conv.insert = {prefix + k: (p, c, f) for k, (p, c, f) in conv.insert.items()}
    conv.leaves = {prefix + k: (v[0] if v[0] in conv.names.values() else prefix + v[0], v[1])
                   for k, v in conv.leaves.items()}
    return conv


def cmu() -> Convention:
    names = {"Hips": "Hips", "Spine": "Spine", "Chest": "Spine1", "Neck": "Neck", "Head": "Head",
             **_sided(dict(zip(LIMBS, ("{s}Shoulder", "{s}Arm", "{s}ForeArm", "{s}Hand", "{s}UpLeg", "{s}Leg", "{s}Foot", "{s}ToeBase"))))}
    insert = {"LowerBack": ("Hips", ("Spine",), 0.4), "Neck1": ("Neck", ("Head",), 0.5),
              "LHipJoint": ("Hips", ("LeftUpperLeg",), 0.0), "RHipJoint": ("Hips", ("RightUpperLeg",), 0.0)}
    leaves = {}
    for s, sx in (("Left", 1.0), ("Right", -1.0)):
        leaves[f"{s}FingerBase"] = (f"{s}Hand", (sx * 0.05, 0.0, 0.0))
        leaves[f"{s}HandIndex1"] = (f"{s}FingerBase", (sx * 0.04, 0.0, 0.0))
        leaves[f"{s[0]}Thumb"] = (f"{s}Hand", (sx * 0.02, 0.0, 0.03))
    return Convention(names=names, units_per_m=1 / 0.0254, fps=120.0, order="ZYX", insert=insert, leaves=leaves)


def bandai() -> Convention:
    names = {"Hips": "Hips", "Spine": "Spine", "Chest": "Chest", "Neck": "Neck", "Head": "Head",
             **_sided(dict(zip(LIMBS, ("Shoulder_{S}", "UpperArm_{S}", "LowerArm_{S}", "Hand_{S}", "UpperLeg_{S}", "LowerLeg_{S}", "Foot_{S}", "Toes_{S}"))))}
    return Convention(names=names, units_per_m=100.0, fps=60.0, order="ZXY", rest="x", root="joint_Root",
                      positions_everywhere=True)


def vrm() -> Convention:
    names = {"Hips": "hips", "Spine": "spine", "Chest": "chest", "Neck": "neck", "Head": "head",
             **_sided(dict(zip(LIMBS, ("{l}Shoulder", "{l}UpperArm", "{l}LowerArm", "{l}Hand", "{l}UpperLeg", "{l}LowerLeg", "{l}Foot", "{l}Toes"))))}
    return Convention(names=names, units_per_m=1.0, up="z", rest="A", fps=24.0, order="XYZ",
                      insert={"upperChest": ("Chest", ("Neck", "LeftShoulder", "RightShoulder"), 0.4)})


CONVENTIONS = {"mixamo_cm": mixamo, "cmu_inches": cmu, "bandai_style": bandai, "vrm_m_zup": vrm}
