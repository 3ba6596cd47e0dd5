"""Training batches and seeding shared by every trainer (:mod:`models.training.train`,
:mod:`models.training.gcn_train`, :mod:`models.training.dance_vq`, :mod:`models.training.dtm`)."""

from __future__ import annotations

import random
from dataclasses import dataclass

import numpy as np
import torch

from models.data.corpus import Clip


@dataclass
class Batch:
    features: torch.Tensor  # (B, D, T)
    poses: torch.Tensor  # (B, POSE_DIM, T)


class SegmentSampler:
    """Random fixed-length segments, clips weighted by how many segments they hold."""

    def __init__(self, clips: list[Clip], segment: int, rng: np.random.Generator) -> None:
        self.clips, self.starts = [], []
        for c in clips:  # valid starts: segments holding no frame of a frozen mocap run
            if c.num_frames < segment:
                continue
            bad = np.concatenate([[0], np.cumsum(~c.valid)])
            ok = np.flatnonzero(bad[segment:] - bad[:-segment] == 0)
            if len(ok):
                self.clips.append(c)
                self.starts.append(ok)
        if not self.clips:
            raise ValueError(f"no clip holds {segment} valid frames in a row")
        counts = np.array([len(s) for s in self.starts], dtype=np.float64)
        self.p = counts / counts.sum()
        self.segment = segment
        self.rng = rng

    def sample(self, batch_size: int) -> Batch:
        idx = self.rng.choice(len(self.clips), size=batch_size, p=self.p)
        feats, poses = [], []
        for i in idx:
            c = self.clips[i]
            s = int(self.rng.choice(self.starts[i]))
            feats.append(c.features[s : s + self.segment])
            poses.append(c.poses[s : s + self.segment])
        f = torch.from_numpy(np.stack(feats)).transpose(1, 2).contiguous()
        p = torch.from_numpy(np.stack(poses)).transpose(1, 2).contiguous()
        return Batch(f, p)


def seed_all(seed: int) -> None:
    """Seed Python's, NumPy's global and torch's random generators with ``seed``."""
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)
