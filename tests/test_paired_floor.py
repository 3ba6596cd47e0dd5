"""benchmarks/studies/paired_floor.py: the mean pose and the beat-shift profile it reports."""

from __future__ import annotations


import numpy as np
from scipy.spatial.transform import Rotation

from models.rig.humanoid import NUM_BONES

from script_loader import load_script

paired_floor = load_script("benchmarks/studies/paired_floor.py")


def test_mean_pose_ignores_quaternion_signs_and_averages_the_root():
    q = Rotation.from_euler("x", [[10.0], [20.0], [30.0]], degrees=True).as_quat()  # (3, 4)
    poses = np.zeros((3, 3 + 4 * NUM_BONES), np.float32)
    poses[:, :3] = [[0, 1, 0], [0, 2, 0], [0, 3, 0]]
    poses[:, 3:] = np.tile(q, NUM_BONES)
    poses[1, 3:] *= -1.0  # the same rotations, other hemisphere
    m = paired_floor.mean_pose(poses)
    np.testing.assert_allclose(m[:3], [0, 2, 0])
    want = Rotation.from_euler("x", 20.0, degrees=True).as_quat()  # nlerp mean of 10/20/30 deg
    got = m[3:].reshape(NUM_BONES, 4)
    np.testing.assert_allclose(np.abs(got @ want), 1.0, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(got, axis=1), 1.0, atol=1e-6)


def test_shift_profile_peaks_where_the_motion_decelerates():
    """A joint whose speed dips 3 frames after every beat: the hit rate is highest with the beats
    moved 1..5 frames later (a kinematic beat within +-2 frames), centred on +3, and 0 far
    from it."""
    period, t = 16, 640
    beats = np.arange(8, t - 8, period)
    u = np.arange(t) - beats[0] - 3.0  # 0 at beat + 3
    # x(t) = integral of the speed 0.3 - 0.25 cos(2 pi u / P) m/s, lowest at beat + 3
    x = (0.3 * u - 0.25 * period / (2 * np.pi) * np.sin(2 * np.pi * u / period)) / 30.0
    pos = np.zeros((t, 2, 3))
    pos[:, 0, 0] = x
    prof = np.array(paired_floor.shift_profile([pos], [beats], shifts=range(-8, 9)))
    best = np.flatnonzero(prof == prof.max()) - 8
    assert prof.max() > 0.95 and best.tolist() == [1, 2, 3, 4, 5]  # (the dip after the last beat has no beat)
    assert prof[8] == 0.0 and prof[:8].max() == 0.0  # shift 0 and earlier: no kinematic beat within +-2
