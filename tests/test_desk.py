"""The show desk (clients/web/public/desk.html, realtime/desk.py) in a real Chromium against a real
``performer run``: what it shows, how it steers, its token rules, an engine restart.

One ``performer run --audio clip.ogg --loop`` of the shipped model serves the module's tests
(``show``); a WebSocket client in this process reads its pose stream beside the page. The
screenshots go to tmp, or to docs/img with ``PERFORMER_DOC_IMAGES=1`` (docs/show.md's).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from test_run_cli import clip, free_port, tiny_checkpoint  # noqa: F401 - fixtures
from test_web_client import chromium_context
from _proc import default_sigint
from _ws_reader import JsonReader

pytestmark = pytest.mark.serial  # the desk's responses timed against 1-2 s bounds: the serial pass of make test

REPO = Path(__file__).resolve().parents[1]
TOKEN = "desk-test-token"
CLIP_BPM = 120.0  # models/assets/clip.json


def start_engine(args: list[str], port: int, log: Path, env: dict | None = None) -> subprocess.Popen:
    """``performer run ARGS --ws 127.0.0.1:PORT`` with the token TOKEN, once its HTTP port answers."""
    out = open(log, "a")
    proc = subprocess.Popen([sys.executable, "-m", "realtime.cli", "run", *args, "--ws", f"127.0.0.1:{port}"],
                            cwd=REPO, stdout=out, stderr=subprocess.STDOUT, preexec_fn=default_sigint,
                            env={**(env or os.environ), "PERFORMER_WS_TOKEN": TOKEN})
    deadline = time.monotonic() + 120
    while True:
        try:
            urllib.request.urlopen(f"http://127.0.0.1:{port}/desk.html", timeout=1).close()
            return proc
        except OSError:
            if proc.poll() is not None or time.monotonic() > deadline:
                proc.kill()
                pytest.fail(f"performer run did not serve the desk: {log.read_text()[-2000:]}")
            time.sleep(0.2)


def stop_engine(proc: subprocess.Popen) -> None:
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()


class Poses(JsonReader):
    """The pose stream (``/ws``, JSON) read on a thread: (arrival time.monotonic(), rotations (B, 4))."""

    def __init__(self, port: int) -> None:
        super().__init__(f"ws://127.0.0.1:{port}/ws?format=json", "frame",
                         lambda m: np.asarray(m["rotations"], np.float64))

    def speed(self, t0: float, t1: float) -> float:
        """Mean bone rotation speed (degrees a frame, over every bone) of the frames that arrived in [t0, t1)."""
        rots = np.stack(self.between(t0, t1))
        dots = np.abs(np.sum(rots[1:] * rots[:-1], axis=-1)).clip(0, 1)
        return float(np.degrees(2 * np.arccos(dots)).mean())


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    """The desk's browser: a laptop-sized 1280x800 window."""
    with chromium_context(tmp_path_factory.mktemp("chromium-desk"), {"width": 1280, "height": 800}, "desk.html") as ctx:
        yield ctx


@pytest.fixture(scope="module")
def show(tmp_path_factory, clip):  # noqa: F811 - fixture
    """The shipped model replaying the clip in a loop, viewers open, steering with TOKEN."""
    port = free_port()
    log = tmp_path_factory.mktemp("desk") / "engine.log"
    proc = start_engine(["--audio", str(clip), "--loop", "--no-osc", "--ws-viewers-open", "--warmup", "0.5"],
                        port, log)
    poses = Poses(port)
    yield port, poses
    poses.close()
    stop_engine(proc)


def open_desk(browser, port: int, query: str = "", width: int = 1280, height: int = 800):
    page = browser.new_page()
    page.set_viewport_size({"width": width, "height": height})
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(f"http://127.0.0.1:{port}/desk.html{query}")
    page.errors = errors
    return page


def wait_state(page, condition: str, timeout: float = 30.0) -> dict:
    """Wait until the JS expression ``condition`` over ``s`` (window.deskState) holds; the state."""
    page.wait_for_function(f"(() => {{ const s = window.deskState; return !!s && ({condition}); }})()",
                           timeout=timeout * 1000)
    return page.evaluate("window.deskState")


def performer(state: dict) -> dict:
    return state["status"]["performers"][0]


def test_desk_shows_tempo_music_and_level(browser, show, tmp_path):
    port, _ = show
    t0 = time.monotonic()
    page = open_desk(browser, port, f"?token={TOKEN}")
    state = wait_state(page, f"s.status && s.status.performers[0].music && "
                             f"Math.abs(s.status.performers[0].tempo_bpm - {CLIP_BPM}) < {0.03 * CLIP_BPM}")
    took = time.monotonic() - t0
    # 2 s asked, the page load first: a guard, not the figure (10.4 s in all while three
    # other jobs held both cores, which failed a 5-s bound here)
    assert took < 20.0, f"the desk showed the tempo {took:.1f} s after the page opened"
    p = performer(state)
    assert p["heard"] == "music" and p["idle"] is False and p["style"] == "auto"
    assert page.locator(".strip .light.music.on").count() == 1  # the light, not only the state
    assert abs(float(page.locator(".strip .bpm").inner_text()) - CLIP_BPM) < 0.03 * CLIP_BPM
    assert -40 < state["status"]["level_dbfs"] < 0 and state["control"] is True
    assert "steering" in page.locator("#mode").inner_text()
    shots = REPO / "docs" / "img" if os.environ.get("PERFORMER_DOC_IMAGES") else tmp_path
    page.screenshot(path=str(shots / "desk_laptop.png"))
    phone = open_desk(browser, port, f"?token={TOKEN}", width=390, height=844)
    wait_state(phone, "s.statuses > 3")
    phone.screenshot(path=str(shots / "desk_phone.png"), full_page=True)
    assert (shots / "desk_phone.png").stat().st_size > 10_000
    assert not page.errors and not phone.errors
    phone.close()
    page.close()


def set_slider(page, selector: str, value: float) -> None:
    page.locator(selector).evaluate(
        "(el, v) => { el.value = v; el.dispatchEvent(new Event('input')); el.dispatchEvent(new Event('change')); }",
        value)


def test_energy_slider_changes_motion_energy_within_a_second(browser, show):
    """docs/show.md, "Energy": 2 livelier than 0. Each setting's first second is read: from 0.27 s
    (the next movement) to 1.0 s after the slider moved, four times each."""
    port, poses = show
    page = open_desk(browser, port, f"?token={TOKEN}")
    wait_state(page, "s.control && s.status && s.status.performers[0].music")
    speeds: dict[float, list[float]] = {0.0: [], 2.0: []}
    for _ in range(4):
        for energy in (0.0, 2.0):
            t = time.monotonic()
            set_slider(page, ".strip .energy", energy)
            state = wait_state(page, f"s.status.performers[0].energy === {energy}", timeout=5)
            assert time.monotonic() - t < 1.0 + 1.0  # the echo of the applied value (5 Hz status; busy-machine guard)
            assert page.locator(".strip .energy-val").inner_text() == f"{energy:.2f}"
            time.sleep(max(0.0, t + 1.0 - time.monotonic()))
            speeds[energy].append(poses.speed(t + 0.27, t + 1.0))
            del state
    set_slider(page, ".strip .energy", 1.0)
    wait_state(page, "s.status.performers[0].energy === 1")
    calm, lively = np.mean(speeds[0.0]), np.mean(speeds[2.0])
    assert lively > 1.2 * calm, speeds
    page.close()


def test_idle_button_reaches_the_idle_pose_within_a_second(browser, show):
    port, poses = show
    page = open_desk(browser, port, f"?token={TOKEN}")
    wait_state(page, "s.control && s.status && s.status.performers[0].music && !s.status.performers[0].idle")
    dancing = poses.speed(time.monotonic() - 2.0, time.monotonic())
    t = time.monotonic()
    page.locator(".strip button.idle").click()
    state = wait_state(page, "s.status.performers[0].idle && s.status.performers[0].idle_weight === 1", timeout=5)
    assert time.monotonic() - t < 1.0 + 1.0  # settled (idle weight 1: 0.53 s fade) and echoed, busy-machine guard
    assert "active" in page.locator(".strip button.idle").get_attribute("class")
    time.sleep(2.0)
    held = poses.speed(t + 1.0, t + 2.0)  # the idle's slow sway from 1 s after the click
    assert held < 0.25 * dancing, (held, dancing)
    page.locator(".strip button.dance").click()
    wait_state(page, "!s.status.performers[0].idle", timeout=5)
    page.close()


def test_wrong_token_cannot_steer_and_the_page_says_so(browser, show):
    port, _ = show
    page = open_desk(browser, port, "?token=not-the-token")
    state = wait_state(page, "s.tokenRejected && s.connects >= 2 && s.conn === 'reconnected' && s.statuses > 0")
    assert state["control"] is False
    assert "wrong token" in page.locator("#message").inner_text()
    assert "watching only" in page.locator("#mode").inner_text()
    page.locator(".strip button.idle").click()  # sent anyway: the server refuses it
    wait_state(page, "s.replies.some(r => r.type === 'error' && /token/.test(r.error))", timeout=5)
    time.sleep(0.5)
    assert performer(page.evaluate("window.deskState"))["idle"] is False
    assert "token" in page.locator("#message").inner_text()
    page.close()


def test_desk_reconnects_after_an_engine_restart(browser, tmp_path, clip, tiny_checkpoint):  # noqa: F811
    port = free_port()
    args = ["--audio", str(clip), "--loop", "--no-osc", "--checkpoint", str(tiny_checkpoint), "--warmup", "0.2",
            "--quiet"]
    proc = start_engine(args, port, tmp_path / "engine.log")
    page = open_desk(browser, port, f"?token={TOKEN}")
    try:
        wait_state(page, "s.control && s.statuses > 2")
        stop_engine(proc)
        wait_state(page, "s.conn.includes('reconnecting')", timeout=10)
        assert "reconnecting" in page.locator("#conn").inner_text()
        proc = start_engine(args, port, tmp_path / "engine.log")
        before = page.evaluate("window.deskState.statuses")
        state = wait_state(page, f"s.connects === 2 && s.control && s.statuses > {before + 2}")
        assert state["conn"] == "reconnected" and "engine back" in state["message"]
        assert state["status"]["performers"][0]["frames"] < 30 * 30  # the new engine's count
    finally:
        stop_engine(proc)
        page.close()


def test_an_ensemble_has_one_strip_each_and_a_strip_steers_its_own_performer(browser, tmp_path, clip,
                                                                               tiny_checkpoint):  # noqa: F811
    port = free_port()
    proc = start_engine(["--audio", str(clip), "--loop", "--no-osc", "--checkpoint", str(tiny_checkpoint),
                         "--warmup", "0.2", "--quiet", "--performer", "alice", "--performer", "bob"],
                        port, tmp_path / "engine.log")
    page = open_desk(browser, port, f"?token={TOKEN}")
    try:
        wait_state(page, "s.control && s.status && s.status.performers.length === 2")
        assert page.locator(".strip .name").all_inner_texts() == ["alice", "bob"]
        page.locator(".strip[data-performer=bob] button.idle").click()
        state = wait_state(page, "s.status.performers[1].idle", timeout=5)
        assert state["status"]["performers"][0]["idle"] is False  # alice dances on
        assert "active" in page.locator(".strip[data-performer=bob] button.idle").get_attribute("class")
        assert not page.errors
    finally:
        page.close()
        stop_engine(proc)
