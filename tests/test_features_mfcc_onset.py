"""The "mfcc_onset" feature kind: A2B's MFCC columns plus the onset column the beat tracker follows."""

from __future__ import annotations

import numpy as np
import pytest
from _audio_blocks import music, stream_in_random_blocks

from models.errors import ConfigError
from models.features.resample import resample
from models.features.spectral import FeatureConfig, extract_features
from models.features.streaming import StreamingFeatureExtractor
from models.timebase import HOP, SAMPLE_RATE

MFCC_ONSET = FeatureConfig(kind="mfcc_onset", n_mels=128)


def test_columns_are_the_mfcc_kind_then_the_logmel_onset_column():
    x = music(3.0)
    both = extract_features(x, MFCC_ONSET)
    assert MFCC_ONSET.base_dim == MFCC_ONSET.dim == 29 and both.shape == (len(x) // HOP, 29)
    np.testing.assert_array_equal(both[:, :28], extract_features(x, FeatureConfig.mfcc()))
    np.testing.assert_array_equal(both[:, 28], extract_features(x, FeatureConfig(n_mels=128))[:, -1])
    assert both[:, 28].max() > 1.0 and both[0, 28] == 0.0  # the bursts show; frame 0 has no predecessor


def test_fingerprint_is_its_own_and_older_kinds_keep_theirs():
    assert MFCC_ONSET.fingerprint().startswith("mfcc_onset-d29-")
    assert FeatureConfig.mfcc().fingerprint() == "mfcc-d28-65129e1607a2"  # pinned in test_features_context too
    assert FeatureConfig.from_dict(MFCC_ONSET.to_dict()) == MFCC_ONSET
    with pytest.raises(ConfigError, match="mfcc_onset kind needs n_mels"):
        FeatureConfig(kind="mfcc_onset", n_mels=12)


def test_beat_phase_and_context_run_on_it():
    full = FeatureConfig(kind="mfcc_onset", n_mels=128, context_s=5.0, beat_phase=True)
    assert full.dim == 29 * 2 + 4
    f = extract_features(music(8.0), full)
    assert np.isfinite(f).all()
    onset_ref = extract_features(music(8.0), FeatureConfig(n_mels=128, beat_phase=True))[:, -4:]
    np.testing.assert_array_equal(f[:, -4:], onset_ref)  # same onset column, same tracker output
    with pytest.raises(ConfigError, match="onset column"):
        FeatureConfig(kind="mfcc", beat_phase=True)


@pytest.mark.parametrize("cfg", [FeatureConfig.mfcc(), MFCC_ONSET], ids=["mfcc", "mfcc_onset"])
def test_mfcc_kinds_are_causal(cfg):
    x = music(2.0)
    y = x.copy()
    cut = 30 * HOP
    y[cut:] = music(2.0, seed=1)[cut:] * 3
    a, b = extract_features(x, cfg), extract_features(y, cfg)
    np.testing.assert_array_equal(a[:30], b[:30])
    assert np.abs(a[30:] - b[30:]).max() > 1


@pytest.mark.parametrize("sr", [22050, 44100])
def test_it_streams_like_offline_in_random_blocks(sr):
    cfg = FeatureConfig(kind="mfcc_onset", n_mels=128, context_s=5.0, beat_phase=True)
    x = music(7.0, sr)
    offline = extract_features(resample(x, sr, SAMPLE_RATE), cfg)
    streamed = stream_in_random_blocks(StreamingFeatureExtractor(cfg, sr), x)
    assert streamed.shape == offline.shape
    np.testing.assert_allclose(streamed, offline, atol=1e-3)
