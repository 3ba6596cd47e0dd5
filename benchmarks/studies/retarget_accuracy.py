"""Retargeting accuracy and rotation continuity over the whole DWM dataset.

For every dance, on its raw mocap frames (``Dance.world_positions_m()``, no
resampling), this measures:

1. Left/right: fractions of frames supporting "joints 12-20 are the character's
   left" (``joint_map.left_right_evidence``), the worst dance per style.
2. Bone-length noise: per segment, the mean and max absolute deviation of the
   frame's length from the dance's median length.
3. Accuracy: ``fk(retarget(P, sk), sk)`` against the 21 covered DWM joints, per
   joint mean / 99th percentile / max error in cm, for three skeletons ``sk``:
   ``per-frame`` (fitted to each frame: chain bones in the dance's median rest
   directions with that frame's measured lengths, end sites and toe points at their
   measured offsets from the parent bone; rotations solved as with the others),
   ``per-dance`` (the dance's median fit) and ``default``
   (models/assets/humanoid_rest.json, one symmetric skeleton for all dances). For the
   per-frame skeleton's measured points, also how far their offsets move from the
   rigid rest shape (what that skeleton absorbs of the markers' non-rigid motion).
4. Continuity: per bone, the largest frame-to-frame change of its local rotation
   (per-dance skeleton), and for every change over 60 degrees the source event
   that explains it (see :func:`explain_jump`).

Usage::

    .venv/bin/python benchmarks/studies/retarget_accuracy.py --data ../shared/data/dwm
    .venv/bin/python benchmarks/studies/retarget_accuracy.py --data ../shared/data/dwm \\
        --write-rest models/assets/humanoid_rest.json   # regenerate the default skeleton

Prints Markdown tables (the figures in docs/rig.md come from here). About 50 s on
one CPU core. ``--trace DANCE:BONE:START:STOP`` prints instead what moves one bone
over a few raw frames (see :func:`trace`).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from models.data.dwm import Dance, load_dance, load_dataset  # noqa: E402
from models.rig.humanoid import BONES, PARENT  # noqa: E402
from models.rig.joint_map import POINT_OF_JOINT, dwm_targets, left_right_evidence  # noqa: E402
from models.rig.kinematics import fk, global_rotations, rotation_jumps_deg  # noqa: E402
from models.rig.retarget import BEND_TRUSTED_DEG, MEASURED_POINTS, fit_skeleton, retarget  # noqa: E402
import models.rig.retarget as retarget_module  # noqa: E402
from models.rig.motion import Motion  # noqa: E402
from models.rig.skeleton import POINT_INDEX, POINT_PARENT_INDEX, Skeleton, load_default_skeleton  # noqa: E402

JUMP_DEG = 60.0
COLLAPSED = 0.5  # a segment under half its median length has no reliable direction
TURN_DEG = 30.0  # a defining vector turning this much in one raw frame is a source jump
FOLD_DEG = 160.0  # a joint bent further than this (beyond human range) has an unstable swing
SKELETONS = ("per-frame", "per-dance", "default")

#: Segments (pairs of rig points) whose directions define each bone's rotation.
_LIMB = {
    "UpperArm": [("UpperArm", "LowerArm"), ("LowerArm", "Hand")],
    "LowerArm": [("LowerArm", "Hand")],
    "Hand": [("Hand", "HandTip")],
    "Shoulder": [("Shoulder", "UpperArm")],
    "UpperLeg": [("UpperLeg", "LowerLeg"), ("LowerLeg", "Foot"), ("Toes", "Heel")],
    "LowerLeg": [("LowerLeg", "Foot")],
    "Foot": [("Foot", "Toes"), ("Foot", "Heel")],
    "Toes": [("Foot", "Toes"), ("Foot", "Heel")],
}
DEFINING: dict[str, list[tuple[str, str]]] = {
    "Hips": [("RightUpperLeg", "LeftUpperLeg"), ("Hips", "Spine")],
    "Spine": [("Spine", "Neck"), ("RightUpperArm", "LeftUpperArm")],
    "Chest": [("Spine", "Neck"), ("RightUpperArm", "LeftUpperArm")],
    "Neck": [("Neck", "Head")],
    "Head": [("Head", "HeadEnd"), ("HeadRight", "HeadLeft")],
    **{
        lr + part: [(lr + a, lr + b) for a, b in segs]
        for lr in ("Left", "Right")
        for part, segs in _LIMB.items()
    },
}
#: Limb upper bones whose twist follows a bend plane (the upper/lower segment pair).
BEND: dict[str, tuple[str, str, str]] = {
    lr + up: (lr + up, lr + mid, lr + low)
    for lr in ("Left", "Right")
    for up, mid, low in (("UpperArm", "LowerArm", "Hand"), ("UpperLeg", "LowerLeg", "Foot"))
}


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    cos = (a * b).sum(-1) / np.maximum(np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1), 1e-12)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def explain_jump(tgt: np.ndarray, bone: str, t: int) -> str:
    """Why bone's local rotation changes a lot between raw frames t and t+1, from the source.

    Checks, for the segments defining the bone and its parent: a segment collapsed
    below COLLAPSED of its median length (its direction is noise); a segment turning
    by TURN_DEG or more within the frame (a teleport, a label swap or a very fast
    turn); a joint folded beyond FOLD_DEG (its swing is near 180 degrees, where the
    smallest rotation is unstable); for a limb's upper bone, its bend plane turning by
    TURN_DEG while the limb is clearly bent (BEND_TRUSTED_DEG) in both frames; a
    segment defining a further ancestor collapsed below COLLAPSED (that ancestor's
    rotation is then wrong, and the bone's local rotation is relative to it, as is the
    twist reference carried along with its parent). Returns "" if none applies.
    """
    names = [bone] + ([PARENT[bone]] if PARENT[bone] else [])
    found = []
    for name in names:
        for a, b in DEFINING[name]:
            v = tgt[:, POINT_INDEX[b]] - tgt[:, POINT_INDEX[a]]
            length = np.linalg.norm(v, axis=-1)
            ratio = min(length[t], length[t + 1]) / np.median(length)
            turn = float(_angle(v[t], v[t + 1]))
            if ratio < COLLAPSED:
                found.append(f"{a}-{b} collapsed to {ratio:.0%} of its length")
            elif turn >= TURN_DEG:
                found.append(f"{a}-{b} turns {turn:.0f} deg")
        parent = PARENT[name]
        if parent in DEFINING and DEFINING[name][0][0] == DEFINING[parent][0][1]:  # chained segments
            a, b = DEFINING[parent][0]
            c = DEFINING[name][0][1]
            seg0 = tgt[t : t + 2, POINT_INDEX[b]] - tgt[t : t + 2, POINT_INDEX[a]]
            seg1 = tgt[t : t + 2, POINT_INDEX[c]] - tgt[t : t + 2, POINT_INDEX[b]]
            fold = _angle(seg0, seg1).max()
            if fold > FOLD_DEG:
                found.append(f"{b} folded to {fold:.0f} deg (swing near 180 deg is singular)")
        if name in BEND:
            u, m, low = (POINT_INDEX[p] for p in BEND[name])
            upper, lower = tgt[t : t + 2, m] - tgt[t : t + 2, u], tgt[t : t + 2, low] - tgt[t : t + 2, m]
            normal = np.cross(upper, lower)
            turn = float(_angle(normal[0], normal[1]))
            if _angle(upper, lower).min() >= BEND_TRUSTED_DEG and turn >= TURN_DEG:
                found.append(f"{name} bend plane turns {turn:.0f} deg")
    ancestor, seen = PARENT[names[-1]], {seg for name in names for seg in DEFINING[name]}
    while ancestor:
        for a, b in DEFINING[ancestor]:
            length = np.linalg.norm(tgt[:, POINT_INDEX[b]] - tgt[:, POINT_INDEX[a]], axis=-1)
            ratio = min(length[t], length[t + 1]) / np.median(length)
            if (a, b) not in seen and ratio < COLLAPSED:
                found.append(f"{a}-{b} (defining ancestor {ancestor}) collapsed to {ratio:.0%} of its length")
            seen.add((a, b))
        ancestor = PARENT[ancestor]
    return "; ".join(dict.fromkeys(found))


def jump_details(tgt: np.ndarray, bone: str, t: int) -> str:
    """The source measures :func:`explain_jump` thresholds, for a jump it did not explain."""
    names = [bone] + ([PARENT[bone]] if PARENT[bone] else [])
    parts = []
    for a, b in dict.fromkeys(seg for name in names for seg in DEFINING[name]):
        v = tgt[:, POINT_INDEX[b]] - tgt[:, POINT_INDEX[a]]
        length = np.linalg.norm(v, axis=-1)
        ratio = min(length[t], length[t + 1]) / np.median(length)
        parts.append(f"{a}-{b} turns {float(_angle(v[t], v[t + 1])):.0f} deg at {ratio:.0%} length")
    for name in names:
        if name in BEND:
            u, m, low = (POINT_INDEX[p] for p in BEND[name])
            upper, lower = tgt[t : t + 2, m] - tgt[t : t + 2, u], tgt[t : t + 2, low] - tgt[t : t + 2, m]
            bend = _angle(upper, lower)
            normal = np.cross(upper, lower)
            parts.append(f"{name} bend {bend[0]:.0f}->{bend[1]:.0f} deg, plane turns {float(_angle(normal[0], normal[1])):.0f} deg")
    return "; ".join(parts)


@dataclass
class Stats:
    errors: dict[str, list[np.ndarray]] = field(default_factory=lambda: {k: [] for k in SKELETONS})
    length_dev: list[np.ndarray] = field(default_factory=list)
    absorbed: list[np.ndarray] = field(default_factory=list)
    frames: list[tuple[str, int]] = field(default_factory=list)  # (dance, raw frame) of each scored row
    rot_diff: list[np.ndarray] = field(default_factory=list)  # (T, J) deg, per-frame vs default skeleton
    jumps: list[np.ndarray] = field(default_factory=list)
    events: list[tuple[str, str, int, float, str]] = field(default_factory=list)
    sides: dict[str, list[dict[str, float]]] = field(default_factory=dict)
    details: dict[tuple[str, str, int], str] = field(default_factory=dict)


def _covered_error(positions: np.ndarray, motion: Motion, sk: Skeleton) -> np.ndarray:
    """(T, 21) cm error of FK(motion, sk) at the covered DWM joints."""
    x = fk(motion, sk)
    idx = [POINT_INDEX[n] for n in POINT_OF_JOINT.values()]
    return 100.0 * np.linalg.norm(x[:, idx] - positions[:, list(POINT_OF_JOINT)], axis=-1)


def absorbed_cm(sk: Skeleton) -> np.ndarray:
    """(T, 21) cm: how far a per-frame skeleton's measured offset of each covered point lies
    from its rigid rest shape (the rest direction at the same length); NaN for chain points."""
    off = sk.point_offsets()
    out = np.full((off.shape[0], len(POINT_OF_JOINT)), np.nan)
    rest = sk.rest_skeleton().point_offsets()
    for c, name in enumerate(POINT_OF_JOINT.values()):
        if name in MEASURED_POINTS:
            i = POINT_INDEX[name]
            o = off[:, i]
            rigid = rest[i] / np.linalg.norm(rest[i]) * np.linalg.norm(o, axis=-1, keepdims=True)
            out[:, c] = 100.0 * np.linalg.norm(o - rigid, axis=-1)
    return out


def _segment_lengths(positions: np.ndarray) -> np.ndarray:
    """(T, 21) length of the segment from each covered point's parent bone head to it."""
    tgt = dwm_targets(positions)
    idx = [POINT_INDEX[n] for n in POINT_OF_JOINT.values()]
    return np.linalg.norm(tgt[:, idx] - tgt[:, [POINT_PARENT_INDEX[i] for i in idx]], axis=-1)


def evaluate(dance: Dance, default: Skeleton, stats: Stats) -> None:
    p = dance.world_positions_m()
    stats.sides.setdefault(dance.style, []).append(left_right_evidence(p))
    lengths = _segment_lengths(p)
    stats.length_dev.append(100.0 * np.abs(lengths - np.median(lengths, axis=0)))
    stats.frames += [(dance.name, t) for t in range(len(p))]
    motions = {}
    for kind in SKELETONS:
        sk = {"per-frame": lambda: fit_skeleton(p, per_frame=True), "per-dance": lambda: fit_skeleton(p), "default": lambda: default}[kind]()
        motions[kind] = retarget(p, sk)
        stats.errors[kind].append(_covered_error(p, motions[kind], sk))
        if sk.per_frame:
            stats.absorbed.append(absorbed_cm(sk))
    a, b = motions["per-frame"].rotations, motions["default"].rotations
    stats.rot_diff.append(np.degrees(2.0 * np.arccos(np.clip(np.abs((a * b).sum(-1)), 0.0, 1.0))))
    motion = motions["per-dance"]
    jumps = rotation_jumps_deg(motion.rotations)
    stats.jumps.append(jumps.max(axis=0))
    tgt = dwm_targets(p)
    for t, j in zip(*np.nonzero(jumps > JUMP_DEG)):
        why = explain_jump(tgt, BONES[j], int(t))
        stats.events.append((dance.name, BONES[j], int(t), float(jumps[t, j]), why))
        if not why:
            stats.details[(dance.name, BONES[j], int(t))] = jump_details(tgt, BONES[j], int(t))


def joint_evidence(dances: list[Dance]) -> str:
    """Markdown: what each DWM joint is, with distances (cm) that show it."""
    by_style: dict[str, np.ndarray] = {}
    for d in dances:
        by_style[d.style] = np.concatenate([by_style.get(d.style, np.zeros((0, 23, 3))), 100 * d.world_positions_m()])
    p = np.concatenate(list(by_style.values()))
    dist = lambda a, b, q=p: np.linalg.norm(q[:, a] - q[:, b], axis=-1)  # noqa: E731
    rows = []
    pairs = [(0, 1), (1, 12), (0, 3), (2, 7), (2, 16), (7, 16), (3, 12), (3, 4), (4, 5), (5, 6), (12, 13), (13, 14),
             (14, 15), (7, 8), (8, 9), (9, 10), (10, 11), (9, 11), (16, 17), (17, 18), (18, 19), (19, 20), (18, 20),
             (21, 13), (21, 14), (21, 15), (22, 4), (22, 5), (22, 6)]  # fmt: skip
    for a, b in pairs:
        d = dist(a, b)
        rows.append([f"{a}-{b}", f"{np.median(d):.1f}", f"{d.std():.1f}"] + [f"{np.median(dist(a, b, q)):.1f}" for q in by_style.values()])
    out = [_table(["joints", "median cm", "std cm"] + [f"median {st}" for st in by_style], rows), ""]
    for st, q in by_style.items():
        n = (q[:, 3] + q[:, 12]) / 2
        x = q[:, 12] - q[:, 3]
        y = n - q[:, 2]
        z = np.cross(x, y)
        h = q[:, 1] - q[:, 0]
        yaw = np.degrees(np.arctan2((h * z).sum(-1) / np.linalg.norm(z, axis=-1), (h * x).sum(-1) / np.linalg.norm(x, axis=-1)))
        short = np.linalg.norm(h, axis=-1) < 0.6 * np.median(np.linalg.norm(h, axis=-1))
        out.append(f"- {st}: head points 0->1 turned more than 90 deg from the shoulder line 3->12 in {(np.abs(yaw) > 90).mean():.1%} of frames; closer than 60% of their median distance in {short.mean():.1%}")
    return "\n".join(out)


def _table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in rows])


def report(stats: Stats, num_dances: int, num_frames: int) -> str:
    out = [f"Dances: {num_dances}, raw frames: {num_frames}.", "", "### Left/right evidence (worst dance per style)", ""]
    keys = list(next(iter(stats.sides.values()))[0])
    rows = [[st] + [f"{min(d[k] for d in ds):.3f}" for k in keys] for st, ds in sorted(stats.sides.items())]
    out += [_table(["style"] + keys, rows), "", "### Accuracy, cm (mean / p99 / max over all frames)", ""]
    err = {k: np.concatenate(v) for k, v in stats.errors.items()}
    dev = np.concatenate(stats.length_dev)
    absorbed = np.concatenate(stats.absorbed)
    rows = []
    for c, (j, name) in enumerate(POINT_OF_JOINT.items()):
        a = absorbed[:, c]
        cells = [f"{j}", name, f"{dev[:, c].mean():.2f} / {dev[:, c].max():.1f}"]
        cells.append(f"{a.mean():.2f} / {a.max():.1f}" if np.isfinite(a).all() else "")
        cells += [f"{err[k][:, c].mean():.2f} / {np.percentile(err[k][:, c], 99):.2f} / {err[k][:, c].max():.2f}" for k in SKELETONS]
        rows.append(cells)
    rows.append(["all", "", f"{dev.mean():.2f} / {dev.max():.1f}", ""] + [
        f"**{e.mean():.2f}** / {np.percentile(e, 99):.2f} / **{e.max():.2f}**" for e in err.values()
    ])
    out.append(_table(["joint", "rig point", "length noise mean / max", "shape absorbed mean / max"] + list(SKELETONS), rows))
    classes = {"chain joints": [c for c, n in enumerate(POINT_OF_JOINT.values()) if n not in MEASURED_POINTS],
               "measured points": [c for c, n in enumerate(POINT_OF_JOINT.values()) if n in MEASURED_POINTS]}
    out.append("")
    for k, e in err.items():
        out.append(f"{k}: " + "; ".join(f"{cls} mean {e[:, cs].mean():.2f} / max {e[:, cs].max():.2f} cm" for cls, cs in classes.items()))
    rd = np.concatenate(stats.rot_diff)
    top = np.argsort(-rd.mean(axis=0))[:3]
    out.append(
        f"local rotations, per-frame against default skeleton (deg): mean {rd.mean():.2f}, p99 {np.percentile(rd, 99):.2f}, "
        f"max {rd.max():.1f} ({BONES[int(np.argmax(rd.max(axis=0)))]}); largest means: "
        + ", ".join(f"{BONES[j]} {rd[:, j].mean():.2f}" for j in top)
    )
    where = [
        f"{name} {stats.frames[int(np.argmax(absorbed[:, c]))][0]} raw frame {stats.frames[int(np.argmax(absorbed[:, c]))][1]}"
        for c, name in enumerate(POINT_OF_JOINT.values())
        if np.isfinite(absorbed[:, c]).all() and absorbed[:, c].max() > 3.0
    ]
    out.append("largest shape absorbed (> 3 cm) at: " + ("; ".join(where) or "none"))
    worst = np.unravel_index(np.argmax(err["per-frame"]), err["per-frame"].shape)
    out.append(f"per-frame worst: {stats.frames[worst[0]][0]} raw frame {stats.frames[worst[0]][1]}, DWM joint {list(POINT_OF_JOINT)[worst[1]]}, {err['per-frame'][worst]:.2f} cm")
    for k, e in err.items():
        worst = e.max(axis=1)
        out.append(f"\n{k}: frames with an error over 3 cm: {(worst > 3).sum()} of {len(worst)} ({(worst > 3).mean():.2%}); over 1 cm mean per frame: {(e.mean(axis=1) > 1).mean():.2%}")
    out += ["", f"### Largest frame-to-frame local rotation change per bone (degrees; > {JUMP_DEG:.0f} counted)", ""]
    jm = np.stack(stats.jumps)
    ev_by_bone: dict[str, list] = {}
    for e in stats.events:
        ev_by_bone.setdefault(e[1], []).append(e)
    rows = []
    for j, b in enumerate(BONES):
        evs = ev_by_bone.get(b, [])
        unexplained = [e for e in evs if not e[4]]
        rows.append([b, f"{jm[:, j].max():.1f}", str(len(evs)), str(len(evs) - len(unexplained)), str(len(unexplained))])
    out.append(_table(["bone", "max jump", f"jumps > {JUMP_DEG:.0f}", "explained by source", "unexplained"], rows))
    out += ["", "Jumps over 60 degrees (dance, bone, raw frame t -> t+1, degrees, source event):", ""]
    for name, bone, t, deg, why in sorted(stats.events, key=lambda e: -e[3]):
        out.append(f"- {name} {bone} {t}->{t + 1}: {deg:.0f} deg; {why or 'UNEXPLAINED'}")
    for (name, bone, t), detail in stats.details.items():
        same = [f"{b}: {w}" for n, b, tt, _, w in stats.events if n == name and tt == t and w]
        out.append(f"\nUnexplained {name} {bone} {t}->{t + 1}: {detail}. Same frame: {'; '.join(same) or 'nothing'}")
    return "\n".join(out)


def trace(dance: Dance, bone: str, start: int, stop: int) -> str:
    """Markdown table, one row per raw frame step t -> t+1 in [start, stop), of what moves ``bone``.

    Columns: the local rotation change of ``bone`` and of every ancestor, in degrees
    (per-dance skeleton); the length at t+1 of each ancestor's defining segments as a
    fraction of its median; for a limb, the bend angle at t+1 and the twist lag: the
    angle about the upper segment between the data's bend direction and where the
    solved upper bone carries its rest bend direction (0 while it follows the data).
    """
    p = dance.world_positions_m()
    motion = retarget(p, fit_skeleton(p))
    tgt = dwm_targets(p)
    jumps = rotation_jumps_deg(motion.rotations)
    chain = [bone]
    while PARENT[chain[-1]]:
        chain.append(PARENT[chain[-1]])  # type: ignore[arg-type]
    segs = list(dict.fromkeys(seg for name in chain[1:] for seg in DEFINING[name]))
    ratio = {}
    for a, b in segs:
        length = np.linalg.norm(tgt[:, POINT_INDEX[b]] - tgt[:, POINT_INDEX[a]], axis=-1)
        ratio[(a, b)] = length / np.median(length)
    limb = next((name for name in chain if name in BEND), None)
    header = ["t -> t+1"] + [f"{n} local" for n in chain] + [f"{a}-{b} length" for a, b in segs]
    if limb:
        u, m, low = (POINT_INDEX[n] for n in BEND[limb])
        upper, lower = tgt[:, m] - tgt[:, u], tgt[:, low] - tgt[:, m]
        bend = _angle(upper, lower)
        axis = upper / np.linalg.norm(upper, axis=-1, keepdims=True)
        rest_bend = np.array([0.0, 0.0, 1.0 if "Arm" in limb else -1.0])
        carried = global_rotations(motion)[BONES.index(limb)].apply(rest_bend)
        data = lower - (lower * axis).sum(-1, keepdims=True) * axis
        lag = np.degrees(np.arctan2((np.cross(carried, data) * axis).sum(-1), (carried * data).sum(-1)))
        header += [f"{limb} bend", "twist lag"]
    rows = []
    for t in range(max(start, 0), min(stop, len(p) - 1)):
        row = [f"{t} -> {t + 1}"] + [f"{jumps[t, BONES.index(n)]:.1f}" for n in chain] + [f"{ratio[sg][t + 1]:.0%}" for sg in segs]
        if limb:
            row += [f"{bend[t + 1]:.0f}", f"{lag[t + 1]:.0f}"]
        rows.append(row)
    return _table(header, rows)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True, type=Path, help="the DWM dataset directory (holds DANCE_* folders)")
    ap.add_argument("--styles", default=None, help="only these style letters, e.g. CR")
    ap.add_argument("--write-rest", type=Path, default=None, help="fit the symmetric dataset-wide rest skeleton and write it here (JSON), then evaluate with it")
    ap.add_argument("--trace", default=None, metavar="DANCE:BONE:START:STOP", help="only print, for raw frames START..STOP of one dance, what moves BONE (see trace())")
    ap.add_argument("--max-twist-step", type=float, default=None, help="with --trace: retarget with this twist-reference step limit (degrees per frame) instead of retarget.MAX_TWIST_STEP_DEG, to see where a jump goes")
    args = ap.parse_args(argv)
    t0 = time.time()
    if args.trace:
        name, bone, start, stop = args.trace.split(":")
        if args.max_twist_step is not None:
            retarget_module.MAX_TWIST_STEP_DEG = args.max_twist_step  # read at call time by the solver
        print(trace(load_dance(args.data / name), bone, int(start), int(stop)))
        return 0
    dances = load_dataset(args.data, styles=args.styles)
    if args.write_rest:
        all_frames = np.concatenate([d.world_positions_m() for d in dances])
        note = "symmetric median fit over all raw frames of the DWM dataset; written by: .venv/bin/python benchmarks/studies/retarget_accuracy.py --data ../shared/data/dwm --write-rest models/assets/humanoid_rest.json"
        fit_skeleton(all_frames, symmetric=True).to_json(args.write_rest, note=note)
        print(f"wrote {args.write_rest}", file=sys.stderr)
        default = load_default_skeleton(args.write_rest)
    else:
        default = load_default_skeleton()
    print("### Joint distances\n")
    print(joint_evidence(dances) + "\n")
    stats = Stats()
    for d in dances:
        evaluate(d, default, stats)
    print(report(stats, len(dances), sum(d.num_frames for d in dances)))
    print(f"\n({time.time() - t0:.0f} s)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
