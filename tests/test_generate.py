"""``performer generate``: whole-file generation to BVH/NPZ, every model kind, and bad input."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from models.networks.dance_stream import generate as stream_generate
from models.networks.stage import DEFAULT_STAGE
import pytest
import soundfile as sf
import torch

from models.errors import CheckpointError
from models.evaluation.metrics import velocity_spread
from models.features.audio_io import bundled_clip_path, load_audio
from models.features.spectral import FeatureConfig, extract_features
from models.generate import default_checkpoint_path, load_model, run_model
from models.networks.checkpoint import build_model, save_checkpoint
from models.rig.bvh import read_bvh
from models.rig.humanoid import BONES
from models.rig.kinematics import fk
from models.rig.motion import POSE_DIM, Motion
from models.rig.npz import load_npz, load_npz_extra
from models.rig.skeleton import load_default_skeleton
from models.timebase import HOP, SAMPLE_RATE
from realtime import cli

FEATS = FeatureConfig()
FEATURE_META = {**FEATS.to_dict(), "fingerprint": FEATS.fingerprint()}
RIG = {"bones": list(BONES), "pose_dim": POSE_DIM}
TINY = {"feature_dim": FEATS.dim, "channels": [8, 8, 8, 8, 8]}


def make_checkpoint(path: Path, name: str = "causal", config: dict | None = None, **kw) -> Path:
    """A real checkpoint of a small random model (seeded)."""
    torch.manual_seed(0)
    model = build_model(name, config or TINY)
    args = dict(model_name=name, generator_config=model.config, feature_config=FEATURE_META, rig=RIG)
    args.update(kw)
    return save_checkpoint(path, model, **args)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> Path:
    return make_checkpoint(tmp_path_factory.mktemp("ckpt") / "tiny.pt")


def run_main(capsys, *args) -> tuple[int, str, str]:
    code = cli.main([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.out, out.err


def one_line_error(err: str) -> str:
    lines = [line for line in err.strip().splitlines() if line]
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith("performer generate: error: ")
    return lines[0]


def write_wav(path: Path, audio: np.ndarray, subtype: str = "FLOAT") -> Path:
    sf.write(path, audio, SAMPLE_RATE, subtype=subtype)
    return path


def poses_of(path: Path) -> np.ndarray:
    return load_npz_extra(path)["pose"]


def unit_and_finite(poses: np.ndarray) -> None:
    assert np.isfinite(poses).all()
    q = poses[:, 3:].reshape(len(poses), -1, 4)
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-5)


# -- the bundled clip ----------------------------------------------------------------------


def test_bundled_clip_to_bvh_and_npz(tmp_path, capsys, tiny):
    clip = bundled_clip_path()
    duration = sf.info(clip).duration
    code, out, err = run_main(capsys, "generate", clip, "--out", tmp_path / "m.bvh", "--checkpoint", tiny)
    assert code == 0, err
    bvh = read_bvh(tmp_path / "m.bvh")
    assert abs(len(bvh.frames) - duration * 30) <= 1
    assert bvh.fps == pytest.approx(30.0)
    assert re.search(r"real-time factor [0-9.]+x", out) and "features" in out and "export" in out, out

    code, out, err = run_main(capsys, "generate", clip, "--out", tmp_path / "m.npz", "--checkpoint", tiny)
    assert code == 0, err
    motion = load_npz(tmp_path / "m.npz")
    extra = load_npz_extra(tmp_path / "m.npz")
    t = motion.num_frames
    assert t == len(bvh.frames)
    np.testing.assert_allclose(extra["audio_time"], (np.arange(t) + 1) * HOP / SAMPLE_RATE)
    unit_and_finite(extra["pose"])
    # the BVH holds the same motion: its Euler channels give back the NPZ's rotations
    np.testing.assert_allclose(fk(bvh.to_motion(), load_default_skeleton()), fk(motion, load_default_skeleton()), atol=1e-3)


def test_energy_reaches_the_dancing_model_and_other_models_refuse_it(tmp_path, capsys, tiny):
    """performer generate --energy: the dance_vq default's motion changes with it, a causal
    U-Net refuses it in one line, an out-of-range value is a one-line error."""
    clip = bundled_clip_path()
    runs = {}
    for e in ("0", "1", "2"):
        code, _, err = run_main(capsys, "generate", clip, "--out", tmp_path / f"e{e}.npz", "--energy", e)
        assert code == 0, err
        runs[e] = poses_of(tmp_path / f"e{e}.npz")
    assert not np.array_equal(runs["0"], runs["2"]) and len(runs["0"]) == len(runs["1"])
    code, _, err = run_main(capsys, "generate", clip, "--out", tmp_path / "x.npz", "--energy", "1.5",
                            "--checkpoint", tiny)
    assert code == 2 and "has no energy control" in err and "Traceback" not in err
    code, _, err = run_main(capsys, "generate", clip, "--out", tmp_path / "x.npz", "--energy", "-1")
    assert code == 2 and "energy must be in [0, 2]" in err


def test_lead_reaches_the_dancing_model_and_other_models_refuse_it(tmp_path, capsys, tiny):
    """performer generate --lead: the dance_vq default writes its lead stream (dance_stream.generate's
    with that lead), a causal U-Net refuses it in one line, an out-of-range lead is a one-line error."""
    clip = bundled_clip_path()
    code, _, err = run_main(capsys, "generate", clip, "--out", tmp_path / "l.npz", "--lead", "133")
    assert code == 0, err
    lm = load_model(None)
    feats = extract_features(load_audio(clip, SAMPLE_RATE)[0], lm.features)
    expected = stream_generate(lm.model, feats, seed=0, lead=133.0, stage=DEFAULT_STAGE)  # generate's default stage
    np.testing.assert_allclose(poses_of(tmp_path / "l.npz"), expected, atol=1e-5)
    assert not np.allclose(expected, stream_generate(lm.model, feats, seed=0), atol=1e-3)
    code, _, err = run_main(capsys, "generate", clip, "--out", tmp_path / "x.npz", "--lead", "67",
                            "--checkpoint", tiny)
    assert code == 2 and "has no lead control" in err and "Traceback" not in err
    code, _, err = run_main(capsys, "generate", clip, "--out", tmp_path / "x.npz", "--lead", "500")
    assert code == 2 and "lead must be in [0, 200] ms" in err


def test_stage_and_facing_reach_the_dancing_model_and_other_models_refuse_them(tmp_path, capsys, tiny):
    """performer generate --stage/--facing: the dance_vq default travels on the stage asked for
    (3x2 unless told), 0 dances in place; bad values and other models get one-line errors."""
    clip = bundled_clip_path()
    code, _, err = run_main(capsys, "generate", clip, "--out", tmp_path / "s.npz", "--stage", "1x1", "--facing",
                            "audience")
    assert code == 0, err
    poses = poses_of(tmp_path / "s.npz")
    assert np.abs(poses[:, [0, 2]]).max() > 0.05 and (np.abs(poses[:, [0, 2]]) <= 0.5 + 1e-6).all()
    code, _, err = run_main(capsys, "generate", clip, "--out", tmp_path / "0.npz", "--stage", "0")
    assert code == 0, err
    np.testing.assert_array_equal(poses_of(tmp_path / "0.npz")[:, [0, 2]], 0.0)
    for args, msg in ((("--stage", "3y2"), "stage must be WxD"),
                      (("--facing", "back"), "facing must be one of free, audience"),
                      (("--stage", "2x2", "--checkpoint", tiny), "dances in place")):
        code, _, err = run_main(capsys, "generate", clip, "--out", tmp_path / "x.npz", *args)
        assert code == 2 and msg in err and "Traceback" not in err


def test_generate_equals_what_the_engine_streams(tmp_path, tiny):
    """The causal model is generated exactly as `performer run` streams it."""
    from models.features.streaming import StreamingFeatureExtractor
    from models.generate import generate
    from realtime.pipeline import build_pipeline

    audio = load_audio(bundled_clip_path())[0][: 8 * SAMPLE_RATE]
    wav = write_wav(tmp_path / "a.wav", audio)
    generate(wav, tmp_path / "a.npz", load_model(tiny))
    pipe = build_pipeline(tiny)
    ex: StreamingFeatureExtractor = pipe.extractor_factory(SAMPLE_RATE)
    streamed = np.concatenate([pipe.model.push(ex.push(b)) for b in np.array_split(load_audio(wav)[0], 50)])
    np.testing.assert_allclose(poses_of(tmp_path / "a.npz"), streamed, atol=1e-4)


# -- model kinds ----------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["unet_plain", "unet_gan", "lstm"])
def test_offline_models_give_one_pose_per_frame(name):
    config = {"feature_dim": FEATS.dim, "hidden": 16, "delay": 3} if name == "lstm" else TINY
    torch.manual_seed(0)
    model = build_model(name, config).eval()
    feats = np.random.default_rng(0).normal(-40, 10, (37, FEATS.dim)).astype(np.float32)  # 37: not a multiple of 16
    poses = run_model(model, feats)
    assert poses.shape == (37, POSE_DIM)
    unit_and_finite(poses)
    if name == "lstm":  # output frame t + delay is pose t; the last `delay` poses see repeated input
        with torch.no_grad():
            raw = model(torch.from_numpy(feats.T.copy())[None])[0].T.numpy()
        q = lambda p: p[:, 3:].reshape(len(p), -1, 4)  # noqa: E731
        dots = np.abs(np.sum(q(poses[:34]) * q(raw[3:]), axis=-1))
        np.testing.assert_allclose(dots, 1.0, atol=1e-5)


# -- bad and unusual input -------------------------------------------------------------------


def test_silence_gives_a_calm_finite_pose(tmp_path, capsys, tiny):
    wav = write_wav(tmp_path / "silence.wav", np.zeros(5 * SAMPLE_RATE, np.float32))
    code, _, err = run_main(capsys, "generate", wav, "--out", tmp_path / "s.npz", "--checkpoint", tiny)
    assert code == 0, err
    poses = poses_of(tmp_path / "s.npz")
    assert len(poses) == 150
    unit_and_finite(poses)
    music = run_model(load_model(tiny).model, extract_features(load_audio(bundled_clip_path())[0][: 5 * SAMPLE_RATE]))
    pos = [fk(Motion.from_vector(p), load_default_skeleton())[64:] for p in (poses, music)]  # after the first hop
    assert velocity_spread(pos[0]) < 0.05 * velocity_spread(pos[1])


def test_clipped_square_wave_gives_finite_motion(tmp_path, capsys, tiny):
    t = np.arange(5 * SAMPLE_RATE) / SAMPLE_RATE
    wav = write_wav(tmp_path / "clip.wav", np.clip(20 * np.sin(2 * np.pi * 110 * t), -1, 1).astype(np.float32), "PCM_16")
    code, _, err = run_main(capsys, "generate", wav, "--out", tmp_path / "c.npz", "--checkpoint", tiny)
    assert code == 0, err
    unit_and_finite(poses_of(tmp_path / "c.npz"))


def test_audio_shorter_than_a_window_is_generated(tmp_path, capsys, tiny):
    wav = write_wav(tmp_path / "short.wav", 0.1 * np.random.default_rng(0).standard_normal(2 * SAMPLE_RATE).astype(np.float32))
    code, out, err = run_main(capsys, "generate", wav, "--out", tmp_path / "s.bvh", "--checkpoint", tiny)
    assert code == 0, err
    assert len(read_bvh(tmp_path / "s.bvh").frames) == 60
    one_frame = write_wav(tmp_path / "one.wav", np.zeros(HOP, np.float32))
    assert run_main(capsys, "generate", one_frame, "--out", tmp_path / "o.bvh", "--checkpoint", tiny)[0] == 0
    assert len(read_bvh(tmp_path / "o.bvh").frames) == 1


def test_audio_shorter_than_a_frame_is_refused(tmp_path, capsys, tiny):
    wav = write_wav(tmp_path / "tiny.wav", np.zeros(HOP - 1, np.float32))
    code, _, err = run_main(capsys, "generate", wav, "--out", tmp_path / "t.bvh", "--checkpoint", tiny)
    assert code == 2
    assert "tiny.wav" in one_line_error(err) and "at least one" in err
    assert not (tmp_path / "t.bvh").exists()


def test_nan_samples_name_the_file(tmp_path, capsys, tiny):
    audio = np.zeros(SAMPLE_RATE, np.float32)
    audio[1000] = np.nan
    wav = write_wav(tmp_path / "nan.wav", audio)
    code, _, err = run_main(capsys, "generate", wav, "--out", tmp_path / "n.bvh", "--checkpoint", tiny)
    assert code == 2
    line = one_line_error(err)
    assert "nan.wav" in line and "non-finite" in line


def test_unknown_output_suffix(tmp_path, capsys, tiny):
    code, _, err = run_main(capsys, "generate", bundled_clip_path(), "--out", tmp_path / "m.fbx", "--checkpoint", tiny)
    assert code == 2
    assert "'.fbx'" in one_line_error(err) and ".bvh" in err


def _other_rig(path: Path) -> Path:
    bones = list(BONES[:-1])
    model = build_model("causal", {**TINY, "pose_dim": 3 + 4 * len(bones)})
    return save_checkpoint(path, model, model_name="causal", generator_config=model.config,
                           feature_config=FEATURE_META, rig={"bones": bones, "pose_dim": 3 + 4 * len(bones)})


def _truncated(path: Path) -> Path:
    make_checkpoint(path)
    path.write_bytes(path.read_bytes()[:5000])
    return path


@pytest.mark.parametrize("make, message", [
    (_other_rig, "another rig"),
    (lambda p: make_checkpoint(p, feature_config={**FEATURE_META, "fingerprint": "logmel_onset-d65-000000000000"}),
     "feature code changed"),
    (lambda p: make_checkpoint(p, feature_config={**FEATURE_META, "version": 99}), "feature config version"),
    (_truncated, "unreadable checkpoint"),
    (lambda p: p, "checkpoint not found"),
])
def test_bad_checkpoints_exit_2_with_one_line(tmp_path, capsys, make, message):
    ckpt = make(tmp_path / "bad.pt")
    code, _, err = run_main(capsys, "generate", bundled_clip_path(), "--out", tmp_path / "m.bvh", "--checkpoint", ckpt)
    assert code == 2
    line = one_line_error(err)
    assert "bad.pt" in line and message in line


def test_load_model_refuses_feature_dim_mismatch(tmp_path):
    path = make_checkpoint(tmp_path / "m.pt", config={**TINY, "feature_dim": 10})
    with pytest.raises(CheckpointError, match="10 features per frame"):
        load_model(path)


# -- seams on real music (issue acceptance (c)) ----------------------------------------------


def seam_ratio_of_default(audio_path: Path) -> float:
    """seam_ratio of the default checkpoint's streamed output (= offline_windowed) on a song."""
    from models.networks.blend import seam_ratio

    path = default_checkpoint_path()
    if not path.is_file():
        pytest.skip(f"default checkpoint not trained yet ({path} is missing)")
    loaded = load_model(path)
    feats = extract_features(load_audio(audio_path)[0], loaded.features)
    poses = run_model(loaded.model, feats, window=128, hop=64)
    if loaded.name == "dance_vq":  # its seams: where one 8-frame movement hands over to the next
        seg = loaded.model.config.seg
        return seam_ratio(poses, seg, seg, radius=1)
    return seam_ratio(poses, 128, 64)


@pytest.mark.slow
def test_seam_ratio_of_the_default_checkpoint_on_the_bundled_clip():
    assert seam_ratio_of_default(bundled_clip_path()) <= 1.2


@pytest.mark.slow
@pytest.mark.data
def test_seam_ratio_of_the_default_checkpoint_on_a_validation_song(dwm_root):
    assert seam_ratio_of_default(dwm_root / "DANCE_W_5" / "audio.mp3") <= 1.2
