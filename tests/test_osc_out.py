"""OscSink over real loopback UDP: a python-osc receiver gets whole frames; errors never raise."""

from __future__ import annotations

import logging
import socket

import numpy as np
import pytest
from pythonosc.dispatcher import Dispatcher
from pythonosc.osc_server import BlockingOSCUDPServer
from test_vmc import random_pose, tpose_offsets

from models.errors import ConfigError, NetworkError, RigError
from models.rig.humanoid import BONES, NUM_BONES
from realtime.frame import PoseFrame
from realtime.osc_out import OscSink, PlainOscEncoder
from realtime.wire import rest_offsets


def _frame(index: int = 7, seed: int = 0) -> PoseFrame:
    return PoseFrame(index=index, audio_sample=index * 735, audio_time=index / 30, wall_time=0.0, pose=random_pose(seed))


def _receive(server: BlockingOSCUDPServer, got: list, datagrams: int) -> None:
    for _ in range(datagrams):
        n = len(got)
        server.handle_request()
        assert len(got) > n, "no OSC datagram arrived within the timeout"


@pytest.fixture
def receiver():
    got: list[tuple[str, tuple]] = []
    disp = Dispatcher()
    disp.set_default_handler(lambda address, *args: got.append((address, args)))
    server = BlockingOSCUDPServer(("127.0.0.1", 0), disp)
    server.timeout = 5
    yield server, got
    server.server_close()


def test_vmc_frame_reaches_a_python_osc_server(receiver):
    server, got = receiver
    offsets, frame = tpose_offsets(), _frame()
    with OscSink("127.0.0.1", server.server_address[1], "vmc", offsets=offsets, vmc_root="hips") as sink:
        sink.send(frame)
        _receive(server, got, 2)
        stats = sink.stats()
    assert [a for a, _ in got] == ["/VMC/Ext/Root/Pos"] + ["/VMC/Ext/Bone/Pos"] * NUM_BONES + ["/VMC/Ext/OK", "/VMC/Ext/T"]
    assert [args[0] for a, args in got[1 : 1 + NUM_BONES]] == list(BONES)
    q = frame.pose[3:].reshape(NUM_BONES, 4)
    for j, (_, args) in enumerate(got[1 : 1 + NUM_BONES]):
        np.testing.assert_allclose(args[4:], [q[j, 0], -q[j, 1], -q[j, 2], q[j, 3]], atol=1e-7)
        if j:
            np.testing.assert_allclose(args[1:4], offsets[j] * [-1, 1, 1], atol=1e-6)
    np.testing.assert_allclose(got[1][1][1:4], frame.pose[:3] * [-1, 1, 1], atol=1e-6)
    assert got[-1][1][0] == pytest.approx(frame.audio_time, abs=1e-6)
    assert stats["frames"] == 1 and stats["sent"] == 2 and stats["errors"] == 0 and stats["bytes"] > 1400


def test_plain_mode_with_a_joint_name_mapping(receiver):
    server, got = receiver
    names = {"Hips": "pelvis", "LeftHand": "l_wrist", "Head": "head"}
    frame = _frame(index=41, seed=3)
    with OscSink("127.0.0.1", server.server_address[1], "plain", names=names) as sink:
        sink.send(frame)
        _receive(server, got, 1)
    assert [a for a, _ in got] == [
        "/performer/frame", "/performer/root", "/performer/bone/pelvis", "/performer/bone/head", "/performer/bone/l_wrist"
    ]
    assert got[0][1][0] == 41 and got[0][1][1] == pytest.approx(41 / 30)
    np.testing.assert_allclose(got[1][1], frame.pose[:3], atol=1e-7)  # project frame, no conversion
    q = frame.pose[3:].reshape(NUM_BONES, 4)
    np.testing.assert_allclose(got[4][1], q[BONES.index("LeftHand")], atol=1e-7)


def test_plain_mode_sends_every_bone_by_default():
    msgs = PlainOscEncoder().layout
    assert sum(len(g) for g in msgs.groups) == 2 + NUM_BONES
    assert all(size <= 1400 for size in msgs.datagram_sizes)


def closed_udp_port() -> int:
    """A loopback UDP port nothing listens on: the kernel answers ICMP port unreachable."""
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    return port


def test_no_receiver_is_refused_not_an_error_logged_once_and_never_raises(caplog):
    port = closed_udp_port()
    caplog.set_level(logging.INFO, logger="realtime.osc_out")
    with OscSink("127.0.0.1", port, "plain") as sink:
        assert sink.notice() is None  # nothing known before the first send
        for i in range(30):
            sink.send(_frame(i))
        stats = sink.stats()
        notice = sink.notice()
    assert stats["frames"] == 30
    assert stats["errors"] == 0 and stats["refused"] > 0 and stats["no_receiver"] == 1
    assert stats["sent"] + stats["refused"] == 30  # one datagram per plain frame
    assert notice == f"no receiver at 127.0.0.1:{port} (connection refused)"
    said = [r.getMessage() for r in caplog.records]
    assert len(said) == 1 and f"no receiver at 127.0.0.1:{port}" in said[0], said


def test_a_receiver_that_appears_gets_frames_and_clears_the_notice(caplog):
    from realtime.osc_out import RECEIVER_BACK_FRAMES

    port = closed_udp_port()
    caplog.set_level(logging.INFO, logger="realtime.osc_out")
    with OscSink("127.0.0.1", port, "vmc", offsets=tpose_offsets()) as sink:
        for i in range(10):
            sink.send(_frame(i))
        assert sink.notice() is not None and sink.stats()["errors"] == 0
        refused = sink.stats()["refused"]
        listener = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        listener.bind(("127.0.0.1", port))
        listener.settimeout(2)
        try:
            got = []
            for i in range(10, 10 + RECEIVER_BACK_FRAMES):
                assert sink.notice() is not None  # until RECEIVER_BACK_FRAMES clean frames went out
                sink.send(_frame(i))
                got += [listener.recv(65536), listener.recv(65536)]  # VMC: two datagrams a frame
        finally:
            listener.close()
        stats = sink.stats()
        assert sink.notice() is None and stats["no_receiver"] == 0
    assert len(got) == 2 * RECEIVER_BACK_FRAMES and all(g.startswith(b"#bundle") for g in got)
    assert stats["refused"] == refused and stats["errors"] == 0
    assert any(f"receiver listens at 127.0.0.1:{port}" in r.getMessage() for r in caplog.records)


def test_ipv6_target_is_named_in_brackets():
    from realtime.osc_out import format_target

    assert format_target("::1", 39539) == "[::1]:39539" and format_target("127.0.0.1", 9) == "127.0.0.1:9"


def test_non_finite_pose_is_skipped_and_counted(receiver):
    server, _ = receiver
    frame = _frame()
    frame.pose[5] = np.nan
    with OscSink("127.0.0.1", server.server_address[1], "plain") as sink:
        sink.send(frame)
        assert sink.stats()["sent"] == 0 and sink.stats()["errors.nonfinite"] == 1


def test_bad_targets_and_options_are_refused():
    with pytest.raises(ConfigError, match="mode"):
        OscSink("127.0.0.1", 9000, "midi")
    with pytest.raises(ConfigError, match="plain"):
        OscSink("127.0.0.1", 9000, "vmc", offsets=tpose_offsets(), names={"Hips": "pelvis"})
    with pytest.raises(RigError, match="Tail"):
        OscSink("127.0.0.1", 9000, "plain", names={"Tail": "tail"})
    with pytest.raises(RigError, match="OSC address"):
        OscSink("127.0.0.1", 9000, "plain", names={"Hips": "pel vis"})
    with pytest.raises(NetworkError, match="no-such-host.invalid:9000"):
        OscSink("no-such-host.invalid", 9000, "plain")


def test_default_offsets_come_from_the_rig_skeleton(receiver):
    """The shipped skeleton is part of the package: without offsets, a VMC sink sends the default
    skeleton's bone offsets (mirrored in x for Unity), not an error and not a T-pose."""
    from models.rig.skeleton import load_default_skeleton

    want = load_default_skeleton().offsets
    np.testing.assert_array_equal(rest_offsets(None), want)
    server, got = receiver
    with OscSink("127.0.0.1", server.server_address[1], "vmc") as sink:
        sink.send(_frame())
        _receive(server, got, 2)
    bones = got[1: 1 + NUM_BONES]
    assert [args[0] for _, args in bones] == list(BONES)
    for j, (_, args) in enumerate(bones[1:], start=1):
        np.testing.assert_allclose(args[1:4], want[j] * [-1, 1, 1], atol=1e-6)
