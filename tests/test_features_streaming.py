"""Streaming features equal offline features, are causal, and the latency constant is exact."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from models.errors import AudioError
from models.features.audio_io import to_mono
from models.features.resample import resample
from models.features.spectral import FeatureConfig, extract_features
from models.features.streaming import (
    COMMON_RATES,
    StreamingFeatureExtractor,
    feature_latency_s,
    feature_latency_samples,
    samples_needed,
)
from models.timebase import HOP, SAMPLE_RATE

CONFIGS = [FeatureConfig(), FeatureConfig.linear()]


def _music_like(sr: int, seconds: float, channels: int, seed: int) -> np.ndarray:
    """Noise bursts + tones with sharp onsets, (n, channels) float32 at sr."""
    rng = np.random.default_rng(seed)
    n = int(seconds * sr)
    t = np.arange(n) / sr
    env = np.exp(-8.0 * ((t * 4) % 1.0))  # an attack every 250 ms
    tone = np.sin(2 * np.pi * 440 * t) + 0.5 * np.sin(2 * np.pi * 1320 * t)
    x = (0.3 * env * tone)[:, None] + 0.05 * rng.standard_normal((n, channels))
    return x.astype(np.float32)


def _offline(x: np.ndarray, sr: int, cfg: FeatureConfig) -> np.ndarray:
    return extract_features(resample(to_mono(x), sr, SAMPLE_RATE), cfg)


def _stream(x: np.ndarray, sr: int, cfg: FeatureConfig, sizes: list[int], flush: bool = True) -> np.ndarray:
    ex = StreamingFeatureExtractor(cfg, sr)
    out, lo, i = [], 0, 0
    while lo < x.shape[0]:
        n = sizes[i % len(sizes)]
        out.append(ex.push(x[lo : lo + n]))
        assert out[-1].dtype == np.float32 and out[-1].shape[1] == cfg.dim
        lo, i = lo + n, i + 1
    if flush:
        out.append(ex.flush())
    frames = np.concatenate(out)
    assert frames.shape[0] == ex.frames_emitted
    return frames


@pytest.mark.parametrize("sr", [8000, 22050, 44100, 48000])
@settings(max_examples=8, deadline=None)
@given(data=st.data())
def test_streamed_equals_offline_any_blocks(sr: int, data: st.DataObject) -> None:
    cfg = data.draw(st.sampled_from(CONFIGS))
    channels = data.draw(st.integers(1, 3))
    # Log-uniform block sizes 1..4096, so single samples and large blocks both occur.
    sizes = data.draw(st.lists(st.integers(0, 12).map(lambda e: 2**e), min_size=1, max_size=20))
    sizes = [min(4096, s + data.draw(st.integers(0, s))) for s in sizes]
    x = _music_like(sr, 1.2, channels, seed=len(sizes))
    offline = _offline(x, sr, cfg)
    streamed = _stream(x, sr, cfg, sizes)
    assert streamed.shape == offline.shape == (int(1.2 * SAMPLE_RATE) // HOP, cfg.dim)
    assert np.abs(streamed - offline).max() < 1e-4


@pytest.mark.parametrize("sr", COMMON_RATES)
def test_streamed_equals_offline_every_common_rate(sr: int) -> None:
    rng = np.random.default_rng(sr)
    x = _music_like(sr, 1.0, 2, seed=sr)
    sizes = [int(s) for s in rng.integers(1, 4097, size=50)]
    offline = _offline(x, sr, FeatureConfig())
    streamed = _stream(x, sr, FeatureConfig(), sizes)
    np.testing.assert_allclose(streamed, offline, atol=1e-4, rtol=0)


def test_without_flush_stream_lags_offline_by_at_most_one_frame() -> None:
    x = _music_like(48000, 1.0, 1, seed=1)
    offline = _offline(x, 48000, FeatureConfig())
    streamed = _stream(x, 48000, FeatureConfig(), [480], flush=False)
    assert offline.shape[0] - streamed.shape[0] in (0, 1)
    np.testing.assert_allclose(streamed, offline[: streamed.shape[0]], atol=1e-4, rtol=0)


@pytest.mark.parametrize("sr", [22050, 44100, 48000, 16000])
def test_future_audio_never_changes_emitted_frames(sr: int) -> None:
    x = _music_like(sr, 1.0, 2, seed=3)
    cut = x.shape[0] // 2
    y = x.copy()
    y[cut:] = np.random.default_rng(9).standard_normal(y[cut:].shape).astype(np.float32)
    ex_x, ex_y = StreamingFeatureExtractor(FeatureConfig(), sr), StreamingFeatureExtractor(FeatureConfig(), sr)
    before = ex_x.push(x[:cut])
    np.testing.assert_array_equal(before, ex_y.push(y[:cut]))
    assert ex_x.frames_emitted == int(np.sum(samples_needed(np.arange(40), sr) <= cut))
    # Offline too: every frame whose inputs lie before the cut is identical.
    fx, fy = _offline(x, sr, FeatureConfig()), _offline(y, sr, FeatureConfig())
    k = before.shape[0]
    np.testing.assert_allclose(fx[:k], before, atol=1e-4, rtol=0)
    np.testing.assert_array_equal(fx[:k], fy[:k])
    assert not np.allclose(fx[k + 1], fy[k + 1]), "frames after the cut should see the change"


@pytest.mark.parametrize("sr", [8000, 22050, 44100, 48000, 96000])
def test_frame_emitted_exactly_when_its_last_needed_sample_arrives(sr: int) -> None:
    ex = StreamingFeatureExtractor(FeatureConfig(), sr)
    x = _music_like(sr, 0.5, 1, seed=5)[:, 0]
    pushed = 0
    for t in range(12):
        need = ex.samples_needed(t)
        assert need == samples_needed(t, sr)
        ex.push(x[pushed : need - 1])
        pushed = need - 1
        assert ex.frames_emitted == t, f"frame {t} emitted before sample {need} arrived"
        assert ex.push(x[pushed:need]).shape[0] == 1
        pushed = need
        assert ex.frames_emitted == t + 1


@pytest.mark.parametrize("sr", COMMON_RATES)
def test_latency_constant_is_the_worst_case_of_the_code(sr: int) -> None:
    ex = StreamingFeatureExtractor(FeatureConfig(), sr)
    t = np.arange(2000)
    nominal = (t + 1) * HOP * sr / SAMPLE_RATE  # end of the frame's hop, in input samples
    excess = np.array([ex.samples_needed(int(i)) for i in t]) - nominal
    assert ex.latency_samples == feature_latency_samples(sr)
    assert excess.max() <= ex.latency_samples < excess.max() + 1
    assert feature_latency_s(FeatureConfig(), sr) == ex.latency_samples / sr
    if sr == SAMPLE_RATE:
        assert ex.latency_samples == 0  # no resampling: a frame is out the moment its hop is complete
    assert feature_latency_s(None, sr) < 0.002


def test_reset_starts_a_new_stream_and_blocks_are_validated() -> None:
    x = _music_like(44100, 0.5, 2, seed=7)
    ex = StreamingFeatureExtractor(FeatureConfig(), 44100)
    first = ex.push(x)
    ex.reset()
    assert ex.frames_emitted == 0 and ex.samples_pushed == 0
    np.testing.assert_array_equal(ex.push(x), first)
    assert ex.push(np.zeros((0, 2), np.float32)).shape == (0, FeatureConfig().dim)
    bad = x[:100].copy()
    bad[[10, 20], 1] = [np.nan, np.inf]
    n = ex.frames_emitted
    with pytest.raises(AudioError, match="2 non-finite samples"):
        ex.push(bad)
    assert ex.frames_emitted == n and ex.samples_pushed == x.shape[0]  # state untouched
    with pytest.raises(AudioError, match="shape"):
        ex.push(np.zeros((4, 2, 2), np.float32))


def test_int16_blocks_equal_their_float_scaling() -> None:
    pcm = (np.random.default_rng(2).integers(-20000, 20000, size=(22050, 2))).astype(np.int16)
    a = _stream(pcm, 22050, FeatureConfig(), [1000])
    b = _stream(pcm.astype(np.float32) / 32768.0, 22050, FeatureConfig(), [1000])
    np.testing.assert_array_equal(a, b)


def test_blocks_that_complete_no_frame_are_held_and_resampled_with_the_next_that_does() -> None:
    """The live path's 512-sample blocks at 44.1 kHz: two of three complete no frame. Such a
    block is only kept (the resampler sees nothing, samples_pushed counts it), a copy: the
    caller's buffer reused at once changes nothing; the frames are bit for bit those of the
    same audio pushed whole (the same samples through the same arithmetic)."""
    sr, cfg = 44100, FeatureConfig()
    x = _music_like(sr, 3.0, 1, seed=11)[:, 0]
    ex = StreamingFeatureExtractor(cfg, sr)
    buf = np.empty(512, np.float32)  # one buffer, as the engine's ring read reuses its chunk
    out, held = [], 0
    for lo in range(0, x.size - 512, 512):
        buf[:] = x[lo : lo + 512]
        before = ex._resampler.samples_in
        frames = ex.push(buf)
        out.append(frames)
        if not len(frames):
            held += 1
            assert ex._resampler.samples_in == before, "a block that completes no frame was resampled"
        assert ex.samples_pushed == lo + 512
    pushed = (x.size - 512) // 512 * 512
    assert held >= len(out) // 2
    whole = StreamingFeatureExtractor(cfg, sr)
    np.testing.assert_array_equal(np.concatenate(out), whole.push(x[:pushed]))
    np.testing.assert_array_equal(ex.flush(), whole.flush())
