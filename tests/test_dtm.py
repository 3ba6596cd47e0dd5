""""Dancing to Music" (``dtm``): kinematic offsets, dance units, DU-VAE / MM-GAN, warping, checkpoints."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from models.errors import CheckpointError
from models.evaluation.lee_beats import kinematic_offsets, motion_matrix, offset_strength
from models.networks.checkpoint import build_model, load_checkpoint, save_checkpoint
from models.networks.dtm import (DanceToMusic, DTMConfig, DTMCritics, beat_grid, extract_units, feature_beats,
                                 resample_poses, warp_units)
from models.rig.humanoid import BONES, NUM_BONES
from models.rig.motion import POSE_DIM
from models.timebase import FPS, SAMPLE_RATE
from models.training.dtm import DTMTrainOptions, UnitSet, composition_step, decomposition_step, optimizers

TINY = DTMConfig(feature_dim=9, hidden=32, z_init=4, z_mov=8, z_dance=8, style_hidden=8, style_window=16,
                 noise_dim=4, num_units=2)


@pytest.fixture(autouse=True)
def _one_thread():
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    torch.manual_seed(0)
    yield
    torch.set_num_threads(before)


def rotating_poses(num_frames: int, speed_deg: float = 3.0) -> np.ndarray:
    """Flat poses: root y = frame index, every bone turning about +Y by speed_deg per frame."""
    t = np.arange(num_frames, dtype=np.float64)
    q = Rotation.from_rotvec(np.outer(np.radians(t * speed_deg), [0.0, 1.0, 0.0])).as_quat()
    poses = np.zeros((num_frames, POSE_DIM), np.float32)
    poses[:, 1] = t
    poses[:, 3:] = np.tile(q, (1, NUM_BONES))
    return poses


def angle_deg(q: np.ndarray) -> np.ndarray:
    """Yaw in degrees of xyzw quaternions (N, 4), unwrapped."""
    return np.degrees(np.unwrap(Rotation.from_quat(q).as_euler("yxz")[:, 0]))


# --------------------------------------------------------------------------- kinematic offsets (eqs. 1-2)


def test_offset_strength_is_the_rectified_drop_of_the_motion_matrix():
    m = np.array([[3.0, 0.0], [1.0, 2.0], [1.0, 2.0], [0.0, 0.0]])  # 5 frames, 4 steps
    np.testing.assert_allclose(offset_strength(m), [0.0, 2.0, 0.0, 3.0, 0.0])


def test_motion_matrix_bins_speed_by_direction():
    pos = np.zeros((3, 2, 3))
    pos[1, 0, 2] = 0.1  # joint 0 moves forward (+Z) 0.1 m, then back
    pos[1:, 1, 1] = [0.1, 0.2]  # joint 1 moves up twice
    m = motion_matrix(pos, fps=30)
    assert m.shape == (2, 24)
    assert m[0, 8] == pytest.approx(3.0) and m[0, 16] == pytest.approx(3.0)  # level +Z, up (sector 0)
    assert m[1, 12] == pytest.approx(3.0) and m[1, 16] == pytest.approx(3.0)  # level -Z is sector 4
    assert m.sum() == pytest.approx(12.0)


def test_kinematic_offsets_on_direction_reversals_and_stops():
    t = np.arange(300)
    tri = np.where(t % 30 < 15, t % 30, 30 - t % 30) * 0.02  # reverses every 15 frames
    pos = np.zeros((300, 2, 3))
    pos[:, 0, 0], pos[:, 1, 1] = tri, 0.5 * tri
    np.testing.assert_array_equal(kinematic_offsets(pos), np.arange(15, 300, 15))

    steps = np.array([0.02 if 1 <= f % 15 <= 10 else 0.0 for f in range(300)]).cumsum()  # stop at 15k + 10
    pos = np.zeros((300, 2, 3))
    pos[:, 0, 0], pos[:, 1, 2] = steps, steps
    pos += np.random.default_rng(0).normal(0, 0.001, pos.shape)  # 1 mm mocap jitter
    found = kinematic_offsets(pos)
    want = np.arange(10, 300, 15)
    assert len(found) == len(want) and np.abs(found - want).max() <= 1
    assert len(kinematic_offsets(np.zeros((60, 3, 3)))) == 0  # motionless: no beats


# --------------------------------------------------------------------------- beats, units, warping


def test_feature_beats_match_librosa_beats_on_the_audio():
    import librosa

    from models.evaluation.beats import music_beats
    from models.features.spectral import FeatureConfig, extract_features

    clicks = librosa.clicks(times=np.arange(0.5, 12.0, 0.5), sr=SAMPLE_RATE, length=12 * SAMPLE_RATE)
    ours = feature_beats(extract_features(clicks.astype(np.float32), FeatureConfig()), 1.0)
    ref = music_beats(clicks, SAMPLE_RATE, FPS) - 1  # a click in hop f is shown by pose f - 1
    assert len(ours) >= 20
    nearest = np.min(np.abs(ours[:, None] - ref[None, :]), axis=1)
    assert np.median(nearest) <= 0.5 and nearest.max() <= 1


def test_beat_grid_covers_the_song_with_whole_units():
    g = beat_grid(np.array([10.0, 25.0, 40.0]), 100, 4)
    assert g[0] <= 0 and g[-1] >= 99 and (len(g) - 1) % 4 == 0
    np.testing.assert_allclose(np.diff(g), 15.0)
    assert 10.0 in g and 40.0 in g
    g = beat_grid(np.zeros(0), 1, 4)  # no beats, one frame: 120 BPM fallback, one unit
    np.testing.assert_allclose(g, [0, 15, 30, 45, 60])


def test_units_are_time_normalised_between_beats():
    poses = rotating_poses(200)
    beats = np.array([3.0, 13.0, 28.0, 40.0, 60.0, 70.0, 90.5, 100.0, 199.5])
    units, starts = extract_units(poses, beats, 32, 4)
    np.testing.assert_array_equal(starts, [0, 1, 2, 3])  # unit 4 would end at 199.5 > T - 1
    for u, s in zip(units, starts):
        np.testing.assert_allclose(u[::8, 1], beats[s : s + 4], atol=1e-3)  # root y = time: beats at 0, 8, 16, 24
        np.testing.assert_allclose(u[4, 1], 0.5 * (beats[s] + beats[s + 1]), atol=1e-3)
        np.testing.assert_allclose(angle_deg(u[:, 3:7]), 3.0 * u[:, 1], atol=1e-2)  # rotation follows time
        assert np.all(u[:, 6] >= 0)  # hemisphere w >= 0
    valid = np.ones(200, bool)
    valid[80] = False
    _, starts = extract_units(poses, beats, 32, 4, valid)
    np.testing.assert_array_equal(starts, [0, 1])  # units 2 and 3 cover frame 80


def test_warping_puts_unit_beats_on_music_beats():
    units = rotating_poses(64, 5.0)  # two units of 32 frames, 8 beats + the closing one
    music = np.array([0.0, 11.0, 20.0, 35.0, 41.0, 55.0, 63.0, 80.0, 90.0])
    out = warp_units(units, music, 91, 8)
    assert out.shape == (91, POSE_DIM)
    for k, b in enumerate(music[:-1]):
        np.testing.assert_allclose(out[int(b), 1], 8 * k, atol=1e-4)
        dot = np.abs(np.sum(out[int(b), 3:7] * units[8 * k, 3:7]))
        assert dot == pytest.approx(1.0, abs=1e-5)
    # between beats the unit time runs linearly: halfway from beat 2 (20) to beat 3 (35)
    np.testing.assert_allclose(out[27, 1], 16 + 8 * 7 / 15, atol=1e-3)
    np.testing.assert_allclose(np.linalg.norm(out[:, 3:].reshape(91, -1, 4), axis=-1), 1.0, atol=1e-5)


def test_resample_poses_interpolates_rotations_on_the_sphere():
    poses = rotating_poses(5, 40.0)
    mid = resample_poses(poses, np.array([1.5]))
    assert angle_deg(mid[:, 3:7])[0] == pytest.approx(60.0, abs=0.5)


# --------------------------------------------------------------------------- networks


def synthetic_units(n: int, cfg: DTMConfig, rng: np.random.Generator) -> np.ndarray:
    """Units of smooth random rotations (per-unit sinusoid about a random axis per bone)."""
    t = np.arange(cfg.unit_frames)[None, :, None] / cfg.unit_frames
    amp = rng.uniform(0.2, 0.8, (n, 1, NUM_BONES))
    freq = rng.integers(1, 3, (n, 1, NUM_BONES))
    ang = amp * np.sin(2 * np.pi * freq * t)
    axes = rng.normal(size=(n, 1, NUM_BONES, 3))
    axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
    q = Rotation.from_rotvec((ang[..., None] * axes).reshape(-1, 3)).as_quat().reshape(n, cfg.unit_frames, -1)
    root = np.zeros((n, cfg.unit_frames, 3))
    root[..., 1] = 0.9 + 0.05 * np.sin(2 * np.pi * t[..., 0])
    return np.concatenate([root, q], -1).astype(np.float32)


def test_vae_and_gan_shapes():
    model, critics = DanceToMusic(TINY), DTMCritics(TINY)
    units = torch.from_numpy(synthetic_units(5, TINY, np.random.default_rng(0)))
    out = model.decompose(model.norm_pose(units))
    assert out["recon"].shape == (5, 32, POSE_DIM)
    assert out["z_init"].shape == (5, 4) and out["z_mov"].shape == (5, 8)
    assert model.reconstruct(units).shape == (5, 32, POSE_DIM)
    feats = torch.rand(2, TINY.feature_dim, 40)
    assert model(feats).shape == (2, POSE_DIM, 40)  # the project contract: (B, D, T) -> (B, POSE_DIM, T)
    style, logits = model.style(torch.randn(5, TINY.style_window, TINY.feature_dim))
    assert style.shape == (5, 8) and logits.shape == (5, 3)
    comp = model.compose(torch.randn(5, 2, 8), torch.randn(5, 2, 8), style)
    assert comp["rec_mu"].shape == comp["fake_mu"].shape == (5, 2, 8)
    assert comp["z_dance"].shape == comp["fake_dance"].shape == (5, 8)
    assert critics.movement_logit(comp["fake_mu"], comp["fake_logvar"], style).shape == (5,)
    assert critics.dance_logit(comp["dance_mu"], comp["dance_logvar"]).shape == (5,)
    assert critics.regressor(comp["z_dance"]).shape == (5, 8)
    units_out = model.dance_units(style[:2], 3, seed=0)
    assert units_out.shape == (96, POSE_DIM)


def tiny_data(rng: np.random.Generator) -> UnitSet:
    units = synthetic_units(64, TINY, rng)
    seqs = rng.integers(0, 64, (48, TINY.num_units))
    labels = rng.integers(0, 3, 48)
    windows = (rng.normal(size=(48, TINY.style_window, TINY.feature_dim)) + labels[:, None, None]).astype(np.float32)
    return UnitSet(units, seqs, windows, labels)


def test_tiny_model_trains_both_phases():
    rng = np.random.default_rng(0)
    data = tiny_data(rng)
    model, critics = DanceToMusic(TINY), DTMCritics(TINY)
    opts = DTMTrainOptions(shift_m=0.3)
    from models.training.dtm import set_statistics

    set_statistics(model, data, [data.windows.reshape(-1, TINY.feature_dim)], opts, rng)
    opt = optimizers(model, critics, 3e-3, 0.5, opts)
    first, last = [], []
    for step in range(60):
        i = rng.choice(64, 16, replace=False)
        s = rng.choice(48, 16, replace=False)
        row = decomposition_step(model, data.units[i], data.windows[s], data.labels[s], opts, min(1, step / 20), rng,
                                 opt["vae"], opt["style"])
        assert all(np.isfinite(v) for v in row.values())
        (first if step < 5 else last if step >= 55 else []).append(row)
    assert np.mean([r["loss_recon"] for r in last]) < 0.95 * np.mean([r["loss_recon"] for r in first])
    assert np.mean([r["loss_cross"] for r in last]) < 0.95 * np.mean([r["loss_cross"] for r in first])
    assert np.mean([r["loss_style"] for r in last]) < np.mean([r["loss_style"] for r in first])
    first, last = [], []
    for step in range(40):
        s = rng.choice(48, 16, replace=False)
        row = composition_step(model, critics, data.units[data.sequences[s]], data.windows[s], opts,
                               opt["gen"], opt["critic"])
        assert all(np.isfinite(v) for v in row.values())
        (first if step < 5 else last if step >= 35 else []).append(row)
    assert np.mean([r["loss_zmov"] for r in last]) < np.mean([r["loss_zmov"] for r in first])


def test_generation_on_short_features_is_seedable_and_valid():
    model = DanceToMusic(TINY).eval()
    rng = np.random.default_rng(1)
    feats = rng.normal(size=(120, 9)).astype(np.float32)
    feats[:, -1] = np.where(np.arange(120) % 12 == 0, 5.0, 0.1)  # onsets every 0.4 s
    a, b, c = model.generate(feats, seed=3), model.generate(feats, seed=3), model.generate(feats, seed=4)
    assert a.shape == (120, POSE_DIM) and a.dtype == np.float32 and np.isfinite(a).all()
    np.testing.assert_allclose(np.linalg.norm(a[:, 3:].reshape(120, -1, 4), axis=-1), 1.0, atol=1e-5)
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).max() > 1e-3
    assert np.all(a[:, [0, 2]] == 0)  # canonical: no horizontal root travel
    for t in (1, 7):  # shorter than one unit, no beats found
        assert model.generate(feats[:t], seed=0).shape == (t, POSE_DIM)
    from models.generate import run_model

    np.testing.assert_array_equal(run_model(model, feats, seed=3), a)


def _save(tmp_path, model: DanceToMusic):
    from models.features.spectral import FeatureConfig

    fcfg = FeatureConfig(n_mels=8)
    return save_checkpoint(tmp_path / "dtm.pt", model, model_name="dtm", generator_config=model.config,
                           feature_config={**fcfg.to_dict(), "fingerprint": fcfg.fingerprint()},
                           rig={"bones": list(BONES), "pose_dim": POSE_DIM})


def test_checkpoint_round_trip_through_build_model(tmp_path):
    model = build_model("dtm", TINY.to_dict())
    assert isinstance(model, DanceToMusic) and model.config == TINY
    with torch.no_grad():
        model.pose_std.fill_(0.5)
    path = _save(tmp_path, model)
    loaded, meta = load_checkpoint(path, expect_bones=BONES)
    assert meta["model_name"] == "dtm" and isinstance(loaded, DanceToMusic)
    for k, v in model.state_dict().items():
        assert torch.equal(v, loaded.state_dict()[k]), k
    feats = np.abs(np.random.default_rng(2).normal(size=(90, 9))).astype(np.float32)
    np.testing.assert_array_equal(model.generate(feats, seed=1), loaded.generate(feats, seed=1))


def test_engine_refuses_the_offline_model_in_one_line(tmp_path, capsys):
    from models.features.audio_io import bundled_clip_path
    from realtime import cli
    from realtime.pipeline import build_pipeline

    path = _save(tmp_path, build_model("dtm", TINY.to_dict()))
    with pytest.raises(CheckpointError, match="offline-only"):
        build_pipeline(path)
    code = cli.main(["run", "--audio", str(bundled_clip_path()), "--checkpoint", str(path), "--no-ws",
                     "--osc-mode", "plain", "--quiet"])
    err = [line for line in capsys.readouterr().err.splitlines() if line]
    assert code == 2 and len(err) == 1 and "offline-only" in err[0] and "performer generate" in err[0]


def test_multimodality_metric():
    from models.evaluation.metrics import multimodality

    same = [np.zeros((3, 4)), np.ones((2, 4))]
    assert multimodality(same) == 0.0
    spread = [np.array([[0.0, 0.0], [3.0, 4.0]]), np.array([[0.0, 0.0], [0.0, 1.0], [0.0, 2.0]])]
    assert multimodality(spread) == pytest.approx((5.0 + (1 + 2 + 1) / 3) / 2)


def test_evaluate_reports_multimodality_only_for_stochastic_models(tmp_path):
    from types import SimpleNamespace

    from models.evaluation.classifier import train_style_classifier
    from models.evaluation.evaluate import EvalOptions, classifier_windows, model_multimodality

    rng = np.random.default_rng(3)
    feats = np.abs(rng.normal(size=(130, 9))).astype(np.float32)
    clips = [SimpleNamespace(features=feats, name="DANCE_C_1")]
    model = DanceToMusic(TINY).eval()
    with torch.no_grad():  # a decoder that moves, so generations differ visibly
        model.pose_std.fill_(0.3)
    from models.evaluation.evaluate import positions

    windows = classifier_windows([positions(model.generate(feats, seed=s)) for s in range(2)])
    classifier = train_style_classifier(windows, np.arange(len(windows)) % 2, epochs=1, seed=0, class_names=["C", "R"])
    opts = EvalOptions(multimodality_samples=3, progress=False)
    lm = SimpleNamespace(model=model, path=tmp_path / "dtm.pt")
    assert model_multimodality(lm, clips, tmp_path, classifier, opts) > 0
    assert model_multimodality(lm, clips, tmp_path, classifier, EvalOptions(multimodality_samples=1)) is None
    deterministic = SimpleNamespace(model=torch.nn.Identity(), path=tmp_path / "x.pt")
    assert model_multimodality(deterministic, clips, tmp_path, classifier, opts) is None
