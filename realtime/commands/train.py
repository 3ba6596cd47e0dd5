"""``performer train``: train a music-to-motion model on the DWM dataset."""

from __future__ import annotations

import argparse

DESCRIPTION = """\
Train a music-to-motion model (default: the causal U-Net generator that the real-time
engine runs) on the DWM dance dataset. Stage 1 fits the rotation and end-effector L1
losses; stage 2 adds the conditional GAN loss of the multi-scale discriminator.

OUT gets last.pt / best.pt (checkpoints usable by every command), log.csv,
losses.png and state.pt. Running the same command again resumes from state.pt.
The training corpus (features + retargeted poses at every tempo factor) is cached
under --cache, so later runs start in seconds.
"""

EPILOG = """\
example (the causal generator with the paper's recipe; every config, and what it trained:
configs/README.md):
  performer train --config configs/default.toml --data /path/to/dwm --out runs/causal
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("train", help="train a model on the DWM dataset",
                              description=DESCRIPTION, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", metavar="FILE.toml", help="training config (default: built-in defaults)")
    p.add_argument("--data", required=True, metavar="DIR", help="the DWM dataset directory (holds DANCE_* dirs)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory (resumed if it holds state.pt)")
    p.add_argument("--model", metavar="NAME", help="override the config's model: causal | unet_gan | unet_plain | lstm | violin | dtm | gcn")
    p.add_argument("--steps", type=int, nargs=2, metavar=("STAGE1", "STAGE2"),
                   help="override the steps of the two stages")
    p.add_argument("--seed", type=int, help="override the config's seed")
    p.add_argument("--cache", metavar="DIR", default=".cache/corpus",
                   help="corpus cache directory (default: .cache/corpus)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from models.training.config import TrainConfig
    from models.training.train import train

    cfg = TrainConfig.from_toml(args.config) if args.config else TrainConfig()
    if args.model:
        cfg.model = args.model
    if args.steps:
        cfg.stage1_steps, cfg.stage2_steps = args.steps
    if args.seed is not None:
        cfg.seed = args.seed
    cfg = TrainConfig.from_dict(cfg.to_dict())
    best = train(cfg, args.data, args.out, cache_dir=args.cache, progress=not args.quiet)
    print(f"best checkpoint: {best}")
    return 0
