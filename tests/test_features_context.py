"""The optional context and beat-phase feature columns (models/features/context.py)."""

from __future__ import annotations

import numpy as np
import pytest
from _audio_blocks import stream_in_random_blocks

from models.errors import ConfigError
from models.features.context import BEAT_COLUMNS, TEMPO_WINDOW, ContextTracker
from models.features.resample import resample
from models.features.spectral import FeatureConfig, extract_features
from models.features.streaming import StreamingFeatureExtractor
from models.timebase import FPS, HOP, SAMPLE_RATE

FULL = FeatureConfig(context_s=20.0, beat_phase=True)


def test_configs_without_the_options_keep_their_fingerprints():
    # Fingerprints from before the options existed: caches and shipped checkpoints stay valid.
    assert FeatureConfig().fingerprint() == "logmel_onset-d65-450fd1c71cf5"
    assert FeatureConfig.linear().fingerprint() == "linear-d513-b696a3870e27"
    assert FeatureConfig.mfcc().fingerprint() == "mfcc-d28-65129e1607a2"
    assert "context_s" not in FeatureConfig().to_dict() and "beat_phase" not in FeatureConfig().to_dict()


def test_dimensions_round_trip_and_base():
    assert FULL.base_dim == 65 and FULL.dim == 65 + 65 + BEAT_COLUMNS
    assert FeatureConfig(beat_phase=True).dim == 65 + BEAT_COLUMNS
    assert FeatureConfig.mfcc().__class__(kind="mfcc", context_s=5).dim == 56
    assert FeatureConfig.from_dict(FULL.to_dict()) == FULL
    assert FULL.base() == FeatureConfig() and FULL.fingerprint() != FeatureConfig().fingerprint()
    assert FeatureConfig(context_s=10).fingerprint() != FeatureConfig(context_s=20).fingerprint()


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"context_s": -1.0}, "context_s"),
        ({"context_s": float("nan")}, "context_s"),
        ({"context_s": "10"}, "context_s"),
        ({"beat_phase": "yes"}, "beat_phase"),
        ({"beat_phase": True, "kind": "mfcc"}, "logmel_onset"),
    ],
)
def test_bad_option_values_are_refused(kwargs, message):
    with pytest.raises(ConfigError, match=message):
        FeatureConfig(**kwargs)


def test_context_columns_are_the_bias_corrected_running_mean():
    rng = np.random.default_rng(0)
    base = rng.normal(size=(300, 5)).astype(np.float32)
    tr = ContextTracker(5, context_s=2.0)
    got = np.concatenate([tr(base[:7]), tr(base[7:8]), tr(base[8:])])
    b, m, want = np.exp(-1 / (FPS * 2.0)), np.zeros(5), []
    for t, row in enumerate(base.astype(np.float64)):
        m = b * m + (1 - b) * row
        want.append(m / (1 - b ** (t + 1)))
    np.testing.assert_allclose(got, np.array(want), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(got[0], base[0], rtol=1e-6)  # frame 0: the mean of one frame
    np.testing.assert_allclose(got[1], base[:2].mean(0) + (got[1] - base[:2].mean(0)), rtol=1e-6)


def _clicks(period: float, frames: int, accent_offbeat: float = 0.0, start: float = 3.0) -> np.ndarray:
    """Onset envelope with a click every ``period`` frames (first at ``start``) and
    optional weaker clicks half-way between."""
    env = np.zeros(frames)
    beats = np.arange(start, frames, period)
    env[np.rint(beats).astype(int)] = 1.0
    if accent_offbeat:
        env[np.rint(beats[:-1] + period / 2).astype(int)] = accent_offbeat
    return env


def _beat_cols(env: np.ndarray) -> np.ndarray:
    base = np.zeros((env.size, 3))
    base[:, -1] = env
    return ContextTracker(3, beat_phase=True)(base)


@pytest.mark.parametrize("period", [12.0, 18.0, 21.0, 30.0])
def test_beat_tracker_finds_tempo_and_phase_of_a_click_track(period):
    env = _clicks(period, 600)
    cols = _beat_cols(env)
    settled = np.arange(TEMPO_WINDOW, 600)
    est = 15.0 * 2.0 ** cols[settled, 3]
    assert np.all(np.abs(est - period) < 0.6)
    # Clear pulse (a mean-removed click train tops out near 0.5: the baseline between
    # clicks counts in the normaliser); random onsets score far lower.
    assert np.all(cols[settled, 2] > 0.4)
    noise = _beat_cols(np.random.default_rng(0).exponential(size=600))
    assert np.median(noise[settled, 2]) < 0.2
    theta = np.arctan2(cols[:, 1], cols[:, 0])
    on = [t for t in np.flatnonzero(env) if t >= TEMPO_WINDOW]
    assert np.all(np.abs(theta[on]) < 0.3)  # phase 0 on the clicks
    # The phase rises by 2 pi / P per frame between clicks.
    step = np.angle(np.exp(1j * (theta[on[0] + 2] - theta[on[0] + 1])))
    assert step == pytest.approx(2 * np.pi / period, abs=0.15)


def test_beat_tracker_prefers_the_beat_to_its_offbeat_eighths():
    env = _clicks(21.0, 600, accent_offbeat=0.6)  # a waltz-like beat with weaker eighths between
    cols = _beat_cols(env)
    est = 15.0 * 2.0 ** cols[TEMPO_WINDOW:, 3]
    assert np.median(est) == pytest.approx(21.0, abs=0.6)


def test_silence_gives_zero_phase_columns_not_nan():
    cols = _beat_cols(np.zeros(400))
    assert np.isfinite(cols).all()
    np.testing.assert_array_equal(cols[:, :3], 0.0)


def _music(seconds: float, bpm: float = 100.0) -> np.ndarray:
    rng = np.random.default_rng(1)
    t = np.arange(int(seconds * SAMPLE_RATE)) / SAMPLE_RATE
    env = np.exp(-10.0 * ((t * bpm / 60.0) % 1.0))
    return (0.3 * env * np.sin(2 * np.pi * 330 * t) + 0.02 * rng.standard_normal(t.size)).astype(np.float32)


@pytest.mark.parametrize("sr", [22050, 44100])
def test_streamed_columns_equal_offline_and_follow_the_music(sr):
    y = _music(14.0)
    x = resample(y, SAMPLE_RATE, sr)
    y22 = resample(x, sr, SAMPLE_RATE)
    offline = extract_features(y22, FULL)
    streamed = stream_in_random_blocks(StreamingFeatureExtractor(FULL, sr), x, seed=sr)
    assert streamed.shape == offline.shape == (offline.shape[0], FULL.dim)
    np.testing.assert_allclose(streamed, offline, atol=1e-4, rtol=0)
    np.testing.assert_array_equal(offline[:, : FULL.base_dim], extract_features(y22, FeatureConfig()))
    # 100 BPM = 18 frames per beat, found once the tracker's window has filled.
    est = 15.0 * 2.0 ** offline[TEMPO_WINDOW:, -1]
    assert np.median(est) == pytest.approx(18.0, abs=0.6)


def test_extra_columns_are_causal():
    y = _music(10.0)
    z = y.copy()
    cut = 150
    z[cut * HOP :] = np.random.default_rng(2).normal(0, 0.3, z.size - cut * HOP).astype(np.float32)
    fy, fz = extract_features(y, FULL), extract_features(z, FULL)
    np.testing.assert_array_equal(fy[:cut], fz[:cut])
    assert not np.allclose(fy[cut + 1], fz[cut + 1])


def test_reset_starts_a_new_stream():
    y = _music(5.0)
    ex = StreamingFeatureExtractor(FULL, SAMPLE_RATE)
    first = ex.push(y)
    ex.reset()
    np.testing.assert_array_equal(ex.push(y), first)


def test_streaming_bench_cli_takes_the_options(capsys):
    from models.features import streaming

    assert streaming.main(["--bench", "--seconds", "2", "--rate", "22050", "--context-s", "5", "--beat-phase"]) == 0
    assert "logmel_onset-d134-" in capsys.readouterr().out
    with pytest.raises(SystemExit) as exc:
        streaming.main(["--bench", "--seconds", "2", "--kind", "mfcc", "--beat-phase"])
    assert exc.value.code == 2 and "logmel_onset" in capsys.readouterr().err
