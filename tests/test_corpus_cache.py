"""The corpus cache under concurrent builders (pytest-xdist workers, two training runs).

Two processes asking for the same uncached clip at the same moment build it once: the second
waits on the first's lock and loads what it wrote (models.data.corpus._build_lock)."""

from __future__ import annotations

import multiprocessing as mp
import time
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from _dwm_synth import sine_dance, write_dance

from models.data import corpus
from models.features.spectral import FeatureConfig
from models.timebase import SAMPLE_RATE

START, END, AUDIO_S = 25, 150, 7.0  # mocap over music frames 25..150 at 25 fps


def _builder(root: str, cache: str, log: str, barrier) -> None:
    """A child process: build DANCE_W_1 at 1.0x, noting each real build in ``log``."""
    real = corpus.make_clip

    def counted(*args, **kwargs):
        with open(log, "a") as fh:
            fh.write("built\n")
        time.sleep(1.0)  # long enough that the other builder arrives while this one works
        return real(*args, **kwargs)

    corpus.make_clip = counted
    barrier.wait()
    clips = corpus.build_corpus(root, ["DANCE_W_1"], FeatureConfig(n_mels=16), (1.0,), cache, progress=False)
    assert clips[0].num_frames > 0


@pytest.mark.skipif("fork" not in mp.get_all_start_methods(), reason="needs the fork start method")
def test_two_processes_build_an_uncached_clip_once(tmp_path: Path) -> None:
    joints_cm, center_cm, _ = sine_dance(END - START + 1, START, END)
    d = write_dance(tmp_path / "dwm", "DANCE_W_1", joints_cm, center_cm, START, END, audio_s=AUDIO_S)
    t = np.arange(int(AUDIO_S * SAMPLE_RATE)) / SAMPLE_RATE
    sf.write(d / "audio.mp3", (0.2 * np.sin(2 * np.pi * 220 * t)).astype(np.float32), SAMPLE_RATE, format="WAV")
    log = tmp_path / "builds.txt"
    ctx = mp.get_context("fork")
    barrier = ctx.Barrier(2)
    procs = [ctx.Process(target=_builder, args=(str(tmp_path / "dwm"), str(tmp_path / "cache"), str(log), barrier))
             for _ in range(2)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(120)
    assert [p.exitcode for p in procs] == [0, 0]
    assert log.read_text().count("built") == 1, "both processes built the clip: the build lock is not held"
    assert len(list((tmp_path / "cache").glob("*.npz"))) == 1
