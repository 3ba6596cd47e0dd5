"""One movement over and over: runs of one code, the dancers' against the performer's.

The dancing default draws a code (an 8-frame movement) every 8 frames. Its predictor sees
the last 16 codes; once they are all one code it tends to keep drawing it. Each repeat
restarts a movement of that kind near where the last one started, the inertialization
bends the new one back onto the pose the last one reached, and most of the motion cancels:
the performer shuffles in place. ``REPEAT_FREE`` / ``REPEAT_PENALTY`` in
``models/networks/dance_stream.py`` lower a code's logit once it has been drawn 4 times in a
row. This study measures both sides:

* **the dancers:** every training dance's motion encoded with the checkpoint's own encoder
  (8-frame segments from frame 0), runs of one code;
* **the performer:** every recording of the listening benchmark's candidates (the DWM
  validation songs and ``DIR/music``; the first ``--seconds`` of each, live stream, seeds
  ``--seeds``), with the shipped limit and without it (``REPEAT_PENALTY = 0``): runs of one
  code, and the **shuffling share**: the dancing frames (no idle weight over the last 2 s)
  where the pose moves less than half as fast as the movements being played (2-s means of
  the mean joint speed against the playing exemplar's own speed times its playback rate).

::

    nice -n 5 .venv/bin/python benchmarks/studies/repeats.py --data ../shared/data

About two minutes on two cores. Exit status 2 on a missing or unreadable checkpoint, data
directory or training config.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

#: Seconds of the 2-s means behind the shuffling share.
WINDOW_S: float = 2.0
#: A dancing frame "shuffles" when the pose moves less than this share of the played movements' speed.
SHUFFLE_RATIO: float = 0.5
#: Run lengths (movements) the table counts the share of movements in runs of at least.
RUN_LENGTHS: tuple[int, ...] = (4, 8, 12)


def run_lengths(codes) -> np.ndarray:
    """Lengths of the runs of equal consecutive values of ``codes`` (n,), in order."""
    c = np.asarray(codes)
    if c.size == 0:
        return np.zeros(0, np.int64)
    edges = np.flatnonzero(np.diff(c) != 0) + 1
    return np.diff(np.concatenate(([0], edges, [c.size])))


def run_summary(runs: np.ndarray) -> dict:
    """Longest run and, per :data:`RUN_LENGTHS` L, the share of movements in runs of at least L."""
    total = max(int(runs.sum()), 1)
    return {"longest": int(runs.max()) if runs.size else 0, "movements": int(runs.sum()),
            **{f"share_ge_{n}": float(runs[runs >= n].sum() / total) for n in RUN_LENGTHS}}


def dancers_runs(checkpoint, config: str, dwm: str, cache: str) -> np.ndarray:
    """Run lengths of one code over every training dance's motion (the checkpoint's encoder)."""
    import torch

    from models.generate import load_model
    from models.training.config import TrainConfig
    from models.training.dance_vq import training_clips

    lm = load_model(checkpoint)
    m = lm.model.eval()
    _, clips = training_clips(TrainConfig.from_toml(config), lm.features, dwm, cache, progress=False)
    out = []
    with torch.no_grad():
        for clip in clips:
            n = clip.num_frames // m.config.seg
            z = m.encoder(m.standardize_poses(torch.from_numpy(clip.poses[: n * m.config.seg])[None]))
            out.append(run_lengths(m.quantizer.codes(z)[0].numpy()))
    return np.concatenate(out)


def perform(lm, audio: np.ndarray, seed: int) -> dict:
    """The live stream on ``audio`` (n,) at 22050 Hz (``listening.perform``): its codes' run
    lengths and its shuffling frames."""
    from scipy.ndimage import uniform_filter1d

    from models.evaluation import listening as L
    from models.timebase import FPS

    trace: dict = {}
    poses, w = L.perform(lm, audio, seed, trace)
    win = int(WINDOW_S * FPS)
    speed = uniform_filter1d(L.motion_speed(L.positions(poses)), win)
    played = uniform_filter1d(trace["movement_speed"] * trace["rate"], win)  # m/s
    dancing = uniform_filter1d((w <= 0.0).astype(float), win) >= 1.0 - 1e-9
    shuffle = dancing & (speed < SHUFFLE_RATIO * played)
    return {"runs": run_lengths(trace["codes"]), "dancing": int(dancing.sum()), "shuffle": int(shuffle.sum())}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("::")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--checkpoint", default=None, metavar="CKPT", help="a dance_vq checkpoint (default: models/assets/default.pt)")
    p.add_argument("--data", required=True, metavar="DIR", help="the data directory holding dwm/ and music/")
    p.add_argument("--config", default=str(REPO / "configs" / "dance_vq.toml"), metavar="TOML",
                   help="the checkpoint's training config, for the dancers' motion (default configs/dance_vq.toml)")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], metavar="SEED", help="sampling seeds (default 0 1 2)")
    p.add_argument("--seconds", type=float, default=120.0, help="seconds of each recording (default 120)")
    p.add_argument("--cache", default=".cache/corpus", metavar="DIR", help="corpus cache (default .cache/corpus)")
    p.add_argument("--json", metavar="OUT", help="write every figure here")
    a = p.parse_args(argv)

    from tqdm import tqdm

    import models.networks.chooser as ds
    from models.errors import PerformerError
    from models.evaluation import listening as L
    from models.generate import load_model
    from models.networks.dance_vq import DanceVQ
    from models.timebase import SAMPLE_RATE

    data = Path(a.data)
    try:
        lm = load_model(a.checkpoint)
        if not isinstance(lm.model, DanceVQ):
            raise PerformerError(f"{lm.path} is a {lm.name!r} model; repeats are dance_vq's")
        dancers = dancers_runs(a.checkpoint, a.config, str(data / "dwm"), a.cache)
        opts = L.Options(dwm=data / "dwm", music=data / "music", progress=False)
        cache = L.AudioCache(None)
        audio = {L.song_name(r): cache.audio(r)[: int(a.seconds * SAMPLE_RATE)]
                 for r in tqdm(L.candidates(opts), desc="recordings", leave=False)}
    except (PerformerError, OSError) as e:
        print(f"repeats: {e}", file=sys.stderr)
        return 2

    shipped = ds.REPEAT_PENALTY
    variants = {"performer, repeats limited (shipped)": shipped, "performer, no limit": 0.0}
    rows = {"dancers (training motion)": {**run_summary(dancers), "shuffle": None}}
    per_song: dict[str, dict] = {}
    try:
        for label, penalty in variants.items():
            ds.REPEAT_PENALTY = penalty
            runs, dancing, shuffle = [], 0, 0
            for name, y in tqdm(audio.items(), desc=label, leave=False):
                for seed in a.seeds:
                    got = perform(lm, y, seed)
                    runs.append(got["runs"])
                    dancing += got["dancing"]
                    shuffle += got["shuffle"]
                    cell = per_song.setdefault(name, {}).setdefault(label, {"longest": 0, "shuffle": 0, "dancing": 0})
                    cell["longest"] = max(cell["longest"], int(got["runs"].max()) if got["runs"].size else 0)
                    cell["shuffle"] += got["shuffle"]
                    cell["dancing"] += got["dancing"]
            rows[label] = {**run_summary(np.concatenate(runs)), "shuffle": shuffle / max(dancing, 1)}
    finally:
        ds.REPEAT_PENALTY = shipped

    print(f"Runs of one code (8-frame movements), {lm.path}; the performer on {len(audio)} recordings "
          f"(first {a.seconds:g} s), seeds {' '.join(map(str, a.seeds))}\n")
    head = " | ".join(f"in runs >= {n}" for n in RUN_LENGTHS)
    print(f"| | longest run | {head} | shuffling share of the dancing frames |")
    print("| --- | ---: |" + " ---: |" * len(RUN_LENGTHS) + " ---: |")
    for label, r in rows.items():
        shares = " | ".join(f"{100 * r[f'share_ge_{n}']:.1f} %" for n in RUN_LENGTHS)
        sh = "-" if r["shuffle"] is None else f"{100 * r['shuffle']:.1f} %"
        print(f"| {label} | {r['longest']} | {shares} | {sh} |")
    print("\nRecording by recording (longest run over the seeds; shuffling share), limited / no limit:\n")
    print("| recording | longest run | shuffling |")
    print("| --- | ---: | ---: |")
    labels = list(variants)
    for name, cells in per_song.items():
        lim, off = (cells[k] for k in labels)
        share = lambda c: 100 * c["shuffle"] / max(c["dancing"], 1)  # noqa: E731
        print(f"| {name} | {lim['longest']} / {off['longest']} | {share(lim):.1f} / {share(off):.1f} % |")
    if a.json:
        Path(a.json).parent.mkdir(parents=True, exist_ok=True)
        Path(a.json).write_text(json.dumps({"checkpoint": str(lm.path), "seeds": a.seeds, "seconds": a.seconds,
                                            "rows": rows, "per_song": per_song}, indent=1))
        print(f"wrote {a.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
