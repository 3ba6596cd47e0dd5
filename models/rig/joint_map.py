"""How the 23 joints of the DWM dataset map onto the humanoid rig.

Joint semantics (docs/rig.md, "Joint map" has the table and the evidence): 0/1 the
right/left side of the head; 2 the pelvis (a lower-spine point about 14 cm above the
hip centre); 3-6 right shoulder, elbow, wrist, hand; 7-11 right hip, knee, ankle,
heel, toe; 12-15 and 16-20 the same on the left; 21 and 22 are markers riding on the
left forearm and the right hand (not used by the rig).

Left is decided from the geometry, assuming the dataset's x, y, z axes are
right-handed like the project frame: with forward taken from the feet (ankle to toe)
or from the knees' bend, ``up x forward`` points to joints 12-20, so they are the
character's left (:func:`left_right_evidence` measures it for any dance).

Every rig point (bone head or end site) gets a target position: a fixed linear
combination of DWM joints (:data:`TARGET_WEIGHTS`), e.g. Hips is the midpoint of the
hip joints 7 and 16 and Neck the midpoint of the shoulders 3 and 12. Spine and Chest,
Neck and Head split the pelvis-to-neck and neck-to-head segments, because the data
has no point in between.
"""

from __future__ import annotations

import numpy as np

from models.errors import RigError
from models.rig.skeleton import NUM_POINTS, POINT_INDEX, POINTS

NUM_DWM_JOINTS: int = 23

#: Name of each DWM joint index, side already decided.
DWM_JOINTS: tuple[str, ...] = (
    "head_right",  # 0
    "head_left",  # 1
    "pelvis",  # 2
    "right_shoulder",  # 3
    "right_elbow",  # 4
    "right_wrist",  # 5
    "right_hand",  # 6
    "right_hip",  # 7
    "right_knee",  # 8
    "right_ankle",  # 9
    "right_heel",  # 10
    "right_toe",  # 11
    "left_shoulder",  # 12
    "left_elbow",  # 13
    "left_wrist",  # 14
    "left_hand",  # 15
    "left_hip",  # 16
    "left_knee",  # 17
    "left_ankle",  # 18
    "left_heel",  # 19
    "left_toe",  # 20
    "left_forearm_marker",  # 21: 11.8 cm from the left elbow, 5.1 cm from the wrist
    "right_hand_marker",  # 22: 4.7 cm from the right hand point
)

#: Fraction of the pelvis(2)-to-neck segment at which the Chest head sits.
CHEST_FRACTION: float = 0.5
#: Fraction of the neck-to-head-centre segment at which the Head head sits.
HEAD_FRACTION: float = 0.5

#: DWM joint that each rig point reproduces directly (the joints FK is scored on).
POINT_OF_JOINT: dict[int, str] = {
    0: "HeadRight",
    1: "HeadLeft",
    2: "Spine",
    3: "RightUpperArm",
    4: "RightLowerArm",
    5: "RightHand",
    6: "RightHandTip",
    7: "RightUpperLeg",
    8: "RightLowerLeg",
    9: "RightFoot",
    10: "RightHeel",
    11: "RightToes",
    12: "LeftUpperArm",
    13: "LeftLowerArm",
    14: "LeftHand",
    15: "LeftHandTip",
    16: "LeftUpperLeg",
    17: "LeftLowerLeg",
    18: "LeftFoot",
    19: "LeftHeel",
    20: "LeftToes",
}
#: Joints the rig does not reproduce, and why.
UNUSED_JOINTS: dict[int, str] = {
    21: "marker on the left forearm near the wrist (not a skeleton joint)",
    22: "marker beside the right hand point (not a skeleton joint)",
}

_NECK = {3: 0.5, 12: 0.5}
_HEAD_CENTRE = {0: 0.5, 1: 0.5}


def _mix(a: dict[int, float], b: dict[int, float], f: float) -> dict[int, float]:
    """Weights of the point ``(1 - f) * a + f * b``."""
    out = {j: (1 - f) * w for j, w in a.items()}
    for j, w in b.items():
        out[j] = out.get(j, 0.0) + f * w
    return out


#: Rig point name -> {DWM joint: weight}; points absent here (toe ends) have no target.
TARGET_SOURCES: dict[str, dict[int, float]] = {
    "Hips": {7: 0.5, 16: 0.5},
    "Chest": _mix({2: 1.0}, _NECK, CHEST_FRACTION),
    "Neck": _NECK,
    "Head": _mix(_NECK, _HEAD_CENTRE, HEAD_FRACTION),
    "LeftShoulder": _NECK,
    "RightShoulder": _NECK,
    "HeadEnd": _HEAD_CENTRE,
    **{name: {j: 1.0} for j, name in POINT_OF_JOINT.items()},
}


def _weight_matrix() -> np.ndarray:
    w = np.full((NUM_POINTS, NUM_DWM_JOINTS), np.nan)
    for name, src in TARGET_SOURCES.items():
        row = np.zeros(NUM_DWM_JOINTS)
        for j, v in src.items():
            row[j] = v
        w[POINT_INDEX[name]] = row
    return w


#: (NUM_POINTS, 23) linear map from DWM joints to rig-point targets; NaN rows: no target.
TARGET_WEIGHTS: np.ndarray = _weight_matrix()
assert set(TARGET_SOURCES) <= set(POINTS)


def check_positions(world_positions_m: np.ndarray, source: str | None = None) -> np.ndarray:
    """Validate DWM positions: (T, 23, 3) finite floats with T >= 1; returns float64.

    Raises :class:`RigError` naming ``source`` (a file or a description) otherwise.
    """
    what = source or "DWM joint positions"
    try:
        p = np.asarray(world_positions_m, dtype=np.float64)
    except (TypeError, ValueError):
        raise RigError(f"{what}: not a numeric array") from None
    if p.ndim != 3 or p.shape[1:] != (NUM_DWM_JOINTS, 3) or p.shape[0] < 1:
        raise RigError(f"{what}: expected shape (T, {NUM_DWM_JOINTS}, 3), got {p.shape}")
    bad = ~np.isfinite(p)
    if bad.any():
        t, j, _ = np.argwhere(bad)[0]
        raise RigError(f"{what}: {int(bad.sum())} non-finite values (first at frame {t}, joint {j})")
    return p


def dwm_targets(world_positions_m: np.ndarray, source: str | None = None) -> np.ndarray:
    """Target position of every rig point, (T, NUM_POINTS, 3) metres; NaN where none."""
    p = check_positions(world_positions_m, source)
    return np.einsum("pj,tjc->tpc", TARGET_WEIGHTS, p)


def _horizontal_unit(v: np.ndarray) -> np.ndarray:
    v = v * np.array([1.0, 0.0, 1.0])
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-9)


def _off_line(p: np.ndarray, a: int, b: int, c: int) -> np.ndarray:
    """Component of joint b's position off the line from joint a to joint c."""
    u = p[:, c] - p[:, a]
    u = u / np.maximum(np.linalg.norm(u, axis=-1, keepdims=True), 1e-9)
    v = p[:, b] - p[:, a]
    return v - (v * u).sum(-1, keepdims=True) * u


def left_right_evidence(world_positions_m: np.ndarray, min_knee_bend_m: float = 0.03) -> dict[str, float]:
    """Fractions of frames supporting "joints 12-20 are the character's left".

    Forward is estimated per frame two ways: from the feet (sum of both ankle-to-toe
    vectors, horizontal) and from the knees (sum of both knees' offsets from their
    hip-ankle lines, horizontal; only frames where that offset exceeds
    ``min_knee_bend_m``). Left is ``up x forward`` (right-handed, Y up). Keys:
    ``hips_by_feet``, ``hips_by_knees``, ``shoulders_by_feet``, ``shoulders_by_knees``
    (fraction of frames where the left-labelled hip/shoulder lies on the left), and
    ``arms_match_legs`` (fraction where the shoulder and hip left-right vectors agree).
    """
    p = check_positions(world_positions_m)
    up = np.array([0.0, 1.0, 0.0])
    fwd_feet = _horizontal_unit((p[:, 11] - p[:, 9]) + (p[:, 20] - p[:, 18]))
    bend = _off_line(p, 7, 8, 9) + _off_line(p, 16, 17, 18)
    bent = np.linalg.norm(bend * np.array([1.0, 0.0, 1.0]), axis=-1) > min_knee_bend_m
    fwd_knees = _horizontal_unit(bend)[bent]
    hips, shoulders = p[:, 16] - p[:, 7], p[:, 12] - p[:, 3]

    def on_left(v: np.ndarray, fwd: np.ndarray) -> float:
        return float(((v * np.cross(up, fwd)).sum(-1) > 0).mean()) if len(fwd) else float("nan")

    return {
        "hips_by_feet": on_left(hips, fwd_feet),
        "hips_by_knees": on_left(hips[bent], fwd_knees),
        "shoulders_by_feet": on_left(shoulders, fwd_feet),
        "shoulders_by_knees": on_left(shoulders[bent], fwd_knees),
        "arms_match_legs": float(((hips * shoulders).sum(-1) > 0).mean()),
    }


#: Rig point standing in for each marker joint in :func:`to_dwm_positions` (approximate).
MARKER_STAND_IN: dict[int, str] = {21: "LeftHand", 22: "RightHandTip"}


def to_dwm_positions(points: np.ndarray) -> np.ndarray:
    """DWM joint layout (T, 23, 3) from rig points (T, NUM_POINTS, 3), e.g. ``fk(...)``'s output.

    Joints 0-20 are their rig points; the markers 21 and 22, which the rig does not
    model, are placed at :data:`MARKER_STAND_IN` (the left wrist, the right hand point).
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 3 or pts.shape[1:] != (NUM_POINTS, 3):
        raise RigError(f"rig points must have shape (T, {NUM_POINTS}, 3), got {pts.shape}")
    out = np.empty((pts.shape[0], NUM_DWM_JOINTS, 3))
    for j, name in {**POINT_OF_JOINT, **MARKER_STAND_IN}.items():
        out[:, j] = pts[:, POINT_INDEX[name]]
    return out
