"""Training of the dancing performer (``dance_vq``): motion codebook, then code predictor.

``performer train --config configs/dance_vq.toml`` dispatches here from
:func:`models.training.train.train`. Two stages, one run:

1. **Codebook** (``stage1_steps``): the motion VQ-VAE (encoder, EMA codebook, causal
   decoder) learns to rebuild ``vq_segment``-frame windows of the dancers' motion: L1 of
   the standardised pose, L1 of the forward-kinematics positions (metres, ``w_fk``), L1
   of their velocities and accelerations (``w_vel``, ``w_acc``: the decoder's output
   must be as smooth as the mocap) and the commitment loss (``w_commit``). Motion only,
   so it reads every training dance, those whose music alignment is unverified too, at
   tempo 1 (and the verified ones at every tempo factor).
2. **Predictor** (``stage2_steps``): the dances are encoded into codes at each of the
   ``seg`` grid phases; the causal Transformer learns ``p(code k | audio <= 8k, codes <
   k, style)`` by cross-entropy on ``window_codes``-step windows of the verified dances.
   Its fed-back codes are replaced by random ones with probability ``pred_noise`` (so a
   wrong code of its own does not derail it) and its style token is "auto" with
   probability ``auto_prob`` (so it learns the style from the music as well as on request).

Outputs in ``out_dir`` as the other trainers: ``last.pt`` / ``best.pt`` (the final model:
no validation number ranks sampled dances; docs/training.md shows how they were judged),
``state.pt`` (resume), ``log.csv``, ``losses.png``, ``config.json``.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from models.errors import ConfigError, DataError
from models.networks.dance_vq import DanceVQ, STYLE_TOKEN
from models.training.resume import resume_or_start, save_state
from models.training.runlog import RunLog
from models.rig.travel import window_travel  # noqa: F401  (a window's travel; the library's too)

LOG_FIELDS = ("step", "stage", "loss_pose", "loss_fk", "loss_vel", "loss_acc", "loss_commit", "perplexity",
              "loss_ce", "acc", "val_pose_l1", "val_fk_m", "val_perplexity", "val_ce", "val_acc", "frames_per_s")
LOSS_PANELS = (("codebook losses", ("loss_pose", "loss_fk", "loss_vel", "loss_acc", "loss_commit"), True),
               ("predictor cross-entropy", ("loss_ce",), False),
               ("validation codebook", ("val_pose_l1", "val_fk_m"), True),
               ("validation predictor", ("val_ce", "val_acc"), False),
               ("code use (perplexity)", ("perplexity", "val_perplexity"), False))


@dataclass(frozen=True)
class DanceVQTrainOptions:
    """The ``[dance]`` table of a training config (defaults in brackets)."""

    vq_segment: int = 128  # frames per codebook training window
    w_fk: float = 10.0  # forward-kinematics position L1, metres
    w_vel: float = 2.0  # velocity L1 (standardised pose and FK positions)
    w_acc: float = 2.0  # acceleration L1
    w_commit: float = 0.25
    vq_lr: float = 3e-4
    pred_lr: float = 3e-4
    pred_batch: int = 64
    pred_noise: float = 0.1  # probability that a fed-back code is replaced by a random one
    auto_prob: float = 0.4  # probability that a window's style token is "auto" (0)
    grad_clip: float = 1.0
    presence_minutes: float = 60.0  # synthetic programmes the presence detector learns from (0: none)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "DanceVQTrainOptions":
        known = set(cls.__dataclass_fields__)
        if set(d) - known:
            raise ConfigError(f"unknown [dance] option(s) {sorted(set(d) - known)}; known: {sorted(known)}")
        opts = cls(**d)
        if opts.vq_segment < 16 or opts.vq_segment % 16 or not 0 <= opts.pred_noise < 1 or not 0 <= opts.auto_prob <= 1:
            raise ConfigError(f"[dance] needs vq_segment a multiple of 16 and probabilities in [0, 1): {opts}")
        return opts


def set_statistics(model: DanceVQ, clips: list, fcfg, rng: np.random.Generator, progress: bool = False) -> None:
    """Pose / feature mean and std from the training clips, then the music detector of the idle gate.

    Silence: the log frame energy must be above its 0.5th percentile in the training songs
    minus 3. Noise without music (applause, crowd, room): :func:`fit_music_gate`.
    """
    poses = np.concatenate([c.poses for c in clips])
    feats = np.concatenate([c.features for c in clips])
    with torch.no_grad():
        model.pose_mean.copy_(torch.from_numpy(poses.mean(0)))
        model.pose_std.copy_(torch.from_numpy(np.maximum(poses.std(0), 0.02)))
        model.feat_mean.copy_(torch.from_numpy(feats.mean(0)))
        model.feat_std.copy_(torch.from_numpy(np.maximum(feats.std(0), 1e-3)))
        c = model.config
        energy = float(np.percentile(feats[:, c.energy_col], 0.5)) - 3.0 if 0 <= c.energy_col < c.feature_dim else -1e9
        model.gate[0] = energy
    if fcfg.beat_phase and fcfg.kind in ("mfcc", "mfcc_onset"):
        fit_music_gate(model, [c.features for c in clips if c.tempo == 1.0], fcfg, rng, progress)


def synthetic_noise(kind: str, seconds: float, rng: np.random.Generator, sr: int = 22050) -> np.ndarray:
    """Audio (n,) float32 at ``sr`` Hz of what plays between songs: "white", "pink", "brown",
    "applause" (random claps, 5-40 a second, over a noise bed), "crowd" (band-limited noise whose
    level moves at syllable rate, 2-6 Hz) or "room" (faint noise); level drawn at random."""
    from scipy.signal import lfilter

    n = int(seconds * sr)
    w = rng.standard_normal(n)
    if kind == "pink":
        x = lfilter([0.049922035, -0.095993537, 0.050612699, -0.004408786], [1, -2.494956002, 2.017265875, -0.522189400], w)
    elif kind == "brown":
        x = lfilter([1.0], [1, -0.995], w)
    elif kind == "applause":
        x = 0.05 * w
        rate = rng.uniform(5, 40)
        clap = int(0.012 * sr)
        env = np.exp(-np.arange(clap) / (0.002 * sr))
        for t in rng.uniform(0, seconds, int(rate * seconds)):
            i = int(t * sr)
            if i + clap < n:
                x[i: i + clap] += rng.uniform(0.2, 1.0) * rng.standard_normal(clap) * env
    elif kind == "crowd":
        band = lfilter([1.0], [1, -1.6, 0.7], w)
        x = band * (1.2 + np.sin(2 * np.pi * np.cumsum(rng.uniform(2, 6, n)) / sr))
    elif kind in ("white", "room"):
        x = w
    else:
        raise ConfigError(f"unknown noise kind {kind!r}")
    gain = rng.uniform(0.001, 0.003) if kind == "room" else 10 ** rng.uniform(-2.5, -0.5)
    return (gain * x / max(np.abs(x).max(), 1e-9)).astype(np.float32)


NOISE_KINDS: tuple[str, ...] = ("white", "pink", "brown", "applause", "crowd", "room")


def gate_inputs(model: DanceVQ, features: np.ndarray) -> np.ndarray:
    """The music detector's inputs (T, 13) for a stream's features (T, D): the running mean
    (time constant GATE_TAU frames, from 0) of the standardised MFCC 1-12 and pulse clarity."""
    from scipy.signal import lfilter

    from models.networks.dance_vq import GATE_MFCC, GATE_TAU

    cols = [*GATE_MFCC, model.config.clarity_col]
    z = (features[:, cols] - model.feat_mean.numpy()[cols]) / model.feat_std.numpy()[cols]
    a = float(np.exp(-1.0 / GATE_TAU))
    return lfilter([1 - a], [1, -a], z, axis=0).astype(np.float32)


def fit_music_gate(model: DanceVQ, songs: list[np.ndarray], fcfg, rng: np.random.Generator,
                   progress: bool = False, seconds: float = 20.0, per_kind: int = 6) -> dict[str, float]:
    """Fit the idle gate's logistic music detector: training songs' features (positives)
    against :func:`synthetic_noise` of every kind (negatives, ``per_kind`` clips of
    ``seconds``), classes weighted equally; stores weights and bias in the model and returns
    the training accuracy on each class."""
    from models.features.spectral import extract_features

    neg = [extract_features(synthetic_noise(k, seconds, rng), fcfg) for k in NOISE_KINDS for _ in range(per_kind)]
    xp = np.concatenate([gate_inputs(model, f)[30:] for f in songs])
    xn = np.concatenate([gate_inputs(model, f)[30:] for f in neg])
    x = torch.from_numpy(np.concatenate([xp, xn]))
    y = torch.cat([torch.ones(len(xp)), torch.zeros(len(xn))])
    wt = torch.cat([torch.full((len(xp),), 0.5 / len(xp)), torch.full((len(xn),), 0.5 / len(xn))])
    lin = torch.nn.Linear(x.shape[1], 1)
    opt = torch.optim.LBFGS(lin.parameters(), max_iter=200, line_search_fn="strong_wolfe")

    def closure() -> torch.Tensor:
        opt.zero_grad()
        loss = (wt * F.binary_cross_entropy_with_logits(lin(x)[:, 0], y, reduction="none")).sum() + 1e-4 * lin.weight.pow(2).sum()
        loss.backward()
        return loss

    opt.step(closure)
    with torch.no_grad():
        model.gate_w.copy_(lin.weight[0])
        model.gate[1] = lin.bias[0]
        pred = lin(x)[:, 0] > 0
    acc = {"music_acc": float(pred[: len(xp)].float().mean()), "noise_acc": float((~pred[len(xp):]).float().mean())}
    if progress:
        print(f"music detector: {acc['music_acc']:.3f} of song frames, {acc['noise_acc']:.3f} of noise frames right")
    return acc


def window_starts(clips: list, length: int) -> list[tuple[int, int]]:
    """(clip index, start frame) of every window of ``length`` valid frames, every 8 frames."""
    out = []
    for i, c in enumerate(clips):
        bad = np.concatenate([[0], np.cumsum(~c.valid)])
        for s in range(0, c.num_frames - length + 1, 8):
            if bad[s + length] == bad[s]:
                out.append((i, s))
    return out


def codebook_step(model: DanceVQ, batch: torch.Tensor, offsets: torch.Tensor, opts: DanceVQTrainOptions,
                  opt: torch.optim.Optimizer) -> dict[str, float]:
    """One VQ-VAE step on poses (B, T, P); returns the losses."""
    from models.rig.kinematics import fk_torch

    rec, codes, commit = model.reconstruct(batch)
    target = model.standardize_poses(batch)
    pose = model.destandardize_poses(rec)
    b, t, _ = batch.shape
    p_rec = fk_torch(pose[..., :3], pose[..., 3:].unflatten(-1, (-1, 4)), offsets)
    p_tgt = fk_torch(batch[..., :3], batch[..., 3:].unflatten(-1, (-1, 4)), offsets)
    l_pose = F.l1_loss(rec, target)
    l_fk = F.l1_loss(p_rec, p_tgt)
    d1 = lambda x: x[:, 1:] - x[:, :-1]  # noqa: E731
    l_vel = F.l1_loss(d1(rec), d1(target)) + 10 * F.l1_loss(d1(p_rec), d1(p_tgt))
    l_acc = F.l1_loss(d1(d1(rec)), d1(d1(target))) + 10 * F.l1_loss(d1(d1(p_rec)), d1(d1(p_tgt)))
    loss = l_pose + opts.w_fk * l_fk + opts.w_vel * l_vel + opts.w_acc * l_acc + opts.w_commit * commit
    opt.zero_grad(set_to_none=True)
    loss.backward()
    torch.nn.utils.clip_grad_norm_([p for g in opt.param_groups for p in g["params"]], opts.grad_clip)
    opt.step()
    return {"loss_pose": l_pose.item(), "loss_fk": l_fk.item(), "loss_vel": l_vel.item(), "loss_acc": l_acc.item(),
            "loss_commit": commit.item(), "perplexity": perplexity(codes, model.config.codebook)}


def perplexity(codes: torch.Tensor, k: int) -> float:
    """exp(entropy) of the code histogram: how many codes are in use."""
    p = torch.bincount(codes.reshape(-1), minlength=k).float()
    p = p / p.sum()
    return float(torch.exp(-(p[p > 0] * p[p > 0].log()).sum()))


@torch.no_grad()
def validate_codebook(model: DanceVQ, clips: list, offsets: torch.Tensor) -> dict[str, float]:
    """Reconstruction of whole validation clips: standardised pose L1, FK position L1 (m), perplexity."""
    from models.rig.kinematics import fk_torch

    model.eval()
    pl, fl, codes_all, n = 0.0, 0.0, [], 0
    s = model.config.seg
    for c in clips:
        t = (c.num_frames // s) * s
        x = torch.from_numpy(c.poses[:t])[None]
        rec, codes, _ = model.reconstruct(x)
        pose = model.destandardize_poses(rec)
        pl += F.l1_loss(rec, model.standardize_poses(x), reduction="sum").item() / x.shape[-1]
        fl += F.l1_loss(fk_torch(pose[..., :3], pose[..., 3:].unflatten(-1, (-1, 4)), offsets),
                        fk_torch(x[..., :3], x[..., 3:].unflatten(-1, (-1, 4)), offsets), reduction="sum").item() / 63
        n += t
        codes_all.append(codes.reshape(-1))
    model.train()
    return {"val_pose_l1": pl / n, "val_fk_m": fl / n,
            "val_perplexity": perplexity(torch.cat(codes_all), model.config.codebook)}


def clip_periods(model: DanceVQ, clips: list) -> dict[int, float]:
    """The beat period (frames at 30 fps, in the performer's tempo range) of each clip's music,
    by ``id(clip)``: :func:`models.networks.tempo.song_period` of the song at its own tempo
    (its tempo-1 clip's beat columns, where there is one), divided by the clip's tempo factor,
    so every stretched copy of a song gets the same octave. 0 where the model has no beat
    columns or the pulse is never clear."""
    from models.networks.tempo import fold_period, song_period

    cc = model.config.clarity_col
    if not (0 <= cc and cc + 1 < model.config.feature_dim):
        return {id(c): 0.0 for c in clips}
    own = {c.name: c for c in clips if c.tempo == 1.0}
    out = {}
    for c in clips:
        src = own.get(c.name, c)
        oc = model.config.onset_col
        onset = src.features[:, oc] if 0 <= oc < model.config.feature_dim else None
        base = song_period(src.features[:, cc + 1], src.features[:, cc], onset) * (src.tempo if src is c else 1.0)
        out[id(c)] = fold_period(base / c.tempo) if base > 0 else 0.0
    return out


@torch.no_grad()
def fit_members(model: DanceVQ, clips: list, phases: tuple[int, ...] = (0, 4), progress: bool = False,
                travel: list | None = None) -> dict[str, float]:
    """Fill the choreographic memory: for every code, the ``members`` real windows of
    ``2 * seg`` valid frames (the code's movement and its continuation) whose encoding
    lies nearest the code vector, from every clip at the grid ``phases``, and each member's
    style token (``member_style``: the style of the dance it comes from). ``travel``: per
    clip its root track (T, 3: x, z, unwrapped heading of the motion before canonicalisation,
    models.training.travel_memory), which fills ``member_travel`` (:func:`window_travel`;
    None: zeros, in place). Returns how many codes got at least one member and how many
    windows were searched."""
    model.eval()
    c = model.config
    s = c.seg
    z_all, windows, styles, periods, travels = [], [], [], [], []
    period = clip_periods(model, clips)
    for ci, clip in enumerate(clips):
        for p in phases:
            n = (clip.num_frames - p) // s
            if n < 3:
                continue
            z = model.encoder(model.standardize_poses(torch.from_numpy(clip.poses[p: p + n * s])[None]))[0].T  # (n, C)
            ok = np.array([clip.valid[p + k * s: p + (k + 2) * s].all() for k in range(n - 1)])
            for k in np.flatnonzero(ok):
                z_all.append(z[k])
                windows.append(clip.poses[p + k * s: p + (k + 2) * s])
                styles.append(STYLE_TOKEN.get(clip.style, 0))
                periods.append(period[id(clip)])
                if travel is not None:
                    travels.append(window_travel(travel[ci][p + k * s: p + (k + 2) * s]))
    z = torch.stack(z_all)
    codes = model.quantizer.codes(z.T[None])[0]
    dist = (z - model.quantizer.embed[codes]).pow(2).sum(1)
    poses = np.stack(windows)
    style = torch.tensor(styles, dtype=torch.int64)
    period_t = torch.tensor(periods, dtype=torch.float32)
    travel_t = torch.from_numpy(np.stack(travels)) if travel is not None else None
    model.member_poses.zero_()
    model.member_count.zero_()
    model.member_style.zero_()
    model.member_period.zero_()
    model.member_travel.zero_()
    for code in codes.unique().tolist():
        idx = torch.nonzero(codes == code)[:, 0]
        keep = idx[dist[idx].argsort()[: c.members]].numpy()
        model.member_poses[code, : len(keep)] = torch.from_numpy(poses[keep]).half()
        model.member_count[code] = len(keep)
        model.member_style[code, : len(keep)] = style[keep]
        model.member_period[code, : len(keep)] = period_t[keep]
        if travel_t is not None:
            model.member_travel[code, : len(keep)] = travel_t[keep].half()
    have = torch.nonzero(model.member_count > 0)[:, 0]
    emb = model.quantizer.embed
    for code in torch.nonzero(model.member_count == 0)[:, 0].tolist():  # a code no window chose: its nearest neighbour's
        near = have[(emb[have] - emb[code]).pow(2).sum(1).argmin()]
        model.member_poses[code] = model.member_poses[near]
        model.member_count[code] = model.member_count[near]
        model.member_style[code] = model.member_style[near]
        model.member_period[code] = model.member_period[near]
        model.member_travel[code] = model.member_travel[near]
    model.train()
    out = {"codes_with_members": len(have), "windows": len(windows)}
    if progress:
        print(f"choreographic memory: {out['codes_with_members']} codes with real exemplars from {len(windows)} windows")
    return out


#: Style tokens the style prior has a column for (cha-cha, rumba, waltz); token 0 ("auto") stays 0.
PRIOR_STYLES: tuple[int, ...] = (STYLE_TOKEN["C"], STYLE_TOKEN["R"], STYLE_TOKEN["W"])


def style_counts(model: DanceVQ, clips: list) -> np.ndarray:
    """(K, 4) int: per code, how many valid ``seg``-frame windows of each style token's clips
    the model's encoder maps to it, at every grid phase."""
    data = encode_clips(model, clips, range(model.config.seg))
    counts = np.zeros((model.config.codebook, 4), np.int64)
    for codes, valid, style in zip(data.codes, data.valid, data.style):
        np.add.at(counts[:, style], codes[valid], 1)
    return counts


def prior_from_counts(counts: np.ndarray) -> np.ndarray:
    """(K, 4) float32 ``log p(style | code)`` under equal style priors: ``p(code | style) =
    (n + 1) / (N_style + K)`` (add-one smoothing) normalised over the styles of
    :data:`PRIOR_STYLES` that have windows; column 0 and styles without windows are 0."""
    k = counts.shape[0]
    out = np.zeros(counts.shape, np.float64)
    have = [s for s in PRIOR_STYLES if counts[:, s].sum() > 0]
    if have:
        lik = np.stack([(counts[:, s] + 1.0) / (counts[:, s].sum() + k) for s in have], axis=1)
        out[:, have] = np.log(lik / lik.sum(axis=1, keepdims=True))
    return out.astype(np.float32)


@torch.no_grad()
def fit_style_prior(model: DanceVQ, clips: list) -> np.ndarray:
    """Set ``model.style_prior`` (how much likelier each code is in each style's dances) from
    ``clips``, the motion the codebook learned from; returns the counts (K, 4)."""
    counts = style_counts(model, clips)
    model.style_prior.copy_(torch.from_numpy(prior_from_counts(counts)))
    return counts


@dataclass
class CodeSet:
    """Per (clip, phase): audio tokens (N, seg * D), codes (N,), code validity (N,), style token, and
    for a predictor that hears the tempo each token's ln(T / T_ref) (N,) (models.training.tempo_predictor;
    None: not heard)."""

    tokens: list[np.ndarray]
    codes: list[np.ndarray]
    valid: list[np.ndarray]
    style: list[int]
    tempo: list[np.ndarray] | None = None


@torch.no_grad()
def encode_clips(model: DanceVQ, clips: list, phases: range) -> CodeSet:
    """Every clip encoded at every grid phase (code k of phase p covers frames p + 8k .. p + 8k + 7)."""
    model.eval()
    s, d = model.config.seg, model.config.feature_dim
    out = CodeSet([], [], [], [])
    for c in clips:
        x = (c.features[:, :d] - model.feat_mean.numpy()) / model.feat_std.numpy()  # columns past d: the gate's
        padded = np.concatenate([np.zeros((s - 1, d), np.float32), x.astype(np.float32)])
        for p in phases:
            n = (c.num_frames - p) // s
            if n < 2:
                continue
            codes = model.encode(torch.from_numpy(c.poses[p: p + n * s])[None])[0].numpy()
            idx = p + s * np.arange(n)[:, None] + np.arange(s)[None]  # padded row of frame f - s + 1 .. f is f .. f + s - 1
            out.tokens.append(padded[idx].reshape(n, s * d))
            out.codes.append(codes)
            out.valid.append(c.valid[p: p + n * s].reshape(n, s).all(1))
            out.style.append(STYLE_TOKEN[c.style])
    model.train()
    return out


def predictor_batch(data: CodeSet, n: int, batch: int, k: int, opts: DanceVQTrainOptions | None,
                    rng: np.random.Generator) -> tuple[torch.Tensor, ...]:
    """A batch of ``n``-step windows: (audio, prev codes, style, target codes, mask), and where ``data``
    has tempo inputs their windows (B, n) last. ``opts`` None: no noise, auto style."""
    long = [i for i in range(len(data.codes)) if len(data.codes[i]) >= n]
    pick = rng.choice(long, batch)
    a, prev, tgt, mask, sty, tempo = [], [], [], [], [], []
    for i in pick:
        k0 = int(rng.integers(0, len(data.codes[i]) - n + 1))
        codes = data.codes[i]
        p = np.concatenate([[k], codes])[k0: k0 + n].copy()  # code before each step; k = none (stream start)
        if opts is not None and opts.pred_noise > 0:
            flip = rng.random(n) < opts.pred_noise
            p[flip] = rng.integers(0, k, int(flip.sum()))
        a.append(data.tokens[i][k0: k0 + n])
        prev.append(p)
        tgt.append(codes[k0: k0 + n])
        mask.append(data.valid[i][k0: k0 + n])
        if data.tempo is not None:
            tempo.append(data.tempo[i][k0: k0 + n])
        auto = opts is None or rng.random() < opts.auto_prob
        sty.append(0 if auto else data.style[i])
    out = (torch.from_numpy(np.stack(a)), torch.from_numpy(np.stack(prev)).long(), torch.tensor(sty),
           torch.from_numpy(np.stack(tgt)).long(), torch.from_numpy(np.stack(mask)))
    return (*out, torch.from_numpy(np.stack(tempo))) if tempo else out


def predictor_loss(model: DanceVQ, batch: tuple[torch.Tensor, ...]) -> tuple[torch.Tensor, float]:
    """Masked cross-entropy of the next code, and the accuracy (``batch``: :func:`predictor_batch`'s)."""
    audio, prev, style, tgt, mask = batch[:5]
    logits = model.predictor(audio, prev, style, batch[5] if len(batch) > 5 else None)
    ce = F.cross_entropy(logits.reshape(-1, logits.shape[-1]), tgt.reshape(-1), reduction="none")
    m = mask.reshape(-1).float()
    acc = ((logits.argmax(-1).reshape(-1) == tgt.reshape(-1)).float() * m).sum() / m.sum().clamp_min(1)
    return (ce * m).sum() / m.sum().clamp_min(1), float(acc)


def predictor_step(model: DanceVQ, codes: CodeSet, opts: DanceVQTrainOptions, opt: torch.optim.Optimizer,
                   rng: np.random.Generator) -> dict[str, float]:
    """One stage-2 step of the predictor on a :func:`predictor_batch` of ``codes``; returns its loss and accuracy."""
    model.encoder.eval()
    loss, acc = predictor_loss(model, predictor_batch(codes, model.config.window_codes, opts.pred_batch,
                                                      model.config.codebook, opts, rng))
    opt.zero_grad(set_to_none=True)
    loss.backward()
    torch.nn.utils.clip_grad_norm_(model.predictor.parameters(), opts.grad_clip)
    opt.step()
    return {"loss_ce": loss.item(), "acc": acc}


@torch.no_grad()
def validate_predictor(model: DanceVQ, val_codes: CodeSet) -> dict[str, float]:
    """Cross-entropy and accuracy of the next code on 256 fixed windows of ``val_codes`` (auto style, no noise)."""
    model.eval()
    ce, acc = predictor_loss(model, predictor_batch(val_codes, model.config.window_codes, 256,
                                                    model.config.codebook, None, np.random.default_rng(0)))
    model.train()
    return {"val_ce": ce.item(), "val_acc": acc}


def training_dances(cfg, data_root: str | Path) -> tuple[list[str], list[str], list[str]]:
    """(training dances whose audio alignment is trusted, the other training dances, the
    validation dances) of ``data_root`` under ``cfg.exclude_unverified``."""
    from models.data.alignment import UNVERIFIED_ALIGNMENT
    from models.data.dwm import dance_dirs
    from models.data.split import split_names

    train_names, val_names = split_names([d.name for d in dance_dirs(data_root)])
    verified = [n for n in train_names if n not in UNVERIFIED_ALIGNMENT] if cfg.exclude_unverified else train_names
    return verified, [n for n in train_names if n not in verified], val_names


def training_clips(cfg, fcfg, data_root: str | Path, cache_dir: str | Path | None, progress: bool) -> tuple[list, list]:
    """(the predictor's clips: the trusted dances at every tempo of ``cfg.tempos``; the motion
    clips the codebook and its memory learn from: those plus the other training dances at
    tempo 1)."""
    from models.data.corpus import build_corpus

    verified, others, _ = training_dances(cfg, data_root)
    train_clips = build_corpus(data_root, verified, fcfg, tuple(cfg.tempos), cache_dir, progress)
    return train_clips, train_clips + build_corpus(data_root, others, fcfg, (1.0,), cache_dir, progress)


def train_dance_vq(cfg, data_root: str | Path, out_dir: str | Path, cache_dir: str | Path | None = None,
                   progress: bool = True) -> Path:
    """Train ``dance_vq`` (``cfg``: :class:`~models.training.config.TrainConfig`) on DWM; returns ``best.pt``."""
    from tqdm import tqdm

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
    opts = DanceVQTrainOptions.from_dict(cfg.dance)
    fcfg = FeatureConfig(**cfg.features)

    verified, others, val_names = training_dances(cfg, data_root)
    train_clips, motion_clips = training_clips(cfg, fcfg, data_root, cache_dir, progress)
    val_clips = build_corpus(data_root, val_names, fcfg, (1.0,), cache_dir, progress)

    model_cfg = {**cfg.model_config, "feature_dim": fcfg.dim, "pose_dim": POSE_DIM}
    if fcfg.beat_phase and "clarity_col" not in cfg.model_config:
        model_cfg["clarity_col"] = fcfg.dim - 2  # [base | context | c cos, c sin, c, log2 P/15]
    if fcfg.beat_phase and "onset_col" not in cfg.model_config:
        model_cfg["onset_col"] = fcfg.base_dim - 1  # the onset kinds' last base column
    model: DanceVQ = build_model("dance_vq", model_cfg)  # type: ignore[assignment]
    rng = np.random.default_rng(cfg.seed)
    set_statistics(model, motion_clips, fcfg, rng, progress)
    if opts.presence_minutes > 0 and fcfg.kind == "mfcc_onset" and fcfg.beat_phase:  # models.training.music_gate
        from models.training.music_gate import fit_presence, song_audio, training_songs

        fit_presence(model, fcfg, song_audio(data_root, training_songs(data_root)), np.random.default_rng(cfg.seed),
                     opts.presence_minutes, progress)
    starts = window_starts(motion_clips, opts.vq_segment)
    if len(starts) < cfg.batch_size:
        raise DataError(f"only {len(starts)} valid {opts.vq_segment}-frame windows in the training dances")
    vq_params = [*model.encoder.parameters(), *model.decoder.parameters()]
    opt_vq = torch.optim.Adam(vq_params, lr=opts.vq_lr)
    opt_pred = torch.optim.AdamW(model.predictor.parameters(), lr=opts.pred_lr, weight_decay=0.01)
    offsets = torch.from_numpy(load_default_skeleton().offsets).float()

    state_path = out / "state.pt"
    runlog = RunLog(out, LOG_FIELDS, LOSS_PANELS)
    parts = {"model": model, "opt_vq": opt_vq, "opt_pred": opt_pred}
    step = resume_or_start(state_path, parts, rng, runlog)["step"]
    (out / "config.json").write_text(json.dumps({
        "train": cfg.to_dict(), "dance": asdict(opts), "data": str(data_root), "train_dances": verified,
        "motion_only_dances": others, "val_dances": val_names, "vq_windows": len(starts)}, indent=1))
    meta = dict(model_name="dance_vq", generator_config=model.config,
                feature_config={**fcfg.to_dict(), "fingerprint": fcfg.fingerprint()},
                rig={"bones": list(BONES), "pose_dim": POSE_DIM})

    def save(path: Path, extra: dict) -> None:
        save_checkpoint(path, model, extra={"step": step, "val_dances": val_names, **extra}, **meta)

    model.train()
    codes = val_codes = None
    bar = tqdm(total=cfg.total_steps, initial=step, desc="train dance_vq", unit="step", disable=not progress)
    t_last, frames = time.perf_counter(), 0
    while step < cfg.total_steps:
        stage = 1 if step < cfg.stage1_steps else 2
        if stage == 1:
            pick = rng.choice(len(starts), cfg.batch_size)
            batch = torch.from_numpy(np.stack([motion_clips[starts[i][0]].poses[starts[i][1]: starts[i][1] + opts.vq_segment]
                                               for i in pick]))
            row: dict[str, object] = codebook_step(model, batch, offsets, opts, opt_vq)
            frames += cfg.batch_size * opts.vq_segment
        else:
            if codes is None:
                if model.config.members > 0 and int(model.member_count.sum()) == 0:
                    fit_members(model, motion_clips, progress=progress)
                    fit_style_prior(model, motion_clips)
                codes = encode_clips(model, train_clips, range(model.config.seg))
                val_codes = encode_clips(model, val_clips, range(1))
            row = predictor_step(model, codes, opts, opt_pred, rng)
            frames += opts.pred_batch * model.config.window_codes * model.config.seg
        step += 1
        row.update(step=step, stage=stage)
        if step % cfg.eval_every == 0 or step == cfg.total_steps or step == cfg.stage1_steps:
            now = time.perf_counter()
            row["frames_per_s"] = frames / (now - t_last)
            t_last, frames = now, 0
            if stage == 1:
                row.update(validate_codebook(model, val_clips, offsets))
            else:
                row.update(validate_predictor(model, val_codes))
            extra = {k: row[k] for k in ("val_pose_l1", "val_fk_m", "val_ce", "val_acc") if k in row}
            save(out / "last.pt", extra)
            if step == cfg.total_steps:
                save(out / "best.pt", extra)
            save_state(state_path, parts, rng, step=step)
        runlog.append(row)
        if step % cfg.eval_every == 0 or step == cfg.total_steps:
            runlog.plot()
        bar.set_postfix(stage=stage, **({"pose": f"{row['loss_pose']:.3f}"} if stage == 1 else {"ce": f"{row['loss_ce']:.2f}"}))
        bar.update(1)
    bar.close()
    return out / "best.pt"
