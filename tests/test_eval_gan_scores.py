"""GAN-train / GAN-test (models/evaluation/gan_scores.py) on synthetic styles with known answers."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from models.errors import DataError
from models.evaluation import classifier as C
from models.evaluation import gan_scores as S
from models.timebase import FPS

J = 5
FREQ = {"C": 0.7, "W": 1.6}  # two synthetic styles: slow and fast oscillation


def dance(style: str, seconds: float, seed: int) -> np.ndarray:
    shared = np.random.default_rng(99)
    rest, amp = shared.uniform(-0.4, 0.4, (J, 3)), shared.uniform(0.05, 0.25, (J, 3))
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * FPS)) / FPS
    pos = rest + amp * rng.uniform(0.8, 1.2, (J, 3)) * np.sin(
        2 * np.pi * FREQ[style] * t[:, None, None] + rng.uniform(0, 2 * np.pi, (J, 3)))
    return pos + rng.normal(0, 0.005, pos.shape)


@pytest.fixture(scope="module")
def setup():
    train_styles = ["C"] * 12 + ["W"] * 12
    train_pos = [dance(s, 12, i) for i, s in enumerate(train_styles)]
    x, y = S.labelled_windows(train_pos, train_styles, ["C", "W"])
    clf = C.train_style_classifier(x, y, epochs=5, seed=0, class_names=["C", "W"])
    val_styles = ["C", "W", "C", "W"]
    real = SimpleNamespace(positions=[dance(s, 20, 100 + i) for i, s in enumerate(val_styles)],
                           clips=[SimpleNamespace(style=s) for s in val_styles])
    return clf, train_styles, real


def test_a_faithful_generator_scores_like_real_data(setup):
    clf, train_styles, real = setup
    ref = S.real_reference(real, clf)
    assert ref["gan_train"] == ref["gan_test"] >= 0.9, ref
    gen_val = [dance(c.style, 20, 200 + i) for i, c in enumerate(real.clips)]  # new takes, right styles
    got = S.gan_scores(lambda: [dance(s, 12, 300 + i) for i, s in enumerate(train_styles)], train_styles,
                       gen_val, real, clf, epochs=5, seed=0)
    assert got["gan_test"] >= 0.9 and got["gan_train"] >= 0.9, got


def test_a_collapsed_generator_fails_both(setup):
    clf, train_styles, real = setup
    # one dance (the slow style) whatever the music: half the windows carry the wrong style
    gen_val = [dance("C", 20, 400 + i) for i in range(len(real.clips))]
    assert S.gan_test(clf, gen_val, [c.style for c in real.clips]) == pytest.approx(0.5, abs=0.1)
    with pytest.raises(DataError):  # generated motion of one style only: nothing to tell apart
        S.gan_train([dance("C", 8, 500 + i) for i in range(4)], ["C"] * 4, real.positions,
                    [c.style for c in real.clips], ["C", "W"], epochs=1)
    # every song gets the slow dance but labelled by its music: GAN-train cannot learn the styles
    acc = S.gan_train([dance("C", 12, 600 + i) for i in range(len(train_styles))], train_styles, real.positions,
                      [c.style for c in real.clips], ["C", "W"], epochs=5)
    assert acc <= 0.75


def test_unknown_style_and_short_motion_are_refused(setup):
    clf, _, _ = setup
    with pytest.raises(DataError, match="style 'R'"):
        S.gan_test(clf, [dance("C", 5, 0)], ["R"])
    with pytest.raises(DataError, match="too short"):
        S.gan_test(clf, [dance("C", 1, 0)], ["C"])
