"""benchmarks/studies/beat_control.py: the beat hit rate's control (beats shifted by half a beat)."""

from __future__ import annotations


import numpy as np
import pytest

from models.evaluation.evaluate import pooled_beats

from script_loader import load_script

beat_control = load_script("benchmarks/studies/beat_control.py")


def test_half_beats_are_the_midpoints_of_consecutive_beats() -> None:
    assert beat_control.half_beats(np.array([10, 20, 31, 45])).tolist() == [15, 26, 38]
    with pytest.raises(ValueError, match="at least 2 beats"):
        beat_control.half_beats(np.array([10]))


def _motion(beats: np.ndarray, frames: int) -> np.ndarray:
    """(frames, 2, 3) m: two points moving along x whose speed dips to near zero on every beat."""
    t = np.arange(frames, dtype=np.float64)
    dist = np.min(np.abs(t[:, None] - beats[None, :]), axis=1)
    speed = 0.05 + np.minimum(dist, 5.0)  # m/s, lowest on the beats
    x = np.cumsum(speed) / 30.0
    pos = np.zeros((frames, 2, 3))
    pos[:, 0, 0] = x
    pos[:, 1, 0] = x
    pos[:, 1, 1] = 1.0
    return pos


def test_a_motion_locked_to_the_beat_hits_the_beats_and_misses_the_control() -> None:
    """The control separates a beat-locked motion from its own score: on the beats its speed
    dips all hit, against the half-beat-shifted beats none does."""
    beats = np.arange(10, 590, 15)
    pos = _motion(beats, 600)
    on = pooled_beats([pos], [beats])["beat_hit_rate"]
    off = pooled_beats([pos], [beat_control.half_beats(beats)])["beat_hit_rate"]
    assert on > 0.9 and off < 0.1, (on, off)


def test_dip_offsets_are_signed_frames_from_the_nearest_beat() -> None:
    """Speed dips 2 frames after every beat read +2; before it, negative."""
    beats = np.arange(10, 300, 15)
    late = beat_control.dip_offsets([_motion(beats + 2, 300)], [beats])
    assert len(late) >= 15 and np.median(late) == 2
    early = beat_control.dip_offsets([_motion(beats - 1, 300)], [beats])
    assert np.median(early) == -1
    assert beat_control.dip_offsets([_motion(beats, 300)], [np.array([5])]).size == 0  # fewer than 2 beats
