"""The real-time engine: real feature extractor, a tiny real torch model, real sources.

The pose model here is a random causal Conv1d (kernel 4) wrapped to the engine's
PoseModel protocol, so these tests do not depend on a trained checkpoint.
"""

from __future__ import annotations

import logging
import threading
import time

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from models.errors import AudioError, ConfigError
from models.features.spectral import FeatureConfig, extract_features
from models.features.streaming import StreamingFeatureExtractor
from models.rig.humanoid import NUM_BONES
from models.rig.motion import POSE_DIM
from models.timebase import FPS, HOP, SAMPLE_RATE
from realtime.audio_input import FileSource, RingBuffer
from realtime.engine import Engine
from realtime.engine_config import EngineConfig
from realtime.frame import PoseFrame
from realtime.pose_filters import IdleFader, PoseSmoother, idle_pose, rest_pose

CFG = FeatureConfig()


class TinyConvModel:
    """PoseModel over a random causal Conv1d (feature_dim -> POSE_DIM, kernel 4).

    Streaming keeps the last ``kernel - 1`` feature frames, so pushing frames one by
    one or all at once gives the same poses.
    """

    def __init__(self, feature_dim: int = CFG.dim, kernel: int = 4, seed: int = 0) -> None:
        g = torch.Generator().manual_seed(seed)
        self.net = torch.nn.Conv1d(feature_dim, POSE_DIM, kernel)
        with torch.no_grad():
            for p in self.net.parameters():
                p.copy_(0.05 * torch.randn(p.shape, generator=g))
        self.feature_dim = feature_dim
        self.kernel = kernel
        self.calls = 0
        self.reset()

    def reset(self) -> None:
        self._ctx = np.zeros((self.kernel - 1, self.feature_dim), np.float32)

    def push(self, features: np.ndarray) -> np.ndarray:
        self.calls += 1
        x = np.concatenate([self._ctx, features.astype(np.float32)])
        self._ctx = x[len(x) - (self.kernel - 1):]
        with torch.inference_mode():
            y = self.net(torch.from_numpy(np.ascontiguousarray(x.T))[None])[0].T
        return y.numpy().copy()


class ListSink:
    """A sink that keeps what it is sent (a real Sink, in memory)."""

    def __init__(self, name: str = "list") -> None:
        self.name = name
        self.frames: list[PoseFrame] = []
        self.closed = False

    def send(self, frame: PoseFrame) -> None:
        self.frames.append(frame)

    def close(self) -> None:
        self.closed = True

    def stats(self) -> dict[str, float]:
        return {"frames": float(len(self.frames))}


def noise(seconds: float, sr: int = SAMPLE_RATE, channels: int = 1, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x = 0.2 * rng.standard_normal((int(seconds * sr), channels)).astype(np.float32)
    return x[:, 0] if channels == 1 else x


def extractor(sr: int) -> StreamingFeatureExtractor:
    return StreamingFeatureExtractor(CFG, sr)


def run_engine(source, model=None, sinks=None, timeout=30.0, **cfg) -> tuple[Engine, ListSink]:
    sink = ListSink()
    cfg.setdefault("warmup_s", 0.5)
    eng = Engine(source, extractor, model or TinyConvModel(), [sink, *(sinks or [])], EngineConfig(**cfg))
    eng.start()
    assert eng.wait(timeout), "engine did not finish in time"
    eng.close()
    return eng, sink


def reference_poses(audio: np.ndarray) -> np.ndarray:
    """What the engine must send: the offline features through a fresh model, quats normalised."""
    poses = TinyConvModel().push(extract_features(audio, CFG))
    smoother = PoseSmoother(0.0)
    return np.stack([smoother(p.copy()) for p in poses])


def test_fast_replay_matches_offline_pipeline_and_stamps():
    audio = noise(2.0)
    eng, sink = run_engine(FileSource(audio, SAMPLE_RATE, realtime=False, block_size=300))
    frames = sink.frames
    assert len(frames) == len(audio) // HOP == 60
    assert [f.index for f in frames] == list(range(len(frames)))
    # poses equal the offline pipeline: warm-up + reset left no state behind
    np.testing.assert_allclose(np.stack([f.pose for f in frames]), reference_poses(audio), atol=1e-4)
    for f in frames:
        assert f.audio_time == pytest.approx((f.index + 1) * HOP / SAMPLE_RATE)
        assert f.audio_sample == (f.index + 1) * HOP - 1  # 22050 Hz input: the hop's last sample
        assert f.pose.dtype == np.float32 and f.pose.shape == (POSE_DIM,)
    assert np.all(np.diff([f.wall_time for f in frames]) >= 0)
    st = eng.stats()
    assert st["frames"] == 60 and st["nan_frames"] == 0 and st["overruns"] == 0
    assert eng.compute_ms.count == 60 and st["compute_ms_p99"] > 0
    assert st["state"] == "finished" and sink.closed


def test_with_one_torch_thread_the_worker_holds_blas_to_one_thread_and_gives_the_count_back():
    """The worker (threads=1, the default) runs BLAS on one thread all its life, so a dance_vq performer's
    per-frame limit (models/networks/dance_numpy.py, single_thread_blas) has nothing to do; after the
    run the process's count is what it was. threads=None leaves BLAS alone."""
    from threadpoolctl import threadpool_info

    import models.networks.dance_numpy as dance_numpy

    def blas_threads() -> list[int]:
        return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]

    seen: list[tuple[int, list[int]]] = []

    class Probe(ListSink):
        def send(self, frame: PoseFrame) -> None:
            if not self.frames:
                seen.append((dance_numpy._held, blas_threads()))
            super().send(frame)

    before = blas_threads()  # more than one on a machine of several cores, unless OMP_NUM_THREADS says one
    for threads, held, inside in ((1, 1, [1] * len(before)), (None, 0, before)):
        run_engine(FileSource(noise(1.0), SAMPLE_RATE, realtime=False), sinks=[Probe()], threads=threads)
        assert seen[-1] == (held, inside)
        assert blas_threads() == before and dance_numpy._held == 0


def test_44k_stereo_input_stamps_in_input_samples():
    sr = 44100
    audio = noise(1.0, sr, channels=2)
    _, sink = run_engine(FileSource(audio, sr, realtime=False, block_size=1000))
    frames = sink.frames
    assert abs(len(frames) - 30) <= 1
    ex = extractor(sr)
    for f in frames:
        assert f.audio_sample == ex.samples_needed(f.index) - 1  # exact completing sample
        assert f.audio_time == pytest.approx((f.index + 1) / FPS)
    # stereo is mixed down to the channel mean before the features
    _, mono_sink = run_engine(FileSource(audio.mean(axis=1), sr, realtime=False, block_size=1000))
    np.testing.assert_allclose([f.pose for f in frames], [f.pose for f in mono_sink.frames], atol=1e-5)


def timed_run(seconds: float, realtime: bool, block: int) -> tuple[Engine, ListSink, float]:
    """Replay ``seconds`` of noise; return the engine, its frames and the wall time (s) after warm-up."""
    t0 = time.monotonic()
    eng, sink = run_engine(FileSource(noise(seconds), SAMPLE_RATE, realtime=realtime, block_size=block))
    assert len(sink.frames) == int(seconds * FPS)
    return eng, sink, time.monotonic() - t0 - eng.warmup_seconds


@pytest.mark.serial  # wall-clock bounds
@pytest.mark.slow
def test_paced_replay_keeps_real_time():
    eng, sink, elapsed = timed_run(2.0, realtime=True, block=512)
    assert 1.9 <= elapsed < 6.0  # never early; generous guard for a loaded machine
    walls = np.array([f.wall_time for f in sink.frames])
    rate = (len(walls) - 1) / (walls[-1] - walls[0])
    assert 20 < rate < 40  # ~30 fps (blocks of 512 samples arrive every 23 ms)
    # latency from block release to send stays far below one second even on a busy box
    assert eng.stats()["latency_ms_p50"] < 250


@pytest.mark.serial  # wall-clock bounds
def test_fast_replay_is_faster_than_real_time():
    _, _, elapsed = timed_run(8.0, realtime=False, block=2048)
    assert elapsed < 8.0


class NaNModel(TinyConvModel):
    """Emits NaN in every 5th pose (and inf in a quaternion of every 7th)."""

    def push(self, features):
        out = super().push(features)
        self.n = getattr(self, "n", 0)
        for row in out:
            if self.n % 5 == 3:
                row[:] = np.nan
            elif self.n % 7 == 6:
                row[10] = np.inf
            self.n += 1
        return out


def test_nan_guard_replaces_bad_poses_with_last_good():
    model = NaNModel()
    eng, sink = run_engine(FileSource(noise(1.0), SAMPLE_RATE, realtime=False), model=model, warmup_s=0)
    poses = np.stack([f.pose for f in sink.frames])
    assert np.isfinite(poses).all()
    bad = [i for i in range(len(poses)) if i % 5 == 3 or i % 7 == 6]
    assert eng.nan_frames == len(bad) > 0
    for i in bad:
        np.testing.assert_array_equal(poses[i], poses[i - 1])  # held last good pose


def test_nan_first_frame_falls_back_to_rest_pose():
    class AllNaN(TinyConvModel):
        def push(self, features):
            return np.full((len(features), POSE_DIM), np.nan, np.float32)

    eng, sink = run_engine(FileSource(noise(0.5), SAMPLE_RATE, realtime=False), model=AllNaN(), warmup_s=0)
    assert eng.nan_frames == len(sink.frames) == 15
    np.testing.assert_array_equal(sink.frames[0].pose, rest_pose())


class RaisingSink(ListSink):
    def send(self, frame):
        raise ConnectionError("peer gone")


def test_a_raising_sink_is_counted_logged_once_and_does_not_stop_the_engine(caplog):
    bad = RaisingSink("bad")
    with caplog.at_level(logging.WARNING, logger="realtime.engine"):
        eng, sink = run_engine(FileSource(noise(1.0), SAMPLE_RATE, realtime=False), sinks=[bad])
    assert len(sink.frames) == 30
    assert eng.stats()["sink_errors"] == 30
    assert sum("output bad failed" in r.message for r in caplog.records) == 1
    assert bad.closed


class FlakySource:
    """Delivers ``audio`` in blocks of 735 samples, 2 ms apart.

    At sample ``fail_at`` it dies like an unplugged device (``error`` set, thread ends)
    and the next ``dead_starts`` start() calls raise; later starts resume where it
    stopped. At sample ``quiet_at`` it just goes silent (no blocks) for ``quiet_s``.
    """

    def __init__(self, audio, *, fail_at=None, dead_starts=0, quiet_at=None, quiet_s=0.0):
        self.audio, self.sample_rate, self.channels, self.block = audio[:, None], SAMPLE_RATE, 1, 735
        self.fail_at, self.dead_starts, self.quiet_at, self.quiet_s = fail_at, dead_starts, quiet_at, quiet_s
        self.name, self.error, self.finished = "flaky", None, False
        self.pos = self.starts = 0
        self._died = self._quieted = False
        self._thread = None
        self._stop = threading.Event()

    def start(self, ring):
        self.starts += 1
        if self._died and self.dead_starts > 0:
            self.dead_starts -= 1
            raise AudioError("device not found")
        self.error = None
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, args=(ring,), daemon=True)
        self._thread.start()

    def _run(self, ring):
        while self.pos < len(self.audio) and not self._stop.is_set():
            if self.fail_at is not None and not self._died and self.pos >= self.fail_at:
                self._died, self.error = True, "device disconnected"
                ring.wake()
                return
            if self.quiet_at is not None and not self._quieted and self.pos >= self.quiet_at:
                self._quieted = True
                time.sleep(self.quiet_s)
            ring.wait_space(self.block)
            ring.write(self.audio[self.pos : self.pos + self.block])
            self.pos += self.block
            time.sleep(0.002)
        self.finished = self.pos >= len(self.audio)
        ring.wake()

    def stop(self):
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None

    def stats(self):
        return {}


def test_failing_source_is_reported_holds_last_pose_and_resumes():
    audio = noise(2.0)
    src = FlakySource(audio, fail_at=30 * HOP, dead_starts=2)
    sink = ListSink()
    eng = Engine(src, extractor, TinyConvModel(), [sink], EngineConfig(warmup_s=0, retry_s=0.05))
    eng.start()
    deadline = time.monotonic() + 10
    while eng.state != "source error" and time.monotonic() < deadline:
        time.sleep(0.005)
    assert eng.state == "source error"
    held = len(sink.frames)
    assert held == 30 and eng.last_frame is sink.frames[-1]
    assert eng.wait(10)
    eng.close()
    assert eng.source_errors == 1
    assert src.starts == 1 + 2 + 1  # first start, two failed retries, the one that worked
    assert len(sink.frames) == 60
    assert [f.index for f in sink.frames] == list(range(60))  # resumed, same stream


@pytest.mark.serial  # wall-clock bounds
def test_silent_source_is_reported_as_stalled_then_resumes():
    src = FlakySource(noise(1.0), quiet_at=15 * HOP, quiet_s=0.6)
    sink = ListSink()
    eng = Engine(src, extractor, TinyConvModel(), [sink], EngineConfig(warmup_s=0, stall_timeout_s=0.2))
    eng.start()
    assert eng.wait(10)
    eng.close()
    assert eng.stalls == 1 and eng.source_errors == 0
    assert len(sink.frames) == 30


def test_reset_restarts_frame_indices_without_stopping():
    audio = noise(1.5)
    src = FileSource(audio, SAMPLE_RATE, realtime=True, block_size=735)
    sink = ListSink()
    eng = Engine(src, extractor, TinyConvModel(), [sink], EngineConfig(warmup_s=0))
    eng.start()
    while len(sink.frames) < 10:
        time.sleep(0.01)
    eng.reset()
    assert eng.wait(10)
    eng.close()
    idx = [f.index for f in sink.frames]
    k = next(i for i in range(1, len(idx)) if idx[i] == 0)
    assert idx[:k] == list(range(k)) and idx[k:] == list(range(len(idx) - k))
    origin = sink.frames[k].audio_sample + 1 - HOP  # reset happened on a hop boundary here
    assert sink.frames[k].audio_time == pytest.approx(origin / SAMPLE_RATE + HOP / SAMPLE_RATE)
    assert np.all(np.diff([f.audio_time for f in sink.frames]) > 0)  # stream time keeps going


def test_stop_then_start_again_in_the_same_process():
    src = FileSource(noise(1.0), SAMPLE_RATE, realtime=False)
    sink = ListSink()
    eng = Engine(src, extractor, TinyConvModel(), [sink], EngineConfig(warmup_s=0.2))
    for _ in range(2):
        src.rewind()
        eng.start()  # the second time without stop(): the finished run is cleaned up first
        assert eng.wait(10)
    assert [f.index for f in sink.frames] == list(range(30)) * 2


def test_positive_offset_delays_sending_and_shifts_audio_time():
    eng, sink = run_engine(FileSource(noise(0.5), SAMPLE_RATE, realtime=True, block_size=735), offset_ms=150)
    assert len(sink.frames) == 15
    assert eng.latency_ms.percentile(0) >= 150.0
    for f in sink.frames:
        assert f.audio_time == pytest.approx((f.index + 1) * HOP / SAMPLE_RATE + 0.150)


def test_negative_offset_only_relabels_audio_time():
    eng, sink = run_engine(FileSource(noise(0.5), SAMPLE_RATE, realtime=False), offset_ms=-100)
    for f in sink.frames:
        assert f.audio_time == pytest.approx((f.index + 1) * HOP / SAMPLE_RATE - 0.100)
        assert f.audio_sample == (f.index + 1) * HOP - 1


def test_duration_limits_the_audio_processed():
    _, sink = run_engine(FileSource(noise(3.0), SAMPLE_RATE, realtime=False), duration_s=1.0)
    assert len(sink.frames) == 30


def test_model_exception_stops_engine_and_is_reraised_by_wait():
    class Broken(TinyConvModel):
        def push(self, features):
            if self.calls >= 1:
                raise RuntimeError("boom")
            return super().push(features)

    eng = Engine(FileSource(noise(1.0), SAMPLE_RATE, realtime=False), extractor, Broken(), [], EngineConfig(warmup_s=0))
    eng.start()
    with pytest.raises(RuntimeError, match="boom"):
        eng.wait(10)
    eng.close()
    assert eng.state == "failed"


def test_warm_up_failure_is_raised_by_start_and_the_source_never_starts():
    class Broken(TinyConvModel):
        def push(self, features):
            raise RuntimeError("bad weights")

    src = FileSource(noise(1.0), SAMPLE_RATE, realtime=False)
    eng = Engine(src, extractor, Broken(), [], EngineConfig(warmup_s=0.5))
    with pytest.raises(RuntimeError, match="bad weights"):
        eng.start()
    assert src.blocks_released == 0 and not eng.running


def test_overrun_is_counted_when_the_worker_is_too_slow():
    class Slow(TinyConvModel):
        def push(self, features):
            time.sleep(0.05 * len(features))  # 1.5x slower than real time
            return super().push(features)

    # paced replay, like a device, never waits for room: the 50 ms ring must overflow
    src = FileSource(noise(1.0), SAMPLE_RATE, realtime=True, block_size=512)
    eng = Engine(src, extractor, Slow(), [], EngineConfig(warmup_s=0, ring_seconds=0.05, max_read=256))
    eng.start()
    assert eng.wait(20)
    eng.close()
    assert eng.stats()["overruns"] > 0 and eng.stats()["dropped_samples"] > 0


# -- smoothing ---------------------------------------------------------------------------


def random_pose(rng) -> np.ndarray:
    pose = np.zeros(POSE_DIM, np.float32)
    pose[:3] = rng.normal(size=3)
    pose[3:] = Rotation.random(NUM_BONES, random_state=rng).as_quat().reshape(-1)
    return pose


def test_smoother_off_only_normalises():
    rng = np.random.default_rng(1)
    pose = random_pose(rng)
    scaled = pose.copy()
    scaled[3:] *= 3.0
    scaled[3:7] = 0.0  # a zero quaternion becomes identity
    out = PoseSmoother(0.0)(scaled)
    np.testing.assert_allclose(out[7:], pose[7:], atol=1e-6)
    np.testing.assert_allclose(out[3:7], [0, 0, 0, 1])


def test_smoother_blends_on_the_shortest_arc():
    rng = np.random.default_rng(2)
    a, b = random_pose(rng), random_pose(rng)
    b_flipped = b.copy()
    b_flipped[3:] *= -1.0  # same rotations, other hemisphere
    sm = PoseSmoother(0.7)
    sm(a.copy())
    out = sm(b_flipped.copy())
    np.testing.assert_allclose(out[:3], 0.7 * a[:3] + 0.3 * b[:3], atol=1e-5)
    ra = Rotation.from_quat(a[3:].reshape(-1, 4))
    rb = Rotation.from_quat(b[3:].reshape(-1, 4))
    ro = Rotation.from_quat(out[3:].reshape(-1, 4))
    total = (ra.inv() * rb).magnitude()
    # on the geodesic between a and b (angles add up), closer to a (weight 0.7)
    np.testing.assert_allclose((ra.inv() * ro).magnitude() + (ro.inv() * rb).magnitude(), total, atol=1e-4)
    assert np.all((ra.inv() * ro).magnitude() <= 0.5 * total + 1e-6)


# -- show controls: idle, style, energy ------------------------------------------------------


class ActingSink(ListSink):
    """Keeps frames and, right after frame ``i`` went out, calls ``engine.control(*actions[i])``
    (on the worker, between two frames: the switch falls exactly between frames i and i + 1)."""

    def __init__(self, actions: dict[int, tuple[str, object]]) -> None:
        super().__init__()
        self.actions = actions
        self.engine: Engine | None = None

    def send(self, frame: PoseFrame) -> None:
        super().send(frame)
        if frame.index in self.actions:
            self.engine.control(*self.actions[frame.index])


def bone_angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(NUM_BONES,) rotation angle in radians between the bones of two flat poses."""
    qa, qb = a[3:].reshape(-1, 4), b[3:].reshape(-1, 4)
    return (Rotation.from_quat(qa).inv() * Rotation.from_quat(qb)).magnitude()


def test_idle_without_model_support_crossfades_in_one_second_holds_and_comes_back():
    audio = noise(4.0)
    sink = ActingSink({10: ("idle", 1), 60: ("idle", 0)})
    eng = Engine(FileSource(audio, SAMPLE_RATE, realtime=False, block_size=300), extractor, TinyConvModel(),
                 [sink], EngineConfig(warmup_s=0.5))
    sink.engine = eng
    eng.start()
    assert eng.wait(30)
    eng.close()
    out = np.stack([f.pose for f in sink.frames])
    ref = reference_poses(audio)  # the dance the model kept making all along
    target = idle_pose()
    assert len(out) == 120 and eng.idle is False and eng.stats()["idle"] is False
    np.testing.assert_allclose(out[:11], ref[:11], atol=1e-4)  # untouched before
    # 29 frames in between (1 s at 30 fps), then exactly the idle pose, held while idle
    np.testing.assert_array_equal(out[40:61], np.tile(target, (21, 1)))
    np.testing.assert_allclose(out[90:], ref[90:], atol=1e-4)  # the live dance again, 1 s after idle ended
    # the blend weight of each frame, read off the root (moved linearly): no step beyond smoothstep's
    d = ref[:, :3] - target[:3]
    e = np.einsum("ij,ij->i", ref[:, :3] - out[:, :3], d) / np.einsum("ij,ij->i", d, d)
    w = np.r_[np.zeros(11), np.arange(1, 30) / 30, np.ones(21), np.arange(29, 0, -1) / 30, np.zeros(30)]
    np.testing.assert_allclose(e, w * w * (3 - 2 * w), atol=1e-4)
    assert np.abs(np.diff(e)).max() <= 1.5 / 30 + 1e-4
    # each bone turns towards the idle pose, never away from it or past it
    for i in [*range(11, 40), *range(61, 90)]:
        assert np.all(bone_angles(out[i], target) <= bone_angles(ref[i], target) + 1e-3), i


def test_idle_fader_reverses_mid_fade_without_a_jump():
    rng = np.random.default_rng(3)
    dance = random_pose(rng)
    dance[3:] /= np.repeat(np.linalg.norm(dance[3:].reshape(-1, 4), axis=1), 4)
    fader = IdleFader(idle_pose(), frames=10)
    assert not fader.active and fader(dance.copy()).tobytes() == dance.tobytes()  # off: bit-exact
    fader.idle = True
    roots = [fader(dance.copy())[:3].copy() for _ in range(4)]
    fader.idle = False  # reverse after 4 of 10 steps: goes back down from there
    roots += [fader(dance.copy())[:3].copy() for _ in range(5)]
    weights = [f.item() for f in np.linalg.norm(np.array(roots) - dance[:3], axis=1)
               / np.linalg.norm(idle_pose()[:3] - dance[:3])]
    expected = [w * w * (3 - 2 * w) for w in np.r_[np.arange(1, 5), np.arange(3, -1, -1), 0] / 10]
    np.testing.assert_allclose(weights, expected, atol=1e-5)
    assert not fader.active
    with pytest.raises(ValueError, match="idle pose"):
        IdleFader(np.full(POSE_DIM, np.nan, np.float32))


def test_idle_pose_stands_on_the_rest_skeleton():
    pose = idle_pose()
    np.testing.assert_array_equal(pose[3:], rest_pose()[3:])  # the T-pose's rotations
    assert pose[0] == pose[2] == 0.0 and 0.8 < pose[1] < 1.1  # hips at standing height, metres


class ShowModel(TinyConvModel):
    """A TinyConvModel with the optional show controls of the PoseModel protocol: two styles
    (an offset on the root's x), an energy (a gain on the root) and its own idle (a still root)."""

    STYLES = {"plain": 0.0, "lean": 0.3}

    def __init__(self) -> None:
        super().__init__()
        self.style, self.energy, self.idle = "plain", 1.0, False

    def set_style(self, name: str) -> None:
        if name not in self.STYLES:
            raise ConfigError(f"unknown style {name!r} (styles: {', '.join(self.STYLES)})")
        self.style = name

    def set_energy(self, x: float) -> None:
        if not 0.0 <= x <= 2.0:
            raise ConfigError(f"energy must be in [0, 2], got {x!r}")
        self.energy = x

    def set_idle(self, idle: bool) -> None:
        self.idle = idle

    def push(self, features):
        out = super().push(features)
        out[:, :3] *= 0.0 if self.idle else self.energy
        out[:, 0] += self.STYLES[self.style]
        return out


def test_style_energy_and_idle_go_to_a_model_that_offers_them():
    model = ShowModel()
    audio = noise(1.0)
    sink = ActingSink({5: ("style", "lean"), 10: ("energy", 0.5), 15: ("idle", True)})
    # one hop per worker step: one push per frame, so a setting reaches the model's very next frame
    eng = Engine(FileSource(audio, SAMPLE_RATE, realtime=False, block_size=HOP), extractor, model, [sink],
                 EngineConfig(warmup_s=0, max_read=HOP))
    sink.engine = eng
    eng.start()
    assert eng.wait(30)
    eng.close()
    assert (model.style, model.energy, model.idle, eng.idle) == ("lean", 0.5, True, True)
    roots = np.stack([f.pose[:3] for f in sink.frames])
    ref = reference_poses(audio)[:, :3]
    lean = np.array([0.3, 0.0, 0.0], np.float32)
    np.testing.assert_allclose(roots[:6], ref[:6], atol=1e-5)
    np.testing.assert_allclose(roots[6:11], ref[6:11] + lean, atol=1e-5)
    np.testing.assert_allclose(roots[11:16], 0.5 * ref[11:16] + lean, atol=1e-5)
    # the model's own idle (a still root), not the engine's crossfade towards the rest skeleton's hips
    np.testing.assert_allclose(roots[16:], np.tile(lean, (len(roots) - 16, 1)), atol=1e-6)
    for action, value, message in [("style", "disco", "unknown style 'disco'"), ("energy", 5.0, "energy must be in"),
                                   ("energy", float("nan"), "energy must be a finite number"),
                                   ("style", "", "style must be a style name"), ("style", 7, "style must be"),
                                   ("style", "x" * 65, "style must be"), ("idle", 2, "idle must be 0 or 1"),
                                   ("idle", "1", "idle must be 0 or 1"), ("idle", float("nan"), "idle must be 0 or 1")]:
        with pytest.raises(ConfigError, match=message):
            eng.control(action, value)
    assert (model.style, model.energy, model.idle) == ("lean", 0.5, True)  # nothing changed


def test_a_model_without_style_or_energy_refuses_them_clearly():
    eng = Engine(FileSource(noise(0.1), SAMPLE_RATE, realtime=False), extractor, TinyConvModel(), [],
                 EngineConfig(warmup_s=0))
    for action in ("style", "energy"):
        with pytest.raises(ConfigError, match=f"^this model offers no {action} control$"):
            eng.control(action, "calm" if action == "style" else 1.0)
    with pytest.raises(ConfigError, match="unknown control action 'dance'"):
        eng.control("dance", 1)
    eng.control("idle", 1.0)  # a TouchOSC toggle's float
    assert eng.idle and eng.stats()["idle"] is True


# -- ring buffer metadata used for latency -------------------------------------------------


def test_release_time_of_each_sample_is_its_blocks():
    ring = RingBuffer(1000)
    for k, n in enumerate([100, 50, 300]):
        ring.write(np.zeros(n, np.float32), release_time=10.0 + k)
    assert ring.release_time(0) == 10.0
    assert ring.release_time(99) == 10.0
    assert ring.release_time(100) == 11.0
    assert ring.release_time(449) == 12.0
    assert np.isnan(ring.release_time(450))


# -- real outputs on loopback ------------------------------------------------------------


class UdpReceiver:
    """Collects every datagram sent to 127.0.0.1:port on a thread."""

    def __init__(self) -> None:
        import socket

        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 21)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.05)
        self.port = self.sock.getsockname()[1]
        self.datagrams: list[bytes] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self.datagrams.append(self.sock.recv(65536))
            except OSError:
                continue

    def close(self) -> list[bytes]:
        time.sleep(0.1)  # let the last datagrams arrive
        self._stop.set()
        self._thread.join()
        self.sock.close()
        return self.datagrams


def osc_messages(datagrams: list[bytes]) -> list[tuple[str, list]]:
    """(address, params) of every OSC message in the datagrams, bundles flattened (python-osc)."""
    from pythonosc.osc_bundle import OscBundle
    from pythonosc.osc_message import OscMessage

    out = []

    def walk(item):
        if isinstance(item, OscBundle):
            for x in item:
                walk(x)
        else:
            out.append((item.address, item.params))

    for dg in datagrams:
        walk(OscBundle(dg) if OscBundle.dgram_is_bundle(dg) else OscMessage(dg))
    return out


def test_file_to_real_udp_and_websocket_receivers():
    from websockets.sync.client import connect

    from realtime.osc_out import OscSink
    from realtime.wire import decode_frame
    from realtime.ws_server import WebSocketSink

    udp = UdpReceiver()
    osc = OscSink("127.0.0.1", udp.port, mode="plain")
    ws = WebSocketSink("127.0.0.1", 0, offsets=np.tile([0.0, 0.1, 0.0], (NUM_BONES, 1)))
    received: list = []
    connected = threading.Event()

    def client() -> None:
        with connect(ws.ws_url, open_timeout=5) as conn:
            connected.set()
            try:
                while True:
                    msg = conn.recv(timeout=3)
                    if isinstance(msg, bytes):
                        received.append(decode_frame(msg))
            except Exception:  # noqa: BLE001 - server closed or timeout: done
                pass

    t = threading.Thread(target=client, daemon=True)
    t.start()
    assert connected.wait(5)
    deadline = time.monotonic() + 5
    while ws.stats()["clients"] < 1 and time.monotonic() < deadline:
        time.sleep(0.01)
    eng, sink = run_engine(FileSource(noise(1.0), SAMPLE_RATE, realtime=True, block_size=735), sinks=[osc, ws])
    t.join(10)
    frames_osc = [p for a, p in osc_messages(udp.close()) if a == "/performer/frame"]
    assert len(sink.frames) == 30
    assert [p[0] for p in frames_osc] == list(range(30))  # loopback UDP: every frame, in order
    np.testing.assert_allclose([p[1] for p in frames_osc], (np.arange(30) + 1) * HOP / SAMPLE_RATE, atol=1e-6)
    assert eng.stats()["sinks"][ws.name]["clients"] == 0  # closed by engine.close()
    idx = [f.index for f in received]
    assert len(idx) >= 20 and idx == sorted(idx)  # a slow client may lose its oldest frames, never order
    for f in received:
        assert f.audio_time == pytest.approx((f.index + 1) * HOP / SAMPLE_RATE)
        np.testing.assert_allclose(f.pose, sink.frames[f.index].pose, atol=1e-6)


def test_no_osc_receiver_is_a_status_notice_while_real_drops_still_count():
    """No receiver on the OSC port: the status line says so and counts no drops for it; a
    WebSocket client that never reads still loses frames from its full queue: real drops."""
    from test_osc_out import closed_udp_port
    from test_ws_server import _stalled_client

    from realtime.osc_out import OscSink
    from realtime.status import format_status
    from realtime.ws_server import WebSocketSink

    port = closed_udp_port()
    notice = f"no receiver at 127.0.0.1:{port} (connection refused)"

    eng, _ = run_engine(FileSource(noise(1.0), SAMPLE_RATE, realtime=False), sinks=[OscSink("127.0.0.1", port)])
    st = eng.stats()
    assert st["frames"] == 30 and st["notices"] == [notice]
    line = format_status(st)
    assert "drops 0" in line and line.endswith(notice), line

    ws = WebSocketSink("127.0.0.1", 0, offsets=np.tile([0.0, 0.1, 0.0], (NUM_BONES, 1)), queue_frames=4)
    stalled = _stalled_client(ws.port)
    try:
        deadline = time.monotonic() + 5
        while ws.stats()["clients"] < 1 and time.monotonic() < deadline:
            time.sleep(0.01)
        eng, _ = run_engine(FileSource(noise(14.0), SAMPLE_RATE, realtime=False),
                            sinks=[OscSink("127.0.0.1", port), ws])
        st = eng.stats()
    finally:
        stalled.close()
    drops = st["sinks"][ws.name]["drops"]
    assert drops > 0 and st["notices"] == [notice]
    line = format_status(st)
    assert f"drops {int(drops)}" in line and notice in line, line
