"""The violinist model (Kao & Su 2020): shapes, relative-position attention, the MFCC
feature kind, training, checkpoints, offline generation, the engine's refusal, and
the Transformer learning-rate schedule."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from _audio_blocks import music, stream_in_random_blocks

from models.errors import CheckpointError, ConfigError
from models.features.spectral import FeatureConfig, extract_features
from models.features.streaming import StreamingFeatureExtractor
from models.networks.checkpoint import build_model, load_checkpoint, save_checkpoint
from models.networks.violin import (
    ARM_BONES, RelativeMultiheadAttention, ViolinConfig, ViolinNet, relative_index,
)
from models.rig.humanoid import BONES, bone_index
from models.rig.motion import POSE_DIM
from models.timebase import HOP, SAMPLE_RATE
from models.training import losses
from models.training.config import TrainConfig
from models.training.schedule import learning_rate, noam_lr

MFCC = FeatureConfig.mfcc()
TINY = {"d_model": 16, "levels": 2, "blocks": 1, "heads": 4, "max_rel": 4, "refine_segment": 8}
RIG = {"bones": list(BONES), "pose_dim": POSE_DIM}


@pytest.fixture(autouse=True)
def one_torch_thread():
    """Many tiny ops: two intra-op threads on a busy 2-core machine run 20x slower."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def tiny(**kw) -> ViolinNet:
    torch.manual_seed(0)
    return build_model("violin", {**TINY, **kw})


def unit_quats(y: torch.Tensor) -> torch.Tensor:
    """(B, P, T) -> quaternion norms (B, T, J)."""
    return y[:, 3:].transpose(1, 2).unflatten(-1, (-1, 4)).norm(dim=-1)


# -- shapes -----------------------------------------------------------------------------------


@pytest.mark.parametrize("t", [1, 3, 16, 37, 64])
def test_shapes_any_length_unit_quaternions(t):
    model = tiny().eval()
    with torch.no_grad():
        y, parts = model(torch.randn(2, 28, t) * 30, return_parts=True)
    assert y.shape == (2, POSE_DIM, t)
    assert torch.isfinite(y).all()
    assert torch.allclose(unit_quats(y), torch.ones(()), atol=1e-5)
    assert parts["right_weight"].shape == (2, t)
    assert ((parts["right_weight"] >= 0) & (parts["right_weight"] <= 1)).all()
    with pytest.raises(ConfigError, match="must be"):
        model(torch.randn(2, 65, t))


def test_default_config_is_the_paper_shape():
    cfg = ViolinConfig()
    assert (cfg.feature_dim, cfg.levels, cfg.blocks, cfg.heads) == (28, 4, 2, 4)
    model = ViolinNet(cfg)
    assert len(model.blocks) == 2 and all(len(b.down) == 4 and len(b.up) == 4 for b in model.blocks)
    assert model.ffn.net[0].out_features == 4 * cfg.d_model  # d_ff = 4d
    assert model.body.lstm.input_size == 28  # the body decoder reads the audio features directly
    assert model.hand.lstm.input_size == cfg.d_model  # the hand decoder reads the encoder
    assert model.offline_only and not cfg.causal
    for bad in ({"d_model": 30, "heads": 4}, {"levels": 0}, {"refine_segment": 1}, {"dropout": 1.0},
                {"input_norm": 1}, {"pose_dim": 7}, {"widths": 3}):
        with pytest.raises(ConfigError):
            build_model("violin", bad)


def test_branches_own_their_bones_and_refinement_touches_one_hand():
    """Body LSTM: root + non-arm bones; hand branch: the arm bones; refinement: LowerArm +
    Hand of the chosen hand only."""
    model = tiny(dropout=0.0).eval()
    x = torch.randn(1, 28, 48) * 30
    arm = set(model.arm_channels.tolist())
    with torch.no_grad():
        base, parts = model(x, return_parts=True)
        with torch.no_grad():
            model.hand.fc.bias.add_(0.3)  # only the arm channels may change
        moved = model(x, return_parts=True)[1]["unrefined"]
    changed = set(torch.nonzero((moved - parts["unrefined"]).abs().amax(dim=(0, 2)) > 1e-6).flatten().tolist())
    assert changed and changed <= arm
    corr = parts["correction"][0]  # (P, T)
    touched = set(torch.nonzero(corr.abs().amax(dim=1) > 0).flatten().tolist())
    refined = {3 + 4 * bone_index(b) + c for b in ("LeftLowerArm", "LeftHand", "RightLowerArm", "RightHand")
               for c in range(4)}
    assert touched <= refined
    assert {b for b in ARM_BONES} == {BONES[i] for i in range(5, 13)}


def test_refinement_follows_the_faster_wrist():
    """The right hand's weight is 1 where the right wrist moves more, 0 where the left does,
    and moves linearly between segment centres."""
    model = tiny(refine_segment=8)
    t = 32
    pose = torch.zeros(1, POSE_DIM, t)
    pose[:, 3 + 3 :: 4] = 1.0  # identity rotations
    wiggle = 0.5 * torch.sin(torch.arange(t) * 1.3)
    lower = {"LeftLowerArm": slice(0, 16), "RightLowerArm": slice(16, 32)}  # left moves first, then right
    for bone, span in lower.items():
        c = 3 + 4 * bone_index(bone)
        pose[0, c + 2, span] = wiggle[span]  # z rotation of the elbow
    w = model.right_hand_weight(pose)[0]
    assert torch.all(w[:4] == 0) and torch.all(w[-4:] == 1)
    assert torch.all(w[1:] >= w[:-1])  # one switch, interpolated
    assert 0 < w[15] < 1 or 0 < w[16] < 1


# -- relative-position attention ---------------------------------------------------------------


def attn(max_rel=3, seed=0) -> RelativeMultiheadAttention:
    torch.manual_seed(seed)
    return RelativeMultiheadAttention(16, 4, max_rel, dropout=0.0).eval()


def test_relative_index_clips_distances():
    idx = relative_index(4, 4, 2)
    assert idx.tolist() == [[2, 3, 4, 4], [1, 2, 3, 4], [0, 1, 2, 3], [0, 0, 1, 2]]


def test_relative_embeddings_are_used():
    a = attn()
    x = torch.randn(2, 10, 16)
    with torch.no_grad():
        y = a(x)
        for p in (a.rel_k, a.rel_v):
            saved = p.clone()
            p.add_(torch.randn_like(p))
            assert (a(x) - y).abs().max() > 1e-3
            p.copy_(saved)
        assert torch.allclose(a(x), y)


def test_without_relative_embeddings_attention_is_permutation_equivariant():
    """Zero relative embeddings: plain content attention, equivariant to permuting frames;
    with them it is not (order matters, which is the point)."""
    a = attn()
    x = torch.randn(1, 9, 16)
    perm = torch.randperm(9)
    with torch.no_grad():
        assert (a(x[:, perm]) - a(x)[:, perm]).abs().max() > 1e-3
        a.rel_k.zero_()
        a.rel_v.zero_()
        assert torch.allclose(a(x[:, perm]), a(x)[:, perm], atol=1e-5)


def test_masked_keys_are_ignored_and_attention_is_translation_equivariant():
    """Masking the keys outside frames [a, b) gives, at queries a..b-1, exactly the output
    of the cropped sequence: only relative positions matter, and masked keys (whatever
    they hold) get zero weight."""
    a = attn(max_rel=3)
    x = torch.randn(1, 20, 16)
    lo, hi = 5, 14
    mask = torch.ones(1, 20, dtype=torch.bool)
    mask[:, lo:hi] = False
    with torch.no_grad():
        full, w = a(x, mask, need_weights=True)
        crop = a(x[:, lo:hi])
        assert torch.allclose(full[:, lo:hi], crop, atol=1e-5)
        assert torch.all(w[..., mask[0]] == 0)
        assert torch.allclose(w.sum(-1), torch.ones(()), atol=1e-5)
        y = x.clone()
        y[:, :lo] = torch.randn(1, lo, 16) * 100
        assert torch.allclose(a(y, mask)[:, lo:hi], full[:, lo:hi], atol=1e-5)


def test_block_passes_the_mask_to_the_bottleneck():
    """UNetAttentionBlock / encode hand a key padding mask to the bottleneck attention."""
    model = tiny(levels=2, dropout=0.0).eval()
    captured = []
    hook = model.blocks[0].attn.attn.register_forward_hook(lambda m, i, o: captured.append(i[1]))
    mask = torch.tensor([[False, False, True]])
    with torch.no_grad():
        x = torch.randn(1, 28, 12)
        a = model.encode(x, mask)
        b = model.encode(x)
    hook.remove()
    assert captured[0] is mask and captured[1] is None
    assert (a - b).abs().max() > 1e-4


# -- MFCC features -------------------------------------------------------------------------------


def test_mfcc_kind_dims_and_librosa_definitions():
    import librosa

    assert MFCC.dim == 28 and MFCC.kind == "mfcc" and MFCC.n_mels == 128
    assert MFCC.fingerprint().startswith("mfcc-d28-") and MFCC.fingerprint() != FeatureConfig().fingerprint()
    assert FeatureConfig.from_dict(MFCC.to_dict()) == MFCC
    with pytest.raises(ConfigError, match="n_mels"):
        FeatureConfig(kind="mfcc", n_mels=12)
    x = music(3.0)
    f = extract_features(x, MFCC)
    assert f.shape == (len(x) // HOP, 28) and f.dtype == np.float32
    padded = np.concatenate([np.zeros(MFCC.n_fft - HOP), x.astype(np.float64)])
    power = np.abs(librosa.stft(padded, n_fft=MFCC.n_fft, hop_length=HOP, center=False)) ** 2
    mel = librosa.feature.melspectrogram(S=power, sr=SAMPLE_RATE, n_mels=MFCC.n_mels)
    ref = librosa.feature.mfcc(S=librosa.power_to_db(mel, top_db=None), n_mfcc=13)[:, : len(f)].T
    np.testing.assert_allclose(f[:, :13], ref, atol=2e-3)
    rms = librosa.feature.rms(y=padded, frame_length=MFCC.n_fft, hop_length=HOP, center=False)[0]
    np.testing.assert_allclose(f[:, 13], librosa.power_to_db(rms**2, top_db=None)[: len(f)], atol=2e-3)
    # first derivatives: backward differences, 0 at frame 0
    np.testing.assert_allclose(f[1:, 14:], np.diff(f[:, :14], axis=0), atol=1e-3)
    assert np.all(f[0, 14:] == 0)


@pytest.mark.parametrize("sr", [22050, 44100])
def test_mfcc_streams_like_offline(sr):
    from models.features.audio_io import load_audio  # noqa: F401  (same resampler as load_audio)
    from models.features.resample import resample

    x = music(1.5, sr)
    offline = extract_features(resample(x, sr, SAMPLE_RATE), MFCC)
    streamed = stream_in_random_blocks(StreamingFeatureExtractor(MFCC, sr), x)
    assert streamed.shape == offline.shape
    np.testing.assert_allclose(streamed, offline, atol=1e-3)


# -- training, checkpoints, generation ---------------------------------------------------------


def test_tiny_model_trains_and_loss_falls():
    """A few Adam steps under the noam schedule on synthetic audio -> motion pairs."""
    torch.manual_seed(0)
    model = tiny(dropout=0.0)
    offsets = torch.from_numpy(__import__("models.rig.skeleton", fromlist=["x"]).load_default_skeleton().offsets).float()
    x = torch.randn(4, 28, 32) * 20
    # target: rotations driven by the first feature (so the audio explains the motion)
    target = torch.zeros(4, POSE_DIM, 32)
    target[:, 3 + 3 :: 4] = 1.0
    target[:, 3 + 4 * bone_index("RightLowerArm") + 2] = torch.tanh(x[:, 0] / 20)
    target[:, 3 + 4 * bone_index("Spine")] = 0.3 * torch.tanh(x[:, 1] / 20)
    target = __import__("models.networks.generator", fromlist=["x"]).normalize_pose(target)
    opt = torch.optim.Adam(model.parameters(), betas=(0.9, 0.98))
    model.train()
    seen = []
    for step in range(1, 41):
        for g in opt.param_groups:
            g["lr"] = noam_lr(step, model.config.d_model, warmup_steps=10)
        loss = 100 * losses.rotation_l1(model(x), target) + 100 * losses.effector_l1(model(x), target, offsets)
        opt.zero_grad()
        loss.backward()
        opt.step()
        seen.append(loss.item())
    assert np.mean(seen[-5:]) < 0.7 * np.mean(seen[:3]), seen


def test_checkpoint_round_trip_and_run_model(tmp_path):
    from models.generate import load_model, run_model

    model = tiny()
    model.train()
    with torch.no_grad():  # give the input norm non-trivial running statistics
        for _ in range(3):
            model(torch.randn(2, 28, 32) * 40 + 10)
    model.eval()
    path = save_checkpoint(
        tmp_path / "violin.pt", model, model_name="violin", generator_config=model.config,
        feature_config={**MFCC.to_dict(), "fingerprint": MFCC.fingerprint()}, rig=RIG,
    )
    loaded, meta = load_checkpoint(path, expect_feature_fingerprint=MFCC.fingerprint(), expect_bones=BONES)
    assert isinstance(loaded, ViolinNet) and meta["model_name"] == "violin"
    assert loaded.config == model.config
    x = torch.randn(1, 28, 40) * 30
    with torch.no_grad():
        assert torch.allclose(loaded(x), model(x), atol=1e-6)
    lm = load_model(path)
    assert lm.features == MFCC
    feats = extract_features(music(2.0), MFCC)
    poses = run_model(lm.model, feats)
    assert poses.shape == (len(feats), POSE_DIM) and np.isfinite(poses).all()
    np.testing.assert_allclose(np.linalg.norm(poses[:, 3:].reshape(len(poses), -1, 4), axis=-1), 1.0, atol=1e-5)
    with torch.no_grad():  # one forward over the whole song (up to the quaternion sign)
        direct = lm.model(torch.from_numpy(feats.T.copy())[None])[0].T.numpy()
    # run_model pads the song to a multiple of 16 frames by repeating the last one; that
    # padding can only change the hand choice of the last refinement segment.
    keep = (len(feats) - 1) // TINY["refine_segment"] * TINY["refine_segment"] - TINY["refine_segment"] // 2
    q = lambda p: p[:keep, 3:].reshape(keep, -1, 4)  # noqa: E731
    np.testing.assert_allclose(np.abs(np.sum(q(poses) * q(direct), axis=-1)), 1.0, atol=1e-4)


def test_engine_refuses_the_offline_model(tmp_path, capsys):
    from models.features.audio_io import bundled_clip_path
    from realtime import cli
    from realtime.pipeline import build_pipeline

    model = tiny().eval()
    path = save_checkpoint(
        tmp_path / "violin.pt", model, model_name="violin", generator_config=model.config,
        feature_config={**MFCC.to_dict(), "fingerprint": MFCC.fingerprint()}, rig=RIG,
    )
    with pytest.raises(CheckpointError, match="offline-only"):
        build_pipeline(path)
    code = cli.main(["run", "--audio", str(bundled_clip_path()), "--checkpoint", str(path), "--no-ws",
                     "--osc-mode", "plain", "--quiet"])
    err = capsys.readouterr().err
    lines = [line for line in err.strip().splitlines() if line]
    assert code == 2 and len(lines) == 1 and "Traceback" not in err
    assert "offline-only" in lines[0] and "violin" in lines[0] and "performer generate" in lines[0]


# -- learning-rate schedule ---------------------------------------------------------------------


def test_noam_schedule_values():
    d, w = 512, 500
    assert noam_lr(1, d, w) == pytest.approx(d**-0.5 * w**-1.5)
    assert noam_lr(w, d, w) == pytest.approx((d * w) ** -0.5)  # the peak
    assert noam_lr(4 * w, d, w) == pytest.approx(d**-0.5 * (4 * w) ** -0.5)
    lrs = [noam_lr(s, d, w) for s in range(1, 3 * w)]
    assert int(np.argmax(lrs)) + 1 == w
    assert all(a < b for a, b in zip(lrs[: w - 1], lrs[1:w]))  # linear warm-up
    assert all(a > b for a, b in zip(lrs[w - 1 :], lrs[w:]))  # then step**-0.5 decay
    assert noam_lr(10, d, w) == pytest.approx(10 * noam_lr(1, d, w))
    assert learning_rate("constant", 123, 1e-4, None, w) == 1e-4
    assert learning_rate("noam", 7, 1e-4, 128, 100) == noam_lr(7, 128, 100)
    with pytest.raises(ConfigError, match="d_model"):
        learning_rate("noam", 1, 1e-4, None, w)
    with pytest.raises(ConfigError):
        noam_lr(0, d, w)


def test_train_config_schedule_option_defaults_off():
    cfg = TrainConfig()
    assert cfg.lr_schedule == "constant"
    assert TrainConfig.from_dict({"lr_schedule": "noam", "warmup_steps": 100}).warmup_steps == 100
    with pytest.raises(ConfigError, match="lr_schedule"):
        TrainConfig.from_dict({"lr_schedule": "cosine"})
    for bad in (0, -1, 2.5):
        with pytest.raises(ConfigError, match="warmup_steps"):
            TrainConfig.from_dict({"warmup_steps": bad})


@pytest.mark.parametrize("name", ["violin.toml", "lstm_mfcc.toml"])
def test_shipped_configs_build_on_mfcc(name):
    from pathlib import Path

    cfg = TrainConfig.from_toml(Path(__file__).resolve().parents[1] / "configs" / name)
    feats = FeatureConfig(**cfg.features)
    assert feats == MFCC
    model = build_model(cfg.model, {**cfg.model_config, "feature_dim": feats.dim, "pose_dim": POSE_DIM})
    assert model.config.feature_dim == 28
    if cfg.model == "lstm":  # A2B: one LSTM layer, 6-frame time delay, linear layer
        assert model.lstm.num_layers == 1 and model.output_delay == 6 and model.config.input_norm
    else:
        assert cfg.lr_schedule == "noam" and cfg.stage2_steps == 0


def test_lstm_input_norm_is_optional_and_off_by_default():
    from models.networks.baselines import LSTMConfig

    assert not LSTMConfig().input_norm
    plain = build_model("lstm", {"hidden": 8})
    assert not any("norm" in k for k in plain.state_dict())
    normed = build_model("lstm", {"hidden": 8, "feature_dim": 28, "input_norm": True}).eval()
    assert "norm.running_mean" in normed.state_dict()
    x = torch.randn(1, 28, 20) * 300
    with torch.no_grad():
        y = normed(x)
    assert y.shape == (1, POSE_DIM, 20) and torch.isfinite(y).all()
