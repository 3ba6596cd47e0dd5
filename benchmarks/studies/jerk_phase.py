"""Is a model's jerk periodic with its pooling levels? Mean joint acceleration by frame phase.

Generates a song with a checkpoint (as ``performer generate`` does), takes the mean
|second difference| of the FK joint positions per frame, and prints, for each period P,
max/median of its average over frames with the same phase t mod P. A value well above
that of unrelated periods means the jerk comes from something that repeats every P
frames (the causal U-Net's level L updates every 2**L frames)::

    .venv/bin/python benchmarks/studies/jerk_phase.py ../shared/data/dwm/DANCE_R_5/audio.mp3 --checkpoint models/assets/default.pt
"""

from __future__ import annotations

import argparse

import numpy as np


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("audio")
    p.add_argument("--checkpoint", default=None, help="default: the packaged checkpoint")
    p.add_argument("--periods", type=int, nargs="+", default=[8, 16, 32, 64, 15, 17, 24])
    a = p.parse_args(argv)
    import torch

    from models.evaluation.evaluate import positions
    from models.features.audio_io import load_audio
    from models.features.spectral import extract_features
    from models.generate import load_model, run_model

    torch.set_num_threads(1)
    lm = load_model(a.checkpoint)
    audio = load_audio(a.audio)[0]
    pos = positions(run_model(lm.model, extract_features(audio, lm.features), audio=audio))  # (T, J, 3) m
    acc = np.linalg.norm(np.diff(pos, n=2, axis=0), axis=-1).mean(axis=1)
    print(f"{lm.name} ({lm.path.name}), {len(pos)} frames: max/median of mean |acceleration| by frame phase")
    for per in a.periods:
        n = len(acc) - len(acc) % per
        phase = acc[:n].reshape(-1, per).mean(axis=0)
        print(f"  period {per:3d}: {phase.max() / np.median(phase):.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
