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
and the chance rate of each (``models.evaluation.beats``).
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


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", required=True, help="the DWM dataset directory")
    p.add_argument("--checkpoint", nargs="*", default=["models/assets/default.pt"],
                   help="checkpoints to score beside the real dances (default: the shipped one)")
    p.add_argument("--cache", default=".cache/corpus", help="corpus cache (as performer evaluate)")
    a = p.parse_args(argv)
    import torch

    from models.evaluation.evaluate import (EvalOptions, _audio_kw, clip_music_beats, load_clips, pooled_beats,
                                            positions, split_dances)
    from models.generate import load_model, run_model

    torch.set_num_threads(1)
    opts = EvalOptions(cache_dir=Path(a.cache), progress=False)
    _, val_names = split_dances(a.data, opts)
    models = [load_model(c) for c in a.checkpoint]
    rows: list[tuple[str, list[np.ndarray], list]] = []
    clips = None
    for lm in models:
        clips = load_clips(a.data, val_names, lm.features, opts)
        with torch.no_grad():
            gen = [positions(run_model(lm.model, c.features, opts.window, opts.hop, **_audio_kw(lm.model, a.data, c)))
                   for c in clips]
        rows.append((f"{lm.name} ({lm.path.name})", gen, clips))
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
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
