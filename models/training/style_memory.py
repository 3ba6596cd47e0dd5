"""Give an existing dance_vq checkpoint its style and tempo memory (issue 18 target 8, issue 25).

A requested style (``--style``, the live control) used to be only a token the predictor
reads: it reweighs the codes the audio already favours, and the exemplars then played
could come from any style's dancers. Training now also records, for the choreographic
memory, each exemplar's style (``member_style``) and, per code, how much likelier it is in
each style's dances (``style_prior``; ``models.training.dance_vq.fit_style_prior``), and
``DanceStream`` plays a requested style from its own dancers' exemplars
(``models/networks/dance_stream.py``, docs/training.md "Style").

This command adds both to a checkpoint trained before they existed, without retraining: it
rebuilds the training run's motion clips from its config, refits the memory with the
checkpoint's own encoder (checking that it picks exactly the exemplars the checkpoint
holds, so only their styles are new) and fits the prior::

    .venv/bin/python -m models.training.style_memory --checkpoint runs/dance_vq_final/best.pt \\
        --config configs/dance_vq.toml --data ../shared/data/dwm --out models/assets/default.pt

Exit status 2 on a missing or unreadable input, a checkpoint that is not dance_vq, or a
memory that does not refit to the same exemplars (another config or dataset).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys

import numpy as np
import torch

from models.errors import DataError
from models.networks.dance_vq import DanceVQ
from models.training.dance_vq import PRIOR_STYLES, fit_members, fit_style_prior


@torch.no_grad()
def add_style_memory(model: DanceVQ, motion_clips: list) -> np.ndarray:
    """Refit ``model``'s members on ``motion_clips`` (its training motion) to learn their
    styles, then its style prior; DataError if the members come out different from those it
    holds. Returns the prior's counts (K, 4)."""
    before = model.member_poses.clone(), model.member_count.clone()
    fit_members(model, motion_clips)
    model.eval()
    if not (torch.equal(before[0], model.member_poses) and torch.equal(before[1], model.member_count)):
        model.member_poses.copy_(before[0])
        model.member_count.copy_(before[1])
        model.member_style.zero_()
        raise DataError("refitting the choreographic memory on these clips picks other exemplars than the "
                        "checkpoint holds: not the motion it was trained on (another --config or --data?)")
    return fit_style_prior(model, motion_clips)


def load_dance_vq(path: str, what: str):
    """:func:`models.generate.load_model` of ``path``; PerformerError unless it is a dance_vq
    model (``what``: what the caller adds to it, for the message)."""
    from models.errors import PerformerError
    from models.generate import load_model

    lm = load_model(path)
    if not isinstance(lm.model, DanceVQ):
        raise PerformerError(f"{lm.path} is a {lm.name!r} model; {what} is dance_vq's")
    return lm


def save_as_loaded(lm, out: str) -> None:
    """Save ``lm.model`` to ``out`` with the metadata it was loaded with (model name, features, rig, extra)."""
    from models.networks.checkpoint import save_checkpoint

    meta = lm.meta
    save_checkpoint(out, lm.model, model_name=meta["model_name"], generator_config=lm.model.config,
                    feature_config=meta["feature_config"], rig=meta["rig"], extra=meta.get("extra"))


def refit_parser(doc: str, what: str) -> argparse.ArgumentParser:
    """The options of a command that adds ``what`` (e.g. "style memory") to a trained checkpoint by
    refitting its memory: --checkpoint, --config, --data, --out; ``doc``: the module docstring."""
    p = argparse.ArgumentParser(description=doc.split("\nExit status")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--checkpoint", required=True, metavar="CKPT", help="a dance_vq checkpoint")
    p.add_argument("--config", required=True, metavar="TOML", help="the training config it was trained with")
    p.add_argument("--data", required=True, metavar="DIR", help="the DWM dataset directory (holds DANCE_* dirs)")
    p.add_argument("--out", required=True, metavar="CKPT", help=f"where to write the checkpoint with its {what}")
    return p


def main(argv: list[str] | None = None) -> int:
    p = refit_parser(__doc__, "style memory")
    p.add_argument("--cache", default=".cache/corpus", metavar="DIR", help="corpus cache (default .cache/corpus)")
    a = p.parse_args(argv)

    from models.errors import PerformerError
    from models.training.config import TrainConfig
    from models.training.dance_vq import training_clips

    torch.set_num_threads(1)
    try:
        lm = load_dance_vq(a.checkpoint, "the style memory")
        if lm.features.beat_phase and lm.model.config.onset_col < 0:  # saved before the tempo memory
            lm.model.config = dataclasses.replace(lm.model.config, onset_col=lm.features.base_dim - 1)
        cfg = TrainConfig.from_toml(a.config)
        _, motion = training_clips(cfg, lm.features, a.data, a.cache, progress=True)
        counts = add_style_memory(lm.model, motion)
        save_as_loaded(lm, a.out)
    except (PerformerError, OSError) as e:
        print(f"style_memory: {e}", file=sys.stderr)
        return 2
    m = lm.model
    n = counts[:, list(PRIOR_STYLES)].sum(axis=0)
    members = [int((m.member_style == s).sum()) for s in PRIOR_STYLES]
    print(f"{a.checkpoint}: exemplars from cha-cha {members[0]}, rumba {members[1]}, waltz {members[2]} dances; "
          f"prior from {n[0]} cha-cha, {n[1]} rumba, {n[2]} waltz windows")
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
