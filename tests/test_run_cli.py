"""``performer run`` / ``performer devices``, the run config file, the recorder and the status line."""

from __future__ import annotations

import argparse
import io
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from models.errors import ConfigError
from models.rig.humanoid import BONES, NUM_BONES
from models.rig.motion import POSE_DIM
from models.timebase import HOP, SAMPLE_RATE
from realtime import cli
from realtime.config import DEFAULT_OSC, DEFAULT_WS, RunConfig, load_run_config, resolve_run_config
from realtime.frame import PoseFrame
from realtime.recorder import Recorder, record_paths
from realtime.status import StatusLine, format_status
from test_engine import osc_messages
from test_osc_out import closed_udp_port
from _proc import default_sigint

REPO = Path(__file__).resolve().parents[1]
PERFORMER = [sys.executable, "-m", "realtime.cli"]


@pytest.fixture(scope="session")
def tiny_checkpoint(tmp_path_factory) -> Path:
    """A real checkpoint of a very small causal generator (random weights, default features)."""
    import torch

    from models.features.spectral import FeatureConfig
    from models.networks.checkpoint import build_model, save_checkpoint

    torch.manual_seed(0)
    feats = FeatureConfig()
    model = build_model("causal", {"feature_dim": feats.dim, "channels": [8, 8, 8, 8, 8]})
    path = tmp_path_factory.mktemp("ckpt") / "tiny.pt"
    return save_checkpoint(
        path, model, model_name="causal", generator_config=model.config,
        feature_config={**feats.to_dict(), "fingerprint": feats.fingerprint()},
        rig={"bones": list(BONES), "pose_dim": POSE_DIM},
    )


@pytest.fixture(scope="session")
def clip() -> Path:
    from models.features.audio_io import bundled_clip_path

    return bundled_clip_path()


def run_main(capsys, *args) -> tuple[int, str]:
    code = cli.main([str(a) for a in args])
    return code, capsys.readouterr().err


def one_line_error(err: str) -> str:
    lines = [line for line in err.strip().splitlines() if line]
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith("performer run: error: ")
    return lines[0]


# -- the run command ---------------------------------------------------------------------


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def udp_receiver() -> socket.socket:
    recv = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    recv.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 21)
    recv.bind(("127.0.0.1", 0))
    recv.settimeout(0.5)
    return recv


def drain(recv: socket.socket) -> list[bytes]:
    out = []
    try:
        while True:
            out.append(recv.recv(65536))
    except OSError:
        pass
    recv.close()
    return out


def test_run_fast_clip_records_npz_with_right_frames(tmp_path, capsys, clip, tiny_checkpoint):
    out = tmp_path / "out.npz"
    recv = udp_receiver()
    code, err = run_main(capsys, "run", "--audio", clip, "--fast", "--duration", 3, "--record", out,
                         "--checkpoint", tiny_checkpoint, "--osc", f"127.0.0.1:{recv.getsockname()[1]}",
                         "--ws", f"127.0.0.1:{free_port()}")
    assert code == 0, err
    assert f"wrote {out}" in err and "90 frames" in err  # the final status line
    assert f"wrote {out.with_suffix('.bvh')}" in err and out.with_suffix(".bvh").stat().st_size > 0
    with np.load(out) as z:
        n = len(z["pose"])
        assert n == 3 * 30
        assert z["pose"].shape == (n, POSE_DIM) and np.isfinite(z["pose"]).all()
        assert z["rotations"].shape == (n, NUM_BONES, 4)
        np.testing.assert_array_equal(z["index"], np.arange(n))
        np.testing.assert_allclose(z["audio_time"], (np.arange(n) + 1) * HOP / SAMPLE_RATE)
        assert np.all(np.diff(z["audio_sample"]) > 0) and np.all(np.diff(z["wall_time"]) >= 0)
        assert int(z["fps"]) == 30 and int(z["input_sample_rate"]) == SAMPLE_RATE
    vmc_times = [p[0] for a, p in osc_messages(drain(recv)) if a == "/VMC/Ext/T"]  # default mode: VMC
    assert len(vmc_times) == 90


def test_run_with_no_osc_receiver_says_so_instead_of_counting_drops(capsys, clip, tiny_checkpoint):
    """`make demo` with nothing on the VMC port: the status line names the missing receiver
    and counts no drops (before, every frame was a drop)."""
    port = closed_udp_port()
    code, err = run_main(capsys, "run", "--audio", clip, "--fast", "--duration", 2, "--checkpoint", tiny_checkpoint,
                         "--osc", f"127.0.0.1:{port}", "--no-ws")
    assert code == 0, err
    final = [line for line in err.splitlines() if " frames" in line and "60 frames" in line][-1]
    assert "drops 0" in final and final.endswith(f"no receiver at 127.0.0.1:{port} (connection refused)"), err


def test_run_in_process_to_udp_and_config_file(tmp_path, capsys, clip, tiny_checkpoint):
    recv = udp_receiver()
    port = recv.getsockname()[1]
    conf = tmp_path / "run.toml"
    conf.write_text(
        f'audio = "{clip}"\nfast = true\nduration = 1.0\nosc = ["127.0.0.1:{port}"]\nosc_mode = "plain"\n'
        f'no_ws = true\ncheckpoint = "{tiny_checkpoint}"\nrecord = "rec"\nsmoothing = 0.5\nwarmup = 0.5\n'
    )
    code, err = run_main(capsys, "run", "--config", conf, "--duration", "2", "--quiet")  # flag overrides file
    assert code == 0, err
    with np.load(tmp_path / "rec.npz") as z:  # relative to the config file
        assert len(z["pose"]) == 60
    frames = [p[0] for a, p in osc_messages(drain(recv)) if a == "/performer/frame"]
    assert frames == list(range(60))  # every frame reached the real UDP socket, in order


def test_run_lead_streams_the_dancing_models_lead(tmp_path, capsys, clip):
    """performer run --lead 133: what is sent is the dancing default's stream with that lead (the
    model fed the clip's streamed features), not lead 0's."""
    from models.features.audio_io import load_audio
    from realtime.pipeline import build_pipeline

    out = tmp_path / "lead.npz"
    code, err = run_main(capsys, "run", "--audio", clip, "--fast", "--no-ws", "--no-osc", "--warmup", "0",
                         "--lead", "133", "--record", out, "--quiet")
    assert code == 0, err
    with np.load(out) as z:
        got = z["pose"]
    pipe = build_pipeline(None, lead=133.0)
    feats = pipe.extractor_factory(SAMPLE_RATE).push(load_audio(clip, SAMPLE_RATE)[0])
    assert pipe.model.lead_ms == 133.0 and len(got) == len(feats)
    np.testing.assert_allclose(got, pipe.model.push(feats), atol=1e-5)
    assert not np.allclose(got, build_pipeline(None).model.push(feats), atol=1e-3)


@pytest.mark.parametrize(
    "args, message",
    [
        (["--audio", "missing.wav"], "missing.wav: audio file not found"),
        (["--audio", "{clip}", "--checkpoint", "{bad}"], "unreadable checkpoint"),
        (["--audio", "{clip}", "--checkpoint", "nope.pt"], "nope.pt: checkpoint not found"),
        (["--audio", "{clip}", "--osc", "localhost"], "osc address must be HOST:PORT"),
        (["--audio", "{clip}", "--smoothing", "1.5"], "smoothing must be [0, 1)"),
        (["--input-device", "no such device"], ""),
        (["--fast"], "--fast only applies to file replay"),
        (["--audio", "{clip}", "--fast", "--monitor"], "--monitor plays a file replayed in real time"),
        (["--audio", "{clip}", "--record", "/nonexistent/dir/x.npz"], "directory does not exist"),
    ],
)
def test_bad_inputs_exit_2_with_one_line(tmp_path, capsys, clip, tiny_checkpoint, args, message):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"not a checkpoint")
    args = [a.format(clip=clip, bad=bad) for a in args]
    if "--checkpoint" not in args:
        args += ["--checkpoint", str(tiny_checkpoint)]
    code, err = run_main(capsys, "run", *args, "--no-ws", "--osc-mode", "plain", "--quiet")
    assert code == 2
    assert message in one_line_error(err)


def test_port_in_use_exits_2_with_one_line(capsys, clip, tiny_checkpoint):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        code, err = run_main(capsys, "run", "--audio", clip, "--fast", "--checkpoint", tiny_checkpoint,
                             "--no-osc", "--ws", f"127.0.0.1:{port}", "--quiet")
    assert code == 2
    line = one_line_error(err)
    assert f"127.0.0.1:{port}" in line and "in use" in line


def test_unresolvable_osc_host_exits_2(capsys, clip, tiny_checkpoint):
    code, err = run_main(capsys, "run", "--audio", clip, "--checkpoint", tiny_checkpoint, "--no-ws",
                         "--osc", "no-such-host.invalid:9000", "--osc-mode", "plain", "--quiet")
    assert code == 2
    assert "no-such-host.invalid:9000" in one_line_error(err)


@pytest.mark.slow
def test_ctrl_c_stops_cleanly_writes_recording_and_exits_130(tmp_path, clip, tiny_checkpoint):
    out = tmp_path / "take.npz"
    proc = subprocess.Popen(
        [*PERFORMER, "run", "--audio", str(clip), "--record", str(out), "--checkpoint", str(tiny_checkpoint),
         "--no-ws", "--no-osc", "--warmup", "0.5"],
        cwd=REPO, stderr=subprocess.PIPE, text=True, preexec_fn=default_sigint,
    )
    lines = []
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:  # status lines (non-TTY: one every 2 s) show frames flowing
        line = proc.stderr.readline()
        lines.append(line)
        if " frames" in line and not line.split("frames")[0].strip().endswith(" 0"):
            break
    proc.send_signal(signal.SIGINT)
    _, rest = proc.communicate(timeout=30)
    assert proc.returncode == 130, "".join(lines) + rest
    assert "Traceback" not in rest
    with np.load(out) as z:
        assert 0 < len(z["pose"]) < 32 * 30
        np.testing.assert_array_equal(z["index"], np.arange(len(z["pose"])))


# -- devices -----------------------------------------------------------------------------


def test_devices_explains_the_no_device_case(capsys):
    code = cli.main(["devices"])
    out, err = capsys.readouterr()
    assert code in (0, 2)
    if code == 2:
        assert "PortAudio" in err and len(err.strip().splitlines()) == 1
    elif "no audio input device" in out:
        assert "performer run --audio FILE" in out
    else:
        assert "index" in out.splitlines()[0]


@pytest.mark.slow
def test_devices_and_run_with_a_real_portaudio_input(tmp_path, tiny_checkpoint):
    """An ALSA 'null' capture device (silence, delivered as fast as read) stands in for a sound card."""
    alsa = Path("/usr/share/alsa/alsa.conf")
    if not alsa.is_file():
        pytest.skip("ALSA configuration not installed")
    conf = tmp_path / "alsa.conf"
    conf.write_text(f"<{alsa}>\npcm.perfnull {{ type null hint {{ show on description \"test\" }} }}\n")
    out = tmp_path / "live.npz"
    run = ["run", "--input-device", "perfnull", "--sample-rate", "22050", "--duration", "1", "--record", str(out),
           "--checkpoint", str(tiny_checkpoint), "--no-ws", "--no-osc", "--warmup", "0.2"]
    script = f"from realtime import cli; print('devices', cli.main(['devices'])); print('run', cli.main({run!r}))"
    res = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True, timeout=120,
                         env={**os.environ, "ALSA_CONFIG_PATH": str(conf)})
    if "perfnull" not in res.stdout:
        pytest.skip(f"PortAudio does not see the ALSA null device here: {res.stdout}{res.stderr}")
    assert "devices 0" in res.stdout and "run 0" in res.stdout, res.stdout + res.stderr
    with np.load(out) as z:
        assert len(z["pose"]) == 30 and np.isfinite(z["pose"]).all()


# -- config file -------------------------------------------------------------------------


def ns(**kw) -> argparse.Namespace:
    """A parsed ``performer run`` command line."""
    parser = cli.build_parser()
    argv = ["run"]
    for k, v in kw.items():
        argv += [f"--{k.replace('_', '-')}"] + ([] if v is True else [str(v)])
    return parser.parse_args(argv)


def test_defaults_are_documented_values():
    cfg = resolve_run_config(ns())
    assert cfg.osc == [DEFAULT_OSC] == ["127.0.0.1:39539"] and cfg.ws == DEFAULT_WS == "127.0.0.1:8765"
    assert cfg.osc_mode == "vmc" and cfg.threads == 1 and cfg.smoothing == 0 and cfg.offset_ms == 0
    assert cfg.osc_targets() == [("127.0.0.1", 39539)] and cfg.ws_endpoint() == ("127.0.0.1", 8765)


def test_config_file_is_equivalent_to_flags_and_flags_win(tmp_path):
    conf = tmp_path / "run.toml"
    conf.write_text('input-device = 3\nosc = "10.0.0.2:9000"\nosc_mode = "plain"\noffset_ms = 80\nno_ws = true\n')
    cfg = resolve_run_config(ns(config=conf))
    assert cfg.input_device == 3 and cfg.osc_targets() == [("10.0.0.2", 9000)] and cfg.ws_endpoint() is None
    assert cfg.offset_ms == 80.0
    cfg = resolve_run_config(ns(config=conf, offset_ms=-20, audio="x.wav"))
    assert cfg.offset_ms == -20.0 and cfg.audio == Path("x.wav") and cfg.input_device is None
    assert resolve_run_config(ns(input_device="7")).input_device == 7
    assert resolve_run_config(ns(input_device="USB")).input_device == "USB"


@pytest.mark.parametrize(
    "text, message",
    [
        ("smoothnes = 0.3\n", "unknown key 'smoothnes'"),
        ('threads = "two"\n', "key 'threads' must be int"),
        ("fast = 1\n", "key 'fast' must be bool"),
        ("osc = [1, 2]\n", "list of \"HOST:PORT\""),
        ("duration = \n", "invalid TOML"),
    ],
)
def test_bad_config_file_names_file_and_key(tmp_path, text, message):
    conf = tmp_path / "bad.toml"
    conf.write_text(text)
    with pytest.raises(ConfigError) as exc:
        load_run_config(conf)
    assert str(conf) in str(exc.value) and message in str(exc.value)


def test_config_validation_messages():
    with pytest.raises(ConfigError, match="either audio"):
        RunConfig(audio=Path("a.wav"), input_device="x").validate()
    with pytest.raises(ConfigError, match="ws address"):
        RunConfig(ws="nope").validate()
    assert RunConfig(ws="[::1]:8765").validate().ws_endpoint() == ("::1", 8765)


# -- recorder and status line ------------------------------------------------------------


def frame(i: int, value: float = 0.0) -> PoseFrame:
    pose = np.zeros(POSE_DIM, np.float32)
    pose[6::4] = 1.0
    pose[0] = value
    return PoseFrame(index=i, audio_sample=(i + 1) * HOP - 1, audio_time=(i + 1) * HOP / SAMPLE_RATE,
                     wall_time=100.0 + i / 30, pose=pose)


def test_recorder_grows_and_writes_what_was_sent(tmp_path):
    from models.rig.bvh import read_bvh
    from models.rig.npz import load_npz, load_npz_extra

    rec = Recorder(tmp_path / "take", input_sample_rate=48000, initial_frames=4)
    for i in range(10):
        rec.send(frame(i, value=i))
    rec.close()
    rec.send(frame(99))  # after close: ignored
    assert rec.written == [tmp_path / "take.npz", tmp_path / "take.bvh"]
    motion = load_npz(rec.npz_path)
    np.testing.assert_array_equal(motion.root_pos[:, 0], np.arange(10))
    extra = load_npz_extra(rec.npz_path)
    np.testing.assert_array_equal(extra["index"], np.arange(10))
    np.testing.assert_array_equal(extra["pose"][:, 0], np.arange(10))
    np.testing.assert_allclose(extra["wall_time"], 100.0 + np.arange(10) / 30)
    assert int(extra["input_sample_rate"]) == 48000
    bvh = read_bvh(rec.bvh_path)
    assert len(bvh.frames) == 10 and bvh.fps == 30


def test_empty_recording_writes_npz_only(tmp_path):
    rec = Recorder(tmp_path / "empty.npz")
    rec.close()
    assert rec.written == [tmp_path / "empty.npz"]
    with np.load(rec.npz_path) as z:
        assert z["pose"].shape == (0, POSE_DIM)


def test_record_paths():
    assert record_paths("a/b.npz") == (Path("a/b.npz"), Path("a/b.bvh"))
    assert record_paths("a/b.bvh") == (Path("a/b.npz"), Path("a/b.bvh"))
    assert record_paths("take.1") == (Path("take.1.npz"), Path("take.1.npz").with_suffix(".bvh"))


def test_status_line_plain_when_not_a_tty():
    stats = {"state": "running", "frames": 120, "compute_ms_p50": 1.25, "compute_ms_p99": 4.5,
             "latency_ms_p50": 9.0, "latency_ms_p99": 20.0, "overruns": 2, "nan_frames": 1,
             "sink_errors": 1, "sinks": {"ws": {"clients": 2, "drops": 3}, "osc": {"errors": 4}},
             "source": {"input_overflows": 1}}
    text = format_status(stats, fps=30.0)
    for part in ("120 frames", "30.0 fps", "hop p50 1.2 p99 4.5 ms", "drops 8", "clients 2", "overruns 3", "nan 1"):
        assert part in text, text
    buf = io.StringIO()
    line = StatusLine(lambda: stats, stream=buf, plain_interval=0.05)
    line.start()
    time.sleep(0.2)
    line.stop()
    out = buf.getvalue()
    assert "\r" not in out and out.count("\n") >= 2


def test_a_reader_that_goes_away_is_no_error_and_prints_no_traceback(tmp_path):
    """`performer library info big.npz | head -1`: the pipe closes under a long output; the command
    ends quietly (exit 0), with no BrokenPipeError traceback."""
    code = (
        "import sys\n"
        "from realtime import cli\n"
        "def spam(args):\n"
        "    for i in range(200000):\n"
        "        print('line', i)\n"
        "cli.build_parser = (lambda orig: (lambda: (lambda p: (p.set_defaults(func=spam, command='x'), p)[1])(orig())))"
        "(cli.build_parser)\n"
        "sys.exit(cli.main([]))\n"
    )
    proc = subprocess.run(f"{sys.executable} -c \"{code}\" | head -1", shell=True, capture_output=True, text=True,
                          cwd=Path(__file__).resolve().parents[1], timeout=60)
    assert proc.stdout == "line 0\n" and "Traceback" not in proc.stderr and "BrokenPipe" not in proc.stderr, proc.stderr
