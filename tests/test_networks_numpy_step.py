"""The NumPy streaming step against the torch reference step and the offline pass."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from models.networks.blocks import randomize_batchnorm
from models.networks.causal import CausalGenerator
from models.networks.generator import GeneratorConfig
from models.networks.numpy_step import NumpyStep
from models.networks.streaming import StreamingGenerator, offline_windowed, torch_threads

D = 65


@pytest.fixture(autouse=True, scope="module")
def one_torch_thread():
    with torch_threads(1):
        yield


def make_model(**kw) -> CausalGenerator:
    torch.manual_seed(1)
    m = randomize_batchnorm(CausalGenerator(GeneratorConfig(channels=(16, 16, 24, 24, 32), **kw)), seed=2)
    with torch.no_grad():
        m.head.weight.normal_(0.0, 0.3)
    return m.eval()


@pytest.mark.parametrize("kw", [{}, {"attention": False}, {"kernel": 5, "convs_per_block": 1}, {"input_norm": True}])
def test_numpy_step_equals_torch_step_frame_by_frame(kw):
    model = make_model(**kw)
    batch = 3
    ref_state = model.init_stream_state(batch)
    fast = NumpyStep(model, batch)
    x = np.random.default_rng(0).normal(size=(80, batch, D)).astype(np.float32)
    worst = 0.0
    for t in range(len(x)):
        if t == 37:  # reset one row mid-stream, as a new window does
            ref_state.zero_rows(1)
            fast.zero_rows(1)
        ref = model.step(torch.from_numpy(x[t]), ref_state).numpy()
        got = fast.step(x[t])
        assert got.shape == ref.shape and got.dtype == np.float32
        worst = max(worst, float(np.abs(got - ref).max()))
    assert worst < 1e-5, worst
    assert np.ptp(got[:, 3:]) > 0.1  # the outputs compared were not constant


def test_streaming_numpy_and_torch_paths_agree_with_offline():
    model = make_model()
    x = np.random.default_rng(5).normal(size=(300, D)).astype(np.float32)
    ref = offline_windowed(model, x)
    outs = {}
    for kind in ("numpy", "torch"):
        gen = StreamingGenerator(model, step=kind)
        outs[kind] = np.concatenate([gen.push(x[i : i + 7]) for i in range(0, len(x), 7)])
        gen.reset()  # and again from a reset: identical
        again = np.concatenate([gen.push(x[i : i + 50]) for i in range(0, len(x), 50)])
        assert np.array_equal(again, outs[kind])
    assert np.abs(outs["numpy"] - ref).max() < 1e-4
    assert np.abs(outs["numpy"] - outs["torch"]).max() < 1e-5


def test_unknown_step_kind_is_a_clear_error():
    from models.errors import ConfigError

    with pytest.raises(ConfigError, match="step must be"):
        StreamingGenerator(make_model(), step="jax")
