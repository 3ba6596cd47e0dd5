"""Training: the loop (models/training/train.py) on a tiny synthetic DWM dataset, its losses,
its config, the tempo-augmented corpus, canonical poses and ``performer train``.

The synthetic dances are real rig motions (FK of smooth joint rotations, exported in the
DWM joint layout) over a tone with clicks and one silent second, so retargeting, the
corpus, the features and the loop all run as on the shared data, in seconds.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import librosa
import numpy as np
import pytest
import soundfile as sf
import torch
from _dwm_synth import write_dance
from scipy.spatial.transform import Rotation

from models.errors import ConfigError, PerformerError
from models.features.audio_io import load_audio
from models.features.spectral import FeatureConfig, extract_features
from models.generate import load_model, run_model
from models.networks.blocks import randomize_batchnorm
from models.networks.checkpoint import build_model, load_checkpoint
from models.rig.humanoid import BONE_INDEX, BONES, END_EFFECTORS, NUM_BONES
from models.rig.joint_map import to_dwm_positions
from models.rig.kinematics import fk
from models.rig.motion import POSE_DIM, Motion
from models.rig.skeleton import load_default_skeleton
from models.timebase import FPS, SAMPLE_RATE
from models.training import losses
from models.training import train as train_module
from models.data.canonical import canonicalize, heading
from models.training.config import TrainConfig
from models.data.corpus import build_corpus
from models.training.train import LOG_FIELDS, train
from realtime import cli

torch.set_num_threads(1)

DANCES = ("DANCE_W_1", "DANCE_W_2", "DANCE_W_3")  # split: 2 train, 1 val
START, END = 25, 275  # the dance covers music frames 25..275 at 25 fps: 1 s .. 11 s
AUDIO_S = 12.0
SILENT_S = (6.0, 7.0)  # a silent second in the song: a landmark for feature alignment
FEATURES = {"n_mels": 16}
BASE = {  # a tiny causal U-Net, 40 regression steps
    "model": "causal",
    "model_config": {"channels": [8, 8, 8, 8, 8]},
    "features": FEATURES,
    "seed": 0,
    "segment": 32,
    "batch_size": 4,
    "lr": 3e-3,
    "beta1": 0.9,
    "stage1_steps": 40,
    "stage2_steps": 0,
    "tempos": [1.0],
    "eval_every": 10,
    "threads": 1,
}
LOSS_KEYS = ("loss_rot", "loss_fk")


# -- synthetic data ---------------------------------------------------------------------------


def song(seconds: float = AUDIO_S) -> np.ndarray:
    """A 220 Hz tone with a click every 0.5 s at 22050 Hz, silent over SILENT_S."""
    t = np.arange(int(seconds * SAMPLE_RATE)) / SAMPLE_RATE
    audio = 0.2 * np.sin(2 * np.pi * 220 * t)
    audio[(t % 0.5) < 0.01] += 0.6
    audio[(t >= SILENT_S[0]) & (t < SILENT_S[1])] = 0.0
    return audio.astype(np.float32)


def dance_motion(n: int, times_s: np.ndarray, seed: int) -> Motion:
    """A smooth rig motion (every bone swinging at 0.3-1.2 Hz) at the given times."""
    rng = np.random.default_rng(seed)
    freq = rng.uniform(0.3, 1.2, (1, NUM_BONES, 3))
    phase = rng.uniform(0, 2 * np.pi, (1, NUM_BONES, 3))
    rotvec = 0.4 * np.sin(2 * np.pi * freq * times_s[:, None, None] + phase)
    for name in ("LeftShoulder", "RightShoulder", "LeftToes", "RightToes"):  # not expressible in DWM joints
        rotvec[:, BONE_INDEX[name]] = 0.0
    for name in ("Chest", "Head"):
        rotvec[:, BONE_INDEX[name], [0, 2]] = 0.0
    quats = Rotation.from_rotvec(rotvec.reshape(-1, 3)).as_quat().reshape(n, NUM_BONES, 4)
    root = np.stack([0.3 * np.sin(times_s), 0.9 + 0.05 * np.cos(2 * np.pi * times_s), 0.1 * times_s], axis=1)
    return Motion(root_pos=root, rotations=quats)


def write_synthetic_dwm(root: Path) -> Path:
    """DANCES in DWM format: mocap at 25 fps over music frames START..END, the song of :func:`song`."""
    n = END - START + 1
    times = (START + np.arange(n) * (END - START) / (n - 1)) / 25.0
    skeleton = load_default_skeleton()
    for i, name in enumerate(DANCES):
        joints_m = to_dwm_positions(fk(dance_motion(n, times, seed=i), skeleton))
        d = write_dance(root, name, joints_m * 100.0, np.zeros((n, 3)), START, END, audio_s=AUDIO_S)
        sf.write(d / "audio.mp3", song(), SAMPLE_RATE, format="WAV")
    return root


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> tuple[Path, Path]:
    """(dataset root, corpus cache shared by every run of this module)."""
    tmp = tmp_path_factory.mktemp("train-data")
    return write_synthetic_dwm(tmp / "dwm"), tmp / "cache"


def run_train(data, out: Path, **overrides) -> Path:
    root, cache = data
    cfg = TrainConfig.from_dict({**BASE, **overrides})
    train(cfg, root, out, cache_dir=cache, progress=False)
    return out


def read_log(out: Path) -> list[dict[str, str]]:
    with open(out / "log.csv") as fh:
        return list(csv.DictReader(fh))


def losses_of(rows: list[dict[str, str]]) -> list[tuple[str, ...]]:
    """Every logged value but the wall-clock throughput, per row."""
    return [tuple(r[k] for k in LOG_FIELDS if k != "frames_per_s") for r in rows]


def weights(path: Path) -> dict[str, torch.Tensor]:
    return load_checkpoint(path)[0].state_dict()


def same_weights(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


@pytest.fixture(scope="module")
def run_a(data, tmp_path_factory) -> Path:
    """The reference run: BASE, seed 0, 40 uninterrupted steps."""
    return run_train(data, tmp_path_factory.mktemp("run-a"))


# -- 1. the loop ------------------------------------------------------------------------------


def test_loss_falls_and_the_run_writes_usable_outputs(run_a, data, tmp_path):
    rows = read_log(run_a)
    assert [int(r["step"]) for r in rows] == list(range(1, 41))
    assert {r["stage"] for r in rows} == {"1"}
    total = np.array([[float(r[k]) for k in LOSS_KEYS] for r in rows]).sum(axis=1)
    assert np.isfinite(total).all()
    first, last = total[:5].mean(), total[-5:].mean()
    assert last < 0.6 * first, (first, last)
    evals = [r for r in rows if r["val_rot_l1"]]
    assert [int(r["step"]) for r in evals] == [10, 20, 30, 40]
    assert all(np.isfinite(float(r[k])) for r in evals for k in ("val_rot_l1", "val_eff_l1_m", "val_energy"))
    assert float(evals[-1]["val_rot_l1"]) < float(evals[0]["val_rot_l1"])

    for name in ("best.pt", "last.pt", "state.pt", "losses.png", "config.json"):
        assert (run_a / name).is_file() and (run_a / name).stat().st_size > 0, name
    assert (run_a / "losses.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    conf = json.loads((run_a / "config.json").read_text())
    assert conf["train"] == TrainConfig.from_dict(BASE).to_dict()
    assert len(conf["train_dances"]) == 2 and len(conf["val_dances"]) == 1
    assert sorted(conf["train_dances"] + conf["val_dances"]) == list(DANCES)

    fcfg = FeatureConfig(**FEATURES)
    best, meta = load_checkpoint(run_a / "best.pt", expect_feature_fingerprint=fcfg.fingerprint(), expect_bones=BONES)
    last, last_meta = load_checkpoint(run_a / "last.pt")
    assert meta["model_name"] == "causal" and last_meta["extra"]["step"] == 40
    best_val = min(float(r["val_rot_l1"]) for r in evals)
    assert meta["extra"]["val_rot_l1"] == pytest.approx(best_val) and meta["extra"]["val_dances"] == conf["val_dances"]
    loaded = load_model(run_a / "best.pt")
    assert loaded.features.fingerprint() == fcfg.fingerprint()
    feats = np.random.default_rng(0).normal(size=(50, fcfg.dim)).astype(np.float32)
    poses = run_model(loaded.model, feats)
    assert poses.shape == (50, POSE_DIM) and np.isfinite(poses).all()

    wav = tmp_path / "song.wav"
    sf.write(wav, song(3.0), SAMPLE_RATE)
    code = cli.main(["generate", str(wav), "--checkpoint", str(run_a / "last.pt"), "--out", str(tmp_path / "x.npz")])
    assert code == 0 and (tmp_path / "x.npz").is_file()


# -- 2. stage 2 -------------------------------------------------------------------------------


GAN = {"segment": 128, "batch_size": 2, "stage1_steps": 2, "stage2_steps": 4, "eval_every": 2, "disc_width": 8}


@pytest.fixture(scope="module")
def gan_run(data, tmp_path_factory) -> Path:
    """2 regression steps, then 4 with the GAN; state saved every 2 steps."""
    return run_train(data, tmp_path_factory.mktemp("gan"), **GAN)


def test_stage_two_trains_the_discriminator(gan_run):
    rows = read_log(gan_run)
    assert [r["stage"] for r in rows] == ["1"] * 2 + ["2"] * 4
    for r in rows[:2]:
        assert r["loss_d"] == "" and r["loss_g_gan"] == ""
    for r in rows[2:]:
        assert float(r["loss_d"]) > 0 and float(r["loss_g_gan"]) > 0
    assert len({r["loss_d"] for r in rows[2:]}) == 4  # the discriminator is learning


def test_run_interrupted_in_stage_two_resumes_discriminator_and_all(gan_run, data, tmp_path, monkeypatch):
    """Killed during step 6: resumed from step 4 with the trained discriminator and its optimiser."""
    out = tmp_path / "gan-crash"
    real = losses.g_gan_loss
    calls = {"n": 0}

    def crashing(maps):
        calls["n"] += 1
        if calls["n"] == 4:  # the generator's GAN loss of step 6 (stage 2 starts at step 3)
            raise KeyboardInterrupt
        return real(maps)

    monkeypatch.setattr(losses, "g_gan_loss", crashing)
    with pytest.raises(KeyboardInterrupt):
        run_train(data, out, **GAN)
    assert torch.load(out / "state.pt", weights_only=False)["step"] == 4
    monkeypatch.setattr(losses, "g_gan_loss", real)
    run_train(data, out, **GAN)
    assert losses_of(read_log(out)) == losses_of(read_log(gan_run))
    assert same_weights(weights(out / "last.pt"), weights(gan_run / "last.pt"))
    a, b = (torch.load(d / "state.pt", weights_only=False) for d in (out, gan_run))
    assert same_weights(a["disc"], b["disc"])


def test_gan_stage_with_too_short_segments_fails_before_training(data, tmp_path):
    """The discriminator needs 128 frames; a shorter segment must not waste stage 1 first."""
    with pytest.raises(ConfigError, match=r"stage 2 \(GAN\) needs segment - output delay >= 128 frames"):
        run_train(data, tmp_path / "short", segment=32, stage1_steps=5, stage2_steps=5, eval_every=5)
    assert not (tmp_path / "short" / "state.pt").exists()


# -- 3. determinism ---------------------------------------------------------------------------


def test_same_seed_same_run_other_seed_differs(run_a, data, tmp_path):
    again = run_train(data, tmp_path / "again")
    assert losses_of(read_log(again)) == losses_of(read_log(run_a))
    assert same_weights(weights(again / "last.pt"), weights(run_a / "last.pt"))
    other = run_train(data, tmp_path / "seed1", seed=1, stage1_steps=10)  # 10 steps tell
    assert all(x != y for x, y in zip(losses_of(read_log(other)), losses_of(read_log(run_a))[:10]))
    first = run_train(data, tmp_path / "seed0", stage1_steps=10)
    assert losses_of(read_log(first)) == losses_of(read_log(run_a))[:10]
    assert not same_weights(weights(other / "last.pt"), weights(first / "last.pt"))


def crash_on_sample(monkeypatch, n: int):
    """Make the n-th training batch draw raise KeyboardInterrupt (a killed run); returns the undo."""
    sample = train_module.SegmentSampler.sample
    calls = {"n": 0}

    def crashing(self, batch_size):
        calls["n"] += 1
        if calls["n"] == n:
            raise KeyboardInterrupt
        return sample(self, batch_size)

    monkeypatch.setattr(train_module.SegmentSampler, "sample", crashing)
    return lambda: monkeypatch.setattr(train_module.SegmentSampler, "sample", sample)


def test_ema_run_saves_the_moving_average_and_resumes_exactly(run_a, data, tmp_path, monkeypatch):
    """ema_decay: best.pt/last.pt hold the averaged weights (kept in state.pt beside the raw
    ones), validation scores them, and an interrupted run resumes to the same average."""
    cfg = {"ema_decay": 0.9, "model_config": {"channels": [8, 8, 8, 8, 8], "dropout": 0.2}, "stage1_steps": 20}
    out = run_train(data, tmp_path / "ema", **cfg)
    st = torch.load(out / "state.pt", weights_only=False)
    ema = {k.removeprefix("module."): v for k, v in st["ema"].items() if k.startswith("module.")}
    last = weights(out / "last.pt")
    assert same_weights(last, ema)
    assert not same_weights(last, st["model"])  # the average lags the raw weights
    plain = read_log(run_train(data, tmp_path / "plain", stage1_steps=20))
    rows = read_log(out)
    assert [r["val_rot_l1"] for r in rows if r["val_rot_l1"]] != [r["val_rot_l1"] for r in plain if r["val_rot_l1"]]
    assert load_checkpoint(out / "last.pt")[1]["model_config"]["dropout"] == 0.2

    crash = tmp_path / "ema-crash"
    undo = crash_on_sample(monkeypatch, 15)  # state.pt holds step 10
    with pytest.raises(KeyboardInterrupt):
        run_train(data, crash, **cfg)
    undo()
    run_train(data, crash, **cfg)
    assert losses_of(read_log(crash)) == losses_of(rows)
    assert same_weights(weights(crash / "last.pt"), last)


def test_ema_decay_is_validated():
    for bad in (-0.5, 1.0):
        with pytest.raises(ConfigError, match="ema_decay"):
            TrainConfig.from_dict({**BASE, "ema_decay": bad})


# -- 4. resume --------------------------------------------------------------------------------


def test_interrupted_run_resumes_to_the_uninterrupted_result(run_a, data, tmp_path, monkeypatch, capsys):
    """Killed during step 26: state.pt holds step 20; rows 21-25 are dropped and redone."""
    out = tmp_path / "crash"
    undo = crash_on_sample(monkeypatch, 26)
    with pytest.raises(KeyboardInterrupt):
        run_train(data, out)
    assert len(read_log(out)) == 25 and torch.load(out / "state.pt", weights_only=False)["step"] == 20
    undo()
    run_train(data, out)
    assert "resuming from step 20" in capsys.readouterr().out
    assert losses_of(read_log(out)) == losses_of(read_log(run_a))
    assert same_weights(weights(out / "last.pt"), weights(run_a / "last.pt"))
    assert same_weights(weights(out / "best.pt"), weights(run_a / "best.pt"))


def write_toml(path: Path, cfg: dict) -> Path:
    """A TOML file of a flat config with [model_config] and [features] tables."""
    def value(v):
        return json.dumps(v) if not isinstance(v, bool) else str(v).lower()

    lines = [f"{k} = {value(v)}" for k, v in cfg.items() if not isinstance(v, dict)]
    for table in ("model_config", "features"):
        lines += [f"[{table}]"] + [f"{k} = {value(v)}" for k, v in cfg.get(table, {}).items()]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_cli_run_with_fewer_steps_then_full_steps_matches_uninterrupted(run_a, data, tmp_path, capsys):
    """``performer train --steps 20 0`` then the same command with ``--steps 40 0`` resumes at 20."""
    root, cache = data
    conf = write_toml(tmp_path / "tiny.toml", BASE)
    out = tmp_path / "cli"
    args = ["train", "--config", str(conf), "--data", str(root), "--out", str(out), "--cache", str(cache), "--quiet"]
    assert cli.main([*args, "--steps", "20", "0"]) == 0
    assert len(read_log(out)) == 20
    assert cli.main([*args, "--steps", "40", "0"]) == 0
    printed = capsys.readouterr().out
    assert "resuming from step 20" in printed and f"best checkpoint: {out / 'best.pt'}" in printed
    assert losses_of(read_log(out)) == losses_of(read_log(run_a))
    assert same_weights(weights(out / "last.pt"), weights(run_a / "last.pt"))


# -- 5. losses --------------------------------------------------------------------------------


def random_poses(b: int, t: int, seed: int) -> torch.Tensor:
    """(B, POSE_DIM, T) poses with unit quaternions and a root height near 0.9 m."""
    g = torch.Generator().manual_seed(seed)
    root = torch.randn(b, 3, t, generator=g) * 0.1 + torch.tensor([0.0, 0.9, 0.0])[None, :, None]
    q = torch.randn(b, NUM_BONES, 4, t, generator=g)
    q = q / q.norm(dim=2, keepdim=True)
    return torch.cat([root, q.reshape(b, NUM_BONES * 4, t)], dim=1)


@pytest.fixture(scope="module")
def offsets() -> torch.Tensor:
    return torch.from_numpy(load_default_skeleton().offsets).float()


def all_losses(pred, true, offsets) -> dict[str, torch.Tensor]:
    return {"rotation_l1": losses.rotation_l1(pred, true), "effector_l1": losses.effector_l1(pred, true, offsets),
            "velocity_l1": losses.velocity_l1(pred, true, offsets),
            "acceleration_l1": losses.acceleration_l1(pred, true, offsets)}


def test_losses_are_zero_for_identical_poses_and_grow_with_a_perturbation(offsets):
    true = random_poses(2, 16, seed=0)
    noise = torch.randn(true.shape, generator=torch.Generator().manual_seed(1))
    for name, v in all_losses(true, true.clone(), offsets).items():
        assert float(v) == pytest.approx(0.0, abs=1e-6), name
    prev = None
    for scale in (0.01, 0.05, 0.2):
        cur = {k: float(v) for k, v in all_losses(true + scale * noise, true, offsets).items()}
        assert all(v > 0 for v in cur.values()), (scale, cur)
        if prev:
            assert all(cur[k] > prev[k] for k in cur), (scale, cur, prev)
        prev = cur


def test_rotation_l1_ignores_quaternion_sign_and_counts_root_height(offsets):
    true = random_poses(1, 8, seed=2)
    flipped = true.clone()
    flipped[:, 3:] = -flipped[:, 3:]  # q and -q: the same rotations
    assert float(losses.rotation_l1(flipped, true)) == pytest.approx(0.0, abs=1e-6)
    assert float(losses.effector_l1(flipped, true, offsets)) == pytest.approx(0.0, abs=1e-5)
    higher = true.clone()
    higher[:, 1] += 0.1  # root height +10 cm
    assert float(losses.rotation_l1(higher, true)) == pytest.approx(0.1, abs=1e-6)
    sideways = true.clone()
    sideways[:, 0] += 0.1  # root x is not a rotation-loss target (canonical poses have x = z = 0)
    assert float(losses.rotation_l1(sideways, true)) == pytest.approx(0.0, abs=1e-6)


def test_effector_positions_are_the_rig_forward_kinematics(offsets):
    pose = random_poses(1, 6, seed=3)
    got = losses.effector_positions(pose, offsets)[0].numpy()
    x = pose[0].T.double().numpy()
    motion = Motion(root_pos=x[:, :3], rotations=x[:, 3:].reshape(-1, NUM_BONES, 4))
    want = fk(motion, load_default_skeleton())[:, [BONE_INDEX[b] for b in END_EFFECTORS]]
    assert got.shape == (6, len(END_EFFECTORS), 3)
    np.testing.assert_allclose(got, want, atol=1e-5)


def test_effector_losses_pass_gradients_through_the_fk(offsets):
    true = random_poses(2, 16, seed=4)
    pred = (true + 0.05 * torch.randn(true.shape, generator=torch.Generator().manual_seed(5))).requires_grad_(True)
    for name in ("effector_l1", "velocity_l1", "acceleration_l1"):
        pred.grad = None
        getattr(losses, name)(pred, true, offsets).backward()
        g = pred.grad
        assert torch.isfinite(g).all(), name
        assert (g[:, [0, 2]].abs().sum(dim=(0, 2)) > 0).all(), name  # root x, z: they reach the loss only by FK
        per_bone = g[:, 3:].reshape(2, NUM_BONES, 4, 16).abs().sum(dim=(0, 2, 3))
        assert (per_bone[[BONE_INDEX[b] for b in ("Hips", "LeftUpperArm", "RightUpperLeg", "Neck")]] > 0).all(), name
    pred.grad = None
    losses.effector_l1(pred, true, offsets).backward()
    per_bone = pred.grad[:, 3:].reshape(2, NUM_BONES, 4, 16).abs().sum(dim=(0, 2, 3))
    assert per_bone[BONE_INDEX["LeftToes"]] == 0 and per_bone[BONE_INDEX["RightToes"]] == 0  # below the feet


def test_gan_losses_have_the_least_squares_optimum():
    ones, zeros = [torch.ones(2, 5)] * 4, [torch.zeros(2, 5)] * 4
    assert float(losses.d_loss(ones, zeros)) == 0.0 and float(losses.d_loss(zeros, ones)) == 1.0
    assert float(losses.g_gan_loss(ones)) == 0.0 and float(losses.g_gan_loss(zeros)) == 1.0


# -- 6. config --------------------------------------------------------------------------------


@pytest.mark.parametrize("text, message", [
    ("stage1_steps = 10\nbogus = 1\n", "unknown training config key(s) ['bogus']"),
    ("segment = 120\n", "segment must be a multiple of 16"),
    ("segment = \"128\"\n", "segment must be int, got str"),
    ("lr = \"fast\"\n", "lr must be float"),
    ("exclude_unverified = 1\n", "exclude_unverified must be bool"),
    ("tempos = [1.0, \"x\"]\n", "tempos must be a list of numbers"),
    ("tempos = [3.0]\n", "tempos must be factors in [0.5, 2]"),
    ("stage1_steps = 0\nstage2_steps = 0\n", "must be at least 1"),
    ("batch_size = 0\n", "batch_size must be a positive integer"),
    ("lr_schedule = \"cosine\"\n", "lr_schedule must be one of"),
    ("model = \"casual\"\n", "model must be one of ["),
    ("train_only = \"head\"\n", "train_only must be list"),
    ("train_only = [\"head\", 3]\n", "train_only must be a list of parameter-name prefixes"),
    ("segment = [\n", "not valid TOML"),
])
def test_bad_config_files_are_refused_naming_the_file(tmp_path, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as exc:
        TrainConfig.from_toml(path)
    assert str(exc.value).startswith(f"{path}: ") and message in str(exc.value)


def test_config_from_toml_reads_every_field_and_missing_file_is_an_error(tmp_path):
    cfg = TrainConfig.from_toml(write_toml(tmp_path / "ok.toml", BASE))
    assert cfg.to_dict() == TrainConfig.from_dict(BASE).to_dict() == {**TrainConfig().to_dict(), **BASE}
    assert cfg.total_steps == 40 and cfg.model_config == {"channels": [8, 8, 8, 8, 8]}
    with pytest.raises(ConfigError, match="training config not found"):
        TrainConfig.from_toml(tmp_path / "missing.toml")
    with pytest.raises(ConfigError, match="unknown training config key") as exc:
        TrainConfig.from_dict({"segmnet": 64})
    assert exc.value.source is None
    assert TrainConfig.from_dict({"lr": 1}).lr == 1  # an integer is a valid float


def test_cli_bad_config_prints_one_line_and_exits_2(data, tmp_path, capsys):
    root, cache = data
    bad = tmp_path / "bad.toml"
    bad.write_text("segment = 120\n")
    for extra, message in (
        (["--config", str(bad)], f"{bad}: segment must be a multiple of 16"),
        (["--config", str(tmp_path / "none.toml")], "training config not found"),
        (["--config", str(write_toml(tmp_path / "ok.toml", BASE)), "--steps", "0", "0"], "must be at least 1"),
        (["--model", "nope"], "model must be one of ["),
    ):
        code = cli.main(["train", *extra, "--data", str(root), "--out", str(tmp_path / "o"),
                         "--cache", str(tmp_path / "cache"), "--quiet"])
        err = capsys.readouterr().err
        lines = err.strip().splitlines()
        assert code == 2 and len(lines) == 1 and lines[0].startswith("performer train: error: "), err
        assert message in lines[0], err
    assert not (tmp_path / "o").exists() and not (tmp_path / "cache").exists()  # refused before any data work


# -- 7. corpus and tempo augmentation ---------------------------------------------------------


def sound_returns(clip) -> int:
    """Clip frame where the song's silent second ends: the first frame after the last one at
    the log-mel floor (-100 dB; the last feature column is onset strength)."""
    floor = np.flatnonzero(clip.features[:, :-1].mean(axis=1) < -99.0)
    assert len(floor) > 5
    return int(floor[-1]) + 1


def rig_points(poses: np.ndarray) -> np.ndarray:
    """(T, POSE_DIM) poses -> (T, points, 3) world positions (m) of every bone head and end site."""
    motion = Motion(root_pos=poses[:, :3], rotations=poses[:, 3:].reshape(len(poses), NUM_BONES, 4))
    return fk(motion, load_default_skeleton())


def test_tempo_augmentation_stretches_music_and_motion_together(data, tmp_path):
    root, _ = data
    fcfg = FeatureConfig(**FEATURES)
    slow, fast = build_corpus(root, ["DANCE_W_1"], fcfg, (1.0, 1.25), tmp_path / "cache", progress=False)
    assert (slow.tempo, fast.tempo) == (1.0, 1.25)
    for c in (slow, fast):
        assert c.features.shape == (c.num_frames, fcfg.dim) and c.poses.shape == (c.num_frames, POSE_DIM)
        assert c.valid.shape == (c.num_frames,) and c.valid.all()
        assert c.features.dtype == c.poses.dtype == np.float32 and np.isfinite(c.features).all()
        q = c.poses[:, 3:].reshape(c.num_frames, NUM_BONES, 4)
        np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-5)
        assert (q[..., 3] >= 0).all()  # one hemisphere
        np.testing.assert_allclose(c.poses[:, [0, 2]], 0.0, atol=1e-6)  # canonical: dancing in place
    # The dance spans 10 s of music: 300 frames at tempo 1, 240 at 1.25.
    assert abs(slow.num_frames - 300) <= 2 and abs(fast.num_frames - 300 / 1.25) <= 2
    # Poses: stretched time tau is original time 1.25 tau. Song frame f ends at (f + 1) / 30 s,
    # so fast song frame 4k - 1 and slow song frame 5k - 1 show the same instant.
    pairs = [(4 * k - 1 - fast.first_frame, 5 * k - 1 - slow.first_frame) for k in range(1, 100)]
    pairs = [(a, b) for a, b in pairs if 0 <= a < fast.num_frames and 0 <= b < slow.num_frames]
    assert len(pairs) > 40
    a, b = np.array(pairs).T
    # Same rig positions (the DWM joints fix every point; a straight limb's twist they leave to the
    # retargeter's continuity, which depends on the sampling, so quaternions are not compared).
    np.testing.assert_allclose(rig_points(fast.poses[a]), rig_points(slow.poses[b]), atol=1e-5)
    np.testing.assert_allclose(fast.poses[a, :7], slow.poses[b, :7], atol=1e-5)  # root and Hips
    assert np.abs(rig_points(fast.poses[a[1:]]) - rig_points(slow.poses[b[:-1]])).max() > 0.05  # one frame off
    # Features: the clip's are the stretched song's from first_frame on...
    audio = load_audio(root / "DANCE_W_1" / "audio.mp3", SAMPLE_RATE)[0]
    stretched = extract_features(librosa.effects.time_stretch(audio, rate=1.25), fcfg)
    np.testing.assert_allclose(fast.features, stretched[fast.first_frame:fast.first_frame + fast.num_frames], atol=1e-4)
    # ...and sound returns at 7 s of the song (song frame 7 * 30 - 1 ends there), 7 / 1.25 s of the
    # stretched one; the phase vocoder's 2048-sample window smears it by up to 3 frames.
    assert sound_returns(slow) == SILENT_S[1] * FPS - slow.first_frame
    assert abs(sound_returns(fast) - (SILENT_S[1] / 1.25 * FPS - fast.first_frame)) <= 3


def test_corpus_cache_returns_the_same_clips(data, tmp_path):
    root, _ = data
    fcfg = FeatureConfig(**FEATURES)
    first = build_corpus(root, ["DANCE_W_2"], fcfg, (0.9,), tmp_path / "c", progress=False)[0]
    assert len(list((tmp_path / "c").glob("DANCE_W_2-t0.900-*.npz"))) == 1
    again = build_corpus(root, ["DANCE_W_2"], fcfg, (0.9,), tmp_path / "c", progress=False)[0]
    for k in ("features", "poses", "valid"):
        np.testing.assert_array_equal(getattr(first, k), getattr(again, k))
    assert (again.name, again.style, again.tempo, again.first_frame) == ("DANCE_W_2", "W", 0.9, first.first_frame)


def test_canonical_poses_ignore_where_the_dancer_stands_and_faces():
    t = np.linspace(0, 2, 40)
    motion = dance_motion(40, t, seed=7)
    turn = Rotation.from_euler("y", (50 + 30 * t)[:, None], degrees=True)  # a changing heading
    moved = Motion(root_pos=motion.root_pos + [2.0, 0.0, -1.0],
                   rotations=motion.rotations.copy(), fps=motion.fps)
    moved.rotations[:, BONE_INDEX["Hips"]] = (turn * Rotation.from_quat(motion.rotations[:, 0])).as_quat()
    a, b = canonicalize(motion), canonicalize(moved)
    np.testing.assert_allclose(a.root_pos[:, [0, 2]], 0.0)
    np.testing.assert_allclose(a.root_pos[:, 1], motion.root_pos[:, 1])  # hip height kept
    np.testing.assert_allclose(heading(Rotation.from_quat(a.rotations[:, 0])), 0.0, atol=1e-9)
    np.testing.assert_allclose(a.root_pos, b.root_pos, atol=1e-12)
    dots = np.abs((a.rotations * b.rotations).sum(-1))  # every bone: the same rotation, up to sign
    np.testing.assert_allclose(dots, 1.0, atol=1e-9)
    other = np.abs((a.rotations[:, 1:] * motion.rotations[:, 1:]).sum(-1))
    np.testing.assert_allclose(other, 1.0, atol=1e-9)  # bones below the Hips are untouched


# -- init_from with appended context/beat columns ----------------------------------------------


def test_widened_input_weights_leave_the_old_model_unchanged(run_a):
    old, _ = load_checkpoint(run_a / "best.pt")
    wide = FeatureConfig(**FEATURES, context_s=5.0, beat_phase=True)
    new = build_model("causal", {**BASE["model_config"], "feature_dim": wide.dim, "pose_dim": POSE_DIM})
    state, widened = train_module.widen_inputs(old.state_dict(), new.state_dict(), wide.base_dim)
    assert widened and all(state[k].shape[1] == wide.dim for k in widened)
    new.load_state_dict(state)
    old.eval(), new.eval()
    x = torch.randn(2, wide.base_dim, 64)
    extra = torch.randn(2, wide.dim - wide.base_dim, 64)
    with torch.no_grad():
        torch.testing.assert_close(new(torch.cat([x, extra], dim=1)), old(x))
    bigger = build_model("causal", {"channels": [8, 8, 8, 8, 16], "feature_dim": wide.dim, "pose_dim": POSE_DIM})
    with pytest.raises(ConfigError, match="shape"):
        train_module.widen_inputs(old.state_dict(), bigger.state_dict(), wide.base_dim)


def test_input_standardised_mfcc_model_trains_loads_and_streams_like_offline(data, tmp_path):
    """The recipe of configs/mfcc_norm.toml in small: input_norm on mfcc_onset features, through
    the real loop; the saved model's running statistics are the corpus's, and the engine's
    streaming path (NumPy step) gives the offline windowed output."""
    from models.networks.streaming import StreamingGenerator, offline_windowed

    feats = {"kind": "mfcc_onset", "n_mels": 16}
    out = run_train(data, tmp_path / "mfcc", features=feats, stage1_steps=20, eval_every=10,
                    model_config={"channels": [8, 8, 8, 8, 8], "input_norm": True})
    rows = read_log(out)
    assert float(rows[-1]["loss_rot"]) < float(rows[0]["loss_rot"])
    loaded = load_model(out / "best.pt")
    assert loaded.features == FeatureConfig(**feats) and loaded.model.config.input_norm
    root, cache = data
    x = extract_features(load_audio(next(root.glob("DANCE_*")) / "audio.mp3")[0], loaded.features)[:200]
    norm = loaded.model.in_norm
    assert abs(float(norm.running_mean[0]) - float(x[:, 0].mean())) < 3 * float(x[:, 0].std())  # c0, O(100) dB units
    assert float(norm.running_var[0]) > 10.0  # a real variance, not the initial 1
    ref = offline_windowed(loaded.model, x)
    gen = StreamingGenerator(loaded.model)
    streamed = np.concatenate([gen.push(x[i : i + 9]) for i in range(0, len(x), 9)])
    assert np.abs(streamed - ref).max() < 1e-4


def test_widening_keeps_an_input_standardisation_and_the_old_outputs():
    base, wide = 6, 10
    torch.manual_seed(0)
    old = randomize_batchnorm(build_model("causal", {"channels": [8, 8, 8, 8, 16], "feature_dim": base,
                                                     "pose_dim": POSE_DIM, "input_norm": True}), 1)
    new = build_model("causal", {"channels": [8, 8, 8, 8, 16], "feature_dim": wide, "pose_dim": POSE_DIM,
                                 "input_norm": True})
    state, widened = train_module.widen_inputs(old.state_dict(), new.state_dict(), base)
    assert widened
    torch.testing.assert_close(state["in_norm.running_mean"][:base], old.in_norm.running_mean)
    assert (state["in_norm.running_var"][base:] == 1).all() and (state["in_norm.running_mean"][base:] == 0).all()
    new.load_state_dict(state)
    old.eval(), new.eval()
    x = torch.randn(2, base, 48) * 30 + 5
    with torch.no_grad():
        torch.testing.assert_close(new(torch.cat([x, torch.randn(2, wide - base, 48)], dim=1)), old(x))


def test_fine_tune_onto_appended_columns_trains_and_refuses_other_features(run_a, data, tmp_path):
    wide = {**FEATURES, "context_s": 5.0, "beat_phase": True}
    out = run_train(data, tmp_path / "wide", features=wide, init_from=str(run_a / "best.pt"), stage1_steps=3,
                    eval_every=3, w_beat=1.0)
    assert all(float(r["loss_beat"]) >= 0 for r in read_log(out))
    loaded = load_model(out / "best.pt")
    assert loaded.features == FeatureConfig(**wide) and loaded.model.config.feature_dim == loaded.features.dim
    with pytest.raises(PerformerError, match="feature"):
        run_train(data, tmp_path / "other", features={"n_mels": 24, "beat_phase": True},
                  init_from=str(run_a / "best.pt"), stage1_steps=3)


def _beat_columns(T: int, period: float, clarity: float = 0.5) -> torch.Tensor:
    theta = 2 * np.pi * np.arange(T) / period
    cols = np.stack([clarity * np.cos(theta), clarity * np.sin(theta), np.full(T, clarity), np.zeros(T)])
    return torch.tensor(cols, dtype=torch.float32)[None]


def _root_walk(speed: np.ndarray) -> torch.Tensor:
    """(1, POSE_DIM, T) poses: identity rotations, the root walking along x at ``speed`` m/frame."""
    T = speed.size + 1
    pose = np.zeros((POSE_DIM, T), np.float32)
    pose[0] = np.concatenate([[0.0], np.cumsum(speed)])
    pose[1] = 0.9
    pose[6::4] = 1.0  # w of every bone quaternion
    return torch.tensor(pose)[None]


def test_beat_loss_is_below_one_when_the_motion_slows_on_the_beats(offsets):
    T, P = 120, 15.0
    t = np.arange(1, T)
    beats = _beat_columns(T, P)
    slow_on_beat = _root_walk(0.01 * (1.0 - 0.8 * np.cos(2 * np.pi * t / P)))
    fast_on_beat = _root_walk(0.01 * (1.0 + 0.8 * np.cos(2 * np.pi * t / P)))
    steady = _root_walk(np.full(T - 1, 0.01))
    assert losses.beat_speed_ratio(slow_on_beat, beats, offsets).item() < 0.5
    assert losses.beat_speed_ratio(fast_on_beat, beats, offsets).item() > 1.5
    assert losses.beat_speed_ratio(steady, beats, offsets).item() == pytest.approx(1.0, abs=1e-4)
    # No pulse (clarity 0): the weights vanish and the loss is 0, not NaN.
    assert losses.beat_speed_ratio(steady, _beat_columns(T, P, clarity=0.0), offsets).item() == 0.0
    pred = fast_on_beat.clone().requires_grad_(True)
    losses.beat_speed_ratio(pred, beats, offsets).backward()
    assert torch.isfinite(pred.grad).all() and pred.grad.abs().sum() > 0


def test_beat_loss_needs_the_beat_columns(data, tmp_path):
    with pytest.raises(ConfigError, match="beat_phase"):
        run_train(data, tmp_path / "nobeat", w_beat=1.0)


def test_train_only_changes_just_the_named_parameters_and_keeps_batch_norm_statistics(run_a, data, tmp_path):
    """A polish of the output layer's bias: every other tensor of the checkpoint, batch-norm
    running statistics included, comes out bit-identical, and the bias does move."""
    before = weights(run_a / "best.pt")
    out = run_train(data, tmp_path / "bias", init_from=str(run_a / "best.pt"), train_only=["head.bias"],
                    stage1_steps=6, eval_every=3, lr=1e-3)
    after = weights(out / "last.pt")
    assert after.keys() == before.keys()
    changed = {k for k in before if not torch.equal(before[k], after[k])}
    assert changed == {"head.bias"}
    assert any("running_mean" in k for k in before)  # the model has batch norm to keep


def test_train_only_matching_no_parameter_is_refused(data, tmp_path):
    with pytest.raises(ConfigError, match="train_only .* matches no parameter.*head"):
        run_train(data, tmp_path / "none", train_only=["decoder_nope"], stage1_steps=2)
