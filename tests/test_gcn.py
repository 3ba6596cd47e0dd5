"""The graph-convolutional adversarial dance generator (``gcn``, models/networks/gcn.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
import torch

from models.errors import CheckpointError, ConfigError
from models.features.spectral import FeatureConfig
from models.generate import generate, load_model, run_model
from models.networks import gcn as G
from models.networks.checkpoint import build_model, load_checkpoint, save_checkpoint
from models.rig.humanoid import BONES, NUM_BONES
from models.rig.motion import POSE_DIM
from models.rig.npz import load_npz_extra
from models.rig.skeleton import load_default_skeleton
from models.timebase import HOP, SAMPLE_RATE
from models.training.gcn_train import GCNTrainOptions, classifier_accuracy, gan_step, train_music_classifier

FEATS = FeatureConfig()
FEATURE_META = {**FEATS.to_dict(), "fingerprint": FEATS.fingerprint()}
RIG = {"bones": list(BONES), "pose_dim": POSE_DIM}
TINY = {"feature_dim": FEATS.dim, "noise_channels": 16, "style_dim": 4, "widths": [16, 8, 8, 8, 8],
        "disc_widths": [8, 8, 8, 8], "t_kernel": 3, "classifier_width": 4, "audio_rate": 8000}


@pytest.fixture(autouse=True)
def one_thread():
    """Many small ops: one torch thread (two stall 5-20x on a busy 2-core machine)."""
    from models.networks.streaming import torch_threads

    with torch_threads(1):
        yield


def tiny_model(seed: int = 0, **over) -> G.GCNDancer:
    torch.manual_seed(seed)
    return build_model("gcn", {**TINY, **over})


def unit_and_finite(poses: np.ndarray) -> None:
    assert np.isfinite(poses).all()
    q = poses[:, 3:].reshape(len(poses), -1, 4)
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-5)


# -- audio and noise -------------------------------------------------------------------------


def test_mu_law_compands_and_inverts():
    x = np.linspace(-1, 1, 2001).astype(np.float32)
    y = G.mu_law(x)
    assert y[0] == pytest.approx(-1) and y[-1] == pytest.approx(1) and y[1000] == pytest.approx(0, abs=1e-7)
    assert np.all(np.diff(y) > 0)  # monotone
    np.testing.assert_allclose(G.mu_law_inverse(y), x, atol=1e-5)
    # small amplitudes get most of the range: |x| = 0.01 maps to ~0.23 for mu = 255
    assert G.mu_law(np.float32(0.01)) == pytest.approx(np.log1p(2.55) / np.log1p(255), rel=1e-5)
    np.testing.assert_allclose(G.mu_law(torch.from_numpy(x)).numpy(), y, atol=1e-6)
    q = G.compand(np.random.default_rng(0).uniform(-1.5, 1.5, 10000))  # clipped, 8-bit
    assert q.min() >= -1 and q.max() <= 1 and len(np.unique(q)) <= 256
    a = G.prepare_audio(0.5 * np.sin(2 * np.pi * 440 * np.arange(SAMPLE_RATE) / SAMPLE_RATE), 16000)
    assert a.shape == (16000,) and a.dtype == np.float32


def test_gp_noise_shape_and_unit_variance():
    scales = G.length_scales(8, 0.5, 16)
    assert scales.shape == (8,) and scales[0] == pytest.approx(0.5) and scales[-1] == pytest.approx(16)
    z = G.gp_noise(scales, 37, batch=3, generator=torch.Generator().manual_seed(0))
    assert z.shape == (3, 8, 37) and z.dtype == torch.float32
    big = G.gp_noise(torch.full((256,), 3.0), 50, batch=4, generator=torch.Generator().manual_seed(1))
    assert big.std().item() == pytest.approx(1.0, abs=0.05)
    # the empirical covariance of many draws is the RBF kernel
    cov = torch.einsum("bci,bcj->ij", big, big) / (big.shape[0] * big.shape[1])
    lag = torch.arange(50.0)
    want = torch.exp(-((lag[:, None] - lag[None]) ** 2) / (2 * 3.0**2))
    assert (cov - want).abs().max().item() < 0.12


def test_gp_noise_is_more_coherent_with_longer_length_scales():
    def lag1_autocorrelation(scale: float) -> float:
        z = G.gp_noise(torch.full((64,), scale), 200, batch=2, generator=torch.Generator().manual_seed(0))
        z = z - z.mean(dim=-1, keepdim=True)
        return float((z[..., 1:] * z[..., :-1]).sum() / (z * z).sum())

    r = [lag1_autocorrelation(s) for s in (0.3, 1.0, 3.0, 10.0)]
    assert r == sorted(r) and r[0] < 0.2 and r[-1] > 0.95  # white-ish -> smooth
    # and the expected value is exp(-1 / (2 l^2))
    assert r[1] == pytest.approx(np.exp(-0.5), abs=0.05)


# -- graph -----------------------------------------------------------------------------------


def test_hierarchy_and_adjacency():
    assert G.LEVEL_SIZES == (1, 3, 11, NUM_BONES)
    for (n, parents, groups), (n_prev, _, _) in zip(G.HIERARCHY[1:], G.HIERARCHY[:-1]):
        assert len(parents) == n and len(groups) == n and set(groups) == set(range(n_prev))
        a = G.partitioned_adjacency(list(parents))
        assert a.shape == (3, n, n)
        np.testing.assert_allclose(a.sum(dim=(0, 1)).numpy(), 1.0, atol=1e-6)  # columns normalised
    # a group's parent holds the parent bone of the group's first bone
    from models.rig.humanoid import PARENT_INDEX

    for bone, par in enumerate(PARENT_INDEX):
        g, gp = G.GROUPS_11[bone], G.GROUPS_11[par] if par >= 0 else -1
        assert gp == g or G.PARENT_11[g] == gp


def test_graph_upsampling_shapes_1_3_11_rig():
    x = torch.randn(2, 5, 7, 1)
    for i in range(3):
        up = G.GraphUpsample(G.HIERARCHY[i + 1][2], G.HIERARCHY[i][0])
        x = up(x)
        assert x.shape == (2, 5, 7, G.LEVEL_SIZES[i + 1])
    down = G.GraphDownsample(G.GROUPS_11, 11)
    assert down(torch.ones(2, 5, 7, NUM_BONES)).shape == (2, 5, 7, 11)
    np.testing.assert_allclose(down(torch.ones(1, 1, 1, NUM_BONES)).detach().numpy(), 1.0, atol=1e-6)  # group mean
    # through the generator: (1 node, T0) -> (3, 2T0) -> (11, 4T0) -> (21, 8T0) -> (21, 16T0)
    m = tiny_model()
    trace: list = []
    lat = m.latent(torch.zeros(1, 4, dtype=torch.long), m.noise(1, 4))
    m.generator(lat, trace=trace)
    assert [(t, v) for _, t, v in trace] == [(4, 1), (8, 3), (16, 11), (32, NUM_BONES), (64, NUM_BONES)]


# -- generator and discriminator ----------------------------------------------------------------


def test_generator_and_discriminator_shapes():
    m = tiny_model().eval()
    f = torch.randn(3, FEATS.dim, 64)
    with torch.no_grad():
        y = m(f, torch.tensor([0, 1, 2]))
    assert y.shape == (3, POSE_DIM, 64)
    q = y[:, 3:].transpose(1, 2).reshape(3, 64, NUM_BONES, 4)
    np.testing.assert_allclose(q.norm(dim=-1).numpy(), 1.0, atol=1e-5)
    d = G.GCNDiscriminator(m.config)
    assert d(y, torch.zeros(3, 4, dtype=torch.long)).shape == (3, 4)
    with pytest.raises(ConfigError):
        m(torch.randn(1, FEATS.dim, 50))  # not a multiple of 16
    with pytest.raises(ConfigError):
        m(f, torch.zeros(3, 5, dtype=torch.long))
    # noise and style matter; the same noise and style give the same poses
    z = m.noise(1, 4, torch.Generator().manual_seed(0))
    with torch.no_grad():
        a, b = m(f[:1], torch.tensor([0]), z), m(f[:1], torch.tensor([0]), z)
        c, e = m(f[:1], torch.tensor([2]), z), m(f[:1], torch.tensor([0]), m.noise(1, 4))
    assert torch.equal(a, b) and not torch.allclose(a, c) and not torch.allclose(a, e)


def test_audio_features_option_conditions_the_generator():
    m = tiny_model(audio_features=True, feature_channels=4).eval()
    z = m.noise(1, 2, torch.Generator().manual_seed(0))
    with torch.no_grad():
        a = m(torch.zeros(1, FEATS.dim, 32), torch.tensor([0]), z)
        b = m(torch.randn(1, FEATS.dim, 32) * 10, torch.tensor([0]), z)
    assert not torch.allclose(a, b)
    with torch.no_grad():  # the paper's generator ignores them
        p = tiny_model().eval()
        assert torch.equal(p(torch.zeros(1, FEATS.dim, 32), torch.tensor([0]), z),
                           p(torch.randn(1, FEATS.dim, 32), torch.tensor([0]), z))


def test_spline_smoothing_removes_jitter_and_keeps_unit_quaternions():
    t = np.arange(120)
    rng = np.random.default_rng(0)
    poses = np.zeros((120, POSE_DIM), np.float32)
    poses[:, 1] = 0.9 + 0.05 * np.sin(t / 10)
    ang = 0.3 * np.sin(t / 15)[:, None] + 0.05 * rng.standard_normal((120, NUM_BONES))
    poses[:, 3:] = np.stack([np.sin(ang / 2), 0 * ang, 0 * ang, np.cos(ang / 2)], -1).reshape(120, -1)
    out = G.spline_smooth(poses, 4)
    unit_and_finite(out)
    jitter = lambda p: np.abs(np.diff(p[:, 3:], n=2, axis=0)).mean()  # noqa: E731
    assert jitter(out) < 0.3 * jitter(poses)
    np.testing.assert_allclose(out[:, 1], poses[:, 1], atol=2e-3)  # smooth signals pass
    np.testing.assert_array_equal(G.spline_smooth(poses[:5], 4), poses[:5])  # too short: unchanged


# -- training ----------------------------------------------------------------------------------


def test_tiny_model_trains_losses_finite_and_l1_falls():
    torch.manual_seed(0)
    m = tiny_model()
    d = G.GCNDiscriminator(m.config)
    gen_params = [p for n, p in m.named_parameters() if not n.startswith("style_net.")]
    opt_g = torch.optim.Adam(gen_params, lr=3e-3, betas=(0.5, 0.999))
    opt_d = torch.optim.Adam(d.parameters(), lr=1e-3, betas=(0.5, 0.999))
    offsets = torch.from_numpy(load_default_skeleton().offsets).float()
    # targets: each style swings every bone about x at its own frequency, hips at 0.9 m
    t = torch.arange(32.0)
    real = torch.zeros(6, POSE_DIM, 32)
    style = torch.tensor([0, 1, 2, 0, 1, 2])
    for i, s in enumerate(style):
        ang = 0.4 * torch.sin(t * (0.1 + 0.1 * s))
        real[i, 1] = 0.9
        real[i, 3::4] = torch.sin(ang / 2)
        real[i, 6::4] = torch.cos(ang / 2)
    feats = torch.zeros(6, FEATS.dim, 32)
    steps = style[:, None].expand(-1, 2)
    rows = [gan_step(m, d, opt_g, opt_d, feats, real, steps, offsets, gan=i >= 5) for i in range(40)]
    for r in rows:
        assert all(np.isfinite(v) for v in r.values())
    assert "loss_d" in rows[-1] and "loss_g_gan" in rows[-1] and "loss_d" not in rows[0]
    first = np.mean([r["loss_pos"] + r["loss_rot"] for r in rows[:3]])
    last = np.mean([r["loss_pos"] + r["loss_rot"] for r in rows[-3:]])
    assert last < 0.5 * first


def test_music_classifier_learns_two_synthetic_styles():
    m = tiny_model()
    rate = m.config.audio_rate
    n = 20 * rate
    tt = np.arange(n) / rate
    rng = np.random.default_rng(0)
    # style C: a low hum; style R: noise bursts. Train on two songs each, test on a third.
    hum = lambda f: (0.5 * np.sin(2 * np.pi * f * tt)).astype(np.float32)  # noqa: E731
    noise = lambda: (0.3 * rng.standard_normal(n) * (np.sin(2 * np.pi * 2 * tt) > 0)).astype(np.float32)  # noqa: E731
    train = [("a", "C", hum(110)), ("b", "C", hum(150)), ("c", "R", noise()), ("d", "R", noise())]
    val = [("e", "C", hum(130)), ("f", "R", noise())]
    hist = train_music_classifier(m, train, GCNTrainOptions(classifier_steps=40, classifier_batch=8), seed=0,
                                  progress=False)
    assert np.isfinite(hist).all() and np.mean(hist[-5:]) < np.mean(hist[:5])
    acc = classifier_accuracy(m, val)
    assert acc["window_accuracy"] >= 0.9 and acc["song_accuracy"] == 1.0 and set(acc["per_style"]) == {"C", "R"}


def test_train_options_are_split_from_the_model_config():
    opts, rest = GCNTrainOptions.pop_from({"widths": [1, 2, 3, 4, 5], "train_classifier_steps": 7})
    assert opts.classifier_steps == 7 and rest == {"widths": [1, 2, 3, 4, 5]}
    with pytest.raises(ConfigError, match="train_nope"):
        GCNTrainOptions.pop_from({"train_nope": 1})


# -- checkpoints and generation -------------------------------------------------------------------


def save_tiny(path: Path, model: G.GCNDancer | None = None) -> Path:
    model = model or tiny_model()
    return save_checkpoint(path, model, model_name="gcn", generator_config=model.config,
                           feature_config=FEATURE_META, rig=RIG)


def test_checkpoint_round_trip_through_build_model(tmp_path):
    m = tiny_model(seed=3).eval()
    path = save_tiny(tmp_path / "g.pt", m)
    back, meta = load_checkpoint(path, expect_bones=BONES)
    assert isinstance(back, G.GCNDancer) and meta["model_name"] == "gcn"
    assert back.config == m.config and meta["model_config"]["widths"] == [16, 8, 8, 8, 8]
    z = m.noise(2, 4, torch.Generator().manual_seed(0))
    f = torch.zeros(2, FEATS.dim, 64)
    with torch.no_grad():
        assert torch.equal(m(f, torch.tensor([1, 2]), z), back(f, torch.tensor([1, 2]), z))
    audio = np.random.default_rng(0).standard_normal(4 * SAMPLE_RATE).astype(np.float32) * 0.1
    np.testing.assert_array_equal(m.style_track(audio, 120).chunk_probs, back.style_track(audio, 120).chunk_probs)
    assert build_model("gcn").config.noise_channels == 512  # the paper's C by default


def test_generation_on_short_audio(tmp_path):
    ckpt = save_tiny(tmp_path / "g.pt")
    loaded = load_model(ckpt)
    t = np.arange(int(2.5 * SAMPLE_RATE)) / SAMPLE_RATE
    wav = tmp_path / "a.wav"
    sf.write(wav, (0.3 * np.sin(2 * np.pi * 220 * t)).astype(np.float32), SAMPLE_RATE)
    g = generate(wav, tmp_path / "a.npz", loaded)
    assert g.poses.shape == (len(t) // HOP, POSE_DIM)
    unit_and_finite(g.poses)
    np.testing.assert_array_equal(load_npz_extra(tmp_path / "a.npz")["pose"], g.poses)
    again = generate(wav, tmp_path / "b.npz", loaded)  # seeded noise: the same song gives the same dance
    np.testing.assert_array_equal(again.poses, g.poses)
    other = run_model(loaded.model, np.zeros((75, FEATS.dim), np.float32), audio=np.zeros(76 * HOP, np.float32),
                      seed=5)
    assert other.shape == (75, POSE_DIM)
    # shorter than one classifier window (2.13 s) and than one latent step (16 frames)
    for frames in (1, 7, 40):
        p = run_model(loaded.model, np.zeros((frames, FEATS.dim), np.float32), audio=np.zeros((frames + 1) * HOP))
        assert p.shape == (frames, POSE_DIM)
        unit_and_finite(p)
    with pytest.raises(ConfigError, match="needs the song's audio"):
        run_model(loaded.model, np.zeros((40, FEATS.dim), np.float32))


def test_style_switching_changes_the_style_input_mid_sequence():
    m = tiny_model().eval()

    class Loudness(torch.nn.Module):  # a stand-in classifier: quiet windows are style 0, loud ones style 2
        def forward(self, x: torch.Tensor) -> torch.Tensor:
            loud = (x.abs().mean(dim=1) > 0.5).float()
            return torch.stack([10 * (1 - loud), torch.zeros_like(loud), 10 * loud], dim=1)

    m.style_net = Loudness()
    with torch.no_grad():  # a random tiny model barely moves: make its output respond visibly
        m.generator.head.weight.mul_(20)
    rng = np.random.default_rng(0)
    song = np.concatenate([0.001 * rng.standard_normal(8 * SAMPLE_RATE),
                           0.9 * np.sign(rng.standard_normal(8 * SAMPLE_RATE))]).astype(np.float32)
    frames = len(song) // HOP  # 480 frames = 30 latent steps
    track = m.style_track(song, frames)
    assert track.steps.shape == (30,) and track.chunk_probs.shape == (8, 3)
    assert track.steps[0] == 0 and track.steps[-1] == 2
    switch = int(np.flatnonzero(np.diff(track.steps))[0]) + 1
    assert abs(switch * 16 / 30 - 8.0) < 2.2  # it switches within one window of the song's change
    # the generator's latent carries the style embedding of each step
    seen = {}

    def keep_latent(mod, args, out) -> None:
        seen["latent"] = args[0]

    hook = m.generator.register_forward_hook(keep_latent)
    poses = m.generate_poses(np.zeros((frames, FEATS.dim), np.float32), song)
    hook.remove()
    emb = seen["latent"][0, m.config.noise_channels :]  # (E, T0)
    np.testing.assert_allclose(emb[:, 0].numpy(), m.embed.weight[0].detach().numpy())
    np.testing.assert_allclose(emb[:, -1].numpy(), m.embed.weight[2].detach().numpy())
    # ... and the motion after the switch differs from the same noise with the first style kept
    kept = m.generate_poses(np.zeros((frames, FEATS.dim), np.float32), style_steps=np.zeros(30, np.int64))
    before, after = np.abs(poses[:100] - kept[:100]).max(), np.abs(poses[-100:] - kept[-100:]).max()
    assert before < 1e-5 and after > 1e-4 and after > 100 * before


def test_run_refuses_the_offline_only_model(tmp_path):
    from realtime.pipeline import build_pipeline

    ckpt = save_tiny(tmp_path / "g.pt")
    with pytest.raises(CheckpointError, match="offline-only") as err:
        build_pipeline(ckpt)
    assert "\n" not in str(err.value) and "performer generate" in str(err.value)


def test_run_command_prints_one_line_for_the_offline_model(tmp_path, capsys):
    from realtime import cli

    ckpt = save_tiny(tmp_path / "g.pt")
    wav = tmp_path / "a.wav"
    sf.write(wav, np.zeros(SAMPLE_RATE, np.float32), SAMPLE_RATE)
    code = cli.main(["run", "--audio", str(wav), "--checkpoint", str(ckpt), "--no-ws", "--no-osc", "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "offline-only" in err[0]


def test_bad_configs_are_refused():
    for bad in ({"widths": [1, 2]}, {"styles": ["C"]}, {"t_kernel": 4}, {"pose_dim": 11}, {"gp_min_scale": 0}):
        with pytest.raises(ConfigError):
            build_model("gcn", {**TINY, **bad})


@pytest.mark.slow
@pytest.mark.data
def test_evaluate_scores_gcn_with_gan_train_and_gan_test(dwm_root, tmp_path):
    """``performer evaluate --gan-scores`` on a tiny gcn: the classifier hears each clip's song."""
    import json
    import math

    from realtime import cli

    ckpt = save_tiny(tmp_path / "g.pt")
    out = tmp_path / "out"
    code = cli.main(["evaluate", "--checkpoint", str(ckpt), "--data", str(dwm_root), "--out", str(out),
                     "--cache", str(tmp_path / "cache"), "--dances", "1", "--max-frames", "300",
                     "--classifier-epochs", "1", "--gan-scores", "--quiet"])
    assert code == 0
    doc = json.loads((out / "results.json").read_text())
    rows = doc["results"]
    assert list(rows) == ["gcn (g.pt)", "real data"] and "--gan-scores" in doc["commands"][0]
    for row in rows.values():
        assert 0.0 <= row["gan_train"] <= 1.0 and 0.0 <= row["gan_test"] <= 1.0
        assert math.isfinite(row["fd"])
    assert rows["real data"]["gan_train"] == rows["real data"]["gan_test"]
    assert "GAN-train" in (out / "results.md").read_text()
