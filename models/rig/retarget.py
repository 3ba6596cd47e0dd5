"""Retargeting DWM joint positions onto the humanoid rig, and fitting its rest offsets.

:func:`retarget` turns world positions (T, 23, 3) into a :class:`Motion`: the root
(Hips = midpoint of the hip joints) position plus each bone's local rotation
relative to the T-pose. Every rig point has a target (``joint_map.TARGET_SOURCES``);
bones are solved parent first, each from the directions between its own targets, so
rotations do not depend on bone lengths (FK with a skeleton of other proportions
gives the same pose on that skeleton):

- Hips: least-squares fit of the two hip joints and the pelvis point (joint 2).
- Spine: half of the pelvis-to-neck rotation relative to Hips (twist from the
  shoulder line), then aimed at the Chest target; Chest: aimed at the neck, twisted
  by the shoulder line.
- Neck: aimed at the Head target by its smallest swing (the neck tilts); Head: aimed
  at the head centre, twisted by the line between the two head points (the head
  turns). That line is trusted while the points are at least 60% of their rest
  distance apart (they collapse and swap in some Waltz frames).
- Shoulders, lower arms, hands, lower legs: swing only (no twist relative to the
  parent), aimed at the next joint.
- Upper arms and legs: aimed at the elbow/knee, twisted so that the limb bends in the
  rest bend direction (elbows towards +Z, knees towards -Z). The bend plane is
  trusted above BEND_TRUSTED_DEG of bend and ignored below BEND_IGNORED_DEG; for
  legs the knee then faces the toes (heel-to-toe line), for arms the last twist is
  carried along with the parent. The twist turns at most MAX_TWIST_STEP_DEG per frame
  towards its data.
- Feet: least-squares fit of the toe and heel points; toes keep the identity.

Degenerate frames (a zero-length vector) repeat the bone's previous local rotation;
quaternions are hemisphere-aligned along time, so no bone flips sign between frames.
:func:`fit_skeleton` derives rest offsets from the same targets.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from models.errors import RigError
from models.rig.humanoid import BONE_INDEX, NUM_BONES, PARENT_INDEX
from models.rig.joint_map import dwm_targets
from models.rig.kinematics import (
    fill_invalid,
    follow_twist_reference,
    frame_rotation,
    hemisphere_align,
    kabsch_rotation,
    swing_rotation,
)
from models.rig.motion import Motion
from models.rig.skeleton import END_SITES, NUM_POINTS, POINT_PARENT_INDEX, POINTS, Skeleton, mirror_name
from models.timebase import FPS

X, Y, Z = np.eye(3)
#: Synthetic toe tip, ahead of the toe point in the foot frame (metres).
TOES_END_OFFSET = np.array([0.0, 0.0, 0.02])
#: Most a twist reference may turn towards its data in one frame (degrees): a bend plane or
#: head line that reappears far from the carried one is caught up over a few frames.
MAX_TWIST_STEP_DEG = 30.0
#: Limb bend angles (degrees) between which the bend plane goes from ignored to trusted.
BEND_IGNORED_DEG, BEND_TRUSTED_DEG = 10.0, 25.0
#: Points that a per-frame skeleton puts at their measured 3-D offset from the parent bone:
#: the end sites with a target and the toe points (the Toes bone has no rotation of its own,
#: so its head is one more marker on the foot). Rotations are not aimed at the head sides,
#: heels and toes, which the mocap does not hold rigid relative to their bone.
MEASURED_POINTS: tuple[str, ...] = (
    "HeadEnd", "HeadLeft", "HeadRight", "LeftHandTip", "RightHandTip", "LeftHeel", "RightHeel", "LeftToes", "RightToes",
)  # fmt: skip

_I = {name: i for i, name in enumerate(POINTS)}


def _v(tgt: np.ndarray, a: str, b: str) -> np.ndarray:
    """Per-frame vector from point b to point a."""
    return tgt[:, _I[a]] - tgt[:, _I[b]]


# -- rest skeleton -------------------------------------------------------------------


def _fit_frames(tgt: np.ndarray) -> dict[str, Rotation]:
    """Per-frame body-part frames (world from rest) with conventional rest axes."""
    frames = {
        "hips": frame_rotation(_v(tgt, "LeftUpperLeg", "RightUpperLeg"), _v(tgt, "Spine", "Hips"), X, Y),
        "torso": frame_rotation(_v(tgt, "Neck", "Spine"), _v(tgt, "LeftUpperArm", "RightUpperArm"), Y, X),
        "head": frame_rotation(_v(tgt, "HeadEnd", "Neck"), _v(tgt, "HeadLeft", "HeadRight"), Y, X),
    }
    for side in ("Left", "Right"):
        toe, heel = _v(tgt, f"{side}Toes", f"{side}Heel"), _v(tgt, f"{side}Foot", f"{side}Heel")
        frames[side + "Foot"] = frame_rotation(toe, heel, Z, Y)
    return {k: fill_invalid(r, valid) for k, (r, valid) in frames.items()}


#: For each non-root point: the frame its offset is measured in, or the rest axis of a
#: limb segment (offset = axis * length).
_OFFSET_FRAME: dict[str, str | np.ndarray] = {
    "Spine": "hips", "LeftUpperLeg": "hips", "RightUpperLeg": "hips",
    "Chest": "torso", "Neck": "torso", "LeftShoulder": "torso", "RightShoulder": "torso",
    "LeftUpperArm": "torso", "RightUpperArm": "torso",
    "LeftLowerArm": X, "LeftHand": X, "LeftHandTip": X,
    "RightLowerArm": -X, "RightHand": -X, "RightHandTip": -X,
    "Head": "head", "HeadEnd": "head", "HeadLeft": "head", "HeadRight": "head",
    "LeftLowerLeg": -Y, "LeftFoot": -Y, "RightLowerLeg": -Y, "RightFoot": -Y,
    "LeftToes": "LeftFoot", "LeftHeel": "LeftFoot", "RightToes": "RightFoot", "RightHeel": "RightFoot",
}  # fmt: skip


def _local_offsets(tgt: np.ndarray) -> np.ndarray:
    """Per-frame offsets (T, NUM_POINTS, 3) of every point in its measuring frame (NaN: none)."""
    frames = _fit_frames(tgt)
    out = np.full(tgt.shape, np.nan)
    for name, how in _OFFSET_FRAME.items():
        i = _I[name]
        vec = tgt[:, i] - tgt[:, POINT_PARENT_INDEX[i]]
        out[:, i] = frames[how].inv().apply(vec) if isinstance(how, str) else np.linalg.norm(vec, axis=-1)[:, None] * how
    return out


def _symmetrize(off: np.ndarray) -> np.ndarray:
    """Average each left/right pair with its mirror image (x negated); centre points get x = 0."""
    out = off.copy()
    flip = np.array([-1.0, 1.0, 1.0])
    for i, name in enumerate(POINTS):
        j = _I[mirror_name(name)]
        out[..., i, :] = 0.5 * (off[..., i, :] + off[..., j, :] * flip)
    return out


def fit_skeleton(world_positions_m: np.ndarray, *, symmetric: bool = False, per_frame: bool = False) -> Skeleton:
    """Fit rest offsets to DWM positions (T, 23, 3) in metres.

    Each offset is the component-wise median over frames of the child's position in
    its parent's body frame (limb segments: the median length along the T-pose axis).
    ``symmetric`` averages left and right. The root's rest position puts the lowest
    rest point at y = 0.

    ``per_frame=True`` returns a skeleton fitted to each frame, offsets (T, J, 3) and
    (T, E, 3), because the mocap does not keep its bones rigid (lengths vary by
    centimetres from frame to frame, and so do the shapes of the head, foot and hand
    point groups). Chain bones keep the median rest direction, scaled to the frame's
    measured distance between the two targets. The :data:`MEASURED_POINTS` (end sites
    and toe points) get the frame's measured 3-D offset from their parent bone's head
    target, in that bone's frame as retargeting solves it. Rotations are solved first,
    from directions, against ``rest`` (the median over frames of the rest pose with
    each frame's bone lengths, as before these offsets existed; kept as the skeleton's
    ``rest``), so they do not depend on the measured offsets: those only absorb the
    markers' non-rigid motion relative to their bone.
    """
    return fit_skeleton_to_targets(dwm_targets(world_positions_m), symmetric=symmetric, per_frame=per_frame)


def fit_skeleton_to_targets(tgt: np.ndarray, *, symmetric: bool = False, per_frame: bool = False) -> Skeleton:
    """:func:`fit_skeleton` from rig-point targets (T, NUM_POINTS, 3) in metres, whatever made them
    (DWM joints through ``joint_map``, or another rig's joints, :mod:`models.data.bvh_import`);
    every point but the toe ends needs a target."""
    local = _local_offsets(tgt)
    rest = np.median(local, axis=0)
    rest[_I["Hips"]] = 0.0
    # HeadEnd is the midpoint of the head points (as its target is): centre the pair on it.
    shift = 0.5 * (rest[_I["HeadLeft"]] + rest[_I["HeadRight"]]) - rest[_I["HeadEnd"]]
    rest[_I["HeadLeft"]] -= shift
    rest[_I["HeadRight"]] -= shift
    for side in ("Left", "Right"):
        rest[_I[side + "ToesEnd"]] = TOES_END_OFFSET
    if symmetric:
        rest = _symmetrize(rest)
    rest[_I["Hips"], 1] = -Skeleton(rest[:NUM_BONES], rest[NUM_BONES:]).rest_positions()[:, 1].min()
    if not per_frame:
        return Skeleton(offsets=rest[:NUM_BONES], end_offsets=rest[NUM_BONES:])
    lengths = np.linalg.norm(local, axis=-1)  # (T, P), NaN where no target
    scale = lengths / np.maximum(np.linalg.norm(rest, axis=-1), 1e-9)
    off = rest[None] * np.where(np.isfinite(scale), scale, 1.0)[..., None]
    off[:, _I["Hips"]] = rest[_I["Hips"]]
    solve_rest = Skeleton(offsets=off[:, :NUM_BONES], end_offsets=off[:, NUM_BONES:]).rest_skeleton()
    glob = _solve(tgt, solve_rest)
    for name in MEASURED_POINTS:
        i, p = _I[name], POINT_PARENT_INDEX[_I[name]]
        off[:, i] = glob[POINTS[p]].inv().apply(tgt[:, i] - tgt[:, p])
    return Skeleton(offsets=off[:, :NUM_BONES], end_offsets=off[:, NUM_BONES:], rest=solve_rest)


# -- retargeting ---------------------------------------------------------------------


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _ramp(x: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """0 below ``lo``, 1 above ``hi``, linear in between."""
    return np.clip((x - lo) / (hi - lo), 0.0, 1.0)


def _blend_about(axis: np.ndarray, a: np.ndarray, b: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Unit vectors (T, 3) perpendicular to ``axis``: ``a``'s perpendicular part turned about
    ``axis`` towards ``b``'s by the fraction ``w`` (T,) of the angle between them."""
    d = _unit(axis)
    a = _unit(a - (a * d).sum(-1, keepdims=True) * d)
    b = b - (b * d).sum(-1, keepdims=True) * d
    da = np.cross(d, a)
    angle = w * np.arctan2((da * b).sum(-1), (a * b).sum(-1))
    return np.cos(angle)[:, None] * a + np.sin(angle)[:, None] * da


def _bend_weight(upper: np.ndarray, lower: np.ndarray) -> np.ndarray:
    """Trust (T,) in a limb's bend plane: 0 under BEND_IGNORED_DEG of bend, 1 over BEND_TRUSTED_DEG."""
    bend = np.degrees(np.arccos(np.clip((_unit(upper) * _unit(lower)).sum(-1), -1.0, 1.0)))
    return _ramp(bend, BEND_IGNORED_DEG, BEND_TRUSTED_DEG)


class _Solver:
    """Solves global bone rotations parent first, from the directions between targets.

    Rotations never depend on where FK would put a bone (so not on bone lengths): a
    bone's rotation comes from the vectors between its own targets. A frame where a
    defining vector is degenerate (zero, or parallel to the twist reference) keeps
    that bone's previous local rotation.
    """

    def __init__(self, tgt: np.ndarray, skeleton: Skeleton) -> None:
        self.tgt = tgt
        self.rest = skeleton.rest_skeleton().rest_positions()
        self.rot: dict[str, Rotation] = {}

    def vec(self, a: str, b: str) -> np.ndarray:
        """Target vector from point b to point a, (T, 3)."""
        return self.tgt[:, _I[a]] - self.tgt[:, _I[b]]

    def rest_vec(self, a: str, b: str) -> np.ndarray:
        return self.rest[_I[a]] - self.rest[_I[b]]

    def parent(self, name: str) -> Rotation:
        return self.rot[POINTS[POINT_PARENT_INDEX[_I[name]]]]

    def set(self, name: str, rot: Rotation, valid: np.ndarray) -> None:
        """Store a global rotation; invalid frames repeat the last valid local rotation."""
        if POINT_PARENT_INDEX[_I[name]] < 0:
            self.rot[name] = fill_invalid(rot, valid)
        else:
            parent = self.parent(name)
            self.rot[name] = parent * fill_invalid(parent.inv() * rot, valid)

    def frame(self, name: str, child: str, secondary: np.ndarray, rest_secondary: np.ndarray) -> None:
        """Aim ``name`` at ``child`` exactly, twisted so rest_secondary follows ``secondary``."""
        rot, valid = frame_rotation(self.vec(child, name), secondary, self.rest_vec(child, name), rest_secondary)
        self.set(name, rot, valid)

    def fit(self, name: str, children: tuple[str, ...]) -> None:
        """Least-squares rotation taking the rest vectors from ``name`` to ``children`` onto the targets'."""
        tv = np.stack([self.vec(c, name) for c in children], axis=1)
        rv = np.stack([self.rest_vec(c, name) for c in children], axis=0)
        self.set(name, *kabsch_rotation(tv, rv))

    def swing(self, name: str, child: str, start: Rotation | None = None) -> None:
        """Aim ``name`` at ``child`` by the smallest rotation from ``start`` (default: the parent)."""
        start = self.parent(name) if start is None else start
        s, valid = swing_rotation(start.apply(self.rest_vec(child, name)), self.vec(child, name))
        self.set(name, s * start, valid)

    def split(self, name: str, child: str, whole: Rotation) -> None:
        """Half of ``whole``'s rotation relative to the parent, then aimed at ``child``."""
        parent = self.parent(name)
        rel = (parent.inv() * whole).as_rotvec()
        self.swing(name, child, start=parent * Rotation.from_rotvec(0.5 * rel))

    def limb(self, upper: str, lower: str, end: str, rest_bend: np.ndarray, straight: np.ndarray | None = None) -> None:
        """Upper bone of a limb, twisted by the bend plane of the upper and lower segments.

        ``straight`` (T, 3), optional: where the rest bend direction points while the
        limb is too straight for its bend plane to count (for legs: behind the foot).
        Without it the last trusted bend direction is carried along.
        """
        d_upper, d_lower = self.vec(lower, upper), self.vec(end, lower)
        bend, trust = d_lower, _bend_weight(d_upper, d_lower)
        if straight is not None:
            bend = _blend_about(d_upper, straight, d_lower, trust)
            along = np.abs((_unit(straight) * _unit(d_upper)).sum(-1))
            trust = trust + (1.0 - trust) * _ramp(np.sqrt(1.0 - np.minimum(along, 1.0) ** 2), 0.2, 0.5)
        self.frame(upper, lower, self.reference(upper, d_upper, bend, trust, rest_bend), rest_bend)

    def reference(self, name: str, primary: np.ndarray, secondary: np.ndarray, trust: np.ndarray, rest: np.ndarray) -> np.ndarray:
        """:func:`~models.rig.kinematics.follow_twist_reference` run in the parent bone's frame, so that a carried twist
        reference turns with the parent (a spinning body carries its limbs' twist along)."""
        parent = self.parent(name)
        inv = parent.inv()
        return parent.apply(follow_twist_reference(inv.apply(primary), inv.apply(secondary), trust, rest, MAX_TWIST_STEP_DEG))


def _solve(tgt: np.ndarray, skeleton: Skeleton) -> dict[str, Rotation]:
    s = _Solver(tgt, skeleton)
    s.fit("Hips", ("LeftUpperLeg", "RightUpperLeg", "Spine"))
    shoulders, rest_shoulders = s.vec("LeftUpperArm", "RightUpperArm"), s.rest_vec("LeftUpperArm", "RightUpperArm")
    torso, _ = frame_rotation(s.vec("Neck", "Spine"), shoulders, s.rest_vec("Neck", "Spine"), rest_shoulders)
    s.split("Spine", "Chest", torso)
    s.frame("Chest", "Neck", shoulders, rest_shoulders)
    # Head twist from the two head points, trusted while they are >= 60% of their rest distance apart.
    side, rest_side = s.vec("HeadLeft", "HeadRight"), s.rest_vec("HeadLeft", "HeadRight")
    trust = _ramp(np.linalg.norm(side, axis=-1) / np.linalg.norm(rest_side), 0.3, 0.6)
    s.swing("Neck", "Head")  # the neck tilts; the head turns (and tilts what is left)
    side = s.reference("Head", s.vec("HeadEnd", "Head"), side, trust, rest_side)
    s.frame("Head", "HeadEnd", side, rest_side)
    for lr in ("Left", "Right"):
        s.swing(f"{lr}Shoulder", f"{lr}UpperArm")
        s.limb(f"{lr}UpperArm", f"{lr}LowerArm", f"{lr}Hand", Z)
        s.swing(f"{lr}LowerArm", f"{lr}Hand")
        s.swing(f"{lr}Hand", f"{lr}HandTip")
        behind_foot = s.vec(f"{lr}Heel", f"{lr}Toes")  # a straight knee faces the toes
        s.limb(f"{lr}UpperLeg", f"{lr}LowerLeg", f"{lr}Foot", -Z, straight=behind_foot)
        s.swing(f"{lr}LowerLeg", f"{lr}Foot")
        s.fit(f"{lr}Foot", (f"{lr}Toes", f"{lr}Heel"))
        s.rot[f"{lr}Toes"] = s.rot[f"{lr}Foot"]
    return s.rot


def retarget(
    world_positions_m: np.ndarray, skeleton: Skeleton, fps: float = FPS, source: str | None = None
) -> Motion:
    """Rig motion from DWM world joint positions (T, 23, 3) in metres.

    Returns the root (Hips = midpoint of the hip joints) position and per-bone local
    rotations (xyzw, relative to the T-pose), hemisphere-aligned along time.
    ``skeleton`` gives the rest directions (a per-frame skeleton must have T frames;
    its :meth:`~models.rig.skeleton.Skeleton.rest_skeleton` is used). ``fps`` is only recorded in the Motion (the raw DWM frame
    rate differs by style; resampling is :mod:`models.data.alignment`'s job). Raises
    :class:`RigError` naming ``source`` for bad input.
    """
    return retarget_targets(dwm_targets(world_positions_m, source), skeleton, fps)


def retarget_targets(tgt: np.ndarray, skeleton: Skeleton, fps: float = FPS) -> Motion:
    """:func:`retarget` from rig-point targets (T, NUM_POINTS, 3) in metres, whatever made them
    (DWM joints through ``joint_map``, or another rig's joints, :mod:`models.data.bvh_import`);
    every point but the toe ends needs a target."""
    if skeleton.per_frame and skeleton.offsets.shape[0] != tgt.shape[0]:
        raise RigError(f"per-frame skeleton has {skeleton.offsets.shape[0]} frames, positions have {tgt.shape[0]}")
    glob = _solve(tgt, skeleton)
    root = tgt[:, _I["Hips"]]
    quats = np.empty((tgt.shape[0], NUM_BONES, 4))
    for name, j in BONE_INDEX.items():
        p = PARENT_INDEX[j]
        local = glob[name] if p < 0 else glob[POINTS[p]].inv() * glob[name]
        quats[:, j] = local.as_quat()
    return Motion(root_pos=root, rotations=hemisphere_align(quats), fps=fps)


assert set(_OFFSET_FRAME) | {"Hips", "LeftToesEnd", "RightToesEnd"} == set(POINTS), "every point needs an offset rule"
assert len(END_SITES) == NUM_POINTS - NUM_BONES
