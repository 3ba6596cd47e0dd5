"""Training the dancing performer, run for real on tiny data: ``train_dance_vq`` (codebook,
exemplars, style prior, predictor; models/training/dance_vq.py) on a synthetic DWM dataset,
and ``fit_music_gate`` (the idle gate's music detector) on the bundled clip against
synthetic noise."""

from __future__ import annotations

import csv

import numpy as np
import pytest
import torch
from test_training import write_synthetic_dwm

from models.features.audio_io import bundled_clip_path, load_audio
from models.features.spectral import FeatureConfig, extract_features
from models.networks.checkpoint import load_checkpoint
from models.networks.dance_stream import DanceStream
from models.networks.dance_vq import DanceVQ, DanceVQConfig
from models.rig.motion import POSE_DIM
from models.timebase import FPS, SAMPLE_RATE
from models.training.config import TrainConfig
from models.training.dance_vq import fit_music_gate, gate_inputs, synthetic_noise, train_dance_vq

torch.set_num_threads(1)

#: The shipped feature kind at a small size: MFCC + onset, 60-s context, the beat tracker's columns.
FCFG = FeatureConfig(kind="mfcc_onset", n_mels=32, context_s=60.0, beat_phase=True)


@pytest.fixture(scope="module")
def clip_features() -> np.ndarray:
    clip, _ = load_audio(bundled_clip_path(), SAMPLE_RATE)
    return extract_features(clip, FCFG)


def gate_model(features: np.ndarray) -> DanceVQ:
    """A tiny dance_vq on FCFG with its feature statistics from ``features``; gate unfitted."""
    torch.manual_seed(0)
    m = DanceVQ(DanceVQConfig(feature_dim=FCFG.dim, codebook=16, code_dim=8, enc_width=16, dec_width=16, d_model=16,
                              layers=1, heads=2, window_codes=4, clarity_col=FCFG.dim - 2)).eval()
    with torch.no_grad():
        m.feat_mean.copy_(torch.from_numpy(features.mean(0)))
        m.feat_std.copy_(torch.from_numpy(np.maximum(features.std(0), 1e-3)))
    return m


def loud(kind: str, seconds: float, seed: int, rms: float = 0.05) -> np.ndarray:
    """:func:`synthetic_noise` of ``kind`` scaled to ``rms`` (the clip's is 0.094)."""
    x = synthetic_noise(kind, seconds, np.random.default_rng(seed))
    return np.clip(x * (rms / np.sqrt(np.mean(x**2))), -1.0, 1.0).astype(np.float32)


@pytest.mark.slow
def test_fit_music_gate_tells_the_clip_from_noise_and_the_stream_idles_on_noise(clip_features):
    """The detector fitted on the clip against 2 clips of every noise kind (4 s each) is right
    on its training frames, on noise of other seeds, and in a stream: with the silence
    threshold off (only the detector can idle it) the performer dances to the clip and
    settles in loud white noise and applause; with the unfitted gate it dances through them."""
    m = gate_model(clip_features)
    acc = fit_music_gate(m, [clip_features], FCFG, np.random.default_rng(0), seconds=4.0, per_kind=2)
    assert acc["music_acc"] >= 0.9 and acc["noise_acc"] >= 0.9, acc
    w, b = m.gate_w.numpy().astype(np.float64), float(m.gate[1])
    assert np.abs(w).sum() > 0 and float(m.gate[0]) < -1e8  # the silence threshold is set elsewhere (off here)
    held_out = [extract_features(loud(k, 6.0, seed=10 + i), FCFG) for i, k in enumerate(("white", "applause"))]
    noise_logit = np.concatenate([gate_inputs(m, f)[30:] @ w + b for f in held_out])
    music_logit = gate_inputs(m, clip_features)[30:] @ w + b
    assert np.mean(noise_logit < 0) >= 0.9 and np.mean(music_logit > 0) >= 0.9

    clip, _ = load_audio(bundled_clip_path(), SAMPLE_RATE)
    for i, kind in enumerate(("white", "applause")):
        # the clip's first 10 s and then noise, as one recording: the features run on through the change
        noise = np.concatenate([clip[: 10 * SAMPLE_RATE], loud(kind, 8.0, seed=20 + i)])
        feats = extract_features(noise, FCFG)[10 * FPS:]
        s = DanceStream(m, seed=0)
        s.push(clip_features[: 10 * FPS])
        assert s.idle_weight == 0.0, f"{kind}: not dancing to the clip"
        s.push(feats)
        assert s.idle_weight == 1.0, f"{kind}: still dancing after 8 s of loud {kind}"
        unfitted = gate_model(clip_features)
        s = DanceStream(unfitted, seed=0)
        s.push(clip_features[: 10 * FPS])
        s.push(feats)
        assert s.idle_weight == 0.0  # the default gate (weights 0, bias 10) always hears music


@pytest.mark.slow
def test_train_dance_vq_writes_a_playable_checkpoint_with_exemplars(tmp_path):
    """20 codebook steps and 10 predictor steps on three synthetic dances (two to train):
    best.pt is a dance_vq on the configured features whose codebook loss fell, whose
    exemplars are the training dances' own poses (every code that has one), whose silence
    threshold comes from the training songs, and which dances from its features."""
    root = write_synthetic_dwm(tmp_path / "dwm")
    cfg = TrainConfig.from_dict({
        "model": "dance_vq", "seed": 0, "batch_size": 4, "stage1_steps": 20, "stage2_steps": 10, "tempos": [1.0],
        "eval_every": 10, "threads": 1,
        "features": {"kind": "mfcc_onset", "n_mels": 16, "context_s": 10.0, "beat_phase": False},
        "model_config": {"codebook": 16, "code_dim": 8, "enc_width": 16, "dec_width": 16, "d_model": 16,
                         "layers": 1, "heads": 2, "window_codes": 4, "members": 2},
        "dance": {"vq_segment": 32, "pred_batch": 8, "vq_lr": 3e-3, "pred_lr": 3e-3},
    })
    best = train_dance_vq(cfg, root, tmp_path / "run", cache_dir=tmp_path / "cache", progress=False)
    m, meta = load_checkpoint(best)
    assert isinstance(m, DanceVQ) and meta["model_name"] == "dance_vq"
    fcfg = FeatureConfig(**cfg.features)
    assert m.config.feature_dim == fcfg.dim and m.config.members == 2 and m.config.codebook == 16
    with open(tmp_path / "run" / "log.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["step"]) for r in rows] == list(range(1, 31)) and {r["stage"] for r in rows} == {"1", "2"}
    pose = [float(r["loss_pose"]) for r in rows if r["stage"] == "1"]
    assert np.mean(pose[-5:]) < np.mean(pose[:5]), pose
    assert all(np.isfinite(float(r["loss_ce"])) for r in rows if r["stage"] == "2")
    # the exemplars: codes that the training motion uses hold real windows of it
    counts = m.member_count.numpy()
    assert counts.sum() > 0 and counts.max() <= 2
    from models.training.dance_vq import training_clips

    _, clips = training_clips(cfg, fcfg, root, tmp_path / "cache", False)  # the motion the run learnt from
    motion = np.concatenate([c.poses for c in clips])
    k = int(np.flatnonzero(counts)[0])
    window = m.member_poses[k, 0].float().numpy()  # (2 seg, P) float16 in the checkpoint
    gaps = [np.abs(motion[i: i + len(window)] - window).max() for i in range(len(motion) - len(window) + 1)]
    assert min(gaps) < 2e-3  # one of the training windows, to float16 rounding
    # the silence threshold: below every training song's frames (its 0.5th percentile minus 3)
    energy = np.concatenate([c.features[:, m.config.energy_col] for c in clips])
    assert -1e8 < float(m.gate[0]) < energy.min()
    poses = DanceStream(m.eval(), seed=0).push(np.concatenate([c.features for c in clips])[:200])
    assert poses.shape == (200, POSE_DIM) and np.isfinite(poses).all()


def test_a_predictor_that_hears_the_tempo_is_trained_on_what_the_stream_gives_it(clip_features):
    """models/training/tempo_predictor.py: the codebook and every buffer kept, a fresh predictor with the
    tempo input; each training token's tempo is the stream's own (``tempo_inputs`` at the token's last
    frame, clip and phase in encode_clips' order), and training moves the tempo input's weights."""
    from types import SimpleNamespace

    from models.networks.player import tempo_inputs
    from models.training.dance_vq import DanceVQTrainOptions
    from models.training.tempo_predictor import tempo_codes, train_tempo_predictor, with_tempo_input

    m = gate_model(clip_features)
    with torch.no_grad():
        m.member_count[:] = 1
        m.member_period[:] = 20.0  # the memory's tempo 90 bpm
    n = len(clip_features)
    poses = np.random.default_rng(0).normal(size=(n, POSE_DIM)).astype(np.float32)
    clip = SimpleNamespace(name="clip", style="W", tempo=1.0, features=clip_features, poses=poses,
                           valid=np.ones(n, bool), num_frames=n)
    new = with_tempo_input(m, seed=0)
    assert new.config.tempo_input and new.predictor.tempo is not None and not m.config.tempo_input
    assert torch.equal(new.member_period, m.member_period) and torch.equal(new.quantizer.embed, m.quantizer.embed)
    data, tempo = tempo_codes(new, [clip], range(2))
    x = tempo_inputs(new, clip_features)
    assert np.abs(x[-100:]).min() > 0.05  # the clip's pulse, away from 90 bpm
    for p, (codes, t) in enumerate(zip(data.codes, tempo)):
        np.testing.assert_array_equal(t, x[p + 8 * np.arange(len(codes))])
    before = new.predictor.tempo.weight.detach().clone()
    rows = train_tempo_predictor(new, [clip], [clip], DanceVQTrainOptions(pred_batch=8), steps=20, seed=0,
                                 eval_every=10, progress=False)
    assert [r["step"] for r in rows] == [10, 20] and all(np.isfinite(r["val_ce"]) for r in rows)
    assert not torch.equal(new.predictor.tempo.weight, before)
