"""The spectral steadiness column (models/features/steadiness.py) and where it goes.

It is the presence detector's cue that a voice is talking (docs/listening.md, "Knowing when
music plays"): held notes keep their harmonics in place over 67 ms, a gliding voice and
noise do not. These tests check the column's values on signals whose answer is known, that
streaming equals the offline pass, that only the idle gate reads it, and that a config
without it keeps its fingerprint (older checkpoints and caches stay valid).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from models.errors import ConfigError
from models.features.spectral import FeatureConfig, extract_features
from models.features.steadiness import SteadinessTracker, steadiness
from models.features.streaming import StreamingFeatureExtractor
from models.timebase import SAMPLE_RATE

SR = SAMPLE_RATE
CFG = FeatureConfig(kind="mfcc_onset", n_mels=128, context_s=3.0, beat_phase=True)


def _harmonic(f0: np.ndarray, seconds: float, n_harm: int = 12) -> np.ndarray:
    """A harmonic tone (n,) whose fundamental follows ``f0`` (Hz, one value per sample)."""
    phase = 2 * np.pi * np.cumsum(f0) / SR
    y = sum(np.sin(k * phase) / k for k in range(1, n_harm + 1))
    return (0.2 * y / np.abs(y).max()).astype(np.float32)


def _column(y: np.ndarray) -> np.ndarray:
    return extract_features(y, dataclasses.replace(CFG, steadiness=True))[:, -1]


def test_held_notes_are_steady_and_a_gliding_voice_and_noise_are_not() -> None:
    rng = np.random.default_rng(0)
    n = 4 * SR
    t = np.arange(n) / SR
    held = _harmonic(np.repeat([196.0, 220.0, 247.0, 262.0], n // 4), 4.0)  # four held notes
    # a talking voice's pitch: 120 Hz +- 20 %, gliding at syllable rate (4 Hz), and a vibrato
    glide = _harmonic(120 * (1 + 0.2 * np.sin(2 * np.pi * 4 * t) + 0.03 * np.sin(2 * np.pi * 11 * t)), 4.0)
    noise = (0.1 * rng.standard_normal(n)).astype(np.float32)
    m_held, m_glide, m_noise = (float(np.median(_column(y)[10:])) for y in (held, glide, noise))
    assert m_held > 0.8, m_held
    assert m_glide < 0.35, m_glide
    assert abs(m_noise) < 0.1, m_noise
    assert np.all(_column(np.zeros(SR, np.float32)) == 0.0)  # silence: no fine structure to hold


def test_the_column_is_loudness_free() -> None:
    y = _harmonic(np.full(2 * SR, 220.0), 2.0) + 0.01 * np.random.default_rng(1).standard_normal(2 * SR).astype(np.float32)
    a, b = _column(y), _column(0.05 * y)
    np.testing.assert_allclose(a, b, atol=1e-3)


def test_streaming_equals_offline_in_any_chunking() -> None:
    rng = np.random.default_rng(2)
    y = np.concatenate([_harmonic(np.full(SR, 330.0), 1.0), (0.05 * rng.standard_normal(SR)).astype(np.float32)])
    cfg = dataclasses.replace(CFG, steadiness=True)
    ref = extract_features(y, cfg)
    for block in (1, 517, 735, 4096):
        s = StreamingFeatureExtractor(cfg, SR)
        got = np.concatenate([s.push(y[i: i + block]) for i in range(0, len(y), block)])
        np.testing.assert_allclose(got, ref[: len(got)], rtol=1e-5, atol=1e-5)  # as tests/test_features_streaming.py
    frames = np.lib.stride_tricks.sliding_window_view(np.concatenate([np.zeros(2048 - 735), y]), 2048)[::735]
    tr = SteadinessTracker(2048)
    np.testing.assert_array_equal(np.concatenate([tr(frames[:7]), tr(frames[7:])]), steadiness(frames, 2048))
    from models.features.spectral import SpectralKernel  # the extractors hand it the spectral kernel's FFT

    np.testing.assert_array_equal(SteadinessTracker(2048).from_spectrum(SpectralKernel(cfg).spectrum(frames)),
                                  steadiness(frames, 2048))


def test_a_config_without_it_keeps_its_fingerprint_and_one_with_it_has_one_more_column() -> None:
    assert "steadiness" not in CFG.to_dict()
    on = dataclasses.replace(CFG, steadiness=True)
    assert on.dim == CFG.dim + 1 and on.fingerprint() != CFG.fingerprint()
    assert FeatureConfig.from_dict(on.to_dict()) == on
    assert on.base() == CFG.base()
    with pytest.raises(ConfigError, match="steadiness"):
        FeatureConfig(steadiness="yes")


def test_only_the_gate_reads_it() -> None:
    from models.networks.dance_vq import DanceVQConfig

    assert DanceVQConfig(feature_dim=62, gate_col=62).input_dim == 63
    assert DanceVQConfig(feature_dim=62).input_dim == 62
    with pytest.raises(ConfigError, match="gate_col"):
        DanceVQConfig(feature_dim=62, gate_col=13)


def test_training_a_predictor_on_it_is_refused() -> None:
    from models.training.config import TrainConfig

    with pytest.raises(ConfigError, match="steadiness"):
        TrainConfig.from_dict({"model": "dance_vq", "features": {"kind": "mfcc_onset", "steadiness": True}})


def test_the_detector_reads_it_as_statistic_0_and_mfcc_1_without_it() -> None:
    from models.networks import music_gate as mg

    rng = np.random.default_rng(3)
    feats = rng.standard_normal((60, 63)).astype(np.float32)
    feats[:, 13] = -20.0  # loud enough
    feats[:, 62] = 0.5
    mean, std = np.zeros(62), np.ones(62)
    with_col = mg.stats_trace(feats, mean, std, 60, 15.0, steadiness_col=62)
    without = mg.stats_trace(feats, mean, std, 60, 15.0)
    np.testing.assert_allclose(with_col[:, 0], 0.5, atol=1e-9)  # the running mean of a constant column
    a = np.exp(-1 / 15.0)
    ref = np.empty(60)
    ref[0] = feats[0, 1]
    for t in range(1, 60):
        ref[t] = a * ref[t - 1] + (1 - a) * feats[t, 1]
    np.testing.assert_allclose(without[:, 0], ref, atol=1e-5)  # MFCC 1's running mean
    np.testing.assert_array_equal(with_col[:, 1:], without[:, 1:])


def test_the_stream_runs_the_detector_at_the_time_constant_it_was_fitted_at() -> None:
    import math

    from models.generate import load_model
    from models.networks.dance_stream import DanceStream

    lm = load_model(None)
    c = lm.model.config
    if c.gate_col < 0:
        pytest.skip(f"{lm.path} has no steadiness column")
    assert lm.features.steadiness and c.gate_col == c.feature_dim and c.gate_tau == 10.0
    gate = DanceStream(lm.model)._idle.presence
    assert gate is not None and gate._a_music == pytest.approx(math.exp(-1.0 / c.gate_tau))
    assert gate._scol == c.gate_col


def test_music_weight_moves_the_fit_towards_music() -> None:
    from models.networks import music_gate as mg
    from models.training.music_gate import fit_network

    rng = np.random.default_rng(5)
    x = rng.standard_normal((2000, mg.N_STATS))
    y = (x[:, 0] + 1.5 * rng.standard_normal(2000) > 0).astype(np.float32)  # overlapping classes

    def music_share(p: np.ndarray) -> float:
        mean, std, w1, b1, w2, b2 = mg.unpack(p)
        return float(((np.tanh(((x - mean) / std) @ w1.T + b1) @ w2 + b2[0]) > 0).mean())

    assert music_share(fit_network(x, y, steps=60, music_weight=3.0)) > music_share(fit_network(x, y, steps=60)) + 0.05
