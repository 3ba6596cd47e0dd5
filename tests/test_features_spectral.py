"""Offline features: librosa's definitions on hop-ending frames, causal, config contract."""

from __future__ import annotations

import json

import librosa
import numpy as np
import pytest

from models.errors import AudioError, ConfigError
from models.features.audio_io import bundled_clip_path, load_audio
from models.features.spectral import FeatureConfig, causal_frames, extract_features, frame_time_s, num_frames
from models.timebase import HOP, SAMPLE_RATE


@pytest.fixture(scope="module")
def clip() -> np.ndarray:
    return load_audio(bundled_clip_path())[0][: 8 * SAMPLE_RATE]


def _left_padded(x: np.ndarray, n_fft: int) -> np.ndarray:
    """The signal librosa.stft(center=False) frames into hop-ending windows."""
    return np.concatenate([np.zeros(n_fft - HOP), x.astype(np.float64)])


def test_logmel_onset_matches_librosa(clip: np.ndarray) -> None:
    cfg = FeatureConfig(n_fft=2048, n_mels=64, fmin=30.0, fmax=10000.0)
    feats = extract_features(clip, cfg)
    mel = librosa.feature.melspectrogram(
        y=_left_padded(clip, cfg.n_fft), sr=SAMPLE_RATE, n_fft=cfg.n_fft, hop_length=HOP, center=False,
        n_mels=cfg.n_mels, fmin=cfg.fmin, fmax=cfg.fmax, power=2.0,
    )
    logmel = librosa.power_to_db(mel, ref=1.0, amin=cfg.amin, top_db=None)
    onset = librosa.onset.onset_strength(S=logmel, lag=1, max_size=1, center=False)
    assert feats.shape == (clip.size // HOP, 65) == (logmel.shape[1], logmel.shape[0] + 1)
    np.testing.assert_allclose(feats[:, :64], logmel.T, atol=1e-3, rtol=0)
    np.testing.assert_allclose(feats[:, 64], onset, atol=1e-4, rtol=0)
    assert feats[0, 64] == 0.0 and onset.max() > 5.0  # the clip has real onsets


def test_linear_matches_librosa(clip: np.ndarray) -> None:
    cfg = FeatureConfig.linear()
    assert (cfg.n_fft, cfg.dim) == (1024, 513)
    feats = extract_features(clip, cfg)
    mag = np.abs(librosa.stft(_left_padded(clip, 1024), n_fft=1024, hop_length=HOP, center=False, window="hann"))
    db = librosa.amplitude_to_db(mag, ref=1.0, amin=np.sqrt(cfg.amin), top_db=None)
    np.testing.assert_allclose(feats, db.T, atol=1e-3, rtol=0)


def test_frames_end_at_their_hop_and_count_is_floor() -> None:
    x = np.random.default_rng(0).standard_normal(10 * HOP + 100)
    frames = causal_frames(x, 2048)
    assert frames.shape == (10, 2048) and num_frames(x.size) == 10
    for t in (0, 1, 5, 9):
        end = (t + 1) * HOP
        np.testing.assert_array_equal(frames[t, -min(end, 2048) :], x[max(0, end - 2048) : end])
    assert np.all(frames[0, : 2048 - HOP] == 0)
    assert extract_features(np.zeros(HOP - 1)).shape == (0, 65)
    assert frame_time_s(0) == pytest.approx(1 / 30) and frame_time_s(29) == pytest.approx(1.0)


def test_features_are_causal(clip: np.ndarray) -> None:
    a = extract_features(clip[: 60 * HOP])
    changed = clip[: 60 * HOP].copy()
    changed[40 * HOP :] = 0.5
    b = extract_features(changed)
    np.testing.assert_array_equal(a[:40], b[:40])  # frame t uses samples < (t + 1) * HOP only
    assert not np.allclose(a[40], b[40])


def test_silence_hits_the_floor_and_input_is_validated() -> None:
    f = extract_features(np.zeros(5 * HOP, np.float32))
    assert np.all(f[:, :64] == -100.0) and np.all(f[:, 64] == 0.0)
    with pytest.raises(AudioError, match="mono"):
        extract_features(np.zeros((5 * HOP, 2)))
    with pytest.raises(AudioError, match="1 non-finite"):
        extract_features(np.r_[np.zeros(3 * HOP), np.nan])


def test_config_round_trip_fingerprint_and_dims() -> None:
    cfg = FeatureConfig()
    assert cfg.dim == 65 and FeatureConfig(n_mels=80).dim == 81 and FeatureConfig(kind="linear").dim == 1025
    d = json.loads(json.dumps(cfg.to_dict()))
    assert FeatureConfig.from_dict(d) == cfg and FeatureConfig.from_dict(d).fingerprint() == cfg.fingerprint()
    # Pinned: if this changes, features changed: bump FEATURE_VERSION and update the value.
    assert cfg.fingerprint() == "logmel_onset-d65-450fd1c71cf5"
    assert FeatureConfig(fmin=0, fmax=11025).fingerprint() == cfg.fingerprint()  # ints canonicalised
    fps = {c.fingerprint() for c in (cfg, FeatureConfig(n_mels=80), FeatureConfig.linear(), FeatureConfig(fmin=20.0))}
    assert len(fps) == 4


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"kind": "no_such_kind"}, "kind"),
        ({"n_fft": 512}, "n_fft"),
        ({"n_mels": 0}, "n_mels"),
        ({"fmin": 5000.0, "fmax": 4000.0}, "fmin"),
        ({"fmax": 20000.0}, "fmax"),
        ({"amin": 0.0}, "amin"),
        ({"hop": 512}, "hop"),
        ({"n_fft": 2048.5}, "integer"),
    ],
)
def test_bad_configs_are_refused(kwargs: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        FeatureConfig(**kwargs)


def test_from_dict_refuses_unknown_keys_and_other_versions() -> None:
    d = FeatureConfig().to_dict()
    with pytest.raises(ConfigError, match="unknown"):
        FeatureConfig.from_dict({**d, "n_chroma": 12})
    with pytest.raises(ConfigError, match="version"):
        FeatureConfig.from_dict({**d, "version": 0})
