"""Feet on the floor: LODGE's foot-skating ratio on this rig, and what goes with it (issue 39).

A foot is **in contact** in frame t when its lower point (heel end site or toe point, the
``*Heel`` and ``*Toes`` points of :mod:`models.rig.skeleton`) is at most
:data:`CONTACT_HEIGHT` (5 cm) above the floor, the floor being the clip's
:data:`FLOOR_PERCENTILE` (2nd) percentile of both feet's lowest points; it **slides** when
its heel-toe midpoint moved more than :data:`SLIDE_STEP` (1 cm) horizontally since frame
t - 1. The foot-skating ratio (FSR, as LODGE, Li et al. CVPR 2024, counts it) is sliding
contact foot-frames over contact foot-frames. Beside it: the mean horizontal speed of a
foot in contact (m/s), how far the lowest foot point goes below the floor (cm), and the
knee angle (degrees of flexion, signed: below 0 the knee is past straight, hyper-extended).

Positions come from forward kinematics on the default skeleton
(:func:`models.evaluation.evaluate.positions`); poses are the rig's flat vectors (T, 87).
Computed on a motion as it stands: in place (the canonical frame, root x/z zeroed and the
heading removed) or with its travel.
"""

from __future__ import annotations

import numpy as np

from models.rig.humanoid import BONE_INDEX
from models.rig.skeleton import POINT_INDEX, load_default_skeleton
from models.timebase import FPS

#: Height above the floor (m) at or under which a foot's lower point is in contact.
CONTACT_HEIGHT: float = 0.05
#: Horizontal step of the heel-toe midpoint (m a frame) above which a foot in contact slides.
SLIDE_STEP: float = 0.01
#: Percentile of both feet's lowest points over the clip that is the floor.
FLOOR_PERCENTILE: float = 2.0

FEET: tuple[str, str] = ("Left", "Right")
#: (2,) FK point indices of each foot's heel and toe, left first.
HEEL_POINTS: tuple[int, int] = tuple(POINT_INDEX[f"{s}Heel"] for s in FEET)  # type: ignore[assignment]
TOE_POINTS: tuple[int, int] = tuple(POINT_INDEX[f"{s}Toes"] for s in FEET)  # type: ignore[assignment]


def knee_flexion_deg(poses: np.ndarray) -> np.ndarray:
    """(T, 2) signed knee flexion (degrees), left then right, from the lower legs' local
    rotations: the angle in the upper leg's sagittal (y-z) plane from the straight shin (its
    rest direction) to the bent one, positive as a knee bends (the ankle goes back, -Z, for a
    leg facing +Z), negative past straight (hyper-extended)."""
    from scipy.spatial.transform import Rotation

    p = np.asarray(poses, np.float64)
    off = load_default_skeleton().offsets
    out = np.empty((len(p), 2))
    for k, side in enumerate(FEET):
        b = BONE_INDEX[f"{side}LowerLeg"]
        q = p[:, 3 + 4 * b : 7 + 4 * b]
        rest = off[BONE_INDEX[f"{side}Foot"]]
        d = Rotation.from_quat(q / np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-12)).apply(rest)
        ang_rest = np.arctan2(-rest[2], -rest[1])
        out[:, k] = np.degrees(np.arctan2(-d[:, 2], -d[:, 1]) - ang_rest)
    return (out + 180.0) % 360.0 - 180.0


def foot_points(positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(heel, toe), each (T, 2, 3) m, left foot first, from FK positions (T, 30, 3)."""
    return positions[:, list(HEEL_POINTS)], positions[:, list(TOE_POINTS)]


def foot_skating(poses: np.ndarray, positions: np.ndarray | None = None, floor: float | None = None,
                 fps: float = FPS) -> dict[str, float]:
    """The feet's figures of one clip of poses (T, 87) (``positions``: their FK points (T, 30, 3),
    if already computed; ``floor``: the floor height in m, default the clip's own, see the
    module docstring):

    - ``fsr``: sliding contact foot-frames / contact foot-frames (frames 1..T-1; 0 without contact)
    - ``contact_speed``: mean horizontal speed of the heel-toe midpoint over those foot-frames, m/s
    - ``contact_share``: contact foot-frames / all foot-frames
    - ``contact_frames``: their number; ``frames``: all foot-frames counted (2 (T - 1))
    - ``below_floor_cm``: the most any foot's lowest point is below the floor, cm (0 if none)
    - ``below_1cm_frames``: foot-frames more than 1 cm below the floor
    - ``knee_min_deg``: the least knee flexion over both legs (below 0: past straight)
    - ``knee_past_straight``: share of leg-frames with flexion below 0
    - ``floor``: the floor height used, m
    """
    if positions is None:
        from models.evaluation.evaluate import positions as fk_positions

        positions = fk_positions(np.asarray(poses, np.float32))
    heel, toe = foot_points(positions)
    low = np.minimum(heel[..., 1], toe[..., 1])  # (T, 2)
    fl = float(np.percentile(low, FLOOR_PERCENTILE)) if floor is None else float(floor)
    contact = low <= fl + CONTACT_HEIGHT
    mid = 0.5 * (heel + toe)
    step = np.linalg.norm(np.diff(mid[..., [0, 2]], axis=0), axis=-1)  # (T-1, 2) m a frame
    c = contact[1:]
    n = int(c.sum())
    depth = np.maximum(fl - low, 0.0)
    knee = knee_flexion_deg(poses)
    return {
        "fsr": float((step[c] > SLIDE_STEP).sum() / n) if n else 0.0,
        "contact_speed": float(step[c].mean() * fps) if n else 0.0,
        "contact_share": float(c.mean()) if c.size else 0.0,
        "contact_frames": n,
        "frames": int(c.size),
        "below_floor_cm": float(depth.max() * 100.0) if depth.size else 0.0,
        "below_1cm_frames": int((depth > 0.01).sum()),
        "knee_min_deg": float(knee.min()) if knee.size else 0.0,
        "knee_past_straight": float((knee < 0.0).mean()) if knee.size else 0.0,
        "floor": fl,
    }


def pooled(rows: list[dict[str, float]]) -> dict[str, float]:
    """:func:`foot_skating` rows of several clips as one: FSR and contact speed over all their
    contact foot-frames, the other shares weighted by their foot-frames, the worst (most below the floor, least knee flexion) for the extremes, sums for
    the counts."""
    w = np.array([r["frames"] for r in rows], np.float64)
    nc = np.array([r["contact_frames"] for r in rows], np.float64)
    out: dict[str, float] = {}
    for key in rows[0]:
        v = np.array([r[key] for r in rows], np.float64)
        if key in ("fsr", "contact_speed"):
            out[key] = float((v * nc).sum() / max(nc.sum(), 1.0))
        elif key == "below_floor_cm":
            out[key] = float(v.max())
        elif key == "knee_min_deg":
            out[key] = float(v.min())
        elif key in ("below_1cm_frames", "contact_frames", "frames"):
            out[key] = int(v.sum())
        else:
            out[key] = float((v * w).sum() / w.sum())
    return out
