"""The ``gcn`` model changes style mid-song when its music classifier's output changes.

Builds one audio file from two songs of different styles (by default the middle
``--seconds`` of the validation songs DANCE_R_5, Rumba, and DANCE_W_22, Waltz: the
classifier never heard them in training; it takes the one validation Cha-cha song,
DANCE_C_2, for Rumba, docs/gcn.md), generates the dance for it exactly as
``performer generate`` does (and writes the WAV, so the same can be done with the
CLI), and plots over time:

1. the music style classifier's probabilities per 2.13 s window (thin) and after
   the 3-window average that decides the style (thick), with the decided style;
2. a motion measure: the mean joint speed (m/s, FK on the default skeleton,
   1 s moving average) and the hip height (m);

with the seam of the two songs marked. Writes ``--png`` (default
docs/img/gcn_style_change.png) and prints when the decided style switched.

    .venv/bin/python benchmarks/studies/gcn_style_change.py --checkpoint models/assets/gcn.pt --data ../shared/data/dwm
    .venv/bin/performer generate out/gcn_style_change.wav --out out/gcn_style_change.npz --checkpoint models/assets/gcn.pt
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--checkpoint", default=str(REPO / "models" / "assets" / "gcn.pt"), help="a gcn checkpoint (default: the shipped models/assets/gcn.pt)")
    p.add_argument("--data", default="../shared/data/dwm", help="the DWM dataset directory")
    p.add_argument("--songs", nargs=2, default=["DANCE_R_5", "DANCE_W_22"], metavar="DANCE",
                   help="two dances of different styles (default: validation songs DANCE_R_5 DANCE_W_22)")
    p.add_argument("--seconds", type=float, default=30.0, help="seconds taken from the middle of each song")
    p.add_argument("--wav", default="out/gcn_style_change.wav", help="where the joined audio is written")
    p.add_argument("--out", default="out/gcn_style_change.npz", help="generated motion (.npz or .bvh)")
    p.add_argument("--png", default="docs/img/gcn_style_change.png", help="the plot")
    args = p.parse_args(argv)

    import soundfile as sf
    import torch

    from models.data.dwm import STYLES, load_dance
    from models.evaluation.evaluate import positions
    from models.features.audio_io import load_audio
    from models.generate import generate, load_model
    from models.networks.gcn import GCNDancer
    from models.networks.streaming import torch_threads
    from models.timebase import FPS, HOP, SAMPLE_RATE

    loaded = load_model(args.checkpoint)
    if not isinstance(loaded.model, GCNDancer):
        raise SystemExit(f"{args.checkpoint}: not a gcn checkpoint ({loaded.name})")
    dances = [load_dance(Path(args.data) / s) for s in args.songs]
    if dances[0].style == dances[1].style:
        raise SystemExit(f"{args.songs} have the same style {dances[0].style}; pick two styles")
    parts = []
    for d in dances:
        a, _ = load_audio(d.audio_path, SAMPLE_RATE)
        n = int(args.seconds * SAMPLE_RATE)
        mid = max(0, len(a) // 2 - n // 2)
        parts.append(a[mid : mid + n])
    seam_s = len(parts[0]) / SAMPLE_RATE
    song = np.concatenate(parts)
    Path(args.wav).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    sf.write(args.wav, song, SAMPLE_RATE, subtype="FLOAT")

    with torch_threads(1):
        g = generate(args.wav, args.out, loaded)  # what `performer generate` does
        track = loaded.model.style_track(song, g.num_frames)
    styles = track.styles
    step_s = 16 / FPS
    switches = [(i * step_s, styles[track.steps[i - 1]], styles[track.steps[i]])
                for i in range(1, len(track.steps)) if track.steps[i] != track.steps[i - 1]]
    print(f"{args.wav}: {args.songs[0]} ({dances[0].style}) then {args.songs[1]} ({dances[1].style}), "
          f"seam at {seam_s:.1f} s; {g.num_frames} frames, real-time factor {g.realtime_factor:.1f}x")
    print("decided style switches: " + (", ".join(f"{a}->{b} at {t:.1f} s" for t, a, b in switches) or "none"))

    pos = positions(g.poses)  # (T, 30, 3) m
    speed = np.linalg.norm(np.gradient(pos, axis=0), axis=-1).mean(axis=1) * FPS
    k = np.ones(FPS) / FPS
    speed_s = np.convolve(np.pad(speed, (FPS // 2, FPS - 1 - FPS // 2), mode="edge"), k, mode="valid")
    t = (np.arange(g.num_frames) + 1) * HOP / SAMPLE_RATE
    before, after = t < seam_s, t >= seam_s
    print(f"mean joint speed: {speed[before].mean():.3f} m/s before the seam, {speed[after].mean():.3f} m/s after")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colors = {"C": "tab:red", "R": "tab:green", "W": "tab:blue"}
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(11, 6), sharex=True, gridspec_kw={"height_ratios": [3, 2]})
    for i, s in enumerate(styles):
        c = colors.get(s, None)
        ax1.plot(track.chunk_time_s, track.chunk_probs[:, i], color=c, alpha=0.35, lw=1)
        ax1.plot(track.chunk_time_s, track.smooth_probs[:, i], color=c, lw=2.2, label=f"{s} ({STYLES.get(s, s)})")
    for i, s in enumerate(track.steps):  # the decided style of every latent step
        ax1.axvspan(i * step_s, (i + 1) * step_s, ymin=0.0, ymax=0.05, color=colors.get(styles[s], "grey"), lw=0)
    ax1.set_ylabel("classifier probability")
    ax1.set_ylim(0, 1.02)
    ax1.set_title(f"gcn: {args.songs[0]} ({STYLES[dances[0].style]}) joined to {args.songs[1]} "
                  f"({STYLES[dances[1].style]}); bar at the bottom = style fed to the generator")
    ax1.legend(loc="center left", fontsize=8)
    ax2.plot(t, speed_s, color="black", lw=1.5, label="mean joint speed (1 s average)")
    ax2.set_ylabel("m/s")
    ax3 = ax2.twinx()
    ax3.plot(t, g.poses[:, 1], color="tab:purple", lw=1, alpha=0.7, label="hip height")
    ax3.set_ylabel("hip height (m)", color="tab:purple")
    ax2.set_xlabel("audio time (s)")
    for ax in (ax1, ax2):
        ax.axvline(seam_s, color="grey", ls="--", lw=1)
    ax2.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    Path(args.png).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.png, dpi=90)
    print(f"wrote {args.png}, {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
