"""The dancing performer: a motion codebook and a causal code predictor (``dance_vq``).

Why a codebook. A regressor from music to pose (the causal U-Net) is asked for one pose
where the dancers did many; its loss is smallest at their average, so it hedges towards
the mean pose and trembles around it (docs/training.md). Here the music never picks a
pose: it picks, every ``seg`` frames, one of ``codebook`` short movements learned from
the dancers (choreographic memory, Bailando, Siyao et al., CVPR 2022). The movement played
is one of that code's exemplars: real ``2 seg``-frame windows of the dancers' poses kept in
the checkpoint (``member_poses``, up to ``members`` per code; the shipped default holds
1,519 for 512 codes), the one that best continues the motion, bent onto it
(:mod:`models.networks.dance_stream`). The decoder writes a movement out only for a code
without exemplars (a model trained with ``members = 0``; none in the shipped default).
What comes out is one of the dancers' movements, at their amplitude, whatever the music;
the music decides which, and when.

Three networks and the exemplars, one checkpoint:

* :class:`MotionEncoder` (training only): poses ``(B, T, P)`` standardised ->
  ``(B, code_dim, T / seg)``, non-causal 1-D convolutions with stride 2 (x3 for seg 8).
* :class:`EMAQuantizer`: nearest of ``codebook`` vectors, updated as exponential moving
  averages of the encodings assigned to them (van den Oord et al. 2017; dead codes are
  restarted from the batch).
* :class:`MotionDecoder`: codes -> poses, **causal over codes**: the ``seg`` frames of
  code ``k`` depend on codes ``k - 7 .. k`` only (kernel-2 convolutions, dilations
  1, 2, 4), so a movement continues the one before it. It trains the codebook and plays
  codes that have no exemplars.
* :class:`CodePredictor`: a causal Transformer over the last ``window_codes`` code steps
  (16 x 8 = 128 frames, the engine's window). Token ``k`` holds the standardised audio
  features of frames ``8k - 7 .. 8k``, the code chosen at step ``k - 1`` (its own output,
  fed back: it continues a dance instead of re-guessing a pose) and a style (0 = the
  music decides; 1..3 cha-cha, rumba, waltz). It returns logits for code ``k``.

Timing: pose ``t`` describes the instant feature frame ``t`` ends (30 fps). Code ``k``
covers poses ``8k .. 8k + 7`` and is chosen when feature frame ``8k`` arrives, from audio
up to that frame: no look-ahead, and the movement of the next 267 ms is committed to at
its start (anticipation, as a dancer does). :class:`~models.networks.dance_stream.DanceStream`
runs this frame by frame; :func:`~models.networks.dance_stream.generate` runs it over a whole song,
so offline and live are the same arithmetic.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from models.errors import ConfigError
from models.networks.dance_jit import draw_code
from models.networks.generator import config_from_dict
from models.networks.music_gate import N_PARAMS as PRESENCE_PARAMS
from models.rig.motion import POSE_DIM

#: Style names, index + 1 is the style token (0 = "auto": the music decides).
STYLES: tuple[str, ...] = ("chacha", "rumba", "waltz")
#: Dataset style letters (models.data.dwm) -> style token.
STYLE_TOKEN: dict[str, int] = {"C": 1, "R": 2, "W": 3, "chacha": 1, "rumba": 2, "waltz": 3}


#: MFCC columns the music detector reads (spectral shape, not level), with the pulse clarity.
GATE_MFCC: tuple[int, ...] = tuple(range(1, 13))
#: Time constant of the detector's running mean, frames (0.5 s).
GATE_TAU: float = 15.0


def style_token(style: str | None) -> int:
    """0 for None/"auto", else 1..3 for chacha|rumba|waltz (or C|R|W); ConfigError otherwise."""
    if style is None or style == "auto":
        return 0
    if style not in STYLE_TOKEN:
        raise ConfigError(f"unknown style {style!r}; choose auto, {', '.join(STYLES)}")
    return STYLE_TOKEN[style]


@dataclass(frozen=True)
class DanceVQConfig:
    """Sizes of the dance_vq networks and its sampling settings.

    feature_dim, pose_dim: D of the audio features and POSE_DIM. seg: frames per code
    (a power of 2, >= 2). codebook: number of codes; code_dim: their size.
    enc_width / dec_width: channels of the motion encoder / decoder. d_model, layers,
    heads: the code predictor's Transformer; window_codes: code steps it reads
    (window_codes * seg frames). temperature, top_k: sampling of the next code
    (top_k 0 = all codes). members: real motion exemplars kept per code (the
    choreographic memory that plays a chosen code; 0 = play the decoder's output).
    energy_col / clarity_col: feature columns of the log frame
    energy and of the beat tracker's pulse clarity, read by the idle gate (-1 = unused).
    onset_col: the onset-strength column, whose onset density picks the octave of the tempo
    the performer follows (models.networks.tempo; -1 = none: the tracker's own octave).
    gate_col: -1, or ``feature_dim``: the features carry one more column, last, the spectral
    steadiness (FeatureConfig ``steadiness``, models/features/steadiness.py), which only the
    idle gate's presence detector reads; the predictor's inputs are the first ``feature_dim``
    (:attr:`input_dim` columns in all).
    gate_tau: time constant (frames) of the presence detector's statistics while the performer
    dances, the one its detector was fitted at (models/networks/music_gate.py; 15 before the
    steadiness column, 10 with it).
    tempo_input: the predictor hears the followed tempo, ``ln(T / T_ref)`` (T the tempo the
    performer follows at the token's last frame, T_ref the memory's mean tempo, faded to 0 as
    the pulse fades: :meth:`~models.networks.dance_stream.DanceStream.tempo_input`), as one more
    input of each token (a learned direction, no bias: 0 at T_ref). False: it does not.
    """

    feature_dim: int = 62
    pose_dim: int = POSE_DIM
    seg: int = 8
    codebook: int = 512
    code_dim: int = 64
    enc_width: int = 128
    dec_width: int = 192
    d_model: int = 128
    layers: int = 3
    heads: int = 4
    window_codes: int = 16
    num_styles: int = 3
    dropout: float = 0.1
    temperature: float = 1.0
    top_k: int = 0
    members: int = 4
    energy_col: int = 13
    clarity_col: int = 60
    onset_col: int = -1
    gate_col: int = -1
    gate_tau: float = 15.0
    tempo_input: bool = False

    def __post_init__(self) -> None:
        ints = ("feature_dim", "seg", "codebook", "code_dim", "enc_width", "dec_width", "d_model", "layers", "heads",
                "window_codes", "num_styles")
        if any(not isinstance(getattr(self, k), int) or getattr(self, k) < 1 for k in ints):
            raise ConfigError(f"dance_vq sizes must be positive integers: {self}")
        if self.seg < 2 or self.seg & (self.seg - 1):
            raise ConfigError(f"dance_vq seg must be a power of 2 >= 2, got {self.seg}")
        if (self.pose_dim - 3) % 4 or self.d_model % self.heads:
            raise ConfigError(f"dance_vq needs pose_dim = 3 + 4 J and d_model divisible by heads: {self}")
        if not self.temperature > 0 or self.top_k < 0:
            raise ConfigError(f"dance_vq sampling needs temperature > 0 and top_k >= 0: {self}")
        if not 1.0 <= self.gate_tau <= 300.0:
            raise ConfigError(f"dance_vq gate_tau must be in [1, 300] frames, got {self.gate_tau}")
        if self.gate_col not in (-1, self.feature_dim):
            raise ConfigError(f"dance_vq gate_col must be -1 (none) or feature_dim = {self.feature_dim} "
                              f"(the last column), got {self.gate_col}")

    @property
    def input_dim(self) -> int:
        """Feature columns the stream takes: ``feature_dim``, + 1 with the gate's column."""
        return self.feature_dim + (self.gate_col >= 0)

    @property
    def causal(self) -> bool:
        return True

    @property
    def decoder_context(self) -> int:
        """Codes the decoder reads for one segment (its receptive field): 1 + 1 + 2 + 4."""
        return 8

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "DanceVQConfig":
        return config_from_dict(cls, d)


class _Res(nn.Module):
    """Residual block ``x + conv1x1(relu(conv_k(relu(x))))``; causal (left padding) or centred."""

    def __init__(self, ch: int, kernel: int, dilation: int, causal: bool) -> None:
        super().__init__()
        self.pad = (dilation * (kernel - 1), 0) if causal else (dilation * (kernel - 1) // 2,) * 2
        self.conv = nn.Conv1d(ch, ch, kernel, dilation=dilation)
        self.proj = nn.Conv1d(ch, ch, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.proj(F.relu(self.conv(F.pad(F.relu(x), self.pad))))


class MotionEncoder(nn.Module):
    """Standardised poses (B, T, P), T a multiple of seg -> encodings (B, code_dim, T / seg)."""

    def __init__(self, c: DanceVQConfig) -> None:
        super().__init__()
        layers: list[nn.Module] = [nn.Conv1d(c.pose_dim, c.enc_width, 3, padding=1)]
        for _ in range(c.seg.bit_length() - 1):
            layers += [nn.ReLU(), nn.Conv1d(c.enc_width, c.enc_width, 4, stride=2, padding=1),
                       _Res(c.enc_width, 3, 1, causal=False)]
        layers += [nn.ReLU(), nn.Conv1d(c.enc_width, c.code_dim, 1)]
        self.net = nn.Sequential(*layers)

    def forward(self, poses: torch.Tensor) -> torch.Tensor:
        return self.net(poses.transpose(1, 2))


class EMAQuantizer(nn.Module):
    """Codebook (K, C) updated by exponential moving averages; nearest-code quantisation."""

    def __init__(self, codebook: int, dim: int, decay: float = 0.99) -> None:
        super().__init__()
        self.decay = decay
        self.register_buffer("embed", torch.randn(codebook, dim) * 0.1)
        self.register_buffer("cluster_size", torch.ones(codebook))
        self.register_buffer("embed_avg", self.embed.clone())

    def codes(self, z: torch.Tensor) -> torch.Tensor:
        """Encodings (B, C, N) -> nearest code indices (B, N)."""
        flat = z.transpose(1, 2).reshape(-1, z.shape[1])
        d = flat.pow(2).sum(1, keepdim=True) - 2 * flat @ self.embed.t() + self.embed.pow(2).sum(1)[None]
        return d.argmin(1).reshape(z.shape[0], z.shape[2])

    def lookup(self, codes: torch.Tensor) -> torch.Tensor:
        """Code indices (B, N) -> code vectors (B, C, N)."""
        return F.embedding(codes, self.embed).transpose(1, 2)

    def forward(self, z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(B, C, N) -> (straight-through quantised (B, C, N), codes (B, N), commitment loss)."""
        if self.training and bool((self.cluster_size == 1.0).all()):  # first step: codes start on the data
            with torch.no_grad():
                flat = z.transpose(1, 2).reshape(-1, z.shape[1])
                pick = flat[torch.randint(len(flat), (self.embed.shape[0],))]
                self.embed.copy_(pick + 1e-3 * torch.randn_like(pick))
                self.embed_avg.copy_(self.embed)
        codes = self.codes(z)
        zq = self.lookup(codes)
        if self.training:
            with torch.no_grad():
                flat = z.transpose(1, 2).reshape(-1, z.shape[1])
                onehot = F.one_hot(codes.reshape(-1), self.embed.shape[0]).to(flat.dtype)
                self.cluster_size.mul_(self.decay).add_(onehot.sum(0), alpha=1 - self.decay)
                self.embed_avg.mul_(self.decay).add_(onehot.t() @ flat, alpha=1 - self.decay)
                n = self.cluster_size.sum()
                size = (self.cluster_size + 1e-5) / (n + self.embed.shape[0] * 1e-5) * n
                self.embed.copy_(self.embed_avg / size[:, None])
                dead = self.cluster_size < 0.03  # unused for ~hundreds of steps: restart from the batch
                if dead.any():
                    pick = flat[torch.randint(len(flat), (int(dead.sum()),))]
                    self.embed[dead] = pick
                    self.embed_avg[dead] = pick
                    self.cluster_size[dead] = 1.0
        commit = F.mse_loss(z, zq.detach())
        return z + (zq - z).detach(), codes, commit


class MotionDecoder(nn.Module):
    """Code vectors (B, code_dim, N) -> standardised poses (B, N * seg, P); causal over codes."""

    def __init__(self, c: DanceVQConfig) -> None:
        super().__init__()
        self.seg, self.pose_dim = c.seg, c.pose_dim
        self.inp = nn.Conv1d(c.code_dim, c.dec_width, 1)
        self.blocks = nn.Sequential(*[_Res(c.dec_width, 2, d, causal=True) for d in (1, 2, 4)])
        self.out = nn.Conv1d(c.dec_width, c.seg * c.pose_dim, 1)

    def forward(self, zq: torch.Tensor) -> torch.Tensor:
        h = F.relu(self.blocks(self.inp(zq)))
        y = self.out(h)  # (B, seg * P, N)
        b, _, n = y.shape
        return y.reshape(b, self.seg, self.pose_dim, n).permute(0, 3, 1, 2).reshape(b, n * self.seg, self.pose_dim)


class CodePredictor(nn.Module):
    """Causal Transformer: audio chunks (B, N, seg * D), previous codes (B, N), style (B,) -> logits (B, N, K).

    ``prev[:, j]`` is the code of the step before token j (``codebook`` = none yet, the
    stream's start). N <= window_codes; token j attends to tokens <= j. With
    ``tempo_input``, ``tempo`` (B, N): each token's ln(T / T_ref) (None: 0, the memory's tempo).
    """

    def __init__(self, c: DanceVQConfig) -> None:
        super().__init__()
        self.audio = nn.Sequential(nn.Linear(c.seg * c.feature_dim, c.d_model), nn.GELU(), nn.Linear(c.d_model, c.d_model))
        self.code = nn.Embedding(c.codebook + 1, c.d_model)
        self.style = nn.Embedding(c.num_styles + 1, c.d_model)
        self.tempo = nn.Linear(1, c.d_model, bias=False) if c.tempo_input else None
        self.pos = nn.Parameter(torch.zeros(c.window_codes, c.d_model))
        nn.init.normal_(self.pos, std=0.02)
        layer = nn.TransformerEncoderLayer(c.d_model, c.heads, 4 * c.d_model, c.dropout, activation="gelu",
                                           batch_first=True, norm_first=True)
        self.blocks = nn.TransformerEncoder(layer, c.layers, enable_nested_tensor=False)
        self.norm = nn.LayerNorm(c.d_model)
        self.head = nn.Linear(c.d_model, c.codebook)
        n = c.window_codes
        self.register_buffer("mask", torch.triu(torch.full((n, n), float("-inf")), diagonal=1), persistent=False)

    def forward(self, audio: torch.Tensor, prev: torch.Tensor, style: torch.Tensor,
                tempo: torch.Tensor | None = None) -> torch.Tensor:
        n = audio.shape[1]
        h = self.audio(audio) + self.code(prev) + self.style(style)[:, None] + self.pos[:n]
        if self.tempo is not None and tempo is not None:
            h = h + self.tempo(tempo[..., None].to(h.dtype))
        h = self.blocks(h, mask=self.mask[:n, :n], is_causal=True)
        return self.head(self.norm(h))


class DanceVQ(nn.Module):
    """Motion codebook + causal code predictor (see the module docstring); one checkpoint."""

    stochastic: bool = True  # run_model(seed=...) samples codes: the same seed gives the same dance
    takes_style: bool = True  # run_model(style=...): auto, chacha, rumba, waltz

    def __init__(self, config: DanceVQConfig) -> None:
        super().__init__()
        c = self.config = config
        self.encoder = MotionEncoder(c)
        self.quantizer = EMAQuantizer(c.codebook, c.code_dim)
        self.decoder = MotionDecoder(c)
        self.predictor = CodePredictor(c)
        # standardisation statistics, set from the training data (models.training.dance_vq)
        self.register_buffer("pose_mean", torch.zeros(c.pose_dim))
        self.pose_mean[6::4] = 1.0  # identity rotations until the statistics are set
        self.register_buffer("pose_std", torch.ones(c.pose_dim))
        self.register_buffer("feat_mean", torch.zeros(c.feature_dim))
        self.register_buffer("feat_std", torch.ones(c.feature_dim))
        # idle gate (models.networks.dance_stream), fitted by models.training.dance_vq.fit_music_gate:
        # gate = (log-energy threshold, logistic bias); gate_w: logistic weights on the running mean
        # of GATE_COLUMNS (MFCC 1-12 and the pulse clarity), standardised.
        self.register_buffer("gate", torch.tensor([-1e9, 10.0]))
        self.register_buffer("gate_w", torch.zeros(len(GATE_MFCC) + 1))
        # music presence detector (models.networks.music_gate, fitted by models.training.music_gate);
        # all zeros (checkpoints from before it): the stream uses the logistic detector above
        self.register_buffer("presence", torch.zeros(PRESENCE_PARAMS))
        # its stop network (models.networks.music_gate: judges while the performer dances, without
        # the beat statistics); all zeros (checkpoints from before it): `presence` in both states
        self.register_buffer("presence_stop", torch.zeros(PRESENCE_PARAMS))
        # its voice network (models.networks.music_gate, issue 43: a voice over the music is music;
        # fitted with voices over music labelled music); all zeros (checkpoints from before it): no such rule
        self.register_buffer("presence_voice", torch.zeros(PRESENCE_PARAMS))
        # choreographic memory (models.training.dance_vq.fit_members): for each code, up to
        # `members` real 2 * seg-frame windows of the dancers' poses whose encoding is nearest the
        # code (the first seg frames are the movement, the rest its natural continuation, float16),
        # and how many each code has (0: play the decoder's output).
        self.register_buffer("member_poses", torch.zeros(c.codebook, c.members, 2 * c.seg, c.pose_dim,
                                                         dtype=torch.float16))
        self.register_buffer("member_count", torch.zeros(c.codebook, dtype=torch.int64))
        # what each style's dancers did (models.training.style_memory): every member's style token
        # (1 C, 2 R, 3 W; 0 unknown), and per code and style token (auto, C, R, W) the log of how
        # much likelier the code is in that style's training dances than in the others' (column 0
        # and an unfitted prior: zeros). A requested style plays its own dancers' exemplars and
        # adds the prior to the logits (models.networks.dance_stream).
        self.register_buffer("member_style", torch.zeros(c.codebook, c.members, dtype=torch.int64))
        self.register_buffer("style_prior", torch.zeros(c.codebook, 4))
        # the pace of each member's music (models.training.dance_vq.fit_members): the beat period,
        # frames per beat at 30 fps, of the song (at the clip's training tempo) it was danced to,
        # as the live beat tracker hears it (0: unknown, played at its own pace). DanceStream plays
        # a member at the ratio of the music's tempo to this one (models.networks.dance_stream).
        self.register_buffer("member_period", torch.zeros(c.codebook, c.members))
        # where each member travels (models.training.travel_memory): per frame of its window, the
        # root's horizontal displacement (x, z, metres) and the Hips' heading change (radians about
        # +Y) since the window's first frame, in that frame's heading frame (+Z its facing), from
        # the dancers' own motion, which the canonical poses above drop (models.data.canonical).
        # float16; zeros (checkpoints from before it): every movement in place. The stage part
        # integrates them into a world position and heading (models.networks.stage).
        self.register_buffer("member_travel", torch.zeros(c.codebook, c.members, 2 * c.seg, 3, dtype=torch.float16))

    def _load_from_state_dict(self, state_dict, prefix, local_metadata, strict, missing_keys, unexpected_keys,
                              error_msgs) -> None:
        """Checkpoints saved before the style, tempo or travel memory or the presence detector
        existed load without them (zeros: unknown, not fitted, in place)."""
        for name in ("member_style", "style_prior", "member_period", "member_travel", "presence", "presence_stop",
                     "presence_voice"):
            state_dict.setdefault(prefix + name, torch.zeros_like(getattr(self, name)))
        super()._load_from_state_dict(state_dict, prefix, local_metadata, strict, missing_keys, unexpected_keys,
                                      error_msgs)

    # -- motion codebook -----------------------------------------------------------------
    def standardize_poses(self, poses: torch.Tensor) -> torch.Tensor:
        return (poses - self.pose_mean) / self.pose_std

    def destandardize_poses(self, y: torch.Tensor) -> torch.Tensor:
        """Standardised decoder output (..., P) -> poses with unit quaternions and root x = z = 0."""
        y = y * self.pose_std + self.pose_mean
        root, q = y[..., :3], y[..., 3:].unflatten(-1, (-1, 4))
        q = q / q.norm(dim=-1, keepdim=True).clamp_min(1e-6)
        root = torch.stack((torch.zeros_like(root[..., 0]), root[..., 1], torch.zeros_like(root[..., 2])), -1)
        return torch.cat((root, q.flatten(-2)), -1)

    def reconstruct(self, poses: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Poses (B, T, P) -> (standardised reconstruction (B, T, P), codes (B, T / seg), commitment loss)."""
        zq, codes, commit = self.quantizer(self.encoder(self.standardize_poses(poses)))
        return self.decoder(zq), codes, commit

    @torch.no_grad()
    def encode(self, poses: torch.Tensor) -> torch.Tensor:
        """Poses (B, T, P), T a multiple of seg -> code indices (B, T / seg)."""
        return self.quantizer.codes(self.encoder(self.standardize_poses(poses)))

    @torch.no_grad()
    def decode_last(self, codes: np.ndarray) -> np.ndarray:
        """The ``seg`` poses (seg, P) of the last code of ``codes`` (n,), n <= decoder_context."""
        zq = self.quantizer.lookup(torch.as_tensor(codes, dtype=torch.long)[None])
        return self.destandardize_poses(self.decoder(zq)[0, -self.config.seg:]).numpy()

    # -- audio -> codes --------------------------------------------------------------------
    def audio_tokens(self, features: np.ndarray) -> np.ndarray:
        """Features (T, D), T a multiple of seg, frame 0 at a code boundary -> (T / seg, seg * D) float32.

        Token k holds the standardised frames ``seg * k - seg + 1 .. seg * k``; frames
        before the first are the mean (0 after standardisation).
        """
        s, d = self.config.seg, self.config.feature_dim
        x = (np.asarray(features, np.float32)[:, :d] - self.feat_mean.numpy()) / self.feat_std.numpy()
        padded = np.concatenate([np.zeros((s - 1, d), np.float32), x])
        n = len(x) // s
        return padded[: n * s].reshape(n, s * d)

    @torch.no_grad()
    def next_logits(self, audio: np.ndarray, prev: np.ndarray, style: int, tempo: np.ndarray | None = None) -> np.ndarray:
        """Logits (K,) of the next code from the window's tokens: audio (n, seg * D), prev codes (n,),
        each token's ln(T / T_ref) (n,) where the predictor hears the tempo (None: 0)."""
        a = torch.from_numpy(np.ascontiguousarray(audio, np.float32))[None]
        p = torch.as_tensor(prev, dtype=torch.long)[None]
        t = None if tempo is None else torch.as_tensor(np.asarray(tempo, np.float32))[None]
        return self.predictor(a, p, torch.tensor([style]), t)[0, -1].numpy()

    def sample(self, logits: np.ndarray, rng: np.random.Generator) -> int:
        """One code drawn from ``softmax(logits / temperature)`` over the top_k codes."""
        if not 0 < self.config.top_k < len(logits):  # every code: one compiled call (models/networks/dance_jit.py)
            return int(draw_code(np.ascontiguousarray(logits, np.float32), float(self.config.temperature),
                                 rng.random()))
        z = logits.astype(np.float64) / self.config.temperature
        if 0 < self.config.top_k < len(z):
            cut = np.partition(z, -self.config.top_k)[-self.config.top_k]
            z = np.where(z >= cut, z, -np.inf)
        p = np.exp(z - z.max())
        # rng.choice(len(p), p=p / p.sum()) without its argument checks (about 25 µs of a 35 µs call on
        # the live path): the same cumulative sum, the same uniform draw, the same search, so the same
        # code for the same generator state (tests/test_dance_vq.py holds the two equal)
        cdf = (p / p.sum()).cumsum()
        cdf /= cdf[-1]
        return int(cdf.searchsorted(rng.random(), side="right"))
