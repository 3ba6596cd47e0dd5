"""FD on a stage (issue 39's "FD no worse than today"): ``performer evaluate``'s set metrics of the
shipped performer travelling on a stage, beside the same performer in place, in one run.

``performer evaluate`` dances in place: its FD is the style classifier's (the one ``evaluate``
ships and caches) Frechet distance between the performer's 64-frame windows and the real
validation dances', which are canonical (no travel, no heading). For every validation dance and
seed the stream dances the song's features (the live stream, one push) once per ``--stages``
entry (``--no-feet``: without the feet step). A stage's poses are canonicalised first
(``models.data.canonical``: root x, z and the Hips' heading taken out, as the dancers the
classifier learned and is compared with are): as they come out, the travel in the joints'
velocities and the heading in their root-relative positions put them outside anything the
classifier saw (FD in the millions).

``0`` (in place) is ``performer evaluate``'s own reading (at seed 0 the headline's FD). Prints FD,
beat hit rate and band amplitude (dancers = 1, the poses as they come out) per stage and seed::

    .venv/bin/python benchmarks/studies/stage_fd.py --data ../shared/data/dwm --seeds 0 1 --stages 0 3x2

Exit status 2 on a missing or unreadable checkpoint or dataset.
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path[:0] = [p for p in (str(HERE.parents[1]), str(HERE)) if p not in sys.path]  # the repo and the studies, from anywhere


def run(data_root: str, checkpoint: str, seeds: list[int], stages: list[str], cache: str,
        feet: bool = True) -> None:
    """Print one row a stage and seed: FD, beat hit rate, band amplitude (see the docstring)."""
    import torch

    from models.data.canonical import canonicalize
    from models.evaluation.evaluate import positions, set_metrics
    from models.networks import dance_stream
    from models.rig.motion import Motion

    from jitter_wrap import style_judge, validation_clips

    lm, clips = validation_clips(data_root, checkpoint, cache)
    val, classifier, real_emb = style_judge(data_root, lm, clips, cache)
    print(f"{'stage':<6} {'seed':>4} {'FD':>7} {'beat hit':>8} {'band amp':>8}", flush=True)
    for stage in stages:
        kw = {} if stage in ("0", "") else {"stage": stage}
        for seed in seeds:
            world, canon = [], []
            for c in clips:
                with torch.no_grad():
                    poses = dance_stream.DanceStream(lm.model, seed=seed, feet=feet, **kw).push(c.features)
                world.append(positions(poses))
                canon.append(positions(canonicalize(Motion.from_vector(poses)).to_vector()) if kw else world[-1])
            fd = set_metrics(canon, val, real_emb, classifier)["fd"]
            row = set_metrics(world, val, real_emb, classifier)
            print(f"{stage:<6} {seed:>4} {fd:>7.3f} {row['beat_hit_rate']:>8.3f} {row['band_amp']:>8.3f}", flush=True)


def main(argv: list[str] | None = None) -> int:
    from foot_skating import apply_sets, study_parser

    p = study_parser(__doc__)
    p.add_argument("--seeds", type=int, nargs="+", default=[0], metavar="N", help="the stream's seeds (default 0)")
    p.add_argument("--stages", nargs="+", default=["0", "3x2"], metavar="WxD",
                   help="stages to dance on, 0 = in place (default: 0 3x2)")
    p.add_argument("--no-feet", action="store_true", help="the performer with its feet step switched off")
    a = p.parse_args(argv)
    apply_sets(p, a.set)
    import torch

    from models.errors import PerformerError
    from models.networks.stage import parse_stage

    torch.set_num_threads(1)
    try:
        for st in a.stages:
            parse_stage(st)
    except PerformerError as e:
        p.error(str(e))
    try:
        run(a.data, a.checkpoint, a.seeds, a.stages, a.cache, feet=not a.no_feet)
    except (PerformerError, OSError) as e:
        print(f"stage_fd.py: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
