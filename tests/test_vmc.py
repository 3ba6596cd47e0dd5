"""VMC encoding: bytes against python-osc, every address/type/value, handedness, datagram split."""

from __future__ import annotations

import numpy as np
import pytest
from pythonosc.osc_bundle import OscBundle
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message import OscMessage
from pythonosc.osc_message_builder import OscMessageBuilder
from scipy.spatial.transform import Rotation

from models.errors import ConfigError
from models.rig.humanoid import BONES, NUM_BONES, bone_index
from realtime.vmc import (
    MAX_DATAGRAM,
    VMC_OK_ARGS,
    VmcEncoder,
    from_unity_position,
    from_unity_quaternion,
    osc_message,
    split_root,
    to_unity_position,
    to_unity_quaternion,
)

_TPOSE = {  # rest offset from the parent, metres; Left* bones at +X, Right* mirrored
    "Hips": (0, 0.95, 0), "Spine": (0, 0.1, 0), "Chest": (0, 0.15, 0), "Neck": (0, 0.2, 0),
    "Head": (0, 0.1, 0), "Shoulder": (0.05, 0.12, 0), "UpperArm": (0.1, 0, 0),
    "LowerArm": (0.28, 0, 0), "Hand": (0.25, 0, 0), "UpperLeg": (0.09, -0.05, 0),
    "LowerLeg": (0, -0.42, 0), "Foot": (0, -0.4, 0), "Toes": (0, -0.05, 0.12),
}


def tpose_offsets() -> np.ndarray:
    """(NUM_BONES, 3) synthetic T-pose rest offsets in the project frame (left = +X)."""
    rows = []
    for name in BONES:
        side = name.removeprefix("Left").removeprefix("Right")
        x, y, z = _TPOSE[side]
        rows.append((-x if name.startswith("Right") else x, y, z))
    return np.array(rows, dtype=np.float64)


def random_pose(seed: int = 0) -> np.ndarray:
    """(POSE_DIM,) float32 pose with a non-trivial unit rotation on every bone."""
    rng = np.random.default_rng(seed)
    q = Rotation.random(NUM_BONES, random_state=seed).as_quat()
    return np.concatenate([rng.uniform(-1, 1, 3) + [0, 1, 0], q.ravel()]).astype(np.float32)


def parse_datagrams(datagrams: list[bytes]) -> list[OscMessage]:
    """All messages of a frame's bundles, in order, parsed by python-osc."""
    out = []
    for d in datagrams:
        assert OscBundle.dgram_is_bundle(d)
        bundle = OscBundle(d)
        assert bundle.timestamp == IMMEDIATELY
        out.extend(bundle)
    return out


def _builder_message(address: str, args: list) -> bytes:
    b = OscMessageBuilder(address)
    for a in args:
        b.add_arg(a, "f" if isinstance(a, float) else None)
    return b.build().dgram


@pytest.mark.parametrize(
    "address,args",
    [("/VMC/Ext/T", [1.5]), ("/VMC/Ext/OK", [1, 3, 0, 1]), ("/a", ["root", 0.25, -2]), ("/abc", ["abc", "abcd"])],
)
def test_osc_message_matches_python_osc_bytes(address, args):
    assert osc_message(address, *args) == _builder_message(address, args)


def expected_root(pose: np.ndarray, mode: str) -> tuple[list[float], np.ndarray]:
    """(Root/Pos's 7 numbers, the pose with the Hips as the encoder sends them), project frame."""
    if mode == "hips":
        return [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0], np.asarray(pose, np.float64)
    root, hips_pos, hips_rot = split_root(np.asarray(pose, np.float64))
    local = np.concatenate([hips_pos, hips_rot, np.asarray(pose[7:], np.float64)])
    if mode == "in-place":
        return [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0], local
    unity = np.concatenate([to_unity_position(root[:3]), to_unity_quaternion(root[3:])])
    return [float(v) for v in unity.astype(np.float32)], local


@pytest.mark.parametrize("mode", ["world", "in-place", "hips"])
def test_vmc_bundles_match_python_osc_builder_byte_for_byte(mode):
    offsets, pose = tpose_offsets(), random_pose(1)
    enc = VmcEncoder(offsets, root=mode)
    got = enc.encode(pose, 12.5)
    # The same messages built with python-osc, split at the same places.
    root, pose = expected_root(pose, mode)
    msgs = [_builder_message("/VMC/Ext/Root/Pos", ["root", *root])]
    pos = to_unity_position(offsets).astype(np.float32)
    pos[bone_index("Hips")] = to_unity_position(pose[:3])
    rot = to_unity_quaternion(pose[3:].reshape(NUM_BONES, 4)).astype(np.float32)
    for name, p, q in zip(BONES, pos.tolist(), rot.tolist()):
        msgs.append(_builder_message("/VMC/Ext/Bone/Pos", [name, *p, *q]))
    msgs += [_builder_message("/VMC/Ext/OK", list(VMC_OK_ARGS)), _builder_message("/VMC/Ext/T", [12.5])]
    want = []
    for group in enc.layout.groups:
        builder = OscBundleBuilder(IMMEDIATELY)
        for i in group:
            builder.add_content(OscMessage(msgs[i]))
        want.append(builder.build().dgram)
    assert got == want


def test_vmc_frame_every_address_type_and_value():
    offsets, pose = tpose_offsets(), random_pose(2)
    msgs = parse_datagrams(VmcEncoder(offsets, root="hips").encode(pose, 3.25))
    assert [m.address for m in msgs] == (
        ["/VMC/Ext/Root/Pos"] + ["/VMC/Ext/Bone/Pos"] * NUM_BONES + ["/VMC/Ext/OK", "/VMC/Ext/T"]
    )
    root = msgs[0].params
    assert root[0] == "root" and root[1:] == [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]
    assert all(isinstance(v, float) for v in root[1:])
    q = pose[3:].reshape(NUM_BONES, 4)
    for j, m in enumerate(msgs[1 : 1 + NUM_BONES]):
        name, *vals = m.params
        assert name == BONES[j]
        assert len(vals) == 7 and all(isinstance(v, float) for v in vals)
        want_pos = (-pose[0], pose[1], pose[2]) if name == "Hips" else (-offsets[j, 0], offsets[j, 1], offsets[j, 2])
        np.testing.assert_allclose(vals[:3], want_pos, atol=1e-6)
        np.testing.assert_allclose(vals[3:], (q[j, 0], -q[j, 1], -q[j, 2], q[j, 3]), atol=1e-7)
    assert msgs[-2].params == list(VMC_OK_ARGS) and all(isinstance(v, int) for v in msgs[-2].params)
    assert msgs[-1].params == [3.25]


def test_handedness_conversion_rotates_vectors_consistently():
    """Rotating in the project frame then mirroring == mirroring then rotating in Unity's."""
    rng = np.random.default_rng(3)
    q = Rotation.random(200, random_state=4).as_quat()
    v = rng.normal(size=(200, 3))
    ours = Rotation.from_quat(q).apply(v)
    unity = Rotation.from_quat(to_unity_quaternion(q)).apply(to_unity_position(v))
    np.testing.assert_allclose(to_unity_position(ours), unity, atol=1e-12)
    # and back: Unity -> project frame
    back = Rotation.from_quat(from_unity_quaternion(to_unity_quaternion(q))).apply(from_unity_position(to_unity_position(v)))
    np.testing.assert_allclose(back, ours, atol=1e-12)
    # composition (parent * child) survives the conversion
    q2 = Rotation.random(200, random_state=5).as_quat()
    composed = to_unity_quaternion((Rotation.from_quat(q) * Rotation.from_quat(q2)).as_quat())
    separate = (Rotation.from_quat(to_unity_quaternion(q)) * Rotation.from_quat(to_unity_quaternion(q2))).as_quat()
    assert np.allclose(composed, separate, atol=1e-12) or np.allclose(composed, -separate, atol=1e-12)


def test_left_arm_raise_points_up_in_unity():
    """+90 deg about the facing axis (+Z) raises the left arm (+X) in the project frame;
    in Unity the left arm points along -X and the converted rotation must raise it too."""
    q = Rotation.from_euler("z", 90, degrees=True).as_quat()
    np.testing.assert_allclose(Rotation.from_quat(q).apply([1, 0, 0]), [0, 1, 0], atol=1e-12)
    uq = to_unity_quaternion(q)
    np.testing.assert_allclose(Rotation.from_quat(uq).apply([-1, 0, 0]), [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(uq, [0, 0, -np.sqrt(0.5), np.sqrt(0.5)], atol=1e-12)


def test_datagrams_stay_under_the_bound_and_split_in_order():
    offsets, pose = tpose_offsets(), random_pose(6)
    default = VmcEncoder(offsets).encode(pose, 1.0)
    assert len(default) == 2 and all(len(d) <= MAX_DATAGRAM for d in default)
    small = VmcEncoder(offsets, max_datagram=200).encode(pose, 1.0)
    assert len(small) > NUM_BONES // 2 and all(len(d) <= 200 for d in small)
    one = VmcEncoder(offsets, max_datagram=65000).encode(pose, 1.0)
    assert len(one) == 1
    flat = [(m.address, m.params) for m in parse_datagrams(default)]
    assert [(m.address, m.params) for m in parse_datagrams(small)] == flat
    assert [(m.address, m.params) for m in parse_datagrams(one)] == flat


def test_bad_configuration_is_refused():
    with pytest.raises(ConfigError, match="too small"):
        VmcEncoder(tpose_offsets(), max_datagram=64)
    with pytest.raises(ConfigError, match="shape"):
        VmcEncoder(np.zeros((3, 3)))
