"""``performer generate``: motion for a whole audio file, written as BVH or NPZ."""

from __future__ import annotations

import argparse

DESCRIPTION = """\
Generate the performer's motion for a whole audio file, offline, and write it as BVH
(default skeleton, centimetres, 30 fps) or NPZ (motion archive with the audio time of
every frame), chosen by the suffix of --out.

A causal model runs exactly as the real-time engine streams it (--window/--hop
crossfaded windows); offline models (unet_gan, unet_plain, lstm, gcn) run once over
the whole song (gcn: its style classifier listens to the file, docs/gcn.md). Pose t belongs to the audio up to (t + 1) / 30 s; a file of D seconds
gives floor(D * 30) frames. Any audio of at least one frame (33 ms) is generated.
"""

EPILOG = """\
examples:
  performer generate song.mp3 --out song.bvh
  performer generate song.wav --out song.npz --checkpoint runs/causal/best.pt
  performer generate song.wav --out song.bvh --library my.npz --style hiphop
"""


def register(subparsers: argparse._SubParsersAction) -> None:
    from realtime.commands.library import add_play_options

    p = subparsers.add_parser("generate", help="generate motion for an audio file (BVH/NPZ)",
                              description=DESCRIPTION, epilog=EPILOG,
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("audio", metavar="AUDIO", help="audio file (WAV, FLAC, OGG, MP3, ...)")
    p.add_argument("--out", required=True, metavar="FILE.bvh|FILE.npz", help="output motion file")
    p.add_argument("--checkpoint", metavar="CKPT", help="model checkpoint (default: the packaged models/assets/default.pt)")
    p.add_argument("--window", type=int, default=128, help="causal model: window length in frames (default 128)")
    p.add_argument("--hop", type=int, default=64, help="causal model: hop between windows in frames, a multiple of 16 (default 64)")
    add_play_options(p)  # --style, --library, --mix (realtime/commands/library.py)
    p.add_argument("--energy", type=float, default=1.0, metavar="E",
                   help="dance_vq models: how lively, 0 (calmest) .. 2 (liveliest); default 1: as the music asks "
                        "(docs/show.md, \"Energy\")")
    p.add_argument("--lead", type=float, default=0.0, metavar="MS",
                   help="dance_vq models: the pose written for audio time t is the one taken at t + MS, "
                        "0..200 ms, for a display chain's delay (default 0; docs/show.md, \"Lead\")")
    p.add_argument("--stage", metavar="WxD",
                   help="dance_vq models: travel and turn inside a stage of W x D metres centred on the origin, "
                        "or 0: dance in place facing +Z (default 3x2; docs/stage.md)")
    p.add_argument("--facing", default="free", metavar="free|audience",
                   help="dance_vq models: free turns as the dancers did; audience dances the turns but comes "
                        "back to face +Z (default free; docs/stage.md)")
    p.add_argument("--seed", type=int, default=0, metavar="N",
                   help="seed of a stochastic model's random choices (default 0)")
    p.add_argument("--threads", type=int, default=1, metavar="N",
                   help="torch intra-op threads (default 1: far faster than 2 when the cores are busy; "
                        "see docs/training.md)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from models.generate import check_output_path, generate, load_model

    from models.errors import ConfigError
    from models.networks.streaming import torch_threads

    if args.threads < 1:
        raise ConfigError(f"--threads must be >= 1, got {args.threads}")
    from models.networks.stage import DEFAULT_STAGE, check_facing, parse_stage

    check_output_path(args.out)  # fail before loading anything
    stage = parse_stage(args.stage) if args.stage is not None else None
    check_facing(args.facing)
    args.style = args.style or "auto"
    if args.style not in ("auto", "chacha", "rumba", "waltz") and args.library is None:
        raise ConfigError(f"--style {args.style}: choose auto, chacha, rumba or waltz (or a folder of --library)")
    from models.generate import with_library

    loaded = with_library(load_model(args.checkpoint), args.library, bool(args.mix))
    if stage is None:  # the default: a small stage for the dancing models, in place for the others
        stage = DEFAULT_STAGE if getattr(loaded.model, "takes_style", False) else 0
    with torch_threads(args.threads):
        g = generate(args.audio, args.out, loaded, window=args.window, hop=args.hop, seed=args.seed,
                     style=None if args.style == "auto" else args.style, energy=args.energy, lead=args.lead,
                     stage=stage, facing=args.facing)
    t = g.timings
    print(f"{args.out}: {g.num_frames} frames ({g.num_frames / 30:.2f} s at 30 fps) from {g.audio_s:.2f} s of audio, "
          f"model {loaded.name} ({loaded.path})")
    print(f"compute {g.compute_s:.2f} s (decode {t['decode']:.2f}, features {t['features']:.2f}, "
          f"model {t['model']:.2f}, export {t['export']:.2f}); real-time factor {g.realtime_factor:.1f}x")
    return 0
