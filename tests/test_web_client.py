"""The three.js web client (clients/web) in a real browser, against the real WebSocket server.

Debian's ``chromium`` is driven by playwright (the PyPI package only; no browser
download). Browser tests skip with the reason when chromium or playwright is absent;
``make test`` installs both. The JavaScript-only checks run with ``node`` when present.
"""

from __future__ import annotations

import base64
import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
import urllib.request
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_run_cli import clip, free_port, tiny_checkpoint  # noqa: F401 - fixtures
from _proc import default_sigint

from models.rig.humanoid import BONES, NUM_BONES, PARENT_INDEX
from models.rig.motion import POSE_DIM
from realtime.frame import PoseFrame
from realtime.wire import encode_frame, rest_offsets

REPO = Path(__file__).resolve().parents[1]
WEB = REPO / "clients" / "web"
CHROMIUM = Path(os.environ.get("PERFORMER_CHROMIUM", "/usr/bin/chromium"))
CHROMIUM_ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]
NODE = shutil.which("node")


# -- browser and stream fixtures -------------------------------------------------------------


@contextlib.contextmanager
def chromium_context(profile: Path, viewport: dict, needs: str = "index.html") -> Iterator:
    """A headless Debian chromium with a fresh profile at `profile`, driven by playwright.

    Skips the calling test when chromium, playwright or clients/web/dist/`needs` is missing."""
    if not CHROMIUM.is_file():
        pytest.skip(f"{CHROMIUM} not installed (apt-get install chromium; 'make test' does it)")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        pytest.skip("the playwright Python package is not installed (pip install -e '.[dev]')")
    if not (WEB / "dist" / needs).is_file():
        pytest.skip(f"clients/web/dist/{needs} is not built ('make web')")
    with sync_playwright() as pw:
        ctx = pw.chromium.launch_persistent_context(
            str(profile), executable_path=str(CHROMIUM), headless=True, args=CHROMIUM_ARGS, viewport=viewport)
        try:
            yield ctx
        finally:
            ctx.close()


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    """The viewer's browser: 800x500."""
    with chromium_context(tmp_path_factory.mktemp("chromium-profile"), {"width": 800, "height": 500}) as ctx:
        yield ctx


class Page:
    """One viewer tab; collects console errors and uncaught exceptions."""

    def __init__(self, ctx, url: str) -> None:
        self.page = ctx.new_page()
        self.errors: list[str] = []
        self.page.on("console", lambda m: m.type == "error" and self.errors.append(m.text))
        self.page.on("pageerror", lambda e: self.errors.append(f"uncaught: {e}"))
        self.page.goto(url)

    def stats(self) -> dict:
        return self.page.evaluate("window.performerStats")

    def wait_for(self, condition: Callable[[dict], bool], timeout: float = 30.0) -> dict:
        """Poll window.performerStats until ``condition`` holds (generous guard, not a timing test)."""
        deadline = time.monotonic() + timeout
        while True:
            stats = self.stats()
            if stats and condition(stats):
                return stats
            if time.monotonic() > deadline:
                raise AssertionError(f"page never reached the condition; last stats {stats}; errors {self.errors}")
            time.sleep(0.2)

    def close(self) -> None:
        self.page.close()


@pytest.fixture
def open_page(browser):
    pages: list[Page] = []

    def open_(url: str) -> Page:
        pages.append(Page(browser, url))
        return pages[-1]

    yield open_
    for p in pages:
        p.close()


def pose_with(rotations: dict[str, Rotation], root=(0.0, 0.95, 0.0)) -> np.ndarray:
    """A flat pose: identity everywhere except ``rotations`` (bone name -> scipy Rotation)."""
    pose = np.zeros(POSE_DIM, np.float32)
    pose[:3] = root
    pose[6::4] = 1.0
    for name, rot in rotations.items():
        j = BONES.index(name)
        pose[3 + 4 * j : 7 + 4 * j] = rot.as_quat()  # scipy: x, y, z, w
    return pose


class SyntheticStream:
    """The real WebSocketSink fed with chosen poses at 30 frames per second from a thread."""

    def __init__(self, pose_at: Callable[[int], np.ndarray], port: int = 0) -> None:
        from realtime.ws_server import WebSocketSink

        self.sink = WebSocketSink("127.0.0.1", port)
        self.pose_at = pose_at
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        i = 0
        while not self._stop.wait(1 / 30):
            self.sink.send(PoseFrame(i, (i + 1) * 735, (i + 1) / 30, time.monotonic(), self.pose_at(i)))
            i += 1

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        self.sink.close()


@pytest.fixture
def synthetic_stream():
    made: list[SyntheticStream] = []

    def make(pose_at: Callable[[int], np.ndarray], port: int = 0) -> SyntheticStream:
        made.append(SyntheticStream(pose_at, port))
        return made[-1]

    yield make
    for s in made:
        s.close()


@contextlib.contextmanager
def performer_run(tmp_path: Path, args: list[str], env: dict | None = None) -> Iterator[str]:
    """``performer run ARGS --ws 127.0.0.1:PORT`` in a child process until its page is served;
    yields the viewer URL, then stops it with SIGINT."""
    port = free_port()
    log = open(tmp_path / "engine.log", "w")
    proc = subprocess.Popen(
        [sys.executable, "-m", "realtime.cli", "run", *args, "--ws", f"127.0.0.1:{port}"],
        cwd=REPO, stdout=log, stderr=subprocess.STDOUT, preexec_fn=default_sigint, env=env,
    )
    url = f"http://127.0.0.1:{port}/"
    deadline = time.monotonic() + 60
    while True:
        try:
            urllib.request.urlopen(url, timeout=1).close()
            break
        except OSError:
            if proc.poll() is not None or time.monotonic() > deadline:
                proc.kill()
                pytest.fail(f"performer run did not serve {url}: {(tmp_path / 'engine.log').read_text()}")
            time.sleep(0.2)
    try:
        yield url
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
        log.close()


@pytest.fixture
def engine(tmp_path, clip, tiny_checkpoint) -> Iterator[str]:  # noqa: F811 - fixtures from test_run_cli
    """``performer run`` replaying the bundled clip in real time; yields the viewer URL."""
    with performer_run(tmp_path, ["--audio", str(clip), "--no-osc", "--checkpoint", str(tiny_checkpoint),
                                  "--warmup", "0.5", "--quiet"]) as url:
        yield url


def spot_pixels(png: bytes) -> int:
    """Pixels of a screenshot drawn in the viewer's own-spot colour (clients/web/src/stage.js SPOT_COLOR)."""
    from io import BytesIO

    from PIL import Image

    rgb = np.asarray(Image.open(BytesIO(png)).convert("RGB"), np.int16)
    return int((np.abs(rgb - np.array([0x4C, 0xC9, 0xF0])).max(axis=2) <= 24).sum())


def test_an_ensemble_viewer_draws_every_spot_and_follows_its_performer_inside_its_own(
        synthetic_stream, open_page, tmp_path):
    """An ensemble performer's viewer (the real state its SpotStage sends: 4 performers on a 3x2
    stage, this one the last, front right) draws the whole stage, its own spot brighter and the
    three others', and its camera follows the performer inside its spot. The spot is seen in the
    picture itself: its colour covers many pixels, and almost none once the state has no spot."""
    from models.networks.stage import SpotStage, ensemble_spots

    state = SpotStage(8, "3x2", "free", (3, 4)).state()
    cx, cz, w, d = state["spot"]
    stream = synthetic_stream(lambda i: pose_with({}, root=(cx + 0.3, 0.95, cz + 0.2)))
    stream.sink.set_state(state)
    page = open_page(f"http://127.0.0.1:{stream.sink.port}/")
    page.wait_for(lambda s: s["spot"] is not None and abs(s["target"][0] - (cx + 0.3)) < 0.05
                  and abs(s["target"][2] - (cz + 0.2)) < 0.05)
    drawn = page.page.evaluate("window.performer.spotOutlines()")
    corners = lambda x, z, sw, sd: [[x - sw / 2, z - sd / 2], [x + sw / 2, z - sd / 2],  # noqa: E731
                                    [x + sw / 2, z + sd / 2], [x - sw / 2, z + sd / 2]]
    assert np.allclose(drawn["spot"], corners(cx, cz, w, d), atol=1e-6)
    others = [corners(*sp) for sp in ensemble_spots("3x2", 4)[:3]]
    assert len(drawn["others"]) == 3 and np.allclose(drawn["others"], others, atol=1e-6)
    assert page.page.evaluate("window.performer.stageOutline()") == [[-1.5, -1.0], [1.5, -1.0], [1.5, 1.0], [-1.5, 1.0]]
    page.page.set_viewport_size({"width": 1280, "height": 720})  # the HUD covers less of the stage
    time.sleep(0.5)  # a picture after the last camera step
    shots = REPO / "docs" / "img" if os.environ.get("PERFORMER_DOC_IMAGES") else tmp_path
    png = page.page.screenshot(path=str(shots / "stage_ensemble_viewer.png"))
    lit = spot_pixels(png)
    stream.sink.set_state({"stage": [3.0, 2.0], "facing": "free"})  # the control: no ensemble, no spot
    page.wait_for(lambda s: s["spot"] is None)
    assert page.page.evaluate("window.performer.spotOutlines()") == {"spot": None, "others": []}
    time.sleep(0.3)
    unlit = spot_pixels(page.page.screenshot())
    assert lit > 200 and unlit < lit / 10, (lit, unlit)
    assert not page.errors, page.errors


# -- the page against the live engine --------------------------------------------------------


@pytest.mark.slow
def test_page_animates_the_live_engine_stream(engine, open_page, tmp_path):
    page = open_page(engine)
    first = page.wait_for(lambda s: s["state"] == "open" and s["framesReceived"] >= 10)
    assert first["bones"] == NUM_BONES and first["avatar"] == "procedural" and first["webgl"]
    q1 = page.page.evaluate("window.performer.boneQuaternion('LeftUpperArm')")
    second = page.wait_for(lambda s: s["framesReceived"] >= first["framesReceived"] + 45)
    q2 = page.page.evaluate("window.performer.boneQuaternion('LeftUpperArm')")

    # The page drew the stream's own rotations, and they moved.
    assert abs(np.linalg.norm(q2) - 1) < 1e-3 and not np.allclose(q1, q2, atol=1e-4)
    # Every frame of the 30 fps stream is accounted for: received + reported dropped = index
    # span = audio-time span x 30. (The server drops a slow client's oldest frames; on an
    # idle machine none are dropped.)
    got = second["framesReceived"] - first["framesReceived"]
    lost = second["dropped"] - first["dropped"]
    assert second["lastIndex"] - first["lastIndex"] == got + lost
    assert abs((second["audioTime"] - first["audioTime"]) * 30 - (got + lost)) < 0.01
    assert lost <= got and second["badFrames"] == 0
    assert second["fps"] > 3  # generous guard: the machine may be busy; about 30 when idle
    assert second["delayMs"] is not None and -50 < second["delayMs"] < 5000  # same machine
    shot = tmp_path / "web_client.png"
    page.page.screenshot(path=str(shot))
    assert shot.stat().st_size > 10_000
    assert not page.errors, page.errors


def test_reconnects_after_the_server_restarts(synthetic_stream, open_page):
    stream = synthetic_stream(lambda i: pose_with({}))
    port = stream.sink.port
    page = open_page(f"http://127.0.0.1:{port}/")
    page.wait_for(lambda s: s["state"] == "open" and s["framesReceived"] > 5)
    stream.close()
    page.wait_for(lambda s: s["state"] in ("closed", "waiting", "connecting"))
    synthetic_stream(lambda i: pose_with({}), port=port)
    stats = page.wait_for(lambda s: s["connects"] == 2 and s["state"] == "open" and s["framesReceived"] > 5)
    assert stats["lastIndex"] < 1000  # counting restarted with the new stream
    assert not [e for e in page.errors if "WebSocket" not in e], page.errors  # the refused reconnects are logged


def test_the_stage_is_drawn_and_the_camera_follows_a_travelling_performer(synthetic_stream, open_page, tmp_path):
    """The viewer draws the stage the server names (its rectangle on the floor) and its camera
    drifts after the performer's hips: a performer standing 1.2 m to the right of a 3x2 stage's
    centre ends up near the middle of the picture; with 'follow' unticked the camera stays."""
    stream = synthetic_stream(lambda i: pose_with({}, root=(1.2, 0.95, 0.6)))
    stream.sink.set_state({"stage": [3.0, 2.0], "facing": "free"})
    page = open_page(f"http://127.0.0.1:{stream.sink.port}/")
    stats = page.wait_for(lambda s: s["stage"] == [3.0, 2.0] and abs(s["target"][0] - 1.2) < 0.05
                          and abs(s["target"][2] - 0.6) < 0.05)
    assert stats["facing"] == "free"
    assert page.page.evaluate("window.performer.stageOutline()") == [[-1.5, -1.0], [1.5, -1.0], [1.5, 1.0], [-1.5, 1.0]]
    page.page.screenshot(path=str(os.environ.get("STAGE_SCREENSHOT") or tmp_path / "stage.png"))
    stream.sink.set_state({"stage": [0.0, 0.0], "facing": "free"})  # in place: no rectangle
    page.wait_for(lambda s: s["stage"] == [0.0, 0.0])
    assert page.page.evaluate("window.performer.stageOutline()") is None
    page.page.click("#follow")  # untick: the camera stays where it is
    assert page.page.evaluate("document.getElementById('follow').checked") is False
    time.sleep(0.5)
    before = page.stats()["target"]
    time.sleep(1.0)
    assert page.stats()["target"] == before
    assert not page.errors, page.errors


# -- VRM avatars -----------------------------------------------------------------------------

VRM_NAMES = {b: b[0].lower() + b[1:] for b in BONES}


def make_vrm(version: str, offsets: np.ndarray, drop: tuple[str, ...] = ()) -> bytes:
    """A minimal VRM (.glb, no mesh) whose skeleton is our rest skeleton in a T-pose.

    ``version`` "1.0": VRMC_vrm, the model faces +Z. "0.0": the VRM extension, the model
    faces -Z as VRM 0.x models do (x and z of every offset negated).
    """
    flip = np.array([-1.0, 1.0, -1.0]) if version == "0.0" else np.ones(3)
    keep = [j for j, b in enumerate(BONES) if b not in drop]
    node_of = {j: k for k, j in enumerate(keep)}

    def kept_parent(j: int) -> int:
        p = PARENT_INDEX[j]
        while p >= 0 and p not in node_of:
            j, p = p, PARENT_INDEX[p]
        return p

    nodes = []
    for j in keep:
        p, offset = kept_parent(j), np.array(offsets[j], float)
        k = j
        while PARENT_INDEX[k] != p and PARENT_INDEX[k] >= 0:  # add the offsets of dropped bones
            k = PARENT_INDEX[k]
            offset += offsets[k]
        nodes.append({"name": BONES[j], "translation": (offset * flip).tolist(),
                      "children": [node_of[c] for c in keep if kept_parent(c) == j]})
    if version == "1.0":
        ext = {"VRMC_vrm": {
            "specVersion": "1.0",
            "meta": {"name": "test", "authors": ["live-performer tests"], "licenseUrl": "https://vrm.dev/licenses/1.0/"},
            "humanoid": {"humanBones": {VRM_NAMES[BONES[j]]: {"node": node_of[j]} for j in keep}},
        }}
    else:
        ext = {"VRM": {
            "specVersion": "0.0", "exporterVersion": "live-performer tests",
            "meta": {"title": "test", "author": "live-performer tests"},
            "humanoid": {"humanBones": [{"bone": VRM_NAMES[BONES[j]], "node": node_of[j]} for j in keep]},
        }}
    gltf = {"asset": {"version": "2.0"}, "extensionsUsed": list(ext), "extensions": ext,
            "scene": 0, "scenes": [{"nodes": [0]}], "nodes": nodes}
    body = json.dumps(gltf).encode()
    body += b" " * (-len(body) % 4)
    return (b"glTF" + (2).to_bytes(4, "little") + (12 + 8 + len(body)).to_bytes(4, "little")
            + len(body).to_bytes(4, "little") + b"JSON" + body)


def load_vrm_file(page: Page, name: str, data: bytes) -> dict:
    page.page.set_input_files("#vrm-file", files=[{"name": name, "mimeType": "model/gltf-binary", "buffer": data}])
    return page.wait_for(lambda s: s["avatar"] == f"vrm:{name}", timeout=20)


# Left arm raised by +90 degrees about the facing axis (+Z), right forearm bent about +Y,
# hips turned about +Y, the body moved 10 cm to its left and 5 cm forward.
RAISED = {
    "LeftUpperArm": Rotation.from_euler("z", 90, degrees=True),
    "RightLowerArm": Rotation.from_euler("y", 60, degrees=True),
    "Hips": Rotation.from_euler("y", 20, degrees=True),
    "Spine": Rotation.from_euler("x", 15, degrees=True),
}


@pytest.mark.parametrize("version", ["1.0", "0.0"])
def test_vrm_avatar_matches_the_procedural_skeleton(version, synthetic_stream, open_page):
    offsets = rest_offsets(None)
    root = offsets[0] + [0.10, 0.0, 0.05]
    stream = synthetic_stream(lambda i: pose_with(RAISED, root=root))
    page = open_page(f"http://127.0.0.1:{stream.sink.port}/")
    page.wait_for(lambda s: s["framesReceived"] > 3)
    stats = load_vrm_file(page, f"test-{version}.vrm", make_vrm(version, offsets))
    assert stats["vrmMissingBones"] == []
    page.wait_for(lambda s: s["framesShown"] > stats["framesShown"])  # a frame drawn on the VRM
    pos = page.page.evaluate("window.performer.jointPositions()")
    for name in BONES:
        np.testing.assert_allclose(pos["vrm"][name], pos["procedural"][name], atol=1e-4, err_msg=name)
    # The raised left arm (character's left = +X) points up: hand above the shoulder.
    hand, shoulder = np.array(pos["vrm"]["LeftHand"]), np.array(pos["vrm"]["LeftUpperArm"])
    assert hand[1] - shoulder[1] > 0.4 and abs(hand[0] - shoulder[0]) < 0.15
    np.testing.assert_allclose(pos["vrm"]["Hips"], root, atol=1e-4)
    assert not page.errors, page.errors


def test_vrm_named_in_the_url_is_loaded(synthetic_stream, open_page):
    stream = synthetic_stream(lambda i: pose_with(RAISED))
    data = base64.b64encode(make_vrm("1.0", rest_offsets(None))).decode()
    page = open_page(f"http://127.0.0.1:{stream.sink.port}/?vrm=data:model/gltf-binary;base64,{data}")
    loaded = page.wait_for(lambda s: s["avatar"] == "vrm:data URL")
    page.wait_for(lambda s: s["framesShown"] > loaded["framesShown"])
    pos = page.page.evaluate("window.performer.jointPositions(['LeftHand'])")
    np.testing.assert_allclose(pos["vrm"]["LeftHand"], pos["procedural"]["LeftHand"], atol=1e-4)
    assert not page.errors, page.errors


def test_vrm_without_optional_bones_folds_their_rotation(synthetic_stream, open_page):
    offsets = rest_offsets(None)
    pose = {**RAISED, "Chest": Rotation.from_euler("z", 25, degrees=True)}
    stream = synthetic_stream(lambda i: pose_with(pose))
    page = open_page(f"http://127.0.0.1:{stream.sink.port}/")
    page.wait_for(lambda s: s["framesReceived"] > 3)
    stats = load_vrm_file(page, "no-chest.vrm", make_vrm("1.0", offsets, drop=("Chest", "LeftToes", "RightToes")))
    assert sorted(stats["vrmMissingBones"]) == ["Chest", "LeftToes", "RightToes"]
    page.wait_for(lambda s: s["framesShown"] > stats["framesShown"])
    pos = page.page.evaluate("window.performer.jointPositions()")
    # Below the missing chest every segment keeps its orientation (the chest's rotation is
    # folded into neck and shoulders); only the pivot moved from the chest down to the spine.
    seg = {k: {n: np.array(v) for n, v in pos[k].items()} for k in ("vrm", "procedural")}
    for tip, base in (("LeftHand", "LeftLowerArm"), ("RightHand", "RightLowerArm"), ("Head", "Neck")):
        np.testing.assert_allclose(seg["vrm"][tip] - seg["vrm"][base], seg["procedural"][tip] - seg["procedural"][base],
                                   atol=1e-4, err_msg=tip)
        assert np.linalg.norm(seg["vrm"][tip] - seg["procedural"][tip]) < 0.1, tip
    for name in ("LeftFoot", "RightFoot", "Spine"):
        np.testing.assert_allclose(pos["vrm"][name], pos["procedural"][name], atol=1e-4, err_msg=name)
    assert not page.errors, page.errors


def test_page_served_offline_and_stream_address_from_query(synthetic_stream, open_page):
    """dist/ references no external host; ?ws= points the page at another server."""
    for f in (WEB / "dist").rglob("*"):
        if f.suffix in (".html", ".js", ".css"):
            text = f.read_text(errors="replace")
            assert "https://unpkg" not in text and "cdn.jsdelivr" not in text and "<script src=\"http" not in text, f
    stream = synthetic_stream(lambda i: pose_with({}))
    other = synthetic_stream(lambda i: pose_with({}))
    page = open_page(f"http://127.0.0.1:{stream.sink.port}/?ws=ws://127.0.0.1:{other.sink.port}/ws&format=json")
    stats = page.wait_for(lambda s: s["framesReceived"] > 3)
    assert stats["url"] == f"ws://127.0.0.1:{other.sink.port}/ws?format=json"
    assert other.sink.stats()["clients"] == 1 and stream.sink.stats()["clients"] == 0


# -- JavaScript without a browser (node) -----------------------------------------------------

needs_node = pytest.mark.skipif(NODE is None, reason="node is not installed")


@needs_node
def test_node_unit_tests():
    res = subprocess.run([NODE, "--test", "tests/"], cwd=WEB, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "# fail 0" in res.stdout


@needs_node
def test_js_decoder_reads_the_python_encoder():
    rng = np.random.default_rng(3)
    pose = rng.normal(size=POSE_DIM).astype(np.float32)
    data = encode_frame(4_000_000_000, 12.5, 1_700_000_000.25, pose)
    script = (
        "import { decodeFrame } from './src/protocol.js';"
        f"const b = Buffer.from('{base64.b64encode(data).decode()}', 'base64');"
        "const f = decodeFrame(b.buffer.slice(b.byteOffset, b.byteOffset + b.length));"
        "console.log(JSON.stringify({...f, root: [...f.root], rotations: [...f.rotations]}));"
    )
    res = subprocess.run([NODE, "--input-type=module", "-e", script], cwd=WEB, capture_output=True, text=True,
                         timeout=60)
    assert res.returncode == 0, res.stderr
    f = json.loads(res.stdout)
    assert f["index"] == 4_000_000_000 and f["audioTime"] == 12.5 and f["sendTime"] == 1_700_000_000.25
    np.testing.assert_array_equal(np.float32(f["root"]), pose[:3])
    np.testing.assert_array_equal(np.float32(f["rotations"]), pose[3:])
