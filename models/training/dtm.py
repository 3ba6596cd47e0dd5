"""Training of the "Dancing to Music" model (``dtm``): decomposition, then composition.

``performer train --config configs/dtm.toml`` dispatches here from
:func:`models.training.train.train`. The two phases of Lee et al. (NeurIPS 2019):

1. **Decomposition** (``stage1_steps``): the DU-VAE learns dance units. Every batch
   holds two copies of each unit with different random global shifts (root moved
   by up to ``shift_m`` metres in x and z, the rig analogue of the paper's 2-D
   keypoint shift); losses: reconstruction L1 of both, cross reconstruction (copy 1
   from its own initial-pose code and copy 2's movement code, and vice versa), L1
   between the two movement codes, KL of both codes (weight ramped up over the first
   ``kl_warmup`` of the phase), and initial-pose VAE reconstruction + KL on random
   single frames. The music style classifier (C/R/W) trains alongside on the audio
   windows of the dance sequences (cross-entropy).
2. **Composition** (``stage2_steps``): the MM-GAN learns dances of ``num_units``
   units. The initial-pose and movement encoders and the style classifier are
   frozen; the movement-to-dance encoder, dance decoder and style-to-dance encoder
   train (the unit decoder fine-tunes at ``lr * decoder_lr_scale``) with:
   movement-code reconstruction L1, pose reconstruction L1 through the unit
   decoder, KL of the dance and movement codes, non-saturating GAN losses of the
   movement discriminator (real: the encoder's movement codes of real dances,
   conditioned on the style feature) and the dance discriminator (real: z_dance of
   real dances), and the style regressor's MSE on real and music-made ``z_dance``.

Units come from every training clip (tempo factors of ``tempos``): music beats from
the clip's onset feature (:func:`models.networks.dtm.feature_beats`, as at test
time), units of 4 beats (:func:`models.networks.dtm.extract_units`), kept when at
least ``min_beat_hits`` of their 4 beats have a kinematic offset
(:func:`models.evaluation.lee_beats.kinematic_offsets`) within ``beat_tolerance``
frames, as the paper keeps units whose kinematic and music beats agree.

Outputs in ``out_dir`` as for :mod:`models.training.train`: ``last.pt`` / ``best.pt``
(checkpoints of the generator side; ``best.pt`` is the final model, since no
validation number ranks music-made dances), ``state.pt`` (resume), ``log.csv``,
``losses.png``, ``config.json``.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from models.errors import ConfigError, DataError
from models.networks.dtm import (DanceToMusic, DTMConfig, DTMCritics, extract_units, feature_beats, kl_normal,
                                 reparameterize, style_window)
from models.networks.generator import config_from_dict
from models.training.resume import resume_or_start, save_state
from models.training.runlog import RunLog

STYLES: tuple[str, ...] = ("C", "R", "W")


@dataclass(frozen=True)
class DTMTrainOptions:
    """The ``[dtm]`` table of a training config (loss weights and data knobs; defaults in brackets)."""

    lambda_recon: float = 1.0  # unit reconstruction L1, standardised pose units
    lambda_kl: float = 0.01  # KL of z_init / z_mov (decomposition) and of z_mov (composition)
    lambda_kl_dance: float = 0.01
    lambda_dist: float = 1.0  # L1 between the movement codes of the two shifted copies
    lambda_initp: float = 1.0  # single-pose reconstruction through the initial-pose VAE
    lambda_zmov: float = 1.0  # composition: movement code (mu, logvar) reconstruction
    lambda_gan: float = 0.1
    lambda_info: float = 1.0  # style regressor MSE
    kl_warmup: float = 0.3  # share of the decomposition phase over which the KL weight rises from 0
    shift_m: float = 0.5  # max root shift in x and z of the shift reconstruction, metres
    decoder_lr_scale: float = 0.1
    grad_clip: float = 0.5
    min_beat_hits: int = 2  # of a unit's 4 beats, how many need a kinematic offset nearby
    beat_tolerance: int = 3  # frames

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "DTMTrainOptions":
        try:
            return config_from_dict(cls, d)
        except TypeError as e:
            raise ConfigError(f"[dtm] table: {e}") from None


# --------------------------------------------------------------------------- data


@dataclass
class UnitSet:
    """Units (N, unit_frames, P) float32, sequences (M, num_units) of unit indices, their
    style windows (M, L, D) and style labels (M,)."""

    units: np.ndarray
    sequences: np.ndarray
    windows: np.ndarray
    labels: np.ndarray


def clip_units(clip, config: DTMConfig, opts: DTMTrainOptions) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(units, start beat indices, beats) of one corpus clip, filtered by beat agreement."""
    from models.evaluation.evaluate import positions
    from models.evaluation.lee_beats import kinematic_offsets

    beats = feature_beats(clip.features, config.beat_shift)
    units, starts = extract_units(clip.poses, beats, config.unit_frames, config.unit_beats, clip.valid)
    if opts.min_beat_hits > 0 and len(starts):
        kin = kinematic_offsets(positions(clip.poses))
        if len(kin) == 0:
            return units[:0], starts[:0], beats
        near = np.min(np.abs(beats[:, None] - kin[None, :]), axis=1) <= opts.beat_tolerance  # per beat
        hits = np.array([near[s : s + config.unit_beats].sum() for s in starts])
        keep = hits >= opts.min_beat_hits
        units, starts = units[keep], starts[keep]
    return units, starts, beats


def build_units(clips: list, config: DTMConfig, opts: DTMTrainOptions, progress: bool = True) -> UnitSet:
    """:class:`UnitSet` of corpus clips (styles from the clip names' C/R/W)."""
    from tqdm import tqdm

    units, seqs, wins, labels = [], [], [], []
    offset = 0
    for c in tqdm(clips, desc="dance units", unit="clip", disable=not progress):
        u, starts, beats = clip_units(c, config, opts)
        index = {int(s): offset + i for i, s in enumerate(starts)}
        span = config.unit_beats * config.num_units
        for s in starts:
            chain = [index.get(int(s) + config.unit_beats * k) for k in range(config.num_units)]
            if None in chain:
                continue
            seqs.append(chain)
            wins.append(style_window(c.features, 0.5 * (beats[s] + beats[s + span]), config.style_window))
            labels.append(STYLES.index(c.style) if c.style in STYLES else 0)
        units.append(u)
        offset += len(u)
    p, d = clips[0].poses.shape[1], clips[0].features.shape[1]
    return UnitSet(
        np.concatenate(units) if units else np.zeros((0, config.unit_frames, p), np.float32),
        np.asarray(seqs, np.int64).reshape(-1, config.num_units),
        np.stack(wins) if wins else np.zeros((0, config.style_window, d), np.float32),
        np.asarray(labels, np.int64),
    )


def shift_units(units: np.ndarray, max_shift: float, rng: np.random.Generator) -> np.ndarray:
    """Copy of flat-pose units (B, F, P) with the root moved by a random (x, 0, z) per unit, |.| <= max_shift m."""
    out = units.copy()
    out[:, :, [0, 2]] += rng.uniform(-max_shift, max_shift, (len(units), 1, 2)).astype(np.float32)
    return out


def set_statistics(model: DanceToMusic, data: UnitSet, features: list[np.ndarray], opts: DTMTrainOptions,
                   rng: np.random.Generator) -> None:
    """Standardisation buffers from the training units (with the shift augmentation) and features.

    Standard deviations are floored at 0.02 (pose) / 1e-3 (features) so near-constant
    channels are not blown up.
    """
    flat = shift_units(data.units, opts.shift_m, rng).reshape(-1, data.units.shape[-1])
    feats = np.concatenate(features)
    with torch.no_grad():
        model.pose_mean.copy_(torch.from_numpy(flat.mean(0)))
        model.pose_std.copy_(torch.from_numpy(np.maximum(flat.std(0), 0.02)))
        model.feat_mean.copy_(torch.from_numpy(feats.mean(0)))
        model.feat_std.copy_(torch.from_numpy(np.maximum(feats.std(0), 1e-3)))


# --------------------------------------------------------------------------- one step of each phase


def bce(logits: torch.Tensor, real: bool) -> torch.Tensor:
    return F.binary_cross_entropy_with_logits(logits, torch.full_like(logits, 1.0 if real else 0.0))


def decomposition_step(model: DanceToMusic, units: np.ndarray, windows: np.ndarray, labels: np.ndarray,
                       opts: DTMTrainOptions, kl_weight: float, rng: np.random.Generator,
                       opt: torch.optim.Optimizer, opt_style: torch.optim.Optimizer) -> dict[str, float]:
    """One DU-VAE update on flat-pose units (B, F, P) and one style-classifier update; returns the losses."""
    b = len(units)
    x = model.norm_pose(torch.from_numpy(np.concatenate([shift_units(units, opts.shift_m, rng),
                                                         shift_units(units, opts.shift_m, rng)])))
    out = model.decompose(x)
    x1, x2 = x[:b], x[b:]
    zi1, zi2 = out["z_init"][:b], out["z_init"][b:]
    zm1, zm2 = out["z_mov"][:b], out["z_mov"][b:]
    recon = (out["recon"] - x).abs().mean()
    cross = 0.5 * ((model.unit_dec(zi1, zm2) - x1).abs().mean() + (model.unit_dec(zi2, zm1) - x2).abs().mean())
    dist = (zm1 - zm2).abs().mean()
    kl = kl_normal(out["init_mu"], out["init_logvar"]) + kl_normal(out["mov_mu"], out["mov_logvar"])
    frames = x.flatten(0, 1)[torch.from_numpy(rng.choice(x.shape[0] * x.shape[1], size=4 * b, replace=False))]
    p_mu, p_logvar = model.init_enc(frames)
    initp = (model.init_dec(reparameterize(p_mu, p_logvar)) - frames).abs().mean()
    kl_p = kl_normal(p_mu, p_logvar)
    loss = (opts.lambda_recon * (recon + cross) + opts.lambda_dist * dist + opts.lambda_initp * initp
            + kl_weight * opts.lambda_kl * (kl + kl_p))
    opt.zero_grad(set_to_none=True)
    loss.backward()
    torch.nn.utils.clip_grad_norm_([p for g in opt.param_groups for p in g["params"]], opts.grad_clip)
    opt.step()
    _, logits = model.style(torch.from_numpy(windows))
    loss_style = F.cross_entropy(logits, torch.from_numpy(labels))
    opt_style.zero_grad(set_to_none=True)
    loss_style.backward()
    opt_style.step()
    return {"loss_recon": recon.item(), "loss_cross": cross.item(), "loss_dist": dist.item(), "loss_kl": kl.item(),
            "loss_initp": initp.item(), "loss_style": loss_style.item()}


def composition_step(model: DanceToMusic, critics: DTMCritics, seq_units: np.ndarray, windows: np.ndarray,
                     opts: DTMTrainOptions, opt_g: torch.optim.Optimizer, opt_d: torch.optim.Optimizer) -> dict[str, float]:
    """One MM-GAN update: critics, then generator side. ``seq_units`` (B, n, F, P) flat poses."""
    b, n = seq_units.shape[:2]
    x = model.norm_pose(torch.from_numpy(seq_units))  # (B, n, F, P)
    with torch.no_grad():  # frozen: initial-pose / movement encoders, style classifier
        init_mu, init_logvar = model.init_enc(x[:, :, 0].flatten(0, 1))
        z_init = reparameterize(init_mu, init_logvar)
        mov_mu, mov_logvar = (t.view(b, n, -1) for t in model.move_enc(x.flatten(0, 1)))
        style, _ = model.style(torch.from_numpy(windows))
    out = model.compose(mov_mu, mov_logvar, style)

    # critics
    loss_d = (bce(critics.movement_logit(mov_mu, mov_logvar, style), True)
              + bce(critics.movement_logit(out["fake_mu"].detach(), out["fake_logvar"].detach(), style), False)
              + bce(critics.dance_logit(out["dance_mu"].detach(), out["dance_logvar"].detach()), True)
              + bce(critics.dance_logit(out["fake_dance_mu"].detach(), out["fake_dance_logvar"].detach()), False))
    opt_d.zero_grad(set_to_none=True)
    loss_d.backward()
    torch.nn.utils.clip_grad_norm_(list(critics.movement.parameters()) + list(critics.dance.parameters()), opts.grad_clip)
    opt_d.step()

    # generator side
    zmov = (out["rec_mu"] - mov_mu).abs().mean() + (out["rec_logvar"] - mov_logvar).abs().mean()
    rec_units = model.unit_dec(z_init, reparameterize(out["rec_mu"], out["rec_logvar"]).flatten(0, 1))
    recon = (rec_units - x.flatten(0, 1)).abs().mean()
    kl = opts.lambda_kl_dance * (kl_normal(out["dance_mu"], out["dance_logvar"])
                                 + kl_normal(out["fake_dance_mu"], out["fake_dance_logvar"]))
    kl = kl + opts.lambda_kl * (kl_normal(out["rec_mu"], out["rec_logvar"]) + kl_normal(out["fake_mu"], out["fake_logvar"]))
    gan = (bce(critics.movement_logit(out["fake_mu"], out["fake_logvar"], style), True)
           + bce(critics.dance_logit(out["fake_dance_mu"], out["fake_dance_logvar"]), True))
    info = F.mse_loss(critics.regressor(out["z_dance"]), style) + F.mse_loss(critics.regressor(out["fake_dance"]), style)
    loss = (opts.lambda_zmov * zmov + opts.lambda_recon * recon + kl + opts.lambda_gan * gan
            + opts.lambda_info * info)
    opt_g.zero_grad(set_to_none=True)
    loss.backward()
    torch.nn.utils.clip_grad_norm_([p for g in opt_g.param_groups for p in g["params"]], opts.grad_clip)
    opt_g.step()
    return {"loss_zmov": zmov.item(), "loss_recon": recon.item(), "loss_kl": kl.item(), "loss_g_gan": gan.item(),
            "loss_d": loss_d.item(), "loss_info": info.item()}


def optimizers(model: DanceToMusic, critics: DTMCritics, lr: float, beta1: float,
               opts: DTMTrainOptions) -> dict[str, torch.optim.Optimizer]:
    """Adam optimisers: decomposition (DU-VAE), style classifier, composition generator side, critics."""
    betas = (beta1, 0.999)
    vae = [*model.init_enc.parameters(), *model.init_dec.parameters(), *model.move_enc.parameters(),
           *model.unit_dec.parameters()]
    comp = [*model.dance_enc.parameters(), *model.dance_dec.parameters(), *model.style_enc.parameters(),
            *critics.regressor.parameters()]
    return {
        "vae": torch.optim.Adam(vae, lr=lr, betas=betas),
        "style": torch.optim.Adam(model.style_cls.parameters(), lr=lr, betas=betas),
        "gen": torch.optim.Adam([{"params": comp}, {"params": list(model.unit_dec.parameters()),
                                                     "lr": lr * opts.decoder_lr_scale}], lr=lr, betas=betas),
        "critic": torch.optim.Adam([*critics.movement.parameters(), *critics.dance.parameters()], lr=lr, betas=betas),
    }


# --------------------------------------------------------------------------- validation


@torch.no_grad()
def validate(model: DanceToMusic, val: UnitSet, val_clips: list, offsets: torch.Tensor) -> dict[str, float]:
    """Unit reconstruction rotation L1 (posterior means), style accuracy, and the energy
    ratio of generated vs real end-effector velocities on the validation clips (seed 0)."""
    from models.training import losses

    model.eval()
    row: dict[str, float] = {}
    if len(val.units):
        u = torch.from_numpy(val.units[:512])
        row["val_recon_rot_l1"] = float(losses.rotation_l1(model.reconstruct(u).transpose(1, 2), u.transpose(1, 2)))
    if len(val.labels):
        _, logits = model.style(torch.from_numpy(val.windows))
        row["val_style_acc"] = float((logits.argmax(1).numpy() == val.labels).mean())
    gen_v, real_v = [], []
    for c in val_clips:
        g = torch.from_numpy(model.generate(c.features, seed=0)).T[None]
        r = torch.from_numpy(c.poses).T[None]
        gen_v.append(losses.effector_positions(g, offsets).diff(dim=1).reshape(-1, 3))
        real_v.append(losses.effector_positions(r, offsets).diff(dim=1).reshape(-1, 3))
    if gen_v:
        row["val_energy"] = float(torch.cat(gen_v).std() / torch.cat(real_v).std().clamp_min(1e-9))
    model.train()
    return row


LOG_FIELDS = ["step", "stage", "loss_recon", "loss_cross", "loss_dist", "loss_kl", "loss_initp", "loss_style",
              "loss_zmov", "loss_g_gan", "loss_d", "loss_info", "units_per_s", "val_recon_rot_l1", "val_style_acc",
              "val_energy"]


LOSS_PANELS = (("decomposition (stage 1)", ("loss_recon", "loss_cross", "loss_dist", "loss_kl", "loss_initp",
                                            "loss_style"), True),
               ("composition (stage 2)", ("loss_zmov", "loss_g_gan", "loss_d", "loss_info"), False),
               ("validation", ("val_recon_rot_l1", "val_style_acc", "val_energy"), False))


# --------------------------------------------------------------------------- driver


def train_dtm(cfg, data_root: str | Path, out_dir: str | Path, cache_dir: str | Path | None = None,
              progress: bool = True) -> Path:
    """Train ``dtm`` (``cfg``: :class:`~models.training.config.TrainConfig`) on DWM; returns ``best.pt``."""
    from tqdm import tqdm

    from models.data.alignment import UNVERIFIED_ALIGNMENT
    from models.data.dwm import dance_dirs
    from models.data.split import split_names
    from models.features.spectral import FeatureConfig
    from models.networks.checkpoint import build_model, save_checkpoint
    from models.rig.humanoid import BONES
    from models.rig.motion import POSE_DIM
    from models.rig.skeleton import load_default_skeleton
    from models.data.corpus import build_corpus
    from models.training.sampler import seed_all

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(cfg.threads)
    seed_all(cfg.seed)
    opts = DTMTrainOptions.from_dict(cfg.dtm)
    fcfg = FeatureConfig(**cfg.features)
    if fcfg.kind != "logmel_onset":
        raise ConfigError(f"dtm tracks beats on the onset column of the logmel_onset features, got kind {fcfg.kind!r}")

    names = [d.name for d in dance_dirs(data_root)]
    train_names, val_names = split_names(names)
    if cfg.exclude_unverified:
        train_names = [n for n in train_names if n not in UNVERIFIED_ALIGNMENT]
    train_clips = build_corpus(data_root, train_names, fcfg, tuple(cfg.tempos), cache_dir, progress)
    val_clips = build_corpus(data_root, val_names, fcfg, (1.0,), cache_dir, progress)

    model_cfg = {**cfg.model_config, "feature_dim": fcfg.dim, "pose_dim": POSE_DIM, "num_styles": len(STYLES)}
    model: DanceToMusic = build_model("dtm", model_cfg)  # type: ignore[assignment]
    critics = DTMCritics(model.config)
    rng = np.random.default_rng(cfg.seed)
    data = build_units(train_clips, model.config, opts, progress)
    val = build_units(val_clips, model.config, DTMTrainOptions(**{**dataclasses.asdict(opts), "min_beat_hits": 0}),
                      progress)
    if len(data.units) < cfg.batch_size or len(data.sequences) < cfg.batch_size:
        raise DataError(f"only {len(data.units)} dance units / {len(data.sequences)} sequences in the training "
                        f"dances; need at least batch_size = {cfg.batch_size}")
    set_statistics(model, data, [c.features for c in train_clips], opts, rng)
    opt = optimizers(model, critics, cfg.lr, cfg.beta1, opts)
    offsets = torch.from_numpy(load_default_skeleton().offsets).float()

    state_path = out / "state.pt"
    runlog = RunLog(out, LOG_FIELDS, LOSS_PANELS)
    parts = {"model": model, "critics": critics, **{f"opt_{k}": o for k, o in opt.items()}}
    step = resume_or_start(state_path, parts, rng, runlog)["step"]
    (out / "config.json").write_text(json.dumps({
        "train": cfg.to_dict(), "data": str(data_root), "train_dances": train_names, "val_dances": val_names,
        "units": len(data.units), "sequences": len(data.sequences), "val_units": len(val.units)}, indent=1))
    if progress:
        print(f"{len(data.units)} training units, {len(data.sequences)} sequences of {model.config.num_units}; "
              f"{len(val.units)} validation units")

    meta = dict(model_name="dtm", generator_config=model.config,
                feature_config={**fcfg.to_dict(), "fingerprint": fcfg.fingerprint()},
                rig={"bones": list(BONES), "pose_dim": POSE_DIM})

    def save(path: Path, extra: dict) -> None:
        save_checkpoint(path, model, extra={"step": step, "val_dances": val_names, "units": len(data.units), **extra},
                        **meta)

    model.train()
    critics.train()
    bar = tqdm(total=cfg.total_steps, initial=step, desc="train dtm", unit="step", disable=not progress)
    t_last, done = time.perf_counter(), 0
    warm = max(1, int(opts.kl_warmup * cfg.stage1_steps))
    while step < cfg.total_steps:
        stage = 1 if step < cfg.stage1_steps else 2
        if stage == 1:
            ui = rng.choice(len(data.units), cfg.batch_size, replace=False)
            si = rng.choice(len(data.sequences), cfg.batch_size, replace=False)
            losses_ = decomposition_step(model, data.units[ui], data.windows[si], data.labels[si], opts,
                                         min(1.0, step / warm), rng, opt["vae"], opt["style"])
        else:
            si = rng.choice(len(data.sequences), cfg.batch_size, replace=False)
            losses_ = composition_step(model, critics, data.units[data.sequences[si]], data.windows[si], opts,
                                       opt["gen"], opt["critic"])
        step += 1
        done += cfg.batch_size
        row: dict[str, object] = {"step": step, "stage": stage, **losses_}
        if step % cfg.eval_every == 0 or step == cfg.total_steps:
            now = time.perf_counter()
            row["units_per_s"] = done / (now - t_last)
            t_last, done = now, 0
            row.update(validate(model, val, val_clips, offsets))
            extra = {k: row[k] for k in ("val_recon_rot_l1", "val_style_acc", "val_energy") if k in row}
            save(out / "last.pt", extra)
            if step == cfg.total_steps:
                save(out / "best.pt", extra)
            save_state(state_path, parts, rng, step=step)
        runlog.append(row)
        if step % cfg.eval_every == 0 or step == cfg.total_steps:
            runlog.plot()
        bar.set_postfix(stage=stage, recon=f"{losses_['loss_recon']:.3f}")
        bar.update(1)
    bar.close()
    return out / "best.pt"
