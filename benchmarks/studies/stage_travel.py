"""Travel and turns on the stage, measured (issue 39, items 1-2): does the performer cover the
floor and turn as the dancers did, and stay inside the stage it is given?

For every validation dance (``models.data.split``, the split ``performer evaluate`` uses) the
checkpoint dances the whole tempo-1 corpus clip from the song's features (the live stream,
one frame a push), once per stage setting, and the dancer's own root track on the same frames
is read from the DWM skeletons before canonicalisation (the retargeted root, the midpoint of
the hips, which follows the skeletons' ``center``; the Hips' heading):

* path / min: metres the root covers a minute on the floor (x, z), both tracks low-passed by a
  Gaussian of :data:`SMOOTH` frames first, so the mocap's frame noise does not count as travel;
* turns / min: the accumulated heading (sum of its absolute changes over full turns) a minute,
  low-passed the same way;
* inside: the share of frames whose root lies inside the stage (a 1-mm tolerance);
* speed p99.9: the 99.9th percentile of the root's horizontal speed, m/s, frame to frame;
* facing +-45: with ``facing audience``, the share of dancing frames (idle weight 0) whose
  heading lies within 45 degrees of +Z;
* edge: the share of frames within the stage's margin of an edge; bent: the share of those
  whose path the stage bent (heading out, turned in); inward: the share of the movements
  chosen there whose own travel heads inwards (``stage.INWARDS`` prefers them;
  ``--no-inwards`` switches that off: then only the bend keeps it inside).

The shared music recordings (``--music``, no dancer) are danced the same way and give the
performer's figures alone. Prints one table per setting and the ratios to the dancers::

    .venv/bin/python benchmarks/studies/stage_travel.py --data ../shared/data/dwm \\
        --music ../shared/data/music --json runs/stage_travel.json

Exit status 2 on a missing or unreadable checkpoint, dataset or recording.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

#: Gaussian sigma (frames) of the low-pass before path and turns are summed.
SMOOTH: float = 3.0
#: (label, stage, facing) settings danced, in table order.
SETTINGS: tuple[tuple[str, str, str], ...] = (
    ("6x5 free", "6x5", "free"), ("3x2 free", "3x2", "free"), ("1x1 free", "1x1", "free"),
    ("6x5 audience", "6x5", "audience"), ("3x2 audience", "3x2", "audience"),
)


def track_figures(track: np.ndarray, dancing: np.ndarray | None = None, stage: tuple[float, float] | None = None) -> dict:
    """Figures of a root track (T, 3): x, z (m), unwrapped heading (rad) at 30 fps (see the
    module docstring). ``dancing`` (T,) bool: the frames the facing share counts (default all);
    ``stage`` (W, D): the share inside it."""
    from scipy.ndimage import gaussian_filter1d

    from models.timebase import FPS

    minutes = len(track) / FPS / 60.0
    sm = gaussian_filter1d(track, SMOOTH, axis=0, mode="nearest")
    step = np.linalg.norm(np.diff(sm[:, :2], axis=0), axis=1)
    turns = np.abs(np.diff(sm[:, 2])).sum() / (2 * math.pi)
    speed = np.linalg.norm(np.diff(track[:, :2], axis=0), axis=1) * FPS
    off = np.abs((track[:, 2] + math.pi) % (2 * math.pi) - math.pi)
    d = np.ones(len(track), bool) if dancing is None else dancing
    out = {"minutes": minutes, "path_per_min": float(step.sum() / minutes), "turns_per_min": float(turns / minutes),
           "speed_p999": float(np.quantile(speed, 0.999)) if len(speed) else 0.0,
           "facing45": float((off[d] <= math.radians(45.0)).mean()) if d.any() else float("nan"),
           "extent_x": float(np.ptp(track[:, 0])), "extent_z": float(np.ptp(track[:, 1]))}
    if stage is not None:
        w, dd = stage
        inside = (np.abs(track[:, 0]) <= w / 2 + 1e-3) & (np.abs(track[:, 1]) <= dd / 2 + 1e-3)
        out["inside"] = float(inside.mean())
    return out


def pose_track(poses: np.ndarray) -> np.ndarray:
    """(T, 3) x, z, unwrapped Hips heading of poses (T, P)."""
    from scipy.spatial.transform import Rotation

    from models.data.canonical import heading

    h = np.unwrap(heading(Rotation.from_quat(poses[:, 3:7].astype(np.float64))))
    return np.stack([poses[:, 0], poses[:, 2], h], 1).astype(np.float64)


def dance(model, features: np.ndarray, stage: str, facing: str, seed: int = 0,
          counts: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(root track (T, 3), dancing (T,) bool): a fresh stream pushed one frame at a time, as live;
    ``counts``: updated with the stage's edge counts (``Stage.counts``)."""
    from models.networks.dance_stream import DanceStream
    from models.networks.streaming import sanitize_features

    x, _ = sanitize_features(np.asarray(features))
    s = DanceStream(model, seed=seed, stage=stage, facing=facing)
    poses = np.empty((len(x), s.pose_dim), np.float32)
    dancing = np.empty(len(x), bool)
    for t in range(len(x)):
        poses[t] = s.push(x[t: t + 1])[0]
        dancing[t] = s.idle_weight <= 0.0
    if counts is not None:
        for k, v in s.stage.counts.items():
            counts[k] = counts.get(k, 0) + v
    return pose_track(poses), dancing


def dancer_track(data_root: str | Path, name: str, frames: int) -> np.ndarray:
    """The dancer's root track (T, 3) on the tempo-1 clip's frames (models.training.travel_memory)."""
    from models.data.corpus import clip_motion
    from models.data.dwm import load_dance
    from models.training.travel_memory import root_track

    motion, *_ = clip_motion(load_dance(Path(data_root) / name), 10**7, 1.0)
    tr = root_track(motion)[:frames]
    return tr - [tr[0, 0], tr[0, 1], 0.0]


def run(checkpoint: str, data_root: str, music: str | None, cache: str | None, seed: int, log=print) -> dict:
    """{"songs": {name: {setting: figures, "dancer": figures}}, "music": {file: {setting: figures}}}."""
    from models.evaluation.evaluate import EvalOptions, load_clips, validation_names
    from models.features.audio_io import load_audio
    from models.features.spectral import extract_features
    from models.generate import load_model
    from models.networks.stage import parse_stage
    from models.timebase import SAMPLE_RATE

    lm = load_model(checkpoint)
    opts = EvalOptions(cache_dir=cache, progress=False)
    clips = load_clips(data_root, validation_names(data_root, None, opts), lm.features, opts)
    out: dict = {"songs": {}, "music": {}}
    songs = [(c.name, c.features, c.name) for c in clips]
    if music:
        for f in sorted(Path(music).iterdir()):
            if f.suffix.lower() in (".ogg", ".mp3", ".wav", ".flac"):
                songs.append((f.name, None, f))
    for name, feats, src in songs:
        log(f"  {name}")
        if feats is None:
            feats = extract_features(load_audio(src, SAMPLE_RATE)[0], lm.features)
        res = {}
        if not isinstance(src, Path):
            res["dancer"] = track_figures(dancer_track(data_root, name, len(feats)))
        for label, stage, facing in SETTINGS:
            counts: dict = {}
            tr, dancing = dance(lm.model, feats, stage, facing, seed, counts)
            res[label] = {**track_figures(tr, dancing, parse_stage(stage)), **counts}
        out["music" if isinstance(src, Path) else "songs"][name] = res
    return out


def table(results: dict) -> str:
    """The pooled figures (minutes-weighted) per setting, and the ratios to the dancers on the validation songs."""
    lines = []
    for group in ("songs", "music"):
        res = results[group]
        if not res:
            continue
        lines.append(f"{'validation songs' if group == 'songs' else 'shared music'} ({len(res)}):")
        lines.append(f"  {'setting':<14}{'path/min':>9}{'turns/min':>10}{'inside':>8}{'speed p99.9':>12}"
                     f"{'facing45':>9}{'edge':>7}{'bent':>7}{'inward':>8}{'path x':>8}{'turns x':>8}{'speed x':>8}")
        labels = (["dancer"] if group == "songs" else []) + [s[0] for s in SETTINGS]
        for label in labels:
            rows = [r[label] for r in res.values()]
            m = np.array([r["minutes"] for r in rows])
            mean = {k: float(np.average([r.get(k, np.nan) for r in rows], weights=m))
                    for k in ("path_per_min", "turns_per_min", "facing45", "inside")}
            p999 = max(r["speed_p999"] for r in rows)
            ratio = ""
            if group == "songs" and label != "dancer":
                d = [r["dancer"] for r in res.values()]
                dm = {k: float(np.average([x[k] for x in d], weights=m)) for k in ("path_per_min", "turns_per_min")}
                dsp = max(x["speed_p999"] for x in d)
                ratio = (f"{mean['path_per_min'] / dm['path_per_min']:8.2f}{mean['turns_per_min'] / dm['turns_per_min']:8.2f}"
                         f"{p999 / dsp:8.2f}")
            inside = "" if label == "dancer" else f"{100 * mean['inside']:7.1f}%"
            edge = ""
            if label != "dancer":  # frames near an edge, the share of them bent, movements chosen there heading in
                c = {k: sum(r.get(k, 0) for r in rows) for k in ("edge_frames", "steered_frames", "edge_choices",
                                                                 "inward_choices")}
                n = sum(r["minutes"] * 60 * 30 for r in rows)
                edge = (f"{100 * c['edge_frames'] / max(n, 1):6.1f}%{100 * c['steered_frames'] / max(c['edge_frames'], 1):6.1f}%"
                        f"{100 * c['inward_choices'] / max(c['edge_choices'], 1):7.1f}%")
            lines.append(f"  {label:<14}{mean['path_per_min']:9.1f}{mean['turns_per_min']:10.2f}{inside:>8}"
                         f"{p999:12.2f}{100 * mean['facing45']:8.1f}%{edge:>22}{ratio}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    global SETTINGS
    p = argparse.ArgumentParser(description=__doc__.split("\nExit status")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog="Exit status 2 on a missing or unreadable checkpoint, dataset or recording.")
    p.add_argument("--checkpoint", default="models/assets/default.pt", metavar="CKPT",
                   help="a dance_vq checkpoint (default: models/assets/default.pt)")
    p.add_argument("--data", required=True, metavar="DIR", help="the DWM dataset directory (holds DANCE_* dirs)")
    p.add_argument("--music", metavar="DIR", help="also dance every recording in this directory (no dancer)")
    p.add_argument("--cache", default=".cache/corpus", metavar="DIR", help="corpus cache (default .cache/corpus)")
    p.add_argument("--seed", type=int, default=0, help="generation seed (default 0)")
    p.add_argument("--json", metavar="OUT", help="also write every song's figures as JSON")
    p.add_argument("--no-inwards", action="store_true",
                   help="near an edge, choose movements as in the middle (stage.INWARDS off): only the bend")
    p.add_argument("--set", action="append", default=[], metavar="PART.NAME=VALUE",
                   help="set a constant of models/networks/feet.py or stage.py for this run, e.g. "
                        "stage.MARGIN=0.4 or feet.LEASH=0.2 (repeatable)")
    p.add_argument("--settings", nargs="+", metavar="LABEL", choices=[s[0] for s in SETTINGS],
                   help="only these settings (default all: " + ", ".join(s[0] for s in SETTINGS) + ")")
    a = p.parse_args(argv)
    import torch

    from models.errors import PerformerError

    torch.set_num_threads(1)
    if a.settings:
        SETTINGS = tuple(s for s in SETTINGS if s[0] in a.settings)
    if a.set:
        sys.path.insert(0, str(Path(__file__).parent))
        from foot_skating import apply_sets

        apply_sets(p, a.set)
    if a.no_inwards:
        from models.networks import stage

        stage.INWARDS = False
    try:
        results = run(a.checkpoint, a.data, a.music, a.cache, a.seed, log=lambda m: print(m, file=sys.stderr))
    except (PerformerError, OSError) as e:
        print(f"stage_travel.py: {e}", file=sys.stderr)
        return 2
    print(f"Travel and turns on the stage ({a.checkpoint}, seed {a.seed}); minutes-weighted means, "
          f"speed: the largest song's; x: performer over dancers\n")
    print(table(results))
    if a.json:
        Path(a.json).parent.mkdir(parents=True, exist_ok=True)
        Path(a.json).write_text(json.dumps({"checkpoint": a.checkpoint, "seed": a.seed, **results}, indent=1) + "\n",
                                encoding="utf-8")
        print(f"wrote {a.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
