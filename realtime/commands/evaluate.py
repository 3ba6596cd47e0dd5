"""``performer evaluate``: score checkpoints on the validation dances of the DWM dataset."""

from __future__ import annotations

import argparse
import shlex

DESCRIPTION = """\
Generate motion for every validation dance (tempo 1.0) with each checkpoint, the way
the model runs (causal: streamed windows; others: one forward), and score it against
the captured motion after forward kinematics on the default skeleton:

  test loss (rotation L1, position L1, hand L1), DTW, LCSS, PCK@0.1/0.2,
  direction-change F1 and cosine of the hands (±3 frames), beat coverage, beat hit
  rate (and its chance level) against music beats of the same audio span, Fréchet
  distance and diversity in the features of a style classifier trained on the
  training split's real motion, motion-energy ratio, jerk, and the dance-scale
  amplitude (0.25-3 Hz) and jitter (above 6 Hz) ratios of FK positions to the real
  dances' (band RMS, power pooled over dances).

A "real data" row scores the real validation motion itself (FD: real validation vs
real training motion). Writes OUT/results.json, results.md, results.png and
per_dance.json, and prints the table. Metric definitions: docs/metrics.md.

--listening adds, for dance_vq checkpoints, the tempo and presence figures of
models/evaluation/listening.py (docs/metrics.md, "Listening"): the validation songs and
--music recordings between 80 and 130 bpm stretched to 0.8x/1.0x/1.25x (speed, frequency
centroid, kinematic bpm, band amplitude, beat hit rate and its half-beat-shifted control),
a tempo ramp 0.85x-1.2x-0.85x, the idle fraction on every --music recording and speech
between two songs; writes OUT/listening.json and listening.md with PASS/FAIL per target.
"""

EPILOG = """\
examples:
  performer evaluate --checkpoint models/assets/default.pt --data /path/to/dwm --out runs/eval
  performer evaluate --checkpoint runs/causal/best.pt runs/unet_gan/best.pt --data /path/to/dwm
  performer evaluate --checkpoint CKPT --data /path/to/dwm --dances 1 --max-frames 600   # quick look
  performer evaluate --checkpoint models/assets/default.pt --data ../shared/data/dwm --listening
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("evaluate", help="score checkpoints on the validation dances",
                              description=DESCRIPTION, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--checkpoint", required=True, nargs="+", metavar="CKPT", help="one or more model checkpoints")
    p.add_argument("--data", required=True, metavar="DIR", help="the DWM dataset directory (holds DANCE_* dirs)")
    p.add_argument("--split", choices=("val", "train"), default="val", help="dances to score (default: val)")
    p.add_argument("--out", default="runs/eval", metavar="DIR", help="report directory (default: runs/eval)")
    p.add_argument("--cache", default=".cache/corpus", metavar="DIR",
                   help="corpus and style-classifier cache (default: .cache/corpus)")
    p.add_argument("--classifier-epochs", type=int, default=10, metavar="N",
                   help="epochs of the style classifier behind FD and diversity (default 10; trained once, cached)")
    p.add_argument("--dances", type=int, metavar="N", help="at most N dances per style in each split (quick runs)")
    p.add_argument("--max-frames", type=int, metavar="N", help="score only the first N frames of each dance")
    p.add_argument("--window", type=int, default=128, help="causal models: window length in frames (default 128)")
    p.add_argument("--hop", type=int, default=64, help="causal models: hop in frames (default 64)")
    p.add_argument("--threads", type=int, default=1, metavar="N", help="torch intra-op threads (default 1)")
    p.add_argument("--gan-scores", action="store_true",
                   help="also GAN-train / GAN-test accuracies of the style classifier (docs/metrics.md); "
                        "generates every training dance too")
    p.add_argument("--multimodality-samples", type=int, default=5, metavar="K",
                   help="stochastic models (dtm): generations per dance behind the multimodality metric "
                        "(default 5; 0 or 1: off); deterministic models show n/a")
    p.add_argument("--listening", nargs="?", const="full", choices=("full", "quick"),
                   help="also the tempo, beat, ramp and presence figures of dance_vq checkpoints "
                        "(docs/metrics.md; 'quick': 3 songs, short excerpts)")
    p.add_argument("--music", metavar="DIR", help="--listening: music recordings (default: music/ beside --data)")
    p.add_argument("--speech", metavar="DIR", help="--listening: speech recordings (default: speech/ beside --data)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from models.errors import ConfigError
    from models.evaluation.evaluate import EvalOptions, run_evaluation

    from models.networks.streaming import torch_threads

    for name in ("classifier_epochs", "dances", "max_frames", "threads"):
        v = getattr(args, name)
        if v is not None and v < 1:
            raise ConfigError(f"--{name.replace('_', '-')} must be >= 1, got {v}")
    opts = EvalOptions(split=args.split, cache_dir=args.cache, classifier_epochs=args.classifier_epochs,
                       dances_per_style=args.dances, max_frames=args.max_frames, window=args.window,
                       hop=args.hop, progress=not args.quiet, gan_scores=args.gan_scores,
                       multimodality_samples=max(0, args.multimodality_samples))
    with torch_threads(args.threads):
        paths = run_evaluation(args.checkpoint, args.data, args.out, command_line(args), opts)
        if getattr(args, "listening", None):
            paths.update(listening(args))
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    return 0


def listening(args: argparse.Namespace) -> dict:
    """The listening sets (models/evaluation/listening.py) for the dance_vq checkpoints of ``args``;
    writes OUT/listening.json and listening.md, prints PASS/FAIL per target."""
    import json
    from pathlib import Path

    from models.evaluation import listening as L

    shared = Path(args.data).parent
    opts = L.Options(dwm=args.data, music=args.music or shared / "music", speech=args.speech or shared / "speech",
                     cache_dir=Path(args.cache).parent / "listening", quick=args.listening == "quick",
                     progress=not args.quiet)
    result = L.run(args.checkpoint, opts, only_dance_vq=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"listening_json": out / "listening.json", "listening_md": out / "listening.md"}
    paths["listening_json"].write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")
    text = L.markdown(result, command_line(args))
    paths["listening_md"].write_text(text, encoding="utf-8")
    print(text)
    for line in L.verdict_lines(result):
        print(line)
    return paths


def command_line(args: argparse.Namespace) -> str:
    """The full ``performer evaluate`` command line equivalent to ``args`` (for the report)."""
    parts = ["performer", "evaluate", "--checkpoint", *args.checkpoint, "--data", args.data,
             "--split", args.split, "--out", args.out, "--cache", args.cache,
             "--classifier-epochs", str(args.classifier_epochs)]
    for flag, v in (("--dances", args.dances), ("--max-frames", args.max_frames),
                    ("--window", args.window if args.window != 128 else None), ("--hop", args.hop if args.hop != 64 else None)):
        if v is not None:
            parts += [flag, str(v)]
    if getattr(args, "gan_scores", False):
        parts.append("--gan-scores")
    if getattr(args, "multimodality_samples", 5) != 5:
        parts += ["--multimodality-samples", str(args.multimodality_samples)]
    if getattr(args, "listening", None):
        parts += ["--listening"] + (["quick"] if args.listening == "quick" else [])
        for flag, v in (("--music", getattr(args, "music", None)), ("--speech", getattr(args, "speech", None))):
            if v is not None:
                parts += [flag, str(v)]
    return " ".join(shlex.quote(str(p)) for p in parts)
