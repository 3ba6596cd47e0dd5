"""An ensemble: several performers on one audio input (docs/show.md, "Ensemble").

Config parsing and its errors, the engine's input stage (one extractor per feature config)
and its stagger (each performer still equals its own offline pass), per-performer show
control over OSC and WebSocket, and a real ``performer run`` with three performers, real
UDP receivers and a WebSocket client, checked against single-performer runs.
"""

from __future__ import annotations

import argparse
import json
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from models.errors import ConfigError
from models.timebase import SAMPLE_RATE
from realtime import cli
from realtime.audio_input import FileSource
from realtime.config import (
    PerformerConfig, RunConfig, load_run_config, parse_performer, performer_live_changes, resolve_run_config,
)
from realtime.engine import Engine
from realtime.engine_config import EngineConfig
from realtime.performer import Performer, stagger_lead
from realtime.pipeline import build_pipeline
from realtime.vmc import osc_message
from _proc import default_sigint
from test_engine import osc_messages
from test_run_cli import clip, drain, free_port, one_line_error, tiny_checkpoint, udp_receiver  # noqa: F401 (fixtures)

REPO = Path(__file__).resolve().parents[1]


class ListSink:
    """Keeps every frame it is sent."""

    def __init__(self, name: str = "list") -> None:
        self.name = name
        self.frames: list = []

    def send(self, frame) -> None:
        self.frames.append(frame)

    def close(self) -> None:
        pass

    def stats(self) -> dict:
        return {"frames": len(self.frames)}


@pytest.fixture(scope="module")
def clip_audio(clip) -> np.ndarray:
    from models.features.audio_io import load_audio

    x, _ = load_audio(clip, SAMPLE_RATE)
    return np.asarray(x[: 4 * SAMPLE_RATE], dtype=np.float32)


def _ensemble(specs: list[tuple[str, int, str | None]], loaded: dict) -> list[Performer]:
    out = []
    for name, seed, style in specs:
        p = build_pipeline(None, seed=seed, style=style, loaded=loaded)
        out.append(Performer(name, p.model, p.extractor_factory, [ListSink()], feature_key=p.feature_key))
    return out


# -- configuration -------------------------------------------------------------------------------

def test_performer_flag_and_toml_tables_resolve_with_top_level_defaults(tmp_path):
    p = parse_performer("alice,style=waltz,seed=3,osc=127.0.0.1:9001,osc=10.0.0.2:9001,offset-ms=40")
    assert p == PerformerConfig(name="alice", style="waltz", seed=3, osc=["127.0.0.1:9001", "10.0.0.2:9001"],
                                offset_ms=40.0)
    conf = tmp_path / "show.toml"
    conf.write_text('audio = "a.wav"\nosc = ["127.0.0.1:39539"]\nstyle = "rumba"\nseed = 5\nsmoothing = 0.2\n'
                    'record = "takes/show.npz"\n'
                    '[[performer]]\nname = "alice"\nstyle = "waltz"\ncheckpoint = "ckpt/a.pt"\n'
                    '[[performer]]\nname = "bob"\nseed = 9\nws_path = "/stage/bob"\nphase = 3\n'
                    '[[performer]]\nname = "carol"\nosc = "192.168.1.20:40000"\nsmoothing = 0.5\n')
    cfg = RunConfig(**load_run_config(conf))
    a, b, c = cfg.performer_specs()
    assert (a.name, a.style, a.seed, a.checkpoint) == ("alice", "waltz", 5, tmp_path / "ckpt/a.pt")
    assert (b.style, b.seed, b.ws_path, b.phase, b.checkpoint) == ("rumba", 9, "/stage/bob", 3, None)
    assert [a.osc, b.osc, c.osc] == [[("127.0.0.1", 39539)], [("127.0.0.1", 39540)], [("192.168.1.20", 40000)]]
    assert [a.ws_path, c.ws_path] == ["/ws/alice", "/ws/carol"]
    assert [a.smoothing, c.smoothing] == [0.2, 0.5]
    assert a.record == tmp_path / "takes/show-alice.npz" and c.record == tmp_path / "takes/show-carol.npz"
    # --performer flags replace the file's list
    args = argparse.Namespace(config=str(conf), performer=["dave,seed=1"])
    (d,) = resolve_run_config(args).performer_specs()
    assert (d.name, d.seed, d.osc) == ("dave", 1, [("127.0.0.1", 39539)])
    # a reload: per-performer live settings, resolved
    new = RunConfig(**{**load_run_config(conf), "smoothing": 0.1})
    live, other = performer_live_changes(cfg, new)
    assert live == {"alice": {"smoothing": 0.1}, "bob": {"smoothing": 0.1}} and other == []


@pytest.mark.parametrize("performers, needle", [
    (["alice", "alice,seed=2"], "performer name 'alice' is given twice"),
    (["alice,osc=127.0.0.1:9000", "bob,osc=127.0.0.1:9000"], "performers 'alice' and 'bob' both use osc 127.0.0.1:9000"),
    (["alice,ws_path=/ws/x", "bob,ws_path=/ws/x"], "performers 'alice' and 'bob' both use ws_path /ws/x"),
    (["alice,record=t.npz", "bob,record=t.npz"], "both use record"),
    (["alice,style=tango"], "performer 'alice': style must be one of"),
    (["alice,smoothing=1.5"], "performer 'alice': smoothing must be [0, 1)"),
    (["alice,phase=-1"], "performer 'alice': phase must be 0..1023"),
    (["alice,ws_path=/ws"], "performer 'alice': ws_path must be a path like /ws/NAME"),
    (["al ice"], "performer name must be 1..32 letters"),
    (["alice,speed=3"], "'speed=3' is not KEY=VALUE with a key of"),
    (["alice,seed=x"], "seed must be a number, got 'x'"),
])
def test_bad_ensembles_are_one_line_errors_naming_the_performer(performers, needle):
    with pytest.raises(ConfigError) as e:
        resolve_run_config(argparse.Namespace(audio="x.wav", performer=performers))
    assert needle in str(e.value)


@pytest.mark.parametrize("text, needle", [
    ('[[performer]]\nseed = 1\n', "performer 1 has no name"),
    ('[[performer]]\nname = "a"\nspeed = 2\n', "performer 1: unknown key 'speed'"),
    ('[[performer]]\nname = "a"\nseed = "one"\n', "performer 1: key 'seed' must be int"),
    ('performer = ["a"]\n', "performer must be a list of tables"),
])
def test_bad_performer_tables_name_the_file_and_the_performer(tmp_path, text, needle):
    conf = tmp_path / "run.toml"
    conf.write_text(text)
    with pytest.raises(ConfigError) as e:
        resolve_run_config(argparse.Namespace(config=str(conf)))
    assert str(conf) in str(e.value) and needle in str(e.value)


def test_run_refuses_a_missing_checkpoint_and_a_style_the_model_lacks(capsys, clip, tiny_checkpoint):
    code = cli.main(["run", "--audio", str(clip), "--fast", "--no-ws", "--no-osc",
                     "--performer", "alice", "--performer", "bob,checkpoint=nope.pt"])
    line = one_line_error(capsys.readouterr().err)
    assert code == 2 and "performer 'bob': nope.pt: checkpoint not found" in line
    code = cli.main(["run", "--audio", str(clip), "--fast", "--no-ws", "--no-osc",
                     "--performer", f"bob,checkpoint={tiny_checkpoint},style=waltz"])
    line = one_line_error(capsys.readouterr().err)
    assert code == 2 and "performer 'bob'" in line and "takes no style" in line
    code = cli.main(["run", "--audio", str(clip), "--fast", "--no-ws", "--no-osc",
                     "--performer", f"bob,checkpoint={tiny_checkpoint},energy=1.5"])
    line = one_line_error(capsys.readouterr().err)
    assert code == 2 and "performer 'bob'" in line and "has no energy control" in line
    code = cli.main(["run", "--audio", str(clip), "--fast", "--no-ws", "--no-osc", "--energy", "2.5"])
    assert code == 2 and "energy must be 0..2" in one_line_error(capsys.readouterr().err)


def test_energy_reaches_each_performers_model_from_flags_and_tables(tmp_path):
    """--energy and a performer's energy key set the dancing model's energy control at start
    (the same as /performer/energy live); config.ENERGY_RANGE is the model's."""
    from models.networks.dance_stream import ENERGY_RANGE
    from realtime.config import ENERGY_RANGE as CONFIG_RANGE

    assert CONFIG_RANGE == ENERGY_RANGE
    conf = tmp_path / "show.toml"
    conf.write_text('audio = "x.wav"\nenergy = 0.5\n[[performer]]\nname = "calm"\n'
                    '[[performer]]\nname = "lively"\nenergy = 1.75\n')
    cfg = resolve_run_config(argparse.Namespace(config=str(conf)))
    calm, lively = cfg.performer_specs()
    assert (calm.energy, lively.energy) == (0.5, 1.75)
    loaded: dict = {}
    models = [build_pipeline(None, energy=spec.energy, loaded=loaded).model for spec in (calm, lively)]
    assert [m.energy for m in models] == [0.5, 1.75] and build_pipeline(None, loaded=loaded).model.energy == 1.0
    assert parse_performer("zed,energy=0.25").energy == 0.25
    for text, needle in [("zed,energy=3", "performer 'zed': energy must be 0..2"),
                         ("zed,energy=loud", "energy must be a number")]:
        with pytest.raises(ConfigError, match=needle):
            RunConfig(performer=[parse_performer(text)]).validate()
    new = RunConfig(**{**load_run_config(conf), "energy": 1.0})
    live, other = performer_live_changes(cfg, new)
    assert live == {} and other == ["energy", "performer calm: energy"]  # a restart: as style


def test_lead_reaches_each_performers_model_from_flags_tables_osc_and_websocket(tmp_path, capsys, clip,
                                                                                tiny_checkpoint):
    """--lead and a performer's lead key set the dancing model's lead at start; /performer/lead
    over a real UDP socket and the WebSocket control's ``lead`` change it live, per performer or
    for all; out of range or for a model without the control it is refused in one line."""
    from websockets.sync.client import connect

    from models.networks.dance_stream import LEAD_RANGE_MS
    from realtime.config import LEAD_RANGE_MS as CONFIG_RANGE
    from realtime.osc_control import OscControl
    from realtime.ws_server import WebSocketSink

    assert CONFIG_RANGE == LEAD_RANGE_MS
    conf = tmp_path / "show.toml"
    conf.write_text('audio = "x.wav"\nlead = 67\n[[performer]]\nname = "near"\n'
                    '[[performer]]\nname = "far"\nlead = 133.5\n')
    cfg = resolve_run_config(argparse.Namespace(config=str(conf)))
    near, far = cfg.performer_specs()
    assert (cfg.lead, near.lead, far.lead) == (67, 67.0, 133.5)
    assert resolve_run_config(argparse.Namespace(lead=100.0)).lead == 100.0
    assert parse_performer("zed,lead=40").lead == 40.0
    for text, needle in [("zed,lead=201", "performer 'zed': lead must be 0..200 ms"),
                         ("zed,lead=soon", "lead must be a number")]:
        with pytest.raises(ConfigError, match=needle):
            RunConfig(performer=[parse_performer(text)]).validate()
    live, other = performer_live_changes(cfg, RunConfig(**{**load_run_config(conf), "lead": 0.0}))
    assert live == {} and other == ["lead", "performer near: lead"]  # a reload: at the next start, as energy
    code = cli.main(["run", "--audio", str(clip), "--fast", "--no-ws", "--no-osc", "--lead", "-5"])
    assert code == 2 and "lead must be 0..200 ms" in one_line_error(capsys.readouterr().err)
    code = cli.main(["run", "--audio", str(clip), "--fast", "--no-ws", "--no-osc",
                     "--performer", f"bob,checkpoint={tiny_checkpoint},lead=67"])
    line = one_line_error(capsys.readouterr().err)
    assert code == 2 and "performer 'bob'" in line and "has no lead control" in line

    loaded: dict = {}
    perfs = []
    for spec in (near, far):
        p = build_pipeline(None, lead=spec.lead, loaded=loaded)
        perfs.append(Performer(spec.name, p.model, p.extractor_factory, [ListSink()], feature_key=p.feature_key))
    assert [p.model.lead_ms for p in perfs] == [67.0, 133.5] and build_pipeline(None, loaded=loaded).model.lead_ms == 0
    eng = Engine(FileSource(np.zeros(SAMPLE_RATE, np.float32), SAMPLE_RATE), config=EngineConfig(),
                 performers=perfs)

    def leads() -> tuple[float, float]:
        return perfs[0].model.lead_ms, perfs[1].model.lead_ms

    with OscControl("127.0.0.1", 0, control=eng.control) as ctl, \
            socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as out:
        ctl.start()
        for message, want in [(osc_message("/performer/far/lead", 100), (67.0, 100.0)),
                              (osc_message("/performer/lead", 0.0), (0.0, 0.0)),
                              (osc_message("/performer/lead", 250.0), (0.0, 0.0)),  # out of range: refused
                              (osc_message("/performer/near/lead", 33), (33.0, 0.0))]:
            out.sendto(message, ("127.0.0.1", ctl.port))
            deadline = time.monotonic() + 5
            while leads() != want and time.monotonic() < deadline:
                time.sleep(0.01)
            assert leads() == want
        deadline = time.monotonic() + 5
        while ctl.stats()["applied"] + ctl.stats()["bad"] < 4 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert (ctl.stats()["applied"], ctl.stats()["bad"]) == (3, 1)

    server = WebSocketSink("127.0.0.1", 0, token="s3cret", control=eng.control)
    routes = [server.route("/ws/near", "near", default=True), server.route("/ws/far", "far")]
    try:
        with connect(routes[1].ws_url + "?token=s3cret", open_timeout=5) as ws:
            assert json.loads(ws.recv(timeout=5))["control"]
            ws.send(json.dumps({"type": "control", "action": "lead", "value": 133}))
            assert json.loads(ws.recv(timeout=5))["type"] == "control_ok"
            assert leads() == (33.0, 133.0)  # the client's own performer
            ws.send(json.dumps({"type": "control", "action": "lead", "value": 200.5, "performer": "*"}))
            assert "lead must be in [0, 200] ms" in json.loads(ws.recv(timeout=5))["error"]
            ws.send(json.dumps({"type": "control", "action": "lead", "value": 67, "performer": "*"}))
            assert json.loads(ws.recv(timeout=5))["type"] == "control_ok"
        assert leads() == (67.0, 67.0)
    finally:
        for r in routes:
            r.close()


# -- the engine: input stage and lanes ------------------------------------------------------------

def test_one_extractor_per_feature_config_and_each_staggered_stream_equals_its_own_offline_pass(
        clip_audio, tiny_checkpoint):
    """Three dance_vq performers share one extractor (a causal U-Net with other features gets its
    own); their code steps are spread over the 8-frame cycle; each performer's poses equal its
    model fed its lead-in of silence frames and then the features of the same audio."""
    loaded: dict = {}
    perfs = _ensemble([("alice", 1, "waltz"), ("bob", 2, None), ("carol", 3, "rumba")], loaded)
    unet = build_pipeline(tiny_checkpoint)
    perfs.append(Performer("dave", unet.model, unet.extractor_factory, [ListSink()], feature_key=unet.feature_key))
    eng = Engine(FileSource(clip_audio, SAMPLE_RATE, realtime=False), config=EngineConfig(warmup_s=0.5),
                 performers=perfs)
    eng.start()
    assert eng.wait(60), "the engine did not finish the clip within 60 s"
    eng.close()
    assert len(loaded) == 1  # the checkpoint was loaded once for the three
    ext = eng.extractors
    assert len(ext) == 2 and ext[0] is not ext[1] and eng.stats()["extractors"] == 2
    assert eng.phases == {"alice": 0, "bob": 2, "carol": 4, "dave": 0}  # dave's U-Net: even cost, no cycle
    features = build_pipeline(None).extractor_factory(SAMPLE_RATE).push(clip_audio)
    assert all(len(p.sinks[0].frames) == len(features) == 120 for p in perfs)
    for p, (seed, style) in zip(perfs[:3], [(1, "waltz"), (2, None), (3, "rumba")]):
        ref = build_pipeline(None, seed=seed, style=style, loaded=loaded)
        lead = stagger_lead(ref.model, ref.extractor_factory, eng.phases[p.name])
        if lead is not None:
            ref.model.push(lead)
        expected = ref.model.push(features)
        got = np.stack([f.pose for f in p.sinks[0].frames])
        np.testing.assert_allclose(got, expected, atol=1e-6)  # float32 rounding: the engine renormalises
        assert [f.index for f in p.sinks[0].frames] == list(range(120))
    # every performer's frames carry the same stamps (one input stage)
    for p in perfs[1:]:
        assert [f.audio_sample for f in p.sinks[0].frames] == [f.audio_sample for f in perfs[0].sinks[0].frames]


def test_show_control_per_performer_over_osc_and_websocket():
    """/performer/X acts on every performer, /performer/NAME/X on one (real OscControl); a
    WebSocket client on /ws/NAME controls that performer unless it names another."""
    from websockets.sync.client import connect

    from realtime.osc_control import OscControl
    from realtime.ws_server import WebSocketSink

    perfs = _ensemble([("alice", 0, None), ("bob", 1, None)], {})
    eng = Engine(FileSource(np.zeros(SAMPLE_RATE, np.float32), SAMPLE_RATE), config=EngineConfig(),
                 performers=perfs)
    ctl = OscControl(port=0, control=eng.control)
    peer = ("127.0.0.1", 5000)
    try:
        ctl.handle(osc_message("/performer/bob/style", "waltz"), peer)
        assert (perfs[0].model.style, perfs[1].model.style) == (0, 3)
        ctl.handle(osc_message("/performer/style", "rumba"), peer)
        assert (perfs[0].model.style, perfs[1].model.style) == (2, 2)
        ctl.handle(osc_message("/performer/alice/offset", 40), peer)
        ctl.handle(osc_message("/performer/smoothing", 0.25), peer)
        ctl.handle(osc_message("/performer/bob/idle", 1), peer)
        per = eng.stats()["performers"]
        assert (per["alice"]["offset_ms"], per["bob"]["offset_ms"]) == (40.0, 0.0)
        assert per["alice"]["smoothing"] == per["bob"]["smoothing"] == 0.25
        assert (per["alice"]["idle"], per["bob"]["idle"], perfs[1].model.forced_idle) == (False, True, True)
        ctl.handle(osc_message("/performer/alice/energy", 0.5), peer)  # the dancing model's energy control
        assert (perfs[0].model.energy, perfs[1].model.energy) == (0.5, 1.0)
        ctl.handle(osc_message("/performer/energy", 2.5), peer)  # out of its range: refused, nothing changes
        assert (perfs[0].model.energy, perfs[1].model.energy) == (0.5, 1.0)
        ctl.handle(osc_message("/performer/nobody/idle", 1), peer)  # unknown performer: a bad message
        ctl.handle(osc_message("/performer/bob/dance", 1), peer)  # unknown control
        assert ctl.stats()["applied"] == 6 and ctl.stats()["bad"] == 3
    finally:
        ctl.close()

    server = WebSocketSink("127.0.0.1", 0, token="s3cret", control=eng.control)
    routes = [server.route("/ws/alice", "alice", default=True), server.route("/ws/bob", "bob")]
    try:
        with pytest.raises(ConfigError, match="given twice"):
            server.route("/ws/bob", "bob")
        with connect(routes[1].ws_url + "?token=s3cret", open_timeout=5) as ws:
            hello = json.loads(ws.recv(timeout=5))
            assert hello["performer"] == "bob" and hello["control"]
            ws.send(json.dumps({"type": "control", "action": "style", "value": "chacha"}))
            assert json.loads(ws.recv(timeout=5))["performer"] == "bob"
            ws.send(json.dumps({"type": "control", "action": "style", "value": "auto", "performer": "alice"}))
            assert json.loads(ws.recv(timeout=5))["type"] == "control_ok"
            ws.send(json.dumps({"type": "control", "action": "idle", "value": 1, "performer": "zed"}))
            assert "unknown performer 'zed'" in json.loads(ws.recv(timeout=5))["error"]
        assert (perfs[0].model.style, perfs[1].model.style) == (0, 1)
        with connect(server.ws_url + "?token=s3cret", open_timeout=5) as ws:  # /ws: the first performer
            assert json.loads(ws.recv(timeout=5))["performer"] == "alice"
    finally:
        for r in routes:
            r.close()  # the server closes with its last route
    assert server._closed


def test_reload_of_an_ensemble_applies_each_performers_live_settings(tmp_path, caplog):
    """SIGHUP's reload (run.reload_settings) on a two-performer engine: a performer's own
    smoothing reaches that performer only, a top-level offset every performer without its
    own, a broken file changes nothing, and a performer added waits for the next start."""
    import logging

    from realtime.commands.run import reload_settings

    conf = tmp_path / "show.toml"
    head = 'audio = "x.wav"\noffset_ms = 0\n'
    alice, bob = '[[performer]]\nname = "alice"\n', '[[performer]]\nname = "bob"\noffset_ms = 25\n'
    conf.write_text(head + alice + bob)
    args = cli.build_parser().parse_args(["run", "--config", str(conf)])
    cfg = resolve_run_config(args)
    perfs = _ensemble([("alice", 0, None), ("bob", 1, None)], {})
    for perf, spec in zip(perfs, cfg.performer_specs()):
        perf.offset_ms, perf.smoothing = spec.offset_ms, spec.smoothing
    eng = Engine(FileSource(np.zeros(SAMPLE_RATE, np.float32), SAMPLE_RATE), config=EngineConfig(), performers=perfs)

    def settings() -> dict[str, tuple[float, float]]:
        per = eng.stats()["performers"]
        return {n: (per[n]["offset_ms"], per[n]["smoothing"]) for n in ("alice", "bob")}

    assert settings() == {"alice": (0.0, 0.0), "bob": (25.0, 0.0)}
    caplog.set_level(logging.WARNING)
    conf.write_text('audio = "x.wav"\noffset_ms = 60\n' + alice + "smoothing = 0.4\n" + bob)
    cfg = reload_settings(args, eng, cfg)
    assert settings() == {"alice": (60.0, 0.4), "bob": (25.0, 0.0)}
    assert any("alice: offset_ms -> 60, smoothing -> 0.4" in r.getMessage() for r in caplog.records)
    for broken in ["offset_ms = [\n", '[[performer]]\nname = "alice"\nsmoothing = 1.5\n']:
        caplog.clear()
        conf.write_text('audio = "x.wav"\n' + broken)
        cfg = reload_settings(args, eng, cfg)
        errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
        assert len(errors) == 1 and "keeping the current settings" in errors[0] and str(conf) in errors[0]
        assert settings() == {"alice": (60.0, 0.4), "bob": (25.0, 0.0)}
    caplog.clear()
    conf.write_text('audio = "x.wav"\noffset_ms = 60\n' + alice + "smoothing = 0.4\n" + bob
                    + '[[performer]]\nname = "carol"\n')
    cfg = reload_settings(args, eng, cfg)
    assert any("performer (names) changed; applied at the next start only" in r.getMessage() for r in caplog.records)
    assert settings() == {"alice": (60.0, 0.4), "bob": (25.0, 0.0)} and eng.performers == ["alice", "bob"]
    eng.close()


# -- performer run: three performers, real receivers ----------------------------------------------

def _plain_poses(datagrams: list[bytes]) -> dict[int, np.ndarray]:
    """Frame index -> the bone quaternions (NUM_BONES, 4) of a plain-OSC stream."""
    out: dict[int, np.ndarray] = {}
    index, bones = None, []
    for address, params in osc_messages(datagrams):
        if address == "/performer/frame":
            if index is not None:
                out[index] = np.array(bones)
            index, bones = params[0], []
        elif address.startswith("/performer/bone/"):
            bones.append(params)
    if index is not None:
        out[index] = np.array(bones)
    return out


def test_run_with_three_performers_to_real_receivers_equals_single_runs(tmp_path, capsys, clip):
    """performer run: alice, bob and carol on the clip; alice and bob each reach their own UDP
    receiver (plain OSC) and WebSocket path, carol's receiver is gone (every send refused) and
    slows no one; alice's and bob's recordings equal single-performer runs with the same settings."""
    from websockets.sync.client import connect

    from realtime.wire import decode_frame

    rx = {"alice": udp_receiver(), "bob": udp_receiver()}
    gone = free_port()  # nothing listens: carol's datagrams are refused
    ws_port = free_port()
    take = tmp_path / "take.npz"
    cmd = [sys.executable, "-m", "realtime.cli", "run", "--audio", str(clip), "--duration", "3", "--warmup", "2",
           "--osc-mode", "plain", "--ws", f"127.0.0.1:{ws_port}", "--record", str(take), "--stage", "0",
           "--performer", f"alice,style=waltz,seed=1,osc=127.0.0.1:{rx['alice'].getsockname()[1]}",
           "--performer", f"bob,style=rumba,seed=2,osc=127.0.0.1:{rx['bob'].getsockname()[1]}",
           "--performer", f"carol,seed=3,osc=127.0.0.1:{gone}"]
    proc = subprocess.Popen(cmd, cwd=REPO, stderr=subprocess.PIPE, text=True, preexec_fn=default_sigint)
    got: dict[str, list] = {"bob": [], "/ws": []}
    hellos: dict[str, dict] = {}

    def client(path: str, key: str) -> None:
        deadline = time.monotonic() + 60
        while True:
            try:
                conn = connect(f"ws://127.0.0.1:{ws_port}{path}", open_timeout=5)
                break
            except OSError:
                if time.monotonic() > deadline or proc.poll() is not None:
                    return
                time.sleep(0.1)
        with conn:
            hellos[key] = json.loads(conn.recv(timeout=30))
            try:
                while True:
                    msg = conn.recv(timeout=10)
                    if isinstance(msg, bytes):
                        got[key].append(decode_frame(msg))
            except Exception:  # noqa: BLE001 - the server closed: the run ended
                pass

    threads = [threading.Thread(target=client, args=a, daemon=True) for a in (("/ws/bob", "bob"), ("/ws", "/ws"))]
    for t in threads:
        t.start()
    try:
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    for t in threads:
        t.join(15)
    assert proc.returncode == 0, err
    assert "3 performers, 1 feature extractor" in err
    assert "alice [default.pt, style waltz, seed 1, phase 0]" in err
    assert "bob [default.pt, style rumba, seed 2, phase 2]" in err and "carol [default.pt, style auto, seed 3, phase 5]" in err
    assert any(line.startswith("finished") and "90 frames" in line and "3 performers" in line
               for line in err.splitlines())  # the final status line
    recs = {}
    for name in ("alice", "bob", "carol"):
        with np.load(tmp_path / f"take-{name}.npz") as z:
            recs[name] = z["pose"]
            assert len(z["pose"]) == 90 and list(z["index"]) == list(range(90))
    assert not np.array_equal(recs["alice"], recs["bob"]) and not np.array_equal(recs["bob"], recs["carol"])
    # each UDP receiver got every frame of its own performer, carol's refused datagrams slowed no one
    for name in ("alice", "bob"):
        poses = _plain_poses(drain(rx[name]))
        assert sorted(poses) == list(range(90))
        np.testing.assert_allclose(np.stack([poses[i] for i in range(90)]),
                                   recs[name][:, 3:].reshape(90, -1, 4), atol=1e-6)
    # WebSocket: /ws/bob is bob's stream, /ws the first performer's (alice)
    assert hellos["bob"]["performer"] == "bob" and hellos["/ws"]["performer"] == "alice"
    for key, name in (("bob", "bob"), ("/ws", "alice")):
        idx = [f.index for f in got[key]]
        assert len(idx) >= 60 and idx == sorted(idx)  # a slow client may lose its oldest frames, never order
        for f in got[key]:
            np.testing.assert_allclose(f.pose, recs[name][f.index], atol=1e-6)
    # one performer of the ensemble = a single-performer run with the same settings (alice: phase 0,
    # the default single run; bob: staggered, the same phase given). The single runs replay --fast,
    # so the model gets several frames per push where the paced run gave one: the same dance, the
    # renormalisation rounded once per push (< 1e-7). The ensemble dances in place (--stage 0: on a
    # stage each performer has its own spot, tests/test_stage_spots.py), so the single runs do too
    single = tmp_path / "single.npz"
    assert cli.main(["run", "--audio", str(clip), "--fast", "--duration", "3", "--warmup", "2", "--no-ws", "--no-osc",
                     "--quiet", "--style", "waltz", "--seed", "1", "--stage", "0", "--record", str(single)]) == 0
    with np.load(single) as z:
        np.testing.assert_allclose(z["pose"], recs["alice"], atol=1e-6)
    assert cli.main(["run", "--audio", str(clip), "--fast", "--duration", "3", "--warmup", "2", "--no-ws", "--no-osc",
                     "--quiet", "--performer", "bob,style=rumba,seed=2,phase=2", "--stage", "0",
                     "--record", str(single)]) == 0
    with np.load(tmp_path / "single-bob.npz") as z:
        np.testing.assert_allclose(z["pose"], recs["bob"], atol=1e-6)
    capsys.readouterr()
