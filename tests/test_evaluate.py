"""``performer evaluate``: the driver's pieces on exact signals, and one short run on the shared data."""

from __future__ import annotations

import json
import math
from pathlib import Path

import librosa
import numpy as np
import pytest

from models.evaluation.beats import beat_scores
from models.evaluation.evaluate import (
    REAL_ROW, ROW_KEYS, EvalOptions, _limit, paired_metrics, pooled_beats, positions, segments, span_beats,
    split_dances,
)
from models.rig.motion import POSE_DIM
from models.timebase import SAMPLE_RATE
from realtime import cli
from test_generate import make_checkpoint


def rest_poses(t: int) -> np.ndarray:
    """(t, POSE_DIM) T-pose with the hips at 1 m and identity rotations."""
    p = np.zeros((t, POSE_DIM), np.float32)
    p[:, 1] = 1.0
    p[:, 6::4] = 1.0
    return p


# -- pieces ---------------------------------------------------------------------------------


def test_segments_cover_every_frame_once():
    for n, seg in [(1, 300), (299, 300), (451, 300), (3395, 300), (900, 300)]:
        parts = segments(n, seg)
        assert parts[0].start == 0 and parts[-1].stop == n
        assert all(a.stop == b.start for a, b in zip(parts, parts[1:]))
        assert all(0.5 * seg <= p.stop - p.start <= 1.5 * seg for p in parts) or len(parts) == 1
    assert len(segments(900, 300)) == 3


def test_paired_metrics_identity_and_offset():
    rng = np.random.default_rng(0)
    poses = rest_poses(400)
    poses[:, 3:] += 0.2 * np.sin(np.linspace(0, 20, 400))[:, None] * rng.normal(size=POSE_DIM - 3)[None]
    pos = positions(poses)
    q = np.asarray(poses)[:, 3:].reshape(400, -1, 4)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    same = paired_metrics(pos, pos, q, q, segment=150)
    assert same["rot_l1"] == 0 and same["pos_l1"] == 0 and same["dtw"] == pytest.approx(0, abs=1e-12)
    assert same["lcss"] == 1 and same["pck@0.1"] == 1 and same["dir_f1"] == 1 and same["cosine"] == pytest.approx(1)
    shifted = paired_metrics(pos + np.array([0.0, 0.0, 0.05]), pos, q, q, segment=150)
    assert shifted["pos_l1"] == pytest.approx(0.05 / 3)  # mean over x, y, z
    assert 0.02 < shifted["dtw"] <= 0.05 + 1e-9  # warping may pair closer frames, never farther
    assert "jerk" not in shifted


def test_pooled_beats_weigh_sequences_by_beats():
    rng = np.random.default_rng(1)
    seqs = [np.cumsum(rng.normal(0, 0.02, (n, 3, 3)), axis=0) for n in (300, 600)]
    beats = [np.arange(5, 300, 15), np.arange(3, 600, 20)]
    each = [beat_scores(p, b) for p, b in zip(seqs, beats)]
    pooled = pooled_beats(seqs, beats)
    kin = [e["kinematic_beats"] for e in each]
    mus = [e["music_beats"] for e in each]
    assert pooled["beat_coverage"] == pytest.approx(sum(kin) / sum(mus))
    assert pooled["beat_hit_rate"] == pytest.approx(sum(e["beat_hit_rate"] * k for e, k in zip(each, kin)) / sum(kin))
    assert pooled["beat_hit_chance"] == pytest.approx((each[0]["beat_hit_chance"] * 300 + each[1]["beat_hit_chance"] * 600) / 900)


def _toy_train_set(shift: float = 0.0):
    """A RealSet of two toy 'dances' (C: slow swing, W: fast), 200 frames of FK-shaped positions."""
    from models.evaluation.evaluate import RealSet

    t = np.arange(200)[:, None, None] / 30.0
    clips, pos = [], []
    for style, freq in (("C", 0.5), ("W", 3.0)):
        p = np.zeros((200, 30, 3), np.float32) + np.linspace(0, 1.7, 30)[None, :, None]
        p[..., 0] += (0.3 * np.sin(2 * np.pi * freq * t[..., 0]) + shift).astype(np.float32)
        clips.append(type("Clip", (), {"name": f"DANCE_{style}_1", "style": style, "num_frames": 200})())
        pos.append(p)
    return RealSet(clips, pos, [])


def test_style_classifier_cache_is_keyed_by_the_motion_it_learns(tmp_path):
    """The same dances and frame counts with other motion (as other corpus code, FK or numpy would give)
    train and cache a classifier of their own instead of reusing one trained on the old motion."""
    from models.evaluation.classifier import embed
    from models.evaluation.evaluate import classifier_windows, style_classifier

    a = style_classifier(_toy_train_set(), 1, 0, tmp_path)
    again = style_classifier(_toy_train_set(), 1, 0, tmp_path)
    assert again.cache_key == a.cache_key and len(list(tmp_path.glob("style-classifier-*.pt"))) == 1
    moved = style_classifier(_toy_train_set(shift=1e-3), 1, 0, tmp_path)
    assert moved.cache_key != a.cache_key and len(list(tmp_path.glob("style-classifier-*.pt"))) == 2
    x = classifier_windows(_toy_train_set().positions)
    np.testing.assert_array_equal(embed(again, x), embed(a, x))
    assert style_classifier(_toy_train_set(), 2, 0, tmp_path).cache_key not in (a.cache_key, moved.cache_key)


@pytest.mark.data
def test_the_default_evaluation_judges_with_the_packaged_classifier(dwm_root):
    """The training split at 10 epochs, seed 0 gets the shipped classifier (the same on every machine), not a fresh one."""
    from models.evaluation.evaluate import PACKAGED_CLASSIFIER, RealSet, packaged_classifier, style_classifier

    train, _ = split_dances(dwm_root, EvalOptions())
    judge = packaged_classifier(train, 10, 0)
    assert judge is not None and judge.class_names == ["C", "R", "W"] and judge.trained_on["dances"] == train
    assert packaged_classifier(train, 9, 0) is None and packaged_classifier(train[1:], 10, 0) is None
    clips = [type("Clip", (), {"name": n, "style": n.split("_")[1]})() for n in train]
    used = style_classifier(RealSet(clips, [], []), 10, 0, None)  # no motion needed: it is not trained
    assert used.cache_key == judge.cache_key and PACKAGED_CLASSIFIER.parent.name == "assets"


def test_style_classifier_weights_do_not_follow_the_callers_thread_count():
    """Trained on 2 threads the weights differ; the classifier trains on TRAIN_THREADS whatever the caller set."""
    import torch

    from models.evaluation import classifier as C

    x = np.random.default_rng(0).normal(size=(128, 64, 60)).astype(np.float32)  # two batches of 64
    y = np.arange(len(x)) % 3

    def weights(model) -> bytes:
        return b"".join(v.numpy().tobytes() for v in model.state_dict().values())

    one = weights(C.train_style_classifier(x, y, epochs=1, seed=0, threads=1))
    assert weights(C.train_style_classifier(x, y, epochs=1, seed=0, threads=2)) != one
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        assert weights(C.train_style_classifier(x, y, epochs=1, seed=0)) == one
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)


@pytest.mark.parametrize("first_frame", [0, 14, 31])
def test_music_beats_land_on_clip_frames(first_frame):
    """A click at song time tau is clip frame 30 tau - first_frame - 1 (the frame that ends then)."""
    taus = 1.0 + 0.5 * np.arange(36)
    song = librosa.clicks(times=taus, sr=SAMPLE_RATE, length=20 * SAMPLE_RATE).astype(np.float32)
    beats = span_beats(song, first_frame, 450)
    expected = np.rint(30 * taus).astype(int) - first_frame - 1
    expected = expected[(expected >= 0) & (expected < 450)]
    np.testing.assert_array_equal(beats, expected)


def test_limit_keeps_n_per_style_in_order():
    names = ["DANCE_C_1", "DANCE_C_4", "DANCE_R_2", "DANCE_W_3", "DANCE_W_1", "DANCE_W_9"]
    assert _limit(names, 1) == ["DANCE_C_1", "DANCE_R_2", "DANCE_W_3"]
    assert _limit(names, 2) == ["DANCE_C_1", "DANCE_C_4", "DANCE_R_2", "DANCE_W_3", "DANCE_W_1"]
    assert _limit(names, None) == names


def test_bad_arguments_exit_2(tmp_path, capsys):
    ckpt = make_checkpoint(tmp_path / "t.pt")
    for args, message in [
        (["--checkpoint", ckpt, "--data", tmp_path / "nowhere"], "nowhere"),
        (["--checkpoint", tmp_path / "missing.pt", "--data", tmp_path], "checkpoint not found"),
        (["--checkpoint", ckpt, "--data", tmp_path, "--max-frames", "0"], "--max-frames must be >= 1"),
    ]:
        code = cli.main(["evaluate", *map(str, args), "--quiet"])
        err = capsys.readouterr().err
        lines = err.strip().splitlines()
        assert code == 2 and len(lines) == 1 and lines[0].startswith("performer evaluate: error: "), err
        assert message in err


# -- a short run on the shared data ------------------------------------------------------------


@pytest.fixture(scope="module")
def eval_run(dwm_root, tmp_path_factory):
    """``performer evaluate`` of a tiny random model: 1 dance per style, 300 frames each."""
    tmp = tmp_path_factory.mktemp("eval")
    ckpt = make_checkpoint(tmp / "tiny.pt")
    out, cache = tmp / "out", tmp / "cache"
    code = cli.main(["evaluate", "--checkpoint", str(ckpt), "--data", str(dwm_root), "--out", str(out),
                     "--cache", str(cache), "--dances", "1", "--max-frames", "300", "--classifier-epochs", "1",
                     "--quiet"])
    assert code == 0
    return out, cache, dwm_root


@pytest.mark.slow
@pytest.mark.data
def test_evaluate_writes_every_metric_for_model_and_real_rows(eval_run, capsys):
    out, cache, _ = eval_run
    doc = json.loads((out / "results.json").read_text())
    rows = doc["results"]
    assert list(rows) == ["causal (tiny.pt)", REAL_ROW]
    for name, row in rows.items():
        missing = set(ROW_KEYS) - set(row)
        assert not missing, (name, missing)
        assert row.pop("multimodality") is None  # n/a: a deterministic model, and real data
        assert all(v is not None and math.isfinite(v) for v in row.values()), (name, row)
    model, real = rows["causal (tiny.pt)"], rows[REAL_ROW]
    assert real["rot_l1"] == 0 and real["pos_l1"] == 0 and real["pck@0.2"] == 1 and real["energy_ratio"] == 1
    assert real["band_amp"] == 1 and real["jitter"] == 1
    assert model["pos_l1"] > 0.01 and model["fd"] > real["fd"]  # random weights are not a dancer
    assert doc["commands"][0].startswith("performer evaluate --checkpoint ") and "--max-frames 300" in doc["commands"][0]
    md = (out / "results.md").read_text()
    assert "| real data |" in md and "performer evaluate" in md
    details = json.loads((out / "per_dance.json").read_text())
    real_m = details[REAL_ROW]["band_rms_m"]
    assert 0.01 < real_m["band_amp"] < 0.5 and 0 < real_m["jitter"] < real_m["band_amp"]  # dancers move cm, not mm or m
    for name in rows:
        assert set(details[name]["per_dance"]["DANCE_W_5"]) >= {"band_amp", "jitter", "rot_l1"}
    assert details["_run"]["dances"] == ["DANCE_C_2", "DANCE_R_5", "DANCE_W_5"]
    assert details["_run"]["frames"] == [300, 300, 300]
    assert len(list(cache.glob("style-classifier-*.pt"))) == 1  # trained once, cached


@pytest.mark.slow
@pytest.mark.data
def test_clip_first_frame_is_where_its_features_start(eval_run):
    """Clip features are the song's features from first_frame on, also for cache entries without it."""
    from models.data.dwm import load_dance
    from models.features.audio_io import load_audio
    from models.features.spectral import FeatureConfig, extract_features
    from models.data.corpus import build_corpus

    _, cache, root = eval_run
    _, names = split_dances(root, EvalOptions(dances_per_style=1))
    name = names[0]  # DANCE_C_2: its music starts before the motion
    (clip,) = build_corpus(root, [name], FeatureConfig(), (1.0,), cache, progress=False)
    assert clip.first_frame > 0
    song = extract_features(load_audio(load_dance(Path(root) / name).audio_path)[0])
    np.testing.assert_array_equal(clip.features, song[clip.first_frame : clip.first_frame + clip.num_frames])

    (entry,) = cache.glob(f"{name}-t1.000-*.npz")  # an entry written before first_frame was stored
    with np.load(entry) as z:
        old = {k: z[k] for k in z.files if k != "first_frame"}
    with open(entry, "wb") as fh:
        np.savez(fh, **old)
    (again,) = build_corpus(root, [name], FeatureConfig(), (1.0,), cache, progress=False)
    assert again.first_frame == clip.first_frame
