"""Training losses of Chen et al. (TVCG 2021), on the flat pose layout of
:mod:`models.rig.motion` (root xyz, then one xyzw quaternion per bone), at 30 fps.

- rotation L1: mean |q_pred - q_true| over bones, taking for each the sign of
  q_true that is closer (q and -q are one rotation), plus L1 on the root height;
- end-effector L1: mean |p_pred - p_true| in metres of both hands, the head and
  both feet after differentiable forward kinematics on the canonical skeleton;
- (not in the paper, off by default) velocity and acceleration L1 and a beat loss,
  :func:`beat_speed_ratio`, that asks the motion to slow down on the beats the causal
  beat-phase feature columns predict (models/features/context.py);
- conditional GAN loss, least-squares form (Mao et al. 2017) on every patch score
  of the multi-scale discriminator: D pushes real (audio, motion) pairs to 1 and
  generated ones to 0, G pushes its pairs to 1.
"""

from __future__ import annotations

import torch

from models.rig.humanoid import END_EFFECTORS, NUM_BONES, bone_index
from models.rig.kinematics import fk_torch

EFFECTOR_INDEX: tuple[int, ...] = tuple(bone_index(b) for b in END_EFFECTORS)


def split_pose(pose: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(B, POSE_DIM, T) -> root (B, T, 3), quaternions (B, T, NUM_BONES, 4)."""
    x = pose.transpose(1, 2)
    return x[..., :3], x[..., 3:].reshape(*x.shape[:2], NUM_BONES, 4)


def rotation_l1(pred: torch.Tensor, true: torch.Tensor) -> torch.Tensor:
    """Sign-invariant quaternion L1 plus root-height L1; inputs (B, POSE_DIM, T)."""
    rp, qp = split_pose(pred)
    rt, qt = split_pose(true)
    d = torch.minimum((qp - qt).abs().sum(-1), (qp + qt).abs().sum(-1)) / 4.0
    return d.mean() + (rp[..., 1] - rt[..., 1]).abs().mean()


def effector_positions(pose: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
    """(B, POSE_DIM, T) -> (B, T, len(END_EFFECTORS), 3) world positions in metres."""
    root, quats = split_pose(pose)
    return fk_torch(root, quats, offsets)[:, :, EFFECTOR_INDEX]


def effector_l1(pred: torch.Tensor, true: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
    """Mean L1 (metres) between end-effector positions of two pose batches."""
    return (effector_positions(pred, offsets) - effector_positions(true, offsets)).abs().mean()


def velocity_l1(pred: torch.Tensor, true: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
    """L1 between frame-to-frame changes of pred and true: quaternion components plus
    end-effector positions (metres per frame). Penalises jitter that per-frame L1 misses."""
    dq = (pred[:, 3:].diff(dim=-1) - true[:, 3:].diff(dim=-1)).abs().mean()
    ep, et = effector_positions(pred, offsets), effector_positions(true, offsets)
    return dq + (ep.diff(dim=1) - et.diff(dim=1)).abs().mean()


def acceleration_l1(pred: torch.Tensor, true: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
    """L1 between second differences of pred and true: quaternion components plus
    end-effector positions (metres per frame squared). Penalises the per-frame jerk of a
    causal model whose coarse levels update every 2**level frames; not in the paper."""
    aq = (pred[:, 3:].diff(n=2, dim=-1) - true[:, 3:].diff(n=2, dim=-1)).abs().mean()
    ep, et = effector_positions(pred, offsets), effector_positions(true, offsets)
    return aq + (ep.diff(n=2, dim=1) - et.diff(n=2, dim=1)).abs().mean()


def beat_speed_ratio(pred: torch.Tensor, beat: torch.Tensor, offsets: torch.Tensor, sharpness: float = 8.0) -> torch.Tensor:
    """Mean joint speed on the predicted beats over the mean joint speed (scale-free).

    pred: (B, POSE_DIM, T) poses at 30 fps; beat: (B, 4, T) the beat-phase feature
    columns ``[c cos(theta), c sin(theta), c, log2(P / 15)]`` of the same frames
    (:mod:`models.features.context`). Speed s[t]: mean over all FK joints of
    ``|p[t] - p[t-1]|`` (metres per frame). Beat weight ``g[t] = c[t] ((1 + cos theta[t]) /
    2) ** sharpness``: a bump around phase 0 about P/5 frames wide, scaled by the pulse
    clarity. Returns the batch mean of ``(sum g s / sum g) / mean s``: below 1 when the
    motion is slower on the beats than on average, which is what the kinematic beats of
    Lee et al. (speed minima) count. Dividing by the mean speed leaves the motion's
    amplitude to the other losses.
    """
    root, quats = split_pose(pred)
    pos = fk_torch(root, quats, offsets)  # (B, T, J, 3)
    speed = (pos[:, 1:] - pos[:, :-1]).norm(dim=-1).mean(dim=-1)  # (B, T-1): frames 1..T-1
    c = beat[:, 2, 1:].clamp(min=0.0)
    cos = beat[:, 0, 1:] / c.clamp(min=1e-6)
    g = c * ((1.0 + cos.clamp(-1.0, 1.0)) / 2.0) ** sharpness
    on_beat = (g * speed).sum(dim=1) / g.sum(dim=1).clamp(min=1e-6)
    return (on_beat / speed.mean(dim=1).clamp(min=1e-6)).mean()


def d_loss(real_maps: list[torch.Tensor], fake_maps: list[torch.Tensor]) -> torch.Tensor:
    """Least-squares discriminator loss, averaged over the four scales."""
    terms = [((r - 1) ** 2).mean() + (f**2).mean() for r, f in zip(real_maps, fake_maps)]
    return torch.stack(terms).mean() / 2


def g_gan_loss(fake_maps: list[torch.Tensor]) -> torch.Tensor:
    """Least-squares generator loss, averaged over the four scales."""
    return torch.stack([((f - 1) ** 2).mean() for f in fake_maps]).mean()
