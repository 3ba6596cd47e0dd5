"""Stability check of long pose streams (models/evaluation/stability.py) on synthetic streams."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from models.errors import DataError
from models.evaluation import stability as S
from models.evaluation.evaluate import positions
from models.evaluation.metrics import DANCE_BAND, band_rms
from models.rig.humanoid import BONE_INDEX, NUM_BONES
from models.rig.motion import POSE_DIM
from models.timebase import FPS

STRETCH = int(S.STRETCH_S * FPS)  # 900 frames


def dancing(seconds: float = 120.0, swing_rad: float = 0.6) -> np.ndarray:
    """(T, POSE_DIM): arms swinging about z at 1 Hz and 0.7 Hz, hips bouncing 3 cm at 2 Hz, standing at (0, 1, 0)."""
    t = np.arange(int(seconds * FPS)) / FPS
    poses = np.zeros((len(t), POSE_DIM))
    poses[:, 1] = 1.0 + 0.03 * np.sin(2 * np.pi * 2.0 * t)
    q = np.tile([0.0, 0.0, 0.0, 1.0], (len(t), NUM_BONES, 1))
    for bone, freq in (("LeftUpperArm", 1.0), ("RightUpperArm", 0.7)):
        q[:, BONE_INDEX[bone]] = Rotation.from_rotvec(np.outer(swing_rad * np.sin(2 * np.pi * freq * t), [0, 0, 1])).as_quat()
    poses[:, 3:] = q.reshape(len(t), -1)
    return poses


@pytest.fixture(scope="module")
def stream() -> np.ndarray:
    return dancing()


@pytest.fixture(scope="module")
def ref_m(stream) -> float:
    """The whole stream's band RMS: every 30-s stretch of it moves at about this amplitude."""
    return band_rms(positions(stream), DANCE_BAND)


def test_a_steady_dance_passes_every_stretch(stream, ref_m):
    r = S.stability_check(stream, ref_m)
    assert r.ok and r.failures == []
    assert [s["index"] for s in r.stretches] == [0, 1, 2, 3] and r.tail_frames == 0
    assert [(s["start_s"], s["end_s"]) for s in r.stretches][-1] == (90.0, 120.0)
    for s in r.stretches:
        assert s["amp_ratio"] == pytest.approx(1.0, abs=0.02) and s["reasons"] == []
        assert s["root_horizontal_m"] == pytest.approx(0.0, abs=1e-9)
        assert s["root_vertical_m"] == pytest.approx(0.03, abs=1e-3)  # the hip bounce, 3 cm
        assert s["still_s"] < 0.1 and 0.5 < s["max_speed"] < 5.0
    assert "4 stretches of 30 s all pass" in r.summary()
    # judged against a reference twice as large, the same dance is too small; half as large, too big
    assert all("amplitude 0.50x" in f or "amplitude 0.49x" in f for f in S.stability_check(stream, 2.01 * ref_m).failures)
    assert len(S.stability_check(stream, ref_m / 1.6).failures) == 4


def test_a_dance_that_freezes_half_way_fails_naming_the_stretches(stream, ref_m):
    frozen = stream.copy()
    frozen[2 * STRETCH :] = frozen[2 * STRETCH]  # stands still from 60 s on
    r = S.stability_check(frozen, ref_m)
    assert not r.ok
    assert [s["index"] for s in r.stretches if s["reasons"]] == [2, 3]
    assert r.failures[0].startswith("stretch 2 (60-90 s): frozen")
    assert r.stretches[2]["still_s"] == pytest.approx(29.97, abs=0.05) and r.stretches[2]["amp_m"] < 1e-9
    assert "2 of 4 stretches of 30 s fail: stretch 2 (60-90 s): frozen" in r.summary()
    # a 2-s freeze inside a lively stretch keeps most of the amplitude but is still a freeze
    pause = stream.copy()
    pause[STRETCH + 300 : STRETCH + 360] = pause[STRETCH + 300]
    r = S.stability_check(pause, ref_m)
    assert [s["index"] for s in r.stretches if s["reasons"]] == [1]
    assert r.stretches[1]["amp_ratio"] > 0.8 and r.stretches[1]["still_s"] == pytest.approx(2.0, abs=0.05)


@pytest.mark.parametrize("axis, what", [(0, "horizontally"), (2, "horizontally"), (1, "vertically")])
def test_a_drifting_root_fails_from_the_stretch_where_it_leaves_half_a_metre(stream, ref_m, axis, what):
    drift = stream.copy()
    drift[:, axis] += 0.01 * np.arange(len(drift)) / FPS  # 1 cm/s: 0.5 m at 50 s
    r = S.stability_check(drift, ref_m)
    failing = [s["index"] for s in r.stretches if s["reasons"]]
    assert failing == [1, 2, 3]
    reach = 0.6 + (0.03 if axis == 1 else 0.0)  # vertically the 3-cm hip bounce adds
    assert f"root {reach:.2f} m from its start {what}" in r.failures[0] and r.failures[0].startswith("stretch 1 (30-60 s)")
    # travel over the floor is not dance amplitude; a vertical drift (kept, as hip height is)
    # leaks a little into the band through the stretch's FFT
    assert r.stretches[0]["amp_ratio"] == pytest.approx(1.0, abs=0.02 if axis != 1 else 0.05)


def test_non_finite_or_exploding_motion_fails(stream, ref_m):
    bad = stream.copy()
    bad[3 * STRETCH + 450, 5] = np.nan
    r = S.stability_check(bad, ref_m)
    assert [s["index"] for s in r.stretches if s["reasons"]] == [3]
    assert r.stretches[3]["finite"] is False and "exploded: non-finite values from 105.00 s" in r.failures[0]
    fling = stream.copy()
    fling[STRETCH + 10, 3:] = Rotation.from_rotvec([0, 0, 3.0]).as_quat().tolist() * NUM_BONES  # every bone flips
    r = S.stability_check(fling, ref_m)
    assert [s["index"] for s in r.stretches if s["reasons"]] == [1]
    assert "exploded: a point moves at" in r.failures[0] and r.stretches[1]["max_speed"] > S.MAX_SPEED
    scaled = stream.copy()
    scaled[STRETCH, 3:7] *= 2.0
    assert "quaternion norm is off by 1" in S.stability_check(scaled, ref_m).failures[0]


def test_the_monitor_fed_in_pieces_equals_the_whole_check(stream, ref_m):
    whole = S.stability_check(stream[: 2 * STRETCH + 100], ref_m)
    mon = S.StabilityMonitor(ref_m)
    for a in range(0, 2 * STRETCH + 100, 7):
        mon.add(stream[a : min(a + 7, 2 * STRETCH + 100)])
    mon.add(np.empty((0, POSE_DIM)))
    assert mon.result().to_dict() == whole.to_dict()
    assert whole.tail_frames == 100 and len(whole.stretches) == 2
    single = S.StabilityMonitor(ref_m)
    for p in stream[:STRETCH]:
        single.add(p)
    assert single.result().stretches == whole.stretches[:1]


def test_too_short_and_bad_input():
    r = S.stability_check(dancing(10.0), 0.05)
    assert not r.ok and r.failures == ["no whole 30-s stretch to judge (300 frames)"]
    with pytest.raises(DataError, match="ref_m"):
        S.stability_check(dancing(10.0), 0.0)
    with pytest.raises(DataError, match="poses"):
        S.stability_check(np.zeros((100, 10)), 0.05)
    with pytest.raises(DataError, match="poses"):
        S.StabilityMonitor(0.05).add(np.zeros(7))


def test_on_a_stage_the_root_may_travel_inside_it_but_not_leave_it(stream, ref_m):
    """A performer on a stage travels: 1.2 m from its start inside a 3x2 stage passes (in place it
    would fail), 0.3 m past the stage's edge fails naming the stage."""
    s = stream.copy()
    t = np.arange(len(s)) / FPS
    s[:, 0] = 1.2 * np.sin(2 * np.pi * t / 20.0)  # across the stage and back, |x| <= 1.2 < 1.5
    assert S.stability_check(s, ref_m, stage=(3.0, 2.0)).ok
    assert not S.stability_check(s, ref_m).ok  # in place, 1.2 m is a drift
    s[:, 2] = 1.3  # 0.3 m in front of the 3x2 stage's front edge
    report = S.stability_check(s, ref_m, stage=(3.0, 2.0))
    assert not report.ok and "0.30 m outside the 3x2 m stage" in report.failures[0]
    assert report.to_dict()["stage"] == [3.0, 2.0]
