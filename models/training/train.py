"""The training loop: regression stage, then regression + conditional GAN stage.

Read top to bottom: data (corpus + segment sampler of :mod:`models.training.sampler`), models,
one step, evaluation, checkpoints. Everything the run writes goes to ``out_dir``:

- ``last.pt`` / ``best.pt``: model checkpoints (:mod:`models.networks.checkpoint`);
  ``best.pt`` has the lowest validation rotation L1 seen (with ``ema_decay`` > 0, both
  hold the exponential moving average of the weights, which is also what is validated);
- ``state.pt``: optimiser, discriminator and RNG state, so that the same command
  resumes an interrupted run where it stopped (and gives the same result);
- ``log.csv`` and ``losses.png``: losses per step, validation metrics per evaluation;
- ``config.json``: the resolved configuration.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import torch

from models.data.alignment import UNVERIFIED_ALIGNMENT
from models.data.dwm import dance_dirs
from models.data.split import split_names
from models.features.context import BEAT_COLUMNS
from models.features.spectral import FeatureConfig
from models.networks.checkpoint import build_model, save_checkpoint
from models.errors import ConfigError
from models.networks.discriminator import RECEPTIVE_FIELDS, DiscriminatorConfig, MultiScaleDiscriminator
from models.rig.humanoid import BONES
from models.rig.motion import POSE_DIM
from models.rig.skeleton import load_default_skeleton
from models.training import losses
from models.training.config import TrainConfig
from models.training.resume import resume_or_start, save_state
from models.training.runlog import RunLog
from models.training.sampler import SegmentSampler, seed_all
from models.training.schedule import learning_rate
from models.data.corpus import Clip, build_corpus


def align_output(model: torch.nn.Module, pred: torch.Tensor, target: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Pair output frames with targets for models whose output lags (LSTM baseline: ``output_delay``)."""
    d = int(getattr(model, "output_delay", 0))
    return (pred[..., d:], target[..., : target.shape[-1] - d]) if d else (pred, target)


@torch.no_grad()
def evaluate_clips(model: torch.nn.Module, clips: list[Clip], offsets: torch.Tensor) -> dict[str, float]:
    """Whole-clip validation: rotation L1, end-effector L1 (m), motion-energy ratio.

    The energy ratio is the std of generated end-effector velocities over the real
    ones (1.0 is right; near 0 is the mean-pose collapse).
    """
    model.eval()
    rot, eff, gen_v, real_v = [], [], [], []
    for c in clips:
        t = c.num_frames - c.num_frames % 16
        f = torch.from_numpy(c.features[:t]).T[None]
        y = torch.from_numpy(c.poses[:t]).T[None]
        p, y = align_output(model, model(f), y)
        f = f[..., : y.shape[-1]]
        rot.append(float(losses.rotation_l1(p, y)))
        ep, et = losses.effector_positions(p, offsets), losses.effector_positions(y, offsets)
        eff.append(float((ep - et).abs().mean()))
        gen_v.append(ep.diff(dim=1).reshape(-1, 3))
        real_v.append(et.diff(dim=1).reshape(-1, 3))
    model.train()
    energy = float(torch.cat(gen_v).std() / torch.cat(real_v).std().clamp_min(1e-9))
    return {"val_rot_l1": float(np.mean(rot)), "val_eff_l1_m": float(np.mean(eff)), "val_energy": energy}


def averaged(model: torch.nn.Module, decay: float) -> torch.optim.swa_utils.AveragedModel | None:
    """An exponential moving average of ``model``'s weights and buffers (batch-norm running
    statistics), ``w_ema <- d * w_ema + (1 - d) * w`` after every step; None if decay is 0.

    ``d = min(decay, (1 + n) / (10 + n))`` after n averaged steps (the warm-up of
    TensorFlow's ExponentialMovingAverage), so a run from scratch does not drag its
    random initial weights along for ~1 / (1 - decay) steps. Averaged weights sit
    nearer the middle of the loss basin than the last step's, which can generalise
    better on a small dataset such as this one (docs/training.md measures it).
    """
    if decay <= 0:
        return None
    from torch.optim.swa_utils import AveragedModel

    @torch.no_grad()
    def ema_update(avg: list[torch.Tensor], cur: list[torch.Tensor], n: torch.Tensor | int) -> None:
        d = min(decay, (1.0 + int(n)) / (10.0 + int(n)))
        for a, c in zip(avg, cur):
            if a.is_floating_point():
                a.lerp_(c, 1.0 - d)
            else:  # batch norm's num_batches_tracked: a count, not averaged
                a.copy_(c)

    return AveragedModel(model, multi_avg_fn=ema_update, use_buffers=True)


def freeze_except(model: torch.nn.Module, prefixes: list[str]) -> list[torch.nn.Module]:
    """Leave trainable only the parameters named ``prefix...`` for a prefix in ``prefixes``.

    Returns the batch-norm layers left with no trainable parameter: :func:`set_train`
    keeps them in eval mode, so a partial fine-tune changes neither their running
    statistics nor what the frozen part computes. ConfigError if no parameter matches.
    """
    names = [n for n, _ in model.named_parameters()]
    hit = {n for n in names if any(n.startswith(p) for p in prefixes)}
    if not hit:
        raise ConfigError(f"train_only {prefixes} matches no parameter of this model; its parameters start with "
                          f"{sorted({n.split('.')[0] for n in names})}")
    for n, prm in model.named_parameters():
        prm.requires_grad_(n in hit)
    return [m for m in model.modules() if isinstance(m, torch.nn.modules.batchnorm._BatchNorm)
            and not any(prm.requires_grad for prm in m.parameters())]


def set_train(model: torch.nn.Module, frozen_norms: list[torch.nn.Module]) -> None:
    """``model.train()``, except the frozen batch-norm layers of :func:`freeze_except`."""
    model.train()
    for m in frozen_norms:
        m.eval()


LOSS_PANELS = (("regression losses", ("loss_rot", "loss_fk", "loss_vel", "loss_acc"), True),
               ("GAN losses", ("loss_g_gan", "loss_d"), False),
               ("beat loss (speed on beats / mean speed)", ("loss_beat",), False),
               ("validation", ("val_rot_l1", "val_energy"), False))


LOG_FIELDS = ["step", "stage", "loss_rot", "loss_fk", "loss_vel", "loss_acc", "loss_beat", "loss_g_gan", "loss_d", "frames_per_s",
              "val_rot_l1", "val_eff_l1_m", "val_energy"]


def widen_inputs(init: dict, target: dict, base_dim: int) -> tuple[dict, list[str]]:
    """State dict ``init`` of a network on ``base_dim`` input features, fitted to
    ``target``'s shapes where only the input width grew: every weight whose dim 1 is
    ``base_dim`` in ``init`` and larger in ``target`` (the convs that read the input)
    keeps its old columns and gets zeros for the new ones, so the widened network
    computes exactly what the old one did until training moves the new weights. An input
    standardisation's running statistics (``in_norm.running_mean`` / ``running_var``,
    ``GeneratorConfig.input_norm``) keep the old columns' values and start the new ones
    at mean 0, variance 1; training mode standardises with batch statistics anyway.
    Returns (state dict, names of the widened tensors); ConfigError on any other
    mismatch.
    """
    out, widened = {}, []
    for name, t in target.items():
        old = init.get(name)
        if old is None:
            raise ConfigError(f"init_from checkpoint has no tensor {name!r} (another architecture?)")
        if old.shape == t.shape:
            out[name] = old
        elif old.dim() >= 2 and old.shape[1] == base_dim and old.shape[0] == t.shape[0] and \
                old.shape[2:] == t.shape[2:] and t.shape[1] > base_dim:
            out[name] = torch.zeros_like(t)
            out[name][:, :base_dim] = old
            widened.append(name)
        elif name in ("in_norm.running_mean", "in_norm.running_var") and old.shape == (base_dim,) and \
                t.dim() == 1 and t.shape[0] > base_dim:
            out[name] = torch.zeros_like(t) if name.endswith("mean") else torch.ones_like(t)
            out[name][:base_dim] = old
        else:
            raise ConfigError(f"init_from tensor {name!r} has shape {tuple(old.shape)}, this model {tuple(t.shape)}")
    return out, widened


def _init_state(path: str, fcfg: FeatureConfig, model: torch.nn.Module) -> dict:
    """Weights to start from: the checkpoint's on this config's features, or, when this
    config only appends context/beat columns to the checkpoint's features, its weights
    widened with zeros for the new inputs (:func:`widen_inputs`)."""
    from models.errors import CheckpointError
    from models.networks.checkpoint import load_checkpoint

    init, meta = load_checkpoint(path, expect_bones=list(BONES))
    stored, base = meta["feature_fingerprint"], fcfg.base()
    if stored == fcfg.fingerprint():
        return init.state_dict()
    if base == fcfg or stored != base.fingerprint():
        raise CheckpointError(f"checkpoint was trained on features {stored!r}, expected {fcfg.fingerprint()!r}"
                              + ("" if base == fcfg else f" or its base {base.fingerprint()!r}"), source=path)
    state, widened = widen_inputs(init.state_dict(), model.state_dict(), base.dim)
    if not widened:
        raise ConfigError(f"init_from {path}: no input weights to widen from {base.dim} to {fcfg.dim} features")
    return state


def train(cfg: TrainConfig, data_root: str | Path, out_dir: str | Path, cache_dir: str | Path | None = None,
          progress: bool = True) -> Path:
    """Train ``cfg.model`` on the DWM dataset at ``data_root``; returns the best checkpoint path."""
    if cfg.model == "dtm":  # two phases of its own (decomposition, composition)
        from models.training.dtm import train_dtm
        return train_dtm(cfg, data_root, out_dir, cache_dir, progress)
    if cfg.model == "dance_vq":  # codebook, then code predictor (models/training/dance_vq.py)
        from models.training.dance_vq import train_dance_vq
        return train_dance_vq(cfg, data_root, out_dir, cache_dir, progress)
    if cfg.model == "gcn":  # its own losses, discriminator and music classifier (models/training/gcn_train.py)
        from models.training.gcn_train import train_gcn
        return train_gcn(cfg, data_root, out_dir, cache_dir, progress)
    from tqdm import tqdm

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(cfg.threads)
    seed_all(cfg.seed)
    fcfg = FeatureConfig(**cfg.features)
    if cfg.w_beat > 0 and not fcfg.beat_phase:
        raise ConfigError("w_beat > 0 needs the beat-phase feature columns: set beat_phase = true under [features]")

    names = [d.name for d in dance_dirs(data_root)]
    train_names, val_names = split_names(names)
    if cfg.exclude_unverified:  # their music-motion timing is not established (docs/data.md)
        train_names = [n for n in train_names if n not in UNVERIFIED_ALIGNMENT]
    train_clips = build_corpus(data_root, train_names, fcfg, tuple(cfg.tempos), cache_dir, progress)
    val_clips = build_corpus(data_root, val_names, fcfg, (1.0,), cache_dir, progress)
    rng = np.random.default_rng(cfg.seed)
    sampler = SegmentSampler(train_clips, cfg.segment, rng)

    model_cfg = {**cfg.model_config, "feature_dim": fcfg.dim, "pose_dim": POSE_DIM}
    model = build_model(cfg.model, model_cfg)
    if cfg.init_from:
        model.load_state_dict(_init_state(cfg.init_from, fcfg, model))
    model_config = model.config if hasattr(model, "config") else model_cfg
    frozen_norms = freeze_except(model, cfg.train_only) if cfg.train_only else []
    ema = averaged(model, cfg.ema_decay)
    disc = MultiScaleDiscriminator(DiscriminatorConfig(feature_dim=fcfg.dim, pose_dim=POSE_DIM, width=cfg.disc_width,
                                                   motion=cfg.disc_motion))
    opt_g = torch.optim.Adam([prm for prm in model.parameters() if prm.requires_grad], lr=cfg.lr, betas=(cfg.beta1, 0.999))
    opt_d = torch.optim.Adam(disc.parameters(), lr=cfg.lr, betas=(cfg.beta1, 0.999))
    d_model = getattr(getattr(model, "config", None), "d_model", None)  # for lr_schedule = "noam"
    learning_rate(cfg.lr_schedule, 1, cfg.lr, d_model, cfg.warmup_steps)  # a schedule the model cannot use fails now
    gan_frames = cfg.segment - int(getattr(model, "output_delay", 0))  # what the discriminator sees per segment
    if cfg.stage2_steps > 0 and cfg.w_gan > 0 and gan_frames < max(RECEPTIVE_FIELDS):  # fail now, not after stage 1
        raise ConfigError(f"stage 2 (GAN) needs segment - output delay >= {max(RECEPTIVE_FIELDS)} frames for the "
                          f"discriminator, got {gan_frames}; raise segment or set stage2_steps = 0")
    offsets = torch.from_numpy(load_default_skeleton().offsets).float()

    state_path = out / "state.pt"
    runlog = RunLog(out, LOG_FIELDS, LOSS_PANELS)
    parts = {"model": model, "disc": disc, "opt_g": opt_g, "opt_d": opt_d, **({"ema": ema} if ema is not None else {})}
    kept = ema.module if ema is not None else model  # what is validated and saved
    st = resume_or_start(state_path, parts, rng, runlog)
    step, best = st["step"], st.get("best", float("inf"))
    (out / "config.json").write_text(json.dumps({"train": cfg.to_dict(), "data": str(data_root),
                                                 "train_dances": train_names, "val_dances": val_names}, indent=1))

    meta = dict(model_name=cfg.model, generator_config=model_config,
                feature_config={**fcfg.to_dict(), "fingerprint": fcfg.fingerprint()},
                rig={"bones": list(BONES), "pose_dim": POSE_DIM})

    def save(path: Path, extra: dict) -> None:
        save_checkpoint(path, kept, extra={"step": step, "val_dances": val_names, **extra}, **meta)

    set_train(model, frozen_norms)
    disc.train()
    bar = tqdm(total=cfg.total_steps, initial=step, desc="train", unit="step", disable=not progress)
    t_last, frames = time.perf_counter(), 0
    while step < cfg.total_steps:
        gan = step >= cfg.stage1_steps and cfg.w_gan > 0
        b = sampler.sample(cfg.batch_size)
        pred, target = align_output(model, model(b.features), b.poses)
        feats = b.features[..., : target.shape[-1]]
        row: dict[str, object] = {"step": step + 1, "stage": 2 if gan else 1}
        if gan:  # discriminator step on detached fakes
            loss_d = losses.d_loss(disc(feats, target), disc(feats, pred.detach()))
            opt_d.zero_grad(set_to_none=True)
            loss_d.backward()
            opt_d.step()
            row["loss_d"] = loss_d.item()
        l_rot = losses.rotation_l1(pred, target)
        l_fk = losses.effector_l1(pred, target, offsets)
        loss = cfg.w_rot * l_rot + cfg.w_fk * l_fk
        if cfg.w_vel > 0:
            l_vel = losses.velocity_l1(pred, target, offsets)
            loss = loss + cfg.w_vel * l_vel
            row["loss_vel"] = l_vel.item()
        if cfg.w_acc > 0:
            l_acc = losses.acceleration_l1(pred, target, offsets)
            loss = loss + cfg.w_acc * l_acc
            row["loss_acc"] = l_acc.item()
        if cfg.w_beat > 0:  # the beat columns are the last BEAT_COLUMNS features (context.py)
            l_beat = losses.beat_speed_ratio(pred, feats[:, -BEAT_COLUMNS:], offsets)
            loss = loss + cfg.w_beat * l_beat
            row["loss_beat"] = l_beat.item()
        if gan:
            l_gan = losses.g_gan_loss(disc(feats, pred))
            loss = loss + cfg.w_gan * l_gan
            row["loss_g_gan"] = l_gan.item()
        opt_g.zero_grad(set_to_none=True)
        loss.backward()
        if cfg.lr_schedule != "constant":  # the generator's lr for this (1-based) step
            for group in opt_g.param_groups:
                group["lr"] = learning_rate(cfg.lr_schedule, step + 1, cfg.lr, d_model, cfg.warmup_steps)
        opt_g.step()
        if ema is not None:
            ema.update_parameters(model)
        step += 1
        frames += cfg.batch_size * cfg.segment
        row.update(loss_rot=l_rot.item(), loss_fk=l_fk.item())

        if step % cfg.eval_every == 0 or step == cfg.total_steps:
            now = time.perf_counter()
            row["frames_per_s"] = frames / (now - t_last)
            t_last, frames = now, 0
            row.update(evaluate_clips(kept, val_clips, offsets))
            set_train(model, frozen_norms)  # evaluate_clips leaves every layer in train mode
            save(out / "last.pt", {k: row[k] for k in ("val_rot_l1", "val_eff_l1_m", "val_energy")})
            if row["val_rot_l1"] < best:  # type: ignore[operator]
                best = float(row["val_rot_l1"])  # type: ignore[arg-type]
                save(out / "best.pt", {k: row[k] for k in ("val_rot_l1", "val_eff_l1_m", "val_energy")})
            save_state(state_path, parts, rng, step=step, best=best)
        runlog.append(row)
        if step % cfg.eval_every == 0 or step == cfg.total_steps:
            runlog.plot()
        bar.set_postfix(rot=f"{l_rot.item():.4f}", fk=f"{l_fk.item():.4f}",
                        **({"gan": f"{row['loss_g_gan']:.3f}"} if gan else {}))
        bar.update(1)
    bar.close()
    return out / "best.pt"
