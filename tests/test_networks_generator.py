"""The U-Net generators: shapes, quaternion normalisation, causality, streaming step."""

from __future__ import annotations

import pytest
import torch

from models.errors import ConfigError
from models.networks.blocks import AttentionGate, UpState, causal_upsample, randomize_batchnorm, upsample_push, upsample_read
from models.networks.causal import CausalGenerator
from models.networks.generator import GeneratorConfig, UNetGenerator, count_parameters, paper_config
from models.networks.streaming import torch_threads
from models.rig.motion import POSE_DIM

SMALL = (16, 16, 24, 24, 32)


@pytest.fixture(autouse=True, scope="module")
def one_torch_thread():
    with torch_threads(1):  # small ops: one thread is faster, and steady on a busy machine
        yield


def small_causal(seed: int = 0) -> CausalGenerator:
    torch.manual_seed(seed)
    return randomize_batchnorm(CausalGenerator(GeneratorConfig(channels=SMALL)), seed).eval()


def quat_norms(y: torch.Tensor) -> torch.Tensor:
    return y[:, 3:].unflatten(1, (-1, 4)).norm(dim=2)


def test_default_sizes_fit_the_cpu_budget():
    for cfg in (GeneratorConfig(), paper_config()):
        n = count_parameters(UNetGenerator(cfg))
        assert 500_000 < n < 3_000_000, n


def test_offline_shapes_and_unit_quaternions():
    torch.manual_seed(0)
    model = UNetGenerator(paper_config(channels=SMALL)).eval()
    y = model(torch.randn(2, 65, 128))
    assert y.shape == (2, POSE_DIM, 128)
    assert torch.allclose(quat_norms(y), torch.ones(()), atol=1e-5)


def test_offline_rejects_bad_shapes():
    model = UNetGenerator(paper_config(channels=SMALL))
    with pytest.raises(ConfigError, match="multiple of 16"):
        model(torch.randn(1, 65, 100))
    with pytest.raises(ConfigError, match="65"):
        model(torch.randn(1, 64, 128))


def test_causal_forward_any_length_and_only_past_inputs():
    model = small_causal()
    x = torch.randn(1, 65, 77)
    with torch.no_grad():
        y = model(x)
        assert y.shape == (1, POSE_DIM, 77)
        for t in (0, 5, 15, 16, 40, 63, 76):
            x2 = x.clone()
            x2[..., t + 1 :] = 10 * torch.randn_like(x2[..., t + 1 :])
            y2 = model(x2)
            assert (y2[..., : t + 1] - y[..., : t + 1]).abs().max() < 1e-6, t
            if t < 70:
                assert (y2[..., t + 1 :] - y[..., t + 1 :]).abs().max() > 1e-3  # later frames do react


def test_offline_generator_does_look_ahead():
    """Sanity for the causality test: the non-causal paper model fails it."""
    torch.manual_seed(0)
    model = randomize_batchnorm(UNetGenerator(paper_config(channels=SMALL))).eval()
    x = torch.randn(1, 65, 64)
    x2 = x.clone()
    x2[..., 40:] += 5
    with torch.no_grad():
        assert (model(x2)[..., :40] - model(x)[..., :40]).abs().max() > 1e-4


def test_step_matches_forward_frame_by_frame():
    model = small_causal(1)
    x = torch.randn(3, 65, 70)
    with torch.no_grad():
        y = model(x)
    with torch.inference_mode():
        st = model.init_stream_state(3)
        ys = torch.stack([model.step(x[:, :, i], st).clone() for i in range(70)], dim=-1)
    assert (ys - y).abs().max() < 1e-5
    with torch.inference_mode():
        st.zero_rows(slice(None))
        st.frame = 0
        again = torch.stack([model.step(x[:, :, i], st).clone() for i in range(20)], dim=-1)
    assert (again - y[..., :20]).abs().max() < 1e-5


def test_causal_upsample_formula_and_stream_agree():
    u = torch.randn(2, 3, 5)
    up = causal_upsample(u)
    prev = torch.cat([torch.zeros(2, 3, 1), u[..., :-1]], dim=-1)
    assert torch.equal(up[..., 0::2], prev)
    assert torch.allclose(up[..., 1::2], 0.5 * (prev + u))
    st = UpState(prev=torch.zeros(2, 3), last=torch.zeros(2, 3))
    out = torch.empty(2, 3)
    for t in range(10):
        if t % 2 == 1:
            upsample_push(st, u[..., t // 2])  # coarse frame t//2 completes at fine frame t
        assert torch.allclose(upsample_read(st, t, out), up[..., t])


def test_attention_gate_is_one_weight_per_frame():
    gate = AttentionGate(8, 6, 4)
    f_d, f_u = torch.randn(2, 8, 10) + 3, torch.randn(2, 6, 10)
    ratio = gate(f_d, f_u) / f_d
    assert torch.allclose(ratio, ratio[:, :1].expand_as(ratio), atol=1e-6)
    assert ((ratio > 0) & (ratio < 1)).all()


def test_training_mode_backward_reaches_every_parameter():
    torch.manual_seed(0)
    for model in (CausalGenerator(GeneratorConfig(channels=SMALL)), UNetGenerator(paper_config(channels=SMALL))):
        model.train()
        model(torch.randn(4, 65, 32)).square().mean().backward()
        missing = [n for n, p in model.named_parameters() if p.grad is None or not torch.isfinite(p.grad).all()]
        assert not missing


def test_fresh_model_starts_near_rest_pose():
    torch.manual_seed(0)
    y = CausalGenerator(GeneratorConfig()).eval()(torch.randn(1, 65, 64)).detach()
    w = y[:, 3:].unflatten(1, (-1, 4))[:, :, 3]
    assert w.abs().mean() > 0.9


def test_config_validation():
    with pytest.raises(ConfigError):
        GeneratorConfig(channels=(8, 8, 8))
    with pytest.raises(ConfigError):
        GeneratorConfig(kernel=4)
    with pytest.raises(ConfigError):
        CausalGenerator(paper_config())
    for bad in (-0.1, 1.0):
        with pytest.raises(ConfigError, match="dropout"):
            GeneratorConfig(dropout=bad)
    cfg = GeneratorConfig(channels=SMALL)
    assert GeneratorConfig.from_dict(cfg.to_dict()) == cfg


def test_dropout_acts_in_training_only_and_leaves_the_stream_unchanged():
    """Training mode draws a new mask per call; eval mode (and so the streaming step) is the
    same network as without dropout, and stays causal."""
    torch.manual_seed(0)
    plain = CausalGenerator(GeneratorConfig(channels=SMALL))
    dropped = CausalGenerator(GeneratorConfig(channels=SMALL, dropout=0.5))
    dropped.load_state_dict(plain.state_dict())
    x = torch.randn(2, 65, 48)
    plain.eval(), dropped.eval()
    with torch.no_grad():
        want = plain(x)
        assert torch.equal(dropped(x), want)
        st = dropped.init_stream_state()
        stepped = torch.stack([dropped.step(x[:1, :, t], st)[0] for t in range(x.shape[-1])], dim=1)
    torch.testing.assert_close(stepped, want[0], atol=1e-4, rtol=0)
    dropped.train()
    a, b = dropped(x), dropped(x)
    assert not torch.allclose(a, b)


def test_input_norm_standardises_before_padding_and_streams_exactly():
    """input_norm: eval mode is a fixed per-column (x - mean) / std before the first block, so
    features with wildly different scales reach it standardised; the causal left padding and
    the stream's zero history are both the mean frame, which keeps the step equal to forward."""
    torch.manual_seed(3)
    model = randomize_batchnorm(CausalGenerator(GeneratorConfig(channels=SMALL, feature_dim=6, input_norm=True)), 3)
    scale = torch.tensor([1000.0, 1.0, 0.01, 50.0, 3.0, 0.5])
    mean = torch.tensor([-300.0, 2.0, 0.0, 10.0, -1.0, 0.0])
    model.train()
    for _ in range(200):  # running statistics converge to the inputs' own
        model(torch.randn(4, 6, 64) * scale[None, :, None] + mean[None, :, None])
    model.eval()
    n = model.in_norm
    assert ((n.running_mean - mean).abs() < 0.1 * scale).all(), n.running_mean  # within a tenth of a std
    assert ((n.running_var.sqrt() / scale - 1).abs() < 0.1).all(), n.running_var.sqrt()
    x = torch.randn(1, 6, 70) * scale[None, :, None] + mean[None, :, None]
    full = model(x)
    # Output frame t only reads inputs <= t, whatever the scales.
    x2 = x.clone()
    x2[..., 40:] *= -5
    torch.testing.assert_close(model(x2)[..., :40], full[..., :40])
    # Same as a model without the option fed the standardised input by hand.
    plain = CausalGenerator(GeneratorConfig(channels=SMALL, feature_dim=6))
    plain.load_state_dict({k: v for k, v in model.state_dict().items() if not k.startswith("in_norm.")})
    plain.eval()
    z = (x - n.running_mean[None, :, None]) / torch.sqrt(n.running_var + n.eps)[None, :, None]
    torch.testing.assert_close(plain(z), full, rtol=1e-4, atol=1e-5)
    st = model.init_stream_state(1)
    stepped = torch.stack([model.step(x[:, :, t], st).clone() for t in range(70)], dim=-1)
    assert (stepped - full).abs().max() < 1e-4


def test_input_norm_is_off_by_default_and_validated():
    assert GeneratorConfig().input_norm is False
    assert not any(k.startswith("in_norm") for k in CausalGenerator(GeneratorConfig(channels=SMALL)).state_dict())
    assert CausalGenerator(GeneratorConfig(channels=SMALL)).input_affine() is None
    with pytest.raises(ConfigError, match="input_norm"):
        GeneratorConfig(input_norm=1)
    # A config dict from before the option (an old checkpoint's) still builds, without it.
    old = {k: v for k, v in GeneratorConfig().to_dict().items() if k != "input_norm"}
    assert GeneratorConfig.from_dict(old).input_norm is False
