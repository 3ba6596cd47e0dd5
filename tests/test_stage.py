"""The stage part (models/networks/stage.py) and the travel memory it plays
(models/training/travel_memory.py): travel and turns from the exemplars, inside the stage,
facing the audience when asked, the same in any chunking; old checkpoints load in place."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from test_dance_vq import TINY, _Clip, _poses, memory_model, music, tiny_model

from models.errors import ConfigError
from models.networks import stage as stage_mod
from models.networks.dance_stream import DanceStream, generate
from models.networks.dance_vq import DanceVQ
from models.networks.stage import MAX_SPEED, Stage, parse_stage
from models.timebase import FPS
from models.training.dance_vq import fit_members, window_travel


def walking_model(speed: float = 0.02, turn: float = 0.0, sway: float = 0.0) -> DanceVQ:
    """A tiny dance_vq whose exemplars all come from one dancer walking forward at ``speed``
    m a frame while turning ``turn`` radians a frame and swaying its heading ``sway`` radians
    either way every 2 s (its travel memory filled by fit_members)."""
    poses = _poses(300, np.random.default_rng(1))
    m = memory_model(poses)
    t = np.arange(300, dtype=np.float64)
    heading = turn * t + sway * np.sin(2 * np.pi * t / 60.0)
    # forward along the heading: d/dt (x, z) = speed (sin h, cos h)
    x = np.concatenate([[0.0], np.cumsum(speed * np.sin(heading[:-1]))])
    z = np.concatenate([[0.0], np.cumsum(speed * np.cos(heading[:-1]))])
    fit_members(m, [_Clip(poses, np.zeros((300, TINY.feature_dim), np.float32), "R")],
                travel=[np.stack([x, z, heading], 1)])
    return m.eval()


def track(poses: np.ndarray) -> np.ndarray:
    """(T, 3) root x, z and the Hips' unwrapped heading of poses (T, P)."""
    from scipy.spatial.transform import Rotation

    from models.data.canonical import heading

    h = np.unwrap(heading(Rotation.from_quat(poses[:, 3:7].astype(np.float64))))
    return np.stack([poses[:, 0], poses[:, 2], h], 1)


def test_window_travel_is_relative_to_the_first_frame_in_its_heading_frame():
    # facing +X (heading 90 degrees) and walking 1 m along +X: 1 m forward (+Z) in its own frame
    tr = np.array([[2.0, 3.0, math.pi / 2], [3.0, 3.0, math.pi / 2 + 0.1]])
    np.testing.assert_allclose(window_travel(tr), [[0, 0, 0], [0, 1, 0.1]], atol=1e-6)


def test_fit_members_records_each_exemplars_travel_and_zeros_without_it():
    m = walking_model(speed=0.02, turn=0.01)
    real = m.member_count.numpy() > 0
    tr = m.member_travel.float().numpy()[real][:, 0]  # (n, 2 seg, 3), first exemplar of each code
    np.testing.assert_allclose(tr[:, 0], 0.0)
    np.testing.assert_allclose(tr[:, -1, 2], 0.01 * 15, atol=1e-3)  # the turn over 15 frames
    np.testing.assert_allclose(np.linalg.norm(tr[:, 1, :2], axis=1), 0.02, atol=1e-3)  # the walk's pace
    assert (tr[:, 1, 1] > 0.019).all()  # forward in the window's own frame
    fit_members(m, [_Clip(_poses(300, np.random.default_rng(1)), np.zeros((300, TINY.feature_dim)), "R")])
    assert float(m.member_travel.abs().sum()) == 0.0  # no tracks: in place


def test_the_performer_travels_and_turns_as_its_exemplars_do():
    """Switching travel off (no stage step, or no travel read) fails this: the root stays at
    the origin and the heading at 0."""
    m = walking_model(speed=0.02, turn=0.01)
    x = music(600)
    tr = track(generate(m, x, seed=3, stage="100x100"))
    dancing = slice(90, None)  # after the fade-in from the idle
    path = np.linalg.norm(np.diff(tr[dancing, :2], axis=0), axis=1).sum()
    turned = np.abs(np.diff(tr[dancing, 2])).sum()
    n = len(tr) - 91
    assert 0.5 * 0.02 * n < path < 2.0 * 0.02 * n  # about the exemplars' pace (the tempo rate is 1 here)
    assert 0.5 * 0.01 * n < turned < 2.0 * 0.01 * n
    assert np.linalg.norm(np.diff(tr[:, :2], axis=0), axis=1).max() <= MAX_SPEED / FPS + 1e-6  # no jump at handovers
    in_place = generate(m, x, seed=3)  # stage 0: exactly the pose the player makes
    np.testing.assert_array_equal(in_place[:, [0, 2]], 0.0)
    assert np.abs(track(in_place)[:, 2]).max() < math.radians(5)  # the idle sway turns the hips 4 degrees at most


def test_the_stage_holds_the_performer_and_bends_its_path_without_stopping():
    """A dancer who walks straight on at 0.6 m/s: on 3x2 and 1x1 stages every frame is inside
    and it keeps moving along. Switching the bound off fails this (it walks off)."""
    m = walking_model(speed=0.02, turn=0.0)
    x = music(1800)  # a minute
    for w, d in ((3.0, 2.0), (1.0, 1.0)):
        tr = track(generate(m, x, seed=1, stage=f"{w:g}x{d:g}"))
        assert (np.abs(tr[:, 0]) <= w / 2 + 1e-6).all() and (np.abs(tr[:, 1]) <= d / 2 + 1e-6).all()
        speed = np.linalg.norm(np.diff(tr[:, :2], axis=0), axis=1)
        assert speed.max() <= MAX_SPEED / FPS + 1e-6
        assert speed[900:].sum() > 0.25 * 0.02 * 900  # still travelling in the second half minute: bent, not stuck
    free = track(generate(m, x, seed=1, stage="100x100"))
    assert np.abs(free[:, 1]).max() > 5.0  # without the stage's edges it would have walked 10+ m


def test_facing_audience_dances_the_turns_and_comes_back_to_face_z():
    """A dancer who turns on the spot, 90 degrees either way and back every 2 s: free, the
    heading wanders off (each movement turns from where the last one ended); audience, most
    frames face +Z within 45 degrees and it still turns. Switching the facing off fails this."""
    m = walking_model(speed=0.0, sway=math.radians(90.0))
    x = music(1800)
    free = track(generate(m, x, seed=2, stage="6x5", facing="free"))
    aud = track(generate(m, x, seed=2, stage="6x5", facing="audience"))
    off = np.abs((aud[90:, 2] + math.pi) % (2 * math.pi) - math.pi)
    assert (off <= math.radians(45)).mean() >= 0.8
    turned = {k: np.abs(np.diff(v[90:, 2])).sum() for k, v in (("free", free), ("aud", aud))}
    assert turned["free"] > 0.3 * math.radians(90.0) * 4 / 60 * (len(x) - 91)  # of 360 degrees of turning every 2 s
    assert turned["aud"] >= 0.2 * turned["free"]  # the turns are still danced
    off_free = np.abs((free[90:, 2] + math.pi) % (2 * math.pi) - math.pi)
    assert (off_free <= math.radians(45)).mean() < 0.5


def test_stream_equals_the_whole_song_in_any_chunking_on_a_stage():
    m = walking_model(speed=0.02, turn=0.02)
    x = music(400)
    whole = generate(m, x, seed=4, stage="3x2", facing="audience")
    rng = np.random.default_rng(0)
    s = DanceStream(m, seed=4, stage="3x2", facing="audience")
    parts, i = [], 0
    while i < len(x):
        k = int(rng.integers(0, 20))
        parts.append(s.push(x[i: i + k]))
        i += k
    np.testing.assert_allclose(np.concatenate(parts), whole, atol=1e-6, rtol=0)
    s.reset()
    np.testing.assert_array_equal(s.push(x), whole)
    assert np.abs(whole[:, [0, 2]]).max() > 0.1


def test_a_handover_read_on_the_frame_before_is_what_it_reads_at_its_code_step(monkeypatch):
    """On the frame before a code step the stream reads what the coming handover reads of the playing
    movement (DanceStream._read_ahead: the rows before the new movement, their contacts and lifts,
    the next two poses; Stage.read_ahead: the track's rows), so the code step only takes them: every
    handover but the first does, and the poses are bit for bit those of a stream that reads them at
    its code step (a turning walker on a 3x2 stage, facing free and the audience)."""
    m = walking_model(speed=0.03, turn=0.03, sway=0.3)
    x = music(400)
    taken = {"stream": 0, "stage": 0}
    ahead_for, handover = DanceStream._ahead_for, Stage.handover

    def counted(self, reached, d):
        got = ahead_for(self, reached, d)
        taken["stream"] += got is not None
        return got

    def stage_counted(self, at, travel, first, lead=None):
        taken["stage"] += self._ahead is not None and not first
        return handover(self, at, travel, first, lead)

    for facing in ("free", "audience"):
        monkeypatch.setattr(DanceStream, "_ahead_for", counted)
        monkeypatch.setattr(Stage, "handover", stage_counted)
        taken.update(stream=0, stage=0)
        s = DanceStream(m, seed=4, stage="3x2", facing=facing)
        got = np.concatenate([s.push(x[i:i + 1]) for i in range(len(x))])
        steps = len(s.codes_drawn)
        assert taken["stream"] == steps - 1 and taken["stage"] == steps - 1  # _ahead_for: once a step, its reading shared
        monkeypatch.setattr(DanceStream, "_read_ahead", lambda self: None)  # each handover reads its own rows
        monkeypatch.setattr(Stage, "handover", handover)
        own = DanceStream(m, seed=4, stage="3x2", facing=facing)
        np.testing.assert_array_equal(got, np.concatenate([own.push(x[i:i + 1]) for i in range(len(x))]))
        monkeypatch.undo()
    assert np.abs(got[:, [0, 2]]).max() > 0.1


def _handover_track_numpy(tr, s, seg, base, travel, carry, first, origin):
    """Stage.handover's track arithmetic as it was in NumPy (the reference of its kernels)."""
    c, sn = math.cos(base[2]), math.sin(base[2])
    e = s + 2 * seg
    if travel is None:
        tr[s:e] = base
    else:
        tr[s:e, 0] = base[0] + c * travel[:, 0] + sn * travel[:, 1]
        tr[s:e, 1] = base[1] - sn * travel[:, 0] + c * travel[:, 1]
        tr[s:e, 2] = base[2] + travel[:, 2]
    if not first:
        prev = tr[s - 1]
        dv = [base[i] - prev[i] - (tr[s + 1, i] - tr[s, i]) for i in range(3)]
        tr[s:e] += carry * dv
    tr[e:] = tr[e - 1]
    if origin is not None:
        p = origin
        c, sn = math.cos(p[2]), math.sin(p[2])
        dx, dz = tr[:, 0] - p[0], tr[:, 1] - p[1]
        tr[:, 0], tr[:, 1] = c * dx - sn * dz, sn * dx + c * dz
        tr[:, 2] -= p[2]


def test_the_handovers_track_kernels_give_the_numpy_arithmetic_bit_for_bit():
    """Stage.handover places the new movement's travel on the track and moves its origin in two
    compiled calls (models/networks/dance_jit.py: place_travel, reorigin_track) instead of about 25
    NumPy calls on a few rows: the same float64 values, bit for bit (random tracks, travels and
    carries; in place and travelling; the first movement and the later ones)."""
    from models.networks.dance_jit import place_travel, reorigin_track

    rng = np.random.default_rng(7)
    seg = 8
    carry = Stage(seg, "3x2", "free")._carry
    for trial in range(300):
        tr = rng.normal(size=(4 * seg, 3)) * rng.choice([0.01, 1.0, 30.0])
        s = int(rng.integers(seg, 2 * seg + 1))
        base = tuple(float(v) for v in rng.normal(size=3) * 2)
        travel = None if trial % 5 == 0 else np.cumsum(rng.normal(scale=0.02, size=(2 * seg, 3)), axis=0)
        first = trial % 7 == 0
        origin = None if first or trial % 3 == 0 else tuple(float(v) for v in rng.normal(size=3))
        want = tr.copy()
        _handover_track_numpy(want, s, seg, base, travel, carry, first, origin)
        got = tr.copy()
        place_travel(got, s, 2 * seg, *base, math.cos(base[2]), math.sin(base[2]),
                     np.zeros((0, 3)) if travel is None else travel, carry, not first)
        if origin is not None:
            reorigin_track(got, *origin, math.cos(origin[2]), math.sin(origin[2]))
        assert got.tobytes() == want.tobytes()


def test_the_idle_stands_still_and_home_walks_back_to_the_centre():
    m = walking_model(speed=0.02, turn=0.0)
    s = DanceStream(m, seed=0, stage="6x5")
    s.set_idle(True)
    held = s.push(music(300))
    np.testing.assert_array_equal(held[:, [0, 2]], 0.0)
    s.set_idle(False)
    s.push(music(300))
    assert math.hypot(s.stage.x, s.stage.z) > 0.5
    s.home()
    s.set_idle(True)  # home walks even while idle
    p = s.push(music(10 * FPS))  # at most 3.9 m at 0.6 m/s, then slowing in
    assert math.hypot(s.stage.x, s.stage.z) < 0.03 and not s.stage.homing
    assert np.linalg.norm(np.diff(p[:, [0, 2]], axis=0), axis=1).max() <= stage_mod.HOME_SPEED / FPS + 1e-6


def test_bad_stage_and_facing_values_are_one_line_config_errors():
    s = DanceStream(walking_model(), seed=0)
    for bad in ("3y2", "-1x2", "0x2", "nanx1", "1000x1", "", None, True, "3x2x1"):
        with pytest.raises(ConfigError, match="stage") as e:
            s.set_stage(bad)
        assert "\n" not in str(e.value)
    with pytest.raises(ConfigError, match="facing"):
        s.set_facing("back")
    assert parse_stage("3x2") == (3.0, 2.0) and parse_stage("0") == (0.0, 0.0) and parse_stage(0) == (0.0, 0.0)
    assert parse_stage((6, 5)) == (6.0, 5.0) and parse_stage(" 1.5 X 1 ") == (1.5, 1.0)
    s.set_stage("1x1")
    s.set_facing("audience")
    assert s.stage.active and s.stage.facing == "audience"


def test_checkpoints_from_before_the_travel_memory_load_in_place(tmp_path):
    m = walking_model(speed=0.02, turn=0.01)
    state = {k: v for k, v in m.state_dict().items() if k != "member_travel"}
    m2 = DanceVQ(m.config)
    with torch.no_grad():
        m2.member_travel.fill_(1.0)  # stale values the load must clear
    m2.load_state_dict(state, strict=True)
    assert float(m2.member_travel.abs().sum()) == 0.0
    m2.eval()
    x = music(200)
    on_stage = generate(m2, x, seed=1, stage="3x2")
    np.testing.assert_array_equal(on_stage, generate(m2, x, seed=1))  # zeros: in place, facing +Z
    assert not np.array_equal(generate(m, x, seed=1, stage="3x2"), on_stage)


def test_a_stage_without_a_playing_movement_stays_at_the_centre():
    st = Stage(8, "3x2")
    pose = np.zeros(87, np.float32)
    pose[6] = 1.0
    st.step(pose, 8.0, 0.0)
    assert (st.x, st.z, st.heading) == (0.0, 0.0, 0.0) and pose[6] == 1.0
    decoded = generate(tiny_model(), music(100), seed=0, stage="3x2")  # no exemplars: decoded movements, no travel
    np.testing.assert_array_equal(decoded[:, [0, 2]], 0.0)


def test_travel_memory_is_added_to_an_older_checkpoint_only_from_its_own_training_motion():
    from models.errors import DataError
    from models.training.travel_memory import add_travel_memory

    poses = _poses(300, np.random.default_rng(1))
    m = memory_model(poses)
    clips = [_Clip(poses, np.zeros((300, TINY.feature_dim), np.float32), "R")]
    fit_members(m, clips)  # as trained before the travel memory: in place
    with torch.no_grad():
        m.member_period.fill_(20.0)  # the songs' tempi, which these clips' (zero) features cannot refit
    kept = {k: v.clone() for k, v in m.state_dict().items() if k != "member_travel"}
    t = np.arange(300.0)
    add_travel_memory(m, clips, [np.stack([np.zeros(300), 0.01 * t, 0.02 * t], 1)])
    assert all(torch.equal(v, m.state_dict()[k]) for k, v in kept.items())  # only the travel is new
    real = m.member_count > 0
    np.testing.assert_allclose(m.member_travel[real][:, 0, -1, 2].float().numpy(), 0.3, atol=1e-3)  # 15 frames at 0.02
    travel = m.member_travel.clone()
    with pytest.raises(DataError, match="other exemplars"):
        add_travel_memory(m, [_Clip(_poses(300, np.random.default_rng(7)), clips[0].features, "R")],
                          [np.zeros((300, 3))])
    assert torch.equal(m.member_travel, travel) and all(torch.equal(v, m.state_dict()[k]) for k, v in kept.items())


def test_stage_facing_and_home_are_engine_and_osc_controls():
    """``Engine.control("stage" | "facing" | "home")``, which the WebSocket and OSC control
    inputs send: checked first (one line, nothing changed), then passed to the stream; a model
    without a stage refuses them."""
    from test_engine import TinyConvModel, extractor, noise

    from models.timebase import SAMPLE_RATE
    from realtime.audio_input import FileSource
    from realtime.engine import Engine
    from realtime.engine_config import EngineConfig
    from realtime.osc_control import OscControl

    s = DanceStream(walking_model(), seed=0)
    eng = Engine(FileSource(noise(0.1), SAMPLE_RATE, realtime=False), extractor, s, [], EngineConfig(warmup_s=0))
    eng.control("stage", "3x2")
    eng.control("facing", "audience")
    eng.control("home")
    assert (s.stage.width, s.stage.depth, s.stage.facing, s.stage.homing) == (3.0, 2.0, "audience", True)
    for action, value, message in [("stage", "3y2", "stage must be WxD"), ("stage", "9" * 5000, "stage must be WxD"),
                                   ("stage", float("nan"), "stage must be WxD"), ("stage", "0x3", "stage sides"),
                                   ("facing", "back", "facing must be one of free, audience"), ("facing", 1, "facing")]:
        with pytest.raises(ConfigError, match=message) as e:
            eng.control(action, value)
        assert "\n" not in str(e.value) and len(str(e.value)) < 200
    assert (s.stage.width, s.stage.depth, s.stage.facing) == (3.0, 2.0, "audience")  # nothing changed
    osc = OscControl(control=eng.control)
    try:
        assert osc._apply("/performer/stage", "s", ["0"]) and not s.stage.active
        assert osc._apply("/performer/facing", "s", ["free"]) and s.stage.facing == "free"
        s.stage._homing = False
        assert not osc._apply("/performer/home", "i", [0]) and not s.stage.homing  # a button's release
        assert osc._apply("/performer/home", "", []) and s.stage.homing
    finally:
        osc.close()
    other = Engine(FileSource(noise(0.1), SAMPLE_RATE, realtime=False), extractor, TinyConvModel(), [],
                   EngineConfig(warmup_s=0))
    for action, value in (("stage", "3x2"), ("facing", "free"), ("home", None)):
        with pytest.raises(ConfigError, match=f"^this model offers no {action} control$"):
            other.control(action, value)



def test_home_over_a_real_websocket_and_osc_udp_walks_the_performer_back_to_the_centre():
    """``{"type": "control", "action": "home"}`` on a real WebSocket and ``/performer/home`` in a
    real UDP datagram each reach the stream through the engine's control (``control_ok``), and the
    performer then walks back from where it travelled to within 3 cm of the centre. Taking
    ``home`` out of the controls fails this."""
    import json
    import socket
    import time

    from pythonosc.osc_message_builder import OscMessageBuilder
    from test_engine import extractor, noise
    from websockets.sync.client import connect

    from models.timebase import SAMPLE_RATE
    from realtime.audio_input import FileSource
    from realtime.engine import Engine
    from realtime.engine_config import EngineConfig
    from realtime.osc_control import OscControl
    from realtime.ws_server import WebSocketSink

    def walked_away() -> DanceStream:
        s = DanceStream(walking_model(speed=0.02), seed=0, stage="6x5")
        s.push(music(300))
        assert math.hypot(s.stage.x, s.stage.z) > 0.5 and not s.stage.homing
        return s

    def arrives(s: DanceStream) -> None:
        deadline = time.monotonic() + 5.0
        while not s.stage.homing:
            assert time.monotonic() < deadline, "home never reached the stream"
            time.sleep(0.01)
        s.set_idle(True)  # stand still: only the walk home moves it
        s.push(music(10 * FPS))  # at most 3.9 m at 0.6 m/s, then slowing in
        assert math.hypot(s.stage.x, s.stage.z) < 0.03 and not s.stage.homing

    s = walked_away()
    eng = Engine(FileSource(noise(0.1), SAMPLE_RATE, realtime=False), extractor, s, [], EngineConfig(warmup_s=0))
    server = WebSocketSink("127.0.0.1", 0, token="s3cret", control=eng.control)
    try:
        with connect(server.ws_url + "?token=s3cret", open_timeout=5) as ws:
            assert json.loads(ws.recv(timeout=5))["control"]
            ws.send(json.dumps({"type": "control", "action": "home"}))
            reply = json.loads(ws.recv(timeout=5))
            while reply.get("type") not in ("control_ok", "error"):  # skip a state or stats message
                reply = json.loads(ws.recv(timeout=5))
            assert (reply["type"], reply["action"]) == ("control_ok", "home"), reply
    finally:
        server.close()
    arrives(s)

    s = walked_away()
    eng = Engine(FileSource(noise(0.1), SAMPLE_RATE, realtime=False), extractor, s, [], EngineConfig(warmup_s=0))
    with OscControl(port=0, control=eng.control) as osc, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp:
        osc.start()
        udp.sendto(OscMessageBuilder("/performer/home").build().dgram, ("127.0.0.1", osc.port))
        arrives(s)
        assert osc.stats()["applied"] == 1

def test_stage_0_set_live_walks_back_to_the_centre_and_a_stage_again_starts_there():
    """Switching the stage off live does not jump the performer to the centre: it walks back
    and turns to face +Z, then dances in place (the pose untouched); a stage set again starts
    from there, without a jump."""
    from models.data.canonical import heading
    from scipy.spatial.transform import Rotation

    m = walking_model(speed=0.02, turn=0.01)
    s = DanceStream(m, seed=0, stage="6x5")
    parts = [s.push(music(400))]
    assert math.hypot(s.stage.x, s.stage.z) > 0.5 and abs(s.stage.heading) > 0.5
    s.set_stage(0)
    parts.append(s.push(music(300, seed=1)))
    assert (s.stage.x, s.stage.z, s.stage.heading) == (0.0, 0.0, 0.0)
    np.testing.assert_array_equal(parts[-1][-30:, [0, 2]], 0.0)  # in place again
    s.set_stage("3x2")
    parts.append(s.push(music(60, seed=2)))
    p = np.concatenate(parts)
    step = np.linalg.norm(np.diff(p[:, [0, 2]], axis=0), axis=1)
    assert step.max() <= (MAX_SPEED + stage_mod.HOME_SPEED) / FPS + 1e-6
    h = np.unwrap(heading(Rotation.from_quat(p[:, 3:7].astype(np.float64))))
    assert np.degrees(np.abs(np.diff(h))).max() < 20.0  # no turn in one frame


def test_a_spin_plays_no_faster_than_max_turn():
    """An exemplar turning 1.2 rad a frame (sped up further by the tempo rate): the heading turns
    at most MAX_TURN a second on the stage; without the cap it turns as fast as it is read."""
    m = walking_model(speed=0.0, turn=1.2)
    x = music(300)
    steps = np.abs(np.diff(track(DanceStream(m, seed=0, stage="6x5").push(x))[60:, 2]))
    assert steps.max() <= stage_mod.MAX_TURN / FPS + 1e-4
    cap = stage_mod.MAX_TURN
    try:
        stage_mod.MAX_TURN = 1e9
        free = np.abs(np.diff(track(DanceStream(m, seed=0, stage="6x5").push(x))[60:, 2]))
    finally:
        stage_mod.MAX_TURN = cap
    assert free.max() > 1.5 * cap / FPS


def test_near_an_edge_a_movement_that_heads_inwards_is_chosen(monkeypatch):
    """Stage.inwards: at the right edge facing +Z a movement travelling +x (out) is passed over for
    one travelling -x or along the edge; in the middle, or with none heading in, any may play. The
    shipped performer on the bundled clip on a 1x1 stage (seeds 0, 1): 78 % of the movements chosen
    near an edge head inwards with it, 55 % with ``INWARDS`` off (the bend alone)."""
    s = Stage(8, "3x2")
    moves = np.array([[0.2, 0.0], [-0.2, 0.0], [0.0, 0.2]])
    assert s.inwards(moves) is None  # the centre: no edge near
    s.x = 1.4
    assert s.inwards(moves).tolist() == [False, True, True]
    assert s.inwards(moves[:1]) is None  # none heads in: any may play
    s.heading = math.pi  # facing -Z the same own-frame moves turn round
    assert s.inwards(moves).tolist() == [True, False, True]

    from models.features.audio_io import load_audio
    from models.features.spectral import extract_features
    from models.generate import load_model

    lm = load_model(None)
    feats = extract_features(load_audio("models/assets/clip.ogg")[0], lm.features)

    def share() -> float:
        c = [DanceStream(lm.model, seed=seed, stage="1x1") for seed in (0, 1)]
        for st in c:
            st.push(feats)
        return sum(st.stage.counts["inward_choices"] for st in c) / sum(st.stage.counts["edge_choices"] for st in c)

    assert share() >= 0.7
    monkeypatch.setattr(stage_mod, "INWARDS", False)
    assert share() < 0.65
