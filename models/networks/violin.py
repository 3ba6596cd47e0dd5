"""The violinist model of Kao and Su, "Temporally Guided Music-to-Body-Movement
Generation" (ACM MM 2020), on this project's humanoid rig.

Input: the ``"mfcc"`` audio features ``(B, 28, T)`` at 30 fps (13 MFCC + log mean
energy + their backward differences, :mod:`models.features.spectral`). Output: poses
``(B, POSE_DIM, T)`` in the flat layout of :mod:`models.rig.motion`.

Data flow (the paper's Fig. 2, checked against the authors' code, ``MovementNet`` in
github.com/hsuankai/Temporally-Guided-Music-to-Body-Movement-Generation)::

    x ─► input standardisation ─┬─► body decoder: LSTM(28 -> d) + linear ─────────► root + body bones
                                │
                                └─► hand encoder: linear(28 -> d)
                                      ─► M x [U-Net encoder ─► rel.-pos. self-attention ─► U-Net decoder]
                                      ─► position-wise FFN (d_ff = 4d)  = e
                                    hand decoder: LSTM(d -> d) + linear(e) ───────► arm bones (both arms)
                                    refinement:   linear(e) ─► correction of the most active hand's
                                                  LowerArm + Hand rotations

* **Body decoder** (the paper's body branch): a one-layer LSTM with a trainable initial
  state, fed directly by the audio features, and a linear layer; it gives the root
  position and the 13 bones outside the arms.
* **Hand encoder** (the paper's right-hand branch): a linear layer to ``d``, then
  ``blocks`` (M = 2) U-Net blocks. Each block's encoder has ``levels`` (N = 4) levels of
  average pooling by 2 followed by 2 x (conv k=3 + BatchNorm + ReLU), all ``d`` wide;
  its bottleneck (30 / 2**N fps) is a Transformer layer: 4-head self-attention with
  relative position representations (Shaw et al., NAACL 2018: learned key and value
  embeddings of the clipped distance ``j - i`` in ``[-max_rel, max_rel]``, shared by the
  heads), then a position-wise FFN, each with a residual connection and post layer
  norm, as in the authors' code; its decoder upsamples by linear interpolation to the
  skip's length, concatenates the skip and applies 2 x (conv + BN + ReLU). After the
  blocks, a position-wise FFN (d_ff = 4d, residual + layer norm).
* **Hand decoder**: LSTM(d -> d) with a trainable initial state + linear, on the
  encoder output; it gives the 8 arm bones (Left/Right Shoulder, UpperArm, LowerArm,
  Hand). In the paper this branch gives the violinist's right (bowing) arm.
* **Refinement**: the paper adds a linear correction of the encoder output to the
  right (bowing) wrist. Dance has no designated bowing hand, so here the model decides
  the most active hand per segment of ``refine_segment`` frames: FK of the unrefined
  pose on the default skeleton, mean wrist speed per segment, the faster wrist wins.
  A linear layer of the encoder output gives a correction to each hand's LowerArm and
  Hand quaternions, and the correction of the chosen hand is added (before the
  quaternions are normalised). The choice is 0/1 per segment and is interpolated
  linearly between segment centres, so the correction never switches in one frame.
  The choice is not differentiated (like the paper's fixed choice of the right hand).

Input standardisation (``input_norm``): a BatchNorm1d without affine parameters over the
28 features. The MFCC values span O(1000) (c0 of a dB log-mel); the paper's data is
normalised before the network. Its running statistics are the training set's.

Deviations from the paper, all documented in docs/violin.md: rotations (quaternions)
instead of 3-D joint positions as the output; both arms (not only the right) in the
hand branch; the refinement hand chosen per segment; ``d_model`` 128 instead of 512
(trainable on a CPU; a config field); the paper's bowing-attack inference is not part
of the network (it is a separate post-hoc mechanism and needs bowing annotations).

**Offline only.** Every output frame depends on future audio: the U-Net convs are
centred (each looks one frame ahead at its level, up to 16 frames at the bottleneck),
average pooling and linear-interpolation upsampling mix later frames into earlier ones,
the bottleneck self-attention attends over the whole window, and the hand choice uses
the whole segment. So it cannot stream (``performer run`` refuses it, see
:attr:`ViolinNet.offline_only`); ``performer generate`` and ``performer evaluate`` run
it with one forward pass over the whole song. Any T >= 1 is accepted: the hand
encoder's input is padded at the end (repeating the last frame) to a multiple of
``2**levels`` and its output cropped (the body LSTM sees only the T real frames).
The attention takes a key padding mask (``encode(x, key_padding_mask)``) for batches
of sequences of different lengths; a single sequence needs none.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

from models.errors import ConfigError
from models.networks.generator import config_from_dict, normalize_pose
from models.rig.humanoid import BONES, bone_index
from models.rig.motion import POSE_DIM

#: Bones the hand branch predicts (the paper's right-arm branch, here both arms).
ARM_BONES: tuple[str, ...] = (
    "LeftShoulder", "LeftUpperArm", "LeftLowerArm", "LeftHand",
    "RightShoulder", "RightUpperArm", "RightLowerArm", "RightHand",
)
#: Per hand (left, right): the bones whose rotations the refinement corrects.
REFINED_BONES: tuple[tuple[str, str], ...] = (("LeftLowerArm", "LeftHand"), ("RightLowerArm", "RightHand"))
#: FK points (bone heads) whose speed decides the most active hand: the wrists.
WRISTS: tuple[str, str] = ("LeftHand", "RightHand")


def _quat_channels(bones: tuple[str, ...] | list[str]) -> list[int]:
    """Flat pose channels of the quaternions of ``bones`` (4 each, in order)."""
    return [3 + 4 * bone_index(b) + c for b in bones for c in range(4)]


@dataclass(frozen=True)
class ViolinConfig:
    """Hyper-parameters of :class:`ViolinNet` (paper values in brackets).

    feature_dim: audio features per frame [28]. pose_dim: POSE_DIM.
    d_model: width d of every layer [512]. levels: U-Net pooling levels N [4].
    blocks: stacked U-Net + attention blocks M [2]. heads: attention heads [4].
    max_rel: relative distances are clipped to [-max_rel, max_rel] bottleneck frames.
    dropout: after each double conv, in attention, FFNs and before the output layers [0.1].
    refine_segment: frames per most-active-hand decision (>= 2).
    input_norm: standardise the input features (BatchNorm without affine).
    """

    feature_dim: int = 28
    pose_dim: int = POSE_DIM
    d_model: int = 128
    levels: int = 4
    blocks: int = 2
    heads: int = 4
    max_rel: int = 16
    dropout: float = 0.1
    refine_segment: int = 64
    input_norm: bool = True

    @property
    def causal(self) -> bool:
        return False

    def __post_init__(self) -> None:
        ints = ("feature_dim", "pose_dim", "d_model", "levels", "blocks", "heads", "max_rel", "refine_segment")
        for name in ints:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int):
                raise ConfigError(f"violin config {name}={v!r} must be an integer")
        if self.pose_dim != POSE_DIM:
            raise ConfigError(f"the violin model predicts the humanoid rig: pose_dim must be {POSE_DIM}, got {self.pose_dim}")
        if self.feature_dim < 1 or self.d_model < 1 or self.heads < 1 or self.d_model % self.heads:
            raise ConfigError(f"need feature_dim, d_model >= 1 and d_model divisible by heads; got {self}")
        if not 1 <= self.levels <= 8 or self.blocks < 1 or self.max_rel < 1 or self.refine_segment < 2:
            raise ConfigError(f"need 1 <= levels <= 8, blocks >= 1, max_rel >= 1, refine_segment >= 2; got {self}")
        if isinstance(self.dropout, bool) or not isinstance(self.dropout, (int, float)) or not 0 <= self.dropout < 1:
            raise ConfigError(f"dropout must be in [0, 1), got {self.dropout!r}")
        if not isinstance(self.input_norm, bool):
            raise ConfigError(f"input_norm must be true or false, got {self.input_norm!r}")
        object.__setattr__(self, "dropout", float(self.dropout))

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "ViolinConfig":
        return config_from_dict(cls, d)


# --------------------------------------------------------------------------- attention


def relative_index(t_q: int, t_k: int, max_rel: int, device: torch.device | None = None) -> torch.Tensor:
    """(t_q, t_k) long: ``clip(j - i, -max_rel, max_rel) + max_rel``, the embedding row of each pair."""
    i = torch.arange(t_q, device=device)[:, None]
    j = torch.arange(t_k, device=device)[None, :]
    return (j - i).clamp(-max_rel, max_rel) + max_rel


class RelativeMultiheadAttention(nn.Module):
    """Multi-head self-attention with relative position representations (Shaw et al. 2018).

    For heads of width ``dh = d / heads``, with ``a^K_ij = w^K[clip(j - i)]`` and
    ``a^V_ij = w^V[clip(j - i)]`` (learned, shared by the heads)::

        e_ij = q_i . (k_j + a^K_ij) / sqrt(dh);   z_i = sum_j softmax_j(e_ij) (v_j + a^V_ij)

    ``key_padding_mask`` (B, T) bool, True = a key to ignore (every query keeps at least
    one key). Input and output (B, T, d).
    """

    def __init__(self, d_model: int, heads: int, max_rel: int, dropout: float = 0.0) -> None:
        super().__init__()
        if d_model % heads:
            raise ConfigError(f"d_model {d_model} is not divisible by {heads} heads")
        self.heads, self.dh, self.max_rel = heads, d_model // heads, max_rel
        self.q = nn.Linear(d_model, d_model, bias=False)
        self.k = nn.Linear(d_model, d_model, bias=False)
        self.v = nn.Linear(d_model, d_model, bias=False)
        self.out = nn.Linear(d_model, d_model)
        self.rel_k = nn.Parameter(torch.randn(2 * max_rel + 1, self.dh) * self.dh**-0.5)
        self.rel_v = nn.Parameter(torch.randn(2 * max_rel + 1, self.dh) * self.dh**-0.5)
        self.drop = nn.Dropout(dropout)

    def forward(
        self, x: torch.Tensor, key_padding_mask: torch.Tensor | None = None, need_weights: bool = False
    ) -> torch.Tensor | tuple[torch.Tensor, torch.Tensor]:
        b, t, d = x.shape
        q, k, v = (m(x).view(b, t, self.heads, self.dh).transpose(1, 2) for m in (self.q, self.k, self.v))
        idx = relative_index(t, t, self.max_rel, x.device)
        a_k, a_v = self.rel_k[idx], self.rel_v[idx]  # (T, T, dh)
        logits = (q @ k.transpose(-1, -2) + torch.einsum("bhid,ijd->bhij", q, a_k)) / math.sqrt(self.dh)
        if key_padding_mask is not None:
            logits = logits.masked_fill(key_padding_mask[:, None, None, :], float("-inf"))
        w = torch.softmax(logits, dim=-1)
        wd = self.drop(w)
        z = wd @ v + torch.einsum("bhij,ijd->bhid", wd, a_v)
        y = self.out(z.transpose(1, 2).reshape(b, t, d))
        return (y, w) if need_weights else y


class FeedForward(nn.Module):
    """Position-wise FFN d -> 4d -> d (ReLU) with a residual connection and post layer norm."""

    def __init__(self, d_model: int, dropout: float) -> None:
        super().__init__()
        self.net = nn.Sequential(
            nn.Linear(d_model, 4 * d_model), nn.ReLU(), nn.Dropout(dropout), nn.Linear(4 * d_model, d_model),
            nn.Dropout(dropout),
        )
        self.norm = nn.LayerNorm(d_model)

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # (B, T, d)
        return self.norm(x + self.net(x))


class BottleneckAttention(nn.Module):
    """Transformer layer at the U-Net bottleneck: relative self-attention, then FFN (post-LN)."""

    def __init__(self, d_model: int, heads: int, max_rel: int, dropout: float) -> None:
        super().__init__()
        self.attn = RelativeMultiheadAttention(d_model, heads, max_rel, dropout)
        self.drop = nn.Dropout(dropout)
        self.norm = nn.LayerNorm(d_model)
        self.ffn = FeedForward(d_model, dropout)

    def forward(self, x: torch.Tensor, key_padding_mask: torch.Tensor | None = None) -> torch.Tensor:
        x = self.norm(x + self.drop(self.attn(x, key_padding_mask)))
        return self.ffn(x)


# --------------------------------------------------------------------------- U-Net


class DoubleConv(nn.Sequential):
    """2 x (conv1d k=3, centred + BatchNorm + ReLU), then dropout; (B, c_in, T) -> (B, c_out, T)."""

    def __init__(self, c_in: int, c_out: int, dropout: float) -> None:
        super().__init__(
            nn.Conv1d(c_in, c_out, 3, padding=1, bias=False), nn.BatchNorm1d(c_out), nn.ReLU(),
            nn.Conv1d(c_out, c_out, 3, padding=1, bias=False), nn.BatchNorm1d(c_out), nn.ReLU(),
            nn.Dropout(dropout),
        )


class UNetAttentionBlock(nn.Module):
    """One U-Net with self-attention at its bottleneck, all ``d`` wide; (B, d, T) -> (B, d, T).

    Encoder level L = 1..N: average pool by 2, DoubleConv. Bottleneck (T / 2**N):
    :class:`BottleneckAttention`. Decoder level L = N-1..0: linear interpolation to the
    skip's length, concatenate [skip, upsampled], DoubleConv(2d -> d). The skip of level
    0 is the block's input.
    """

    def __init__(self, d_model: int, levels: int, heads: int, max_rel: int, dropout: float) -> None:
        super().__init__()
        self.down = nn.ModuleList(DoubleConv(d_model, d_model, dropout) for _ in range(levels))
        self.attn = BottleneckAttention(d_model, heads, max_rel, dropout)
        self.up = nn.ModuleList(DoubleConv(2 * d_model, d_model, dropout) for _ in range(levels))

    def forward(self, x: torch.Tensor, key_padding_mask: torch.Tensor | None = None) -> torch.Tensor:
        skips = []
        for down in self.down:
            skips.append(x)
            x = down(F.avg_pool1d(x, 2))
        x = self.attn(x.transpose(1, 2), key_padding_mask).transpose(1, 2)
        for up, skip in zip(self.up, reversed(skips)):
            x = F.interpolate(x, size=skip.shape[-1], mode="linear", align_corners=False)
            x = up(torch.cat((skip, x), dim=1))
        return x


# --------------------------------------------------------------------------- decoders


class LSTMDecoder(nn.Module):
    """One-layer LSTM with a trainable initial state, dropout, linear; (B, T, c_in) -> (B, T, c_out)."""

    def __init__(self, c_in: int, hidden: int, c_out: int, dropout: float) -> None:
        super().__init__()
        self.lstm = nn.LSTM(c_in, hidden, num_layers=1, batch_first=True)
        self.h0 = nn.Parameter(torch.zeros(1, 1, hidden))
        self.c0 = nn.Parameter(torch.zeros(1, 1, hidden))
        self.drop = nn.Dropout(dropout)
        self.fc = nn.Linear(hidden, c_out)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b = x.shape[0]
        h, _ = self.lstm(x, (self.h0.expand(-1, b, -1).contiguous(), self.c0.expand(-1, b, -1).contiguous()))
        return self.fc(self.drop(h))


def _init_quat_head(linear: nn.Linear, channels: list[int]) -> None:
    """Small weights; bias = identity quaternions (w = 1) on the output rows that are a w."""
    with torch.no_grad():
        linear.weight.mul_(0.1)
        linear.bias.zero_()
        for row, ch in enumerate(channels):
            if ch >= 3 and (ch - 3) % 4 == 3:
                linear.bias[row] = 1.0


# --------------------------------------------------------------------------- the model


class ViolinNet(nn.Module):
    """Kao & Su's violinist model (see the module docstring); ``(B, D, T) -> (B, POSE_DIM, T)``.

    Offline only (:attr:`offline_only`): every output frame depends on the whole input
    window. ``forward(x, return_parts=True)`` also returns the unrefined pose, the
    per-frame weight of the right hand in the refinement (0 = left) and the correction.
    """

    output_delay: int = 0
    offline_only: bool = True
    offline_reason: str = (
        "its U-Net (centred convs, pooling, interpolation) and bottleneck self-attention read future "
        "frames, so no output frame is final before the whole window has been heard"
    )

    def __init__(self, config: ViolinConfig | None = None) -> None:
        super().__init__()
        self.config = cfg = config or ViolinConfig()
        d = cfg.d_model
        arm = _quat_channels(ARM_BONES)
        body = [c for c in range(cfg.pose_dim) if c not in set(arm)]  # root xyz + 13 bones
        self.register_buffer("arm_channels", torch.tensor(arm), persistent=False)
        self.register_buffer("body_channels", torch.tensor(body), persistent=False)
        self.register_buffer(
            "refine_channels",
            torch.tensor([_quat_channels(pair) for pair in REFINED_BONES]),  # (2 hands, 8)
            persistent=False,
        )
        from models.rig.skeleton import load_default_skeleton

        offsets = torch.from_numpy(load_default_skeleton().offsets).float()
        self.register_buffer("offsets", offsets, persistent=False)
        self.wrists = [bone_index(b) for b in WRISTS]

        self.norm = nn.BatchNorm1d(cfg.feature_dim, affine=False) if cfg.input_norm else nn.Identity()
        self.body = LSTMDecoder(cfg.feature_dim, d, len(body), cfg.dropout)
        self.proj = nn.Linear(cfg.feature_dim, d)
        self.blocks = nn.ModuleList(
            UNetAttentionBlock(d, cfg.levels, cfg.heads, cfg.max_rel, cfg.dropout) for _ in range(cfg.blocks)
        )
        self.ffn = FeedForward(d, cfg.dropout)
        self.hand = LSTMDecoder(d, d, len(arm), cfg.dropout)
        self.refine = nn.Linear(d, 2 * 8)
        _init_quat_head(self.body.fc, body)
        _init_quat_head(self.hand.fc, arm)
        with torch.no_grad():
            self.refine.weight.mul_(0.1)
            self.refine.bias.zero_()

    # ----------------------------------------------------------------- pieces

    def encode(self, x: torch.Tensor, key_padding_mask: torch.Tensor | None = None) -> torch.Tensor:
        """Hand encoder: standardised features (B, D, T), T a multiple of 2**levels -> (B, T, d)."""
        h = self.proj(x.transpose(1, 2)).transpose(1, 2)
        for block in self.blocks:
            h = block(h, key_padding_mask)
        return self.ffn(h.transpose(1, 2))

    @torch.no_grad()
    def right_hand_weight(self, pose: torch.Tensor) -> torch.Tensor:
        """(B, T) weight of the right hand in the refinement, from an unrefined pose (B, P, T).

        Per segment of ``refine_segment`` frames (the last may be shorter): 1 where the
        right wrist's mean FK speed (default skeleton) exceeds the left's, else 0;
        linearly interpolated between segment centres, constant before the first centre
        and after the last.
        """
        from models.rig.kinematics import fk_torch

        b, _, frames = pose.shape
        seg = self.config.refine_segment
        x = normalize_pose(pose).float().transpose(1, 2)
        root, quats = x[..., :3], x[..., 3:].unflatten(-1, (len(BONES), 4))
        wrists = fk_torch(root, quats, self.offsets)[:, :, self.wrists]  # (B, T, 2, 3)
        speed = torch.zeros(b, frames, 2, device=pose.device)
        speed[:, 1:] = (wrists[:, 1:] - wrists[:, :-1]).norm(dim=-1)
        n_seg = -(-frames // seg)
        pad = n_seg * seg - frames
        counts = torch.full((n_seg,), float(seg), device=pose.device)
        counts[-1] = seg - pad
        sums = F.pad(speed.transpose(1, 2), (0, pad)).unflatten(-1, (n_seg, seg)).sum(-1)  # (B, 2, S)
        mean = sums / counts
        choice = (mean[:, 1] > mean[:, 0]).float()  # (B, S), 1 = right hand
        w = F.interpolate(choice[:, None], scale_factor=seg, mode="linear", align_corners=False)[:, 0]
        return w[:, :frames]

    # ----------------------------------------------------------------- forward

    def forward(self, x: torch.Tensor, return_parts: bool = False):
        cfg = self.config
        if x.ndim != 3 or x.shape[1] != cfg.feature_dim:
            raise ConfigError(f"violin model input must be (B, {cfg.feature_dim}, T), got {tuple(x.shape)}")
        b, _, t = x.shape
        if t < 1:
            raise ConfigError("violin model input needs at least one frame")
        mult = 2**cfg.levels
        tp = -(-t // mult) * mult
        x = self.norm(x)
        body = self.body(x.transpose(1, 2))  # (B, T, body); the LSTM never sees the padding
        xp = F.pad(x, (0, tp - t), mode="replicate") if tp > t else x
        enc = self.encode(xp)[:, :t]  # (B, T, d)
        arm = self.hand(enc)
        pose = x.new_zeros(b, t, cfg.pose_dim)
        pose[..., self.body_channels] = body
        pose[..., self.arm_channels] = arm
        pose = pose.transpose(1, 2)  # (B, P, T)
        w_right = self.right_hand_weight(pose)  # (B, T)
        corr = self.refine(enc).unflatten(-1, (2, 8))  # (B, T, hand, 8)
        weights = torch.stack((1.0 - w_right, w_right), dim=-1)[..., None]  # (B, T, 2, 1)
        delta = x.new_zeros(b, t, cfg.pose_dim)
        delta[..., self.refine_channels.flatten()] = (corr * weights).flatten(-2)
        out = normalize_pose(pose + delta.transpose(1, 2))
        if return_parts:
            return out, {"unrefined": normalize_pose(pose), "right_weight": w_right, "correction": delta.transpose(1, 2)}
        return out


__all__ = ["ViolinConfig", "ViolinNet", "RelativeMultiheadAttention", "relative_index", "UNetAttentionBlock"]
