"""Metrics on synthetic trajectories with known answers."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from scipy.spatial.transform import Rotation

from models.errors import DataError
from models.evaluation import metrics as M
from models.timebase import FPS


def oscillation(T: int = 240, J: int = 6, delay: float = 0.0, seed: int = 0) -> np.ndarray:
    """Smooth multi-joint motion (T, J, 3) m; ``delay`` frames shifts it later in time."""
    rng = np.random.default_rng(seed)
    freq = rng.uniform(0.5, 1.5, (J, 3))
    phase = rng.uniform(0, 2 * np.pi, (J, 3))
    amp = rng.uniform(0.05, 0.3, (J, 3))
    rest = rng.uniform(-0.5, 0.5, (J, 3)) + [0.0, 1.0, 0.0]
    t = (np.arange(T) - delay)[:, None, None] / FPS
    return rest + amp * np.sin(2 * np.pi * freq * t + phase)


@pytest.fixture(scope="module")
def pos() -> np.ndarray:
    return oscillation()


def test_identical_sequences_score_perfectly(pos):
    assert M.position_l1(pos, pos) == 0.0
    assert M.dtw_distance(pos, pos) == pytest.approx(0.0, abs=1e-12)
    assert M.lcss_similarity(pos, pos) == 1.0
    assert M.pck(pos, pos, 0.1) == 1.0 and M.pck(pos, pos, 0.2) == 1.0
    assert M.direction_change_f1(pos, pos, hands=[0, 1])["f1"] == 1.0
    assert M.energy_ratio(pos, pos) == pytest.approx(1.0)
    assert M.cosine_similarity(pos, pos) == pytest.approx(1.0)


def test_rotation_l1_ignores_quaternion_sign():
    q = Rotation.random(60 * 4, random_state=1).as_quat().reshape(60, 4, 4)
    assert M.rotation_l1(q, q) == 0.0
    assert M.rotation_l1(-q, q) == 0.0
    other = Rotation.random(60 * 4, random_state=2).as_quat().reshape(60, 4, 4)
    assert M.rotation_l1(other, q) > 0.1


def test_hand_l1_only_sees_the_hands(pos):
    gen = pos.copy()
    gen[:, 3] += [0.0, 0.02, 0.0]  # 2 cm on y only -> mean abs over x, y, z = 2/3 cm
    assert M.hand_l1(gen, pos, hands=[3]) == pytest.approx(0.02 / 3)
    assert M.hand_l1(gen, pos, hands=[0, 1]) == 0.0
    assert M.position_l1(gen, pos) == pytest.approx(0.02 / 3 / pos.shape[1])


def test_dtw_equals_a_constant_offset_across_the_motion():
    # Joints move along y only; an x offset d makes every frame pair at least d apart,
    # and exactly d on the diagonal, so the path-normalised DTW is exactly d.
    T = 90
    ref = np.zeros((T, 4, 3))
    ref[:, :, 1] = np.sin(np.linspace(0, 6, T))[:, None]
    assert M.dtw_distance(ref + [0.05, 0.0, 0.0], ref) == pytest.approx(0.05)


def test_dtw_forgives_timing_that_frame_wise_error_punishes(pos):
    late = oscillation(delay=4)
    assert M.dtw_distance(late, pos) < 0.25 * M.position_l1(late, pos)
    # different lengths are allowed
    assert M.dtw_distance(pos[:200], pos) >= 0.0


def _lcs_reference(match: np.ndarray) -> int:
    n, m = match.shape
    L = np.zeros((n + 1, m + 1), dtype=int)
    for i in range(1, n + 1):
        for j in range(1, m + 1):
            L[i, j] = L[i - 1, j - 1] + 1 if match[i - 1, j - 1] else max(L[i - 1, j], L[i, j - 1])
    return int(L[n, m])


def test_lcss_matches_the_textbook_recurrence():
    rng = np.random.default_rng(3)
    a = rng.normal(0, 0.1, (40, 3, 3))
    b = rng.normal(0, 0.1, (33, 3, 3))
    eps = 0.15
    match = M._frame_distances(a, b) <= eps
    assert 0 < match.mean() < 1
    assert M.lcss_similarity(a, b, epsilon=eps) == pytest.approx(_lcs_reference(match) / 33)


def test_lcss_epsilon_and_window(pos):
    far = pos + [1.0, 0.0, 0.0]
    assert M.lcss_similarity(far, pos, epsilon=0.1) == 0.0
    assert M.lcss_similarity(far, pos, epsilon=1.01) == 1.0
    half = pos.copy()
    half[::2] += [1.0, 0.0, 0.0]  # every other frame far away
    assert M.lcss_similarity(half, pos, epsilon=0.1, delta=0) == pytest.approx(0.5)


def test_pck_uses_the_reference_bounding_box():
    T, J = 10, 4
    ref = np.zeros((T, J, 3))
    ref[:, :, 1] = np.linspace(0.0, 1.0, J)  # bounding box: 1 m tall -> L = 1 m
    gen = ref.copy()
    gen[:, :2, 0] += 0.15  # half the joints 15 cm off
    assert M.pck(gen, ref, 0.1) == pytest.approx(0.5)
    assert M.pck(gen, ref, 0.2) == pytest.approx(1.0)
    # torso reference: joints 0 and 1 are 1/3 m apart -> radius 0.2 * 1/3 < 0.15
    assert M.pck(gen, ref, 0.2, torso=(0, 1)) == pytest.approx(0.5)


def test_direction_changes_land_on_the_extrema():
    t = np.arange(120)
    x = 0.2 * np.cos(2 * np.pi * t / 30)  # extrema every 15 frames
    np.testing.assert_array_equal(M.direction_changes(x), [15, 30, 45, 60, 75, 90, 105])


def test_dead_band_ignores_jitter():
    rng = np.random.default_rng(0)
    jitter = rng.uniform(-0.0004, 0.0004, 300)  # |v| <= 0.8 mm/frame = 0.024 m/s
    assert M.direction_changes(jitter).size == 0
    assert M.direction_changes(jitter, deadband=0.0).size > 50


def test_direction_f1_tolerance_two_frame_delay(pos):
    ref = pos.copy()
    ref[:10], ref[-10:] = ref[10], ref[-11]  # still at both ends, so a delay loses no event
    late = np.concatenate([ref[:2], ref[:-2]])  # late[t] = ref[t - 2]
    hands = [0, 1]
    assert M.direction_change_f1(late, ref, hands, tolerance=3)["f1"] == 1.0
    assert M.direction_change_f1(late, ref, hands, tolerance=2)["f1"] == 1.0
    assert M.direction_change_f1(late, ref, hands, tolerance=1)["f1"] < 0.5


def test_event_matching_is_one_to_one_and_maximal():
    assert M.event_f1(np.array([10, 11]), np.array([10]), 3) == (0.5, 1.0, pytest.approx(2 / 3))
    # greedy nearest-first would pair 5 with 7 and strand 8; the maximum matching pairs 5-2 and 8-7
    assert M.match_events(np.array([5, 8]), np.array([2, 7]), 3) == 2
    assert M.event_f1(np.array([], dtype=int), np.array([], dtype=int), 3) == (1.0, 1.0, 1.0)
    assert M.event_f1(np.array([4]), np.array([], dtype=int), 3)[2] == 0.0


def test_cosine_of_centred_trajectories(pos):
    assert M.cosine_similarity(pos + [0.3, -0.2, 1.0], pos) == pytest.approx(1.0)
    mirrored = 2 * pos.mean(axis=0) - pos  # same centre, every displacement reversed
    assert M.cosine_similarity(mirrored, pos) == pytest.approx(-1.0)
    frozen = np.repeat(pos[:1], len(pos), axis=0)
    assert M.cosine_similarity(frozen, pos) == 0.0
    assert M.cosine_similarity(frozen, frozen) == 1.0


def test_energy_ratio(pos):
    frozen = np.repeat(pos[:1], len(pos), axis=0)
    assert M.energy_ratio(frozen, pos) == 0.0
    doubled = 2 * (pos - pos.mean(axis=0))
    assert M.energy_ratio(doubled, pos) == pytest.approx(2.0)
    assert M.energy_ratio([pos[:100], pos[100:]], [pos[:120], pos[120:]]) == pytest.approx(1.0, abs=0.05)
    with pytest.raises(DataError, match="frozen"):
        M.energy_ratio(pos, frozen)


def test_jerk_of_a_cubic_is_six_c():
    t = np.arange(60) / FPS
    pos = np.zeros((60, 2, 3))
    pos[:, :, 0] = 0.5 * t[:, None] ** 3  # d3x/dt3 = 3 m/s^3 exactly
    assert M.jerk(pos) == pytest.approx(3.0, rel=1e-6)
    assert M.jerk(np.zeros((10, 2, 3))) == 0.0
    assert M.jerk([pos, pos]) == pytest.approx(3.0, rel=1e-6)


def test_frechet_distance_closed_form():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(500, 8))
    assert M.frechet_distance(a, a) == pytest.approx(0.0, abs=1e-8)
    shift = np.array([1.0, -2.0, 0, 0, 0.5, 0, 0, 0])
    # same covariance, means differ by `shift`: FD = |shift|^2
    assert M.frechet_distance(a + shift, a) == pytest.approx(np.sum(shift**2), rel=1e-6)
    assert M.frechet_distance(a + 2 * shift, a) == pytest.approx(4 * np.sum(shift**2), rel=1e-6)


def test_frechet_distance_agrees_with_sqrtm_and_survives_singular_covariances():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(400, 5))
    b = rng.normal(size=(300, 5)) @ rng.normal(size=(5, 5)) + 0.3
    ca, cb = np.cov(a, rowvar=False), np.cov(b, rowvar=False)
    ref = np.sum((a.mean(0) - b.mean(0)) ** 2) + np.trace(ca + cb - 2 * scipy.linalg.sqrtm(ca @ cb).real)
    assert M.frechet_distance(a, b) == pytest.approx(ref, rel=1e-6)
    few = rng.normal(size=(4, 32))  # N < F: rank-deficient covariance
    fd = M.frechet_distance(few, rng.normal(size=(6, 32)))
    assert np.isfinite(fd) and fd > 0


def test_diversity_mean_pairwise_distance():
    assert M.diversity(np.array([[0.0, 0.0], [3.0, 4.0]])) == 5.0
    assert M.diversity(np.array([[0.0], [1.0], [3.0]])) == pytest.approx((1 + 3 + 2) / 3)


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda p: M.position_l1(p[:, :, :2], p[:, :, :2]), "pos_gen"),
        (lambda p: M.pck(p, p[:-1], 0.1), "pos_gen"),
        (lambda p: M.dtw_distance(p, p[:, :2]), "pos_a"),
        (lambda p: M.direction_change_f1(p, p, hands=[99]), "hands"),
        (lambda p: M.rotation_l1(p, p), "quat_gen"),
        (lambda p: M.frechet_distance(p[0], p[0, :, :2]), "feats_a"),
    ],
)
def test_bad_input_names_the_argument(pos, call, name):
    with pytest.raises(DataError, match=name):
        call(pos)


def test_nan_is_rejected(pos):
    bad = pos.copy()
    bad[3, 2, 1] = np.nan
    with pytest.raises(DataError, match="NaN"):
        M.position_l1(bad, pos)


def test_sequence_metrics_keys_are_reported_metrics(pos):
    from models.evaluation.report import METRICS

    q = Rotation.random(len(pos) * 3, random_state=0).as_quat().reshape(len(pos), 3, 4)
    same = M.sequence_metrics(pos, pos, hands=[0, 1], quat_gen=q, quat_ref=q)
    assert set(same) <= set(METRICS) and "rot_l1" in same
    assert same["pos_l1"] == same["hand_l1"] == same["rot_l1"] == 0.0
    assert same["lcss"] == same["pck@0.1"] == same["dir_f1"] == 1.0
    assert same["jerk"] == pytest.approx(M.jerk(pos))
    worse = M.sequence_metrics(oscillation(delay=6), pos, hands=[0, 1])
    assert worse["pos_l1"] > 0 and worse["pck@0.1"] < 1 and worse["cosine"] < 1 and "rot_l1" not in worse


# -- band amplitude and jitter (issue 18) ----------------------------------------------------


def sine(T: int, freq: float, amp: float, J: int = 5, axis: int = 1, phase: float = 0.0) -> np.ndarray:
    """(T, J, 3) m: every joint at a rest position plus ``amp * sin(2 pi freq t)`` on ``axis``."""
    rest = np.linspace(-0.5, 0.5, J * 3).reshape(1, J, 3) + [0.0, 1.0, 0.0]
    x = np.zeros((T, J, 3))
    x[:, :, axis] = amp * np.sin(2 * np.pi * freq * np.arange(T)[:, None] / FPS + phase)
    return rest + x


def test_band_rms_of_a_sinusoid_is_its_rms_over_values():
    # 1 Hz on y of every joint, 10 s (a whole number of periods): A / sqrt(2) on y, 0 on x and z
    assert M.band_rms(sine(300, 1.0, 0.2), M.DANCE_BAND) == pytest.approx(0.2 / np.sqrt(6))
    assert M.band_rms(sine(300, 1.0, 0.2), M.JITTER_BAND) == pytest.approx(0.0, abs=1e-12)
    assert M.band_rms(sine(300, 10.0, 0.01), M.JITTER_BAND) == pytest.approx(0.01 / np.sqrt(6))
    assert M.band_rms(sine(300, 10.0, 0.01), M.DANCE_BAND) == pytest.approx(0.0, abs=1e-12)
    # the Nyquist bin (15 Hz, even T) counts once: cos(pi t) has RMS A on its axis
    nyq = sine(300, 15.0, 0.01, phase=np.pi / 2)
    assert M.band_rms(nyq, M.JITTER_BAND) == pytest.approx(0.01 / np.sqrt(3))


def dance(T: int, freq: float, amp: float, tremble: float = 0.002) -> np.ndarray:
    """:func:`sine` plus a small 8 Hz motion (real dances have a little high-frequency motion too)."""
    return sine(T, freq, amp) + sine(T, 8.0, tremble) - sine(T, 8.0, 0.0)


def test_band_ratios_read_amplitude_and_jitter():
    real = dance(600, 1.0, 0.2)
    same = M.band_ratios(real, real)
    assert same["band_amp"] == pytest.approx(1.0) and same["jitter"] == pytest.approx(1.0)
    half = M.band_ratios(dance(600, 1.0, 0.1), real)
    assert half["band_amp"] == pytest.approx(0.5) and half["jitter"] == pytest.approx(1.0)
    assert half["band_amp_gen_m"] == pytest.approx(0.1 / np.sqrt(6))
    assert half["band_amp_real_m"] == pytest.approx(0.2 / np.sqrt(6))
    assert half["jitter_real_m"] == pytest.approx(0.002 / np.sqrt(6))
    # a 10 Hz tremble only in the generated motion: jitter ratio large, band amplitude unchanged
    shaky = real + sine(600, 10.0, 0.02) - sine(600, 10.0, 0.0)
    r = M.band_ratios(shaky, real)
    assert r["band_amp"] == pytest.approx(1.0)
    assert r["jitter"] == pytest.approx(np.hypot(0.002, 0.02) / 0.002)  # powers add: sqrt(1 + 10²) ≈ 10.05


def test_band_rms_removes_each_dances_mean_and_horizontal_travel():
    a, b = sine(300, 1.0, 0.2), sine(300, 1.0, 0.2)
    b_far = b + [3.0, 0.5, -2.0]  # another dance, elsewhere on the stage and higher up
    both = M.band_rms([a, b], M.DANCE_BAND)
    assert M.band_rms([a, b_far], M.DANCE_BAND) == pytest.approx(both)
    assert M.band_rms([a, b_far], (0.0, 15.0)) == pytest.approx(both)  # the mean is not motion, even at 0 Hz
    # concatenated, the jump between the two dances would leak into every band
    assert M.band_rms(np.concatenate([a, b_far]), M.DANCE_BAND) > 1.1 * both
    # travel of the root (joint 0) over the floor is removed from every joint: in place
    walk = a.copy()
    walk[:, :, 0] += 0.05 * np.sin(2 * np.pi * 0.5 * np.arange(300) / FPS)[:, None]
    assert M.band_rms(walk, M.DANCE_BAND) == pytest.approx(M.band_rms(a, M.DANCE_BAND))
    assert M.band_rms(walk, M.DANCE_BAND, root=None) > M.band_rms(a, M.DANCE_BAND)
    bounce = a.copy()  # the root's height is kept
    bounce[:, :, 1] += 0.05 * np.sin(2 * np.pi * 0.5 * np.arange(300) / FPS)[:, None]
    assert M.band_rms(bounce, M.DANCE_BAND) == pytest.approx(M.band_rms(walk, M.DANCE_BAND, root=None))


def test_band_power_is_pooled_over_dances_of_different_lengths():
    # 10 s at 0.2 m and 30 s at 0.1 m: pooled mean square = (300 * 0.2² + 900 * 0.1²) / 1200 / 6
    short, long = sine(300, 1.0, 0.2), sine(900, 2.0, 0.1)
    expect = np.sqrt((300 * 0.2**2 + 900 * 0.1**2) / 1200 / 6)
    assert M.band_rms([short, long], M.DANCE_BAND) == pytest.approx(expect)
    # a ratio pools power too: not the mean of the per-dance ratios (0.5 and 1)
    r = M.band_ratios([dance(300, 1.0, 0.1), dance(900, 2.0, 0.1)], [dance(300, 1.0, 0.2), dance(900, 2.0, 0.1)])
    assert r["band_amp"] == pytest.approx(np.sqrt((300 * 0.1**2 + 900 * 0.1**2) / (300 * 0.2**2 + 900 * 0.1**2)))


def test_band_ratio_errors_name_the_argument():
    with pytest.raises(DataError, match="pos_real"):
        M.band_ratios(sine(300, 1.0, 0.1), sine(300, 1.0, 0.0))  # a frozen reference
    with pytest.raises(DataError, match="band"):
        M.band_rms(sine(300, 1.0, 0.1), (3.0, 1.0))
    with pytest.raises(DataError, match=r"pos\[1\]"):
        M.band_rms([sine(300, 1.0, 0.1), np.full((300, 5, 3), np.nan)], M.DANCE_BAND)
