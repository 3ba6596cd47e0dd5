"""BVH motion of any humanoid rig onto the project's rig: names, units, axes, rest pose, frame rate.

:func:`import_bvh` reads one BVH file of another skeleton (Mixamo, CMU, MotionBuilder /
HumanIK, Unity humanoid / VRM, Bandai-style ``UpperArm_L``, Blender rigs ...) and returns its
motion on the humanoid rig at 30 fps, with the retarget error. The steps:

1. **Names** (:func:`find_joints`): every joint name is split into lower-case words
   (namespaces such as ``mixamorig:`` dropped, ``camelCase``, ``snake_case``, ``L``/``Left``
   prefixes and ``_L``/``.L`` suffixes understood); a side word makes it left or right and the
   rest is looked up in :data:`SYNONYMS`. The limbs are then found from the hand and foot up:
   the lower arm is the hand's nearest ancestor named like a lower arm, the upper arm the lower
   arm's nearest ancestor named like an upper arm (so Mixamo's ``LeftShoulder`` stays a
   clavicle while Biovision's ``LeftShoulder`` above ``LeftElbow`` is the upper arm), and the
   same for the legs. Spine joints are found from the hierarchy, not their names. A map file
   (:func:`read_map`) names joints the conventions do not cover. Fingers, twist bones,
   props and other extra joints are ignored.
2. **Frame rate**: each joint's local rotation is resampled to 30 fps by slerp, translations
   linearly, before forward kinematics.
3. **Axes**: the up axis is the one along which the head stands above the hips (median over
   frames); a Z-up file is turned by the smallest rotation that makes it Y up (Blender's
   forward, -Y, becomes the project's +Z). If the joints named left then lie on the
   character's right (a left-handed file), X is mirrored.
4. **Units** (:data:`UNITS`): the leg length (thigh + shin) in file units is compared with the
   rig's (83.7 cm); the unit that makes the dancer closest to the rig's size is taken (or
   ``units=``). The motion is then scaled to the rig's leg length ("scale normalisation"), so
   root travel and foot heights fit the rig.
5. **Targets and rest pose**: retargeting is positional (:func:`models.rig.retarget.retarget_targets`,
   the solver the DWM dances use), so a T- or A-pose rest makes no difference. Points the
   source has no joint for ride rigidly on a source bone: the head's top and sides, the heels,
   and the hand tip when there is no finger. Their direction in the bone's frame comes from the
   file's rest pose when that pose stands upright (legs down, head up), else from the motion
   itself (the head's up from upright frames, the heel below the ankle from frames with the
   foot flat on the floor).
6. **Error**: a rest skeleton with the clip's own proportions is fitted to the targets
   (:func:`~models.rig.retarget.fit_skeleton_to_targets`), the rotations are solved against it,
   and FK on it is compared with the source's own joints (:data:`SCORED_POINTS`), in cm at the
   rig's scale.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from models.errors import DataError, PerformerError, RigError
from models.rig.bvh import BvhFile, read_bvh
from models.rig.kinematics import fk
from models.rig.motion import Motion
from models.rig.retarget import fit_skeleton_to_targets, retarget_targets
from models.rig.skeleton import NUM_POINTS, POINT_INDEX, POINTS, Skeleton, load_default_skeleton
from models.timebase import FPS

#: File units per metre that units detection chooses among (``mmd``: MikuMikuDance, 8 cm).
UNITS: dict[str, float] = {"m": 1.0, "cm": 100.0, "mm": 1000.0, "in": 1 / 0.0254, "ft": 1 / 0.3048, "mmd": 12.5}

#: Lower-case joint-name words (side words removed, joined) for each role.
SYNONYMS: dict[str, frozenset[str]] = {
    "Head": frozenset({"head"}),
    "Neck": frozenset({"neck", "neck1"}),
    "UpperLeg": frozenset({"upleg", "upperleg", "thigh", "hip", "legupper", "uleg", "femur", "uppleg", "leg"}),
    # ("leg" is MMD's thigh; Mixamo's LeftLeg is the knee: the nearest-ancestor rule tells them apart)
    "LowerLeg": frozenset({"leg", "lowerleg", "knee", "shin", "calf", "leglower", "loleg", "lowleg", "tibia", "lleg"}),
    "Foot": frozenset({"foot", "ankle"}),
    "UpperArm": frozenset({"arm", "upperarm", "uparm", "shldr", "shoulder", "humerus", "armupper", "uarm", "upparm"}),
    "LowerArm": frozenset({"forearm", "lowerarm", "elbow", "loarm", "armlower", "lowarm", "radius", "larm"}),
    "Hand": frozenset({"hand", "wrist"}),
}
_SIDE_WORDS = {"left": "Left", "l": "Left", "lf": "Left", "lft": "Left", "right": "Right", "r": "Right", "rt": "Right", "rgt": "Right"}
#: Words that carry no meaning in a joint name (rig prefixes); digits right after them go too.
_FILLER = frozenset({"j", "bip", "b", "def", "jnt", "mixamorig", "character", "ctrl", "sk", "bone", "c", "org"})
_CAMEL = re.compile(r"[A-Z]+(?=[A-Z][a-z])|[A-Z]?[a-z]+|[A-Z]+|\d+")

_LIMBS = {"Arm": ("Hand", "LowerArm", "UpperArm"), "Leg": ("Foot", "LowerLeg", "UpperLeg")}
#: Rig names a map file may give (the rig's bones and its hand tip); Hips is accepted and ignored.
MAP_KEYS: tuple[str, ...] = (
    "Hips", "Spine", "Chest", "Neck", "Head",
    *(f"{s}{r}" for s in ("Left", "Right") for r in ("UpperArm", "LowerArm", "Hand", "HandTip", "UpperLeg", "LowerLeg", "Foot", "Toes")),
)  # fmt: skip
#: Roles without which a clip cannot be mapped (Toes may be the foot's End Site instead).
REQUIRED: tuple[str, ...] = ("Head",) + tuple(f"{s}{r}" for s in ("Left", "Right") for r in (
    "UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot", "Toes"))  # fmt: skip
#: Rig points whose target is a source joint (when the source has it): the retarget error.
SCORED_POINTS: tuple[str, ...] = (
    "Spine", "Chest", "Head",
    *(f"{s}{r}" for s in ("Left", "Right") for r in ("UpperArm", "LowerArm", "Hand", "HandTip", "UpperLeg", "LowerLeg", "Foot", "Toes")),
)  # fmt: skip

#: Fraction of the hip-centre-to-neck line at which the rig's Spine and Chest heads sit (default rig).
SPINE_AT, CHEST_AT = 0.305, 0.652


def name_words(name: str) -> tuple[str | None, str]:
    """(side, base) of a joint name: ``"mixamorig:LeftUpLeg"`` -> ("Left", "upleg"),
    ``"UpperArm_L"`` -> ("Left", "upperarm"), ``"LHipJoint"`` -> ("Left", "hipjoint"),
    ``"J_Bip_R_LowerLeg"`` -> ("Right", "lowerleg"), ``"Spine1"`` -> (None, "spine1")."""
    name = re.split(r"[:|]", name)[-1]
    words: list[str] = []
    for part in re.split(r"[^A-Za-z0-9]+", name):
        words += [w.lower() for w in _CAMEL.findall(part)]
    side, base, prev_filler = None, [], False
    for w in words:
        if w in _SIDE_WORDS and side is None:
            side, prev_filler = _SIDE_WORDS[w], False
        elif w in _FILLER:
            prev_filler = True
        elif w.isdigit() and prev_filler:
            continue
        else:
            base.append(w)
            prev_filler = False
    return side, "".join(base)


def read_map(path: str | Path) -> dict[str, str]:
    """A joint map file: one ``RigName = SourceJointName`` per line, ``#`` comments.

    Rig names are :data:`MAP_KEYS`. Raises :class:`DataError` naming the file and line.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DataError("map file not found", source=path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"cannot read map file ({exc})", source=path) from None
    out: dict[str, str] = {}
    for n, line in enumerate(text.splitlines(), 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        key, eq, value = (s.strip() for s in line.partition("="))
        if not eq or not key or not value:
            raise DataError(f"line {n}: expected 'RigName = SourceJointName', found {line!r}", source=path)
        if key not in MAP_KEYS:
            raise DataError(f"line {n}: {key!r} is not a rig name; use one of {', '.join(MAP_KEYS)}", source=path)
        if key in out:
            raise DataError(f"line {n}: {key!r} is mapped twice", source=path)
        out[key] = value
    return out


@dataclass
class JointRoles:
    """Which source joint (index into the file's joints) plays each role.

    ``roles`` maps :data:`MAP_KEYS` names to joint indices; ``end_site`` names the roles
    ("LeftToes", "LeftHandTip", ...) taken from an End Site of the named joint instead;
    ``spine`` the joints between the legs and the arms (hips side first).
    """

    roles: dict[str, int]
    end_site: dict[str, int] = field(default_factory=dict)
    spine: list[int] = field(default_factory=list)


def _ancestors(parents: list[int], j: int) -> list[int]:
    out = []
    while parents[j] >= 0:
        j = parents[j]
        out.append(j)
    return out


def _depth(parents: list[int], j: int) -> int:
    return len(_ancestors(parents, j))


def _describe(names: list[str], limit: int = 16) -> str:
    shown = ", ".join(names[:limit])
    return shown + (f" and {len(names) - limit} more" if len(names) > limit else "")


def find_joints(bvh: BvhFile, joint_map: dict[str, str] | None = None) -> JointRoles:
    """The role of each source joint by name conventions and hierarchy, ``joint_map`` first.

    Raises :class:`RigError` naming the file and every role it cannot fill.
    """
    names, parents = bvh.names, bvh.parents
    words = [name_words(n) for n in names]
    roles: dict[str, int] = {}
    end_site: dict[str, int] = {}
    for key, src in (joint_map or {}).items():
        if src not in names:
            raise RigError(f"the map names {src!r} for {key}, but the file has no such joint "
                           f"(its joints: {_describe(names)})", source=bvh.path)
        roles[key] = names.index(src)

    def named(side: str | None, role: str) -> list[int]:
        return [j for j, (s, b) in enumerate(words) if s == side and b in SYNONYMS[role]]

    def nearest_ancestor(j: int, side: str, role: str) -> int | None:
        ok = set(named(side, role))
        return next((a for a in _ancestors(parents, j) if a in ok), None)

    for key in ("Head", "Neck"):
        if key not in roles:
            cands = sorted(named(None, key), key=lambda j: _depth(parents, j))
            if cands:
                roles[key] = cands[0]
    for side in ("Left", "Right"):
        for end, mid, top in _LIMBS.values():
            if side + end not in roles:
                cands = sorted(named(side, end), key=lambda j: _depth(parents, j))
                if cands:
                    roles[side + end] = cands[0]
            if side + mid not in roles and side + end in roles:
                j = nearest_ancestor(roles[side + end], side, mid)
                if j is not None:
                    roles[side + mid] = j
            if side + top not in roles and side + mid in roles:
                j = nearest_ancestor(roles[side + mid], side, top)
                if j is not None:
                    roles[side + top] = j
        foot, hand = roles.get(side + "Foot"), roles.get(side + "Hand")
        if side + "Toes" not in roles and foot is not None:
            below = [j for j in range(len(names)) if foot in _ancestors(parents, j)]
            toes = sorted((j for j in below if words[j][1].startswith("toe") or words[j][1] == "ball"),
                          key=lambda j: _depth(parents, j))
            if toes:
                roles[side + "Toes"] = toes[0]
            elif foot in bvh.end_sites and np.linalg.norm(bvh.end_sites[foot]) > 0:
                end_site[side + "Toes"] = foot
        if side + "HandTip" not in roles and hand is not None:
            below = sorted((j for j in range(len(names)) if hand in _ancestors(parents, j)),
                           key=lambda j: _depth(parents, j))
            for prefix in ("middle", "mid", "index", "fingerbase", "finger", "ring"):
                tips = [j for j in below if words[j][1].removeprefix("hand").startswith(prefix)]
                if tips:
                    roles[side + "HandTip"] = tips[0]
                    break
            else:
                if hand in bvh.end_sites and np.linalg.norm(bvh.end_sites[hand]) > 0:
                    end_site[side + "HandTip"] = hand
    missing = [k for k in REQUIRED if k not in roles and k not in end_site]
    if missing:
        raise RigError(f"cannot map {', '.join(missing)} onto this file's joints ({_describe(names)}); "
                       f"name them with --map FILE (docs/library.md)", source=bvh.path)
    _check_structure(bvh, roles)
    legs = _lca(parents, roles["LeftUpperLeg"], roles["RightUpperLeg"])
    arms = _lca(parents, roles["LeftUpperArm"], roles["RightUpperArm"])
    spine: list[int] = []
    if legs is not None and arms is not None and (arms == legs or legs in _ancestors(parents, arms)):
        spine = [arms] + _ancestors(parents, arms)
        spine = spine[: spine.index(legs) + 1][::-1]
    return JointRoles(roles=roles, end_site=end_site, spine=spine)


def _lca(parents: list[int], a: int, b: int) -> int | None:
    up = {a, *_ancestors(parents, a)}
    return next((j for j in [b, *_ancestors(parents, b)] if j in up), None)


def _check_structure(bvh: BvhFile, roles: dict[str, int]) -> None:
    """Each limb is one chain (upper above lower above the end), and no joint plays two roles."""
    names, parents = bvh.names, bvh.parents
    for side in ("Left", "Right"):
        for end, mid, top in _LIMBS.values():
            chain = [roles[side + end], roles[side + mid], roles[side + top]]
            if chain[1] not in _ancestors(parents, chain[0]) or chain[2] not in _ancestors(parents, chain[1]):
                raise RigError(f"{side}{top} {names[chain[2]]!r}, {side}{mid} {names[chain[1]]!r} and {side}{end} "
                               f"{names[chain[0]]!r} are not one chain from the body outwards", source=bvh.path)
    seen: dict[int, str] = {}
    for key, j in roles.items():
        if key != "Hips" and j in seen:
            raise RigError(f"joint {names[j]!r} would be both {seen[j]} and {key}; fix it with --map", source=bvh.path)
        seen[j] = key


# -- forward kinematics of the source, resampled -------------------------------------------


def _slerp_resample(q: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Quaternions (F, 4) at fractional frame indices ``u`` (T,), by slerp."""
    i0 = np.clip(np.floor(u).astype(int), 0, len(q) - 1)
    i1 = np.minimum(i0 + 1, len(q) - 1)
    w = (u - i0)[:, None]
    a, b = q[i0], q[i1]
    d = (a * b).sum(-1, keepdims=True)
    b = np.where(d < 0, -b, b)
    d = np.abs(d)
    omega = np.arccos(np.clip(d, -1.0, 1.0))
    so = np.sin(omega)
    small = so < 1e-6
    wa = np.where(small, 1 - w, np.sin((1 - w) * omega) / np.where(small, 1.0, so))
    wb = np.where(small, w, np.sin(w * omega) / np.where(small, 1.0, so))
    out = wa * a + wb * b
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def _linear_resample(x: np.ndarray, u: np.ndarray) -> np.ndarray:
    i0 = np.clip(np.floor(u).astype(int), 0, len(x) - 1)
    i1 = np.minimum(i0 + 1, len(x) - 1)
    w = (u - i0)[:, None]
    return (1 - w) * x[i0] + w * x[i1]


@dataclass
class SourceFK:
    """World positions (T, 3) and global rotations of the source joints, in file units and axes."""

    pos: dict[int, np.ndarray]
    rot: dict[int, Rotation]
    rest: dict[int, np.ndarray]  # rest-pose (all channels at their rest) world positions


def source_fk(bvh: BvhFile, joints: set[int], fps: float = FPS) -> SourceFK:
    """FK of ``joints`` (and their ancestors) at ``fps``. A joint's position channels replace its
    OFFSET (as the root's do: absolute, as Blender reads them); rotation channels compose in
    file order (intrinsic). Local rotations are resampled by slerp, translations linearly."""
    need = set(joints)
    for j in joints:
        need.update(_ancestors(bvh.parents, j))
    f = bvh.frames.shape[0]
    duration = (f - 1) / bvh.fps
    t_out = np.arange(int(np.floor(duration * fps + 1e-6)) + 1) / fps
    u = t_out * bvh.fps
    same = abs(bvh.fps - fps) < 1e-6
    out = SourceFK(pos={}, rot={}, rest={})
    axes = {"X": 0, "Y": 1, "Z": 2}
    for j in sorted(need, key=lambda k: _depth(bvh.parents, k)):
        chans, vals = bvh.channels[j], bvh.channel_values(j)
        rot_idx = [k for k, c in enumerate(chans) if c.endswith("rotation")]
        if rot_idx:
            q = Rotation.from_euler("".join(chans[k][0] for k in rot_idx), vals[:, rot_idx], degrees=True).as_quat()
            local = Rotation.from_quat(q if same else _slerp_resample(q, u))
        else:
            local = Rotation.identity(len(t_out))
        trans = np.repeat(bvh.offsets[j][None], f, axis=0)
        for k, c in enumerate(chans):
            if c.endswith("position"):
                trans[:, axes[c[0]]] = vals[:, k]
        trans = trans if same else _linear_resample(trans, u)
        p = bvh.parents[j]
        if p < 0:
            out.rot[j], out.pos[j], out.rest[j] = local, trans, np.zeros(3)
        else:
            out.rot[j] = out.rot[p] * local
            out.pos[j] = out.pos[p] + out.rot[p].apply(trans)
            out.rest[j] = out.rest[p] + bvh.offsets[j]
    return out


# -- the import ---------------------------------------------------------------------------


@dataclass
class ImportedClip:
    """One clip on the rig at 30 fps, with how it was read and how well it maps."""

    name: str
    source: str
    folder: str
    motion: Motion
    skeleton: Skeleton  # the clip's own proportions at the rig's scale (what the error is measured on)
    source_fps: float
    source_frames: int
    units: str
    up: str  # "+y", "+z", ...
    mirrored: bool
    scale: float  # rig metres per file unit
    rest_from: str  # "file" (its rest pose stands) or "motion"
    error_mean_cm: dict[str, float]  # per scored point present in the source
    error_max_cm: dict[str, float]

    @property
    def mean_error_cm(self) -> float:
        return float(np.mean(list(self.error_mean_cm.values())))

    @property
    def max_error_cm(self) -> float:
        return float(max(self.error_max_cm.values()))


_RIG: Skeleton | None = None


def _rig() -> tuple[Skeleton, np.ndarray]:
    global _RIG
    if _RIG is None:
        _RIG = load_default_skeleton()
    return _RIG, _RIG.rest_positions()


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _axis_rotation(up: np.ndarray) -> np.ndarray:
    """Smallest rotation matrix taking the unit axis ``up`` to +Y."""
    y = np.array([0.0, 1.0, 0.0])
    c = float(up @ y)
    if c > 1 - 1e-9:
        return np.eye(3)
    if c < -1 + 1e-9:
        return np.diag([1.0, -1.0, -1.0])
    return Rotation.align_vectors([y], [up])[0].as_matrix()


def import_bvh(
    path: str | Path,
    joint_map: dict[str, str] | None = None,
    *,
    units: str = "auto",
    name: str | None = None,
    folder: str | None = None,
) -> ImportedClip:
    """Read a BVH file of any humanoid rig and retarget it onto the project's rig (module doc).

    Raises :class:`DataError` / :class:`RigError` naming the file for anything it cannot read
    or map: a malformed or truncated file, non-finite values, fewer than two frames, missing
    limbs.
    """
    path = Path(path)
    try:
        return _import(path, joint_map, units, name, folder)
    except PerformerError as exc:
        if str(path) in str(exc):
            raise
        raise type(exc)(str(exc), source=path) from None


def _import(path: Path, joint_map: dict[str, str] | None, units: str, name: str | None, folder: str | None) -> ImportedClip:
    if units != "auto" and units not in UNITS:
        raise DataError(f"unknown units {units!r}; use auto or one of {', '.join(UNITS)}")
    bvh = read_bvh(path)
    if bvh.frames.shape[0] < 2:
        raise DataError(f"{bvh.frames.shape[0]} frame(s): a clip needs at least two")
    jr = find_joints(bvh, joint_map)
    r = jr.roles
    fkj = source_fk(bvh, set(r.values()) | set(jr.end_site.values()) | set(jr.spine))
    P, G = fkj.pos, fkj.rot
    rig, rig_rest = _rig()
    I = POINT_INDEX

    def end_site_pos(key: str) -> np.ndarray:
        j = jr.end_site[key]
        return P[j] + G[j].apply(bvh.end_sites[j])

    def joint(key: str) -> np.ndarray:
        return end_site_pos(key) if key in jr.end_site else P[r[key]]

    hipc = 0.5 * (P[r["LeftUpperLeg"]] + P[r["RightUpperLeg"]])
    neck = 0.5 * (P[r["LeftUpperArm"]] + P[r["RightUpperArm"]])
    head = P[r["Head"]]
    # -- axes: up is where the head stands above the hips; mirror a left-handed file.
    up_v = np.median(head - hipc, axis=0)
    k = int(np.argmax(np.abs(up_v)))
    up_src = np.zeros(3)
    up_src[k] = np.sign(up_v[k]) or 1.0
    m = _axis_rotation(up_src)
    left = np.einsum("ij,tj->ti", m, P[r["LeftUpperLeg"]] - P[r["RightUpperLeg"]])
    fwd = sum(np.einsum("ij,tj->ti", m, joint(f"{s}Toes") - P[r[f"{s}Foot"]]) for s in ("Left", "Right"))
    side = (np.cross([0.0, 1.0, 0.0], fwd * [1.0, 0.0, 1.0]) * left).sum(-1)
    mirrored = bool(np.median(np.sign(side)) < 0)
    if mirrored:
        m = np.diag([-1.0, 1.0, 1.0]) @ m
    # -- units and scale: the legs against the rig's.
    leg_len = np.mean([
        np.median(np.linalg.norm(P[r[f"{s}LowerLeg"]] - P[r[f"{s}UpperLeg"]], axis=-1))
        + np.median(np.linalg.norm(P[r[f"{s}Foot"]] - P[r[f"{s}LowerLeg"]], axis=-1))
        for s in ("Left", "Right")
    ])
    rig_leg = float(np.linalg.norm(rig.offsets[I["LeftLowerLeg"]]) + np.linalg.norm(rig.offsets[I["LeftFoot"]]))
    if not leg_len > 1e-9:
        raise RigError("the legs have no length (upper leg, knee and foot joints coincide)")
    if units == "auto":
        units = min(UNITS, key=lambda u: abs(np.log(leg_len / UNITS[u] / rig_leg)))
    scale = rig_leg / leg_len  # rig metres per file unit
    # -- points that ride on a source bone, from an upright rest pose or from the motion.
    rest = fkj.rest

    def rest_vec(a: int, b: int) -> np.ndarray:
        return m @ (rest[a] - rest[b])

    def cos(v: np.ndarray, w: np.ndarray) -> float:
        return float(_unit(v) @ _unit(w))

    y = np.array([0.0, 1.0, 0.0])
    rest_hipc = 0.5 * (rest[r["LeftUpperLeg"]] + rest[r["RightUpperLeg"]])
    rest_left = _unit(rest_vec(r["LeftUpperLeg"], r["RightUpperLeg"]) * [1.0, 0.0, 1.0])
    upright = (
        cos(m @ (rest[r["Head"]] - rest_hipc), y) > 0.9
        and all(cos(rest_vec(r[f"{s}Foot"], r[f"{s}UpperLeg"]), -y) > 0.9 for s in ("Left", "Right"))
    )
    minv = m.T  # m is orthogonal
    world_up = minv @ y  # +Y of the rig, in file axes
    if upright:
        rest_from = "file"
        head_up = minv @ y
        head_side = minv @ rest_left
        foot_down = {s: minv @ -y for s in ("Left", "Right")}
        hand_dir = {s: _unit(rest[r[f"{s}Hand"]] - rest[r[f"{s}LowerArm"]]) for s in ("Left", "Right")}
    else:
        rest_from = "motion"
        torso = np.einsum("ij,tj->ti", m, neck - hipc)
        straight = (_unit(torso) @ y) > 0.9
        sel = straight if straight.sum() >= 10 else np.ones(len(torso), dtype=bool)
        gh = G[r["Head"]][np.flatnonzero(sel)]
        head_up = _unit(np.median(gh.inv().apply(np.tile(world_up, (len(gh), 1))), axis=0))
        shoulders = (P[r["LeftUpperArm"]] - P[r["RightUpperArm"]])[sel]
        head_side = _unit(np.median(gh.inv().apply(shoulders), axis=0))
        foot_down, hand_dir = {}, {}
        for s in ("Left", "Right"):
            ankle_h = np.einsum("ij,tj->ti", m, P[r[f"{s}Foot"]])[:, 1]
            toe_h = np.einsum("ij,tj->ti", m, joint(f"{s}Toes"))[:, 1]
            lift = np.maximum(ankle_h - np.percentile(ankle_h, 10), toe_h - np.percentile(toe_h, 10))
            flat = np.flatnonzero(lift <= np.percentile(lift, 10))
            gf = G[r[f"{s}Foot"]][flat]
            foot_down[s] = _unit(np.median(gf.inv().apply(np.tile(-world_up, (len(flat), 1))), axis=0))
            gl = G[r[f"{s}Hand"]]
            hand_dir[s] = _unit(np.median(gl.inv().apply(P[r[f"{s}Hand"]] - P[r[f"{s}LowerArm"]]), axis=0))
    head_side = _unit(head_side - (head_side @ head_up) * head_up)
    # -- rig-point targets in file units and axes
    tgt = np.full((len(hipc), NUM_POINTS, 3), np.nan)
    tgt[:, I["Hips"]] = hipc
    for key in ("UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot", "Toes", "HandTip"):
        for s in ("Left", "Right"):
            if f"{s}{key}" in r or f"{s}{key}" in jr.end_site:
                tgt[:, I[s + key]] = joint(s + key)
    # The rig's clavicles start at the neck: the file's neck joint where it has one (rigid on its
    # chest), else the midpoint of the shoulders (as for the DWM dances).
    neck_point = P[r["Neck"]] if "Neck" in r else neck
    tgt[:, I["Neck"]] = tgt[:, I["LeftShoulder"]] = tgt[:, I["RightShoulder"]] = neck_point
    tgt[:, I["Head"]] = head
    head_len = np.median(np.linalg.norm(head - neck, axis=-1))
    head_end = head + G[r["Head"]].apply(head_up * head_len)
    tgt[:, I["HeadEnd"]] = head_end
    half_width = (rig_rest[I["HeadLeft"]] - rig_rest[I["HeadRight"]])[0] / 2 / scale
    tgt[:, I["HeadLeft"]] = head_end + G[r["Head"]].apply(head_side * half_width)
    tgt[:, I["HeadRight"]] = head_end - G[r["Head"]].apply(head_side * half_width)
    heel_back = -rig.end_offsets[POINTS.index("LeftHeel") - len(rig.offsets)][2] / scale
    tip_len = np.linalg.norm(rig.end_offsets[POINTS.index("LeftHandTip") - len(rig.offsets)]) / scale
    for s in ("Left", "Right"):
        gf = G[r[f"{s}Foot"]]
        toe_local = gf.inv().apply(joint(f"{s}Toes") - P[r[f"{s}Foot"]])
        toe_local = np.median(toe_local, axis=0)
        down = foot_down[s]
        ahead = _unit(toe_local - (toe_local @ down) * down)
        heel_local = down * (toe_local @ down) - ahead * heel_back
        tgt[:, I[f"{s}Heel"]] = P[r[f"{s}Foot"]] + gf.apply(heel_local)
        if f"{s}HandTip" not in r and f"{s}HandTip" not in jr.end_site:
            tgt[:, I[f"{s}HandTip"]] = P[r[f"{s}Hand"]] + G[r[f"{s}Hand"]].apply(hand_dir[s] * tip_len)
    # Spine and Chest: the spine joints nearest their place on the hip-centre-to-neck line.
    line = neck - hipc
    frac = {j: float(np.median(((P[j] - hipc) * line).sum(-1) / np.maximum((line * line).sum(-1), 1e-12)))
            for j in jr.spine}
    picked: dict[str, int] = {}
    for key, at, lo, hi in (("Spine", SPINE_AT, 0.1, 0.55), ("Chest", CHEST_AT, 0.45, 0.9)):
        if key in r:
            picked[key] = r[key]
            continue
        cands = [j for j in jr.spine if lo <= frac[j] <= hi and j not in picked.values()]
        if cands:
            picked[key] = min(cands, key=lambda j: abs(frac[j] - at))
    tgt[:, I["Spine"]] = P[picked["Spine"]] if "Spine" in picked else hipc + SPINE_AT * line
    tgt[:, I["Chest"]] = (P[picked["Chest"]] if "Chest" in picked
                          else 0.5 * (tgt[:, I["Spine"]] + neck))
    # -- to the rig's axes and scale, then retarget
    tgt = np.einsum("ij,tpj->tpi", m * scale, tgt)
    tgt[:, I["LeftToesEnd"]] = tgt[:, I["RightToesEnd"]] = np.nan
    skeleton = fit_skeleton_to_targets(np.nan_to_num(tgt))
    motion = retarget_targets(np.nan_to_num(tgt), skeleton, fps=FPS)
    got = fk(motion, skeleton)
    scored = [p for p in SCORED_POINTS if p in picked or p in r or p in jr.end_site]
    err_mean, err_max = {}, {}
    for p in scored:
        d = np.linalg.norm(got[:, I[p]] - tgt[:, I[p]], axis=-1) * 100.0
        err_mean[p], err_max[p] = float(d.mean()), float(d.max())
    up_name = ("+" if up_src[k] > 0 else "-") + "xyz"[k]
    return ImportedClip(
        name=name or path.stem, source=str(path), folder=folder if folder is not None else path.parent.name,
        motion=motion, skeleton=skeleton, source_fps=bvh.fps, source_frames=int(bvh.frames.shape[0]),
        units=units, up=up_name, mirrored=mirrored, scale=float(scale), rest_from=rest_from,
        error_mean_cm=err_mean, error_max_cm=err_max,
    )
