"""How a dance_vq checkpoint's playback settings move its motion metrics (docs/training.md).

For each setting ``DRAWS,BEAT_WEIGHT[,TEMPERATURE[,BEAT_WARP]]`` (codes drawn per step, weight
of a speed dip on the expected beat, sampling temperature, depth of the beat warp;
models/networks/dance_stream.py; TEMPERATURE 0 keeps the checkpoint's) and each
seed, generates the 6 validation dances through the live stream and prints the dance-scale
amplitude and jitter ratios (models.evaluation.metrics.band_ratios), the jerk against the
real dances' and the pooled beat hit rate and coverage (the evaluate report's definitions)::

    .venv/bin/python benchmarks/studies/dance_sweep.py --checkpoint models/assets/default.pt \\
        --data ../shared/data/dwm 1,1 2,1 4,2 1,1,0.8

``--members 0`` plays the codebook's decoder instead of the real exemplars (the design
without choreographic memory); ``--style`` dances every song in one style, ``--guidance G``
with ``STYLE_GUIDANCE`` G (1: the style unguided).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

VAL = ("DANCE_C_2", "DANCE_R_5", "DANCE_W_5", "DANCE_W_22", "DANCE_W_28", "DANCE_W_31")


def jerk(pos: list[np.ndarray]) -> float:
    """Mean over dances of the mean joint jerk, m/s^3 (third differences at 30 fps)."""
    return float(np.mean([np.linalg.norm(np.diff(p, 3, axis=0), axis=-1).mean() * 30**3 for p in pos]))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("settings", nargs="*", default=["1,1"], help="DRAWS,BEAT_WEIGHT[,TEMPERATURE[,BEAT_WARP]] (default 1,1)")
    p.add_argument("--checkpoint", default=None, help="a dance_vq checkpoint (default: the packaged one)")
    p.add_argument("--data", required=True, type=Path, help="the DWM dataset directory")
    p.add_argument("--cache", default=".cache/corpus", help="corpus cache (default .cache/corpus)")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1], help="sampling seeds (default 0 1)")
    p.add_argument("--members", type=int, choices=(0,), help="0: play the decoder, not the exemplars")
    p.add_argument("--style", default=None, choices=("auto", "chacha", "rumba", "waltz"),
                   help="dance every song in this style (default: auto, the music decides)")
    p.add_argument("--guidance", type=float, default=None,
                   help="STYLE_GUIDANCE for this run (default: the shipped one; 1: a style without guidance)")
    args = p.parse_args(argv)

    import torch

    import models.networks.chooser as ds
    import models.networks.player as pl
    from models.errors import PerformerError
    from models.evaluation.evaluate import EvalOptions, clip_music_beats, load_clips, pooled_beats, positions
    from models.evaluation.metrics import band_ratios
    from models.generate import load_model, run_model

    torch.set_num_threads(1)
    try:
        specs = [[float(v) for v in s.split(",")] for s in args.settings]
        if any(len(s) not in (2, 3, 4) or s[0] < 1 for s in specs):
            raise ValueError
    except ValueError:
        print(f"dance_sweep: settings are DRAWS,BEAT_WEIGHT[,TEMPERATURE[,BEAT_WARP]] with DRAWS >= 1, got {args.settings}",
              file=sys.stderr)
        return 2
    try:
        lm = load_model(args.checkpoint)
        if lm.name != "dance_vq":
            raise PerformerError(f"{lm.path} is a {lm.name!r} model, not dance_vq")
        clips = load_clips(args.data, list(VAL), lm.features, EvalOptions(cache_dir=args.cache, progress=False))
    except (PerformerError, OSError) as e:
        print(f"dance_sweep: {e}", file=sys.stderr)
        return 2
    if args.members == 0:
        lm.model.member_count.zero_()
    if args.guidance is not None:  # a script: the module's setting for this one run
        ds.STYLE_GUIDANCE = args.guidance
    real = [positions(c.poses) for c in clips]
    beats = [clip_music_beats(args.data, c) for c in clips]
    rb = pooled_beats(real, beats)
    print(f"real dances: jerk {jerk(real):.1f} m/s^3, beat hit rate {rb['beat_hit_rate']:.4f}, "
          f"coverage {rb['beat_coverage']:.3f}, chance {rb['beat_hit_chance']:.4f}")
    if args.style not in (None, "auto"):  # the yardstick for a style: its own dancers against the validation dances
        from models.data.dwm import dance_dirs
        from models.networks.dance_vq import STYLE_TOKEN

        letter = next(k for k, v in STYLE_TOKEN.items() if len(k) == 1 and v == STYLE_TOKEN[args.style])
        own = [d.name for d in dance_dirs(args.data) if d.name.startswith(f"DANCE_{letter}_")]
        mine = [positions(c.poses) for c in load_clips(args.data, own, lm.features,
                                                       EvalOptions(cache_dir=args.cache, progress=False))]
        r = band_ratios(mine, real)
        print(f"real {args.style} dances (all {len(mine)} of the dataset) against the validation dances: "
              f"dance amp {r['band_amp']:.3f}, jitter {r['jitter']:.3f}, jerk {jerk(mine) / jerk(real):.2f}x")
    print("| draws | beat weight | temperature | beat warp | seed | dance amp | jitter | jerk / real | beat hit rate "
          "| beat coverage |")
    print("| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    config0 = lm.model.config
    warp0 = pl.BEAT_WARP
    for s in specs:
        ds.DRAWS, ds.BEAT_WEIGHT = int(s[0]), s[1]
        temp = s[2] if len(s) >= 3 and s[2] > 0 else config0.temperature
        pl.BEAT_WARP = s[3] if len(s) == 4 else warp0
        lm.model.config = dataclasses.replace(config0, temperature=temp)
        for seed in args.seeds:
            gen = [positions(run_model(lm.model, c.features, seed=seed, style=args.style)) for c in clips]
            r, b = band_ratios(gen, real), pooled_beats(gen, beats)
            print(f"| {int(s[0])} | {s[1]:g} | {temp:g} | {pl.BEAT_WARP:g} | {seed} | {r['band_amp']:.3f} | {r['jitter']:.3f} | "
                  f"{jerk(gen) / jerk(real):.2f} | {b['beat_hit_rate']:.4f} | {b['beat_coverage']:.3f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
