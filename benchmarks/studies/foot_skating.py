"""Feet on the floor (issue 39): LODGE's foot-skating ratio of the performer and the dancers.

For the validation dances (``models.data.split.VAL_DANCES``, or ``--dances``) prints
:func:`models.evaluation.foot_skating.foot_skating` per dance and pooled, for

- ``performer``: the checkpoint's live stream run on the song's features
  (:func:`models.networks.dance_stream.generate`, seed ``--seed``), as it comes out (in
  place, or with ``--stage WxD`` travelling on that stage, ``--facing`` free or audience);
  ``--no-feet`` runs it with the feet step switched off, ``--in-place MODE`` sets what the
  feet step does in place (``dance_stream.FEET_IN_PLACE``: off, floor, hold);
- ``dancers in place``: the dancers' own motion as the corpus keeps it (canonical: root
  x/z zeroed, heading removed; the tempo-1 clip on the 30 fps grid);
- ``dancers travelling``: the same motion with its root position and heading
  (``--travel``; retargeted from the mocap the same way, not canonicalised).

The performer's motion against the dancers in place: band amplitude, jitter and jerk as
``performer evaluate`` computes them; ``jitter_mirrored``: the jitter of every sequence (the
performer's and the dancers') followed by itself backwards (:func:`mirrored`), which leaves out
the step an FFT sees where a sequence's end wraps round to its start; ``jitter_canonical``: the
performer's poses canonicalised first (``models.data.canonical``: root x, z and the Hips'
heading taken out, as the dancers in place are).

``--plot PNG`` draws one foot of one dance (``--plot-dance``, 8 s from ``--plot-start``) with the
feet step and without, in place and on the ``--stage`` (default 6x5): its path seen from
above and its speed, contact frames marked::

    .venv/bin/python benchmarks/studies/foot_skating.py --data ../shared/data/dwm --travel
    .venv/bin/python benchmarks/studies/foot_skating.py --data ../shared/data/dwm --stage 6x5
    .venv/bin/python benchmarks/studies/foot_skating.py --data ../shared/data/dwm --plot docs/img/feet_paths.png --in-place hold

Exit status 2 on a missing or unreadable checkpoint or dataset.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

COLUMNS = ("fsr", "contact_speed", "contact_share", "below_floor_cm", "below_1cm_frames", "knee_min_deg",
           "knee_past_straight")


def travelling_poses(data_root: str | Path, name: str, frames: int, first: int) -> np.ndarray:
    """(frames, 87) poses of dance ``name`` on the corpus clip's 30 fps grid (clip frame t is
    song frame ``first + t``), retargeted like the corpus but keeping the root's travel and heading."""
    from scipy.interpolate import CubicSpline

    from models.data.alignment import motion_timestamps
    from models.data.dwm import load_dance
    from models.features.spectral import frame_time_s
    from models.rig.retarget import retarget
    from models.rig.skeleton import load_default_skeleton

    dance = load_dance(Path(data_root) / name)
    ts = motion_timestamps(dance)
    t = frame_time_s(np.arange(first, first + frames))
    pos = CubicSpline(ts, dance.world_positions_m(), axis=0)(np.clip(t, ts[0], ts[-1]))
    return retarget(pos, load_default_skeleton(), source=name).to_vector()


def rows_for(data_root: str, checkpoint: str, dances: list[str] | None, seed: int, travel: bool,
             feet: bool, cache: str | None, stage: str | None = None,
             facing: str | None = None) -> tuple[dict[str, dict[str, dict]], dict[str, dict[str, float]]]:
    """({row label: {dance: foot_skating dict}}, {row label: motion against the dancers in place:
    band_amp, jitter (:func:`models.evaluation.metrics.band_ratios`), jerk ratio})."""
    import torch

    from models.evaluation.evaluate import EvalOptions, load_clips, positions, validation_names
    from models.evaluation.foot_skating import foot_skating
    from models.data.canonical import canonicalize
    from models.evaluation.metrics import band_ratios, jerk
    from models.generate import load_model
    from models.networks import dance_stream
    from models.rig.motion import Motion

    lm = load_model(checkpoint)
    opts = EvalOptions(cache_dir=cache, progress=False)
    names = validation_names(data_root, dances, opts)
    clips = load_clips(data_root, names, lm.features, opts)
    label = "performer" + (f" on {stage}" if stage else "") + ("" if feet else " (feet off)")
    where = {k: v for k, v in (("stage", stage), ("facing", facing)) if v is not None}
    out: dict[str, dict[str, dict]] = {label: {}, "dancers in place": {}}
    pos: dict[str, list] = {label: [], "dancers in place": []}
    canon: list[np.ndarray] = []  # the performer canonicalised as the dancers in place are
    if travel:
        out["dancers travelling"] = {}
    for clip in clips:
        with torch.no_grad():
            poses = dance_stream.DanceStream(lm.model, seed=seed, feet=feet, **where).push(clip.features)
        canon.append(positions(canonicalize(Motion.from_vector(poses)).to_vector()))
        for row, p in ((label, poses), ("dancers in place", clip.poses)):
            pos[row].append(positions(p))
            out[row][clip.name] = foot_skating(p, pos[row][-1])
        if travel:
            world = travelling_poses(data_root, clip.name, clip.num_frames, clip.first_frame)
            out["dancers travelling"][clip.name] = foot_skating(world)
    real = pos["dancers in place"]
    bands = band_ratios(pos[label], real)
    ends = band_ratios(mirrored(pos[label]), mirrored(real), root=None)
    motion = {label: {"band_amp": bands["band_amp"], "jitter": bands["jitter"], "jerk": jerk(pos[label]) / jerk(real),
                      "jitter_mirrored": ends["jitter"], "jitter_canonical": band_ratios(canon, real)["jitter"]}}
    return out, motion


def mirrored(pos: list[np.ndarray]) -> list[np.ndarray]:
    """Each sequence (T, J, 3) put in place and followed by itself backwards (2T frames): its FFT then
    sees no step where the end wraps round to the start. ``band_ratios``' jitter (above 6 Hz) counts
    that step's broadband energy: a performer that ends a song turned or standing elsewhere than it
    began (on a stage) gets one the in-place dance does not have."""
    from models.evaluation.metrics import in_place

    return [np.concatenate([in_place(p), in_place(p)[::-1]]) for p in pos]


def plot_foot(data_root: str, checkpoint: str, dance: str, start_s: float, stage: str, seed: int,
              cache: str | None, path: str) -> None:
    """The left foot's heel-toe midpoint of ``dance`` over 8 s from ``start_s``: seen from above and
    its horizontal speed, the performer with the feet step and without, in place and on ``stage``."""
    import torch
    from matplotlib.figure import Figure

    from models.evaluation.evaluate import EvalOptions, load_clips, positions
    from models.evaluation.foot_skating import CONTACT_HEIGHT, FLOOR_PERCENTILE, foot_points
    from models.generate import load_model
    from models.networks import dance_stream
    from models.timebase import FPS

    lm = load_model(checkpoint)
    (clip,) = load_clips(data_root, [dance], lm.features, EvalOptions(cache_dir=cache, progress=False))
    a, b = int(start_s * FPS), int((start_s + 8.0) * FPS)
    fig = Figure(figsize=(11, 7), layout="constrained")
    axs = fig.subplots(2, 2)
    for col, where in enumerate((0, stage)):
        for feet, color in ((False, "C3"), (True, "C0")):
            with torch.no_grad():
                poses = dance_stream.DanceStream(lm.model, seed=seed, feet=feet, stage=where).push(clip.features)
            heel, toe = foot_points(positions(poses))
            low = np.minimum(heel[..., 1], toe[..., 1])
            on = low[a:b, 0] <= np.percentile(low, FLOOR_PERCENTILE) + CONTACT_HEIGHT
            mid = 0.5 * (heel + toe)[a:b, 0]
            speed = np.r_[0.0, np.linalg.norm(np.diff(mid[:, [0, 2]], axis=0), axis=1)] * FPS
            t = np.arange(a, b) / FPS
            label = f"feet step {'on' if feet else 'off'}"
            axs[0, col].plot(mid[:, 0], mid[:, 2], color=color, lw=1, label=label)
            axs[0, col].plot(mid[on, 0], mid[on, 2], ".", color=color, ms=3)
            axs[1, col].plot(t, speed, color=color, lw=1, label=label)
            axs[1, col].fill_between(t, 0, np.where(on, speed, np.nan), color=color, alpha=0.25)
        name = f"in place ({dance_stream.FEET_IN_PLACE})" if where == 0 else f"on a {where} stage"
        axs[0, col].set_title(f"left foot seen from above, {name} (dots: in contact)", fontsize=9)
        axs[0, col].set_aspect("equal")
        axs[0, col].set_xlabel("x (m)")
        axs[0, col].set_ylabel("z (m)")
        axs[1, col].set_title(f"its horizontal speed, m/s, {name} (shaded: in contact, <= 5 cm up)", fontsize=9)
        axs[1, col].set_xlabel(f"time in {dance} (s)")
        for ax in axs[:, col]:
            ax.legend(fontsize=8)
            ax.grid(alpha=0.3)
    fig.suptitle(f"{dance}, {Path(checkpoint).name} (seed {seed}): the left foot's heel-toe midpoint, "
                 f"{start_s:g}-{start_s + 8:g} s, with the feet step and without", fontsize=10)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)


def apply_sets(p: argparse.ArgumentParser, items: list[str]) -> None:
    """``--set feet.NAME=VALUE`` / ``stage.NAME=VALUE``: a constant of models/networks/feet.py or
    stage.py for this run (a script's own process); ``p.error`` on a bad one."""
    from models.networks import feet, stage

    for item in items:
        name, _, value = item.partition("=")
        part, _, const = name.partition(".")
        mod = {"feet": feet, "stage": stage}.get(part)
        if mod is None or not const.isupper() or not hasattr(mod, const) or not value:
            p.error(f"--set wants feet.NAME=VALUE or stage.NAME=VALUE of an existing constant, got {item!r}")
        old = getattr(mod, const)
        try:
            setattr(mod, const, type(old)(float(value)) if not isinstance(old, bool) else value.lower() in ("1", "true"))
        except ValueError:
            p.error(f"--set {name}: not a number: {value!r}")


def study_parser(doc: str) -> argparse.ArgumentParser:
    """A study's parser (description: ``doc`` up to "Exit status") with ``--checkpoint``,
    ``--data``, ``--cache`` and ``--set`` (:func:`apply_sets`)."""
    p = argparse.ArgumentParser(description=doc.split("\nExit status")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--checkpoint", default="models/assets/default.pt", metavar="CKPT",
                   help="the checkpoint (default models/assets/default.pt)")
    p.add_argument("--data", required=True, metavar="DIR", help="the DWM dataset directory (holds DANCE_* dirs)")
    p.add_argument("--cache", default=".cache/corpus", metavar="DIR", help="corpus cache (default .cache/corpus)")
    p.add_argument("--set", action="append", default=[], metavar="PART.NAME=VALUE",
                   help="set a constant of models/networks/feet.py or stage.py for this run, e.g. "
                        "feet.SOFT_REACH=0 or feet.RELEASE_FRAMES=10 (repeatable)")
    return p


def main(argv: list[str] | None = None) -> int:
    p = study_parser(__doc__)
    p.add_argument("--dances", nargs="*", metavar="NAME", help="validation dances to use (default: all six)")
    p.add_argument("--seed", type=int, default=0, help="the stream's seed (default 0)")
    p.add_argument("--travel", action="store_true", help="also the dancers with their travel and heading")
    p.add_argument("--no-feet", action="store_true", help="the performer with its feet step switched off")
    p.add_argument("--stage", default=None, metavar="WxD", help="the performer travels on this stage (default: in place)")
    p.add_argument("--in-place", default=None, choices=("off", "floor", "hold"),
                   help="what the feet step does in place (dance_stream.FEET_IN_PLACE; default: the shipped one)")
    p.add_argument("--facing", default=None, help="with --stage: free or audience (default: the stream's)")
    p.add_argument("--plot", default=None, metavar="PNG", help="draw one foot instead of the tables (see above)")
    p.add_argument("--plot-dance", default="DANCE_W_5", metavar="NAME", help="--plot: the dance (default DANCE_W_5)")
    p.add_argument("--plot-start", type=float, default=40.0, metavar="S", help="--plot: first second (default 40)")
    a = p.parse_args(argv)
    import torch

    from models.errors import PerformerError
    from models.evaluation.foot_skating import pooled

    torch.set_num_threads(1)
    apply_sets(p, a.set)
    if a.in_place is not None:  # a script: the module's setting for this one run
        from models.networks import dance_stream

        dance_stream.FEET_IN_PLACE = a.in_place
    if a.plot:
        try:
            plot_foot(a.data, a.checkpoint, a.plot_dance, a.plot_start, a.stage or "6x5", a.seed, a.cache, a.plot)
        except (PerformerError, OSError) as e:
            print(f"foot_skating.py: {e}", file=sys.stderr)
            return 2
        print(f"wrote {a.plot}")
        return 0
    try:
        rows, motion = rows_for(a.data, a.checkpoint, a.dances, a.seed, a.travel, not a.no_feet, a.cache, a.stage,
                                a.facing)
    except (PerformerError, OSError) as e:
        print(f"foot_skating.py: {e}", file=sys.stderr)
        return 2
    print(f"{'row':<22} {'dance':<11} " + " ".join(f"{c:>18}" for c in COLUMNS))
    for label, per in rows.items():
        for name, r in per.items():
            print(f"{label:<22} {name:<11} " + " ".join(f"{r[c]:>18.3f}" for c in COLUMNS))
        tot = pooled(list(per.values()))
        print(f"{label:<22} {'pooled':<11} " + " ".join(f"{tot[c]:>18.3f}" for c in COLUMNS))
    for label, m in motion.items():
        print(f"{label}, motion against the dancers in place (1 = theirs): " +
              ", ".join(f"{k} {v:.3f}" for k, v in m.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
