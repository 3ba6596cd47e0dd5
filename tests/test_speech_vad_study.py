"""benchmarks/studies/speech_vad.py: silero-vad's speech shares, counted right (docs/listening.md)."""

from __future__ import annotations


import numpy as np
import pytest

from script_loader import load_script

study = load_script("benchmarks/studies/speech_vad.py")


def test_shares_count_chunks_and_one_second_windows():
    p = np.r_[np.full(31, 0.9), np.r_[np.full(15, 0.9), np.full(16, 0.1)], np.full(10, 0.9)]  # 2 windows and a rest
    s = study.shares(p)
    assert s["speech"] == pytest.approx((31 + 15 + 10) / len(p))
    assert s["windows"] == 0.5  # the second window has 15 of 31 chunks: not more than half
    assert study.shares(np.zeros(0)) == {"speech": 0.0, "windows": 0.0}


def test_silero_hears_no_speech_in_silence_and_the_bundled_clip():
    pytest.importorskip("silero_vad", reason="silero-vad is not installed (the dev extras have it)")
    from silero_vad import load_silero_vad

    from models.features.audio_io import bundled_clip_path, load_audio

    model = load_silero_vad()
    clip = load_audio(bundled_clip_path(), study.SR)[0]
    for audio in (np.zeros(study.SR, np.float32), clip):
        p, cost = study.speech_probability(model, audio)
        assert len(p) == len(audio) // study.CHUNK == len(cost)
        assert study.shares(p)["speech"] < 0.05
