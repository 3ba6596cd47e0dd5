"""The handover waits for the playing exemplar's recorded frames (models/networks/handover.py)."""

from __future__ import annotations

import numpy as np
import pytest

import models.networks.dance_stream as ds
import models.networks.handover as handover
from models.features.audio_io import load_audio
from models.features.spectral import extract_features
from models.generate import load_model
from models.timebase import FPS


class _HeldTempo:
    """A tempo follower held at one tempo (bpm), fully confident: what a steady song gives."""

    def __init__(self, bpm: float) -> None:
        self.period, self.confidence = 60.0 * FPS / bpm, 1.0

    def update(self, *args) -> None:
        pass


@pytest.fixture(scope="module")
def clip():
    lm = load_model(None)
    return lm, extract_features(load_audio("models/assets/clip.ogg")[0], lm.features)


def _handovers(lm, feats: np.ndarray, bpm: float) -> tuple[list[float], list[float], int]:
    """(rows each handed-over exemplar had played, the rate it ended at, code steps) of a stream
    over ``feats`` at a held tempo of ``bpm``."""
    s = ds.DanceStream(lm.model, seed=0)
    s._tempo = _HeldTempo(bpm)
    rows, rates = [], []
    for t in range(len(feats)):
        n, rate = s._handover.handovers, s._player.rate
        s.push(feats[t: t + 1])
        if s._handover.handovers != n and n > 0:
            rows.append(s._handover.rows)
            rates.append(rate)
    return rows, rates, len(s.codes_drawn)


@pytest.mark.parametrize("on", [True, False])
def test_a_slow_movement_plays_its_recorded_frames_before_the_next(clip, on, monkeypatch):
    """At a slow tempo (70 bpm held: the tempo's rate 0.78 of the memory's pace, the speed
    matching's lower, 0.6-0.8), with ON_FRAMES, every exemplar plays at least 7.5 of its
    recorded frames, 8 to the nearest frame where it ends slower than 0.95, before the next one
    is handed over (over 10-13 output frames: the code steps that come sooner hold, 36 of the
    clip's 120; least 7.54 frames, median 7.8). Switched off (shipped) a movement is handed over
    every 8 output frames: 8 r of its frames, median 4.4."""
    monkeypatch.setattr(handover, "ON_FRAMES", on)
    lm, feats = clip
    rows, rates, steps = _handovers(lm, feats, 70.0)
    slow = np.array(rows)[np.array(rates) < 0.95]
    assert len(slow) > 50
    if on:  # never fewer than 7.5 (a movement sped up past 1 within its step may play a frame more)
        assert min(rows) >= 7.5 and 7.5 <= np.median(slow) <= 8.5, (min(rows), np.median(slow))
        assert 0.1 * steps < steps - len(rows) - 1 < 0.4 * steps, (steps, len(rows))
    else:
        assert np.median(slow) < 7.0 and len(rows) + 1 == steps
