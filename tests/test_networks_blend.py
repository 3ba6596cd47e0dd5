"""Rotation-aware window blending and the seam measure."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from models.errors import DataError
from models.networks.blend import (
    align_sequence,
    blend_frame,
    blend_poses,
    blend_track,
    crossfade_weights,
    sanitize_quaternions,
    seam_ratio,
    slot_weights,
)
from models.rig.humanoid import NUM_BONES
from models.rig.motion import POSE_DIM

RNG = np.random.default_rng(0)


def random_poses(n: int, rng=RNG) -> np.ndarray:
    q = Rotation.random(n * NUM_BONES, random_state=rng).as_quat().reshape(n, -1)
    return np.concatenate([rng.normal(size=(n, 3)), q], axis=1).astype(np.float32)


def quats(p: np.ndarray) -> np.ndarray:
    return p[..., 3:].reshape(*p.shape[:-1], NUM_BONES, 4)


def test_crossfade_weights_are_a_partition_of_unity_for_half_overlap():
    w = crossfade_weights(128, 64)
    assert (w > 0).all() and w.max() <= 1.0
    np.testing.assert_allclose(w[64:] + w[:64], 1.0, atol=1e-12)
    assert (np.diff(w[:64]) > 0).all()  # a fresh window fades in
    assert w[0] < 0.01 and w[-1] < 0.01


@pytest.mark.parametrize("window,hop", [(128, 64), (128, 32), (96, 64), (64, 64)])
def test_slot_weights_cover_every_frame(window, hop):
    frames = np.arange(500)
    index, w = slot_weights(frames, window, hop)
    assert (w.sum(axis=0) > 0).all()
    covered = w > 0
    start = index * hop
    assert ((frames >= start) & (frames < start + window))[covered].all()
    assert (covered.sum(axis=0) <= int(np.ceil(window / hop))).all()
    assert covered[:, :hop].sum(axis=0).tolist() == [1] * hop  # only window 0 at the start


def test_blend_of_identical_candidates_is_identity():
    p = random_poses(20)
    out = blend_poses(np.stack([p, p, p]), RNG.uniform(0.1, 1.0, size=(3, 20)))
    np.testing.assert_allclose(out, p, atol=1e-6)


def test_blend_is_unit_norm_and_roots_are_lerped():
    a, b = random_poses(50), random_poses(50)
    w = RNG.uniform(0.0, 1.0, size=(2, 50)) + np.array([[1e-3], [0.0]])
    out = blend_poses(np.stack([a, b]), w)
    np.testing.assert_allclose(np.linalg.norm(quats(out), axis=-1), 1.0, atol=1e-6)
    root = (w[0, :, None] * a[:, :3] + w[1, :, None] * b[:, :3]) / w.sum(0)[:, None]
    np.testing.assert_allclose(out[:, :3], root, atol=1e-5)


def test_q_and_minus_q_blend_to_the_same_rotation():
    p = random_poses(10)
    neg = p.copy()
    neg[:, 3:] *= -1
    out = blend_poses(np.stack([p, neg]), np.full((2, 10), 0.5))
    assert np.isfinite(out).all()
    np.testing.assert_allclose(np.abs(np.einsum("njc,njc->nj", quats(out), quats(p))), 1.0, atol=1e-6)


def test_midpoint_blend_equals_scipy_slerp():
    a, b = random_poses(5), random_poses(5)
    out = blend_poses(np.stack([a, b]), np.full((2, 5), 0.5))
    for n in range(5):
        for j in range(NUM_BONES):
            key = Rotation.from_quat([quats(a)[n, j], quats(b)[n, j]])
            mid = Slerp([0, 1], key)(0.5).as_quat()
            assert abs(np.dot(mid, quats(out)[n, j])) == pytest.approx(1.0, abs=1e-5)


def test_align_sequence_removes_sign_flips_and_continues_a_stream():
    q = quats(random_poses(1))[0]
    track = np.repeat(q[None], 30, axis=0) * RNG.choice([-1.0, 1.0], size=(30, NUM_BONES, 1))
    aligned = align_sequence(track)
    assert (np.einsum("tjc,tjc->tj", aligned[1:], aligned[:-1]) > 0).all()
    np.testing.assert_allclose(aligned[0], track[0])
    cont = align_sequence(track[10:], prev=aligned[9])
    np.testing.assert_allclose(cont, aligned[10:])


def test_sanitize_quaternions_replaces_bad_ones_with_identity():
    q = np.array([[0, 0, 0, 2.0], [np.nan, 0, 0, 1], [0, 0, 0, 0], [np.inf, 1, 1, 1]])
    out = sanitize_quaternions(q)
    np.testing.assert_allclose(out, [[0, 0, 0, 1]] * 4)


def test_blend_track_outputs_finite_unit_quaternions_even_from_nan_candidates():
    p = random_poses(8)
    p[3, 5:9] = np.nan
    out = blend_track(p[None], np.ones((1, 8)))
    assert np.isfinite(out).all()
    np.testing.assert_allclose(np.linalg.norm(quats(out), axis=-1), 1.0, atol=1e-6)


def smooth_motion(t: int) -> np.ndarray:
    """Every bone turning smoothly about its own axis (angle ~ sin), root still."""
    rng = np.random.default_rng(1)
    axes = rng.normal(size=(NUM_BONES, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    phase = rng.uniform(0, 2 * np.pi, NUM_BONES)
    ang = 0.6 * np.sin(2 * np.pi * 0.7 * np.arange(t)[:, None] / 30 + phase)
    q = Rotation.from_rotvec((ang[..., None] * axes).reshape(-1, 3)).as_quat().reshape(t, -1)
    return np.concatenate([np.zeros((t, 3)), q], axis=1).astype(np.float32)


def test_seam_ratio_sees_an_artificial_seam():
    t, window, hop = 640, 128, 64
    smooth = smooth_motion(t)
    assert 0.5 < seam_ratio(smooth, window, hop) < 1.5
    ratios = []
    for degrees in (1.0, 3.0, 6.0):  # every window boundary adds a step about x to every bone
        seamy = smooth.copy()
        q = Rotation.from_quat(seamy[:, 3:].reshape(-1, 4))
        steps = np.deg2rad(degrees) * (np.arange(t) // hop)
        kick = Rotation.from_rotvec(np.repeat(steps, NUM_BONES)[:, None] * np.array([[1.0, 0, 0]]))
        seamy[:, 3:] = (q * kick).as_quat().reshape(t, -1)
        ratios.append(seam_ratio(seamy, window, hop))
    assert ratios[1] > 2.0
    assert ratios[0] < ratios[1] < ratios[2]


def test_seam_ratio_needs_frames_on_both_sides():
    with pytest.raises(DataError):
        seam_ratio(smooth_motion(4), 128, 64)
    assert POSE_DIM == smooth_motion(3).shape[1]


def test_one_frame_blend_equals_the_many_frame_blend_frame_by_frame():
    """The engine's one-frame blend against the general one: sign flips, a zero weight,
    a continuing stream, NaN and cancelling candidates, a non-finite root."""
    rng = np.random.default_rng(3)
    k, n = 2, 40
    cand = np.stack([random_poses(n, rng), random_poses(n, rng)])
    cand[1, ::3, 3:] *= -1.0  # q and -q mixed in
    w = rng.uniform(0.0, 1.0, size=(k, n))
    w[0, 5] = 0.0  # the reference becomes the second candidate
    cand[:, 7, 3:7] = np.nan  # one bone NaN in both
    cand[1, 9, 3:] = -cand[0, 9, 3:]
    w[:, 9] = 0.5  # cancelling? no: sign-aligned first, so they agree
    cand[0, 11, 3:] = 0.0
    cand[1, 11, 3:] = 0.0  # zero quaternions -> identity
    cand[:, 13, 0] = np.inf  # root blows up -> 0
    want = blend_poses(cand, w)
    want[:, 3:] = align_sequence(quats(want)).reshape(n, -1)
    want[:, :3] = np.nan_to_num(want[:, :3], nan=0.0, posinf=0.0, neginf=0.0)
    np.testing.assert_array_equal(blend_track(cand, w), want)  # many frames: the general path
    prev = None
    for t in range(n):
        got = blend_frame(cand[:, t], w[:, t], prev)
        np.testing.assert_allclose(got, want[t], atol=2e-6, err_msg=f"frame {t}")
        np.testing.assert_array_equal(blend_track(cand[:, t : t + 1], w[:, t : t + 1], prev)[0], got)
        prev = got[3:].reshape(-1, 4)
    assert np.isfinite(want).all()
