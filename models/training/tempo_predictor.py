"""Stage 2 again, hearing the tempo: a dance_vq checkpoint's code predictor retrained with the
followed tempo as an input of each token (issue 43; ``DanceVQConfig.tempo_input``).

The predictor of ``performer train`` hears the music (the beat tracker's period among its
features) but not the tempo the performer follows. This trains a fresh predictor, as stage 2 of
:func:`models.training.dance_vq.train_dance_vq` does (the same steps, batch, learning rate, noise
and style dropout, on the verified dances at every tempo factor of the config), with each token
also given ``ln(T / T_ref)``: the tempo the stream's own follower reads at the token's last frame
over the memory's mean tempo, faded with the pulse (:func:`models.networks.player.tempo_inputs`,
the stream's arithmetic). Everything else of the checkpoint (codebook, choreographic memory, style
memory, music gate, presence detector) is kept as it is: the stream plays the new predictor's
codes from the same memory, with the tempo's logit tilt :data:`~models.networks.chooser.TEMPO_ENERGY_HEARD`.

Not shipped: the codebook's codes hardly tell a movement played fast from the same played slow (the
stretched corpus's target codes are as quick at 1.25x as at 0.75x), so the predictor has nothing of the
tempo to learn; with the tilt off it chooses the same movements at 1.25x as at 0.8x
(docs/history-listening.md, "A predictor that hears the tempo"). Run::

    PYTHONPATH=. .venv/bin/python -m models.training.tempo_predictor --checkpoint models/assets/default.pt \\
        --config configs/dance_vq.toml --data ../shared/data/dwm --out runs/tempo_predictor.pt

Exit status: 0 written, 2 an unusable checkpoint, config or data.
"""

from __future__ import annotations

import dataclasses
import sys
import time

import numpy as np
import torch

from models.networks.dance_vq import CodePredictor, DanceVQ
from models.training.dance_vq import CodeSet, DanceVQTrainOptions, encode_clips, predictor_batch
from models.training.style_memory import load_dance_vq, refit_parser, save_as_loaded


def tempo_codes(model: DanceVQ, clips: list, phases: range) -> tuple[CodeSet, list[np.ndarray]]:
    """:func:`~models.training.dance_vq.encode_clips` of ``clips`` at ``phases``, and per (clip, phase),
    in the same order, each token's tempo input (N,): :func:`~models.networks.player.tempo_inputs`
    at the token's last frame (token k of phase p ends at frame p + seg k)."""
    from models.networks.player import tempo_inputs

    data = encode_clips(model, clips, phases)
    s = model.config.seg
    tempo = []
    for c in clips:
        x = tempo_inputs(model, c.features)
        for p in phases:
            n = (c.num_frames - p) // s
            if n >= 2:
                tempo.append(x[p + s * np.arange(n)])
    return data, tempo


@torch.no_grad()
def with_tempo_input(model: DanceVQ, seed: int) -> DanceVQ:
    """A copy of ``model`` whose predictor hears the tempo: every buffer and the codebook as they are,
    a fresh predictor (``tempo_input`` on) drawn from ``seed``."""
    torch.manual_seed(seed)
    new = DanceVQ(dataclasses.replace(model.config, tempo_input=True))
    state = {k: v for k, v in model.state_dict().items() if not k.startswith("predictor.")}
    missing, unexpected = new.load_state_dict(state, strict=False)
    assert not unexpected and all(k.startswith("predictor.") for k in missing), (missing, unexpected)
    new.predictor = CodePredictor(new.config)
    return new


def train_tempo_predictor(model: DanceVQ, train_clips: list, val_clips: list, opts: DanceVQTrainOptions, steps: int,
                          seed: int, eval_every: int = 250, progress: bool = True) -> list[dict[str, float]]:
    """Train ``model.predictor`` (``tempo_input`` on) ``steps`` steps as stage 2 does, on ``train_clips`` at every
    grid phase; returns the validation rows (step, val_ce, val_acc) every ``eval_every`` steps."""
    from models.training.dance_vq import predictor_step, validate_predictor

    rng = np.random.default_rng(seed)
    codes, tempo = tempo_codes(model, train_clips, range(model.config.seg))
    codes.tempo = tempo
    val, vtempo = tempo_codes(model, val_clips, range(1))
    val.tempo = vtempo
    if progress:
        every = np.concatenate(tempo)
        print(f"tempo inputs: {len(every)} tokens, ln(T / T_ref) mean {every.mean():+.3f}, "
              f"5-95 % {np.percentile(every, 5):+.3f} .. {np.percentile(every, 95):+.3f}", flush=True)
    opt = torch.optim.AdamW(model.predictor.parameters(), lr=opts.pred_lr, weight_decay=0.01)
    model.train()
    rows, t0 = [], time.perf_counter()
    for step in range(1, steps + 1):
        got = predictor_step(model, codes, opts, opt, rng)
        if step % eval_every == 0 or step == steps:
            row = {"step": step, **got, **validate_predictor(model, val)}
            rows.append(row)
            if progress:
                print(f"step {step}: ce {row['loss_ce']:.3f} val ce {row['val_ce']:.3f} val acc {row['val_acc']:.3f} "
                      f"({time.perf_counter() - t0:.0f} s)", flush=True)
    model.eval()
    return rows


def main(argv: list[str] | None = None) -> int:
    p = refit_parser(__doc__, "predictor that hears the tempo")
    p.add_argument("--cache", default=".cache/corpus", metavar="DIR", help="corpus cache (default .cache/corpus)")
    p.add_argument("--steps", type=int, help="predictor steps (default the config's stage2_steps)")
    p.add_argument("--seed", type=int, help="seed of the new predictor and its batches (default the config's)")
    a = p.parse_args(argv)

    from models.data.corpus import build_corpus
    from models.errors import PerformerError
    from models.training.config import TrainConfig
    from models.training.dance_vq import training_clips, training_dances

    try:
        cfg = TrainConfig.from_toml(a.config)
        torch.set_num_threads(cfg.threads)
        lm = load_dance_vq(a.checkpoint, "the tempo input")
        train, _ = training_clips(cfg, lm.features, a.data, a.cache, progress=True)
        val = build_corpus(a.data, training_dances(cfg, a.data)[2], lm.features, (1.0,), a.cache, True)
        seed = cfg.seed if a.seed is None else a.seed
        lm.model = with_tempo_input(lm.model, seed)
        rows = train_tempo_predictor(lm.model, train, val, DanceVQTrainOptions.from_dict(cfg.dance),
                                     cfg.stage2_steps if a.steps is None else a.steps, seed, cfg.eval_every)
        lm.meta = {**lm.meta, "extra": {**(lm.meta.get("extra") or {}), "tempo_predictor": rows[-1]}}
        save_as_loaded(lm, a.out)
    except (PerformerError, OSError) as e:
        print(f"tempo_predictor: {e}", file=sys.stderr)
        return 2
    last = rows[-1]
    print(f"wrote {a.out}: after {last['step']} steps validation cross-entropy {last['val_ce']:.3f}, "
          f"accuracy {last['val_acc']:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
