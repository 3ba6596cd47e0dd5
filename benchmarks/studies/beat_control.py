"""The beat hit rate beside its control: on the music's beats and on beats shifted by half a beat.

The beat warp slows the performer's motion into every beat the causal tracker expects, and
a slowing (a speed dip, a kinematic beat) near a music beat is what the beat hit rate
counts. So the rate on the beats says the warp does what it is built to do; the same motion
scored against beats moved to the midpoint between each pair of consecutive beats is the
control: a motion locked to the beat scores low there, one independent of it about the same.

For the validation dances (``models.data.split``, the split ``performer evaluate`` uses),
the real dances and each checkpoint generated as ``performer evaluate`` generates it
(``models.generate.run_model``), pooled as in the evaluation's table::

    .venv/bin/python benchmarks/studies/beat_control.py --data ../shared/data/dwm \\
        --checkpoint models/assets/default.pt

Prints one Markdown row per motion: hit rate on the beats, on the half-beat-shifted beats,
and the chance rate of each (``models.evaluation.beats``); then where the speed dips fall:
each dip's signed distance to the nearest music beat (frames, + after it), median, mean of
those within 4 frames, and their histogram. ``--split train --max-frames 1800`` scores the
first minute of every training dance instead (motion never judged: where the dips fall
there is what ``BEAT_DELAY`` in models/networks/dance_stream.py was set from), and
``--beat-delay D ...`` scores the shipped checkpoint at each of those delays::

    .venv/bin/python benchmarks/studies/beat_control.py --data ../shared/data/dwm --split train \
        --max-frames 1800 --beat-delay 0 1
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def half_beats(beats: np.ndarray) -> np.ndarray:
    """Frames halfway between consecutive music beats ``beats`` (sorted frame indices, n >= 2):
    (n - 1,) int, rounded to the nearest frame."""
    b = np.asarray(beats, dtype=np.float64)
    if b.ndim != 1 or len(b) < 2:
        raise ValueError(f"need at least 2 beats to shift by half a beat, got {b.shape}")
    return np.round((b[:-1] + b[1:]) / 2).astype(np.int64)


def dip_offsets(positions: list[np.ndarray], beats: list[np.ndarray]) -> np.ndarray:
    """Signed frames from each kinematic beat (speed dip) of every motion in ``positions``
    (each (T, J, 3) m) to the nearest of its music ``beats`` (sorted frames; + after the beat),
    pooled; motions with fewer than 2 beats are left out."""
    from models.evaluation.beats import kinematic_beats

    out = []
    for pos, b in zip(positions, beats):
        b = np.asarray(b)
        b = b[b < len(pos)]
        if len(b) < 2:
            continue
        k = np.asarray(kinematic_beats(pos), dtype=np.int64)
        if k.size:
            near = b[np.argmin(np.abs(k[:, None] - b[None, :]), axis=1)]
            out.append(k - near)
    return np.concatenate(out) if out else np.zeros(0, np.int64)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", required=True, help="the DWM dataset directory")
    p.add_argument("--checkpoint", nargs="*", default=["models/assets/default.pt"],
                   help="checkpoints to score beside the real dances (default: the shipped one)")
    p.add_argument("--cache", default=".cache/corpus", help="corpus cache (as performer evaluate)")
    p.add_argument("--split", default="val", choices=("val", "train"), help="the dances scored (default val)")
    p.add_argument("--max-frames", type=int, default=None, metavar="N", help="only the first N frames of each dance")
    p.add_argument("--beat-delay", type=float, nargs="+", default=None, metavar="D",
                   help="score the checkpoints at each of these BEAT_DELAY values (frames; default: as shipped)")
    a = p.parse_args(argv)
    import models.networks.player as ds
    import torch

    from models.evaluation.evaluate import (EvalOptions, _audio_kw, clip_music_beats, load_clips, pooled_beats,
                                            positions, split_dances)
    from models.generate import load_model, run_model

    torch.set_num_threads(1)
    opts = EvalOptions(cache_dir=Path(a.cache), progress=False, split=a.split, max_frames=a.max_frames)
    _, val_names = split_dances(a.data, opts)
    models = [load_model(c) for c in a.checkpoint]
    rows: list[tuple[str, list[np.ndarray], list]] = []
    clips = None
    shipped = ds.BEAT_DELAY
    for lm in models:
        clips = load_clips(a.data, val_names, lm.features, opts)
        for delay in a.beat_delay or [shipped]:
            ds.BEAT_DELAY = delay
            try:
                with torch.no_grad():
                    gen = [positions(run_model(lm.model, c.features, opts.window, opts.hop,
                                               **_audio_kw(lm.model, a.data, c))) for c in clips]
            finally:
                ds.BEAT_DELAY = shipped
            label = f"{lm.name} ({lm.path.name})" + (f", BEAT_DELAY {delay:g}" if a.beat_delay else "")
            rows.append((label, gen, clips))
    if clips is None:
        from models.features.spectral import FeatureConfig
        clips = load_clips(a.data, val_names, FeatureConfig(), opts)
    beats = [clip_music_beats(a.data, c) for c in clips]
    shifted = [half_beats(b) for b in beats]
    rows.insert(0, ("real dances", [positions(c.poses) for c in clips], clips))

    print("| motion | beat hit rate on the beats | chance | on beats shifted half a beat | chance |")
    print("| --- | ---: | ---: | ---: | ---: |")
    for label, pos, _ in rows:
        on, off = pooled_beats(pos, beats), pooled_beats(pos, shifted)
        print(f"| {label} | {on['beat_hit_rate']:.3f} | {on['beat_hit_chance']:.3f} | "
              f"{off['beat_hit_rate']:.3f} | {off['beat_hit_chance']:.3f} |")
    print(f"\nWhere the speed dips fall ({len(clips)} {a.split} dances): frames from the nearest music beat, + after it\n")
    print("| motion | dips | median | mean within 4 | -4 | -3 | -2 | -1 | 0 | +1 | +2 | +3 | +4 |")
    print("| --- | ---: | ---: | ---: |" + " ---: |" * 9)
    for label, pos, _ in rows:
        d = dip_offsets(pos, beats)
        near = d[np.abs(d) <= 4]
        hist = np.bincount(near + 4, minlength=9) / max(len(d), 1)
        print(f"| {label} | {len(d)} | {np.median(d) if len(d) else float('nan'):+.1f} | "
              f"{near.mean() if len(near) else float('nan'):+.2f} | " + " | ".join(f"{h:.2f}" for h in hist) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
