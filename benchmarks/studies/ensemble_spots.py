"""An ensemble on one stage, measured (issue 39): does each performer stay inside its own spot
(models/networks/stage.py, ensemble_spots) and never come near another, and does it still travel?

For every shared music recording (its first ``--seconds``), ``n`` performers (seeds 0..n-1, as
``performer run --performer a,seed=0 --performer b,seed=1 ...``) dance the song's features on
one stage, each on its spot; the baseline in the same run is the same performers each on the
whole stage (no spots: what the ensemble did before, had it travelled). Per song, stage and n:

* inside: the share of frames whose root lies inside the performer's own spot (1-mm
  tolerance), the lowest of the n performers;
* min distance: the least distance between two performers' roots (x, z) over the song, m, and
  close: the share of frames where some two are nearer than MIN_SEPARATION (0.6 m);
* path / min: metres a performer's root covers a minute (after a 0.1-s low-pass, as
  stage_travel.py counts it), the mean of the n; beside it one performer alone on the whole stage.

Prints one line per setting (the worst song's inside and distance, the mean path)::

    .venv/bin/python benchmarks/studies/ensemble_spots.py --music ../shared/data/music \\
        --seconds 180 --json runs/ensemble_spots.json

Exit status 2 on a missing or unreadable checkpoint or recording.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

#: (stage, performers) danced, in table order.
SETTINGS: tuple[tuple[str, int], ...] = (("3x2", 2), ("3x2", 4), ("6x5", 4))


def roots(model, features: np.ndarray, stage: str, n: int, spots: bool) -> np.ndarray:
    """(n, T, 2) root x, z of n performers (seeds 0..n-1) on ``stage``, each on its spot or not."""
    from models.networks.dance_stream import DanceStream

    return np.stack([DanceStream(model, seed=i, stage=stage, spot=(i, n) if spots else None).push(features)[:, [0, 2]]
                     for i in range(n)]).astype(np.float64)


def figures(r: np.ndarray, stage: str, spots: bool) -> dict:
    """inside (lowest share of the n), min distance (m), close (share), mean path / min (m) of roots (n, T, 2)."""
    from scipy.ndimage import gaussian_filter1d

    from models.networks.stage import ensemble_spots, parse_stage
    from models.timebase import FPS

    n, t = r.shape[:2]
    if spots:
        boxes = ensemble_spots(stage, n)
    else:
        w, d = parse_stage(stage)
        boxes = [(0.0, 0.0, w, d)] * n
    inside = min(float(((np.abs(ri[:, 0] - cx) <= w / 2 + 1e-3) & (np.abs(ri[:, 1] - cz) <= d / 2 + 1e-3)).mean())
                 for ri, (cx, cz, w, d) in zip(r, boxes))
    from models.networks.stage import MIN_SEPARATION

    dist = [np.linalg.norm(a - b, axis=1) for a, b in itertools.combinations(r, 2)]
    apart = min((float(d_.min()) for d_ in dist), default=np.inf)
    close = float(np.any(np.stack(dist) < MIN_SEPARATION, axis=0).mean()) if dist else 0.0
    sm = gaussian_filter1d(r, 3.0, axis=1, mode="nearest")
    path = float(np.linalg.norm(np.diff(sm, axis=1), axis=2).sum(axis=1).mean()) / (t / FPS / 60.0)
    return {"inside": inside, "min_distance": apart, "close": close, "path_per_min": path}


def run(checkpoint: str | None, music: str, seconds: float, log=print) -> dict:
    """{song: {"STAGE n": {"spots": figures, "shared": figures, "alone": figures}}}."""
    from models.features.audio_io import load_audio
    from models.features.spectral import extract_features
    from models.generate import load_model
    from models.networks.streaming import sanitize_features
    from models.timebase import FPS, SAMPLE_RATE

    lm = load_model(checkpoint)
    out: dict = {}
    for f in sorted(Path(music).iterdir()):
        if f.suffix.lower() not in (".ogg", ".mp3", ".wav", ".flac"):
            continue
        log(f"  {f.name}")
        audio = load_audio(f, SAMPLE_RATE)[0][: int(seconds * SAMPLE_RATE)]
        x, _ = sanitize_features(np.asarray(extract_features(audio, lm.features)))
        x = x[: int(seconds * FPS)]
        res = {}
        for stage, n in SETTINGS:
            res[f"{stage} {n}"] = {"spots": figures(roots(lm.model, x, stage, n, True), stage, True),
                                   "shared": figures(roots(lm.model, x, stage, n, False), stage, False),
                                   "alone": figures(roots(lm.model, x, stage, 1, False), stage, False)}
        out[f.name] = res
    return out


def table(results: dict) -> str:
    lines = ["setting | spots: inside (worst song) | min distance m (worst song) | path/min m | "
             "no spots: frames nearer than 0.6 m (mean) | alone: path/min m"]
    for stage, n in SETTINGS:
        key = f"{stage} {n}"
        rows = [r[key] for r in results.values()]
        lines.append(f"{key} | {100 * min(r['spots']['inside'] for r in rows):.1f} % | "
                     f"{min(r['spots']['min_distance'] for r in rows):.3f} | "
                     f"{np.mean([r['spots']['path_per_min'] for r in rows]):.1f} | "
                     f"{100 * np.mean([r['shared']['close'] for r in rows]):.1f} % | "
                     f"{np.mean([r['alone']['path_per_min'] for r in rows]):.1f}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--checkpoint", help="checkpoint (default: the shipped models/assets/default.pt)")
    p.add_argument("--music", metavar="DIR", help="dance every recording in this directory (required)")
    p.add_argument("--seconds", type=float, default=180.0, help="seconds of each recording danced (default 180)")
    p.add_argument("--json", metavar="FILE", help="also write the figures per song as JSON")
    p.add_argument("--table-from", metavar="FILE", help="print the table of an earlier --json instead of dancing")
    a = p.parse_args(argv)
    from models.errors import PerformerError

    if a.table_from:
        print(table(json.loads(Path(a.table_from).read_text())))
        return 0

    if not a.music or not Path(a.music).is_dir():
        print(f"ensemble_spots: no such directory: {a.music}", file=sys.stderr)
        return 2
    try:
        results = run(a.checkpoint, a.music, a.seconds, log=lambda m: print(m, file=sys.stderr))
    except PerformerError as exc:
        print(f"ensemble_spots: {exc}", file=sys.stderr)
        return 2
    print(table(results))
    if a.json:
        Path(a.json).parent.mkdir(parents=True, exist_ok=True)
        Path(a.json).write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
