"""Graph-convolutional adversarial dance generator (registry name ``gcn``), after
Ferreira et al., "Learning to dance: A graph convolutional adversarial network to
generate realistic dance motions from audio", Computers & Graphics 94 (2021)
(arXiv 2011.12999).

Pieces, in the order a song goes through them:

1. **Music style classifier** (:class:`MusicStyleClassifier`): a 1-D CNN on the raw
   waveform (resampled to ``audio_rate`` = 16 kHz and mu-law companded first,
   :func:`mu_law`) that tells the DWM styles apart (C, R, W). It classifies one
   window per ``style_chunk`` latent steps (4 steps = 64 frames = 2.13 s, the
   paper's sample length); the chunk probabilities are averaged over
   ``style_smooth`` neighbouring chunks and the argmax is the style of those steps.
   So the style can change mid-song when the classifier's output changes.
2. **Latent** ``(B, C + E, T0)`` with ``T0 = N / 16`` for N frames: ``C = noise_channels``
   (512, the paper's value) channels of temporally coherent noise from a Gaussian
   process with an RBF kernel, each channel with its own length scale (log-spaced
   over ``[gp_min_scale, gp_max_scale]`` latent steps, :func:`gp_noise`), concatenated
   with a learned embedding (``E = style_dim``) of each step's style.
3. **Generator** (:class:`GCNGenerator`): spatial-temporal graph convolutions
   (:class:`STGCNBlock`, ST-GCN style: partitioned adjacency self / from parent /
   from children with learned edge importance, then a temporal conv) on a graph
   that grows from 1 node to 3, 11 and the 21 bones of the humanoid rig
   (:data:`HIERARCHY`, learned aggregation matrices initialised from the group
   membership, :class:`GraphUpsample`), and time that doubles four times with
   transposed convolutions (``T0 -> 2 T0 -> ... -> 16 T0 = N``).
4. **Output**: per rig node 7 channels; channels 0-3 are the bone's local xyzw
   quaternion (unit-normalised), channels 4-6 of the Hips node are the root
   position. That is the project's ``POSE_DIM`` layout, so FK and every metric apply.
   Offline generation smooths the track with a least-squares cubic B-spline
   (knots every ``spline_knot`` frames, :func:`spline_smooth`), the paper's
   cubic-spline post-processing.
5. **Discriminator** (:class:`GCNDiscriminator`, training only): the generator
   mirrored, 21 -> 11 -> 3 -> 1 nodes (learned pooling matrices) and time halved four
   times with strided convs, conditioned on the style embedding; it sees each bone's
   quaternion and its joint position after differentiable forward kinematics (the
   paper's discriminator saw joint positions) and gives one logit per latent step.

Adaptations, all deliberate:

* Output: the paper regresses 2-D/3-D joint positions of an OpenPose-like skeleton
  (25 nodes, spatial levels 1 -> 3 -> 11 -> 25); here the nodes are the 21 humanoid
  bones and each predicts its local rotation, so the shared rig, FK and exporters
  apply. The L1 reconstruction loss (lambda = 100) is taken on the FK joint
  positions (what the paper's L1 compared) plus the rotations (docs/gcn.md).
* Like the paper, the generator sees the music only through the style; it gets no
  per-frame audio features. ``audio_features=True`` adds them (pooled to every
  temporal level and concatenated to every node) as an option; it is off by default.
* GP length scales are in latent steps (0.53 s each), not relative to the song
  length, so a long song is as smooth as a short one.

**Not causal: offline only.** The transposed convolutions and temporal graph convs
look up to hundreds of milliseconds ahead, the GP noise is one sample over the whole
song's N/16 steps, and the style of a step is decided from a 2.13 s window around it
averaged with its neighbours. The real-time engine needs every pose to depend only
on audio already heard, so ``performer run`` refuses this model with one line
(:attr:`GCNDancer.offline_only` and ``offline_reason``, checked by
:func:`realtime.pipeline.build_pipeline`); ``performer generate`` and
``performer evaluate`` run it over the whole song (:meth:`GCNDancer.generate_poses`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from models.errors import ConfigError
from models.rig.humanoid import BONES, NUM_BONES, PARENT_INDEX
from models.rig.motion import POSE_DIM
from models.timebase import HOP, SAMPLE_RATE

#: Temporal upsampling steps of the generator: N frames = 16 latent steps.
TIME_FACTOR: int = 16
#: Channels per rig node at the output: xyzw quaternion, then root xyz (Hips only).
NODE_OUT: int = 7

# --------------------------------------------------------------------------- the rig graph

#: The spatial levels of the generator, coarse to fine: every node of level i+1
#: belongs to one node (group) of level i. Level sizes 1, 3, 11, 21 (the bones).
#: 11 groups: hips, spine+chest, neck+head, L/R shoulder+upper arm, L/R lower arm+hand,
#: L/R upper leg, L/R lower leg+foot+toes. 3 groups: core (hips, torso, head), arms, legs.
GROUPS_11: tuple[int, ...] = (0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 6, 7, 8, 8, 8, 9, 10, 10, 10)  # bone -> group
PARENT_11: tuple[int, ...] = (-1, 0, 1, 1, 3, 1, 5, 0, 7, 0, 9)
GROUPS_3: tuple[int, ...] = (0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2)  # group of 11 -> group of 3
PARENT_3: tuple[int, ...] = (-1, 0, 0)
HIERARCHY: tuple[tuple[int, tuple[int, ...], tuple[int, ...]], ...] = (
    # (nodes, parent of each node, group of each node in the previous level)
    (1, (-1,), ()),
    (3, PARENT_3, (0, 0, 0)),
    (11, PARENT_11, GROUPS_3),
    (NUM_BONES, PARENT_INDEX, GROUPS_11),
)
LEVEL_SIZES: tuple[int, ...] = tuple(h[0] for h in HIERARCHY)
assert len(GROUPS_11) == NUM_BONES == len(BONES)


def partitioned_adjacency(parents: tuple[int, ...] | list[int]) -> torch.Tensor:
    """ST-GCN spatial partitions of a tree: (3, V, V) with ``A[k, v, w]`` the weight of v -> w.

    k = 0: each node itself; 1: from its parent; 2: from its children. Columns are
    divided by the in-degree of the whole neighbourhood (self + parent + children).
    """
    v = len(parents)
    a = torch.zeros(3, v, v)
    a[0] = torch.eye(v)
    for child, par in enumerate(parents):
        if par >= 0:
            a[1, par, child] = 1.0  # the child hears its parent
            a[2, child, par] = 1.0  # the parent hears its child
    deg = a.sum(dim=(0, 1))
    return a / deg.clamp_min(1.0)


def membership(groups: tuple[int, ...] | list[int], coarse: int) -> torch.Tensor:
    """(coarse, fine) 0/1 matrix: ``M[g, i] = 1`` when fine node i belongs to coarse node g."""
    m = torch.zeros(coarse, len(groups))
    for i, g in enumerate(groups):
        m[g, i] = 1.0
    return m


# --------------------------------------------------------------------------- audio and noise


def mu_law(x: np.ndarray | torch.Tensor, mu: int = 255):
    """Mu-law companding ``sign(x) ln(1 + mu |x|) / ln(1 + mu)`` of samples in [-1, 1] (clipped)."""
    if isinstance(x, torch.Tensor):
        x = x.clamp(-1.0, 1.0)
        return torch.sign(x) * torch.log1p(mu * x.abs()) / math.log1p(mu)
    x = np.clip(np.asarray(x, dtype=np.float32), -1.0, 1.0)
    return (np.sign(x) * np.log1p(mu * np.abs(x)) / np.log1p(mu)).astype(np.float32)


def mu_law_inverse(y: np.ndarray, mu: int = 255) -> np.ndarray:
    """Inverse of :func:`mu_law`: ``sign(y) ((1 + mu)^|y| - 1) / mu``."""
    y = np.asarray(y, dtype=np.float64)
    return (np.sign(y) * ((1.0 + mu) ** np.abs(y) - 1.0) / mu).astype(np.float32)


def compand(x: np.ndarray, mu: int = 255) -> np.ndarray:
    """:func:`mu_law`, then quantised to ``mu + 1`` levels (8 bits for mu = 255), as float32 in [-1, 1]."""
    y = mu_law(x, mu)
    return (np.round((y + 1.0) * (mu / 2.0)) / (mu / 2.0) - 1.0).astype(np.float32)


def resample_to(audio: np.ndarray, rate: int) -> np.ndarray:
    """Mono audio at 22050 Hz -> ``rate`` Hz (polyphase, scipy.signal.resample_poly)."""
    from scipy.signal import resample_poly

    x = np.asarray(audio, dtype=np.float32)
    if rate == SAMPLE_RATE:
        return x
    g = math.gcd(rate, SAMPLE_RATE)
    return resample_poly(x, rate // g, SAMPLE_RATE // g).astype(np.float32)


def prepare_audio(audio: np.ndarray, rate: int, mu: int = 255) -> np.ndarray:
    """The classifier's input: mono audio at 22050 Hz -> ``rate`` Hz -> :func:`compand`."""
    return compand(resample_to(audio, rate), mu)


def length_scales(channels: int, lo: float, hi: float) -> torch.Tensor:
    """Per-channel GP length scales (latent steps), log-spaced from ``lo`` to ``hi``."""
    if channels == 1:
        return torch.tensor([float(hi)])
    return torch.logspace(math.log10(lo), math.log10(hi), channels)


def gp_noise(scales: torch.Tensor, steps: int, batch: int = 1, generator: torch.Generator | None = None) -> torch.Tensor:
    """Samples ``(batch, C, steps)`` of zero-mean unit-variance GPs with RBF kernels.

    Channel c has covariance ``k(i, j) = exp(-(i - j)^2 / (2 l_c^2))`` over the steps.
    Drawn exactly by circulant embedding (Dietrich & Newsam 1997): the kernel on a
    periodic grid of M >= 2 (steps + 8 l) points is diagonalised by the FFT, so one
    complex normal vector per channel, scaled by the square root of the kernel's
    spectrum, gives two independent samples (real and imaginary parts); the first
    ``steps`` points are kept. O(C M log M), so whole songs cost nothing.
    """
    if steps < 1:
        raise ConfigError(f"GP noise needs at least one step, got {steps}")
    scales = scales.double()
    m = 2 ** math.ceil(math.log2(max(2 * (steps + 8 * float(scales.max())), 8)))
    k = torch.arange(m, dtype=torch.float64)
    lag = torch.minimum(k, m - k)
    row = torch.exp(-(lag[None] ** 2) / (2 * scales[:, None] ** 2))  # (C, M)
    lam = torch.fft.fft(row).real.clamp_min(0.0)  # (C, M) eigenvalues
    n = (batch + 1) // 2
    re = torch.randn(n, *lam.shape, generator=generator, dtype=torch.float64)
    im = torch.randn(n, *lam.shape, generator=generator, dtype=torch.float64)
    w = torch.fft.fft(torch.complex(re, im) * torch.sqrt(lam / m))
    out = torch.cat([w.real, w.imag])[:batch, :, :steps]
    return out.float()


# --------------------------------------------------------------------------- configuration


@dataclass(frozen=True)
class GCNConfig:
    """Hyper-parameters of :class:`GCNDancer` (paper values where the paper gives them).

    feature_dim: D of the project's audio features (used only with ``audio_features``).
    styles: style letters the classifier and the embedding know (DWM: C, R, W).
    noise_channels: C, GP noise channels of the latent (paper: 512).
    style_dim: E, learned style embedding width.
    widths: generator channels at (1 node, T0), (3, 2T0), (11, 4T0), (21, 8T0), (21, 16T0).
    disc_widths: discriminator channels at (21, T), (11, T/2), (3, T/4), (1, T/8).
    t_kernel: temporal kernel of every ST-GCN block (odd; ST-GCN uses 9).
    gp_min_scale, gp_max_scale: range of the per-channel RBF length scales, latent steps.
    audio_features: also condition the generator on per-frame audio features (off: the paper).
    audio_rate, mu: classifier input rate (Hz) and mu-law parameter.
    classifier_width: channels of the classifier's first conv (doubling per layer).
    style_chunk: latent steps per classifier window (4 = 64 frames = 2.13 s).
    style_smooth: chunks whose probabilities are averaged before the argmax (odd).
    spline_knot: frames between spline knots when smoothing the output (0 = off).
    seed: seed of the GP noise at generation (same song, same seed: same dance).
    """

    feature_dim: int = 65
    pose_dim: int = POSE_DIM
    styles: tuple[str, ...] = ("C", "R", "W")
    noise_channels: int = 512
    style_dim: int = 16
    widths: tuple[int, ...] = (256, 128, 64, 64, 32)
    disc_widths: tuple[int, ...] = (32, 64, 64, 128)
    t_kernel: int = 9
    gp_min_scale: float = 0.5
    gp_max_scale: float = 16.0
    audio_features: bool = False
    feature_channels: int = 32
    audio_rate: int = 16000
    mu: int = 255
    classifier_width: int = 16
    style_chunk: int = 4
    style_smooth: int = 3
    spline_knot: int = 4
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("styles", "widths", "disc_widths"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        if self.pose_dim != POSE_DIM:
            raise ConfigError(f"gcn predicts the humanoid rig: pose_dim must be {POSE_DIM}, got {self.pose_dim}")
        if len(self.widths) != 5 or len(self.disc_widths) != 4 or min(self.widths + self.disc_widths) < 1:
            raise ConfigError(f"gcn needs 5 positive widths and 4 disc_widths, got {self.widths}, {self.disc_widths}")
        if len(self.styles) < 2 or len(set(self.styles)) != len(self.styles):
            raise ConfigError(f"gcn needs at least 2 distinct styles, got {self.styles}")
        if self.t_kernel < 1 or self.t_kernel % 2 == 0 or self.style_smooth < 1 or self.style_smooth % 2 == 0:
            raise ConfigError(f"t_kernel and style_smooth must be odd and >= 1, got {self.t_kernel}, {self.style_smooth}")
        if min(self.noise_channels, self.style_dim, self.feature_dim, self.style_chunk, self.classifier_width) < 1:
            raise ConfigError(f"invalid gcn config {self}")
        if not 0 < self.gp_min_scale <= self.gp_max_scale or self.spline_knot < 0 or not 4000 <= self.audio_rate <= 48000:
            raise ConfigError(f"invalid gcn config {self}")

    @property
    def causal(self) -> bool:
        return False

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        for name in ("styles", "widths", "disc_widths"):
            d[name] = list(d[name])
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "GCNConfig":
        from models.networks.generator import config_from_dict

        return config_from_dict(cls, d)


# --------------------------------------------------------------------------- building blocks


class STGCNBlock(nn.Module):
    """Spatial-temporal graph convolution (Yan et al., AAAI 2018) on (B, C, T, V).

    Spatial: one 1x1 conv per adjacency partition, mixed over nodes by the partitioned
    adjacency times a learned edge-importance mask; then BN + ReLU, a temporal conv
    (``t_kernel`` frames, same padding) + BN, a residual path and ReLU.
    """

    def __init__(self, c_in: int, c_out: int, adjacency: torch.Tensor, t_kernel: int = 9) -> None:
        super().__init__()
        self.register_buffer("adjacency", adjacency.clone())
        k = adjacency.shape[0]
        self.importance = nn.Parameter(torch.ones_like(adjacency))
        self.spatial = nn.Conv2d(c_in, k * c_out, 1)
        self.bn1 = nn.BatchNorm2d(c_out)
        self.temporal = nn.Conv2d(c_out, c_out, (t_kernel, 1), padding=(t_kernel // 2, 0))
        self.bn2 = nn.BatchNorm2d(c_out)
        self.residual = nn.Identity() if c_in == c_out else nn.Sequential(nn.Conv2d(c_in, c_out, 1), nn.BatchNorm2d(c_out))
        self.c_out = c_out

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, _, t, v = x.shape
        h = self.spatial(x).view(b, -1, self.c_out, t, v)
        h = torch.einsum("bkctv,kvw->bctw", h, self.adjacency * self.importance).contiguous()
        h = self.bn2(self.temporal(F.relu(self.bn1(h))))
        return F.relu(h + self.residual(x))


class GraphUpsample(nn.Module):
    """Coarse -> fine nodes: ``x_fine[..., i] = sum_g W[g, i] x_coarse[..., g]``, W learned (init: membership)."""

    def __init__(self, groups: tuple[int, ...], coarse: int) -> None:
        super().__init__()
        self.weight = nn.Parameter(membership(groups, coarse))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.einsum("bctg,gi->bcti", x, self.weight)


class GraphDownsample(nn.Module):
    """Fine -> coarse nodes by a learned aggregation matrix (init: the mean over each group)."""

    def __init__(self, groups: tuple[int, ...], coarse: int) -> None:
        super().__init__()
        m = membership(groups, coarse)
        self.weight = nn.Parameter((m / m.sum(dim=1, keepdim=True)).T.contiguous())  # (fine, coarse)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.einsum("bcti,ig->bctg", x, self.weight)


def _time_up(c_in: int, c_out: int) -> nn.Module:
    """Transposed conv doubling time, per node: (B, c_in, T, V) -> (B, c_out, 2T, V)."""
    return nn.Sequential(nn.ConvTranspose2d(c_in, c_out, (4, 1), stride=(2, 1), padding=(1, 0)),
                         nn.BatchNorm2d(c_out), nn.ReLU())


def _time_down(c_in: int, c_out: int) -> nn.Module:
    """Strided conv halving time, per node."""
    return nn.Sequential(nn.Conv2d(c_in, c_out, (4, 1), stride=(2, 1), padding=(1, 0)),
                         nn.BatchNorm2d(c_out), nn.LeakyReLU(0.2))


# --------------------------------------------------------------------------- generator


class GCNGenerator(nn.Module):
    """Latent ``(B, C + E, T0)`` (+ optional features) -> poses ``(B, POSE_DIM, 16 T0)``.

    Stages (nodes, time): (1, T0) -> up -> (3, 2T0) -> up -> (11, 4T0) -> up -> (21, 8T0)
    -> up (time only) -> (21, 16T0) -> per-node 7 channels -> pose layout.
    """

    def __init__(self, cfg: GCNConfig) -> None:
        super().__init__()
        self.config = cfg
        w, kt = cfg.widths, cfg.t_kernel
        cond = cfg.feature_channels if cfg.audio_features else 0
        adj = [partitioned_adjacency(list(h[1])) for h in HIERARCHY]
        c_latent = cfg.noise_channels + cfg.style_dim
        self.blocks = nn.ModuleList([
            STGCNBlock(c_latent + cond, w[0], adj[0], kt),
            STGCNBlock(w[1] + cond, w[1], adj[1], kt),
            STGCNBlock(w[2] + cond, w[2], adj[2], kt),
            STGCNBlock(w[3] + cond, w[3], adj[3], kt),
            STGCNBlock(w[4] + cond, w[4], adj[3], kt),
        ])
        self.time_up = nn.ModuleList(_time_up(w[i], w[i + 1]) for i in range(4))
        self.node_up = nn.ModuleList(GraphUpsample(HIERARCHY[i + 1][2], HIERARCHY[i][0]) for i in range(3))
        self.head = nn.Conv2d(w[4], NODE_OUT, 1)
        with torch.no_grad():  # start near the rest pose: identity quaternions
            self.head.weight.mul_(0.1)
            self.head.bias.zero_()
            self.head.bias[3] = 1.0
        if cfg.audio_features:
            self.feature_net = nn.Sequential(nn.Conv1d(cfg.feature_dim, cfg.feature_channels, 3, padding=1), nn.ReLU())

    def _cond(self, feats: torch.Tensor | None, t: int, v: int) -> list[torch.Tensor]:
        if feats is None:
            return []
        c = F.adaptive_avg_pool1d(feats, t)  # (B, Fc, t)
        return [c[..., None].expand(-1, -1, -1, v)]

    def forward(self, latent: torch.Tensor, features: torch.Tensor | None = None,
                trace: list | None = None) -> torch.Tensor:
        cfg = self.config
        feats = None
        if cfg.audio_features:
            if features is None:
                raise ConfigError("this gcn generator was built with audio_features=True and needs features")
            feats = self.feature_net(features)
        h = latent[..., None]  # (B, C+E, T0, 1)
        for i, block in enumerate(self.blocks):
            h = block(torch.cat([h, *self._cond(feats, h.shape[2], h.shape[3])], dim=1))
            if trace is not None:
                trace.append(tuple(h.shape[1:]))
            if i < 4:
                h = self.time_up[i](h)
                if i < 3:
                    h = self.node_up[i](h)
        y = self.head(h)  # (B, 7, T, 21)
        return nodes_to_pose(y)


def nodes_to_pose(y: torch.Tensor, eps: float = 1e-6) -> torch.Tensor:
    """Per-node output (B, 7, T, 21) -> poses (B, POSE_DIM, T): unit quaternions, root xyz from the Hips node."""
    q = y[:, :4]
    q = q / q.norm(dim=1, keepdim=True).clamp_min(eps)  # (B, 4, T, V)
    b, _, t, v = q.shape
    quats = q.permute(0, 2, 3, 1).reshape(b, t, v * 4)
    root = y[:, 4:7, :, 0].transpose(1, 2)  # (B, T, 3)
    return torch.cat([root, quats], dim=2).transpose(1, 2)


# --------------------------------------------------------------------------- discriminator


class GCNDiscriminator(nn.Module):
    """The generator mirrored: (pose, style) -> one real/fake logit per latent step (B, T/16).

    Input per bone node: its local quaternion (4) and FK joint position (3, metres),
    plus the style embedding of the step (conditional GAN). Stages: (21, T) -> (11, T/2)
    -> (3, T/4) -> (1, T/8) -> (1, T/16).
    """

    def __init__(self, cfg: GCNConfig) -> None:
        super().__init__()
        self.config = cfg
        w, kt = cfg.disc_widths, cfg.t_kernel
        adj = [partitioned_adjacency(list(h[1])) for h in HIERARCHY]
        self.embed = nn.Embedding(len(cfg.styles), cfg.style_dim)
        self.blocks = nn.ModuleList([
            STGCNBlock(7 + cfg.style_dim, w[0], adj[3], kt),
            STGCNBlock(w[1], w[1], adj[2], kt),
            STGCNBlock(w[2], w[2], adj[1], kt),
            STGCNBlock(w[3], w[3], adj[0], kt),
        ])
        self.time_down = nn.ModuleList(_time_down(w[i], w[min(i + 1, 3)]) for i in range(4))
        self.node_down = nn.ModuleList(GraphDownsample(HIERARCHY[3 - i][2], HIERARCHY[2 - i][0]) for i in range(3))
        self.score = nn.Conv1d(w[3], 1, 1)
        from models.rig.skeleton import load_default_skeleton

        self.register_buffer("offsets", torch.from_numpy(load_default_skeleton().offsets).float())

    def forward(self, pose: torch.Tensor, style: torch.Tensor) -> torch.Tensor:
        """pose (B, POSE_DIM, T) with T a multiple of 16; style (B, T/16) indices -> logits (B, T/16)."""
        from models.rig.kinematics import fk_torch

        b, _, t = pose.shape
        x = pose.transpose(1, 2)
        root, quats = x[..., :3], x[..., 3:].reshape(b, t, NUM_BONES, 4)
        pos = fk_torch(root, quats, self.offsets)  # (B, T, 21, 3)
        nodes = torch.cat([quats, pos], dim=-1).permute(0, 3, 1, 2)  # (B, 7, T, 21)
        emb = self.embed(style).transpose(1, 2).repeat_interleave(TIME_FACTOR, dim=2)  # (B, E, T)
        h = torch.cat([nodes, emb[..., None].expand(-1, -1, -1, NUM_BONES)], dim=1)
        for i, block in enumerate(self.blocks):
            h = self.time_down[i](block(h))
            if i < 3:
                h = self.node_down[i](h)
        return self.score(h[..., 0])[:, 0]


# --------------------------------------------------------------------------- music style classifier


class MusicStyleClassifier(nn.Module):
    """1-D CNN on mu-law waveform windows ``(B, L)`` at ``audio_rate`` -> style logits ``(B, S)``.

    SoundNet-like: five conv + BN + ReLU layers (kernels 64, 32, 16, 8, 4, stride 2,
    widths w, 2w, 4w, 8w, 8w, max-pooling by 8 after the first two), then mean and max
    pooling over time and a linear layer.
    """

    def __init__(self, n_styles: int, width: int = 16) -> None:
        super().__init__()
        w = width
        layers: list[nn.Module] = []
        chans = [1, w, 2 * w, 4 * w, 8 * w, 8 * w]
        for i, k in enumerate((64, 32, 16, 8, 4)):
            layers += [nn.Conv1d(chans[i], chans[i + 1], k, stride=2, padding=k // 2), nn.BatchNorm1d(chans[i + 1]), nn.ReLU()]
            if i < 2:
                layers.append(nn.MaxPool1d(8))
        self.body = nn.Sequential(*layers)
        self.drop = nn.Dropout(0.3)
        self.head = nn.Linear(16 * w, n_styles)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = self.body(x[:, None])
        return self.head(self.drop(torch.cat([h.mean(dim=2), h.amax(dim=2)], dim=1)))


# --------------------------------------------------------------------------- the whole model


@dataclass
class StyleTrack:
    """What the classifier says about a song: per chunk and per latent step."""

    chunk_probs: np.ndarray  # (n_chunks, S) softmax of each window
    smooth_probs: np.ndarray  # (n_chunks, S) averaged over style_smooth chunks
    chunk_time_s: np.ndarray  # (n_chunks,) audio time of each window's centre
    steps: np.ndarray  # (T0,) style index of every latent step
    styles: tuple[str, ...]


class GCNDancer(nn.Module):
    """The ``gcn`` model: music style classifier + GCN generator (the discriminator trains beside it).

    ``forward(features, style=None, noise=None)`` is the training path: features
    ``(B, D, T)`` (T a multiple of 16; only T is used unless ``audio_features``), style
    ``(B,)`` or ``(B, T/16)`` indices (default: style 0), noise ``(B, C, T/16)``
    (default: the GP noise of seed ``config.seed``, so ``model(x)`` is repeatable)
    -> poses ``(B, POSE_DIM, T)``.

    :meth:`generate_poses` is the offline path for a whole song (classifier, seeded
    noise, generator, spline smoothing). Offline only: see the module docstring.
    """

    output_delay: int = 0
    offline_only: bool = True
    offline_reason: str = ("transposed convs and Gaussian-process noise span the whole song, and each step's "
                           "style is classified from audio around it")
    needs_audio: bool = True
    stochastic: bool = True  # the GP noise is seeded: another seed, another dance (evaluate's multimodality)

    def __init__(self, config: GCNConfig | None = None) -> None:
        super().__init__()
        self.config = cfg = config or GCNConfig()
        self.embed = nn.Embedding(len(cfg.styles), cfg.style_dim)
        self.generator = GCNGenerator(cfg)
        self.style_net = MusicStyleClassifier(len(cfg.styles), cfg.classifier_width)
        self.register_buffer("scales", length_scales(cfg.noise_channels, cfg.gp_min_scale, cfg.gp_max_scale))

    # -- latent
    def noise(self, batch: int, steps: int, generator: torch.Generator | None = None) -> torch.Tensor:
        return gp_noise(self.scales.cpu(), steps, batch, generator).to(self.scales.device)

    def latent(self, style: torch.Tensor, noise: torch.Tensor) -> torch.Tensor:
        """Noise (B, C, T0) and style (B, T0) -> latent (B, C + E, T0)."""
        return torch.cat([noise, self.embed(style).transpose(1, 2)], dim=1)

    def forward(self, features: torch.Tensor, style: torch.Tensor | None = None,
                noise: torch.Tensor | None = None) -> torch.Tensor:
        cfg = self.config
        if features.ndim != 3 or features.shape[1] != cfg.feature_dim:
            raise ConfigError(f"gcn input must be (B, {cfg.feature_dim}, T), got {tuple(features.shape)}")
        b, _, t = features.shape
        if t % TIME_FACTOR:
            raise ConfigError(f"gcn needs T a multiple of {TIME_FACTOR} frames, got T={t}")
        t0 = t // TIME_FACTOR
        if style is None:
            style = torch.zeros(b, t0, dtype=torch.long, device=features.device)
        elif style.ndim == 1:
            style = style[:, None].expand(b, t0)
        if style.shape != (b, t0):
            raise ConfigError(f"style must be (B,) or (B, {t0}) indices, got {tuple(style.shape)}")
        if noise is None:  # deterministic: the noise of seed ``config.seed`` (training passes fresh noise)
            noise = self.noise(b, t0, torch.Generator().manual_seed(cfg.seed))
        return self.generator(self.latent(style.long(), noise), features if cfg.audio_features else None)

    # -- offline generation
    @torch.no_grad()
    def style_track(self, audio: np.ndarray, num_frames: int) -> StyleTrack:
        """Classify the song: audio (n,) mono at 22050 Hz, where frame t ends at sample (t + 1) * HOP.

        One window of ``style_chunk * 16`` frames per chunk of latent steps, centred on
        the chunk (shifted inside the song at its ends, zero-padded if the song is
        shorter than one window).
        """
        cfg = self.config
        t0 = max(1, -(-num_frames // TIME_FACTOR))
        chunk_frames = cfg.style_chunk * TIME_FACTOR
        n_chunks = -(-t0 // cfg.style_chunk)
        x = prepare_audio(np.asarray(audio, dtype=np.float32).reshape(-1), cfg.audio_rate, cfg.mu)
        win = int(round(chunk_frames * HOP * cfg.audio_rate / SAMPLE_RATE))
        if len(x) < win:
            x = np.pad(x, (0, win - len(x)))
        centres = (np.arange(n_chunks) * chunk_frames + chunk_frames / 2) * HOP / SAMPLE_RATE  # seconds
        starts = np.clip(np.round(centres * cfg.audio_rate).astype(int) - win // 2, 0, len(x) - win)
        windows = np.stack([x[s : s + win] for s in starts])
        self.style_net.eval()
        probs = torch.cat([torch.softmax(self.style_net(torch.from_numpy(w)), dim=1)
                           for w in np.array_split(windows, max(1, -(-len(windows) // 64)))]).numpy()
        smooth = _moving_average(probs, cfg.style_smooth)
        steps = np.repeat(smooth.argmax(axis=1), cfg.style_chunk)[:t0]
        return StyleTrack(probs, smooth, centres, steps, cfg.styles)

    @torch.no_grad()
    def generate_poses(self, features: np.ndarray, audio: np.ndarray | None = None,
                       style_steps: np.ndarray | None = None, seed: int | None = None) -> np.ndarray:
        """Poses ``(T, POSE_DIM)`` float32 for a whole song, one per feature frame.

        ``audio``: the song (n,) at 22050 Hz aligned with the features (frame t ends at
        sample (t + 1) * HOP); classified by :meth:`style_track` unless ``style_steps``
        (T/16 rounded up, style indices) is given. ``seed``: GP noise seed
        (default: ``config.seed``).
        """
        from models.networks.blend import blend_track
        from models.networks.streaming import sanitize_features

        x, _ = sanitize_features(np.asarray(features))
        if x.ndim != 2 or x.shape[0] < 1:
            raise ConfigError(f"features must have shape (frames >= 1, D), got {x.shape}")
        t = len(x)
        t0 = -(-t // TIME_FACTOR)
        if style_steps is None:
            if audio is None:
                raise ConfigError("model 'gcn' needs the song's audio: its style classifier listens to the waveform")
            style_steps = self.style_track(audio, t).steps
        style_steps = np.asarray(style_steps, dtype=np.int64).reshape(-1)
        if len(style_steps) != t0 or style_steps.min() < 0 or style_steps.max() >= len(self.config.styles):
            raise ConfigError(f"style_steps must hold {t0} indices in [0, {len(self.config.styles)})")
        pad = t0 * TIME_FACTOR - t
        if pad:
            x = np.concatenate([x, np.repeat(x[-1:], pad, axis=0)])
        gen = torch.Generator().manual_seed(self.config.seed if seed is None else int(seed))
        self.eval()
        y = self(torch.from_numpy(np.ascontiguousarray(x.T))[None], torch.from_numpy(style_steps)[None],
                 self.noise(1, t0, gen))[0].T.numpy()[:t]
        y = spline_smooth(y, self.config.spline_knot)
        return blend_track(y[None].astype(np.float32), np.ones((1, t)))


def _moving_average(p: np.ndarray, width: int) -> np.ndarray:
    """Centred moving average over rows (edges use the rows that exist)."""
    if width <= 1 or len(p) < 2:
        return p.copy()
    r = width // 2
    c = np.concatenate([np.zeros((1, p.shape[1])), np.cumsum(p, axis=0)])
    idx = np.arange(len(p))
    lo, hi = np.clip(idx - r, 0, len(p)), np.clip(idx + r + 1, 0, len(p))
    return (c[hi] - c[lo]) / (hi - lo)[:, None]


def spline_smooth(poses: np.ndarray, knot_every: int) -> np.ndarray:
    """Least-squares cubic B-spline fit of every pose channel, knots every ``knot_every`` frames.

    Quaternions are made sign-continuous first and renormalised after (the paper
    smooths its joint trajectories with cubic splines). Tracks shorter than two knot
    spans, or ``knot_every < 2``, are returned unchanged.
    """
    from scipy.interpolate import make_lsq_spline

    from models.networks.blend import align_sequence

    y = np.asarray(poses, dtype=np.float64).copy()
    t = len(y)
    if knot_every < 2 or t < 2 * knot_every + 4:
        return y.astype(np.float32)
    q = align_sequence(y[:, 3:].reshape(t, -1, 4))
    y[:, 3:] = q.reshape(t, -1)
    x = np.arange(t, dtype=np.float64)
    interior = np.arange(knot_every, t - 1, knot_every, dtype=np.float64)
    interior = interior[interior < t - 1 - 0.5 * knot_every]
    knots = np.concatenate([[0.0] * 4, interior, [t - 1.0] * 4])
    out = make_lsq_spline(x, y, knots, k=3, axis=0)(x)
    qs = out[:, 3:].reshape(t, -1, 4)
    qs /= np.maximum(np.linalg.norm(qs, axis=-1, keepdims=True), 1e-8)
    out[:, 3:] = qs.reshape(t, -1)
    return out.astype(np.float32)


__all__ = [
    "GCNConfig", "GCNDancer", "GCNGenerator", "GCNDiscriminator", "MusicStyleClassifier", "STGCNBlock",
    "GraphUpsample", "GraphDownsample", "gp_noise", "length_scales", "mu_law", "mu_law_inverse",
    "prepare_audio", "compand", "resample_to", "spline_smooth", "HIERARCHY", "LEVEL_SIZES", "StyleTrack",
]
