"""A dancer's travel across the floor and turns, from a motion's root (the stage's format).

The choreographic memory keeps, beside each exemplar's canonical poses, where its dancer went
(``DanceVQ.member_travel``, models/networks/stage.py plays it): per frame of the window the
root's displacement and the Hips' heading change since its first frame, in that frame's
heading frame. These read it from a motion before it is put in place
(models/data/canonical.py): the training memory (models/training/travel_memory.py) and a
user's library (models/networks/library_player.py) alike.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from models.rig.humanoid import BONE_INDEX

_HIPS = BONE_INDEX["Hips"]


def heading(hips_rot: Rotation) -> np.ndarray:
    """(T,) heading angles in radians: the yaw of the Hips' forward (+Z) axis about +Y."""
    fwd = hips_rot.apply(np.array([0.0, 0.0, 1.0]))
    return np.arctan2(fwd[:, 0], fwd[:, 2])


def root_track(motion) -> np.ndarray:
    """(T, 3) float64: the root's x, z (m) and the Hips' unwrapped heading (rad) of a
    retargeted, not canonicalised :class:`~models.rig.motion.Motion`."""
    h = np.unwrap(heading(Rotation.from_quat(motion.rotations[:, _HIPS])))
    return np.stack([motion.root_pos[:, 0], motion.root_pos[:, 2], h], 1)


def window_travel(track: np.ndarray) -> np.ndarray:
    """(F, 3) float32 travel of one window from its root track (F, 3): x, z (m) and unwrapped
    heading (rad) per frame: each frame's horizontal displacement from frame 0 turned into
    frame 0's heading frame (+Z its facing), and its heading change since frame 0
    (``DanceVQ.member_travel``)."""
    d = track[:, :2] - track[:1, :2]
    c, s = np.cos(track[0, 2]), np.sin(track[0, 2])
    return np.stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1], track[:, 2] - track[0, 2]], 1).astype(np.float32)
