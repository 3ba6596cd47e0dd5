"""Canonical motion for training: the performer dances in place, facing +Z.

Music says nothing about where on the stage a dancer stands or which way they face,
so a network asked to predict the world position and heading can only learn their
average. Training targets therefore drop the root's horizontal position and the
Hips' heading (rotation about the vertical axis); everything else — hip height,
hip tilt and roll, every other bone's local rotation — is kept. A receiver that
wants travel or turns adds them itself.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from models.rig.kinematics import hemisphere_align
from models.rig.motion import Motion
from models.rig.travel import _HIPS, heading  # noqa: F401  (heading: read here by its users)


def canonicalize(motion: Motion) -> Motion:
    """Remove horizontal root position and Hips heading; keep hip height and all else.

    Returns a new Motion with root (0, y, 0) and Hips rotation ``Ry(-heading) * R``.
    """
    rot = motion.rotations.copy()
    hips = Rotation.from_quat(rot[:, _HIPS])
    unyaw = Rotation.from_rotvec(np.outer(-heading(hips), [0.0, 1.0, 0.0]))
    rot[:, _HIPS] = (unyaw * hips).as_quat()
    root = np.zeros_like(motion.root_pos)
    root[:, 1] = motion.root_pos[:, 1]
    return Motion(root_pos=root, rotations=hemisphere_align(rot), fps=motion.fps)
