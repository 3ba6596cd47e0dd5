"""How the ``gcn`` model's output smoothing trades motion energy against jerk (docs/gcn.md).

Generates the first ``--seconds`` of every validation dance with a gcn checkpoint, once
per spline knot spacing (``--knots``; 0 = the generator's raw output, 4 = the default),
with the style its music classifier decides and, with ``--true-style``, also with the
dance's real style, then prints the energy ratio (velocity spread generated / real, →1)
and the jerk (m/s³) of each setting next to the real dances' jerk. Same definitions as
``performer evaluate`` (docs/metrics.md)::

    .venv/bin/python benchmarks/studies/gcn_smoothing.py --data ../shared/data/dwm --true-style
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--checkpoint", default=str(REPO / "models" / "assets" / "gcn.pt"),
                   help="a gcn checkpoint (default: the shipped models/assets/gcn.pt)")
    p.add_argument("--data", required=True, help="the DWM dataset directory")
    p.add_argument("--seconds", type=float, default=60.0, help="seconds from the start of each dance (default 60)")
    p.add_argument("--knots", type=int, nargs="+", default=[0, 4, 8], help="spline knot spacings in frames (0: off)")
    p.add_argument("--true-style", action="store_true", help="also generate with each dance's real style")
    a = p.parse_args(argv)

    import torch

    from models.errors import PerformerError
    from models.evaluation.evaluate import EvalOptions, clip_audio, load_clips, positions, split_dances
    from models.evaluation.metrics import energy_ratio, jerk
    from models.generate import load_model
    from models.networks.gcn import TIME_FACTOR, GCNDancer
    from models.timebase import FPS

    torch.set_num_threads(1)
    try:
        lm = load_model(a.checkpoint)
        if not isinstance(lm.model, GCNDancer):
            raise PerformerError(f"{a.checkpoint}: a gcn checkpoint is needed, got model {lm.name!r}")
        opts = EvalOptions(max_frames=int(a.seconds * FPS), progress=False)
        _, val = split_dances(a.data, opts)
        clips = load_clips(a.data, val, lm.features, opts)
    except PerformerError as exc:
        print(f"gcn_smoothing.py: error: {exc}", file=sys.stderr)
        return 2
    model, cfg0 = lm.model, lm.model.config
    real = [positions(c.poses) for c in clips]
    styles = list(cfg0.styles)
    print(f"{len(clips)} validation dances, first {a.seconds:g} s each; real jerk {jerk(real):.1f} m/s³\n")
    print("| style fed | spline knots every | energy ratio →1 | jerk (m/s³) |\n|---|---:|---:|---:|")
    for true_style in ([False, True] if a.true_style else [False]):
        for knot in a.knots:
            model.config = dataclasses.replace(cfg0, spline_knot=knot)
            gen = []
            for c in clips:
                steps = None
                if true_style:
                    steps = np.full(-(-len(c.features) // TIME_FACTOR), styles.index(c.style))
                audio = clip_audio(a.data, c)[: (len(c.features) + 1) * 735]
                gen.append(positions(model.generate_poses(c.features, audio, style_steps=steps)))
            label = "true style" if true_style else "classifier's"
            print(f"| {label} | {knot if knot else 'off'} | {energy_ratio(gen, real):.3f} | {jerk(gen):.1f} |")
    model.config = cfg0
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
