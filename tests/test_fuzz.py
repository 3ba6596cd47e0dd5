"""Fuzzing every parser that takes outside bytes: no crash, no hang, only the package's clear errors.

Each test feeds generated input (random bytes and text, structured values, and valid
files mutated line by line and token by token) to one parser and accepts exactly two
outcomes: a result that is well formed, or a :class:`PerformerError` subclass. Anything
else (KeyError, OverflowError, RecursionError, ...) fails the test. Hypothesis keeps
the failing input it found in ``.hypothesis/`` and shrinks it.
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
import tempfile
from collections import deque
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from models.errors import CheckpointError, ConfigError, DataError, NetworkError, RigError
from models.rig.humanoid import BONES, NUM_BONES
from models.rig.motion import Motion

FAST = settings(max_examples=500, deadline=None)  # pure parsers: a few ms per example at most
FILES = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
FEW = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])

# Tokens that have broken parsers before: non-ASCII digits, overflow, subnormals, NaN, nesting.
JUNK = ["nan", "NaN", "inf", "-inf", "1e999", "-1e999", "1e-320", "\u00b2", "\u0661", "-0", "0x10", "1_0",
        "99999999999999999999", "9" * 400, "-1", "0", "", " ", "{", "}", "[", "]", ",", ":", "=", '"', "'",
        "\\", "\x00", "\t", "\r\n", "\ufeff", "\u00e9", "\U0001f511", "true", "null", "[" * 50, "{" * 50]

scalars = st.one_of(
    st.none(), st.booleans(), st.integers(), st.integers(min_value=-(10**400), max_value=10**400),
    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=20), st.sampled_from(JUNK),
)
json_values = st.recursive(scalars, lambda kids: st.lists(kids, max_size=5) | st.dictionaries(st.text(max_size=8), kids,
                                                                                           max_size=5), max_leaves=20)


@st.composite
def mutated(draw, text: str, max_ops: int = 4) -> str:
    """``text`` after 1..max_ops random edits: lines deleted, duplicated, swapped or cut;
    a token replaced by junk; junk inserted; the file truncated."""
    lines = text.splitlines(keepends=True) or [""]
    for _ in range(draw(st.integers(1, max_ops))):
        op = draw(st.sampled_from(["delete", "duplicate", "swap", "token", "insert", "truncate", "cut"]))
        i = draw(st.integers(0, len(lines) - 1))
        if op == "delete" and len(lines) > 1:
            del lines[i]
        elif op == "duplicate":
            lines.insert(i, lines[i])
        elif op == "swap":
            j = draw(st.integers(0, len(lines) - 1))
            lines[i], lines[j] = lines[j], lines[i]
        elif op == "token":
            parts = lines[i].replace(",", " , ").split(" ")
            k = draw(st.integers(0, len(parts) - 1))
            parts[k] = draw(st.sampled_from(JUNK) | st.text(max_size=6))
            lines[i] = " ".join(parts)
        elif op == "insert":
            lines.insert(i, draw(st.sampled_from(JUNK) | st.text(max_size=30)) + draw(st.sampled_from(["", "\n"])))
        elif op == "truncate":
            lines = lines[: i + 1]
            lines[-1] = lines[-1][: draw(st.integers(0, len(lines[-1])))]
        elif op == "cut":
            lines[i] = lines[i][: draw(st.integers(0, len(lines[i])))]
    return "".join(lines)


@st.composite
def flipped(draw, data: bytes) -> bytes:
    """``data`` with a few bytes changed, a slice removed, or the end cut off."""
    b = bytearray(data)
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(["flip", "cut", "drop"]))
        i = draw(st.integers(0, max(0, len(b) - 1)))
        if op == "flip" and b:
            b[i] = draw(st.integers(0, 255))
        elif op == "cut":
            del b[i:]
        elif op == "drop":
            del b[i : i + draw(st.integers(1, 64))]
    return bytes(b)


@pytest.fixture(scope="module")
def workdir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fuzz")


def write(path: Path, content: str | bytes) -> Path:
    if isinstance(content, str):
        path.write_text(content, encoding="utf-8", errors="surrogatepass")
    else:
        path.write_bytes(content)
    return path


# -- WebSocket client messages ----------------------------------------------------------------------

TYPES = ["subscribe", "ping", "auth", "control", "frame", None]
messages = st.one_of(
    st.binary(max_size=64),
    st.text(max_size=64),
    json_values.map(json.dumps),
    st.fixed_dictionaries({"type": st.sampled_from(TYPES)}, optional={
        "format": st.sampled_from(["binary", "json", "xml"]) | json_values,
        "id": json_values, "token": st.sampled_from(["s3cret", "wrong"]) | json_values,
        "action": st.sampled_from(["reset", "set_offset", "set_smoothing", "idle", "style", "energy", "lead",
                                           "stop"])
        | json_values,
        "value": st.floats() | st.integers(-20000, 20000) | json_values,
    }).map(json.dumps),
)


@FAST
@given(messages)
@example("[" * 3000 + "]" * 3000)
@example('{"type": ' + "[" * 900 + "]" * 900 + "}")
def test_client_message_parser(message):
    from realtime.ws_server import parse_client_message

    try:
        msg = parse_client_message(message)
    except NetworkError as exc:
        assert len(str(exc)) < 300
        return
    assert isinstance(msg, dict) and msg["type"] in ("subscribe", "ping", "auth", "control")


@pytest.fixture(scope="module")
def server():
    """A token-protected server whose control channel drives a real (stopped) engine."""
    from test_engine import TinyConvModel, extractor, noise

    from realtime.audio_input import FileSource
    from realtime.engine import Engine
    from realtime.engine_config import EngineConfig
    from realtime.ws_server import WebSocketSink

    eng = Engine(FileSource(noise(0.2), 22050), extractor, TinyConvModel(), [], EngineConfig(warmup_s=0))
    sink = WebSocketSink("127.0.0.1", 0, token="s3cret", control=eng.control, max_messages_per_s=10_000,
                         max_message_bytes=4096, offsets=np.tile([0.0, 0.1, 0.0], (NUM_BONES, 1)))
    yield sink, eng
    sink.close()


@FAST
@given(message=messages, controller=st.booleans())
def test_server_reply_to_any_message(server, message, controller):
    from realtime.ws_server import _Client

    sink, eng = server
    client = _Client(None, "binary", deque(maxlen=8), "fuzz", controller=controller)  # type: ignore[arg-type]
    reply = sink._reply(client, message)
    assert reply is None or reply["type"] in ("error", "subscribed", "pong", "auth_ok", "control_ok")
    json.dumps(reply)  # every reply can be sent
    assert client.fmt in ("binary", "json")
    assert math.isfinite(eng.config.offset_ms) and -10000 <= eng.config.offset_ms <= 10000
    assert 0.0 <= eng.smoother.alpha < 1.0


@FEW
@given(st.lists(messages | st.binary(min_size=4090, max_size=5000) | st.text(min_size=4097, max_size=4200),
                min_size=1, max_size=6))
def test_server_on_a_real_socket(server, batch):
    """Messages on a real connection: each gets a reply or a policy/size close; the server stays up."""
    from websockets.exceptions import ConnectionClosed
    from websockets.sync.client import connect

    sink, _ = server
    with connect(sink.ws_url + "?token=s3cret", max_size=1 << 20) as ws:
        assert json.loads(ws.recv(timeout=5))["type"] == "hello"
        for message in batch:
            try:
                ws.send(message)
                reply = json.loads(ws.recv(timeout=5))
            except ConnectionClosed as exc:
                assert exc.rcvd is not None and exc.rcvd.code in (1008, 1009), exc
                break
            assert reply["type"] in ("error", "subscribed", "pong", "auth_ok", "control_ok")
    with connect(sink.ws_url + "?token=s3cret") as ws:  # still serving
        assert json.loads(ws.recv(timeout=5))["type"] == "hello"


@FAST
@given(action=st.sampled_from(["reset", "set_offset", "set_smoothing", "idle", "style", "energy", "lead"])
       | json_values,
       value=json_values | st.floats() | st.integers())
def test_control_commands(server, action, value):
    _, eng = server
    try:
        eng.control(action, value)
    except ConfigError as exc:
        assert len(str(exc)) < 300
    assert math.isfinite(eng.config.offset_ms) and -10000 <= eng.config.offset_ms <= 10000
    assert 0.0 <= eng.config.smoothing < 1.0
    assert isinstance(eng.idle, bool)


# -- OSC control datagrams ----------------------------------------------------------------------------

osc_texts = st.text(max_size=24).filter(lambda t: "\x00" not in t)
osc_args = st.lists(st.integers(-(2**31), 2**31 - 1) | st.floats(width=32) | osc_texts
                    | st.sampled_from([0, 1, 0.0, 1.0, 40, "calm"]), max_size=3)


@pytest.fixture(scope="module")
def osc_control(server):
    """An OSC control input on loopback driving the same real (stopped) engine."""
    from realtime.osc_control import OscControl

    _, eng = server
    with OscControl("127.0.0.1", 0, control=eng.control, max_messages_per_s=1e9) as ctl:
        yield ctl, eng


@FAST
@given(address=st.sampled_from(["/performer/reset", "/performer/offset", "/performer/smoothing",
                                "/performer/idle", "/performer/style", "/performer/energy", "/performer/lead", "/x",
                                "/"])
       | osc_texts.map(lambda t: "/" + t), args=osc_args, cut=st.integers(0, 64), junk=st.binary(max_size=12),
       bundle=st.booleans())
def test_osc_control_any_datagram(osc_control, address, args, cut, junk, bundle):
    """Any datagram (messages, bundles, cut or with junk added): counted as applied, bad or
    nothing asked; never an exception; the engine's settings stay valid."""
    from realtime.vmc import osc_message

    ctl, eng = osc_control
    data = osc_message(address, *args)
    if bundle:
        data = b"#bundle\x00" + bytes(8) + len(data).to_bytes(4, "big") + data
    data = data[: len(data) - cut % (len(data) + 1)] + junk
    before = ctl.stats()
    ctl.handle(data, ("127.0.0.1", 9))
    after = ctl.stats()
    new = {k: after[k] - before[k] for k in after}
    assert new["refused"] == new["rate_limited"] == 0
    assert new["applied"] + new["bad"] <= new["messages"]  # an empty bundle holds no message
    assert math.isfinite(eng.config.offset_ms) and -10000 <= eng.config.offset_ms <= 10000
    assert 0.0 <= eng.config.smoothing < 1.0 and isinstance(eng.idle, bool)


# -- configuration files ---------------------------------------------------------------------------------

RUN_KEYS = [f.name for f in dataclasses.fields(__import__("realtime.config", fromlist=["RunConfig"]).RunConfig)]
toml_scalars = st.one_of(
    st.booleans(), st.integers(-(2**63), 2**63 - 1), st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=20), st.sampled_from(["127.0.0.1:39539", "[::1]:9000", "h:\u00b2", "x:0", "a.wav", "\u0661"]),
)


def toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, list):
        return "[" + ", ".join(map(toml_value, v)) + "]"
    return json.dumps(v)  # a TOML basic string


def toml_doc(keys) -> st.SearchStrategy[str]:
    value = toml_scalars | st.lists(toml_scalars, max_size=3)
    docs = st.dictionaries(st.sampled_from(keys) | st.text("abcdef_-", min_size=1, max_size=8), value, max_size=6)
    return docs.map(lambda d: "".join(f"{json.dumps(k)} = {toml_value(v)}\n" for k, v in d.items()))


RUN_TOML = 'audio = "a.wav"\nosc = ["127.0.0.1:39539"]\nsmoothing = 0.3\noffset_ms = 80\nws = "0.0.0.0:8765"\n'


@FILES
@given(st.one_of(toml_doc(RUN_KEYS), mutated(RUN_TOML), st.binary(max_size=200).map(bytes)))
@example("a = " + "[" * 5000 + "]" * 5000 + "\n")
@example('osc = "h:\u00b2"\n')
@example('input_device = "\u00b2"\n')
@example("duration = inf\n")
def test_run_config_file(workdir, content):
    from realtime import cli
    from realtime.config import resolve_run_config

    path = write(workdir / "run.toml", content)
    args = cli.build_parser().parse_args(["run", "--config", str(path)])
    try:
        cfg = resolve_run_config(args)
    except ConfigError as exc:
        assert "\n" not in str(exc).strip() or "TOML" in str(exc)
        return
    for name in ("duration", "offset_ms", "smoothing", "warmup", "fallback_after"):
        v = getattr(cfg, name)
        assert v is None or math.isfinite(v), (name, v)
    cfg.osc_targets(), cfg.ws_endpoint()


TRAIN_KEYS = [f.name for f in dataclasses.fields(__import__("models.training.config", fromlist=["x"]).TrainConfig)]
TRAIN_TOML = 'model = "causal"\nseed = 0\nstage1_steps = 30\nlr = 1e-4\ntempos = [0.9, 1.0]\n[model_config]\n' \
             'channels = [8, 8, 8, 8, 8]\n[features]\nn_mels = 64\n'


@FILES
@given(st.one_of(toml_doc(TRAIN_KEYS), mutated(TRAIN_TOML), st.binary(max_size=200).map(bytes)))
@example('tempos = "fast"\n')
@example("lr = \"high\"\n")
@example("[features]\n[model_config]\nchannels = 3\n")
def test_training_config_file(workdir, content):
    from models.training.config import TrainConfig

    path = write(workdir / "train.toml", content)
    try:
        cfg = TrainConfig.from_toml(path)
    except ConfigError:
        return
    defaults = TrainConfig()
    for f in dataclasses.fields(cfg):  # never a silently wrong type
        got, want = getattr(cfg, f.name), getattr(defaults, f.name)
        if f.name == "init_from":  # None by default, a path when given
            assert got is None or isinstance(got, str), f.name
        elif isinstance(want, bool):
            assert isinstance(got, bool), f.name
        elif isinstance(want, float):
            assert isinstance(got, (int, float)) and not isinstance(got, bool) and math.isfinite(got), f.name
        else:
            assert isinstance(got, type(want)) and not (isinstance(got, bool) and not isinstance(want, bool)), f.name
    assert all(isinstance(t, (int, float)) and not isinstance(t, bool) for t in cfg.tempos)


# -- datasets and motion files -----------------------------------------------------------------------------


def dance_json(n: int = 3, seed: int = 0) -> tuple[dict, dict]:
    rng = np.random.default_rng(seed)
    skel = {"length": n, "center": rng.normal(size=(n, 3)).round(3).tolist(),
            "skeletons": rng.normal(size=(n, 23, 3)).round(3).tolist()}
    return skel, {"start_position": 10, "end_position": 10 + 5 * n}


@st.composite
def dance_files(draw) -> tuple[str | bytes, str | bytes]:
    skel, cfg = dance_json(draw(st.integers(0, 4)))
    for doc in (skel, cfg):
        for _ in range(draw(st.integers(0, 3))):
            if not doc:
                break
            key = draw(st.sampled_from(sorted(doc)))
            where = draw(st.sampled_from(["replace", "element", "delete"]))
            if where == "replace":
                doc[key] = draw(json_values)
            elif where == "element" and isinstance(doc[key], list) and doc[key]:
                row = doc[key][draw(st.integers(0, len(doc[key]) - 1))]
                if isinstance(row, list) and row:
                    row[draw(st.integers(0, len(row) - 1))] = draw(json_values)
            elif where == "delete":
                del doc[key]
    texts = [json.dumps(skel), json.dumps(cfg)]
    k = draw(st.integers(0, 2))
    if k < 2:
        texts[k] = draw(mutated(texts[k], 2) | st.binary(max_size=64).map(bytes) | st.just("[" * 100_000))
    return texts[0], texts[1]


@FILES
@given(dance_files())
@example(("[" * 100_000, "{}"))
@example((json.dumps({"length": 2, "center": [[0, 0, 10**400]] * 2, "skeletons": [[[0, 0, 0]] * 23] * 2}), "{}"))
@example((json.dumps(dance_json()[0]), '{"start_position": 1' + "0" * 400 + ', "end_position": 5}'))
@example((json.dumps(dance_json()[0]), '{"start_position": 1' + "0" * 5000 + ', "end_position": 5}'))
def test_dwm_dance_loader(workdir, files):
    from models.data.dwm import load_dance

    d = workdir / "DANCE_C_1"
    d.mkdir(exist_ok=True)
    write(d / "audio.mp3", b"\0")
    write(d / "skeletons.json", files[0])
    write(d / "config.json", files[1])
    try:
        dance = load_dance(d)
    except DataError as exc:
        assert "DANCE_C_1" in str(exc)
        return
    assert np.isfinite(dance.joints_cm).all() and dance.joints_cm.shape[1:] == (23, 3)
    assert 0 <= dance.start_frame < dance.end_frame


@pytest.fixture(scope="module")
def guzheng(guzheng_rig_dir):
    """(rig, a valid animation text with two frames) from the shared Guzheng rig files."""
    from models.data.guzheng import GuzhengAnimation, load_guzheng_rig, write_guzheng_animation

    rig = load_guzheng_rig(guzheng_rig_dir / "skel.txt", guzheng_rig_dir / "useful_joints.txt")
    rot = np.broadcast_to(rig.rest_rotations, (2, rig.num_joints, 4)).copy()
    anim = GuzhengAnimation(root_joint="Bip001 Spine1", root_pos=np.zeros((2, 3)), rotations=rot,
                            joints=tuple(rig.animated))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "a_skeleton.txt"
        write_guzheng_animation(path, anim, rig, groups_per_line=4)
        return rig, path.read_text()


@FILES
@given(data=st.data())
def test_guzheng_animation_loader(workdir, guzheng, data):
    from models.data.guzheng import load_guzheng_animation

    rig, text = guzheng
    content = data.draw(mutated(text, 6) | st.binary(max_size=100).map(bytes))
    path = write(workdir / "x_skeleton.txt", content)
    try:
        anim = load_guzheng_animation(path, rig)
    except (DataError, RigError) as exc:
        assert "x_skeleton.txt" in str(exc)
        return
    assert np.isfinite(anim.root_pos).all() and np.isfinite(anim.rotations).all()
    np.testing.assert_allclose(np.linalg.norm(anim.rotations, axis=-1), 1.0, atol=1e-6)


@FILES
@given(data=st.data())
def test_guzheng_rig_loader(workdir, guzheng_rig_dir, data):
    from models.data.guzheng import load_guzheng_rig

    skel = (guzheng_rig_dir / "skel.txt").read_text(encoding="utf-8-sig")
    useful = (guzheng_rig_dir / "useful_joints.txt").read_text(encoding="utf-8-sig")
    which = data.draw(st.integers(0, 1))
    content = data.draw(mutated([skel, useful][which], 4) | st.binary(max_size=100).map(bytes))
    paths = [write(workdir / "skel.txt", skel), write(workdir / "useful_joints.txt", useful)]
    write(paths[which], content)
    try:
        rig = load_guzheng_rig(*paths)
    except (DataError, RigError):
        return
    assert len(rig.names) == len(rig.parents) and np.isfinite(rig.rest_rotations).all()


@pytest.fixture(scope="module")
def bvh_text(tmp_path_factory) -> str:
    from models.rig.bvh import write_bvh

    rot = np.zeros((3, NUM_BONES, 4))
    rot[..., 3] = 1.0
    path = tmp_path_factory.mktemp("bvh") / "m.bvh"
    write_bvh(path, Motion(root_pos=np.zeros((3, 3)), rotations=rot))
    return path.read_text()


def nested_bvh(depth: int) -> str:
    head = "HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n"
    body = "".join(f"JOINT j{i}\n{{\nOFFSET 0 1 0\nCHANNELS 0\n" for i in range(depth))
    return head + body + "}\n" * (depth + 1) + "MOTION\nFrames: 1\nFrame Time: 0.0333333\n0 0 0\n"


@FILES
@given(data=st.data())
@example(data=None)
def test_bvh_reader(workdir, bvh_text, data):
    from models.rig.bvh import read_bvh

    cases = [nested_bvh(5000), bvh_text.replace("Frame Time: 0.0333333", "Frame Time: 1e-320"),
             bvh_text.replace("CHANNELS 6", "CHANNELS \u0666"), bvh_text.replace("Frames: 3", "Frames: \u00b3")]
    contents = cases if data is None else [data.draw(mutated(bvh_text, 6) | st.binary(max_size=100).map(bytes))]
    for content in contents:
        path = write(workdir / "m.bvh", content)
        try:
            bvh = read_bvh(path)
            assert bvh.fps > 0 and math.isfinite(bvh.fps)
            motion = bvh.to_motion()
        except (DataError, RigError) as exc:
            assert "m.bvh" in str(exc)
            continue
        assert np.isfinite(motion.rotations).all() and np.isfinite(motion.root_pos).all()


def npz_bytes(**arrays) -> bytes:
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return buf.getvalue()


@pytest.fixture(scope="module")
def motion_npz() -> bytes:
    from models.rig.npz import save_npz

    rot = np.zeros((4, NUM_BONES, 4))
    rot[..., 3] = 1.0
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "m.npz"
        save_npz(path, Motion(root_pos=np.zeros((4, 3)), rotations=rot), index=np.arange(4))
        return path.read_bytes()


npz_arrays = st.fixed_dictionaries({}, optional={
    "format": st.sampled_from([np.array("live-performer motion v1"), np.array(1), np.array(["a", "b"])]),
    "bones": st.sampled_from([np.array(BONES), np.array(BONES[:-1]), np.array(3.0), np.array([b"Hips"])]),
    "fps": st.sampled_from([np.array(30.0), np.array("fast"), np.array([30.0, 25.0]), np.array(np.nan),
                            np.array(-1.0), np.array(0.0)]),
    "root_pos": st.sampled_from([np.zeros((2, 3)), np.zeros((2, 2)), np.full((2, 3), np.inf), np.zeros(0),
                                 np.array("x")]),
    "rotations": st.sampled_from([np.tile([0, 0, 0, 1.0], (2, NUM_BONES, 1)), np.zeros((2, NUM_BONES, 4)),
                                  np.zeros((3, NUM_BONES, 4)), np.full((2, NUM_BONES, 4), np.nan),
                                  np.zeros((2, 4))]),
})


@FILES
@given(data=st.data())
def test_npz_loader(workdir, motion_npz, data):
    from models.rig.npz import load_npz, load_npz_extra

    crafted = npz_arrays.map(lambda a: npz_bytes(**a))
    content = data.draw(flipped(motion_npz) | st.binary(max_size=200).map(bytes) | crafted)
    path = write(workdir / "m.npz", content)
    try:
        motion = load_npz(path)
        load_npz_extra(path)
    except (DataError, RigError) as exc:
        assert "m.npz" in str(exc)
        return
    assert np.isfinite(motion.rotations).all() and np.isfinite(motion.root_pos).all()
    assert motion.fps > 0 and math.isfinite(motion.fps)


# -- network frames and OSC ------------------------------------------------------------------------------


@FAST
@given(st.binary(max_size=600))
def test_binary_frame_decoder(data):
    from realtime.wire import decode_frame

    try:
        f = decode_frame(data)
    except NetworkError:
        return
    assert f.rotations.shape[1] == 4 and f.root.shape == (3,)


@FAST
@given(data=st.data())
def test_binary_frame_decoder_on_damaged_frames(data):
    from realtime.wire import decode_frame, encode_frame

    pose = np.r_[0, 1, 0, [0, 0, 0, 1] * NUM_BONES].astype(np.float32)
    damaged = data.draw(flipped(encode_frame(7, 1.0, 2.0, pose)))
    try:
        decode_frame(damaged)
    except NetworkError:
        pass


@FAST
@given(data=st.data())
def test_bench_receiver_frame_index_parsers(data):
    """The latency suite's receiver reads every datagram that reaches its port."""
    measure = pytest.importorskip("realtime.bench.measure")
    from realtime.vmc import VmcEncoder
    from realtime.wire import encode_frame

    pose = np.r_[0, 1, 0, [0, 0, 0, 1] * NUM_BONES].astype(np.float32)
    vmc = b"".join(VmcEncoder(np.zeros((NUM_BONES, 3))).encode(pose, 1.0))
    datagram = data.draw(flipped(vmc) | st.binary(max_size=300) | st.builds(
        lambda t: vmc[: vmc.rfind(b",f\x00\x00") + 4] + np.float32(t).astype(">f4").tobytes(),
        st.floats(width=32, allow_nan=True, allow_infinity=True)))
    i = measure.vmc_frame_index(datagram)
    assert i is None or isinstance(i, int)
    message = data.draw(flipped(encode_frame(7, 1.0, 2.0, pose)) | st.text(max_size=50) | st.binary(max_size=50))
    j = measure.ws_frame_index(message)
    assert j is None or isinstance(j, int)


# -- checkpoints and audio ----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def checkpoint_dict(tmp_path_factory) -> dict:
    import torch

    from models.features.spectral import FeatureConfig
    from models.networks.checkpoint import build_model, save_checkpoint

    torch.manual_seed(0)
    feats = FeatureConfig()
    model = build_model("causal", {"feature_dim": feats.dim, "channels": [8, 8, 8, 8, 8]})
    path = save_checkpoint(tmp_path_factory.mktemp("ck") / "tiny.pt", model, model_name="causal",
                           generator_config=model.config,
                           feature_config={**feats.to_dict(), "fingerprint": feats.fingerprint()},
                           rig={"bones": list(BONES), "pose_dim": 3 + 4 * NUM_BONES})
    return torch.load(path, weights_only=True)


@FEW
@given(data=st.data())
def test_checkpoint_loader(workdir, checkpoint_dict, data):
    """Damaged files and well-formed files with wrong fields: CheckpointError, nothing else."""
    import torch

    from realtime.pipeline import build_pipeline

    ck = dict(checkpoint_dict)
    for _ in range(data.draw(st.integers(1, 3))):
        if not ck:
            break
        key = data.draw(st.sampled_from(sorted(ck)))
        op = data.draw(st.sampled_from(["delete", "replace", "nested"]))
        if op == "delete":
            del ck[key]
        elif op == "replace":
            ck[key] = data.draw(json_values)
        elif isinstance(ck[key], dict) and ck[key]:
            ck[key] = dict(ck[key])
            ck[key][data.draw(st.sampled_from(sorted(ck[key])))] = data.draw(json_values)
    buf = io.BytesIO()
    torch.save(ck, buf)
    raw = buf.getvalue()
    if data.draw(st.booleans()):
        raw = data.draw(flipped(raw))
    path = write(workdir / "ck.pt", raw)
    try:
        build_pipeline(path)
    except CheckpointError as exc:
        assert "ck.pt" in str(exc) and "\n" not in str(exc)


@pytest.mark.parametrize("feature_config", [[1, 2], "abc", 5, {"n_mels": "x"}, {"sample_rate": 10**400}])
def test_checkpoint_with_a_malformed_feature_config(workdir, checkpoint_dict, feature_config):
    import torch

    from realtime.pipeline import build_pipeline

    path = workdir / "fc.pt"
    torch.save({**checkpoint_dict, "feature_config": feature_config}, path)
    with pytest.raises(CheckpointError, match="fc.pt"):
        build_pipeline(path)


@FEW
@given(st.binary(max_size=300) | st.builds(lambda b: b"RIFF\x24\x00\x00\x00WAVEfmt " + b, st.binary(max_size=200)))
def test_audio_file_loader(workdir, content):
    from models.errors import AudioError
    from models.features.audio_io import load_audio

    path = write(workdir / "a.wav", content)
    try:
        audio, sr = load_audio(path)
    except AudioError as exc:
        assert "a.wav" in str(exc)
        return
    assert sr == 22050 and np.isfinite(audio).all()

