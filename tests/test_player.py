"""The dance stream's player (models/networks/player.py): its reset replays a fresh player, and the
beat warp slows its read-out into every beat and catches up between them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from models.generate import load_model
from models.networks import player as player_part
from models.networks.dance_stream import DanceStream
from models.timebase import FPS


class _HeldTempo:
    """A tempo follower held at one tempo (bpm), fully confident."""

    def __init__(self, bpm: float) -> None:
        self.period, self.confidence = 60.0 * FPS / bpm, 1.0


@pytest.fixture(scope="module")
def stream() -> DanceStream:
    return DanceStream(load_model(None).model, seed=0)


def beat_rows(stream: DanceStream, frames: int, period: float = 20.0) -> np.ndarray:
    """Feature rows (frames, D), zero but for the beat tracker's columns: a clear pulse of ``period``
    frames (90 bpm), its phase advancing 2 pi a period."""
    rows = np.zeros((frames, stream.feature_dim), np.float32)
    ccos, csin, clarity, logp = stream._beat_cols
    theta = 2.0 * np.pi * np.arange(frames) / period
    rows[:, ccos], rows[:, csin], rows[:, clarity] = np.cos(theta), np.sin(theta), 0.5
    rows[:, logp] = math.log2(period / 15.0)
    return rows


def play(player, stream: DanceStream, rows: np.ndarray, tempo, codes) -> tuple[np.ndarray, np.ndarray]:
    """(poses (T, P), rows read (T,)): ``player`` handed one exemplar of each of ``codes`` in turn at its
    tempo rate (the first from its own pose, each next one at once where the last has got to), every
    frame between read out under the beat warp, as the stream's code steps and frames drive it."""
    seg, poses, at = player.seg, [], []
    for k, code in enumerate(codes):
        reached = player.reached()
        window = stream._chooser.members[code, 0]
        player.play(window, player.rate_for(code, 0, tempo), np.inf, stream._contacts[code, 0], reached - seg,
                    first=k == 0)
        player.handover.handed(seg, reached)
        player.has_cont = True
        for j in range(seg):
            poses.append(player.warped(j, rows[k * seg + j], tempo))
            at.append(player.at)
    return np.array(poses), np.array(at)


def test_a_reset_player_plays_what_a_fresh_one_plays(stream):
    codes = [int(c) for c in np.flatnonzero(stream._counts > 0)[:12]]
    rows, tempo = beat_rows(stream, 8 * len(codes)), _HeldTempo(130.0)
    fresh = play(DanceStream(stream.model, seed=0)._player, stream, rows, tempo, codes)
    used = DanceStream(stream.model, seed=0)._player
    play(used, stream, rows, tempo, codes[::-1])
    carried = play(used, stream, rows, tempo, codes)
    assert not np.array_equal(carried[0], fresh[0])  # its rows, rate and lag carried on: other poses
    used.reset()
    again = play(used, stream, rows, tempo, codes)
    np.testing.assert_array_equal(again[0], fresh[0])
    np.testing.assert_array_equal(again[1], fresh[1])


def test_the_beat_warp_slows_the_read_out_into_every_beat(stream):
    """BEAT_WARP: at a clear pulse the rows read a frame fall below the movement's rate where the
    danced phase is near a beat (cos theta > 0.5) and rise above it half a beat off (measured: 0.63
    and 1.37 rows a frame, the median 1.07). With BEAT_WARP 0 every frame reads 1.00 row (checked once)."""
    p = DanceStream(stream.model, seed=0)._player
    codes = [int(c) for c in np.flatnonzero(stream._counts > 0)[:30]]
    rows, tempo = beat_rows(stream, 8 * len(codes)), _HeldTempo(90.0)  # at the memory's tempo: rate about 1
    _, at = play(p, stream, rows, tempo, codes)
    theta = np.array([player_part.danced_phase(*(float(r[c]) for c in (stream._beat_cols[0], stream._beat_cols[1],
                                                                         stream._beat_cols[3])), tempo.period)[0]
                      for r in rows])
    inside = np.arange(len(at)) % 8 != 0  # steps within a movement (a handover moves the rows)
    step = np.diff(at, prepend=np.nan)[inside]
    near, off = np.cos(theta[inside]) > 0.5, np.cos(theta[inside]) < -0.5
    rate = float(np.median(step))
    assert step[near].mean() < 0.85 * rate and step[off].mean() > 1.15 * rate, (step[near].mean(), step[off].mean(), rate)
