"""The features' compiled kernels against the NumPy arithmetic they replaced (docs/features.md)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from models.features.context import LAGS, PRIOR_PERIOD, TEMPO_WINDOW, ContextTracker
from models.features.spectral import FeatureConfig, SpectralKernel, _log_mel


@pytest.mark.parametrize("cfg", [FeatureConfig(), FeatureConfig(kind="mfcc_onset", n_mels=128), FeatureConfig.mfcc()],
                         ids=lambda c: f"{c.kind}-{c.n_mels}")
def test_banded_log_mel_is_the_dense_filterbank_product(cfg):
    import librosa

    kernel = SpectralKernel(cfg)
    mel = librosa.filters.mel(sr=cfg.sample_rate, n_fft=cfg.n_fft, n_mels=cfg.n_mels, fmin=cfg.fmin, fmax=cfg.fmax,
                              dtype=np.float64)
    frames = np.random.default_rng(0).normal(size=(40, cfg.n_fft))
    frames[:5] *= 1e-7  # quiet frames: the amin floor
    spec = np.fft.rfft(frames * kernel.window, axis=-1)
    want = 10.0 * np.log10(np.maximum((spec.real ** 2 + spec.imag ** 2) @ mel.T, cfg.amin))
    got = _log_mel(spec, kernel.mel_lo, kernel.mel_w, cfg.amin)
    assert kernel.mel_w.shape[1] < mel.shape[1] // 8  # bands, not the dense matrix
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-10)


def _beat_numpy(win: np.ndarray, tracker: ContextTracker) -> tuple[float, float, float, float]:
    """The beat columns as the NumPy version computed them (256-point FFT autocorrelation)."""
    xw = (win - float(win @ tracker._w) / tracker._w_sum) * tracker._w
    spec = np.fft.rfft(xw, 256)
    ac = np.fft.irfft(spec.real * spec.real + spec.imag * spec.imag, 256)
    lag = int(LAGS[0] + np.argmax(ac[LAGS[0]: LAGS[-1] + 1] * tracker._lag_prior))
    y0, y1, y2 = float(ac[lag - 1]), float(ac[lag]), float(ac[lag + 1])
    den = y0 - 2.0 * y1 + y2
    period = lag + (min(0.5, max(-0.5, 0.5 * (y0 - y2) / den)) if den < 0 else 0.0)
    ang = tracker._two_pi_j / period
    re, im = float(xw @ np.cos(ang)), float(xw @ np.sin(ang))
    m = math.hypot(re, im)
    norm = float(np.abs(xw).sum())
    clarity = m / norm if norm > 1e-9 else 0.0
    unit = 1.0 / m if m > 1e-12 else 0.0
    return clarity * re * unit, clarity * im * unit, clarity, math.log2(period / PRIOR_PERIOD)


def test_compiled_beat_tracker_gives_the_numpy_columns():
    rng = np.random.default_rng(3)
    tracker = ContextTracker(base_dim=1, beat_phase=True)
    period = 14.0
    onsets = np.maximum(0.0, np.cos(2 * np.pi * np.arange(900) / period)) ** 8 + 0.2 * rng.random(900)
    onsets[300:340] = 0.0  # a silent stretch: clarity 0
    got = tracker(onsets[:, None])
    ring = np.zeros(2 * TEMPO_WINDOW)
    for t, onset in enumerate(onsets):
        ring[t % TEMPO_WINDOW] = ring[t % TEMPO_WINDOW + TEMPO_WINDOW] = onset
        pos = t % TEMPO_WINDOW
        want = np.asarray(_beat_numpy(ring[pos + TEMPO_WINDOW: pos: -1], tracker), np.float32)
        np.testing.assert_allclose(got[t], want, rtol=0, atol=1e-6, err_msg=f"frame {t}")
    assert abs(2 ** got[-1, 3] * PRIOR_PERIOD - period) < 0.5  # it found the beat
