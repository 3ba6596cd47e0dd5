"""The presence networks' 13th statistic, the log energy's 4-Hz modulation (models/networks/modulation.py, issue 43)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from models.networks import music_gate as mg
from models.networks.modulation import N_MOD_STATE, TAU_MOD, modulation_step


def reference(e: np.ndarray) -> np.ndarray:
    """The definition offline: scipy's 1st-order Butterworth band-pass at 3-6 Hz (30 fps) of ``e`` minus its first
    value, squared, the exponential mean over TAU_MOD frames, in dB."""
    from scipy.signal import butter, lfilter

    b, a = butter(1, (3.0, 6.0), btype="band", fs=30.0)
    k = np.exp(-1.0 / TAU_MOD)
    return 10 * np.log10(lfilter([1 - k], [1, -k], lfilter(b, a, e - e[0]) ** 2) + 1e-6)


def run(e: np.ndarray) -> np.ndarray:
    state = np.zeros(N_MOD_STATE)
    return np.array([modulation_step(float(v), state, 0) for v in e])


def test_the_modulation_is_the_band_passed_energys_mean_square_streamed_frame_by_frame() -> None:
    e = np.random.default_rng(0).normal(-30.0, 8.0, 600)
    np.testing.assert_allclose(run(e), reference(e), atol=1e-9)


def test_syllable_rate_steps_read_high_a_steady_or_slow_level_low() -> None:
    t = np.arange(300)
    syllables = np.where((t // 4) % 2 == 0, -20.0, -40.0)  # 20 dB steps at 3.75 Hz
    slow = -30.0 + 10.0 * np.sin(2 * np.pi * 0.5 * t / 30.0)  # a phrase's swell at 0.5 Hz
    assert run(syllables)[60:].min() > 15.0
    assert run(slow)[60:].max() < 0.0 and run(np.full(300, -20.0)).max() == pytest.approx(-60.0)


def modulation_network() -> np.ndarray:
    """Packed parameters of a network that hears music (logit +13) on a steady level and none (-6.6) under
    syllable-rate steps: it reads the modulation alone; without it (weight 0) its logit is +3, music."""
    w1 = np.zeros((mg.HIDDEN, mg.N_STATS))
    w1[0, mg.MOD_STAT] = -1.0
    mean, std = np.zeros(mg.N_STATS), np.ones(mg.N_STATS)
    mean[mg.MOD_STAT], std[mg.MOD_STAT] = 5.0, 5.0
    w2 = np.zeros(mg.HIDDEN)
    w2[0] = 10.0
    return mg.pack(mean, std, w1, np.zeros(mg.HIDDEN), w2, 3.0)


def test_the_detector_hears_a_voices_syllables_through_the_modulation_and_not_with_it_off() -> None:
    """An idle performer's detector reading only the modulation: a level stepping 20 dB at 3.75 Hz (a voice's
    syllables) is no music, a steady one music; with ``modulation_rule`` off the steps are music too."""
    d = 64
    row = np.random.default_rng(0).normal(size=d).astype(np.float32)

    def hears(levels: np.ndarray, rule: bool = True) -> list[bool]:
        g = mg.MusicGate(np.zeros(d), np.ones(d), modulation_network(), -60.0, clarity_col=60)
        g.modulation_rule = rule
        out = []
        for e in levels:
            row[mg.ENERGY_COL] = e
            out.append(g.step(row, False))
        return out[60:]

    t = np.arange(150)
    syllables = np.where((t // 4) % 2 == 0, -20.0, -40.0)
    assert not any(hears(syllables)) and all(hears(np.full(150, -20.0)))
    assert all(hears(syllables, rule=False))


def test_networks_fitted_before_the_modulation_read_the_first_12_statistics() -> None:
    """A checkpoint's 12-statistic networks (shorter parameters) unpack, judge by the first 12 as before,
    and load into a model whose fresh buffers have 13."""
    rng = np.random.default_rng(1)
    s = mg.N_STATS_BEFORE
    old = mg.pack(rng.normal(size=s), rng.uniform(1, 2, s), rng.normal(size=(mg.HIDDEN, s)), rng.normal(size=mg.HIDDEN),
                  rng.normal(size=mg.HIDDEN), 0.3)
    assert old.shape == (mg.n_params(s),) and mg.unpack(old)[2].shape == (mg.HIDDEN, s)
    mean, std, w1, b1, w2, b2 = mg.unpack(old)
    stats = rng.normal(size=mg.N_STATS)
    want = b2[0] + w2 @ np.tanh(w1 @ ((stats[:s] - mean) / std) + b1)
    assert mg.presence_logit(stats, mean, std, w1, b1, w2, b2[0]) == pytest.approx(want)

    from models.networks.dance_vq import DanceVQ, DanceVQConfig

    model = DanceVQ(DanceVQConfig())
    state = model.state_dict()
    state["presence"] = torch.from_numpy(old)
    model.load_state_dict(state)
    assert model.presence.shape == (mg.n_params(s),) and model.presence_stop.shape == (mg.N_PARAMS,)
