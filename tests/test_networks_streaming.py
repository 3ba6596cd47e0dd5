"""Acceptance tests of the streaming generator against the windowed offline reference."""

from __future__ import annotations

import time

import numpy as np
import pytest
import torch

from models.errors import ConfigError
from models.networks.blend import seam_ratio
from models.networks.blocks import randomize_batchnorm
from models.networks.causal import CausalGenerator
from models.networks.generator import GeneratorConfig, UNetGenerator, paper_config
from models.networks.streaming import NaiveWindowGenerator, StreamingGenerator, offline_windowed, torch_threads
from models.rig.motion import POSE_DIM

D = 65


@pytest.fixture(autouse=True, scope="module")
def one_torch_thread():
    with torch_threads(1):  # small ops: one thread is faster, and steady on a busy machine
        yield


@pytest.fixture(scope="module")
def model() -> CausalGenerator:
    torch.manual_seed(0)
    m = randomize_batchnorm(CausalGenerator(GeneratorConfig(channels=(16, 16, 24, 24, 32))))
    with torch.no_grad():
        m.head.weight.normal_(0.0, 0.3)  # livelier output than the rest-pose init
    return m.eval()


def random_features(t: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=(t, D)).astype(np.float32)


def structured_features(t: int) -> np.ndarray:
    """Slow sinusoids per band plus an onset-like impulse train every 15 frames."""
    n = np.arange(t)[:, None]
    x = np.sin(2 * np.pi * n / (20 + np.arange(D)[None])) * 2.0
    x[::15, -1] += 5.0
    return x.astype(np.float32)


def stream(gen, x: np.ndarray, seed: int = 0, max_block: int = 40) -> np.ndarray:
    rng = np.random.default_rng(seed)
    out, i = [], 0
    while i < len(x):
        k = int(rng.integers(1, max_block + 1))
        y = gen.push(x[i : i + k])
        assert y.shape == (len(x[i : i + k]), POSE_DIM) and y.dtype == np.float32
        out.append(y)
        i += k
    return np.concatenate(out)


def unit_quats(p: np.ndarray) -> bool:
    n = np.linalg.norm(p[:, 3:].reshape(len(p), -1, 4), axis=-1)
    return bool(np.isfinite(p).all() and np.abs(n - 1).max() < 1e-5)


@pytest.mark.parametrize("window,hop", [(128, 64), (96, 32)])
@pytest.mark.parametrize("kind", ["random", "structured"])
def test_stream_equals_offline_windowed(model, window, hop, kind):
    x = random_features(333, 3) if kind == "random" else structured_features(333)
    ref = offline_windowed(model, x, window, hop)
    got = stream(StreamingGenerator(model, window, hop), x, seed=window + hop)
    assert ref.shape == got.shape == (333, POSE_DIM)
    assert np.abs(got - ref).max() < 1e-4
    assert unit_quats(got)


def test_windows_blend_into_one_track(model):
    """Sanity that the test above compares something: windows disagree before blending."""
    x = random_features(200, 4)
    whole = model(torch.from_numpy(x.T[None].copy())).detach()[0].T.numpy()
    assert np.abs(offline_windowed(model, x)[130:] - whole[130:]).max() > 1e-2


def test_crossfade_hides_the_zero_state_seams(model):
    """Switching hard to each fresh window shows its zero-state start; the blend does not."""
    x = structured_features(1024)
    blended = offline_windowed(model, x)
    with torch.no_grad():
        fresh = np.concatenate([
            model(torch.from_numpy(x[s : s + 64].T[None].copy()))[0].T.numpy() for s in range(0, len(x), 64)
        ])
    assert seam_ratio(fresh, 128, 64) > 1.5
    assert seam_ratio(blended, 128, 64) < 1.2


def test_causality_offline_and_streaming(model):
    x = random_features(260, 1)
    base_off = offline_windowed(model, x)
    base_stream = stream(StreamingGenerator(model), x)
    for t in (0, 63, 64, 100, 127, 128, 200):
        x2 = x.copy()
        x2[t + 1 :] = random_features(len(x) - t - 1, 100 + t) * 5
        off = offline_windowed(model, x2)
        st = stream(StreamingGenerator(model), x2, seed=t)
        assert np.abs(off[: t + 1] - base_off[: t + 1]).max() < 1e-5, t
        assert np.abs(st[: t + 1] - base_stream[: t + 1]).max() < 1e-5, t
        assert np.abs(st[t + 1 :] - base_stream[t + 1 :]).max() > 1e-3  # the change does arrive


def test_non_finite_features_never_give_nan(model):
    x = random_features(150, 2)
    bad = x.copy()
    bad[10, 3] = np.nan
    bad[20] = np.inf
    bad[30, :5] = -np.inf
    bad[40, 0] = 1e30  # finite but absurd: clipped
    gen = StreamingGenerator(model)
    out = stream(gen, bad)
    assert unit_quats(out)
    assert gen.nonfinite_frames == 3
    zeroed = np.nan_to_num(bad, nan=0.0, posinf=0.0, neginf=0.0)
    zeroed[40, 0] = 1e4
    assert np.abs(out - stream(StreamingGenerator(model), zeroed)).max() < 1e-5
    np.testing.assert_allclose(out, offline_windowed(model, bad), rtol=1e-4, atol=1e-4)  # frame 40 is huge


def test_reset_and_empty_pushes(model):
    x = random_features(90, 5)
    gen = StreamingGenerator(model)
    first = gen.push(x)
    assert gen.push(np.zeros((0, D), np.float32)).shape == (0, POSE_DIM)
    gen.push(random_features(50, 6))
    gen.reset()
    assert gen.frame == 0
    np.testing.assert_allclose(gen.push(x), first, atol=1e-6)


def test_bad_arguments_raise_config_errors(model):
    with pytest.raises(ConfigError, match="multiple of 16"):
        StreamingGenerator(model, 128, 40)
    with pytest.raises(ConfigError, match="causal"):
        StreamingGenerator(UNetGenerator(paper_config(channels=(8, 8, 8, 8, 8))))
    with pytest.raises(ConfigError, match="65"):
        StreamingGenerator(model).push(np.zeros((3, 64), np.float32))
    with pytest.raises(ConfigError, match="causal"):
        NaiveWindowGenerator(UNetGenerator(paper_config(channels=(8, 8, 8, 8, 8))))


def test_naive_generator_matches_first_window(model):
    """Before the second window starts, both are window 0 run causally."""
    x = random_features(64, 7)
    naive = NaiveWindowGenerator(model)
    np.testing.assert_allclose(stream(naive, x, max_block=5), offline_windowed(model, x), atol=1e-5)


def median_us_per_frame(gen, x: np.ndarray) -> tuple[float, float]:
    times = []
    for row in x:
        t0 = time.perf_counter()
        gen.push(row[None])
        times.append(time.perf_counter() - t0)
    return float(np.median(times) * 1e6), float(np.percentile(times, 99) * 1e6)


@pytest.mark.slow
def test_streaming_is_far_cheaper_than_naive_recompute():
    """Generous guard only; benchmarks/studies/stream_cost.py measures the real figures."""
    torch.manual_seed(0)
    m = randomize_batchnorm(CausalGenerator(GeneratorConfig())).eval()  # the shipped size
    x = random_features(300, 8)
    fast = median_us_per_frame(StreamingGenerator(m), x)
    naive_gen = NaiveWindowGenerator(m)
    naive_gen.push(x[:127])  # measure at full window length
    slow = median_us_per_frame(naive_gen, x[127:187])
    print(f"\nper-frame median/p99 us: streaming {fast[0]:.0f}/{fast[1]:.0f}, naive {slow[0]:.0f}/{slow[1]:.0f}")
    assert fast[0] * 3 < slow[0]
