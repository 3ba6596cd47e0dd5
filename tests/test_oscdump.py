"""An independent OSC parser, liblo's ``oscdump``, reads every address and value we send."""

from __future__ import annotations

import queue
import shutil
import socket
import subprocess
import threading
import time

import numpy as np
import pytest
from test_dance_vq import music
from test_vmc import random_pose, tpose_offsets

from models.rig.humanoid import BONES, NUM_BONES
from realtime.frame import PoseFrame
from realtime.osc_out import OscSink

pytestmark = pytest.mark.skipif(
    shutil.which("oscdump") is None,
    reason="oscdump not installed (Debian package liblo-tools; `make setup` installs it when run as root)",
)


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _parse(line: str) -> tuple[str, str, list]:
    """``[timetag] /address types args...`` -> (address, types, values)."""
    tokens = line.split()
    if not tokens[0].startswith("/"):
        tokens = tokens[1:]  # bundle time tag, e.g. "eead18d5.8c1de268"
    address, types, raw = tokens[0], tokens[1], tokens[2:]
    values: list = []
    for t, r in zip(types, raw, strict=True):
        values.append(r.strip('"') if t == "s" else int(r) if t == "i" else float(r))
    return address, types, values


def _dump_one_frame(mode: str, frame: PoseFrame, last_address: str, **kw) -> list[tuple[str, str, list]]:
    """Run oscdump, send ``frame`` until it shows up, return the lines of one whole frame."""
    port = _free_udp_port()
    proc = subprocess.Popen(["oscdump", "-L", str(port)], stdout=subprocess.PIPE, text=True)
    lines: queue.Queue[str] = queue.Queue()
    threading.Thread(target=lambda: [lines.put(x) for x in proc.stdout], daemon=True).start()  # type: ignore[union-attr]
    try:
        with OscSink("127.0.0.1", port, mode, **kw) as sink:
            seen: list[str] = []
            deadline = time.monotonic() + 10
            while time.monotonic() < deadline:
                sink.send(frame)  # oscdump may not be listening yet: resend until a frame shows up
                try:
                    while True:
                        seen.append(lines.get(timeout=0.1).strip())
                except queue.Empty:
                    pass
                ends = [i for i, x in enumerate(seen) if _parse(x)[0] == last_address]
                if len(ends) >= 2:
                    return [_parse(x) for x in seen[ends[-2] + 1 : ends[-1] + 1]]
            pytest.fail(f"oscdump printed no complete frame within 10 s; got {seen[:5]}")
    finally:
        proc.terminate()
        proc.wait(timeout=5)
    return []


def test_oscdump_reads_a_vmc_frame():
    offsets = tpose_offsets()
    frame = PoseFrame(index=3, audio_sample=0, audio_time=2.5, wall_time=0.0, pose=random_pose(7))
    got = _dump_one_frame("vmc", frame, "/VMC/Ext/T", offsets=offsets, vmc_root="hips")
    assert [(a, t) for a, t, _ in got] == (
        [("/VMC/Ext/Root/Pos", "sfffffff")]
        + [("/VMC/Ext/Bone/Pos", "sfffffff")] * NUM_BONES
        + [("/VMC/Ext/OK", "iiii"), ("/VMC/Ext/T", "f")]
    )
    assert got[0][2] == ["root", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]
    root, q = frame.pose[:3], frame.pose[3:].reshape(NUM_BONES, 4)
    for j, (_, _, values) in enumerate(got[1 : 1 + NUM_BONES]):
        assert values[0] == BONES[j]
        pos = root if j == 0 else offsets[j]
        # oscdump prints 6 decimals; Unity is left-handed: x -> -x, q -> (x, -y, -z, w)
        np.testing.assert_allclose(values[1:4], [-pos[0], pos[1], pos[2]], atol=1e-6)
        np.testing.assert_allclose(values[4:], [q[j, 0], -q[j, 1], -q[j, 2], q[j, 3]], atol=1e-6)
    assert got[-2][2] == [1, 3, 0, 1]
    assert got[-1][2] == [2.5]


def test_oscdump_reads_a_plain_frame():
    frame = PoseFrame(index=12, audio_sample=0, audio_time=0.4, wall_time=0.0, pose=random_pose(8))
    got = _dump_one_frame("plain", frame, f"/performer/bone/{BONES[-1]}")
    assert [(a, t) for a, t, _ in got] == (
        [("/performer/frame", "if"), ("/performer/root", "fff")] + [(f"/performer/bone/{b}", "ffff") for b in BONES]
    )
    assert got[0][2][0] == 12 and got[0][2][1] == pytest.approx(0.4, abs=1e-6)
    np.testing.assert_allclose(got[1][2], frame.pose[:3], atol=1e-6)
    np.testing.assert_allclose([v for _, _, v in got[2:]], frame.pose[3:].reshape(NUM_BONES, 4), atol=1e-6)


@pytest.mark.parametrize("vmc_root", ["world", "in-place"])
def test_oscdump_reads_the_performers_place_and_heading_in_the_vmc_root(vmc_root):
    """A performer that walked and turned on a stage (issue 39): with ``world`` (the default)
    /VMC/Ext/Root/Pos carries where it stands (x, 0, z) and its heading, the Hips their height
    and the rest of their rotation, and root * Hips is the pose sent; ``in-place`` sends the
    same bones under an identity root. Switching travel off (stage 0) fails the distance check."""
    from scipy.spatial.transform import Rotation
    from test_stage import walking_model

    from models.data.canonical import heading
    from models.networks.dance_stream import generate
    from realtime.receiver import compose_root
    from realtime.vmc import from_unity_position, from_unity_quaternion

    poses = generate(walking_model(speed=0.02, turn=0.01), music(600), seed=3, stage="100x100")
    pose = poses[-1].astype(np.float64)
    assert np.hypot(pose[0], pose[2]) > 1.0  # it travelled
    frame = PoseFrame(index=599, audio_sample=0, audio_time=20.0, wall_time=0.0, pose=pose.astype(np.float32))
    got = _dump_one_frame("vmc", frame, "/VMC/Ext/T", vmc_root=vmc_root)
    assert got[0][0] == "/VMC/Ext/Root/Pos" and got[1][2][0] == "Hips"
    root = np.concatenate([from_unity_position(got[0][2][1:4]), from_unity_quaternion(got[0][2][4:8])])
    hips_pos, hips_rot = from_unity_position(got[1][2][1:4]), from_unity_quaternion(got[1][2][4:8])
    np.testing.assert_allclose(hips_pos, [0.0, pose[1], 0.0], atol=1e-5)  # only the height: no travel
    assert abs(heading(Rotation.from_quat([hips_rot]))[0]) < 1e-4  # and no heading
    if vmc_root == "in-place":
        assert got[0][2][1:] == [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]
        return
    np.testing.assert_allclose(root[:3], [pose[0], 0.0, pose[2]], atol=1e-5)
    h = heading(Rotation.from_quat([pose[3:7]]))[0]
    np.testing.assert_allclose(abs(np.dot(root[3:], [0.0, np.sin(h / 2), 0.0, np.cos(h / 2)])), 1.0, atol=1e-5)
    world_pos, world_rot = compose_root(root, hips_pos, hips_rot)
    np.testing.assert_allclose(world_pos, pose[:3], atol=1e-5)
    assert abs(abs(np.dot(world_rot, pose[3:7])) - 1.0) < 1e-5
