"""The dancing performer (dance_vq): codebook, predictor, live stream, idle gate, pipeline."""

from __future__ import annotations

import math
from dataclasses import replace as dataclasses_replace

import numpy as np

import pytest
import torch
from _streams import push_in_chunks

from models.errors import CheckpointError, ConfigError
from models.networks import chooser as chooser_part
from models.networks import player as player_part
from models.networks.checkpoint import build_model, load_checkpoint, save_checkpoint
from models.networks.dance_stream import DanceStream, generate
from models.networks.idle_gate import FADE_FRAMES, PRESENT_FRAMES
from models.networks.idle_fade import idle_pose
from models.networks.idle_gate import BREAK_HOLD_SILENT
from models.networks.dance_vq import DanceVQ, DanceVQConfig, style_token
from models.rig.humanoid import BONES
from models.rig.motion import POSE_DIM
from models.training.dance_vq import (DanceVQTrainOptions, codebook_step, encode_clips, predictor_batch,
                                      predictor_loss, synthetic_noise)

TINY = DanceVQConfig(feature_dim=10, codebook=16, code_dim=8, enc_width=16, dec_width=16, d_model=16, layers=1,
                     heads=2, window_codes=4, energy_col=0, clarity_col=-1)


def tiny_model(seed: int = 0) -> DanceVQ:
    torch.manual_seed(seed)
    m = DanceVQ(TINY).eval()
    with torch.no_grad():
        m.gate[0] = -50.0  # silence below -50 in column 0
        for p in m.decoder.out.parameters():  # visible motion from a random decoder
            p.mul_(20.0)
    return m


def music(n: int, seed: int = 0) -> np.ndarray:
    x = np.random.default_rng(seed).normal(size=(n, TINY.feature_dim)).astype(np.float32)
    x[:, 0] = -10.0  # loud
    return x


def quat_angles_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-bone rotation angle (deg) between two poses' quaternions (…, P)."""
    qa, qb = a[..., 3:].reshape(*a.shape[:-1], -1, 4), b[..., 3:].reshape(*b.shape[:-1], -1, 4)
    dot = np.clip(np.abs((qa * qb).sum(-1)), 0, 1)
    return np.degrees(2 * np.arccos(dot))


def test_live_stream_equals_the_whole_song_in_any_chunking():
    m = tiny_model()
    x = music(300)
    whole = generate(m, x, seed=5)
    assert whole.shape == (300, POSE_DIM) and whole.dtype == np.float32 and np.isfinite(whole).all()
    np.testing.assert_allclose(np.linalg.norm(whole[:, 3:].reshape(300, -1, 4), axis=-1), 1.0, atol=1e-5)
    s = DanceStream(m, seed=5)
    # the same codes, so the same poses to float32 rounding (the output's renormalisation runs per push)
    np.testing.assert_allclose(push_in_chunks(s, x), whole, atol=1e-6, rtol=0)
    s.reset()  # same seed again: the same dance
    np.testing.assert_array_equal(s.push(x), whole)
    assert np.all(whole[:, [0, 2]] == 0)  # in place


def test_seed_and_style_change_the_dance_and_bad_styles_are_refused():
    m = tiny_model()
    x = music(200)
    a, b = generate(m, x, seed=1), generate(m, x, seed=2)
    assert np.abs(a - b).max() > 1e-3
    c = generate(m, x, seed=1, style="waltz")
    assert np.abs(a - c).max() > 1e-3
    np.testing.assert_array_equal(generate(m, x, seed=1, style="auto"), a)
    assert style_token(None) == 0 and style_token("W") == 3
    with pytest.raises(ConfigError, match="unknown style 'tango'"):
        generate(m, x, style="tango")
    with pytest.raises(ConfigError, match="unknown style"):
        DanceStream(m).set_style("salsa")


def test_silence_settles_to_a_calm_idle_and_music_brings_the_dance_back_without_a_jump():
    m = tiny_model()
    x = music(600)
    x[200:400, 0] = -100.0  # 6.7 s of silence
    s = DanceStream(m, seed=0, feet=False)  # the idle pose exactly: the feet step (tests/test_feet.py) bends its legs
    weights, poses = [], []
    for row in x:
        poses.append(s.push(row[None])[0])
        weights.append(s.idle_weight)
    w, p = np.array(weights), np.array(poses)
    # a stream starts at rest and fades in on music
    assert w[0] == pytest.approx(1.0 - 1 / FADE_FRAMES) or w[0] == 1.0
    assert w[PRESENT_FRAMES + FADE_FRAMES + 2] == 0.0
    # silence: the song's break held for BREAK_HOLD_SILENT frames, then idle within 3 s, and held
    settle = 200 + BREAK_HOLD_SILENT + FADE_FRAMES
    assert settle - 200 <= 90 and np.all(w[settle:400] == 1.0) and np.all(w[30:200 + BREAK_HOLD_SILENT - 1] == 0.0)
    idle = idle_pose(s._idle_base, np.arange(settle, 400))
    assert quat_angles_deg(p[settle:400], idle).max() < 0.01
    # the idle is calm: a small sway, far less than the dance moves
    sway = quat_angles_deg(p[settle + 1:400], p[settle:399]).max()
    dance = quat_angles_deg(p[60:199], p[59:198]).max()
    assert sway < 0.5 < dance
    # music again: dancing within PRESENT + FADE frames (< 1 s)
    back = 400 + PRESENT_FRAMES + FADE_FRAMES
    assert back - 400 < 30 and np.all(w[back:] == 0.0)
    # no snap: no frame-to-frame step during the fades is larger than the dance's own
    fades = np.r_[200:settle + 1, 400:back + 1]
    assert quat_angles_deg(p[fades], p[fades - 1]).max() <= dance + 1e-3


def test_forced_idle_holds_whatever_the_music():
    m = tiny_model()
    s = DanceStream(m, seed=0)
    s.push(music(100))
    assert s.idle_weight == 0.0
    s.set_idle(True)
    s.push(music(FADE_FRAMES + 5, seed=1))
    assert s.idle_weight == 1.0
    s.set_idle(False)
    s.push(music(FADE_FRAMES + 5, seed=2))
    assert s.idle_weight == 0.0


def test_non_finite_features_are_counted_and_poses_stay_valid():
    m = tiny_model()
    x = music(50)
    x[10, 3] = np.nan
    x[11, :] = np.inf
    s = DanceStream(m)
    y = s.push(x)
    assert s.nonfinite_frames == 2 and np.isfinite(y).all()
    with pytest.raises(ConfigError, match=r"shape \(frames, 10\)"):
        s.push(np.zeros((3, 9), np.float32))


@pytest.mark.parametrize("cfg", [TINY, DanceVQConfig(feature_dim=12, codebook=40, code_dim=8, enc_width=16,
                                                     dec_width=16, d_model=32, layers=3, heads=4, window_codes=6),
                                 dataclasses_replace(TINY, tempo_input=True)])
def test_numpy_predictor_gives_the_torch_predictors_logits(cfg):
    """The live path's NumPy predictor (models/networks/dance_numpy.py) against the torch module it copies:
    the whole window at once, and the newest row after the others were computed ahead (Prefix); with the
    tempo input (``tempo_input``), each token's own ln(T / T_ref)."""
    from models.networks.dance_numpy import NumpyPredictor, Prefix, single_thread_blas

    torch.manual_seed(1)
    m = DanceVQ(cfg).eval()
    fast = NumpyPredictor(m.predictor)
    rng = np.random.default_rng(0)
    for n in range(1, cfg.window_codes + 1):
        audio = rng.normal(size=(n, cfg.seg * cfg.feature_dim)).astype(np.float32)
        prev = rng.integers(0, cfg.codebook + 1, n)  # codebook = "no code yet"
        tempo = rng.normal(size=n) * 0.3 if cfg.tempo_input else np.zeros(n)
        for style in range(cfg.num_styles + 1):
            ref = m.next_logits(audio, prev, style, tempo if cfg.tempo_input else None)
            with single_thread_blas():
                tokens = [fast.with_tempo(fast.embed(a, int(p)), t) for a, p, t in zip(audio, prev, tempo)]
                whole = fast.logits(np.stack(tokens), style)
                ahead = Prefix(fast, tokens[:-1], style)
                if n > 1:
                    ahead.step()  # some pieces ahead, the rest when the newest token is there
                row = fast.logits_after(ahead, tokens[-1])
            for got in (whole, row):
                assert got.shape == ref.shape == (cfg.codebook,) and got.dtype == np.float32
                np.testing.assert_allclose(got, ref, atol=1e-5 * max(1.0, float(np.abs(ref).max())), rtol=0)


def test_the_pieces_ahead_level_the_even_and_odd_hops_of_four_staggered_performers(monkeypatch):
    """A 3-layer predictor's 7 pieces ahead (models/networks/dance_numpy.py, Prefix) fall on the frames
    of the 8-frame cycle that PIECES_BY_8 gives: layer 0's first feed-forward half on frame 2, the only
    piece on an even frame, so that with 4 performers staggered by 2 frames (every code step on an even
    hop) the even hops (a code step and it) cost what the odd ones do (the other pieces and the
    handover's reads); none on the code step nor on frame 4 (the code step of a performer staggered
    by half a cycle)."""
    import models.networks.dance_numpy as dance_numpy

    torch.manual_seed(0)
    m = DanceVQ(dataclasses_replace(TINY, layers=3, window_codes=6)).eval()
    assert m.config.seg == 8
    s = DanceStream(m, seed=0)
    seen: dict[int, list[tuple[str, int]]] = {}
    step = dance_numpy.Prefix.step

    def counted(pre):
        if s.frame >= 8 * 8:  # a full window: every piece there
            seen.setdefault(s.frame, []).append(pre._todo[pre._next])
        step(pre)

    monkeypatch.setattr(dance_numpy.Prefix, "step", counted)
    s.push(music(8 * 12))
    by_position = {f % 8: kinds for f, kinds in seen.items()}
    assert all(seen[f] == by_position[f % 8] for f in seen)  # the same every cycle
    assert by_position == {1: [("attn", 0)], 2: [("ff1", 0)], 3: [("ff2", 0), ("attn", 1)],
                           5: [("ff1", 1), ("ff2", 1)], 7: [("attn", 2)]}


def test_the_fades_row_norms_and_products_are_numpys_bit_for_bit():
    """IdleFade's row norms and quaternion products without NumPy's Python wrappers
    (models/networks/dance_stream.py, _row_norms, _qmul) give np.linalg.norm's and moveaxis's bytes."""
    from models.networks.idle_fade import _qmul, _row_norms

    rng = np.random.default_rng(7)
    for n, k in ((21, 3), (21, 4), (1, 3), (55, 4)):
        x = rng.normal(size=(n, 4))[:, :k] * 10.0 ** rng.uniform(-8, 3, (n, 1))  # a strided view, as rel[:, :3]
        assert _row_norms(x).tobytes() == np.linalg.norm(x, axis=1).tobytes()
        assert _row_norms(x, True).tobytes() == np.linalg.norm(x, axis=1, keepdims=True).tobytes()
    a, b = rng.normal(size=(21, 4)), rng.normal(size=(21, 4))
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    ref = np.stack([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                    aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz], axis=-1)
    assert _qmul(a, b).tobytes() == ref.tobytes()


def test_compiled_frame_kernels_give_the_numpy_arithmetic_bit_for_bit():
    """The kernels of a performer's ordinary frame (models/networks/dance_jit.py) against the NumPy
    code they replaced: the same float32 values, not merely close ones, so codes and poses do not
    move (the layer norm's and GELU's sums paired as NumPy pairs them; einsum's four products)."""
    from models.networks.blend import blend_track
    from models.networks.dance_jit import gelu_bias, layer_norm_rows, push_history, renorm_pose, sanitize_rows
    from models.networks.dance_numpy import _gelu, _layer_norm
    from models.networks.streaming import FEATURE_LIMIT, sanitize_features

    rng = np.random.default_rng(5)
    for d in (16, 128, 200, 1000):  # up to a block of 128, and the pairwise split beyond
        x = (rng.normal(size=(15, d)) * 3 + 1).astype(np.float32)
        w, b = rng.normal(size=d).astype(np.float32), rng.normal(size=d).astype(np.float32)
        np.testing.assert_array_equal(layer_norm_rows(x, w, b, 1e-5), _layer_norm(x, w, b, 1e-5))
        u = (rng.normal(size=(15, d)) * 2).astype(np.float32)
        ref = _gelu(u + b)
        gelu_bias(u, b)
        np.testing.assert_array_equal(u, ref)
    feats = rng.normal(scale=50.0, size=(40, 12)).astype(np.float32)
    feats[3, 2], feats[7, 0], feats[7, 5], feats[9, 1], feats[11, 4] = np.nan, np.inf, -np.inf, 3e5, -2e4
    clean = np.empty_like(feats)
    ref, n_bad = sanitize_features(feats)
    assert sanitize_rows(feats, clean, FEATURE_LIMIT) == n_bad == 2
    np.testing.assert_array_equal(clean, ref)
    hist, mean, std = np.zeros((8, 12), np.float32), clean.mean(0), clean.std(0) + 1
    push_history(hist, clean[0], mean, std)
    push_history(hist, clean[1], mean, std)
    np.testing.assert_array_equal(hist[-2:], (clean[:2] - mean) / std)
    assert not hist[:-2].any()
    prev = None
    for scale in rng.uniform(0.3, 3.0, 50).astype(np.float32):
        pose = rng.normal(size=POSE_DIM).astype(np.float32) * scale
        q = pose[3:].reshape(-1, 4).copy()  # the NumPy renormalisation it replaced
        q /= np.sqrt(np.einsum("jc,jc->j", q, q))[:, None]
        if prev is not None:
            q[np.einsum("jc,jc->j", q, prev) < 0.0] *= -1.0
        out = np.empty_like(pose)
        assert renorm_pose(pose, np.zeros((0, 4), np.float32) if prev is None else prev, out)
        np.testing.assert_array_equal(out[3:], q.ravel())
        np.testing.assert_array_equal(out[:3], pose[:3])
        np.testing.assert_allclose(out, blend_track(pose[None, None], np.ones((1, 1)), prev)[0], atol=1e-6)
        prev = q
    pose[7:11] = 0.0  # a zero quaternion: the caller's general path
    assert not renorm_pose(pose, prev, out)


def test_sampling_draws_what_rng_choice_draws():
    """DanceVQ.sample replays Generator.choice(p=...) without its checks: same codes, same generator state."""
    m = tiny_model()
    logits = np.random.default_rng(3).normal(scale=3.0, size=(2000, TINY.codebook)).astype(np.float32)
    a, b = np.random.default_rng(9), np.random.default_rng(9)
    for lg in logits:
        z = lg.astype(np.float64) / TINY.temperature
        p = np.exp(z - z.max())
        assert m.sample(lg, a) == int(b.choice(len(p), p=p / p.sum()))
    assert a.bit_generator.state == b.bit_generator.state


def test_idle_pose_is_the_scipy_composition_it_replaced():
    from scipy.spatial.transform import Rotation

    from models.networks.idle_fade import SWAY, IdleSway
    from models.rig.humanoid import BONE_INDEX
    from models.timebase import FPS

    base = DanceStream(tiny_model())._idle_base
    t = np.arange(0, 20000, 3)
    ref = np.repeat(base[None].astype(np.float64), len(t), axis=0)
    for bone, axis, deg, period, phase in SWAY:
        i = 3 + 4 * BONE_INDEX[bone]
        vec = np.zeros((len(t), 3))
        vec[:, axis] = np.deg2rad(deg) * np.sin(2 * np.pi * (t / FPS) / period + phase)
        ref[:, i: i + 4] = (Rotation.from_quat(ref[:, i: i + 4]) * Rotation.from_rotvec(vec)).as_quat()
    np.testing.assert_allclose(idle_pose(base, t), ref.astype(np.float32), atol=1e-7, rtol=0)
    sway = IdleSway(base)
    np.testing.assert_array_equal(np.concatenate([sway(np.array([k])) for k in t[:50]]), idle_pose(base, t[:50]))


def test_streams_of_one_model_share_its_predictor_exemplars_and_dips_until_they_change():
    """An ensemble's performers of one checkpoint hold one copy of what they only read; a
    weight written in place (a training step) gives the next stream fresh copies."""
    from models.networks.dance_numpy import NumpyPredictor

    m = tiny_model()
    with torch.no_grad():
        m.member_poses.copy_(m.pose_mean.to(m.member_poses.dtype))
        m.member_count.fill_(1)
    a, b = DanceStream(m), DanceStream(m)
    assert a._chooser.dips is b._chooser.dips and a._chooser.members is b._chooser.members \
        and a._chooser.predictor is b._chooser.predictor
    with torch.no_grad():
        m.member_poses[0, 0, :, 4] += 0.5  # written in place: the version counter moves
    c = DanceStream(m)
    assert c._chooser.dips is not a._chooser.dips and c._chooser.dips.shape == a._chooser.dips.shape
    assert c._chooser.members is not a._chooser.members \
        and c._chooser.members[0, 0, 0, 4] != a._chooser.members[0, 0, 0, 4]
    assert c._chooser.predictor is a._chooser.predictor  # the predictor did not change
    with torch.no_grad():
        m.predictor.head.weight.add_(1.0)
    d = DanceStream(m)
    assert d._chooser.predictor is not a._chooser.predictor
    np.testing.assert_array_equal(d._chooser.predictor.w_head, NumpyPredictor(m.predictor).w_head)
    np.testing.assert_allclose(d._chooser.predictor.w_head - a._chooser.predictor.w_head, 1.0, atol=1e-6)


def test_decoder_is_causal_over_codes():
    m = tiny_model()
    zq = torch.randn(1, TINY.code_dim, 12)
    y = m.decoder(zq)
    zq2 = zq.clone()
    zq2[..., 7:] += 1.0  # change codes from 7 on
    y2 = m.decoder(zq2)
    seg = TINY.seg
    torch.testing.assert_close(y[:, : 7 * seg], y2[:, : 7 * seg])
    assert (y[:, 7 * seg:] - y2[:, 7 * seg:]).abs().max() > 1e-4
    # the last segment of a window of decoder_context codes equals the full pass (streaming decode)
    full = m.decoder(zq)[0, 11 * seg:]
    win = m.decoder(zq[..., 12 - TINY.decoder_context:])[0, -seg:]
    torch.testing.assert_close(full, win)


def _poses(t: int, rng: np.random.Generator) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    phase = 2 * np.pi * np.arange(t) / 30.0
    rot = np.zeros((t, len(BONES), 3))
    rot[:, :, 2] = 0.4 * np.sin(phase[:, None] + rng.uniform(0, 6, len(BONES)))
    q = Rotation.from_rotvec(rot.reshape(-1, 3)).as_quat().reshape(t, -1).astype(np.float32)
    root = np.zeros((t, 3), np.float32)
    root[:, 1] = 1.0
    return np.concatenate([root, q], 1)


def memory_model(poses: np.ndarray) -> DanceVQ:
    """A tiny dance_vq with 3 exemplars a code, its pose statistics set from ``poses`` (T, P)."""
    torch.manual_seed(0)
    m = DanceVQ(dataclasses_replace(TINY, members=3))
    m.pose_mean.copy_(torch.from_numpy(poses.mean(0)))
    m.pose_std.copy_(torch.from_numpy(np.maximum(poses.std(0), 0.02)))
    return m


class _Clip:
    def __init__(self, poses, features, style):
        self.poses, self.features, self.style = poses, features, style
        self.valid = np.ones(len(poses), bool)
        self.num_frames = len(poses)
        self.tempo = 1.0


def test_codebook_and_predictor_learn_on_a_toy_dance():
    from models.rig.skeleton import load_default_skeleton

    rng = np.random.default_rng(0)
    torch.manual_seed(0)
    m = DanceVQ(TINY)
    poses = _poses(512, rng)
    m.pose_mean.copy_(torch.from_numpy(poses.mean(0)))
    m.pose_std.copy_(torch.from_numpy(np.maximum(poses.std(0), 0.02)))
    offsets = torch.from_numpy(load_default_skeleton().offsets).float()
    opts = DanceVQTrainOptions(vq_segment=64)
    opt = torch.optim.Adam([*m.encoder.parameters(), *m.decoder.parameters()], lr=3e-3)
    m.train()
    rows = []
    for _ in range(60):
        s = rng.integers(0, 512 - 64, 8)
        rows.append(codebook_step(m, torch.from_numpy(np.stack([poses[i: i + 64] for i in s])), offsets, opts, opt))
    assert np.mean([r["loss_pose"] for r in rows[-5:]]) < 0.9 * np.mean([r["loss_pose"] for r in rows[:5]])
    feats = rng.normal(size=(512, TINY.feature_dim)).astype(np.float32)
    codes = encode_clips(m, [_Clip(poses, feats, "W")], range(2))
    assert len(codes.codes) == 2 and codes.tokens[0].shape == (64, TINY.seg * TINY.feature_dim)
    assert codes.style == [3, 3]
    # a checkpoint whose features carry the idle gate's steadiness column past feature_dim
    # (the shipped one): the predictor's tokens are the same, the extra column left out
    wide = encode_clips(m, [_Clip(poses, np.concatenate([feats, feats[:, :1]], 1), "W")], range(2))
    np.testing.assert_array_equal(wide.tokens[0], codes.tokens[0])
    popt = torch.optim.Adam(m.predictor.parameters(), lr=3e-3)
    ce = []
    for _ in range(40):
        loss, _ = predictor_loss(m, predictor_batch(codes, TINY.window_codes, 16, TINY.codebook, opts, rng))
        popt.zero_grad()
        loss.backward()
        popt.step()
        ce.append(loss.item())
    assert np.mean(ce[-5:]) < np.mean(ce[:5])


def tiny_checkpoint(path):
    """A small dance_vq checkpoint on the shipped feature kind (MFCC + onset, context, beat): (path, config, features)."""
    from models.features.spectral import FeatureConfig

    fcfg = FeatureConfig(kind="mfcc_onset", n_mels=32, context_s=60.0, beat_phase=True)
    cfg = DanceVQConfig(feature_dim=fcfg.dim, codebook=16, code_dim=8, enc_width=16, dec_width=16, d_model=16,
                        layers=1, heads=2, clarity_col=fcfg.dim - 2)
    torch.manual_seed(0)
    m = build_model("dance_vq", cfg)
    path = save_checkpoint(path, m, model_name="dance_vq", generator_config=m.config,
                           feature_config={**fcfg.to_dict(), "fingerprint": fcfg.fingerprint()},
                           rig={"bones": list(BONES), "pose_dim": POSE_DIM})
    return path, cfg, fcfg


def test_checkpoint_round_trip_and_the_engine_pipeline(tmp_path):
    from realtime.pipeline import build_pipeline

    path, cfg, fcfg = tiny_checkpoint(tmp_path / "d.pt")
    m2, meta = load_checkpoint(path)
    assert isinstance(m2, DanceVQ) and meta["model_name"] == "dance_vq" and m2.config == cfg
    pipe = build_pipeline(path, seed=3, style="rumba")
    assert isinstance(pipe.model, DanceStream) and pipe.model.style == 2 and pipe.model.seed == 3
    ext = pipe.extractor_factory(44100)
    feats = ext.push(np.random.default_rng(0).normal(scale=0.1, size=44100).astype(np.float32))
    assert pipe.model.push(feats).shape == (len(feats), POSE_DIM)
    from models.networks.causal import CausalGenerator

    causal = tmp_path / "c.pt"
    c = build_model("causal", {"feature_dim": fcfg.dim, "channels": [8, 8, 8, 8, 8]})
    assert isinstance(c, CausalGenerator)
    save_checkpoint(causal, c, model_name="causal", generator_config=c.config,
                    feature_config={**fcfg.to_dict(), "fingerprint": fcfg.fingerprint()},
                    rig={"bones": list(BONES), "pose_dim": POSE_DIM})
    build_pipeline(causal)  # loads and runs without a style
    with pytest.raises(CheckpointError, match="takes no style"):
        build_pipeline(causal, style="waltz")


@pytest.mark.parametrize("kind", ["white", "pink", "brown", "applause", "crowd", "room"])
def test_synthetic_noise_is_finite_and_bounded(kind):
    x = synthetic_noise(kind, 1.0, np.random.default_rng(0))
    assert x.shape == (22050,) and x.dtype == np.float32 and np.isfinite(x).all() and 0 < np.abs(x).max() <= 1.0
    with pytest.raises(ConfigError):
        synthetic_noise("jazz", 1.0, np.random.default_rng(0))


def test_member_dips_mark_where_the_movement_stops():
    from scipy.spatial.transform import Rotation

    from models.networks.dance_stream import member_dips

    t = np.arange(18)
    angle = np.where(t < 5, 0.15 * t, 0.75 + 0.15 * (t - 5))  # steady swing...
    angle[5:8] = 0.75  # ...that stops at frames 5-7
    angle[8:] = 0.75 + 0.15 * (t[8:] - 7)
    rot = np.zeros((18, len(BONES), 3))
    rot[:, BONES.index("RightUpperArm"), 2] = angle
    rot[:, BONES.index("LeftUpperArm"), 2] = angle
    q = Rotation.from_rotvec(rot.reshape(-1, 3)).as_quat().reshape(18, -1)
    w = np.concatenate([np.tile([0.0, 1.0, 0.0], (18, 1)), q], 1).astype(np.float32)
    dips = member_dips(w[None, None], 8)
    assert dips.shape == (1, 1, 8)
    assert dips[0, 0, 6] == 1.0 and dips[0, 0, :4].sum() == 0


def test_choreographic_memory_plays_real_movements_at_their_scale_and_hands_over_smoothly():
    from models.networks.blend import seam_ratio
    from models.training.dance_vq import fit_members

    rng = np.random.default_rng(0)
    poses = _poses(900, rng)
    m = memory_model(poses)
    cfg = m.config
    with torch.no_grad():
        m.gate[0] = -50.0
    info = fit_members(m, [_Clip(poses, np.zeros((900, 10), np.float32), "C")])
    assert info["codes_with_members"] >= 1 and bool((m.member_count > 0).all())  # unused codes borrow a neighbour's
    assert int(m.member_count.max()) <= 3
    m.eval()
    out = generate(m, music(600), seed=0)[60:]  # after the fade-in from rest
    assert np.isfinite(out).all()
    # real movements at their own scale: the bones swing about as far as in the data
    ang = lambda p: quat_angles_deg(p, np.tile(poses.mean(0), (len(p), 1)))  # noqa: E731
    assert ang(out).std() > 0.5 * ang(poses).std()
    # handovers between exemplars are invisible: no extra angular acceleration at movement starts
    assert seam_ratio(out, cfg.seg, cfg.seg, radius=1) < 1.5


def test_no_movement_is_drawn_over_and_over(monkeypatch):
    """A code drawn n >= 4 times among the last 8 draws has its logit lowered by n - 3 (scaled
    down to none for calm codes, energy z -1 or less), no other code's. On the bundled clip (shipped performer, seeds 0-7) that keeps the movements in runs
    of 6 or more of one code to 24 of 960 (longest 6); without the penalty the predictor, its
    window full of one code, keeps drawing it: 72 (longest 8)."""
    import models.networks.dance_stream as ds
    from models.features.audio_io import load_audio
    from models.features.spectral import extract_features
    from models.generate import load_model

    lm = load_model(None)
    s = ds.DanceStream(lm.model, seed=0)
    z = s._chooser.code_energy
    lively, calm, other = int(np.argmax(z)), int(np.argmin(z)), int(np.argsort(z)[len(z) // 2 + 50])
    logits = np.zeros(lm.model.config.codebook, np.float32)
    s.codes_drawn = [calm] * 3 + [lively, lively, other, lively, lively, lively, other, other]  # the last 8: 5 and 3
    out = s._chooser.repeat_penalty(logits, s.codes_drawn)
    assert out[lively] == -2.0 and np.count_nonzero(out) == 1 and not logits.any()
    s.codes_drawn += [calm] * 5  # a calm code (energy z <= -1) repeats freely: holding still is no shuffle
    assert z[calm] <= -1.0 and not s._chooser.repeat_penalty(logits, s.codes_drawn).any()

    feats = extract_features(load_audio("models/assets/clip.ogg")[0], lm.features)

    def runs() -> np.ndarray:
        out = []
        for seed in range(8):
            st = ds.DanceStream(lm.model, seed=seed)
            st.push(feats)
            c = np.asarray(st.codes_drawn)
            out.append(np.diff(np.concatenate(([0], np.flatnonzero(np.diff(c) != 0) + 1, [c.size]))))
        return np.concatenate(out)

    r = runs()
    assert r[r >= 6].sum() <= 30 and r.max() <= 7
    monkeypatch.setattr(chooser_part, "REPEAT_PENALTY", 0.0)
    r = runs()
    assert r[r >= 6].sum() >= 60 and r.max() >= 8  # the clip asks for long runs: the limit above is the penalty's


def _inertialize_reference(window: np.ndarray, cont: np.ndarray, decay: np.ndarray, cap: float) -> np.ndarray:
    """Rotation-space inertialization with SciPy's Rotation: per bone, offset = rotvec(cont0 w0^-1),
    velocity gap = rotvec(cont1 cont0^-1) - rotvec(w1 w0^-1) (capped), applied as
    exp(h0 offset + h1 gap) before the exemplar's rotation over the decay's frames."""
    from scipy.spatial.transform import Rotation as R

    out = window.astype(np.float64).copy()
    d = decay.shape[1]
    out[:d, :3] += decay[0][:, None] * (cont[0, :3] - window[0, :3]) \
        + decay[1][:, None] * ((cont[1, :3] - cont[0, :3]) - (window[1, :3] - window[0, :3]))
    for c in range(3, window.shape[1], 4):
        w, k = R.from_quat(window[:, c:c + 4].astype(np.float64)), R.from_quat(cont[:, c:c + 4].astype(np.float64))
        r0 = (k[0] * w[0].inv()).as_rotvec()
        gap = (k[1] * k[0].inv()).as_rotvec() - (w[1] * w[0].inv()).as_rotvec()
        gap *= min(1.0, cap / max(np.linalg.norm(gap), 1e-12))
        q = (R.from_rotvec(decay[0][:, None] * r0 + decay[1][:, None] * gap) * w[:d]).as_quat()
        q *= np.where((q * window[:d, c:c + 4]).sum(1, keepdims=True) < 0, -1.0, 1.0)  # the exemplar's signs
        out[:d, c:c + 4] = q
    return out.astype(np.float32)


def test_compiled_motion_matching_picks_and_bends_as_scipy_rotations_do():
    """match_exemplar (one numba call on the live path): the exemplar the cost picks (less each one's
    bias), sign-aligned to the motion, bent from it by rotation-space inertialization (SciPy's Rotation as the reference)."""
    from models.networks.dance_jit import match_exemplar
    from models.networks.dance_stream import _unit, sign_continuous
    from models.networks.player import hermite_decay

    rng = np.random.default_rng(5)
    decay = hermite_decay(16)
    agree = 0
    for trial in range(200):
        n = int(rng.integers(1, 4))
        cands = _unit(sign_continuous(np.cumsum(rng.normal(scale=0.05, size=(n, 16, POSE_DIM)), 1)
                                      .astype(np.float32) + rng.normal(size=(n, 1, POSE_DIM)).astype(np.float32)))
        cont = _unit(rng.normal(size=(2, POSE_DIM)).astype(np.float32))
        cont[1] = _unit(cont[0] + rng.normal(scale=0.05, size=POSE_DIM).astype(np.float32))
        dips = (rng.random((n, 8)) < 0.3).astype(np.float32)
        frame = int(rng.integers(-1, 8))
        bonus = float(rng.random())
        q = cands[..., 3:].reshape(n, 16, -1, 4)  # each bone's signs onto cont[0]'s hemisphere
        a = cands.copy()
        a[..., 3:] = (q * np.where((q[:, :1] * cont[0, 3:].reshape(-1, 4)).sum(-1, keepdims=True) < 0, -1, 1)
                      ).reshape(n, 16, -1)
        cost = np.abs(a[:, 0] - cont[0]).sum(1) + 4.0 * np.abs((a[:, 1] - a[:, 0]) - (cont[1] - cont[0])).sum(1)
        cost = cost / max(float(np.median(cost)), 1e-9)
        if frame >= 0:
            cost -= bonus * dips[:, frame]
        bias = rng.normal(scale=0.5, size=n) if trial % 3 == 0 else np.zeros(n)  # a library's liveliness at the tempo
        cost -= bias
        want_i = int(np.argmin(cost))
        cap = 0.4 if trial % 2 else 10.0
        want = _inertialize_reference(a[want_i], cont, decay, cap)
        got_i, got = match_exemplar(cands, dips, cont, decay, frame, bonus, 8, cap, bias)
        assert got.shape == want.shape and got.dtype == np.float32
        if n == 1 or np.ptp(np.sort(cost)[:2]) > 1e-5:  # no near tie: the same exemplar, the same poses
            assert got_i == want_i
            np.testing.assert_allclose(got, want, atol=2e-5)
            agree += 1
    assert agree > 150


# The code step's kernels as they were before they made no array per bone and frame (their arithmetic,
# the reference the allocation-free ones in models/networks/dance_jit.py must give bit for bit).
def _qmul_arrays(a, b):  # pragma: no cover - compiled
    ax, ay, az, aw = a[0], a[1], a[2], a[3]
    bx, by, bz, bw = b[0], b[1], b[2], b[3]
    return np.array([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz])


def _qlog_arrays(q):  # pragma: no cover - compiled
    x, y, z, w = q[0], q[1], q[2], q[3]
    if w < 0:
        x, y, z, w = -x, -y, -z, -w
    s = math.sqrt(x * x + y * y + z * z)
    k = 2.0 * math.atan2(s, w) / s if s > 1e-12 else 2.0
    return np.array([k * x, k * y, k * z])


def _qexp_arrays(r):  # pragma: no cover - compiled
    a = math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
    k = math.sin(0.5 * a) / a if a > 1e-12 else 0.5
    return np.array([k * r[0], k * r[1], k * r[2], math.cos(0.5 * a)])


def _bend_arrays(w, out, cont, decay, vel_cap):  # pragma: no cover - compiled
    """match_exemplar's per-bone bend of window ``w`` into ``out`` (its rows nd and on untouched)."""
    nd = min(decay.shape[1], w.shape[0])
    for c in range(3, w.shape[1], 4):
        c0, c1 = cont[0, c:c + 4].astype(np.float64), cont[1, c:c + 4].astype(np.float64)
        w0, w1 = w[0, c:c + 4].astype(np.float64), w[1, c:c + 4].astype(np.float64)
        inv0 = np.array([-w0[0], -w0[1], -w0[2], w0[3]])
        inv_c0 = np.array([-c0[0], -c0[1], -c0[2], c0[3]])
        r0 = _qlog_arrays(_qmul_arrays(c0, inv0))
        d1 = _qlog_arrays(_qmul_arrays(c1, inv_c0)) - _qlog_arrays(_qmul_arrays(w1, inv0))
        norm = math.sqrt(d1[0] * d1[0] + d1[1] * d1[1] + d1[2] * d1[2])
        if norm > vel_cap:
            d1 *= vel_cap / norm
        for j in range(nd):
            wj = w[j, c:c + 4].astype(np.float64)
            q = _qmul_arrays(_qexp_arrays(decay[0, j] * r0 + decay[1, j] * d1), wj)
            qn = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
            if q[0] * wj[0] + q[1] * wj[1] + q[2] * wj[2] + q[3] * wj[3] < 0:
                qn = -qn
            for k in range(4):
                out[j, c + k] = q[k] / qn


def _bone_rotations_arrays(window, f, parents, g):  # pragma: no cover - compiled
    """joint_speed's bone rotations of frame ``f`` into ``g`` (J, 4), with an array per bone."""
    q = np.zeros(4)
    for j in range(g.shape[0]):
        s = 0.0
        for k in range(4):
            q[k] = window[f, 3 + 4 * j + k]
            s += q[k] * q[k]
        s = math.sqrt(s) if s > 1e-18 else 1.0
        for k in range(4):
            q[k] /= s
        p = parents[j]
        g[j] = q.copy() if p < 0 else _qmul_arrays(g[p], q)


def test_the_code_steps_kernels_give_their_array_arithmetic_bit_for_bit():
    """match_exemplar's bend and joint_speed's bone rotations (bone_rotations) run on float64 scalars, no
    array made per bone and frame (the motion matching 0.108 -> 0.042 ms a code step, docs/latency.md's "Where a
    hop goes"): the same values as the array code they replaced (above), bit for bit, so no code step's
    movement moves (random windows, near and far from the motion, capped and not; rotations through w = 0;
    a zero quaternion)."""
    from numba import njit

    import models.networks.dance_jit as dj
    from models.networks.dance_stream import _unit, sign_continuous
    from models.networks.player import hermite_decay
    from models.rig.skeleton import POINT_PARENT_INDEX

    for f in (_qmul_arrays, _qlog_arrays, _qexp_arrays):  # the reference kernels call each other by these names
        globals()[f.__name__] = njit(getattr(f, "py_func", f))
    bend, rotations = njit(_bend_arrays), njit(_bone_rotations_arrays)
    rng = np.random.default_rng(3)
    decay = hermite_decay(16)
    for trial in range(300):
        n, scale = int(rng.integers(1, 5)), float(rng.choice([0.01, 0.05, 0.5]))
        cands = _unit(sign_continuous(np.cumsum(rng.normal(scale=scale, size=(n, 16, POSE_DIM)), 1).astype(np.float32)
                                      + rng.normal(size=(n, 1, POSE_DIM)).astype(np.float32)))
        cont = _unit(rng.normal(size=(2, POSE_DIM)).astype(np.float32))
        cont[1] = cont[0] if trial % 7 == 0 else _unit(cont[0] + rng.normal(scale=scale, size=POSE_DIM).astype(np.float32))
        cap = (0.4, 10.0, 0.01)[trial % 3]
        i, got = dj.match_exemplar(cands, np.zeros((n, 8), np.float32), cont, decay, -1, 0.0, 8, cap, np.zeros(n))
        w = cands[i].copy()
        q = w[:, 3:].reshape(16, -1, 4)
        q *= np.where((q[:1] * cont[0, 3:].reshape(-1, 4)).sum(-1, keepdims=True) < 0, -1.0, 1.0).astype(np.float32)
        want = got.copy()
        bend(w, want, cont, decay, cap)
        dj._unit_rows(want)
        np.testing.assert_array_equal(got[:, 3:], want[:, 3:])
    parents = np.array(POINT_PARENT_INDEX, np.int64)
    nb = (POSE_DIM - 3) // 4
    for trial in range(200):
        window = rng.normal(size=(16, POSE_DIM)).astype(np.float32)
        window[3, 7:11] = 0.0 if trial % 5 == 0 else window[3, 7:11]
        for f in (0, 3, 15):
            got, want = np.zeros((nb, 4)), np.zeros((nb, 4))
            dj.bone_rotations(window, f, parents, got)
            rotations(window, f, parents, want)
            assert got.tobytes() == want.tobytes()


def test_a_token_embedded_a_frame_at_a_time_is_its_whole_embedding_bit_for_bit():
    """The stream adds each coming token's frames to its audio MLP's first layer as they arrive
    (NumpyPredictor.embed_frame on frames 1-7 of the cycle), so the code step adds the newest
    frame only: the token is the whole embedding's, bit for bit (the sums in the same order), and
    a stream that does it plays what one embedding each token at its code step plays."""
    from models.networks.dance_numpy import NumpyPredictor

    cfg = dataclasses_replace(TINY, seg=8)
    torch.manual_seed(2)
    pred = NumpyPredictor(DanceVQ(cfg).eval().predictor)
    rng = np.random.default_rng(4)
    for prev in (0, 5, cfg.codebook):
        frames = (rng.normal(size=(cfg.seg, cfg.feature_dim)) * 3).astype(np.float32)
        acc = pred.embed_start()
        for r in range(cfg.seg - 1):
            pred.embed_frame(acc, frames[r], r)
        np.testing.assert_array_equal(pred.embed_last(acc, frames[-1], prev), pred.embed(frames.reshape(-1), prev))
    m, x = tiny_model(), music(200, seed=3)
    s = DanceStream(m, seed=1)
    whole = DanceStream(m, seed=1)
    whole._embed_rows = -1  # never summed ahead: every token embedded whole at its code step
    for i in range(len(x)):  # one frame a push, as the engine pushes
        np.testing.assert_array_equal(s.push(x[i:i + 1]), whole.push(x[i:i + 1]))
        whole._embed_rows = -1
    assert s.codes_drawn == whole.codes_drawn


def test_inertialization_starts_on_the_motion_and_never_whips_a_bone():
    """The bent movement's first pose is the motion's next pose (each bone up to sign), and however far
    apart the two are, no bone turns faster than the exemplar, the offset and the capped velocity allow."""
    from models.networks.dance_jit import match_exemplar
    from models.networks.dance_stream import _unit, sign_continuous
    from models.networks.player import hermite_decay

    rng = np.random.default_rng(11)
    decay = hermite_decay(16)
    for _ in range(50):
        still = np.repeat(_unit(rng.normal(size=(1, 1, POSE_DIM)).astype(np.float32)), 16, axis=1)
        cont = _unit(rng.normal(size=(2, POSE_DIM)).astype(np.float32))  # far from the exemplar, any velocity
        cont[1] = _unit(cont[0] + rng.normal(scale=0.3, size=POSE_DIM).astype(np.float32))
        _, out = match_exemplar(sign_continuous(still), np.zeros((1, 8), np.float32), cont, decay, -1, 0.0, 8, 0.4, np.zeros(1))
        q0, c0 = out[0, 3:].reshape(-1, 4), cont[0, 3:].reshape(-1, 4)
        np.testing.assert_allclose(np.abs((q0 * c0).sum(1)), 1.0, atol=1e-5)
        steps = np.degrees(2 * np.arccos(np.clip(np.abs((out[1:, 3:].reshape(15, -1, 4)
                                                           * out[:-1, 3:].reshape(15, -1, 4)).sum(-1)), 0, 1)))
        # a still exemplar: each frame turns by the offset's decay (<= 180 deg x max |dh0/dj| = 180 x 1.5 / 16)
        # plus the capped velocity's (0.4 rad x max |dh1/dj| = 0.4 x 1 -> 23 deg)
        assert steps.max() < 180 * 1.5 / 16 + 23 + 1


BEAT = DanceVQConfig(feature_dim=20, codebook=16, code_dim=8, enc_width=16, dec_width=16, d_model=16, layers=1,
                     heads=2, window_codes=4, energy_col=0, clarity_col=16, members=15)


def beat_music(n: int, period: float = 15.0, clarity: float = 0.5, seed: int = 0) -> np.ndarray:
    """Loud random features whose beat-tracker columns (14-17: c cos, c sin, c, log2 P/15) say a
    beat every ``period`` frames, on frames 0, period, 2 period, ..."""
    x = music(n, seed)[:, :1].repeat(BEAT.feature_dim, axis=1)
    x[:, 1:14] = np.random.default_rng(seed).normal(size=(n, 13))
    theta = 2 * np.pi * np.arange(n) / period
    x[:, 14], x[:, 15], x[:, 16], x[:, 17] = clarity * np.cos(theta), clarity * np.sin(theta), clarity, np.log2(
        period / 15.0)
    x[:, 18:] = 0.0
    return x


def turning_exemplars(m: DanceVQ, deg_per_frame: float = 3.0) -> None:
    """Give every code of ``m`` (whose config holds ``members = 360 / (seg * deg_per_frame)``)
    the same exemplars: every bone turning about the vertical at a steady ``deg_per_frame``, one
    exemplar starting at each multiple of ``seg * deg_per_frame`` degrees, so that motion
    matching always finds the exact continuation: smooth motion at a constant speed."""
    from scipy.spatial.transform import Rotation

    c = m.config
    f = np.arange(2 * c.seg)
    with torch.no_grad():
        for j in range(c.members):
            angles = (j * c.seg * deg_per_frame + deg_per_frame * f)[:, None]
            q = Rotation.from_euler("y", angles, degrees=True).as_quat()
            pose = np.zeros((len(f), c.pose_dim), np.float32)
            pose[:, 1] = 1.0
            pose[:, 3:] = np.tile(q, (1, (c.pose_dim - 3) // 4))
            m.member_poses[:, j] = torch.from_numpy(pose)
        m.member_count[:] = c.members


def test_a_predictor_that_hears_the_tempo_is_given_it_and_chooses_by_it():
    """``tempo_input``: every token gets the followed tempo's ln(T / T_ref) (``DanceStream.tempo_input``);
    the same music draws other codes than with the input's weight zeroed (the tempo at T_ref), and the
    stream's offline twin (``tempo_inputs``) reads what the stream gave."""
    torch.manual_seed(3)
    m = DanceVQ(dataclasses_replace(BEAT, tempo_input=True)).eval()
    turning_exemplars(m)
    with torch.no_grad():
        m.member_period[:] = 20.0  # the memory's tempo 90 bpm; the music's 120 (a beat every 15 frames)
        m.predictor.tempo.weight.mul_(20.0)
    x = beat_music(600)
    s = DanceStream(m, seed=1)
    s.push(x)
    assert s.tempo_input == pytest.approx(math.log(20.0 / 15.0), abs=0.02)
    np.testing.assert_allclose(player_part.tempo_inputs(m, x)[-1], s.tempo_input, atol=1e-6)
    heard = list(s.codes_drawn)
    with torch.no_grad():
        m.predictor.tempo.weight.zero_()
    s0 = DanceStream(m, seed=1)
    s0.push(x)
    assert sum(a != b for a, b in zip(s0.codes_drawn, heard)) > len(heard) // 4


def test_beat_warp_slows_the_motion_into_every_beat_and_streams_like_the_whole_song(monkeypatch):
    m = DanceVQ(BEAT).eval()
    turning_exemplars(m)
    x = beat_music(900)
    warped = generate(m, x, seed=2)
    s, parts, i = DanceStream(m, seed=2), [], 0
    for k in np.random.default_rng(1).integers(0, 13, size=900):
        parts.append(s.push(x[i: i + k]))
        i += k
    parts.append(s.push(x[i:]))
    np.testing.assert_allclose(np.concatenate(parts), warped, atol=1e-5)
    monkeypatch.setattr(player_part, "BEAT_WARP", 0.0)
    plain = generate(m, x, seed=2)

    def speed_by_phase(p: np.ndarray) -> np.ndarray:
        """Mean bone rotation between frames t-1 and t (degrees), by the step's midpoint's frames
        after a beat (0.5, 1.5, ... 14.5), once the dance has faded in (frame 60 on)."""
        step = quat_angles_deg(p[61:], p[60:-1]).mean(1)
        phase = (np.arange(61, len(p)) - 0.5) % 15
        return np.array([step[np.abs(phase - h) < 0.1].mean() for h in np.arange(0.5, 15)])

    v, v0 = speed_by_phase(warped), speed_by_phase(plain)
    np.testing.assert_allclose(v0, 3.0, atol=0.3)  # the movements themselves turn steadily
    np.testing.assert_allclose(v.mean(), 3.0, atol=0.3)  # the warp keeps the pace on average ...
    assert v[[0, -1]].max() < 0.75 * 3.0 < 1.25 * 3.0 < v[7]  # ... slows into the beat, hurries between


def test_warp_pose_reads_between_frames_as_nlerp_does():
    from models.networks.dance_jit import warp_pose
    from models.networks.idle_fade import _nlerp

    rng = np.random.default_rng(0)
    played = rng.normal(size=(16, POSE_DIM)).astype(np.float32)
    np.testing.assert_array_equal(warp_pose(played, 5.0), played[5])  # on a frame: that frame, untouched
    for x in (0.25, 7.5, 14.999):
        i = int(x)
        got = warp_pose(played, x)
        np.testing.assert_allclose(got, _nlerp(played[i], played[i + 1], x - i), atol=1e-6)
        np.testing.assert_allclose(np.linalg.norm(got[3:].reshape(-1, 4), axis=1), 1.0, atol=1e-6)


def test_style_memory_records_each_exemplars_style_and_which_codes_each_style_uses():
    from models.training.dance_vq import fit_members, fit_style_prior, prior_from_counts

    rng = np.random.default_rng(0)
    cha, wal = _poses(400, rng), _poses(400, rng)
    cha[:, 1], wal[:, 1] = 1.1, 0.7  # each style's dancers at their own hip height
    m = memory_model(np.concatenate([cha, wal]))
    cfg = m.config
    clips = [_Clip(cha, np.zeros((400, 10), np.float32), "C"), _Clip(wal, np.zeros((400, 10), np.float32), "W")]
    fit_members(m, clips)
    have = m.member_count.numpy()
    style = m.member_style.numpy()
    hips = m.member_poses[..., 0, 1].float().numpy()
    for k in range(cfg.codebook):
        for j in range(have[k]):  # every exemplar is labelled with the style of the dance it came from
            assert style[k, j] == (1 if abs(hips[k, j] - 1.1) < 1e-3 else 3)
    assert (style[:, :1] > 0).all()
    counts = fit_style_prior(m, clips)
    assert counts[:, 1].sum() > 0 and counts[:, 3].sum() > 0 and counts[:, [0, 2]].sum() == 0
    prior = m.style_prior.numpy()
    np.testing.assert_allclose(np.exp(prior[:, [1, 3]]).sum(1), 1.0, rtol=1e-5)  # p(style | code) over the styles
    assert (prior[:, [0, 2]] == 0).all()
    only_cha = (counts[:, 1] > 20) & (counts[:, 3] == 0)
    if only_cha.any():
        assert (prior[only_cha, 1] > np.log(0.9)).all()
    # add-one smoothing: a code no style used is equally likely in each
    np.testing.assert_allclose(prior_from_counts(np.array([[0, 0, 0, 0], [0, 50, 0, 50]])), 0.0 * 0 + np.array(
        [[0, np.log(0.5), 0, np.log(0.5)], [0, np.log(0.5), 0, np.log(0.5)]]), atol=1e-6)


def test_a_requested_style_dances_with_its_own_dancers_exemplars(monkeypatch):
    from scipy.spatial.transform import Rotation

    import models.networks.dance_stream as ds

    torch.manual_seed(0)
    m = DanceVQ(TINY).eval()
    c = m.config
    with torch.no_grad():
        m.gate[0] = -50.0
        f = np.arange(2 * c.seg)
        for k in range(c.codebook):
            for j, (hips, style) in enumerate(((1.1, 1), (0.7, 3))):  # one cha-cha and one waltz exemplar per code
                q = Rotation.from_euler("y", (10 * k + 2 * f)[:, None], degrees=True).as_quat()
                pose = np.concatenate([np.tile([0.0, hips, 0.0], (len(f), 1)), np.tile(q, (1, len(BONES)))], 1)
                m.member_poses[k, j] = torch.from_numpy(pose.astype(np.float32))
                m.member_style[k, j] = style
        m.member_count[:] = 2
    x = music(400)
    monkeypatch.setattr(ds, "FEET_LOCK", False)  # the exemplars' own hip heights (the feet step grounds them)
    hips = {s: generate(m, x, seed=0, style=s)[100:, 1] for s in ("chacha", "waltz")}
    np.testing.assert_allclose(hips["chacha"], 1.1, atol=1e-3)  # only the cha-cha dancers' movements
    np.testing.assert_allclose(hips["waltz"], 0.7, atol=1e-3)  # only the waltz dancers'
    monkeypatch.setattr(chooser_part, "STYLE_MEMBERS", False)  # without the filter motion matching keeps to the first
    np.testing.assert_allclose(generate(m, x, seed=0, style="waltz")[100:, 1], 1.1, atol=1e-3)  # exemplar's kind


def test_checkpoints_from_before_the_style_memory_still_load(tmp_path):
    """A state dict without ``member_style`` and ``style_prior`` loads strictly, and the model
    it loads into forgets whatever style memory it held: both buffers become zeros (unknown),
    so a requested style then dances as a model that never had one."""
    m = tiny_model()
    with torch.no_grad():  # a style memory in the source, which the old checkpoint does not carry
        m.member_style[:] = 1 + torch.arange(m.member_style.numel()).reshape(m.member_style.shape) % 3
        m.style_prior[:, 1:] = torch.randn(TINY.codebook, 3)
    state = {k: v for k, v in m.state_dict().items() if k not in ("member_style", "style_prior")}
    m2 = DanceVQ(TINY)
    with torch.no_grad():  # and stale values in the target, which the load must clear
        m2.member_style.fill_(3)
        m2.style_prior.normal_(0.0, 5.0)
    m2.load_state_dict(state, strict=True)
    assert int(m2.member_style.abs().sum()) == 0 and float(m2.style_prior.abs().sum()) == 0.0
    m2.eval()
    x = music(64)
    np.testing.assert_array_equal(DanceStream(m2, seed=1).push(x), DanceStream(m, seed=1).push(x))  # auto reads no style memory
    with torch.no_grad():
        m.member_style.zero_()
        m.style_prior.zero_()
    waltz = {k: DanceStream(v, seed=1, style="waltz").push(x) for k, v in (("old", m2), ("zeroed", m))}
    np.testing.assert_array_equal(waltz["old"], waltz["zeroed"])


def test_style_memory_is_added_to_an_older_checkpoint_only_from_its_own_training_motion():
    from models.errors import DataError
    from models.training.dance_vq import fit_members
    from models.training.style_memory import add_style_memory

    rng = np.random.default_rng(1)
    poses = _poses(300, rng)
    m = memory_model(poses)
    clips = [_Clip(poses, np.zeros((300, TINY.feature_dim), np.float32), "R")]
    fit_members(m, clips)
    members = m.member_poses.clone()
    m.member_style.zero_()  # as saved before the style memory existed
    m.style_prior.zero_()
    counts = add_style_memory(m, clips)
    assert torch.equal(m.member_poses, members) and bool((m.member_style[m.member_count > 0][:, 0] == 2).all())
    assert counts[:, 2].sum() > 0 and (m.style_prior[:, 2] == 0).all()  # one style: no preference among codes
    other = [_Clip(_poses(300, np.random.default_rng(7)), clips[0].features, "R")]
    with pytest.raises(DataError, match="other exemplars"):
        add_style_memory(m, other)
    assert torch.equal(m.member_poses, members)  # left as it was


def speed_model(speeds_deg: np.ndarray) -> DanceVQ:
    """A tiny dance_vq whose code k's one exemplar turns every bone about y at speeds_deg[k] a frame."""
    from scipy.spatial.transform import Rotation

    torch.manual_seed(0)
    m = DanceVQ(TINY).eval()
    f = np.arange(2 * m.config.seg)
    with torch.no_grad():
        m.gate[0] = -50.0
        for k, v in enumerate(speeds_deg):
            q = Rotation.from_euler("y", (v * f)[:, None], degrees=True).as_quat()
            pose = np.concatenate([np.tile([0.0, 1.0, 0.0], (len(f), 1)), np.tile(q, (1, len(BONES)))], 1)
            m.member_poses[k, 0] = torch.from_numpy(pose.astype(np.float32))
        m.member_count[:] = 1
    return m


def test_energy_control_favours_calm_or_lively_movements_and_1_changes_nothing():
    from models.networks.dance_stream import code_energy

    m = speed_model(np.linspace(0.5, 8.0, TINY.codebook))
    s = DanceStream(m)
    z = s._chooser.code_energy
    assert np.all(np.diff(z) > 0) and abs(z.mean()) < 1e-5 and abs(z.std() - 1) < 1e-4  # the speeds' order
    np.testing.assert_array_equal(z, code_energy(s._chooser.members, m.member_count.numpy(), m.config.seg))
    x = music(800)
    np.testing.assert_array_equal(generate(m, x, seed=3, energy=1.0), generate(m, x, seed=3))
    drawn = {}
    for e in (0.0, 1.0, 2.0):
        st = DanceStream(m, seed=3)
        st.set_energy(e)
        st.push(x)
        drawn[e] = z[st.codes_drawn].mean()
    assert drawn[0.0] < drawn[1.0] - 0.5 and drawn[2.0] > drawn[1.0] + 0.5, drawn
    from models.generate import run_model  # performer generate's path takes it too; other models refuse it

    np.testing.assert_array_equal(run_model(m, x, seed=3, energy=0.0), generate(m, x, seed=3, energy=0.0))
    with pytest.raises(ConfigError, match="has no energy control"):
        run_model(build_model("causal", {"feature_dim": 10}), x, energy=1.5)
    for bad in (-0.1, 2.5, float("nan"), "high", None, "1.5", True):
        with pytest.raises(ConfigError, match="energy must be"):
            s.set_energy(bad)
    assert s.energy == 1.0 and s._chooser._energy_bias is None  # a refused value changes nothing


def test_the_idle_fade_keeps_each_bone_on_one_arc():
    """A bone whose dance rotation passes 180 degrees from the idle one mid-fade: choosing the
    shorter arc anew every frame (_nlerp) flips it to the other side in one frame; the fade
    follows the rotation it started on continuously."""
    from scipy.spatial.transform import Rotation

    from models.networks.idle_fade import _nlerp

    s = DanceStream(tiny_model())
    n = 31
    angles = np.linspace(150.0, 210.0, n)  # the dance pose turns past 180 degrees from the idle's
    idle = np.zeros(POSE_DIM, np.float32)
    idle[3:] = np.tile([0.0, 0.0, 0.0, 1.0], len(BONES))
    dance = np.repeat(idle[None], n, 0)
    dance[:, 3:7] = Rotation.from_euler("y", angles[:, None], degrees=True).as_quat()
    weights = np.linspace(0.6, 0.4, n)

    def largest_step(poses: np.ndarray) -> float:
        return float(quat_angles_deg(poses[1:], poses[:-1]).max())

    fresh = np.stack([_nlerp(d, idle, w) for d, w in zip(dance, weights)])
    faded = np.stack([s._idle_fade(d, idle, w) for d, w in zip(dance, weights)])
    assert largest_step(fresh) > 90.0  # the flip
    assert largest_step(faded) < 5.0
    # the first frame: on the shorter arc (150 degrees apart), 0.6 of the way from the dance to the idle
    first = quat_angles_deg(faded[:1], dance[:1])[0, 0], quat_angles_deg(faded[:1], idle[None])[0, 0]
    np.testing.assert_allclose(first, (0.6 * 150.0, 0.4 * 150.0), atol=1e-3)


def test_a_bone_turning_back_to_the_idle_mid_fade_blends_the_short_way():
    """A bone 180 degrees from the idle when a fade-in starts, then turning back towards it
    (the head at a fade-in of DANCE_W_22): each input's sign kept from the start made the two
    nearly opposite and their blend whipped the bone (91 degrees in a frame, 32 here); followed
    continuously it turns no faster than the dance and the fade together."""
    from scipy.spatial.transform import Rotation

    s = DanceStream(tiny_model())
    n = 21
    angles = np.linspace(181.0, 10.0, n)  # just past 180 degrees, then back towards the idle's
    idle = np.zeros(POSE_DIM, np.float32)
    idle[3:] = np.tile([0.0, 0.0, 0.0, 1.0], len(BONES))
    dance = np.repeat(idle[None], n, 0)
    dance[:, 3:7] = Rotation.from_euler("y", angles[:, None], degrees=True).as_quat()
    weights = np.linspace(0.95, 0.05, n)  # fading in
    faded = np.stack([s._idle_fade(d, idle, w) for d, w in zip(dance, weights)])
    dance_step = float(np.diff(angles).__abs__().max())  # 8.45 degrees a frame
    # the rotation to the idle, followed past 180 degrees, is at most a full turn: 0.045 of it a frame
    assert float(quat_angles_deg(faded[1:], faded[:-1]).max()) < dance_step + 360.0 * 0.045 + 1.0


def speed_by_beat_phase(p: np.ndarray, period: int = 15, lead: int = 0) -> np.ndarray:
    """Mean bone rotation between frames t-1 and t (degrees) of poses ``p`` (T, P), by the step's
    midpoint's frames after a beat of a ``period``-frame pulse with beats on frames 0, period, ...,
    counted ``lead`` frames later (0.5, 1.5, ...), once the dance has faded in (frame 60 on)."""
    step = quat_angles_deg(p[61:], p[60:-1]).mean(1)
    phase = (np.arange(61, len(p)) - 0.5 + lead) % period
    return np.array([step[np.abs(phase - h) < 0.1].mean() for h in np.arange(0.5, period)])


def test_a_lead_puts_the_beat_moves_that_many_frames_earlier():
    """With a lead of L frames the warp slows into the beats the tracker expects L frames on:
    the pose sent at t is the one taken at t + L, so the speed profile over the beat, counted L
    frames later, is lead 0's (a stream that ignored the lead would keep its dips on the beat)."""
    m = DanceVQ(BEAT).eval()
    turning_exemplars(m)
    x = beat_music(900)
    v0 = speed_by_beat_phase(generate(m, x, seed=2))
    assert v0[[0, -1]].max() < 0.75 * 3.0 < 1.25 * 3.0 < v0[7]  # lead 0: slowest on the beat
    for ms, frames in ((67.0, 2), (133.0, 4), (200.0, 6)):
        led = generate(m, x, seed=2, lead=ms)
        np.testing.assert_allclose(speed_by_beat_phase(led, lead=frames), v0, atol=0.25)
        v = speed_by_beat_phase(led)
        assert v[[0, -1]].max() > 1.25 * v0[[0, -1]].max()  # not on the audio's beat any more
        assert int(np.argmin(v)) in {(15 - frames - 1) % 15, 15 - frames}  # but L frames before it


def test_the_speed_dips_fall_beat_delay_frames_after_the_trackers_beat(monkeypatch):
    """BEAT_DELAY (1 frame: the chain put the dips a frame early against the music's beats on
    the training dances, beat_control.py --split train) moves where the warp slows and where the matching places a dip, and
    nothing else: the speed profile over the beat is the one on the tracker's beat (BEAT_DELAY
    0), one frame later."""
    m = DanceVQ(BEAT).eval()
    turning_exemplars(m)
    x = beat_music(900)
    assert player_part.BEAT_DELAY == 1.0
    v1 = speed_by_beat_phase(generate(m, x, seed=2))
    monkeypatch.setattr(player_part, "BEAT_DELAY", 0.0)
    v0 = speed_by_beat_phase(generate(m, x, seed=2))
    np.testing.assert_allclose(v1, np.roll(v0, 1), atol=0.1)
    assert int(np.argmin(v1)) == (int(np.argmin(v0)) + 1) % 15 and int(np.argmin(v0)) == 14


def test_a_lead_streams_like_the_whole_song_reads_no_audio_ahead_and_changes_at_a_code_step():
    from models.networks.dance_stream import LEAD_RANGE_MS

    m = DanceVQ(BEAT).eval()
    turning_exemplars(m)
    x = beat_music(600)
    for ms in (0.0, 67.0, 133.0, 200.0):
        whole = generate(m, x, seed=2, lead=ms)
        s, parts, i = DanceStream(m, seed=2, lead_ms=ms), [], 0
        for k in np.random.default_rng(int(ms)).integers(0, 13, size=600):
            parts.append(s.push(x[i: i + k]))
            i += k
        parts.append(s.push(x[i:]))
        np.testing.assert_allclose(np.concatenate(parts), whole, atol=1e-5)  # stream == offline, every lead
        steps = DanceStream(m, seed=2, lead_ms=ms)
        assert [len(steps.codes_drawn) for _ in range(3) if steps.push(x[:8]) is not None] == [1, 2, 3]
        steps.push(x[:1])
        assert len(steps.codes_drawn) == 4  # code steps on frames 0, 8, 16, ... whatever the lead (the stagger's)
        y = x.copy()
        y[300:] = beat_music(300, period=11.0, seed=9)  # other music from frame 300 on
        np.testing.assert_array_equal(generate(m, y, seed=2, lead=ms)[:300], whole[:300])  # never heard early
    # a live change takes effect at the next code step (frame 104 after a call at frame 100), without a jump
    s = DanceStream(m, seed=2)
    before = s.push(x[:100])
    s.set_lead(133.0)
    after = s.push(x[100:])
    plain = generate(m, x, seed=2)
    np.testing.assert_allclose(np.concatenate([before, after])[:104], plain[:104], atol=1e-6)
    assert not np.allclose(after[4:40], plain[104:140], atol=1e-3)
    steps = quat_angles_deg(after[1:], after[:-1]).max(1)
    assert steps[:10].max() < 2.0 * quat_angles_deg(plain[61:], plain[60:-1]).max()
    assert s.lead_ms == 133.0 and LEAD_RANGE_MS == (0.0, 200.0)
    s.reset()  # the lead is a setting: a reset keeps it, as style and energy
    np.testing.assert_allclose(s.push(x), generate(m, x, seed=2, lead=133.0), atol=1e-5)
    from models.generate import run_model  # performer generate's path takes it too; other models refuse it

    np.testing.assert_array_equal(run_model(m, x, seed=2, lead=67.0), generate(m, x, seed=2, lead=67.0))
    with pytest.raises(ConfigError, match="has no lead control"):
        run_model(build_model("causal", {"feature_dim": 10}), x[:, :10], lead=67.0)
    for bad in (-1.0, 250.0, float("nan"), "soon", None, "100", True):
        with pytest.raises(ConfigError, match="lead must be"):
            s.set_lead(bad)
    assert s.lead_ms == 133.0  # a refused value changes nothing


def test_a_long_stream_keeps_a_bounded_code_history_and_dances_the_same(monkeypatch):
    """``codes_drawn`` keeps only the newest ``CODES_KEPT`` codes (dropping ``CODES_TRIM`` at a
    time), so a stream running for days does not grow; what it dances does not change (the
    repeat limit reads only the last few codes)."""
    import models.networks.dance_stream as ds

    m = DanceVQ(BEAT).eval()
    turning_exemplars(m)
    x = beat_music(400)  # 50 code steps
    full = DanceStream(m, seed=4)
    whole = full.push(x)
    monkeypatch.setattr(ds, "CODES_KEPT", 16)
    monkeypatch.setattr(ds, "CODES_TRIM", 4)
    s = DanceStream(m, seed=4)
    lengths = []
    for i in range(0, 400, 8):
        s.push(x[i: i + 8])
        lengths.append(len(s.codes_drawn))
    assert max(lengths) == 20 and lengths[-1] <= 20  # never more than CODES_KEPT + CODES_TRIM
    assert s.codes_drawn == full.codes_drawn[-len(s.codes_drawn):]  # the newest, in order
    np.testing.assert_array_equal(DanceStream(m, seed=4).push(x), whole)  # the same dance
