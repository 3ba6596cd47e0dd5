"""Training of the ``gcn`` model (:mod:`models.networks.gcn`): ``performer train`` with
``model = "gcn"`` comes here (:func:`train_gcn`).

Two stages, one run, same output files as :mod:`models.training.train` (``last.pt``,
``best.pt``, ``state.pt``, ``log.csv``, ``losses.png``, ``config.json``), plus
``style_classifier.json`` with the music classifier's validation accuracy:

0. **Music style classifier** on the training split's songs (the whole audio file of
   every training dance, resampled to 16 kHz, mu-law companded): random windows of
   64 frames (2.13 s), styles drawn uniformly (DWM has 4 C, 8 R and 28 W dances),
   random gain of -6..0 dB, Adam, cross-entropy; ``classifier_steps`` batches of
   ``classifier_batch`` (``model_config`` keys prefixed ``train_`` are read by this
   module, not by the network: see :class:`GCNTrainOptions`). Validation accuracy on
   every 2.13 s window (hop 1 s) of the validation songs, per style and per song
   (majority vote), goes to ``style_classifier.json`` and the checkpoint's ``extra``.
1. **Conditional GAN** (Ferreira et al. 2021): segments of ``segment`` frames from
   the tempo-augmented corpus, conditioned on the dance's true style (at generation
   the classifier's output is used); fresh GP noise per segment. Discriminator:
   binary cross-entropy with the paper's soft labels (real in [0.7, 1.0], fake in
   [0.0, 0.3]); generator: ``w_gan`` x BCE(D(fake), 1) + ``w_rot`` x rotation L1 +
   ``w_fk`` x L1 of all 21 FK joint positions (the paper's lambda = 100 L1 on joint
   positions; both weights 100). The first ``stage1_steps`` use the L1 terms only.

A GAN has no validation loss that tracks quality, so ``best.pt`` is the last step's
model too (the log keeps the validation L1 and energy ratio for reading).
"""

from __future__ import annotations

import hashlib
import json
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from models.data.alignment import UNVERIFIED_ALIGNMENT
from models.data.dwm import dance_dirs, load_dance
from models.data.split import split_names
from models.errors import ConfigError
from models.features.spectral import FeatureConfig
from models.networks.checkpoint import build_model, save_checkpoint
from models.networks.gcn import TIME_FACTOR, GCNDancer, GCNDiscriminator, compand, resample_to
from models.rig.humanoid import BONES
from models.rig.kinematics import fk_torch
from models.rig.motion import POSE_DIM
from models.rig.skeleton import load_default_skeleton
from models.timebase import HOP, SAMPLE_RATE
from models.training import losses
from models.training.config import TrainConfig
from models.training.resume import resume_or_start, save_state
from models.training.runlog import RunLog
from models.data.corpus import Clip, build_corpus
from models.training.sampler import SegmentSampler, seed_all

LOG_FIELDS = ["step", "stage", "loss_rot", "loss_pos", "loss_g_gan", "loss_d", "d_real", "d_fake", "frames_per_s",
              "val_rot_l1", "val_pos_l1_m", "val_energy"]


@dataclass
class GCNTrainOptions:
    """Training-only knobs, given in ``[model_config]`` with a ``train_`` prefix (removed before the network sees it)."""

    classifier_steps: int = 600
    classifier_batch: int = 32
    classifier_lr: float = 1e-3
    disc_lr_factor: float = 1.0  # discriminator lr = lr x this

    @classmethod
    def pop_from(cls, model_config: dict) -> tuple["GCNTrainOptions", dict]:
        opts, rest = {}, {}
        for k, v in model_config.items():
            (opts if k.startswith("train_") else rest)[k.removeprefix("train_") if k.startswith("train_") else k] = v
        known = set(cls.__dataclass_fields__)
        bad = sorted(set(opts) - known)
        if bad:
            raise ConfigError(f"unknown gcn training option(s) {['train_' + b for b in bad]}; known: "
                              f"{sorted('train_' + k for k in known)}")
        return cls(**opts), rest


# --------------------------------------------------------------------------- music classifier


def song_audio(data_root: str | Path, names: list[str], rate: int, cache_dir: str | Path | None,
               progress: bool = True) -> list[tuple[str, str, np.ndarray]]:
    """(name, style, mono float32 audio at ``rate`` Hz) of every named dance, cached as float16."""
    from tqdm import tqdm

    from models.features.audio_io import load_audio

    cache = Path(cache_dir) if cache_dir else None
    if cache:
        cache.mkdir(parents=True, exist_ok=True)
    out = []
    for name in tqdm(names, desc="song audio", unit="song", disable=not progress):
        dance = load_dance(Path(data_root) / name)
        st = dance.audio_path.stat()
        key = hashlib.sha1(f"{name}:{st.st_size}:{int(st.st_mtime)}:{rate}".encode()).hexdigest()[:12]
        path = cache / f"{name}-audio{rate}-{key}.npy" if cache else None
        x = None
        if path is not None and path.is_file():
            try:
                x = np.load(path).astype(np.float32)
            except Exception:  # a damaged cache entry is rebuilt
                x = None
        if x is None:
            x = resample_to(load_audio(dance.audio_path, SAMPLE_RATE)[0], rate)
            if path is not None:
                tmp = path.with_suffix(".tmp.npy")
                np.save(tmp, x.astype(np.float16))
                tmp.replace(path)
        out.append((name, dance.style, x))
    return out


def window_samples(model: GCNDancer) -> int:
    cfg = model.config
    return int(round(cfg.style_chunk * TIME_FACTOR * HOP * cfg.audio_rate / SAMPLE_RATE))


def train_music_classifier(model: GCNDancer, train_songs: list, opts: GCNTrainOptions, seed: int,
                           progress: bool = True) -> list[float]:
    """Fit ``model.style_net`` on random windows of the training songs; returns the loss per step."""
    from tqdm import tqdm

    cfg = model.config
    win = window_samples(model)
    rng = np.random.default_rng(seed + 1)
    by_style = {s: [x for _, st, x in train_songs if st == s and len(x) > win] for s in cfg.styles}
    present = [s for s in cfg.styles if by_style[s]]
    if len(present) < 2:
        raise ConfigError(f"the music classifier needs songs of at least 2 styles, got {present}")
    net = model.style_net
    net.train()
    opt = torch.optim.Adam(net.parameters(), lr=opts.classifier_lr)
    hist = []
    for _ in tqdm(range(opts.classifier_steps), desc="music classifier", unit="batch", disable=not progress):
        xs, ys = [], []
        for _ in range(opts.classifier_batch):
            s = present[rng.integers(len(present))]
            song = by_style[s][rng.integers(len(by_style[s]))]
            a = int(rng.integers(0, len(song) - win))
            gain = 10 ** (rng.uniform(-6, 0) / 20)
            xs.append(compand(song[a : a + win] * gain, cfg.mu))
            ys.append(cfg.styles.index(s))
        loss = F.cross_entropy(net(torch.from_numpy(np.stack(xs))), torch.tensor(ys))
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        hist.append(float(loss.detach()))
    net.eval()
    return hist


@torch.no_grad()
def classifier_accuracy(model: GCNDancer, songs: list, hop_s: float = 1.0) -> dict:
    """Window accuracy (2.13 s windows every ``hop_s``), per style and per song (majority vote)."""
    cfg = model.config
    win = window_samples(model)
    net = model.style_net.eval()
    hop = int(hop_s * cfg.audio_rate)
    right = total = 0
    per_style: dict[str, list[int]] = {}
    per_song: dict[str, dict] = {}
    for name, style, x in songs:
        if len(x) < win:
            continue
        w = np.stack([compand(x[a : a + win], cfg.mu) for a in range(0, len(x) - win + 1, hop)])
        pred = torch.cat([net(torch.from_numpy(b)).argmax(1) for b in np.array_split(w, max(1, len(w) // 64))]).numpy()
        ok = pred == cfg.styles.index(style)
        right += int(ok.sum())
        total += len(ok)
        r = per_style.setdefault(style, [0, 0])
        r[0] += int(ok.sum())
        r[1] += len(ok)
        vote = cfg.styles[int(np.bincount(pred, minlength=len(cfg.styles)).argmax())]
        per_song[name] = {"style": style, "window_accuracy": round(float(ok.mean()), 4), "majority": vote,
                          "windows": len(ok)}
    return {
        "window_accuracy": right / max(total, 1),
        "windows": total,
        "per_style": {s: round(r[0] / r[1], 4) for s, r in sorted(per_style.items())},
        "song_accuracy": float(np.mean([v["majority"] == v["style"] for v in per_song.values()])) if per_song else 0.0,
        "per_song": per_song,
    }


# --------------------------------------------------------------------------- GAN


class StyledSampler(SegmentSampler):
    """:class:`SegmentSampler` that also returns each segment's style index."""

    def __init__(self, clips: list[Clip], segment: int, rng: np.random.Generator, styles: tuple[str, ...]) -> None:
        super().__init__(clips, segment, rng)
        self.styles = styles

    def sample_styled(self, batch_size: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        idx = self.rng.choice(len(self.clips), size=batch_size, p=self.p)
        feats, poses, styles = [], [], []
        for i in idx:
            c = self.clips[i]
            s = int(self.rng.choice(self.starts[i]))
            feats.append(c.features[s : s + self.segment])
            poses.append(c.poses[s : s + self.segment])
            styles.append(self.styles.index(c.style))
        f = torch.from_numpy(np.stack(feats)).transpose(1, 2).contiguous()
        p = torch.from_numpy(np.stack(poses)).transpose(1, 2).contiguous()
        return f, p, torch.tensor(styles)


def joint_positions(pose: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
    """(B, POSE_DIM, T) -> FK positions of the 21 bone heads (B, T, 21, 3), metres."""
    root, quats = losses.split_pose(pose)
    return fk_torch(root, quats, offsets)


def _bce(logits: torch.Tensor, lo: float, hi: float) -> torch.Tensor:
    target = torch.empty_like(logits).uniform_(lo, hi)
    return F.binary_cross_entropy_with_logits(logits, target)


def gan_step(model: GCNDancer, disc: GCNDiscriminator, opt_g: torch.optim.Optimizer, opt_d: torch.optim.Optimizer,
             feats: torch.Tensor, real: torch.Tensor, style_steps: torch.Tensor, offsets: torch.Tensor, *,
             gan: bool = True, w_rot: float = 100.0, w_fk: float = 100.0, w_gan: float = 1.0) -> dict[str, float]:
    """One training step on a batch: features (B, D, T), real poses (B, POSE_DIM, T), styles (B, T/16).

    With ``gan``: a discriminator step (soft labels) on detached fakes, then the generator
    step on ``w_rot`` rotation L1 + ``w_fk`` FK-joint-position L1 + ``w_gan`` BCE(D(fake), 1);
    without: the L1 terms only. Returns the losses as floats.
    """
    b, t0 = style_steps.shape
    fake = model(feats, style_steps, model.noise(b, t0))
    row: dict[str, float] = {}
    if gan:
        d_real, d_fake = disc(real, style_steps), disc(fake.detach(), style_steps)
        loss_d = 0.5 * (_bce(d_real, 0.7, 1.0) + _bce(d_fake, 0.0, 0.3))
        opt_d.zero_grad(set_to_none=True)
        loss_d.backward()
        opt_d.step()
        row.update(loss_d=float(loss_d.detach()), d_real=float(torch.sigmoid(d_real.detach()).mean()),
                   d_fake=float(torch.sigmoid(d_fake.detach()).mean()))
    l_rot = losses.rotation_l1(fake, real)
    l_pos = (joint_positions(fake, offsets) - joint_positions(real, offsets)).abs().mean()
    loss = w_rot * l_rot + w_fk * l_pos
    if gan:
        l_gan = F.binary_cross_entropy_with_logits(disc(fake, style_steps), torch.ones(b, t0))
        loss = loss + w_gan * l_gan
        row["loss_g_gan"] = float(l_gan.detach())
    opt_g.zero_grad(set_to_none=True)
    loss.backward()
    opt_g.step()
    row.update(loss_rot=float(l_rot.detach()), loss_pos=float(l_pos.detach()))
    return row


@torch.no_grad()
def validate(model: GCNDancer, clips: list[Clip], offsets: torch.Tensor) -> dict[str, float]:
    """Rotation L1 and FK position L1 (m) against the real motion, and the energy ratio, on the
    validation clips with their true style and a fixed noise seed (no spline smoothing)."""
    model.eval()
    rot, pos, gen_v, real_v = [], [], [], []
    styles = model.config.styles
    for c in clips:
        t = c.num_frames - c.num_frames % TIME_FACTOR
        if t < TIME_FACTOR:
            continue
        f = torch.from_numpy(c.features[:t]).T[None]
        y = torch.from_numpy(c.poses[:t]).T[None]
        gen = torch.Generator().manual_seed(0)
        p = model(f, torch.tensor([styles.index(c.style)]), model.noise(1, t // TIME_FACTOR, gen))
        rot.append(float(losses.rotation_l1(p, y)))
        jp, jt = joint_positions(p, offsets), joint_positions(y, offsets)
        pos.append(float((jp - jt).abs().mean()))
        gen_v.append(jp.diff(dim=1).reshape(-1, 3))
        real_v.append(jt.diff(dim=1).reshape(-1, 3))
    model.train()
    energy = float(torch.cat(gen_v).std() / torch.cat(real_v).std().clamp_min(1e-9))
    return {"val_rot_l1": float(np.mean(rot)), "val_pos_l1_m": float(np.mean(pos)), "val_energy": energy}


LOSS_PANELS = (("L1 reconstruction", ("loss_rot", "loss_pos"), True),
               ("GAN (BCE)", ("loss_g_gan", "loss_d"), False),
               ("validation", ("val_rot_l1", "val_pos_l1_m", "val_energy"), False))


def train_gcn(cfg: TrainConfig, data_root: str | Path, out_dir: str | Path, cache_dir: str | Path | None = None,
              progress: bool = True) -> Path:
    """Train the ``gcn`` model on the DWM dataset at ``data_root``; returns ``out_dir/best.pt``."""
    from tqdm import tqdm

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(cfg.threads)
    seed_all(cfg.seed)
    fcfg = FeatureConfig(**cfg.features)
    opts, net_cfg = GCNTrainOptions.pop_from(dict(cfg.model_config))
    if cfg.segment % TIME_FACTOR:
        raise ConfigError(f"gcn segments must be a multiple of {TIME_FACTOR} frames, got {cfg.segment}")

    names = [d.name for d in dance_dirs(data_root)]
    train_names, val_names = split_names(names)
    song_names = list(train_names)  # the classifier hears every training song: motion timing is irrelevant to it
    if cfg.exclude_unverified:
        train_names = [n for n in train_names if n not in UNVERIFIED_ALIGNMENT]

    model = build_model("gcn", {**net_cfg, "feature_dim": fcfg.dim, "pose_dim": POSE_DIM})
    assert isinstance(model, GCNDancer)
    disc = GCNDiscriminator(model.config)
    styles = model.config.styles
    gen_params = [p for n, p in model.named_parameters() if not n.startswith("style_net.")]
    opt_g = torch.optim.Adam(gen_params, lr=cfg.lr, betas=(cfg.beta1, 0.999))
    opt_d = torch.optim.Adam(disc.parameters(), lr=cfg.lr * opts.disc_lr_factor, betas=(cfg.beta1, 0.999))
    offsets = torch.from_numpy(load_default_skeleton().offsets).float()

    state_path = out / "state.pt"
    runlog = RunLog(out, LOG_FIELDS, LOSS_PANELS)
    rng = np.random.default_rng(cfg.seed)
    parts = {"model": model, "disc": disc, "opt_g": opt_g, "opt_d": opt_d}
    st = resume_or_start(state_path, parts, rng, runlog)
    step, clf_report = st["step"], st.get("classifier")
    (out / "config.json").write_text(json.dumps({"train": cfg.to_dict(), "data": str(data_root),
                                                 "train_dances": train_names, "val_dances": val_names}, indent=1))

    # -- stage 0: the music style classifier (once; kept in classifier.pt and state.pt)
    clf_path = out / "classifier.pt"
    if clf_report is None and clf_path.exists():
        st = torch.load(clf_path, weights_only=False)
        model.style_net.load_state_dict(st["style_net"])
        clf_report = st["report"]
        print(f"music style classifier from {clf_path}")
    if clf_report is None:
        rate = model.config.audio_rate
        t0 = time.perf_counter()
        train_songs = song_audio(data_root, song_names, rate, cache_dir, progress)
        val_songs = song_audio(data_root, val_names, rate, cache_dir, progress)
        hist = train_music_classifier(model, train_songs, opts, cfg.seed, progress)
        clf_report = {**classifier_accuracy(model, val_songs), "train_steps": opts.classifier_steps,
                      "final_train_loss": float(np.mean(hist[-20:])), "seconds": round(time.perf_counter() - t0, 1),
                      "train_songs": song_names, "val_songs": val_names}
        del train_songs, val_songs
        torch.save({"style_net": model.style_net.state_dict(), "report": clf_report}, clf_path)
        print(f"music style classifier: validation window accuracy {clf_report['window_accuracy']:.3f} "
              f"({clf_report['windows']} windows), per style {clf_report['per_style']}, "
              f"song majority accuracy {clf_report['song_accuracy']:.2f}")
    (out / "style_classifier.json").write_text(json.dumps(clf_report, indent=1) + "\n")
    for p in model.style_net.parameters():
        p.requires_grad_(False)

    train_clips = build_corpus(data_root, train_names, fcfg, tuple(cfg.tempos), cache_dir, progress)
    val_clips = build_corpus(data_root, val_names, fcfg, (1.0,), cache_dir, progress)
    sampler = StyledSampler(train_clips, cfg.segment, rng, styles)

    meta = dict(model_name="gcn", generator_config=model.config,
                feature_config={**fcfg.to_dict(), "fingerprint": fcfg.fingerprint()},
                rig={"bones": list(BONES), "pose_dim": POSE_DIM})
    clf_summary = {k: clf_report[k] for k in ("window_accuracy", "windows", "per_style", "song_accuracy")}

    def save(path: Path, extra: dict) -> None:
        save_checkpoint(path, model, extra={"step": step, "val_dances": val_names,
                                            "style_classifier": clf_summary, **extra}, **meta)

    model.train()
    model.style_net.eval()
    disc.train()
    t0_steps = cfg.segment // TIME_FACTOR
    bar = tqdm(total=cfg.total_steps, initial=step, desc="train gcn", unit="step", disable=not progress)
    t_last, frames = time.perf_counter(), 0
    while step < cfg.total_steps:
        gan = step >= cfg.stage1_steps and cfg.w_gan > 0
        feats, real, style = sampler.sample_styled(cfg.batch_size)
        row: dict[str, object] = {"step": step + 1, "stage": 2 if gan else 1}
        row.update(gan_step(model, disc, opt_g, opt_d, feats, real, style[:, None].expand(-1, t0_steps), offsets,
                            gan=gan, w_rot=cfg.w_rot, w_fk=cfg.w_fk, w_gan=cfg.w_gan))
        step += 1
        frames += cfg.batch_size * cfg.segment
        l_rot, l_pos = row["loss_rot"], row["loss_pos"]
        last = step == cfg.total_steps
        if step % cfg.eval_every == 0 or last:
            now = time.perf_counter()
            row["frames_per_s"] = frames / (now - t_last)
            t_last, frames = now, 0
            row.update(validate(model, val_clips, offsets))
            model.style_net.eval()
            save(out / "last.pt", {k: row[k] for k in ("val_rot_l1", "val_pos_l1_m", "val_energy")})
            shutil.copyfile(out / "last.pt", out / "best.pt")  # a GAN has no model selection here
            save_state(state_path, parts, rng, step=step, classifier=clf_report)
        runlog.append(row)
        if step % cfg.eval_every == 0 or last:
            runlog.plot()
        bar.set_postfix(rot=f"{l_rot.item():.4f}", pos=f"{l_pos.item():.4f}",
                        **({"d": f"{row['loss_d']:.3f}"} if gan else {}))
        bar.update(1)
    bar.close()
    return out / "best.pt"
