"""``performer library build CLIPS... --out FILE.npz``: a user's BVH dances onto the rig, in one file.

``performer library info FILE.npz`` lists what a library holds. See docs/library.md.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

BUILD_HELP = """\
Read BVH files (and every .bvh under the folders given), map each skeleton onto the
performer's humanoid rig and write the clips, resampled to 30 fps, to one .npz library.
No audio is needed.

Recognised without a map: Unity humanoid / VRM (leftUpperArm), Mixamo (mixamorig:LeftArm),
CMU (LeftUpLeg, LHipJoint), MotionBuilder / HumanIK (Character1_LeftUpLeg), Bandai-style
(UpperArm_L), Blender (upper_arm.L), DAZ (lShldr), Biovision (LeftHip, LeftKnee) and others
whose names say side and part. Units (m, cm, mm, inches, feet, MMD) are read from the
dancer's leg length, Y or Z up from where the head is, the rest pose (T or A) does not
matter, any frame rate is resampled to 30 fps. Fingers, twist bones and props are ignored.

For every clip it prints the retarget error: the file's own joint positions against the
rig's forward kinematics, in cm at the rig's scale (mean over frames and joints / max).

A file it cannot read or map (truncated, non-finite values, one frame, no legs, names it
does not know) stops the build with one line naming the file and the missing bones, exit
status 2, and nothing is written. A map file names the joints yourself, one per line:

    LeftUpperLeg = thigh_l        # rig name = joint name in the file; '#' starts a comment

Rig names: Spine Chest Neck Head, and Left/Right + UpperArm LowerArm Hand HandTip
UpperLeg LowerLeg Foot Toes. Unmapped ones are still found by name.

Each clip's tempo (what the performer's tempo following plays it against) is read from its
motion when it is danced, unless --bpm gives it: --bpm 120 for every clip, --bpm hiphop=96
for the clips of folder hiphop, --bpm take3=128 for the clip named take3 (repeatable; a
clip's own value wins over its folder's, which wins over a bare number).

Dance a library live or offline: performer run|generate --library FILE.npz [--style FOLDER]
[--mix] (docs/library.md).
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "library", help="build a motion library from your own BVH dances",
        description="Your own dances for the performer: import BVH motion of any humanoid rig. See docs/library.md.",
    )
    sub = p.add_subparsers(dest="library_command", metavar="SUBCOMMAND", required=True)
    build = sub.add_parser(
        "build", help="import BVH files and folders into one library file",
        formatter_class=argparse.RawDescriptionHelpFormatter, description=BUILD_HELP,
    )
    build.add_argument("clips", nargs="+", type=Path, metavar="CLIP",
                       help="a .bvh file, or a folder: every .bvh below it (the folder's name is kept with each clip)")
    build.add_argument("--out", type=Path, required=True, metavar="FILE.npz", help="the library file to write")
    build.add_argument("--map", type=Path, metavar="FILE", help="joint names for rigs the conventions do not cover (see above)")
    build.add_argument("--units", default="auto", metavar="UNIT",
                       help="the files' length unit: auto (default: from the leg length), m, cm, mm, in, ft or mmd")
    build.add_argument("--bpm", action="append", metavar="[NAME=]BPM",
                       help="tempo of the clips (all), of folder NAME or of clip NAME, beats per minute, "
                            "20..300; repeat (default: read from the motion when danced)")
    build.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                       help="show a progress bar on stderr (default: when stderr is a terminal)")
    build.set_defaults(func=build_command)
    info = sub.add_parser("info", help="list the clips of a library and their retarget errors",
                          description="List the clips of a library file: source, folder, length, units, retarget error.")
    info.add_argument("library", type=Path, metavar="FILE.npz")
    info.set_defaults(func=info_command)


def add_play_options(group) -> None:
    """``--style``, ``--library`` and ``--mix`` of ``performer run`` and ``performer generate`` (defaults None)."""
    group.add_argument("--style", metavar="NAME",
                       help="dance this style to any music: auto (default: the style the music suggests), chacha, "
                            "rumba, waltz, or with --library a folder of the library; dance_vq models only "
                            "(performer run, live: /performer/style)")
    group.add_argument("--library", metavar="FILE.npz",
                       help="dance your own motion library (performer library build) instead of the checkpoint's "
                            "memory: its windows play, the music chooses among them; dance_vq models (docs/library.md)")
    group.add_argument("--mix", action=argparse.BooleanOptionalAction, default=None,
                       help="with --library: the checkpoint's dancers and the library together (default: the library "
                            "alone)")


def collect(paths: list[Path]) -> list[Path]:
    """The BVH files named and below the folders named, in order; DataError for a path that is
    missing, a folder without any, or a file that is not .bvh."""
    from models.errors import DataError

    files: list[Path] = []
    for p in paths:
        if p.is_dir():
            found = sorted(f for f in p.rglob("*") if f.is_file() and f.suffix.lower() == ".bvh")
            if not found:
                raise DataError("no .bvh files in this folder", source=p)
            files += found
        elif p.is_file():
            if p.suffix.lower() != ".bvh":
                raise DataError("not a .bvh file", source=p)
            files.append(p)
        else:
            raise DataError("no such file or folder", source=p)
    seen: set[Path] = set()
    return [f for f in files if not (f.resolve() in seen or seen.add(f.resolve()))]


def clip_names(files: list[Path]) -> list[str]:
    """A unique name per file: its stem, or folder/stem where stems repeat, then #2, #3."""
    stems = [f.stem for f in files]
    names = [f"{f.parent.name}/{f.stem}" if stems.count(f.stem) > 1 else f.stem for f in files]
    out: list[str] = []
    for n in names:
        k, name = 1, n
        while name in out:
            k += 1
            name = f"{n}#{k}"
        out.append(name)
    return out


def _table(clips) -> str:
    rows = [f"{'clip':<28} {'folder':<14} {'s':>7} {'src fps':>7} {'units':>5} {'up':>3} {'rest':>6} "
            f"{'mean cm':>7} {'max cm':>7}  worst joint"]
    for c in clips:
        worst = max(c.error_max_cm, key=c.error_max_cm.get)
        rows.append(f"{c.name[:28]:<28} {c.folder[:14]:<14} {c.motion.num_frames / c.motion.fps:7.1f} {c.source_fps:7.1f} "
                    f"{c.units:>5} {c.up:>3} {c.rest_from:>6} {c.mean_error_cm:7.2f} {c.max_error_cm:7.2f}  {worst}"
                    + (" (mirrored: left-handed file)" if c.mirrored else ""))
    return "\n".join(rows)


def _point_table(clips) -> str:
    from models.data.bvh_import import SCORED_POINTS

    rows = [f"{'joint':<16} {'clips':>5} {'mean cm':>8} {'max cm':>7}"]
    for p in SCORED_POINTS:
        have = [c for c in clips if p in c.error_mean_cm]
        if have:
            frames = sum(c.motion.num_frames for c in have)
            mean = sum(c.error_mean_cm[p] * c.motion.num_frames for c in have) / frames
            rows.append(f"{p:<16} {len(have):>5} {mean:8.2f} {max(c.error_max_cm[p] for c in have):7.2f}")
    return "\n".join(rows)


def clip_bpm(specs: list[str], clips) -> list[float]:
    """Per clip its --bpm tempo (0: none given) from ``specs`` ("BPM", "FOLDER=BPM" or "CLIP=BPM");
    ConfigError naming a bad value or a name that is neither a clip nor a folder."""
    from models.errors import ConfigError

    every, by_name = 0.0, {}
    for spec in specs:
        name, sep, value = spec.rpartition("=")
        try:
            bpm = float(value)
        except ValueError:
            bpm = float("nan")
        if not 20.0 <= bpm <= 300.0:  # NaN fails too
            raise ConfigError(f"--bpm {spec}: the tempo must be a number of beats per minute in 20..300")
        if not sep:
            every = bpm
        elif any(name in (c.name, c.folder) for c in clips):
            by_name[name] = bpm
        else:
            raise ConfigError(f"--bpm {spec}: no clip or folder named {name!r} in this build")
    return [by_name.get(c.name, by_name.get(c.folder, every)) for c in clips]


def build_command(args: argparse.Namespace) -> int:
    from models.data.bvh_import import UNITS, import_bvh, read_map
    from models.data.library import save_library
    from models.errors import ConfigError

    t0 = time.perf_counter()
    if args.out.suffix.lower() != ".npz":
        raise ConfigError(f"--out {args.out}: the library is a numpy archive, name it FILE.npz")
    if not args.out.parent.is_dir():
        raise ConfigError(f"--out {args.out}: folder {args.out.parent} does not exist")
    if args.units != "auto" and args.units not in UNITS:
        raise ConfigError(f"--units {args.units}: use auto or one of {', '.join(UNITS)}")
    joint_map = read_map(args.map) if args.map else None
    files = collect(args.clips)
    names = clip_names(files)
    progress = sys.stderr.isatty() if args.progress is None else args.progress
    from tqdm import tqdm

    clips = []
    with tqdm(total=sum(f.stat().st_size for f in files), unit="B", unit_scale=True, desc="importing",
              disable=not progress, file=sys.stderr, leave=False) as bar:
        for f, name in zip(files, names):
            bar.set_postfix_str(f.name[:30], refresh=False)
            clips.append(import_bvh(f, joint_map, units=args.units, name=name, folder=f.parent.name))
            bar.update(f.stat().st_size)
    save_library(args.out, clips, clip_bpm(args.bpm or [], clips))
    seconds = sum(c.motion.num_frames for c in clips) / 30.0
    print(_table(clips))
    print()
    print("retarget error by joint over all clips (mean weighted by frames / max):")
    print(_point_table(clips))
    print()
    print(f"wrote {args.out}: {len(clips)} clip(s), {seconds / 60:.1f} min of motion at 30 fps "
          f"({time.perf_counter() - t0:.1f} s)")
    return 0


def info_command(args: argparse.Namespace) -> int:
    from models.data.library import load_library

    clips = load_library(args.library)
    print(f"{'clip':<28} {'folder':<14} {'s':>7} {'units':>5} {'up':>3} {'mean cm':>7} {'max cm':>7} {'bpm':>5}  source")
    for c in clips:
        bpm = f"{c.bpm:5.0f}" if c.bpm else "    -"  # -: read from the motion when danced
        print(f"{c.name[:28]:<28} {c.folder[:14]:<14} {c.motion.num_frames / c.motion.fps:7.1f} {c.units:>5} {c.up:>3} "
              f"{c.error_mean_cm:7.2f} {c.error_max_cm:7.2f} {bpm}  {c.source}")
    total = sum(c.motion.num_frames for c in clips) / 30.0
    print(f"{len(clips)} clip(s), {total / 60:.1f} min")
    return 0
