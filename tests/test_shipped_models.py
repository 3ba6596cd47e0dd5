"""The checkpoints shipped beside the default (docs/models.md): they load, generate
sensible motion for the bundled clip, and the real-time engine refuses them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from models.errors import CheckpointError
from models.features.audio_io import bundled_clip_path, load_audio
from models.features.spectral import extract_features
from models.generate import load_model, run_model
from models.networks.streaming import torch_threads
from models.rig.motion import POSE_DIM
from models.timebase import HOP, SAMPLE_RATE

ASSETS = Path(__file__).resolve().parents[1] / "models" / "assets"
SHIPPED = {"violin.pt": "violin", "dtm.pt": "dtm", "gcn.pt": "gcn"}


@pytest.fixture(scope="module")
def clip() -> np.ndarray:
    return load_audio(bundled_clip_path())[0][: 12 * SAMPLE_RATE]  # 12 s of the bundled clip


@pytest.mark.parametrize("file,name", sorted(SHIPPED.items()))
def test_shipped_checkpoint_generates_moving_unit_quaternion_motion(file, name, clip):
    path = ASSETS / file
    assert path.stat().st_size < 12 * 2**20  # small enough to ship
    lm = load_model(path)
    assert lm.name == name and getattr(lm.model, "offline_only", False)
    assert lm.meta["extra"]["val_dances"]  # trained with a validation split, recorded in the file
    feats = extract_features(clip, lm.features)
    with torch_threads(1):
        poses = run_model(lm.model, feats, audio=clip[: (len(feats) + 1) * HOP])
    assert poses.shape == (len(feats), POSE_DIM) and np.isfinite(poses).all()
    q = poses[:, 3:].reshape(len(poses), -1, 4)
    assert np.abs(np.linalg.norm(q, axis=-1) - 1).max() < 1e-4
    # A trained model moves: bone rotations change over the clip by more than a few degrees.
    dots = np.abs(np.einsum("tjc,jc->tj", q, q[0])).clip(0, 1)
    assert np.degrees(2 * np.arccos(dots)).max() > 5.0


@pytest.mark.parametrize("file", sorted(SHIPPED))
def test_engine_refuses_shipped_offline_models(file):
    from realtime.pipeline import build_pipeline

    with pytest.raises(CheckpointError, match="offline-only") as err:
        build_pipeline(ASSETS / file)
    assert file in str(err.value) and "performer generate" in str(err.value)
