"""Show control over OSC (docs/show.md): an independent sender, liblo's ``oscsend``, steers a
running ``performer run --loop`` process; its plain-OSC output and its status line show the effect.

One process serves the tests of this module (``show``): it plays the bundled clip in a loop
through a tiny real checkpoint, streams plain OSC to a receiver in this process, listens for
control on a loopback port with ``--control-allow 127.0.0.1/32``, and prints its status line
every 2 s (stderr is not a terminal). Each test puts back what it changed.
"""

from __future__ import annotations

import logging
import re
import shutil
import signal
import socket
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from test_engine import bone_angles
from test_run_cli import PERFORMER, REPO, clip, ns, one_line_error, run_main, tiny_checkpoint  # noqa: F401
from _proc import default_sigint

from models.errors import ConfigError, NetworkError
from models.timebase import FPS
from realtime.config import load_run_config, resolve_run_config
from realtime.endpoints import parse_networks
from realtime.osc_control import MAX_BUNDLE_DEPTH, OscControl, parse_packet
from realtime.pose_filters import idle_pose
from realtime.receiver import OscReceiver, ReceivedFrame
from realtime.vmc import osc_message

pytestmark = pytest.mark.serial  # controls timed against 0.3-1 s settle bounds: the serial pass of make test

needs_oscsend = pytest.mark.skipif(
    shutil.which("oscsend") is None,
    reason="oscsend not installed (Debian package liblo-tools; `make setup` installs it when run as root)",
)
STATUS = re.compile(r"control (\d+) ok (\d+) bad(?: (\d+) refused)?")


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Show:
    """A running ``performer run`` with OSC control, what it streams and what it prints."""

    def __init__(self, checkpoint: Path, audio: Path) -> None:
        self.receiver = OscReceiver(0, "plain")
        self.port = free_udp_port()
        self.frames: list[ReceivedFrame] = []
        self.lines: list[tuple[float, str]] = []  # (time.monotonic() when read, stderr line)
        self.proc = subprocess.Popen(
            [*PERFORMER, "run", "--audio", str(audio), "--loop", "--checkpoint", str(checkpoint), "--no-ws",
             "--osc-mode", "plain", "--osc", f"127.0.0.1:{self.receiver.port}", "--warmup", "0.2",
             "--control-osc", str(self.port), "--control-allow", "127.0.0.1/32"],
            cwd=REPO, stderr=subprocess.PIPE, text=True, preexec_fn=default_sigint,
        )
        self._stop = threading.Event()
        self._threads = [threading.Thread(target=self._read_frames, daemon=True),
                         threading.Thread(target=self._read_stderr, daemon=True)]
        for t in self._threads:
            t.start()

    def _read_frames(self) -> None:
        while not self._stop.is_set():
            self.frames.extend(self.receiver.poll(0.1))

    def _read_stderr(self) -> None:
        for line in self.proc.stderr:  # type: ignore[union-attr]
            self.lines.append((time.monotonic(), line.rstrip("\n")))

    @property
    def stderr(self) -> str:
        return "\n".join(line for _, line in self.lines)

    def send(self, *args: str) -> float:
        """``oscsend 127.0.0.1 PORT ARGS...``; returns time.monotonic() just before it ran."""
        t = time.monotonic()
        subprocess.run(["oscsend", "127.0.0.1", str(self.port), *args], check=True, timeout=10)
        return t

    def send_raw(self, data: bytes, source: str = "127.0.0.1") -> float:
        """One UDP datagram from a socket bound to ``source`` (any 127.x.y.z works on Linux)."""
        t = time.monotonic()
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind((source, 0))
            s.sendto(data, ("127.0.0.1", self.port))
        return t

    def frames_after(self, t: float, n: int = 1, timeout: float = 10.0) -> list[ReceivedFrame]:
        """At least ``n`` frames that arrived after ``t`` (all of them so far)."""
        deadline = time.monotonic() + timeout
        while True:
            got = [f for f in list(self.frames) if f.arrival > t]
            if len(got) >= n:
                return got
            assert self.proc.poll() is None, f"performer run exited:\n{self.stderr}"
            assert time.monotonic() < deadline, f"{len(got)} of {n} frames after {timeout} s:\n{self.stderr}"
            time.sleep(0.05)

    def status_after(self, t: float, timeout: float = 10.0) -> str:
        """The first status line printed after ``t`` (one every 2 s)."""
        deadline = time.monotonic() + timeout
        while True:
            for when, line in list(self.lines):
                if when > t and " frames" in line:
                    return line
            assert self.proc.poll() is None, f"performer run exited:\n{self.stderr}"
            assert time.monotonic() < deadline, f"no status line within {timeout} s:\n{self.stderr}"
            time.sleep(0.05)

    def counts(self, t: float) -> tuple[int, int, int]:
        """(ok, bad, refused) of the control counters in the first status line after ``t``."""
        line = self.status_after(t)
        m = STATUS.search(line)
        assert m, line
        return int(m[1]), int(m[2]), int(m[3] or 0)

    def close(self) -> tuple[int, str]:
        self.proc.send_signal(signal.SIGINT)
        try:
            self.proc.wait(30)
        finally:
            self._stop.set()
            for t in self._threads:
                t.join(5)
            self.receiver.close()
        return self.proc.returncode, self.stderr


@pytest.fixture(scope="module")
def show(tiny_checkpoint, clip):  # noqa: F811 - the fixtures imported above
    s = Show(tiny_checkpoint, clip)
    try:
        s.frames_after(0.0, n=30, timeout=120)  # streaming (startup on a busy machine can be slow)
        yield s
    finally:
        code, err = s.close()
    assert code == 130 and "Traceback" not in err, err


def offset_of(frames: list[ReceivedFrame]) -> np.ndarray:
    """audio_time minus the frame's nominal end, seconds: the stage offset plus the stream
    time at the last reset (constant between resets)."""
    return np.array([f.audio_time - (f.index + 1) / FPS for f in frames])


def settled(show: Show, t: float) -> list[ReceivedFrame]:
    """Frames that left the engine at least 0.3 s after ``t`` (after the control was applied)."""
    return show.frames_after(t + 0.3, n=10)[:10]


def baseline(show: Show) -> tuple[tuple[int, int, int], float]:
    """The control counters (ok, bad, refused) and the stream's offset (s) as they are now."""
    t0 = time.monotonic()
    return show.counts(t0), offset_of(settled(show, t0))[-1]


# -- each address acts --------------------------------------------------------------------------


@pytest.mark.slow
@needs_oscsend
def test_offset_moves_audio_time_and_shows_in_the_status_line(show):
    before = offset_of(settled(show, time.monotonic()))
    t = show.send("/performer/offset", "i", "40")  # an integer, as a desk may send "40"
    np.testing.assert_allclose(offset_of(settled(show, t)), before[-1] + 0.040, atol=1e-3)
    assert "offset 40 ms" in show.status_after(t + 0.3)
    t = show.send("/performer/offset", "f", "0")
    np.testing.assert_allclose(offset_of(settled(show, t)), before[-1], atol=1e-3)
    assert "offset" not in show.status_after(t + 0.3)


@pytest.mark.slow
@needs_oscsend
def test_smoothing_shows_in_the_status_line(show):
    t = show.send("/performer/smoothing", "f", "0.5")
    assert "smoothing 0.5" in show.status_after(t + 0.3)
    t = show.send("/performer/smoothing", "f", "0")
    assert "smoothing" not in show.status_after(t + 0.3)


@pytest.mark.slow
@needs_oscsend
def test_idle_settles_in_one_second_holds_and_dances_again_without_a_jump(show):
    target = idle_pose().astype(np.float64)

    def is_idle(f: ReceivedFrame) -> bool:
        return np.allclose(f.pose, target, atol=1e-6)

    t_on = show.send("/performer/idle", "i", "1")
    time.sleep(2.5)
    assert "| idle |" in show.status_after(t_on + 0.3)
    t_off = show.send("/performer/idle", "f", "0")  # a TouchOSC toggle sends floats
    after = show.frames_after(t_off + 1.5, n=5)
    frames = [f for f in list(show.frames) if t_on < f.arrival]
    during = [f for f in frames if f.arrival < t_off]
    first = next(i for i, f in enumerate(during) if is_idle(f))
    assert 29 <= first <= 40, first  # 29 blended frames (1 s), give or take the message's way in
    assert all(is_idle(f) for f in during[first:]) and len(during) - first >= 30  # held while idle
    last_fading = during[first - 1]
    assert bone_angles(last_fading.pose, target).max() < np.radians(2) and not is_idle(last_fading)
    leaving = next(f for f in frames if f.arrival > t_off and not is_idle(f))
    assert bone_angles(leaving.pose, target).max() < np.radians(2)  # starts back from the idle pose
    assert np.linalg.norm(leaving.root - target[:3]) < 0.02
    assert not any(is_idle(f) for f in after)  # dancing again
    idx = [f.index for f in frames]
    assert idx == list(range(idx[0], idx[0] + len(idx)))  # the stream never paused
    assert "idle" not in show.status_after(t_off + 1.5)


@pytest.mark.slow
@needs_oscsend
def test_reset_restarts_frame_indices_and_a_buttons_release_does_nothing(show):
    t = show.send("/performer/reset", "f", "0")  # a TouchOSC button's release
    idx = [f.index for f in show.frames_after(t, n=40)]
    assert idx == list(range(idx[0], idx[0] + len(idx))) and idx[0] > 0
    t = show.send("/performer/reset")
    idx = [f.index for f in show.frames_after(t - 0.5, n=55)]  # from before it was sent
    k = next(i for i in range(1, len(idx)) if idx[i] < idx[i - 1])
    assert idx[k:] == list(range(len(idx) - k))  # from 0 again, then on without a gap


# -- bad input is counted and logged once, and never stops the stream -------------------------


BAD_MESSAGES: list[tuple[str, ...]] = [
    ("/performer/offset", "s", "abc"),  # wrong type
    ("/performer/offset", "f", "nan"),
    ("/performer/offset", "f", "20000"),  # out of range
    ("/performer/offset", "ff", "1", "2"),  # too many arguments
    ("/performer/offset",),  # none
    ("/performer/smoothing", "f", "1.5"),
    ("/performer/idle", "i", "2"),
    ("/performer/idle", "s", "on"),
    ("/performer/dance", "f", "1"),  # unknown address
    ("/performer/style", "s", "calm"),  # the tiny model offers no styles
    ("/performer/energy", "f", "1"),
    ("/performer/lead", "f", "67"),  # nor a lead
    ("/performer/reset", "s", "now"),
]


@pytest.mark.slow
@needs_oscsend
def test_bad_messages_are_counted_logged_once_per_address_and_change_nothing(show):
    (ok0, bad0, _), before = baseline(show)
    for args in BAD_MESSAGES:
        show.send(*args)
    t = show.send_raw(b"garbage!")  # not OSC at all
    show.send_raw(b"garbage!")
    ok, bad, _ = show.counts(t + 0.3)
    assert (ok, bad) == (ok0, bad0 + len(BAD_MESSAGES) + 2)
    frames = show.frames_after(t, n=60)
    idx = [f.index for f in frames]
    assert idx == list(range(idx[0], idx[0] + len(idx)))  # still streaming, nothing skipped
    np.testing.assert_allclose(offset_of(frames), before, atol=1e-3)  # no offset was applied
    line = show.status_after(t + 0.3)
    assert "smoothing" not in line and "idle" not in line, line
    err = show.stderr
    assert "Traceback" not in err and show.proc.poll() is None
    for address in {args[0] for args in BAD_MESSAGES}:
        logged = [x for x in err.splitlines() if f"OSC control '{address}'" in x]
        assert len(logged) == 1, (address, logged)  # once per address, however many came
    assert err.count("bad datagram of 8 bytes") == 1
    for text in ["offset_ms must be a finite number, got 'abc'", "unknown address", "this model offers no style control"]:
        assert text in err


@pytest.mark.slow
@needs_oscsend
def test_control_allow_refuses_other_senders(show):
    (ok0, bad0, refused0), before = baseline(show)
    message = osc_message("/performer/offset", 500.0)
    t = show.send_raw(message, source="127.0.0.2")  # outside --control-allow 127.0.0.1/32
    show.send_raw(message, source="127.0.0.2")
    np.testing.assert_allclose(offset_of(settled(show, t)), before, atol=1e-3)
    assert show.counts(t + 0.3) == (ok0, bad0, refused0 + 2)
    assert show.stderr.count("OSC control from 127.0.0.2 refused") == 1
    t = show.send_raw(osc_message("/performer/offset", 0.0), source="127.0.0.1")  # the allowed sender
    assert show.counts(t + 0.3) == (ok0 + 1, bad0, refused0 + 2)


# -- options, warnings and the parser (no process) ---------------------------------------------


def test_control_options_from_flags_and_config_file(tmp_path):
    assert resolve_run_config(ns()).control_endpoint() is None  # off by default
    assert resolve_run_config(ns(control_osc="9000")).control_endpoint() == ("127.0.0.1", 9000)
    assert resolve_run_config(ns(control_osc="0.0.0.0:9000")).control_endpoint() == ("0.0.0.0", 9000)
    assert resolve_run_config(ns(control_osc="[::1]:9000")).control_endpoint() == ("::1", 9000)
    cfg = resolve_run_config(ns(control_osc="0.0.0.0:9000", control_allow="192.168.10.7"))
    assert [str(n) for n in cfg.control_networks()] == ["192.168.10.7/32"]
    conf = tmp_path / "run.toml"
    conf.write_text('control_osc = 9100\ncontrol_allow = ["10.0.0.0/8", "192.168.1.0/24"]\n')
    assert load_run_config(conf) == {"control_osc": "9100", "control_allow": ["10.0.0.0/8", "192.168.1.0/24"]}
    cfg = resolve_run_config(ns(config=conf))
    assert cfg.control_endpoint() == ("127.0.0.1", 9100) and len(cfg.control_networks()) == 2
    conf.write_text("control_allow = [1]\n")
    with pytest.raises(ConfigError, match="list of network strings"):
        load_run_config(conf)


@pytest.mark.parametrize(
    "args, message",
    [
        (["--control-osc", "stage"], "control_osc address must be HOST:PORT"),
        (["--control-osc", "70000"], "control_osc address must be HOST:PORT with a port in 1..65535"),
        (["--control-osc", "9000", "--control-allow", "10.0.0.0/33"], "control_allow must be an IP address"),
        (["--control-allow", "10.0.0.0/8"], "needs --control-osc"),
    ],
)
def test_bad_control_options_exit_2_with_one_line(capsys, clip, tiny_checkpoint, args, message):  # noqa: F811
    code, err = run_main(capsys, "run", "--audio", clip, "--checkpoint", tiny_checkpoint, "--no-ws", "--no-osc",
                         "--quiet", *args)
    assert code == 2
    assert message in one_line_error(err)


def test_control_port_in_use_exits_2_with_one_line(capsys, clip, tiny_checkpoint):  # noqa: F811
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        code, err = run_main(capsys, "run", "--audio", clip, "--checkpoint", tiny_checkpoint, "--no-ws",
                             "--no-osc", "--quiet", "--control-osc", str(port))
    assert code == 2
    assert f"cannot listen for OSC control on 127.0.0.1:{port}" in one_line_error(err)


@pytest.mark.parametrize("host, allow, warns", [("0.0.0.0", None, True), ("0.0.0.0", ["127.0.0.1"], False),
                                                ("127.0.0.1", None, False)])
def test_listening_beyond_loopback_without_an_allow_list_is_warned_about(caplog, host, allow, warns):
    caplog.set_level(logging.WARNING, logger="realtime.osc_control")
    with OscControl(host, 0, control=lambda action, value: None,
                    allow=None if allow is None else parse_networks(allow)):
        pass
    said = [r.getMessage() for r in caplog.records if "without --control-allow" in r.getMessage()]
    assert len(said) == int(warns)


def test_parser_reads_messages_and_bundles_and_refuses_the_rest():
    msg = osc_message("/performer/offset", 40.0)
    assert parse_packet(msg) == [("/performer/offset", "f", [40.0])]
    bundle = b"#bundle\x00" + bytes(8)
    for m in (msg, osc_message("/performer/idle", 1), osc_message("/performer/style", "calm")):
        bundle += len(m).to_bytes(4, "big") + m
    assert parse_packet(bundle) == [("/performer/offset", "f", [40.0]), ("/performer/idle", "i", [1]),
                                    ("/performer/style", "s", ["calm"])]
    nested = msg
    for _ in range(MAX_BUNDLE_DEPTH + 1):
        nested = b"#bundle\x00" + bytes(8) + len(nested).to_bytes(4, "big") + nested
    for bad, why in [(nested, "nested deeper"), (msg[:-4], "truncated"), (msg + bytes(4), "bytes after"),
                     (b"/x\x00\x00,b\x00\x00" + bytes(4), "unsupported OSC argument type 'b'"),
                     (b"x\x00\x00\x00", "must start with '/'"), (b"/abc", "unterminated"),
                     (msg[:-3], "not a multiple of 4"), (bundle[:-4], "bundle element of bad size")]:
        with pytest.raises(NetworkError, match=why):
            parse_packet(bad)
    rng = np.random.default_rng(0)
    for _ in range(2000):  # random bytes and mangled messages: NetworkError or messages, nothing else
        data = bytearray(bundle)
        for i in rng.integers(0, len(data), 3):
            data[i] = rng.integers(0, 256)
        for packet in (bytes(data), rng.bytes(int(rng.integers(0, 64)))):
            try:
                parse_packet(packet)
            except NetworkError:
                pass
