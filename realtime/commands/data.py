"""``performer data info PATH``: what is in a DWM dataset directory, and what looks wrong."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TextIO

import numpy as np

#: Joint pairs measured as bones (from the dataset authors' drawing code; see
#: docs/data.md).  Joints 21 and 22 are not drawn by the authors and not measured.
BONES: dict[str, tuple[int, int]] = {
    "head 0-1": (0, 1),
    "shoulders 3-12": (3, 12),
    "arm 3-4": (3, 4), "arm 4-5": (4, 5), "arm 5-6": (5, 6),
    "arm 12-13": (12, 13), "arm 13-14": (13, 14), "arm 14-15": (14, 15),
    "pelvis 2-7": (2, 7), "pelvis 2-16": (2, 16),
    "leg 7-8": (7, 8), "leg 8-9": (8, 9), "leg 9-10": (9, 10), "leg 10-11": (10, 11),
    "leg 16-17": (16, 17), "leg 17-18": (17, 18), "leg 18-19": (18, 19), "leg 19-20": (19, 20),
}
TELEPORT_M_S = 10.0  # a joint faster than this between two stored frames is a teleport
FLOOR_M, CEILING_M = -0.10, 2.60  # joint heights outside this range are out of range
BONE_OUTLIER = (0.25, 2.0)  # a bone shorter/longer than this x its median in the dance
# DWM joints are not a rigid skeleton: 5-95 % bone-length ranges are 14-66 % of the
# median length in an ordinary dance.  A dance is flagged when one of its ranges is
# this many times the median range of that bone over all dances.
BONE_SPREAD_FLAG = 1.5


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "data", help="inspect the DWM training dataset",
        description="Inspect the DWM (Dance with Melody) dataset. See docs/data.md.",
    )
    sub = p.add_subparsers(dest="data_command", metavar="SUBCOMMAND", required=True)
    info = sub.add_parser(
        "info", help="list the dances and flag suspicious frames",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "Validate every dance under PATH (the 'dwm' directory holding DANCE_<C|R|W>_<id>/) and print,\n"
            "per dance: style, stored frames, seconds of motion, effective frame rate of the stored\n"
            "frames ((N-1)*25/(E-S)), the music interval [S/25, E/25] s, the song's length, train/val\n"
            "membership and flags; then minutes per style, total frames, the split, and a summary of\n"
            "suspicious frames.\n\n"
            "Flags:\n"
            "  held N/L     N frames repeat their predecessor exactly, longest run L frames\n"
            "  teleport N   N frame steps where a joint moves faster than 10 m/s\n"
            "  range N      N frames with a joint below -0.10 m or above 2.60 m, or a bone outside\n"
            "               0.25-2x its median length in that dance\n"
            "  bones        some bone's 5-95 % length range is over 1.5x that bone's median range\n"
            "               over all dances (DWM bones are not rigid: 14-66 % of their length)\n"
            "  unverified   the alignment study could not confirm the timing (docs/data.md)\n"
            "  past-audio   the music interval ends after the end of audio.mp3\n\n"
            "Exit status 0 when the dataset loads (flags do not fail it), 2 with a one-line\n"
            "message naming the file for a missing directory or a malformed file."
        ),
    )
    info.add_argument("path", type=Path, metavar="PATH", help="the dwm dataset directory")
    info.add_argument("--json", action="store_true", help="print one JSON object instead of tables")
    info.set_defaults(func=info_command)


# ------------------------------------------------------------------------- analysis
def bone_lengths_cm(joints_cm: np.ndarray) -> np.ndarray:
    """(N, len(BONES)) bone lengths in cm of (N, 23, 3) joint positions."""
    a = np.array([i for i, _ in BONES.values()])
    b = np.array([j for _, j in BONES.values()])
    return np.linalg.norm(joints_cm[:, a] - joints_cm[:, b], axis=-1)


def dance_report(dance, audio_seconds: float | None) -> dict:
    """Facts and suspicious-frame counts for one :class:`models.data.dwm.Dance`."""
    from models.data.alignment import UNVERIFIED_ALIGNMENT, held_runs, motion_timestamps, source_fps

    ts = motion_timestamps(dance)
    world = dance.world_positions_m()
    speed = np.linalg.norm(np.diff(world, axis=0), axis=2) / np.diff(ts)[:, None]  # (N-1, 23) m/s
    lengths = bone_lengths_cm(dance.joints_cm)
    med = np.median(lengths, axis=0)
    spread = np.percentile(lengths, 95, axis=0) - np.percentile(lengths, 5, axis=0)
    bad_bone = (lengths < BONE_OUTLIER[0] * med) | (lengths > BONE_OUTLIER[1] * med)
    bad_height = (world[..., 1] < FLOOR_M) | (world[..., 1] > CEILING_M)
    runs = held_runs(dance)
    return {
        "name": dance.name,
        "style": dance.style,
        "frames": dance.num_frames,
        "motion_s": float(ts[-1] - ts[0]),
        "source_fps": source_fps(dance),
        "music_start_s": dance.start_seconds,
        "music_end_s": dance.end_seconds,
        "audio_s": audio_seconds,
        "held_frames": int(sum(n for _, n in runs)),
        "held_runs": [{"first": s, "length": n} for s, n in runs],
        "teleports": int((speed.max(axis=1) > TELEPORT_M_S).sum()),
        "max_joint_speed_m_s": float(speed.max()),
        "out_of_range_frames": int((bad_height.any(axis=1) | bad_bone.any(axis=1)).sum()),
        "out_of_range_by_bone": {k: int(n) for k, n in zip(BONES, bad_bone.sum(axis=0)) if n},
        "bone_median_cm": dict(zip(BONES, np.round(med, 2).tolist())),
        "bone_spread_cm": dict(zip(BONES, np.round(spread, 2).tolist())),
        "alignment_unverified": UNVERIFIED_ALIGNMENT.get(dance.name),
        "past_audio": audio_seconds is not None and dance.end_seconds > audio_seconds,
    }


def audio_seconds(path: Path) -> float:
    """Length of an audio file from its header; DataError naming the file if unreadable."""
    import soundfile as sf

    from models.errors import DataError

    try:
        return float(sf.info(str(path)).duration)
    except (RuntimeError, sf.LibsndfileError) as exc:
        raise DataError(f"cannot read the audio header ({exc})", source=path) from None


def dataset_report(root: Path) -> dict:
    """Everything ``performer data info`` prints, as a JSON-ready dict."""
    from models.data.dwm import STYLES, dance_dirs, load_dance
    from models.data.split import split_names

    dances = [load_dance(d) for d in dance_dirs(root)]
    reports = [dance_report(d, audio_seconds(d.audio_path)) for d in dances]
    train, val = split_names([r["name"] for r in reports])
    typical = {b: float(np.median([r["bone_spread_cm"][b] for r in reports])) for b in BONES}
    for r in reports:
        r["split"] = "val" if r["name"] in val else "train"
        r["wide_bones"] = [b for b in BONES if r["bone_spread_cm"][b] > BONE_SPREAD_FLAG * typical[b]]
    lengths = np.concatenate([bone_lengths_cm(d.joints_cm) for d in dances])
    per_style = {
        STYLES[s]: {
            "dances": sum(r["style"] == s for r in reports),
            "minutes": sum(r["motion_s"] for r in reports if r["style"] == s) / 60.0,
            "frames": sum(r["frames"] for r in reports if r["style"] == s),
        }
        for s in STYLES
    }
    held = [r for r in reports if r["held_frames"]]
    runs = [(run["length"], r["name"], run["first"]) for r in reports for run in r["held_runs"]]
    longest = max(runs, key=lambda x: x[0]) if runs else None
    return {
        "root": str(root),
        "dances": reports,
        "per_style": per_style,
        "total": {
            "dances": len(reports),
            "frames": sum(r["frames"] for r in reports),
            "minutes": sum(r["motion_s"] for r in reports) / 60.0,
            "frames_at_30fps": int(sum(np.floor(r["motion_s"] * 30 + 1e-9) + 1 for r in reports)),
        },
        "split": {"train": train, "val": val},
        "suspicious": {
            "held": {
                "dances": len(held),
                "frames": sum(r["held_frames"] for r in reports),
                "runs": sum(len(r["held_runs"]) for r in reports),
                "longest": None if longest is None else {"length": longest[0], "dance": longest[1], "first": longest[2]},
            },
            "teleports": sum(r["teleports"] for r in reports),
            "max_joint_speed_m_s": max(r["max_joint_speed_m_s"] for r in reports),
            "out_of_range_frames": sum(r["out_of_range_frames"] for r in reports),
            "out_of_range_by_bone": {
                b: n for b in BONES if (n := sum(r["out_of_range_by_bone"].get(b, 0) for r in reports))
            },
            "past_audio": [r["name"] for r in reports if r["past_audio"]],
            "alignment_unverified": [r["name"] for r in reports if r["alignment_unverified"]],
            "bones": {
                name: {
                    "median_cm": float(np.median(lengths[:, k])),
                    "spread_5_95_cm": float(np.percentile(lengths[:, k], 95) - np.percentile(lengths[:, k], 5)),
                    "typical_dance_spread_cm": typical[name],
                    "max_dance_spread_cm": max(r["bone_spread_cm"][name] for r in reports),
                    "wide_in": [r["name"] for r in reports if name in r["wide_bones"]],
                }
                for k, name in enumerate(BONES)
            },
        },
    }


# -------------------------------------------------------------------------- output
def flags(r: dict) -> str:
    out = []
    if r["held_frames"]:
        out.append(f"held {r['held_frames']}/{max(x['length'] for x in r['held_runs'])}")
    if r["teleports"]:
        out.append(f"teleport {r['teleports']}")
    if r["out_of_range_frames"]:
        out.append(f"range {r['out_of_range_frames']}")
    if r["wide_bones"]:
        out.append("bones")
    if r["alignment_unverified"]:
        out.append("unverified")
    if r["past_audio"]:
        out.append("past-audio")
    return " ".join(out)


def print_report(rep: dict, file: TextIO | None = None) -> None:
    """The report as a table on ``file`` (None: the current ``sys.stdout``, looked up at the call)."""
    from models.data.dwm import STYLES

    file = sys.stdout if file is None else file
    p = lambda *a: print(*a, file=file)  # noqa: E731
    t = rep["total"]
    p(f"DWM dataset at {rep['root']}: {t['dances']} dances, {t['minutes']:.1f} min of motion, "
      f"{t['frames']} stored frames ({t['frames_at_30fps']} at 30 fps)")
    p("Timing: frame i of N at (S + i*(E-S)/(N-1))/25 s of audio (docs/data.md)\n")
    p(f"{'dance':<11} {'style':<7} {'frames':>6} {'motion s':>8} {'src fps':>7} {'music interval s':>16} "
      f"{'audio s':>7}  {'split':<5}  flags")
    for r in rep["dances"]:
        music = f"{r['music_start_s']:.2f}-{r['music_end_s']:.2f}"
        p(f"{r['name']:<11} {STYLES[r['style']]:<7} {r['frames']:>6} {r['motion_s']:>8.1f} {r['source_fps']:>7.2f} "
          f"{music:>16} {r['audio_s']:>7.1f}  {r['split']:<5}  {flags(r)}")
    p("\nPer style:")
    for style, s in rep["per_style"].items():
        p(f"  {style:<8} {s['dances']:>2} dances  {s['minutes']:5.1f} min  {s['frames']:>6} stored frames")
    p(f"  total    {t['dances']:>2} dances  {t['minutes']:5.1f} min  {t['frames']:>6} stored frames")
    sp = rep["split"]
    p(f"\nSplit: {len(sp['train'])} train, {len(sp['val'])} val: {', '.join(sp['val'])}")
    s = rep["suspicious"]
    h = s["held"]
    p("\nSuspicious frames:")
    if h["longest"]:
        lo = h["longest"]
        p(f"  held poses (exact repeats): {h['frames']} frames in {h['runs']} runs over {h['dances']} dances; "
          f"longest {lo['length']} frames ({lo['dance']} from frame {lo['first']})")
    else:
        p("  held poses (exact repeats): none")
    p(f"  teleports (> {TELEPORT_M_S:g} m/s): {s['teleports']} (fastest joint {s['max_joint_speed_m_s']:.1f} m/s)")
    p(f"  out of range (height outside {FLOOR_M:g}..{CEILING_M:g} m, or a bone outside "
      f"{BONE_OUTLIER[0]:g}-{BONE_OUTLIER[1]:g}x median): {s['out_of_range_frames']} frames")
    p(f"  music interval past the end of the audio: {', '.join(s['past_audio']) or 'none'}")
    p(f"  alignment unverified: {', '.join(s['alignment_unverified']) or 'none'}")
    p("  bone lengths, cm: median, 5-95 % range over all frames; median and widest 5-95 % range of one dance")
    for name, b in s["bones"].items():
        wide = f"  wide in {', '.join(b['wide_in'])}" if b["wide_in"] else ""
        p(f"    {name:<15} {b['median_cm']:6.1f} {b['spread_5_95_cm']:6.1f} {b['typical_dance_spread_cm']:6.1f} "
          f"{b['max_dance_spread_cm']:6.1f}{wide}")


def info_command(args: argparse.Namespace) -> int:
    rep = dataset_report(args.path)
    if args.json:
        json.dump(rep, sys.stdout, indent=1)
        print()
    else:
        print_report(rep)
    return 0
