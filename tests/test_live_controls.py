"""The live controls over long streams: a stateful property test (hypothesis ``RuleBasedStateMachine``)
of :class:`models.networks.dance_stream.DanceStream` driven the way a show desk drives it.

The machine pushes the bundled clip's features (looped) and the extractor's features of silence
(the clip followed by silence: the idle gate and the fade run) in chunks of 0..300 frames, and
between pushes sets what OSC ``/performer/style``, ``/energy``, ``/lead``, ``/idle``, stage,
facing, home and reset set (realtime/controls.py reaches the same setters), valid values and
junk (a bad value raises :class:`models.errors.ConfigError` with a message that names the
control, and changes nothing). After every push: the shape (k, POSE_DIM), every value finite,
every quaternion unit (1e-4), no bone turning more than :data:`STEP_GUARD_DEG` between consecutive
frames across any control change (no clean bound exists: see the constant). After ``reset()``
the stream replays, byte for byte, what a fresh stream with the same controls gives for the same
pushes and controls.

Three machines: the shipped model in place, the shipped model on a stage (set_stage, set_facing,
home), and a library model of the shared motion sample on its spot of the stage (performer 1 of an
ensemble of 2: a stage the spots do not fit is refused; its folder as a style; skipped without the
shared data). A style change once the 16-token window was full crashed the next push with
IndexError (fixed at dc52637): with that fix reverted both shipped machines and the engine test
fail with it, shrunk to ``push_music(k=121)``, ``set_style("C", then=8)`` (docs/testing.md);
``pytest -s`` prints each machine's examples, minutes pushed, longest stream and largest bone step.
"""

from __future__ import annotations

import functools
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, Phase, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, precondition, rule, run_state_machine_as_test

from models.errors import ConfigError
from models.networks.dance_stream import ENERGY_RANGE, LEAD_RANGE_MS, DanceStream
from models.networks.dance_vq import STYLE_TOKEN, STYLES
from models.networks.stage import ensemble_spots, parse_stage
from models.rig.kinematics import rotation_jumps_deg
from models.timebase import FPS

torch.set_num_threads(1)
pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]
SAMPLE_RATE = 22050
#: Seconds of silence after the clip the silence features are taken from (their context columns
#: decay over it, as after a song).
SILENCE_S = 20
#: The largest bone turn (degrees) allowed between two consecutive frames, across any control.
#: No clean bound exists: the player's bone cap (the memory's 0.999 quantile of a frame's
#: largest bone turn, 26.7 deg for the shipped memory) is where it slows a movement, not a hard
#: bound (the clip alone reaches 29.8; the feet part on a stage turns a foot up to 45), and the
#: idle fade turns a bone up to 180 deg over the shipped idle_gate.FADE_FRAMES (16) with a
#: smoothstep (at most 1.5 x 180 / 16 = 16.9 deg a frame) on top of the dance. The guard is twice
#: the cap plus the fade's share, a number (not read from FADE_FRAMES, so a shorter fade breaks it):
#: the examples' largest is 59 deg (``pytest -s``); with FADE_FRAMES 1 the test fails on a 78-deg snap.
STEP_GUARD_DEG: float = 70.0
#: Frames the predictor's token window spans (16 tokens of 8 frames: 4.3 s).
TOKEN_FRAMES: int = 128
#: Quaternion norms allowed off 1.
UNIT_TOL: float = 1e-4


@functools.cache
def shipped():
    from models.generate import load_model

    return load_model(None)


@functools.cache
def clip_features() -> tuple[np.ndarray, np.ndarray]:
    """(the bundled clip's features (T, D), the features of the SILENCE_S s of silence after it (S, D))."""
    from models.features.audio_io import load_audio
    from models.features.spectral import extract_features

    y, _ = load_audio(REPO / "models" / "assets" / "clip.ogg", SAMPLE_RATE)
    audio = np.concatenate([y, np.zeros(SILENCE_S * SAMPLE_RATE, np.float32)])
    f = extract_features(audio, shipped().features)
    n = len(y) // (SAMPLE_RATE // FPS)
    return f[:n], f[n + FPS:]  # the silence a second in: what a song's end leaves


@functools.cache
def sample_library(folder: str):
    """A library model of the shared motion sample built into ``folder`` by the real command (None
    without the shared data: the sample is CC BY-NC, never kept in the repository)."""
    sample = REPO.parent / "shared" / "data" / "motion"
    if not sample.is_dir():
        return None
    from models.generate import load_library_model

    out = Path(folder) / "sample.npz"
    r = subprocess.run([sys.executable, "-m", "realtime.cli", "library", "build", sample, "--out", out], cwd=REPO,
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    return load_library_model(shipped().model, out)


def styles_of(model) -> tuple[str, ...]:
    """The style names the model dances (a library: its folders, with the default's where it keeps
    them; the default alone also takes the dataset's letters C, R, W: dance_vq.STYLE_TOKEN)."""
    names = tuple(getattr(model, "library_styles", ()))
    if not names:
        return tuple(STYLE_TOKEN)
    return names + (STYLES if getattr(model, "default_styles", True) else ())


#: Frames of music a push (and each valid control, after it) gives the stream: up to 10 s.
FRAMES = st.integers(0, 300)
BAD_STYLES = st.one_of(st.sampled_from(["", "Waltz", "salsa", "auto ", "none", "chacha\x00", "x" * 80]),
                       st.text(max_size=12))
BAD_NUMBERS = st.sampled_from([math.nan, math.inf, -math.inf, -1e-3, -1.0, 1e308, None, "x", [1.0], "1.5", True])
#: The number controls: (least, most, the fresh stream's argument).
NUMBERS: dict[str, tuple[float, float, str]] = {"energy": (*ENERGY_RANGE, "energy"), "lead": (*LEAD_RANGE_MS, "lead_ms")}
BAD_STAGES = st.sampled_from(["", "3", "3x", "x2", "axb", "-3x2", "3x-2", "nanx2", "infx2", "3x2x1", -1, 2.5,
                              None, "9" * 40, (1.0,), "3x0"])


class LiveControls(RuleBasedStateMachine):
    """One performer's stream driven by a show's controls; the invariants hold after every step."""

    def __init__(self, model, music: np.ndarray, silence: np.ndarray, stage, tally: dict,
                 spot: tuple[int, int] | None = None) -> None:
        super().__init__()
        self.tally = tally  # over the examples: frames pushed, the longest stream, the largest step, late styles
        tally["examples"] += 1
        self.model, self.music, self.silence = model, music, silence
        self.styles = styles_of(model)
        self.staged = stage != 0
        self.ctl = {"seed": 3, "style": None, "energy": 1.0, "lead_ms": 0.0, "stage": stage, "facing": "free",
                    "idle": False, "spot": spot}
        self.stream = DanceStream(model, seed=3, stage=stage, spot=spot)
        self.pos = 0  # next clip frame (looped)
        self.quiet = 0  # next silence frame (looped)
        self.last: np.ndarray | None = None  # the last pose pushed (None after a reset)
        self.replay: list | None = None  # since the last reset: (fresh stream's controls, [(op, arg, out)])
        self.largest = 0.0

    # -- pushes -------------------------------------------------------------------------------
    def _push(self, feats: np.ndarray) -> None:
        out = self.stream.push(feats)
        k, p = len(feats), self.stream.pose_dim
        assert out.shape == (k, p) and out.dtype == np.float32, out.shape
        assert np.isfinite(out).all(), f"non-finite pose at frame {self.stream.frame - k}"
        q = out[:, 3:].reshape(k, (p - 3) // 4, 4).astype(np.float64)
        norms = np.linalg.norm(q, axis=-1)
        assert np.abs(norms - 1.0).max(initial=0.0) <= UNIT_TOL, f"a quaternion of norm {norms.min()}..{norms.max()}"
        track = q if self.last is None else np.concatenate([self.last[None], q])
        if len(track) > 1:
            steps = rotation_jumps_deg(track).max(axis=1)
            self.largest = max(self.largest, float(steps.max()))
            assert steps.max() <= STEP_GUARD_DEG, \
                f"a bone turned {steps.max():.1f} deg in one frame (guard {STEP_GUARD_DEG:.1f}), " \
                f"frame {self.stream.frame - len(steps) + int(np.argmax(steps))}, idle weight {self.stream.idle_weight}"
        if k:
            self.last = q[-1]
        self.tally["frames"] += k
        self.tally["longest"] = max(self.tally["longest"], self.stream.frame)
        self.tally["largest"] = max(self.tally["largest"], self.largest)
        if self.replay is not None:
            self.replay[1].append(("push", feats, out))

    def _music(self, k: int) -> None:
        idx = (self.pos + np.arange(k)) % len(self.music)
        self.pos = (self.pos + k) % len(self.music)
        self._push(self.music[idx])

    @rule(k=FRAMES)
    def push_music(self, k: int) -> None:
        self._music(k)

    @rule(k=FRAMES)
    def push_silence(self, k: int) -> None:
        idx = (self.quiet + np.arange(k)) % len(self.silence)
        self.quiet = (self.quiet + k) % len(self.silence)
        self._push(self.silence[idx])

    # -- controls ------------------------------------------------------------------------------
    def _control(self, name: str, value, key: str | None, then: int) -> None:
        """The control ``name`` set to ``value`` (``...``: called without one), then ``then`` frames of music."""
        if name == "set_style" and self.stream.frame >= TOKEN_FRAMES:
            self.tally["late styles"] += 1
        getattr(self.stream, name)(*(() if value is ... else (value,)))
        if key is not None:
            self.ctl[key] = value
        if self.replay is not None:
            self.replay[1].append((name, value, None))
        self._music(then)

    def _refused(self, name: str, value, match: str) -> None:
        before = (self.stream.style, self.stream.energy, self.stream.lead_ms, self.stream.stage.width,
                  self.stream.stage.depth, self.stream.stage.facing)
        with pytest.raises(ConfigError, match=match):
            getattr(self.stream, name)(value)
        assert before == (self.stream.style, self.stream.energy, self.stream.lead_ms, self.stream.stage.width,
                          self.stream.stage.depth, self.stream.stage.facing), f"a refused {name} changed the stream"

    @rule(data=st.data(), then=FRAMES)
    def set_style(self, data, then: int) -> None:
        self._control("set_style", data.draw(st.sampled_from((None, "auto") + self.styles)), "style", then)

    @rule(name=BAD_STYLES)
    def set_bad_style(self, name: str) -> None:
        if name in self.styles or name == "auto":
            return
        self._refused("set_style", name, "style")

    @rule(control=st.sampled_from(sorted(NUMBERS)), data=st.data(), then=FRAMES)
    def set_number(self, control: str, data, then: int) -> None:
        """set_energy (0..2) or set_lead (0..200 ms)."""
        lo, hi, key = NUMBERS[control]
        self._control(f"set_{control}", data.draw(st.floats(lo, hi)), key, then)

    @rule(control=st.sampled_from(sorted(NUMBERS)), data=st.data())
    def set_bad_number(self, control: str, data) -> None:
        """Junk or out of range energy or lead: refused."""
        lo, hi, _ = NUMBERS[control]
        bad = data.draw(st.one_of(BAD_NUMBERS, st.floats(hi, exclude_min=True), st.floats(max_value=lo, exclude_max=True)))
        self._refused(f"set_{control}", bad, f"{control} must be")

    @rule(idle=st.booleans(), then=FRAMES)
    def set_idle(self, idle: bool, then: int) -> None:
        self._control("set_idle", idle, "idle", then)

    @precondition(lambda self: self.staged)
    @rule(stage=st.sampled_from(["3x2", "6x5", "1x1", "0", 0, (4.0, 3.0), "0.5x12"]), then=FRAMES)
    def set_stage(self, stage, then: int) -> None:
        """A stage; an ensemble performer's spot is cut from it, refused where the spots do not fit."""
        if self.ctl["spot"] is not None:
            try:
                ensemble_spots(parse_stage(stage), self.ctl["spot"][1])
            except ConfigError:
                self._refused("set_stage", stage, "stage")
                return
        self._control("set_stage", stage, "stage", then)

    @precondition(lambda self: self.staged)
    @rule(stage=BAD_STAGES)
    def set_bad_stage(self, stage) -> None:
        self._refused("set_stage", stage, "stage")

    @precondition(lambda self: self.staged)
    @rule(facing=st.sampled_from(["free", "audience"]), then=FRAMES)
    def set_facing(self, facing: str, then: int) -> None:
        self._control("set_facing", facing, "facing", then)

    @precondition(lambda self: self.staged)
    @rule(facing=st.sampled_from(["", "Audience", "front", None, 1]))
    def set_bad_facing(self, facing) -> None:
        self._refused("set_facing", facing, "facing must be")

    @precondition(lambda self: self.staged)
    @rule(then=FRAMES)
    def home(self, then: int) -> None:
        self._control("home", ..., None, then)

    @rule()
    def reset(self) -> None:
        self.check_replay()
        self.stream.reset()
        self.last = None
        self.replay = (dict(self.ctl), [])

    # -- the offline check ---------------------------------------------------------------------
    def check_replay(self) -> None:
        """What the stream gave since its last reset is what a fresh stream with the controls it had
        then gives for the same pushes and controls (equal bytes)."""
        if self.replay is None or not any(op == "push" for op, _, _ in self.replay[1]):
            return
        c, ops = self.replay
        fresh = DanceStream(self.model, seed=c["seed"], style=c["style"], energy=c["energy"], lead_ms=c["lead_ms"],
                            stage=c["stage"], facing=c["facing"], spot=c["spot"])
        fresh.set_idle(c["idle"])
        for n, (op, arg, out) in enumerate(ops):
            if op == "push":
                got = fresh.push(arg)
                assert got.tobytes() == out.tobytes(), \
                    f"after reset the stream differs from a fresh one at push {n} (frames {fresh.frame - len(arg)}..)"
            else:
                getattr(fresh, op)(*(() if arg is ... else (arg,)))

    def teardown(self) -> None:
        self.check_replay()


#: Per machine: steps per example and hypothesis's settings (derandomized: every run plays the
#: same examples, so CI time stays put; a failure prints its shrunk steps). Each push and each
#: valid control gives the stream 0..300 frames, so the examples run streams of minutes, past the
#: token window (128 frames) many times; their CPU time and lengths: docs/testing.md.
RUNS = settings(stateful_step_count=40, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def run_machine(model, stage, examples: int, spot: tuple[int, int] | None = None, shrink: bool = True) -> None:
    music, silence = clip_features()
    tally = {"examples": 0, "frames": 0, "longest": 0, "largest": 0.0, "late styles": 0}
    phases = None if shrink else [Phase.explicit, Phase.reuse, Phase.generate]  # a failure reported as found
    run_state_machine_as_test(lambda: LiveControls(model, music, silence, stage, tally, spot),
                              settings=settings(RUNS, max_examples=examples, **({"phases": phases} if phases else {})))
    print(f"{tally['examples']} examples, {tally['frames'] / FPS / 60:.1f} min pushed, the longest stream "
          f"{tally['longest'] / FPS / 60:.1f} min, the largest bone step {tally['largest']:.1f} deg, "
          f"{tally['late styles']} styles set after the token window filled")


def test_the_shipped_performer_takes_every_live_control_over_long_streams():
    run_machine(shipped().model, 0, 12)


def test_the_shipped_performer_on_a_stage_takes_every_live_control_over_long_streams():
    run_machine(shipped().model, "3x2", 12)


def test_a_library_performer_takes_every_live_control_over_long_streams(tmp_path_factory):
    model = sample_library(str(tmp_path_factory.mktemp("library")))
    if model is None:
        pytest.skip(f"needs the shared motion sample at {REPO.parent / 'shared' / 'data' / 'motion'}")
    run_machine(model, "3x2", 10, spot=(1, 2), shrink=False)  # performer 1 of an ensemble of 2: its spot


def test_the_engine_with_the_shipped_performer_plays_on_through_osc_controls_after_5_s():
    """One level up: the real engine (realtime/engine.py) plays the bundled clip twice (fast, not paced)
    through the shipped performer, and after 5 s of audio (frame 150: the token window full) real OSC
    datagrams over UDP change its style (guided waltz, cha-cha by letter, back to auto), energy and lead,
    and send a bad style. Every good message is applied, the bad one counted, and the engine plays the
    audio to its end: not "failed". With dc52637's fix reverted the engine stops "failed" with IndexError."""
    import socket
    import time

    from pythonosc.osc_message_builder import OscMessageBuilder

    from models.features.audio_io import load_audio
    from models.features.streaming import StreamingFeatureExtractor
    from realtime.audio_input import FileSource
    from realtime.engine import Engine
    from realtime.engine_config import EngineConfig
    from realtime.osc_control import OscControl

    lm = shipped()
    y, _ = load_audio(REPO / "models" / "assets" / "clip.ogg", SAMPLE_RATE)
    audio = np.concatenate([y, y])
    total = len(audio) // (SAMPLE_RATE // FPS)
    eng = Engine(FileSource(audio, SAMPLE_RATE, realtime=False), lambda sr: StreamingFeatureExtractor(lm.features, sr),
                 DanceStream(lm.model, seed=0), [], EngineConfig(warmup_s=0))

    def message(address: str, *args) -> bytes:
        b = OscMessageBuilder(address)
        for a in args:
            b.add_arg(a)
        return b.build().dgram

    sent = [message("/performer/style", "waltz"), message("/performer/energy", 2.0),
            message("/performer/style", "C"), message("/performer/lead", 100.0), message("/performer/style", "salsa"),
            message("/performer/style", "auto")]
    with OscControl(port=0, control=eng.control) as osc, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp:
        osc.start()
        eng.start()
        try:
            deadline = time.monotonic() + 60.0
            while eng.frames_out < 5 * FPS:
                assert eng.state != "failed" and time.monotonic() < deadline, f"the engine did not play 5 s: {eng.state}"
                time.sleep(0.002)
            at = eng.frames_out
            for dgram in sent:
                udp.sendto(dgram, ("127.0.0.1", osc.port))
                seen = eng.frames_out
                while osc.stats()["applied"] + osc.stats()["bad"] < sent.index(dgram) + 1:
                    assert time.monotonic() < deadline, "a control message was never applied"
                    time.sleep(0.001)
                while eng.frames_out < seen + 2 * lm.model.config.seg and eng.running:  # a code step or two on
                    time.sleep(0.001)
            after = eng.frames_out
            assert after < total, f"the controls came at frames {at}..{after} of {total}: too late to test anything"
            print(f"the controls came at frames {at}..{after} of {total}")
            eng.wait(timeout=120.0)
        finally:
            eng.stop()
        stats = osc.stats()
    assert eng.error is None and eng.state != "failed", f"the engine stopped: {eng.state}: {eng.error!r}"
    assert eng.frames_out == total, (eng.frames_out, total)
    assert (stats["applied"], stats["bad"]) == (len(sent) - 1, 1), stats  # salsa: no such style
