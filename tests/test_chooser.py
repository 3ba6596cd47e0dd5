"""The dance stream's chooser (models/networks/chooser.py): its reset replays a fresh chooser, and
the energy control tilts which movements it draws."""

from __future__ import annotations

import numpy as np
import pytest

from models.features.audio_io import load_audio
from models.features.spectral import extract_features
from models.generate import load_model
from models.networks.dance_stream import DanceStream
from models.timebase import FPS


class _HeldTempo:
    """A tempo follower held at one tempo (bpm), fully confident."""

    def __init__(self, bpm: float) -> None:
        self.period, self.confidence = 60.0 * FPS / bpm, 1.0


@pytest.fixture(scope="module")
def clip():
    lm = load_model(None)
    return lm, extract_features(load_audio("models/assets/clip.ogg")[0], lm.features)


def drive(chooser, feats: np.ndarray, tempo) -> list[int]:
    """The codes ``chooser`` draws over feature rows ``feats`` (T, D), as the stream drives it: every
    frame heard, a draw on each code step (the first drawn code played), its pieces ahead between."""
    codes: list[int] = []
    for t, row in enumerate(feats):
        j = t % chooser.seg
        chooser.hear(row, j)
        if j == 0:
            draws, _ = chooser.draw(tempo, codes, 0.0)
            codes.append(draws[0])
            chooser.commit(draws[0])
        else:
            chooser.think(j)
    return codes


def test_a_reset_chooser_draws_what_a_fresh_one_draws(clip):
    lm, feats = clip
    song, other = feats[:480], feats[600:1080]
    tempo = _HeldTempo(120.0)
    fresh = drive(DanceStream(lm.model, seed=5)._chooser, song, tempo)
    used = DanceStream(lm.model, seed=5)._chooser
    first = drive(used, other, tempo)
    assert drive(used, song, tempo) != fresh  # its context and generator carried on: other codes
    used.reset()
    assert drive(used, song, tempo) == fresh
    used.reset()
    assert drive(used, other, tempo) == first


def test_the_energy_control_draws_calmer_or_livelier_codes(clip):
    """set_energy tilts the logits by ENERGY_GAIN * (energy - 1) * z (z each code's liveliness): on the
    clip's first 24 s, the same seed and context, energy 0 draws codes 4.2 z calmer than energy 2
    (-2.55 against +1.61). With ENERGY_GAIN 0 the draws are the same at both (checked once)."""
    lm, feats = clip
    song, tempo = feats[:720], _HeldTempo(120.0)
    drawn = {}
    for e in (0.0, 2.0):
        chooser = DanceStream(lm.model, seed=2)._chooser
        chooser.set_energy(e)
        codes = drive(chooser, song, tempo)
        drawn[e] = float(chooser.code_energy[codes].mean())
    assert drawn[2.0] - drawn[0.0] > 1.0, drawn


def test_a_style_changed_after_the_window_filled_plays_on(clip):
    """The show desk changes the style mid-song: once the token window is full (128 frames), the
    new style's window is rebuilt from its last ``window - 1`` tokens, as every step's is (it was
    built from all of them, one too many: the next push raised IndexError). The new style takes
    effect: the codes drawn after it differ from the same stream's without the change."""
    lm, feats = clip
    n = min(len(feats), 420)
    assert n >= 380, "the bundled clip is shorter than the test needs"
    changed, kept = DanceStream(lm.model, seed=0), DanceStream(lm.model, seed=0)
    for s in (changed, kept):
        s.push(feats[:300])
    assert len(changed._chooser._tokens) == changed._chooser._tokens.maxlen  # the window is full
    changed.set_style("waltz")  # guided: both the style's and auto's windows rebuilt
    poses = changed.push(feats[300:340])
    changed.set_style(None)  # back to auto: the auto window rebuilt
    poses = np.concatenate([poses, changed.push(feats[340:n])])
    assert np.isfinite(poses).all()
    kept.push(feats[300:n])
    assert changed.codes_drawn[:38] == kept.codes_drawn[:38]  # the same until the change
    assert changed.codes_drawn[38:] != kept.codes_drawn[38:]
