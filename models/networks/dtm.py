""""Dancing to Music" (Lee et al., NeurIPS 2019): decomposition to composition, on this rig.

Registry name ``dtm``. The model dances in **dance units**: ``unit_frames`` (32) poses
spanning ``unit_beats`` (4) music beats, time-normalised so the beats fall on unit
frames 0, 8, 16, 24 (the next unit starts on the fifth beat).

Decomposition (DU-VAE, :meth:`DanceToMusic.decompose`): an initial-pose encoder
(first pose -> Gaussian ``z_init``), a movement encoder (GRU over the unit ->
Gaussian ``z_mov``) and a GRU unit decoder (``z_init``, ``z_mov`` -> 32 poses), plus an
initial-pose decoder (``z_init`` -> pose) so ``z_init`` is a VAE of single poses.
Losses (``models.training.dtm``): KL of both codes, reconstruction, and the
shift-reconstruction of the paper: two copies of a unit with different global
shifts must swap movement codes and still reconstruct, and their movement codes
must agree.

Composition (MM-GAN, :meth:`DanceToMusic.compose`): a music style classifier (GRU
over a window of log-mel + onset features, trained on the DWM styles C/R/W; its
last hidden state is the style feature), a movement-to-dance encoder (GRU over the
units' ``(mu, logvar)`` -> ``z_dance``), a style-to-dance encoder (style feature +
noise -> ``z_dance``), and a recurrent dance decoder (``z_dance`` -> ``num_units``
movement codes). Training-only critics live in :class:`DTMCritics`: a movement
discriminator (movement-code sequences, conditioned on the style feature), a dance
discriminator (on ``z_dance``) and a style regressor (``z_dance`` -> style feature).

Test time (:meth:`DanceToMusic.generate`): music beats come from the onset column of
the features (``librosa.beat.beat_track`` on it), the style from the classifier; the
dance decoder proposes movement codes per group of ``num_units`` units; units are
decoded recurrently from a sampled initial pose (``z_init`` from the prior, then
from the last generated pose); and the units are time-warped so their beats land on
the music beats (:func:`warp_units`: rotation splines, cubic root).

**Offline only.** Beat tracking needs the whole song (the tempo and phase of the
beats are estimated globally, and a unit spans four future beats that have to be
known before its first pose is drawn), so the model cannot produce pose ``t`` from
audio up to ``t``; the real-time engine refuses it (:attr:`DanceToMusic.offline_only`)
and ``performer generate`` / ``performer evaluate`` run it over whole songs.

Poses are the project's flat layout (``models.rig.motion``: root xyz + one xyzw
quaternion per bone, ``POSE_DIM``); the paper used 2-D keypoints. Networks see poses
and features standardised with statistics stored in the model (buffers).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torch import nn

from models.errors import ConfigError
from models.networks.generator import config_from_dict, normalize_pose
from models.rig.motion import POSE_DIM
from models.timebase import HOP


@dataclass(frozen=True)
class DTMConfig:
    """Sizes of the DTM networks.

    feature_dim: D of the audio features (log-mel + onset; the onset strength is the last column).
    pose_dim: POSE_DIM. unit_frames / unit_beats: frames and beats per dance unit.
    num_units: units per dance (composition phase and one style decision at test time).
    z_init, z_mov, z_dance: code sizes. hidden: GRU / MLP width.
    style_window: feature frames the music style classifier reads; num_styles: its classes.
    noise_dim: noise appended to the style feature by the style-to-dance encoder.
    beat_shift: frames subtracted from beats tracked on the onset column (1: a beat found in
    feature frame t happened during hop t, i.e. by the instant of pose t - 1; see :func:`feature_beats`).
    """

    feature_dim: int = 65
    pose_dim: int = POSE_DIM
    unit_frames: int = 32
    unit_beats: int = 4
    num_units: int = 3
    z_init: int = 16
    z_mov: int = 64
    z_dance: int = 64
    hidden: int = 256
    style_hidden: int = 64
    style_window: int = 64
    num_styles: int = 3
    noise_dim: int = 16
    beat_shift: float = 1.0

    def __post_init__(self) -> None:
        ints = ("feature_dim", "unit_frames", "unit_beats", "num_units", "z_init", "z_mov", "z_dance", "hidden",
                "style_hidden", "style_window", "num_styles", "noise_dim")
        if any(getattr(self, k) < 1 for k in ints) or (self.pose_dim - 3) % 4 or self.pose_dim < 7:
            raise ConfigError(f"invalid DTM config {self}")
        if self.unit_frames % self.unit_beats or self.num_styles < 2 or self.feature_dim < 2:
            raise ConfigError(f"DTM needs unit_frames divisible by unit_beats, >= 2 styles and features: {self}")

    @property
    def causal(self) -> bool:
        return False

    @property
    def frames_per_beat(self) -> int:
        return self.unit_frames // self.unit_beats

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "DTMConfig":
        return config_from_dict(cls, d)


# --------------------------------------------------------------------------- building blocks


def mlp(sizes: list[int], final_act: bool = False) -> nn.Sequential:
    """Linear -> LayerNorm -> LeakyReLU(0.2) between the given widths (none after the last unless final_act)."""
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
        layers.append(nn.Linear(a, b))
        if i < len(sizes) - 2 or final_act:
            layers += [nn.LayerNorm(b), nn.LeakyReLU(0.2)]
    return nn.Sequential(*layers)


def reparameterize(mu: torch.Tensor, logvar: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
    """``mu + exp(logvar / 2) * eps``, eps ~ N(0, I) (drawn from ``generator`` when given)."""
    eps = torch.randn(mu.shape, generator=generator, dtype=mu.dtype, device=mu.device)
    return mu + (0.5 * logvar).exp() * eps


def kl_normal(mu: torch.Tensor, logvar: torch.Tensor) -> torch.Tensor:
    """KL(N(mu, exp(logvar)) || N(0, I)), summed over the last axis, averaged over the rest."""
    return (-0.5 * (1 + logvar - mu.pow(2) - logvar.exp()).sum(-1)).mean()


class GaussianHead(nn.Module):
    """x (B, in) -> (mu, logvar) (B, out), log-variance clamped to [-10, 10]."""

    def __init__(self, d_in: int, d_out: int) -> None:
        super().__init__()
        self.mu, self.logvar = nn.Linear(d_in, d_out), nn.Linear(d_in, d_out)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.mu(x), self.logvar(x).clamp(-10.0, 10.0)


class GRUEncoder(nn.Module):
    """Sequence (B, L, in) -> Gaussian code of its last GRU state (learned initial state)."""

    def __init__(self, d_in: int, hidden: int, d_out: int) -> None:
        super().__init__()
        self.gru = nn.GRU(d_in, hidden, batch_first=True)
        self.h0 = nn.Parameter(torch.zeros(1, 1, hidden))
        self.head = GaussianHead(hidden, d_out)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        out, _ = self.gru(x, self.h0.expand(1, x.shape[0], -1).contiguous())
        return self.head(out[:, -1])


class UnitDecoder(nn.Module):
    """(z_init, z_mov) (B, *) -> unit (B, unit_frames, pose_dim), standardised pose space.

    The GRU starts from a state made of both codes and reads ``z_mov`` at every step.
    """

    def __init__(self, c: DTMConfig) -> None:
        super().__init__()
        self.frames, self.hidden = c.unit_frames, c.hidden
        self.h0 = nn.Linear(c.z_init + c.z_mov, c.hidden)
        self.gru = nn.GRU(c.z_mov, c.hidden, batch_first=True)
        self.pose = mlp([c.hidden, c.hidden, c.pose_dim])

    def forward(self, z_init: torch.Tensor, z_mov: torch.Tensor) -> torch.Tensor:
        h0 = self.h0(torch.cat([z_init, z_mov], -1))[None]
        out, _ = self.gru(z_mov[:, None].expand(-1, self.frames, -1), h0.contiguous())
        return self.pose(out)


class DanceDecoder(nn.Module):
    """z_dance (B, z_dance) -> movement codes ``(mu, logvar)`` (B, num_units, z_mov), recurrent."""

    def __init__(self, c: DTMConfig) -> None:
        super().__init__()
        self.h0 = nn.Linear(c.z_dance, c.hidden)
        self.gru = nn.GRU(c.z_dance, c.hidden, batch_first=True)
        self.body = mlp([c.hidden, c.hidden], final_act=True)
        self.head = GaussianHead(c.hidden, c.z_mov)

    def forward(self, z_dance: torch.Tensor, num_units: int) -> tuple[torch.Tensor, torch.Tensor]:
        out, _ = self.gru(z_dance[:, None].expand(-1, num_units, -1), self.h0(z_dance)[None].contiguous())
        return self.head(self.body(out))


class StyleClassifier(nn.Module):
    """Music style classifier: features (B, L, D) standardised -> (style feature (B, style_hidden), logits (B, S))."""

    def __init__(self, c: DTMConfig) -> None:
        super().__init__()
        self.gru = nn.GRU(c.feature_dim, c.style_hidden, batch_first=True)
        self.h0 = nn.Parameter(torch.zeros(1, 1, c.style_hidden))
        self.classify = nn.Sequential(nn.Linear(c.style_hidden, c.style_hidden), nn.ReLU(), nn.Linear(c.style_hidden, c.num_styles))

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        out, _ = self.gru(x, self.h0.expand(1, x.shape[0], -1).contiguous())
        style = out[:, -1]
        return style, self.classify(style)


# --------------------------------------------------------------------------- the model


class DanceToMusic(nn.Module):
    """The DTM generator: DU-VAE + MM-GAN generator side + music style classifier (see module docstring)."""

    offline_only: bool = True
    offline_reason: str = ("it tracks beats over the whole song and warps each 4-beat dance unit onto beats "
                           "that lie in the future")
    stochastic: bool = True  # generate(seed=...) draws different dances for the same music

    def __init__(self, config: DTMConfig) -> None:
        super().__init__()
        c = self.config = config
        # decomposition: DU-VAE
        self.init_enc = nn.Sequential(mlp([c.pose_dim, c.hidden, c.hidden], final_act=True), GaussianHead(c.hidden, c.z_init))
        self.init_dec = mlp([c.z_init, c.hidden, c.hidden, c.pose_dim])
        self.move_enc = GRUEncoder(c.pose_dim, c.hidden, c.z_mov)
        self.unit_dec = UnitDecoder(c)
        # composition: MM-GAN generator side
        self.dance_enc = GRUEncoder(2 * c.z_mov, c.hidden, c.z_dance)
        self.dance_dec = DanceDecoder(c)
        self.style_enc = nn.Sequential(mlp([c.style_hidden + c.noise_dim, c.hidden, c.hidden], final_act=True),
                                       GaussianHead(c.hidden, c.z_dance))
        self.style_cls = StyleClassifier(c)
        # standardisation statistics (set from the training data by models.training.dtm)
        self.register_buffer("pose_mean", torch.zeros(c.pose_dim))
        self.register_buffer("pose_std", torch.ones(c.pose_dim))
        self.register_buffer("feat_mean", torch.zeros(c.feature_dim))
        self.register_buffer("feat_std", torch.ones(c.feature_dim))

    # ------------------------------------------------------------------ pose space

    def norm_pose(self, poses: torch.Tensor) -> torch.Tensor:
        """Flat poses (..., pose_dim) -> standardised."""
        return (poses - self.pose_mean) / self.pose_std

    def denorm_pose(self, x: torch.Tensor) -> torch.Tensor:
        """Standardised (..., pose_dim) -> flat poses with unit quaternions."""
        return normalize_pose(x * self.pose_std + self.pose_mean, dim=-1)

    def norm_features(self, feats: torch.Tensor) -> torch.Tensor:
        return (feats - self.feat_mean) / self.feat_std

    # ------------------------------------------------------------------ phases

    def decompose(self, units: torch.Tensor, generator: torch.Generator | None = None) -> dict[str, torch.Tensor]:
        """DU-VAE pass over standardised units ``(B, unit_frames, pose_dim)``.

        Returns ``z_init``/``z_mov`` samples with their ``*_mu``/``*_logvar`` and the
        reconstruction ``recon`` (B, unit_frames, pose_dim), standardised.
        """
        init_mu, init_logvar = self.init_enc(units[:, 0])
        mov_mu, mov_logvar = self.move_enc(units)
        z_init, z_mov = reparameterize(init_mu, init_logvar, generator), reparameterize(mov_mu, mov_logvar, generator)
        return dict(z_init=z_init, init_mu=init_mu, init_logvar=init_logvar, z_mov=z_mov, mov_mu=mov_mu,
                    mov_logvar=mov_logvar, recon=self.unit_dec(z_init, z_mov))

    def style(self, windows: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Music style feature (B, style_hidden) and logits (B, num_styles) of raw feature windows (B, L, D)."""
        return self.style_cls(self.norm_features(windows))

    def compose(self, mov_mu: torch.Tensor, mov_logvar: torch.Tensor, style: torch.Tensor,
                generator: torch.Generator | None = None) -> dict[str, torch.Tensor]:
        """MM-GAN generator pass.

        ``mov_mu``/``mov_logvar`` (B, n, z_mov): movement codes of ``n`` real consecutive
        units; ``style`` (B, style_hidden). Returns the real dance code ``z_dance`` (+ mu,
        logvar), its reconstructed movements ``rec_mu``/``rec_logvar``, the music-made
        dance code ``fake_dance`` (+ mu, logvar) and its movements ``fake_mu``/``fake_logvar``.
        """
        n = mov_mu.shape[1]
        d_mu, d_logvar = self.dance_enc(torch.cat([mov_mu, mov_logvar], -1))
        z_dance = reparameterize(d_mu, d_logvar, generator)
        rec_mu, rec_logvar = self.dance_dec(z_dance, n)
        f_mu, f_logvar = self.music_to_dance(style, generator)
        fake_dance = reparameterize(f_mu, f_logvar, generator)
        fake_mu, fake_logvar = self.dance_dec(fake_dance, n)
        return dict(z_dance=z_dance, dance_mu=d_mu, dance_logvar=d_logvar, rec_mu=rec_mu, rec_logvar=rec_logvar,
                    fake_dance=fake_dance, fake_dance_mu=f_mu, fake_dance_logvar=f_logvar, fake_mu=fake_mu,
                    fake_logvar=fake_logvar)

    def music_to_dance(self, style: torch.Tensor, generator: torch.Generator | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Style-to-dance encoder: style feature (B, style_hidden) + fresh noise -> (mu, logvar) of z_dance."""
        noise = torch.randn((style.shape[0], self.config.noise_dim), generator=generator, dtype=style.dtype)
        return self.style_enc(torch.cat([style, noise], -1))

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        """The project's model contract: features (B, D, T) -> poses (B, pose_dim, T), :meth:`generate` with seed 0.

        Whole songs, offline, not differentiable (training uses :meth:`decompose` / :meth:`compose`).
        """
        out = [self.generate(f.T.detach().cpu().numpy(), seed=0) for f in features]
        return torch.from_numpy(np.stack(out)).transpose(1, 2).to(features.device)

    @torch.no_grad()
    def reconstruct(self, units: torch.Tensor) -> torch.Tensor:
        """Reconstruct flat-pose units (B, unit_frames, pose_dim) through the DU-VAE (posterior means)."""
        x = self.norm_pose(units)
        init_mu, _ = self.init_enc(x[:, 0])
        mov_mu, _ = self.move_enc(x)
        return self.denorm_pose(self.unit_dec(init_mu, mov_mu))

    # ------------------------------------------------------------------ test time

    @torch.no_grad()
    def dance_units(self, styles: torch.Tensor, num_units: int, seed: int = 0) -> torch.Tensor:
        """Generate ``num_units`` consecutive units, flat poses ``(num_units * unit_frames, pose_dim)``.

        ``styles`` (G, style_hidden): one style feature per group of ``config.num_units``
        units (G >= ceil(num_units / config.num_units)). The first unit starts from an
        initial pose code drawn from the prior; every later one from the code of the
        previous unit's last pose.
        """
        c, g = self.config, torch.Generator().manual_seed(int(seed))
        units: list[torch.Tensor] = []
        pose0 = self.denorm_pose(self.init_dec(torch.randn((1, c.z_init), generator=g)))
        pose0[:, [0, 2]] = 0.0  # a sampled initial pose, placed like the canonical training data
        z_init = self.init_enc(self.norm_pose(pose0))[0]
        for gi in range(-(-num_units // c.num_units)):
            d_mu, d_logvar = self.music_to_dance(styles[gi : gi + 1], g)
            m_mu, m_logvar = self.dance_dec(reparameterize(d_mu, d_logvar, g), c.num_units)
            z_movs = reparameterize(m_mu, m_logvar, g)[0]
            for k in range(min(c.num_units, num_units - len(units))):
                if units:
                    z_init = reparameterize(*self.init_enc(units[-1][:, -1]), g)
                units.append(self.unit_dec(z_init, z_movs[k : k + 1]))
        return self.denorm_pose(torch.cat(units, dim=1)[0])

    @torch.no_grad()
    def generate(self, features: np.ndarray, seed: int = 0) -> np.ndarray:
        """A dance for a whole song: features (T, D) at 30 fps -> poses (T, pose_dim) float32.

        Beats: :func:`feature_beats` (extended over the song by :func:`beat_grid`);
        style: the classifier on a ``style_window`` centred on each group's beats;
        units: :meth:`dance_units` with ``seed``; then :func:`warp_units`. The same
        seed gives the same dance.
        """
        from models.networks.blend import blend_track

        c = self.config
        x = np.asarray(features, dtype=np.float32)
        if x.ndim != 2 or x.shape[1] != c.feature_dim or len(x) < 1:
            raise ConfigError(f"DTM features must have shape (frames >= 1, {c.feature_dim}), got {x.shape}")
        self.eval()
        t = len(x)
        beats = beat_grid(feature_beats(x, c.beat_shift), t, c.unit_beats)
        num_units = (len(beats) - 1) // c.unit_beats
        group_beats = c.unit_beats * c.num_units
        windows = [style_window(x, 0.5 * (beats[i] + beats[min(i + group_beats, len(beats) - 1)]), c.style_window)
                   for i in range(0, num_units * c.unit_beats, group_beats)]
        styles, _ = self.style(torch.from_numpy(np.stack(windows)))
        units = self.dance_units(styles, num_units, seed).numpy()
        poses = warp_units(units, beats, t, c.frames_per_beat)
        poses[:, [0, 2]] = 0.0  # canonical: no horizontal root travel (models.data.canonical)
        return blend_track(poses[None].astype(np.float32), np.ones((1, t)))


class DTMCritics(nn.Module):
    """Training-only MM-GAN critics: movement discriminator, dance discriminator, style regressor (logits / values)."""

    def __init__(self, c: DTMConfig) -> None:
        super().__init__()
        self.movement = mlp([c.num_units * 2 * c.z_mov + c.style_hidden, 2 * c.hidden, c.hidden, 1])
        self.dance = mlp([2 * c.z_dance, c.hidden, c.hidden, 1])
        self.regressor = mlp([c.z_dance, c.hidden, c.hidden, c.style_hidden])

    def movement_logit(self, mu: torch.Tensor, logvar: torch.Tensor, style: torch.Tensor) -> torch.Tensor:
        """(B, n, z_mov) twice + style (B, style_hidden) -> (B,) real/fake logits."""
        return self.movement(torch.cat([mu.flatten(1), logvar.flatten(1), style], -1))[:, 0]

    def dance_logit(self, mu: torch.Tensor, logvar: torch.Tensor) -> torch.Tensor:
        """z_dance (mu, logvar) (B, z_dance) -> (B,) logits."""
        return self.dance(torch.cat([mu, logvar], -1))[:, 0]


# --------------------------------------------------------------------------- beats, units, warping


def feature_beats(features: np.ndarray, shift: float = 1.0) -> np.ndarray:
    """Music beats (fractional pose frames, sorted) tracked on the onset column (last) of ``features (T, D)``.

    ``librosa.beat.beat_track`` on the onset envelope at 30 fps, then ``shift`` frames
    earlier. On click tracks the unshifted frames equal ``librosa.beat.beat_track`` on
    the waveform (tests/test_dtm.py): a click during hop ``t`` is found in frame ``t``,
    which ends one frame after the instant of pose ``t - 1`` that shows it. With
    ``shift = 1`` the beats are pose frames, the convention of the evaluation's music
    beats (``models.evaluation.evaluate.span_beats``).
    """
    import librosa

    from models.timebase import SAMPLE_RATE

    # An onset strength is >= 0; clipping keeps librosa's tempogram (log1p) finite on other inputs.
    env = np.maximum(np.nan_to_num(np.asarray(features, np.float64)[:, -1], nan=0.0, posinf=0.0, neginf=0.0), 0.0)
    if len(env) < 8 or env.max() <= 0:
        return np.zeros(0)
    _, frames = librosa.beat.beat_track(onset_envelope=env, sr=SAMPLE_RATE, hop_length=HOP)
    return np.sort(np.asarray(frames, np.float64) - shift)


def beat_grid(beats: np.ndarray, num_frames: int, unit_beats: int = 4, default_period: float = 15.0) -> np.ndarray:
    """Beat times (frames) covering ``[0, num_frames - 1]`` with a whole number of units.

    Tracked ``beats`` (any count) are kept; before the first and after the last the
    grid continues with their median period (``default_period`` frames, 120 BPM at
    30 fps, when fewer than two beats were found), so that the first grid beat is
    <= 0 and the grid ends at or after the last frame on a unit boundary. Returns
    ``(unit_beats * U + 1,)`` increasing times.
    """
    b = np.asarray(beats, np.float64)
    b = b[(b > -num_frames) & (b < 2 * num_frames)]
    if len(b) >= 2 and np.all(np.diff(b) > 0):
        period = float(np.median(np.diff(b)))
    else:
        period, b = default_period, np.zeros(1)
    period = max(period, 1.0)
    before = np.arange(int(np.ceil(b[0] / period)), 0, -1) * -period + b[0] if b[0] > 0 else np.zeros(0)
    grid = np.concatenate([before, b])
    need = max(2, int(np.ceil((num_frames - 1 - grid[-1]) / period)) + 1)  # at least one step past the end
    grid = np.concatenate([grid, grid[-1] + period * np.arange(1, need + 1)])
    grid = grid[: max(1, np.flatnonzero(grid >= num_frames - 1)[0]) + 1]  # stop at the first beat at/after the end
    extra = (-(len(grid) - 1)) % unit_beats
    return np.concatenate([grid, grid[-1] + period * np.arange(1, extra + 1)])


def style_window(features: np.ndarray, centre: float, length: int) -> np.ndarray:
    """``length`` feature frames centred on frame ``centre``, edge-padded, float32 (length, D)."""
    idx = np.clip(np.round(centre - length / 2).astype(int) + np.arange(length), 0, len(features) - 1)
    return np.asarray(features, np.float32)[idx]


def resample_poses(poses: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Flat poses (N, pose_dim) at frames 0..N-1, sampled at fractional frame ``times`` (M,).

    Rotations: ``scipy.spatial.transform.RotationSpline`` per bone (cubic, C2,
    shortest path on the sphere); root: ``CubicSpline``. Times are clipped to [0, N-1].
    """
    from scipy.interpolate import CubicSpline
    from scipy.spatial.transform import Rotation, RotationSpline

    poses = np.asarray(poses, np.float64)
    n = len(poses)
    t = np.clip(np.asarray(times, np.float64), 0, n - 1)
    if n == 1:
        return np.repeat(poses.astype(np.float32), len(t), axis=0)
    knots = np.arange(n, dtype=np.float64)
    out = np.empty((len(t), poses.shape[1]))
    out[:, :3] = CubicSpline(knots, poses[:, :3], axis=0)(t)
    q = poses[:, 3:].reshape(n, -1, 4)
    for b in range(q.shape[1]):
        out[:, 3 + 4 * b : 7 + 4 * b] = RotationSpline(knots, Rotation.from_quat(q[:, b]))(t).as_quat()
    return out.astype(np.float32)


def beat_time_map(frames: np.ndarray, beats: np.ndarray, frames_per_beat: int) -> np.ndarray:
    """Unit time (fractional unit frame) of real ``frames``: piecewise linear, beat ``k`` -> ``k * frames_per_beat``.

    Outside the beats the first / last beat period continues the line.
    """
    k = np.arange(len(beats), dtype=np.float64) * frames_per_beat
    f = np.asarray(frames, np.float64)
    u = np.interp(f, beats, k)
    lo, hi = f < beats[0], f > beats[-1]
    u[lo] = (f[lo] - beats[0]) * frames_per_beat / (beats[1] - beats[0])
    u[hi] = k[-1] + (f[hi] - beats[-1]) * frames_per_beat / (beats[-1] - beats[-2])
    return u


def warp_units(units: np.ndarray, beats: np.ndarray, num_frames: int, frames_per_beat: int = 8) -> np.ndarray:
    """Time-warp concatenated units onto music beats: (U * unit_frames, P) -> (num_frames, P).

    Unit frame ``k * frames_per_beat`` (beat ``k`` of the generated dance) is placed at
    music beat ``beats[k]`` and everything between is stretched linearly in time, the
    poses read off :func:`resample_poses`. ``beats`` (U * unit_beats + 1,) increasing.
    """
    beats = np.asarray(beats, np.float64)
    if len(beats) < 2 or np.any(np.diff(beats) <= 0):
        raise ConfigError(f"warping needs at least two increasing beat times, got {beats[:8]}")
    u = beat_time_map(np.arange(num_frames), beats, frames_per_beat)
    return resample_poses(units, u)


def extract_units(poses: np.ndarray, beats: np.ndarray, unit_frames: int = 32, unit_beats: int = 4,
                  valid: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Dance units of a clip: every run of ``unit_beats`` beat intervals, time-normalised.

    ``poses (T, P)`` at 30 fps; ``beats`` fractional frames, increasing. Unit ``i``
    spans ``beats[i] .. beats[i + unit_beats]`` and is resampled (:func:`resample_poses`)
    to ``unit_frames`` poses whose frame ``k * unit_frames / unit_beats`` is beat ``i + k``.
    Units reaching outside ``[0, T-1]`` or over a frame where ``valid`` is False are
    skipped. Returns ``(units (N, unit_frames, P) float32, first beat index (N,))``.
    """
    fpb = unit_frames // unit_beats
    b = np.asarray(beats, np.float64)
    t = len(poses)
    starts, times = [], []
    for i in range(len(b) - unit_beats):
        lo, hi = b[i], b[i + unit_beats]
        if lo < 0 or hi > t - 1:
            continue
        if valid is not None and not np.all(valid[int(np.floor(lo)) : int(np.ceil(hi)) + 1]):
            continue
        u = np.arange(unit_frames) / fpb  # beat position within the unit
        times.append(np.interp(i + u, np.arange(len(b)), b))
        starts.append(i)
    if not starts:
        return np.zeros((0, unit_frames, poses.shape[1]), np.float32), np.zeros(0, np.int64)
    flat = resample_poses(poses, np.concatenate(times))
    q = flat[:, 3:].reshape(len(flat), -1, 4)
    q *= np.where(q[..., 3:] < 0, -1.0, 1.0).astype(np.float32)  # the corpus' hemisphere, w >= 0
    return flat.reshape(len(starts), unit_frames, -1), np.asarray(starts, np.int64)


def count_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())
