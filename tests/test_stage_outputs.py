"""Every output carries the stage (issue 39): a performer that walked and turned arrives where it
stood and facing where it faced over VMC (each --vmc-root), WebSocket (binary and JSON), in the
recorded NPZ and BVH, and in the Python receiver; each test fails when travel is switched off
(stage 0: it checks that the performer went more than a metre and turned)."""

from __future__ import annotations

import time

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_dance_vq import music
from test_stage import walking_model

from models.data.canonical import heading
from models.networks.dance_stream import generate
from realtime.frame import PoseFrame
from realtime.osc_out import OscSink
from realtime.receiver import OscReceiver, WsReceiver
from realtime.ws_server import WebSocketSink

N = 40  # frames sent: the last 40 of a 20-s walk


@pytest.fixture(scope="module")
def walked() -> np.ndarray:
    """(N, P) float32 poses of a performer that walked 0.6 m/s and turned 17 degrees a second on a
    100x100 stage (travel on); the checks below assume it went > 1 m and turned > 10 degrees."""
    poses = generate(walking_model(speed=0.02, turn=0.01), music(600), seed=3, stage="100x100")[-N:]
    assert np.hypot(poses[:, 0], poses[:, 2]).min() > 1.0  # travel is on: without it every check fails
    assert np.abs(np.unwrap(heading(Rotation.from_quat(poses[:, 3:7].astype(np.float64))))).min() > 0.17
    return poses


def frames(poses: np.ndarray) -> list[PoseFrame]:
    return [PoseFrame(index=i, audio_sample=0, audio_time=(i + 1) / 30, wall_time=0.0, pose=p)
            for i, p in enumerate(poses)]


def same_place_and_heading(got: np.ndarray, want: np.ndarray, atol: float = 1e-5) -> None:
    """Root positions equal; Hips rotations equal up to the quaternion's sign."""
    np.testing.assert_allclose(got[:, :3], want[:, :3], atol=atol)
    dots = np.abs(np.sum(got[:, 3:7] * want[:, 3:7], axis=1))
    np.testing.assert_allclose(dots, 1.0, atol=atol)


def collect(rx, n: int) -> list:
    out: list = []
    deadline = time.monotonic() + 10
    while len(out) < n and time.monotonic() < deadline:
        out += rx.poll(0.2)
    assert len(out) == n, f"received {len(out)} of {n} frames"
    return out


@pytest.mark.parametrize("vmc_root", ["world", "hips", "in-place"])
def test_the_vmc_receiver_gets_the_place_and_heading_back_unless_in_place(walked, vmc_root):
    with OscReceiver(0, "vmc") as rx, OscSink("127.0.0.1", rx.port, "vmc", vmc_root=vmc_root) as tx:
        for f in frames(walked):
            tx.send(f)
        got = np.stack([f.pose for f in collect(rx, N)])
    if vmc_root != "in-place":
        same_place_and_heading(got, walked)
        return
    np.testing.assert_allclose(got[:, [0, 2]], 0.0, atol=1e-6)  # in place: no travel
    np.testing.assert_allclose(got[:, 1], walked[:, 1], atol=1e-5)  # the hips' height kept
    np.testing.assert_allclose(heading(Rotation.from_quat(got[:, 3:7])), 0.0, atol=1e-4)  # no heading


@pytest.mark.parametrize("fmt", ["binary", "json"])
def test_websocket_frames_carry_the_place_and_heading(walked, fmt):
    with WebSocketSink(port=0) as sink, WsReceiver(sink.ws_url, fmt) as rx:
        deadline = time.monotonic() + 5
        while sink.stats()["clients"] < 1 and time.monotonic() < deadline:
            time.sleep(0.01)
        for f in frames(walked):
            sink.send(f)
            time.sleep(0.003)  # the server drops a slow client's oldest frames: give it time
        got = collect(rx, N)
    index = [f.index for f in got]
    same_place_and_heading(np.stack([f.pose for f in got]), walked[index], atol=1e-5)


def test_the_recording_keeps_the_place_and_heading_in_npz_and_bvh(walked, tmp_path):
    from models.rig.bvh import read_bvh
    from models.rig.npz import load_npz_extra
    from realtime.recorder import Recorder

    rec = Recorder(tmp_path / "take.npz")
    for f in frames(walked):
        rec.send(f)
    rec.close()
    same_place_and_heading(load_npz_extra(tmp_path / "take.npz")["pose"], walked)
    bvh = read_bvh(tmp_path / "take.bvh")
    assert bvh.names[0] == "Hips" and bvh.channels[0][:3] == ("Xposition", "Yposition", "Zposition")
    root = bvh.frames[:, :3] / 100.0  # centimetres
    order = "".join(c[0] for c in bvh.channels[0][3:6])  # e.g. "ZXY"
    angles = bvh.frames[:, 3:6]
    hips = Rotation.from_euler(order.upper(), angles, degrees=True).as_quat()
    # the file's root is the Hips' joint position; its offset is the rest height, frames the full position
    np.testing.assert_allclose(root[:, [0, 2]], walked[:, [0, 2]], atol=1e-4)
    np.testing.assert_allclose(np.abs(np.sum(hips * walked[:, 3:7], axis=1)), 1.0, atol=1e-4)
