"""Who may steer the engine: bind address, token, control channel, origins and limits (docs/security.md)."""

from __future__ import annotations

import inspect
import json
import logging
import threading
import time

import numpy as np
import pytest
from test_engine import ListSink, TinyConvModel, extractor, noise
from test_run_cli import free_port, ns
from test_vmc import tpose_offsets
from test_ws_server import _close_code, _frame, _hello
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from models.errors import ConfigError
from models.timebase import HOP, SAMPLE_RATE
from realtime.audio_input import FileSource
from realtime.config import DEFAULT_WS, TOKEN_ENV, RunConfig, resolve_run_config
from realtime.engine import Engine
from realtime.engine_config import EngineConfig
from realtime.pose_filters import idle_pose
from realtime.ws_server import WebSocketSink, is_loopback

TOKEN = "s3cret-token"


def make_sink(**kw) -> WebSocketSink:
    kw.setdefault("offsets", tpose_offsets())
    return WebSocketSink(kw.pop("host", "127.0.0.1"), 0, **kw)


def ask(ws, message: dict) -> dict:
    """Send one JSON message; return the next JSON (non-frame) reply."""
    ws.send(json.dumps(message))
    while True:
        msg = ws.recv(timeout=5)
        if isinstance(msg, str):
            return json.loads(msg)


# -- where it listens ----------------------------------------------------------------------------


def test_listens_on_loopback_unless_told_otherwise():
    assert DEFAULT_WS == "127.0.0.1:8765" and RunConfig().ws_endpoint() == ("127.0.0.1", 8765)
    assert inspect.signature(WebSocketSink).parameters["host"].default == "127.0.0.1"
    assert all(map(is_loopback, ["127.0.0.1", "127.8.0.1", "localhost", "::1", "[::1]"]))
    assert not any(map(is_loopback, ["0.0.0.0", "::", "", "192.168.1.20", "stage-pc"]))


@pytest.mark.parametrize("host, token, warns", [("0.0.0.0", None, True), ("0.0.0.0", TOKEN, False),
                                                ("127.0.0.1", None, False)])
def test_public_bind_without_token_is_warned_about(caplog, host, token, warns):
    caplog.set_level(logging.WARNING, logger="realtime.ws_server")
    with make_sink(host=host, token=token):
        pass
    said = [r.getMessage() for r in caplog.records if "without a token" in r.getMessage()]
    assert len(said) == int(warns)


# -- the control channel ---------------------------------------------------------------------------


@pytest.fixture
def live():
    """A running engine (3 s of noise in real time) streaming to a token-protected server with control."""
    frames = ListSink()
    eng = Engine(FileSource(noise(3.0), SAMPLE_RATE, realtime=True, block_size=735), extractor, TinyConvModel(),
                 [frames], EngineConfig(warmup_s=0))
    sink = make_sink(token=TOKEN, control=eng.control)
    eng.sinks.append(sink)
    eng.start()
    yield eng, sink, frames
    eng.close()


def wait_until(cond, timeout: float = 5.0) -> None:
    deadline = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < deadline, "condition not reached"
        time.sleep(0.01)


def test_token_holder_controls_the_engine_on_its_worker(live):
    eng, sink, frames = live
    with connect(sink.ws_url + f"?token={TOKEN}") as ws:
        assert _hello(ws)["control"] is True
        assert ask(ws, {"type": "control", "action": "set_offset", "value": -200}) == {
            "type": "control_ok", "action": "set_offset", "value": -200}
        n = len(frames.frames)
        wait_until(lambda: len(frames.frames) > n + 3)
        f = frames.frames[-1]
        assert f.audio_time == pytest.approx((f.index + 1) * HOP / SAMPLE_RATE - 0.2)
        assert ask(ws, {"type": "control", "action": "set_smoothing", "value": 0.5})["type"] == "control_ok"
        wait_until(lambda: eng.smoother.alpha == 0.5)
        for bad, why in [(float("nan"), "finite number"), ("80", "finite number"), (1e9, "-10000..10000"),
                         (None, "finite number"), ([[[1]]], "finite number")]:
            reply = ask(ws, {"type": "control", "action": "set_offset", "value": bad})
            assert reply["type"] == "error" and why in reply["error"], reply
        assert ask(ws, {"type": "control", "action": "set_smoothing", "value": 1.0})["type"] == "error"
        assert eng.config.offset_ms == -200 and eng.smoother.alpha == 0.5  # bad values changed nothing
        n = len(frames.frames)
        assert ask(ws, {"type": "control", "action": "reset"})["type"] == "control_ok"
        wait_until(lambda: any(f.index == 0 for f in frames.frames[n:]))
        reply = ask(ws, {"type": "control", "action": "shutdown"})
        assert reply["type"] == "error" and "unknown control action 'shutdown'" in reply["error"]
    assert sink.stats()["controls"] == 3


def test_idle_and_style_over_websocket_take_the_engine_path(live):
    eng, sink, frames = live
    with connect(sink.ws_url + f"?token={TOKEN}") as ws:
        _hello(ws)
        assert ask(ws, {"type": "control", "action": "idle", "value": 1}) == {
            "type": "control_ok", "action": "idle", "value": 1}
        assert eng.idle is True
        wait_until(lambda: frames.frames and np.array_equal(frames.frames[-1].pose, idle_pose()), timeout=10)
        for action, value, why in [("style", "calm", "this model offers no style control"),
                                   ("energy", 1.0, "this model offers no energy control"),
                                   ("idle", 2, "idle must be 0 or 1")]:
            reply = ask(ws, {"type": "control", "action": action, "value": value})
            assert reply == {"type": "error", "error": f"control {action}: {why}, got 2"
                             if action == "idle" else f"control {action}: {why}"}, reply
        assert eng.idle is True  # the bad idle value changed nothing
        assert ask(ws, {"type": "control", "action": "idle", "value": False})["type"] == "control_ok"
        assert eng.idle is False
    assert sink.stats()["controls"] == 2


def test_without_the_token_nobody_connects_or_steers(live):
    _, sink, _ = live
    for url in [sink.ws_url, sink.ws_url + "?token=wrong", sink.ws_url + f"?token={TOKEN[:-1]}",
                sink.ws_url + f"?token={TOKEN}x", sink.ws_url + f"?token={TOKEN.upper()}"]:
        with connect(url) as ws:
            if "?" not in url:
                ws.send(json.dumps({"type": "control", "action": "reset"}))  # not an auth message
            assert _close_code(ws) == (1008, "invalid or missing token")


def test_open_viewers_watch_but_only_token_holders_steer(live):
    eng, _, _ = live
    sink = make_sink(token=TOKEN, viewers_open=True, control=eng.control)
    eng.sinks.append(sink)
    try:
        with connect(sink.ws_url) as viewer:
            assert _hello(viewer)["control"] is False
            reply = ask(viewer, {"type": "control", "action": "set_offset", "value": 500})
            assert reply["type"] == "error" and "needs the server token" in reply["error"]
            assert eng.config.offset_ms == 0
            assert isinstance(viewer.recv(timeout=5), bytes)  # still streaming
        with connect(sink.ws_url) as guesser:
            _hello(guesser)
            guesser.send(json.dumps({"type": "auth", "token": "guess"}))
            assert _close_code(guesser) == (1008, "invalid or missing token")
        with connect(sink.ws_url) as operator:
            _hello(operator)
            assert ask(operator, {"type": "auth", "token": TOKEN}) == {"type": "auth_ok", "control": True}
            assert ask(operator, {"type": "control", "action": "set_offset", "value": 40})["type"] == "control_ok"
            wait_until(lambda: eng.config.offset_ms == 40)
    finally:
        sink.close()


def test_no_token_means_no_control():
    calls = []
    with make_sink(control=lambda action, value: calls.append(action)) as sink, connect(sink.ws_url) as ws:
        assert _hello(ws)["control"] is False
        reply = ask(ws, {"type": "control", "action": "reset"})
        assert reply["type"] == "error" and "not enabled" in reply["error"]
        assert ask(ws, {"type": "auth", "token": "anything"})["error"].startswith("this server has no token")
    assert calls == []


def test_a_non_ascii_token_works_and_is_compared_as_utf8():
    with make_sink(token="clé-🔑") as sink:
        with connect(sink.ws_url) as ws:
            ws.send(json.dumps({"type": "auth", "token": "clé-🔑"}))
            _hello(ws)
        with connect(sink.ws_url) as ws:
            ws.send(json.dumps({"type": "auth", "token": "cle-🔑"}))
            assert _close_code(ws)[0] == 1008
    with pytest.raises(ConfigError):
        WebSocketSink("127.0.0.1", 0, token="", offsets=tpose_offsets())


# -- limits -----------------------------------------------------------------------------------------


def test_a_flooding_client_is_closed_and_others_keep_streaming():
    with make_sink(max_messages_per_s=20) as sink, connect(sink.ws_url) as calm, connect(sink.ws_url) as flood:
        _hello(calm), _hello(flood)
        stop = threading.Event()

        def frames() -> None:
            i = 0
            while not stop.is_set():
                sink.send(_frame(i, seed=0))
                i += 1
                time.sleep(1 / 30)

        t = threading.Thread(target=frames, daemon=True)
        t.start()
        try:
            for i in range(500):
                try:
                    flood.send(json.dumps({"type": "ping", "id": i}))
                except Exception:  # noqa: BLE001 - closed under us: the point of the test
                    break
            assert _close_code(flood) == (1008, "message rate limit exceeded (20/s)")
            for i in range(15):  # 10 messages/s: within the limit
                assert ask(calm, {"type": "ping", "id": i})["id"] == i
                time.sleep(0.1)
            assert isinstance(calm.recv(timeout=5), bytes)
        finally:
            stop.set()
            t.join()
        assert sink.stats()["rate_limited"] == 1


# -- the command line ---------------------------------------------------------------------------------


def test_token_from_environment_file_or_flag(tmp_path, monkeypatch):
    monkeypatch.delenv(TOKEN_ENV, raising=False)
    assert resolve_run_config(ns()).ws_token is None
    monkeypatch.setenv(TOKEN_ENV, "from-env")
    assert resolve_run_config(ns()).ws_token == "from-env"
    conf = tmp_path / "run.toml"
    conf.write_text('ws_token = "from-file"\nws_viewers_open = true\nws_origin = "http://stage:8765"\n')
    cfg = resolve_run_config(ns(config=conf))
    assert cfg.ws_token == "from-file" and cfg.ws_viewers_open and cfg.ws_origin == ["http://stage:8765"]
    assert resolve_run_config(ns(config=conf, ws_token="from-flag")).ws_token == "from-flag"
    monkeypatch.delenv(TOKEN_ENV)
    with pytest.raises(ConfigError, match="needs a token"):
        resolve_run_config(ns(ws_viewers_open=True))
    with pytest.raises(ConfigError, match="ws_max_clients"):
        resolve_run_config(ns(ws_max_clients=0))


def test_run_options_reach_the_server(monkeypatch):
    from realtime.commands.run import _open_sinks

    monkeypatch.delenv(TOKEN_ENV, raising=False)
    cfg = resolve_run_config(ns(no_osc=True, ws=f"127.0.0.1:{free_port()}", ws_token=TOKEN, ws_viewers_open=True,
                                ws_max_clients=1, ws_origin="http://stage:8765"))
    (sink,) = _open_sinks(cfg, SAMPLE_RATE)
    try:
        with pytest.raises(InvalidStatus) as info:
            connect(sink.ws_url, origin="http://evil.example")
        assert info.value.response.status_code == 403
        with connect(sink.ws_url, origin="http://stage:8765") as viewer:
            assert _hello(viewer)["control"] is False
            with connect(sink.ws_url) as second:
                assert _close_code(second) == (1013, "server full: 1 clients")
    finally:
        sink.close()
