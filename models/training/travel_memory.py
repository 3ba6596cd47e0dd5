"""Give an existing dance_vq checkpoint its travel memory (issue 39: travel and turns).

Training learns from canonical motion: the root's horizontal position and the Hips' heading
are dropped (models/data/canonical.py), so the performer danced on one spot facing +Z. The
dancers did not: they cover metres of floor and turn many times a minute. This command
records, for every exemplar of the choreographic memory, where its dancer went: per frame of
its window the root's displacement (x, z, metres) and heading change (radians) since the
window's first frame, in that frame's heading frame (``DanceVQ.member_travel``), read from the
same dancers' motion before it was canonicalised. The stage part
(:mod:`models.networks.stage`) integrates them while the exemplar plays.

Like :mod:`models.training.style_memory` it does not retrain: it rebuilds the training run's
motion clips from its config (motion only: the clips' audio features play no part in which
windows become exemplars), refits the memory with the checkpoint's own encoder, checks that it
picks exactly the exemplars the checkpoint holds (poses, counts and styles bit for bit) and
keeps everything but the new travel as it was::

    .venv/bin/python -m models.training.travel_memory --checkpoint models/assets/default.pt \\
        --config configs/dance_vq.toml --data ../shared/data/dwm --out models/assets/default.pt

Exit status 2 on a missing or unreadable input, a checkpoint that is not dance_vq, or a
memory that does not refit to the same exemplars (another config or dataset).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import torch

from models.errors import DataError
from models.networks.dance_vq import DanceVQ
from models.training.dance_vq import fit_members
from models.rig.travel import root_track  # noqa: F401  (a library's travel too: models/rig/travel.py)

#: Memory buffers the refit rewrites and this command keeps as the checkpoint has them.
_KEPT = ("member_poses", "member_count", "member_style", "member_period")


def motion_clips(cfg, feature_dim: int, data_root: str | Path, progress: bool = False) -> tuple[list, list]:
    """(clips, root tracks): the training run's motion clips in the order
    :func:`models.training.dance_vq.training_clips` builds them (the trusted dances at every
    tempo of ``cfg.tempos``, then the other training dances at tempo 1), their poses exactly
    as the corpus makes them but with zero features (``feature_dim`` columns, no memory), and
    per clip its :func:`root_track`."""
    from models.data.canonical import canonicalize
    from models.data.corpus import Clip, clip_motion
    from models.data.dwm import load_dance
    from models.training.dance_vq import training_dances

    verified, others, _ = training_dances(cfg, data_root)
    jobs = [(n, t) for n in verified for t in cfg.tempos] + [(n, 1.0) for n in others]
    clips, tracks = [], []
    for i, (name, tempo) in enumerate(jobs):
        dance = load_dance(Path(data_root) / name)
        motion, valid, f0, f1 = clip_motion(dance, 10**7, tempo)  # the mocap's span: no song ends first
        poses = canonicalize(motion).to_vector()
        q = poses[:, 3:].reshape(len(poses), -1, 4)
        q *= np.where(q[..., 3:] < 0, -1.0, 1.0).astype(np.float32)  # as make_clip
        feats = np.broadcast_to(np.zeros((1, feature_dim), np.float32), (len(poses), feature_dim))
        clips.append(Clip(dance.name, dance.style, float(tempo), feats, poses, valid, f0))
        tracks.append(root_track(motion))
        if progress:
            print(f"\rmotion clips {i + 1}/{len(jobs)}", end="", file=sys.stderr, flush=True)
    if progress:
        print(file=sys.stderr)
    return clips, tracks


@torch.no_grad()
def add_travel_memory(model: DanceVQ, clips: list, tracks: list) -> None:
    """Refit ``model``'s members on ``clips`` (its training motion) with their root ``tracks``
    to fill ``member_travel``; every other memory buffer stays as it was. DataError (and
    nothing changed) if the refit picks other exemplars than the model holds."""
    before = {n: getattr(model, n).clone() for n in _KEPT}
    travel_before = model.member_travel.clone()
    fit_members(model, clips, travel=tracks)
    model.eval()
    same = all(torch.equal(before[n], getattr(model, n)) for n in ("member_poses", "member_count", "member_style"))
    for n in _KEPT:  # member_period needs the songs' features, which these clips do not carry: kept
        getattr(model, n).copy_(before[n])
    if not same:
        model.member_travel.copy_(travel_before)
        raise DataError("refitting the choreographic memory on these clips picks other exemplars than the "
                        "checkpoint holds: not the motion it was trained on (another --config or --data?)")


def travel_summary(model: DanceVQ) -> str:
    """One line: how far and how much the memory's movements (their first seg frames) travel and turn."""
    s = model.config.seg
    real = np.arange(model.config.members)[None, :] < model.member_count.numpy()[:, None]
    t = model.member_travel.float().numpy()[real]  # (n, 2 seg, 3)
    dist = np.linalg.norm(t[:, s, :2], axis=1)
    turn = np.abs(t[:, s, 2])
    return (f"{len(t)} exemplars: over one movement ({s} frames) median travel {np.median(dist) * 100:.1f} cm "
            f"(90th percentile {np.quantile(dist, 0.9) * 100:.1f}), median turn {np.degrees(np.median(turn)):.1f} deg "
            f"(90th percentile {np.degrees(np.quantile(turn, 0.9)):.1f})")


def main(argv: list[str] | None = None) -> int:
    from models.training.style_memory import refit_parser

    a = refit_parser(__doc__, "travel memory").parse_args(argv)

    from models.errors import PerformerError
    from models.training.config import TrainConfig
    from models.training.style_memory import load_dance_vq, save_as_loaded

    torch.set_num_threads(1)
    try:
        lm = load_dance_vq(a.checkpoint, "the travel memory")
        cfg = TrainConfig.from_toml(a.config)
        clips, tracks = motion_clips(cfg, lm.model.config.feature_dim, a.data, progress=True)
        add_travel_memory(lm.model, clips, tracks)
        save_as_loaded(lm, a.out)
    except (PerformerError, OSError, ValueError) as e:
        print(f"travel_memory: {e}", file=sys.stderr)
        return 2
    print(f"{a.checkpoint}: {travel_summary(lm.model)}")
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
