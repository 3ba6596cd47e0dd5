"""Issue 40's second design, the match chooser (models/networks/motion_match.py,
``library_model(..., chooser="match")``): music descriptors -> motion descriptors -> the
library's nearest windows. No shared data: a synthetic dance at three paces, the bundled clip
time-stretched."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from models.rig.humanoid import NUM_BONES

REPO = Path(__file__).resolve().parents[1]
CLIP = REPO / "models" / "assets" / "clip.ogg"


def swaying(pace: float, seconds: float = 20.0) -> np.ndarray:
    """(T, 87) poses: every bone swinging at its own rate times ``pace`` (same seed at every pace)."""
    t = np.arange(int(seconds * 30)) / 30.0
    rng = np.random.default_rng(3)
    freq, phase, amp = rng.uniform(0.3, 1.2, (NUM_BONES, 3)), rng.uniform(0, 6.28, (NUM_BONES, 3)), rng.uniform(0.1, 0.5, (NUM_BONES, 3))
    rotvec = amp[None] * np.sin(2 * np.pi * pace * freq[None] * t[:, None, None] + phase[None])
    q = Rotation.from_rotvec(rotvec.reshape(-1, 3)).as_quat().reshape(len(t), NUM_BONES, 4)
    q *= np.where(q[..., 3:] < 0, -1.0, 1.0)
    root = np.stack([np.zeros_like(t), np.full_like(t, 0.95), np.zeros_like(t)], 1)
    return np.concatenate([root, q.reshape(len(t), -1)], 1).astype(np.float32)


@pytest.fixture(scope="module")
def setup():
    import librosa

    from models.features.audio_io import load_audio
    from models.features.spectral import extract_features
    from models.generate import load_model
    from models.networks.library_player import library_model

    lm = load_model(None)
    poses = [swaying(p) for p in (0.5, 1.0, 2.0)]
    tracks = [p[:, :3].copy() for p in poses]
    lib = library_model(lm.model, poses, tracks, ["one"] * 3, chooser="match")
    y = load_audio(CLIP, 22050)[0]
    feats = {r: extract_features(librosa.effects.time_stretch(y, rate=r), lm.features) for r in (0.8, 1.25)}
    return lm, lib, feats


def picked_speed(lib, chooser, feats: np.ndarray) -> float:
    """Mean ln joint speed of the exemplars of the code the chooser ranks first, over the code steps from 6 s."""
    from models.networks.motion_match import motion_descriptors
    from models.networks.tempo import track_periods

    seg = lib.config.seg
    z = (feats[:, : lib.config.feature_dim] - lib.feat_mean.numpy()) / lib.feat_std.numpy()
    per = track_periods(feats[:, 61], feats[:, 60], feats[:, 28])
    out = []
    for t in range(180, len(feats), seg):
        k = int(np.argmax(chooser(z[t - seg: t], float(per[t - 1]))))
        n = int(lib.member_count[k])
        out.append(motion_descriptors(lib.member_poses[k, :n].float().numpy(), seg)[:, 0].mean())
    return float(np.mean(out))


def test_match_chooser_speed_follows_the_music_tempo(setup):
    """The same clip at 1.25x makes the chooser pick faster windows than at 0.8x; with the regression
    replaced by a constant (its weights 0) both pick alike and this fails."""
    _, lib, feats = setup
    fast, slow = picked_speed(lib, lib.code_chooser, feats[1.25]), picked_speed(lib, lib.code_chooser, feats[0.8])
    assert fast - slow > np.log(1.2), (fast, slow)  # the library spans paces 0.5-2: at least 20 % faster windows
    flat = copy.deepcopy(lib.code_chooser)
    flat.regression.w = np.zeros_like(flat.regression.w)
    assert abs(picked_speed(lib, flat, feats[1.25]) - picked_speed(lib, flat, feats[0.8])) < 1e-9


def test_match_library_dances(setup):
    """A match library streams finite poses from the library's windows, and codes is still the default."""
    from models.errors import ConfigError
    from models.networks.dance_stream import DanceStream
    from models.networks.library_player import library_model

    lm, lib, feats = setup
    s = DanceStream(lib, seed=0)
    out = s.push(feats[1.25][:600])
    assert np.isfinite(out).all() and len(set(s.codes_drawn)) > 5
    with pytest.raises(ConfigError, match="chooser"):
        library_model(lm.model, [swaying(1.0)], [swaying(1.0)[:, :3]], ["one"], chooser="nearest")
