"""Checkpoints: round trip, atomic writes, and every refusal names the file and the difference."""

from __future__ import annotations

import os

import numpy as np
import pytest
import torch

from models.errors import CheckpointError
from models.networks.checkpoint import MODELS, _weights_hash, build_model, load_checkpoint, save_checkpoint
from models.networks.generator import GeneratorConfig
from models.rig.humanoid import BONES
from models.rig.motion import POSE_DIM

SMALL = GeneratorConfig(channels=(8, 8, 12, 12, 16))
FEATURES = {"kind": "logmel_onset", "n_mels": 64, "fingerprint": "logmel_onset-d65-abc123"}
RIG = {"bones": list(BONES), "pose_dim": POSE_DIM}
# Per model name, a small config taking 65 features (None: the name's defaults); SMALL otherwise.
SMALL_CONFIGS = {
    "gcn": {"feature_dim": 65, "noise_channels": 8, "style_dim": 4, "widths": [8, 8, 8, 8, 8],
            "disc_widths": [8, 8, 8, 8], "t_kernel": 3, "classifier_width": 4},
    "lstm": None,
    "violin": {"feature_dim": 65, "d_model": 16, "levels": 2, "blocks": 1},
    "dance_vq": {"feature_dim": 65, "codebook": 16, "code_dim": 8, "enc_width": 16, "dec_width": 16, "d_model": 16,
                 "layers": 1, "heads": 2, "members": 2},
    "dtm": {"feature_dim": 65, "hidden": 16, "z_init": 4, "z_mov": 8, "z_dance": 8, "style_hidden": 8, "noise_dim": 4},
}


def save(path, name="causal", config=SMALL, **kw):
    model = build_model(name, config)
    args = dict(model_name=name, generator_config=model.config, feature_config=FEATURES, rig=RIG,
                extra={"step": 7})
    args.update(kw)
    save_checkpoint(path, model, **args)
    return model


@pytest.mark.parametrize("name", sorted(MODELS))
def test_round_trip_every_model(tmp_path, name):
    path = tmp_path / f"{name}.pt"
    torch.manual_seed(0)
    model = save(path, name, SMALL_CONFIGS.get(name, SMALL)).eval()
    loaded, meta = load_checkpoint(path, expect_feature_fingerprint=FEATURES["fingerprint"], expect_bones=BONES)
    x = torch.randn(1, 65, 32)
    if name == "dance_vq":  # no forward: it generates frame by frame (models/networks/dance_stream.py)
        from models.networks.dance_stream import generate

        f = x[0].T.numpy()
        np.testing.assert_array_equal(generate(loaded, f, seed=1), generate(model, f, seed=1))
    else:
        assert torch.allclose(loaded(x), model(x))
    assert not loaded.training
    assert meta["model_name"] == name and meta["extra"] == {"step": 7} and meta["rig"] == RIG
    assert meta["feature_fingerprint"] == FEATURES["fingerprint"]
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # no temp files left


def test_default_model_checkpoint_is_small(tmp_path):
    path = tmp_path / "default.pt"
    save(path, config=GeneratorConfig())
    assert path.stat().st_size < 20e6


def test_truncated_file_is_refused(tmp_path):
    path = tmp_path / "m.pt"
    save(path)
    data = path.read_bytes()
    for keep in (len(data) // 2, 100, 0):
        path.write_bytes(data[:keep])
        with pytest.raises(CheckpointError, match="unreadable") as e:
            load_checkpoint(path)
        assert str(path) in str(e.value)


def test_corrupted_weights_are_refused(tmp_path):
    path = tmp_path / "m.pt"
    save(path)
    data = bytearray(path.read_bytes())
    ck = torch.load(path, weights_only=True)
    w = ck["state_dict"]["head.weight"].numpy().tobytes()
    at = bytes(data).find(w[:64])  # stored uncompressed inside the zip
    assert at > 0
    data[at + 5] ^= 0xFF
    path.write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match="SHA-256|unreadable"):
        load_checkpoint(path)


def test_other_rig_is_refused(tmp_path):
    path = tmp_path / "m.pt"
    save(path)
    other = list(BONES)
    other[7] = "LeftForeArm"
    with pytest.raises(CheckpointError, match="another rig.*LeftLowerArm.*LeftForeArm") as e:
        load_checkpoint(path, expect_bones=other)
    assert str(path) in str(e.value)
    with pytest.raises(CheckpointError, match="21 bones.*expected 20"):
        load_checkpoint(path, expect_bones=BONES[:-1])


def test_other_feature_config_is_refused(tmp_path):
    path = tmp_path / "m.pt"
    save(path)
    with pytest.raises(CheckpointError, match="abc123.*linear-d513") as e:
        load_checkpoint(path, expect_feature_fingerprint="linear-d513-ffffffffffff")
    assert str(path) in str(e.value)


def test_save_refuses_inconsistent_rig_and_keeps_old_file(tmp_path):
    path = tmp_path / "m.pt"
    save(path)
    before = path.read_bytes()
    with pytest.raises(CheckpointError, match="pose_dim"):
        save(path, rig={"bones": list(BONES[:20]), "pose_dim": POSE_DIM})
    with pytest.raises(CheckpointError, match="JSON"):
        save(path, extra={"bad": object()})
    with pytest.raises(CheckpointError, match="does not fit"):
        save(path, model_name="lstm")
    assert path.read_bytes() == before
    assert sorted(os.listdir(tmp_path)) == ["m.pt"]


def test_missing_and_foreign_files(tmp_path):
    with pytest.raises(CheckpointError, match="not found"):
        load_checkpoint(tmp_path / "nope.pt")
    path = tmp_path / "other.pt"
    torch.save({"weights": torch.zeros(3)}, path)
    with pytest.raises(CheckpointError, match="not a live-performer-checkpoint"):
        load_checkpoint(path)


def test_non_finite_weights_are_refused_on_save_and_load(tmp_path):
    path = tmp_path / "m.pt"
    model = save(path)
    with torch.no_grad():
        model.head.bias[0] = float("nan")
    with pytest.raises(CheckpointError, match="non-finite"):
        save_checkpoint(path, model, model_name="causal", generator_config=SMALL, feature_config=FEATURES, rig=RIG)
    ck = torch.load(path, weights_only=True)  # forge one on disk, hash consistent
    ck["state_dict"] = {k: v.detach().clone() for k, v in model.state_dict().items()}
    ck["weights_sha256"] = _weights_hash(ck["state_dict"])
    torch.save(ck, path)
    with pytest.raises(CheckpointError, match="non-finite"):
        load_checkpoint(path)
