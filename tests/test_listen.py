"""The reference receivers (realtime/receiver.py) and ``performer listen``, on real loopback sockets."""

from __future__ import annotations

import contextlib
import json
import shutil
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_run_cli import clip, free_port, tiny_checkpoint  # noqa: F401 - fixtures
from test_vmc import tpose_offsets

from models.rig.humanoid import BONES, NUM_BONES
from models.rig.npz import load_npz_extra
from realtime import cli
from realtime.frame import PoseFrame
from realtime.osc_out import OscSink
from realtime.receiver import OscReceiver, StreamCheck, WsReceiver
from realtime.vmc import osc_message
from realtime.ws_server import WebSocketSink

REPO = Path(__file__).resolve().parents[1]
BASE = Rotation.random(NUM_BONES, random_state=7)


def smooth_pose(i: int) -> np.ndarray:
    """(POSE_DIM,) float32: fixed random rotations turned 2 degrees more about Y per frame, a drifting root."""
    q = (BASE * Rotation.from_euler("y", 2 * i, degrees=True)).as_quat()
    return np.concatenate([[0.01 * i, 0.95, -0.02 * i], q.ravel()]).astype(np.float32)


def frame(i: int, pose: np.ndarray | None = None) -> PoseFrame:
    return PoseFrame(i, (i + 1) * 735 - 1, (i + 1) / 30, time.monotonic(), smooth_pose(i) if pose is None else pose)


def collect(receiver, n: int, timeout: float = 10.0) -> list:
    frames, deadline = [], time.monotonic() + timeout
    while len(frames) < n and time.monotonic() < deadline:
        frames += receiver.poll(0.2)
    return frames


def check_frames(frames, indices) -> StreamCheck:
    """Frames decode back to the sent poses (float32-exact), in the project frame."""
    assert [f.index for f in frames] == list(indices)
    for f in frames:
        assert f.names == BONES and not f.missing
        np.testing.assert_allclose(f.pose, smooth_pose(f.index), atol=1e-6)
        assert f.audio_time == pytest.approx((f.index + 1) / 30, abs=1e-6)
    check = StreamCheck()
    for f in frames:
        assert check.add(f) == []
    return check


# -- receivers against the real sinks ------------------------------------------------------------


@pytest.mark.parametrize("mode", ["vmc", "plain"])
def test_osc_receiver_decodes_what_the_sink_sends(mode):
    with OscReceiver(0, mode) as rx, OscSink("127.0.0.1", rx.port, mode, offsets=tpose_offsets()) as tx:
        for i in range(5):
            tx.send(frame(i))
        frames = collect(rx, 5)
    check = check_frames(frames, range(5))
    assert check.summary()["format_errors"] == 0 and rx.problems.count == 0
    assert rx.datagrams == 5 * (2 if mode == "vmc" else 1)


@pytest.mark.parametrize("fmt", ["binary", "json"])
def test_ws_receiver_decodes_what_the_sink_sends(fmt):
    with WebSocketSink(port=0, offsets=tpose_offsets()) as sink:
        with WsReceiver(sink.ws_url, fmt) as rx:
            assert rx.hello["bones"] == list(BONES) and rx.hello["format"] == fmt
            deadline = time.monotonic() + 5
            while sink.stats()["clients"] < 1 and time.monotonic() < deadline:
                time.sleep(0.01)
            for i in range(5):
                sink.send(frame(i))
            frames = collect(rx, 5)
    check_frames(frames, range(5))
    for f in frames:  # delay measured against the server's send time, same machine
        assert 0 <= f.delay < 5


def test_vmc_receiver_reports_lost_datagrams_and_garbage_without_crashing():
    with OscReceiver(0, "vmc") as rx, OscSink("127.0.0.1", rx.port, "vmc", offsets=tpose_offsets()) as tx:
        udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        tx.send(frame(0))
        udp.sendto(b"\x00garbage that is not OSC", ("127.0.0.1", rx.port))
        udp.sendto(osc_message("/VMC/Ext/Bone/Pos", "Hips", 1.0), ("127.0.0.1", rx.port))  # too few values
        datagrams = tx._encode(frame(1))  # the two bundles of frame 1; only the second arrives
        udp.sendto(datagrams[1], ("127.0.0.1", rx.port))
        tx.send(frame(3))  # frame 2 never sent
        frames = collect(rx, 3)
        udp.close()
    assert [f.index for f in frames] == [0, 1, 3]
    assert "Hips" in frames[1].missing and "RightToes" not in frames[1].missing
    assert rx.problems.count == 2
    assert "malformed OSC datagram" in rx.problems.items[0] and "needs a name and 7 floats" in rx.problems.items[1]
    check = StreamCheck()
    problems = [check.add(f) for f in frames]
    assert problems[0] == [] and "missing bones Hips" in problems[1][0] and "1 frames lost" in problems[2][0]
    s = check.summary()
    assert s["format_errors"] == 1 and s["lost"] == 1 and s["gaps"] == 1


def test_stream_check_finds_format_and_continuity_problems():
    from realtime.receiver import ReceivedFrame

    def rec(i, pose, arrival):
        return ReceivedFrame(i, (i + 1) / 30, pose[:3].astype(float), pose[3:].reshape(-1, 4).astype(float), BONES,
                             arrival, 1000.0 + arrival, send_time=1000.0 + arrival - 0.004)

    check = StreamCheck(jump_deg=30)
    assert check.add(rec(0, smooth_pose(0), 0.0)) == []
    jumped = smooth_pose(1)
    jumped[3 + 4 * 6 : 7 + 4 * 6] = Rotation.from_euler("x", 90, degrees=True).as_quat()  # LeftUpperArm
    assert "LeftUpperArm turned" in check.add(rec(1, jumped, 0.040))[0]
    not_unit = smooth_pose(2)
    not_unit[3:7] *= 1.1
    assert "non-unit quaternions (worst Hips" in check.add(rec(2, not_unit, 0.060))[0]
    assert "not after frame 2" in check.add(rec(2, smooth_pose(2), 0.100))[0]  # repeated index
    s = check.summary()
    assert (s["frames"], s["format_errors"], s["jumps"], s["lost"]) == (4, 2, 2, 0)  # the arm jumps out and back
    np.testing.assert_allclose(s["interval_ms"]["max"], 40.0, atol=1e-6)
    np.testing.assert_allclose(s["delay_ms"]["p50"], 4.0, atol=1e-6)
    assert s["max_jump_bone"] == "LeftUpperArm" and s["jitter_ms_p99"] > 6


# -- the performer listen command -----------------------------------------------------------------


class Sender:
    """Calls ``send(i)`` for i = 0, 1, ... every ``period`` seconds from a thread until stopped."""

    def __init__(self, send: Callable[[int], None], period: float = 1 / 30) -> None:
        self.send, self.period = send, period
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        i = 0
        while not self._stop.wait(self.period):
            self.send(i)
            i += 1

    def __enter__(self) -> "Sender":
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()


def listen(capsys, *args) -> tuple[int, str, str]:
    code = cli.main(["listen", *map(str, args)])
    out, err = capsys.readouterr()
    return code, out, err


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_listen_plain_osc_records_what_arrived(tmp_path, capsys):
    port = free_udp_port()
    with OscSink("127.0.0.1", port, "plain") as tx, Sender(lambda i: tx.send(frame(i))):
        code, out, err = listen(capsys, "--osc", port, "--mode", "plain", "--count", 20, "--print", "frames",
                                "--record", tmp_path / "take.npz", "--json", tmp_path / "report.json")
    assert code == 0, out + err
    assert "received 20 frames" in out and "format errors 0" in out and f"wrote {tmp_path / 'take.bvh'}" in err
    lines = [ln for ln in out.splitlines() if ln.startswith("#")]
    assert len(lines) == 20 and "fastest bone" in lines[1]
    extra = load_npz_extra(tmp_path / "take.npz")
    first = int(extra["index"][0])
    np.testing.assert_array_equal(extra["index"], np.arange(first, first + 20))
    np.testing.assert_allclose(extra["pose"], np.stack([smooth_pose(i) for i in extra["index"]]), atol=1e-6)
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["frames"] == 20 and report["lost"] == 0 and report["interval_ms"]["p50"] > 0


def test_listen_ws_json_reports_delay(capsys):
    with WebSocketSink(port=0, offsets=tpose_offsets()) as sink, Sender(lambda i: sink.send(frame(i))):
        code, out, err = listen(capsys, "--ws", sink.ws_url, "--format", "json", "--count", 15, "--print", "none")
    assert code == 0, out + err
    assert "received 15 frames" in out and "delay ms (arrival - send, same clock)" in out


def test_listen_vmc_malformed_datagram_is_reported_and_fails_the_check(capsys):
    port = free_udp_port()
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def send(i: int) -> None:
        tx.send(frame(i))
        if i == 3:
            udp.sendto(b"#bundle\x00broken", ("127.0.0.1", port))

    with OscSink("127.0.0.1", port, "vmc", offsets=tpose_offsets()) as tx, Sender(send):
        code, out, err = listen(capsys, "--osc", port, "--count", 10, "--print", "none")
    udp.close()
    assert code == 1, out + err
    assert "received 10 frames" in out and "malformed 1" in out and "malformed OSC datagram" in out
    assert "Traceback" not in err


def test_listen_without_a_sender_exits_2_with_one_line(capsys):
    code, out, err = listen(capsys, "--osc", free_udp_port(), "--timeout", "0.3", "--print", "none")
    assert code == 2 and err.strip().splitlines()[-1].startswith("performer listen: error: no frame received")
    code, out, err = listen(capsys, "--ws", f"ws://127.0.0.1:{free_port()}/ws")
    assert code == 2 and "cannot receive the pose stream" in err and "Traceback" not in err
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        code, out, err = listen(capsys, "--osc", taken.getsockname()[1])
    assert code == 2 and "cannot listen for OSC" in err


# -- against the live engine ---------------------------------------------------------------------


@pytest.mark.slow
def test_receivers_get_exactly_what_the_engine_recorded(tmp_path, clip, tiny_checkpoint):  # noqa: F811
    """VMC (converted back from Unity's frame) and WebSocket frames equal the engine's own recording."""
    ws_port = free_port()
    osc = OscReceiver(0, "vmc")
    run = subprocess.Popen(
        [sys.executable, "-m", "realtime.cli", "run", "--audio", str(clip), "--duration", "3", "--warmup", "0.3",
         "--checkpoint", str(tiny_checkpoint), "--osc", f"127.0.0.1:{osc.port}", "--ws", f"127.0.0.1:{ws_port}",
         "--record", str(tmp_path / "engine.npz"), "--quiet"],
        cwd=REPO, stderr=subprocess.PIPE, text=True,
    )
    got: dict[str, list] = {"vmc": [], "ws": []}

    def receive_ws() -> None:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            try:
                rx = WsReceiver(f"ws://127.0.0.1:{ws_port}/ws", open_timeout=1)
                break
            except Exception:  # noqa: BLE001 - the server is not up yet
                time.sleep(0.1)
        else:
            return
        with rx:
            for f in rx:
                got["ws"].append(f)

    ws_thread = threading.Thread(target=receive_ws, daemon=True)
    ws_thread.start()
    while run.poll() is None:
        got["vmc"] += osc.poll(0.2)
    got["vmc"] += osc.poll(0.2)
    osc.close()
    ws_thread.join(timeout=10)
    assert run.returncode == 0, run.stderr.read()
    rec = load_npz_extra(tmp_path / "engine.npz")
    by_index = {int(i): p for i, p in zip(rec["index"], rec["pose"])}
    assert len(got["vmc"]) == len(by_index) == 90  # loopback UDP: nothing lost
    assert len(got["ws"]) > 30
    for kind, frames in got.items():
        check = StreamCheck()
        for f in frames:
            np.testing.assert_allclose(f.pose, by_index[f.index], atol=1e-6, err_msg=f"{kind} frame {f.index}")
            check.add(f)
        assert check.summary()["format_errors"] == 0, check.problems


# -- the standalone example receiver (clients/python) ---------------------------------------------

STANDALONE = REPO / "clients" / "python" / "performer_receiver.py"


@pytest.mark.parametrize("args", [["osc", "--mode", "vmc"], ["osc", "--mode", "plain"], ["ws"], ["ws", "--format", "json"]])
def test_standalone_receiver_prints_the_sent_frames(args):
    ws = args[0] == "ws"
    port = free_udp_port()
    with contextlib.ExitStack() as stack:
        if ws:
            sink = stack.enter_context(WebSocketSink(port=0, offsets=tpose_offsets()))
            args = [*args, "--url", sink.ws_url]
        else:
            sink = stack.enter_context(OscSink("127.0.0.1", port, args[2], offsets=tpose_offsets()))
            args = [*args, "--port", str(port)]
        stack.enter_context(Sender(lambda i: sink.send(frame(i))))
        res = subprocess.run([sys.executable, str(STANDALONE), *args, "--count", "3"], capture_output=True, text=True,
                             timeout=60)
    assert res.returncode == 0, res.stderr
    lines = [ln for ln in res.stdout.splitlines() if ln.startswith("#")]
    assert len(lines) == 3
    for line in lines:
        index = int(line[1:].split()[0])
        pose = smooth_pose(index)
        quat = [float(v) for v in line.split("LeftUpperArm (")[1].split(")")[0].split(",")]
        np.testing.assert_allclose(quat, pose[3 + 4 * 6 : 7 + 4 * 6], atol=1e-3)
        root = [float(v) for v in line.split("root (")[1].split(")")[0].split(",")]
        np.testing.assert_allclose(root, pose[:3], atol=1e-3)
        assert ("delay" in line) == ws


# -- the Unity receiver's OSC parser (clients/unity), when a C# compiler is installed -------------


@pytest.mark.skipif(not (shutil.which("mcs") and shutil.which("mono")),
                    reason="mcs/mono not installed (C# check of clients/unity/OscParser.cs; apt-get install mono-mcs)")
def test_unity_osc_parser_reads_the_vmc_encoder(tmp_path):
    from pythonosc.osc_packet import OscPacket

    from realtime.vmc import VmcEncoder

    unity = REPO / "clients" / "unity"
    exe = tmp_path / "check.exe"
    subprocess.run(["mcs", f"-out:{exe}", str(unity / "OscParser.cs"), str(unity / "VmcFrame.cs"),
                    str(unity / "Tests" / "OscParserCheck.cs")], check=True, capture_output=True, timeout=120)
    files = []
    pose = smooth_pose(3)
    pose[[0, 2]] = [1.25, -0.75]  # standing away from the centre of a stage (issue 39)
    for k, dgram in enumerate(VmcEncoder(tpose_offsets()).encode(pose, 0.125) + [b"#bundle\x00\x00"]):
        files.append(tmp_path / f"d{k}.bin")
        files[-1].write_bytes(dgram)
    res = subprocess.run(["mono", str(exe), *map(str, files)], capture_output=True, text=True, timeout=60, check=True)
    lines = res.stdout.splitlines()
    frame_lines = [ln for ln in lines if ln.startswith("FRAME ")]
    lines = [ln for ln in lines if not ln.startswith("FRAME ")]
    # the frame PerformerVmcReceiver applies: the avatar's root where the performer stands, facing its
    # heading (--vmc-root world), and the Hips back where the pose has them
    from realtime.vmc import split_root, to_unity_position, to_unity_quaternion

    assert len(frame_lines) == 1
    t, *nums = (float(v) for v in frame_lines[0].split()[1:])
    root, _, _ = split_root(pose.astype(np.float64))
    assert t == 0.125
    np.testing.assert_allclose(nums[:3], to_unity_position(root[:3]), atol=1e-5)
    np.testing.assert_allclose(nums[3:7], to_unity_quaternion(root[3:]), atol=1e-5)
    np.testing.assert_allclose(nums[7:], to_unity_position(pose[:3]), atol=1e-5)
    expected = [m.message for f in files[:-1] for m in OscPacket(f.read_bytes()).messages]
    assert len(lines) == len(expected) + 1 and lines[-1] == "MALFORMED d2.bin"
    for line, msg in zip(lines, expected):
        address, *args = line.split(" ")
        assert address == msg.address and len(args) == len(msg.params)
        for got, want in zip(args, msg.params):
            assert got == want if isinstance(want, str) else float(got) == pytest.approx(want, abs=1e-6)


# -- the documented Unreal conversion (docs/receivers.md, clients/unreal) ------------------------


@pytest.mark.parametrize(
    "to_ue_position, to_ue_quat",
    [  # mesh facing +Y (component space of imported skeletal meshes); mesh facing +X
        (lambda p: 100 * np.array([p[0], p[2], p[1]]), lambda q: np.array([-q[0], -q[2], -q[1], q[3]])),
        (lambda p: 100 * np.array([p[2], -p[0], p[1]]), lambda q: np.array([-q[2], q[0], -q[1], q[3]])),
    ],
)
def test_unreal_conversion_maps_rotations_consistently(to_ue_position, to_ue_quat):
    """Rotating then converting equals converting then rotating with the converted quaternion."""
    rots = Rotation.random(50, random_state=1)
    vecs = np.random.default_rng(1).normal(size=(50, 3))
    for rot, v in zip(rots, vecs):
        # Unreal's FQuat rotates vectors with the same formula as scipy (x, y, z, w storage).
        ue = Rotation.from_quat(to_ue_quat(rot.as_quat()))
        np.testing.assert_allclose(to_ue_position(rot.apply(v)), ue.apply(to_ue_position(v)), atol=1e-9)
    up, left, forward = (to_ue_position(np.eye(3)[i]) / 100 for i in (1, 0, 2))
    assert up.tolist() == [0, 0, 1]  # +Y up -> Unreal +Z up
    assert forward.tolist() in ([0, 1, 0], [1, 0, 0]) and left.tolist() in ([1, 0, 0], [0, -1, 0])
