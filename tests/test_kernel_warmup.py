"""A first run (empty numba cache): ``performer run``'s warm-up compiles every kernel of the live
path (realtime/kernels.py, :meth:`realtime.engine.Engine._warm_up`), none in a streamed frame."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.serial  # a frame's lateness against LATE_GUARD_MS: the serial pass of make test

REPO = Path(__file__).resolve().parents[1]
CLIP = REPO / "models" / "assets" / "clip.ogg"
#: Most a frame may come out later than the run's most punctual one (ms). A kernel compiled in
#: the live path made the first frame 448 ms late on a busy 2-core machine, where a run with
#: every kernel cached was at worst 127 ms late (`performer run --record`, 960 frames).
LATE_GUARD_MS = 250.0


def performer_run(cache: Path, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    return subprocess.run([sys.executable, "-m", "realtime.cli", "run", "--audio", str(CLIP), "--no-osc",
                           "--no-ws", *args], cwd=REPO, env=env, capture_output=True, text=True, timeout=900)


@pytest.mark.slow
def test_first_run_compiles_the_live_kernels_in_the_warm_up_not_in_a_frame(tmp_path):
    cache = tmp_path / "numba"
    cache.mkdir()
    take = tmp_path / "take.npz"
    run = performer_run(cache, "--duration", "8", "--record", str(take))
    assert run.returncode == 0, run.stderr
    assert "compiling the live path's" in run.stderr, run.stderr  # the one status line of a first run
    clock = time.time() - time.monotonic()  # file times (time.time) on the frames' monotonic clock

    rec = np.load(take)
    arrival = rec["wall_time"] - rec["audio_sample"] / int(rec["input_sample_rate"])
    audio_start = float(arrival.min())  # at or after the source started: the warm-up was over
    compiled_live = sorted(f"{p.name} ({(p.stat().st_mtime - clock - audio_start) * 1000:.0f} ms after)"
                           for p in cache.rglob("*.nbi") if p.stat().st_mtime - clock > audio_start)
    assert not compiled_live, f"kernels compiled after the audio started: {compiled_live}"
    late_ms = (arrival - audio_start) * 1000.0
    assert len(late_ms) == 8 * 30 and late_ms.max() < LATE_GUARD_MS, \
        f"frame {int(late_ms.argmax())} came out {late_ms.max():.0f} ms late"

    again = performer_run(cache, "--fast", "--duration", "1")  # the cache holds them now
    assert again.returncode == 0 and "compiling" not in again.stderr, again.stderr


def test_kernels_numba_inlines_are_not_counted_as_uncached():
    """feet.py's quaternion helpers are ``inline="always"``: numba compiles them into their
    callers and never caches them alone, so counting them left `python -m realtime.kernels`
    (make setup) failing and every run announcing a compile."""
    import models.networks.feet  # noqa: F401 - its kernels join the live dispatchers
    from realtime.kernels import _live_dispatchers

    names = {f"{d.py_func.__module__}.{d.py_func.__qualname__}" for d in _live_dispatchers()}
    assert "models.networks.feet._leg_ik" in names
    assert not {"models.networks.feet._mul", "models.networks.feet._q"} & names
