"""NPZ motion files: round trip, extras, and clear errors for wrong or corrupt files."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from models.errors import DataError, RigError
from models.rig.humanoid import BONES, NUM_BONES
from models.rig.motion import Motion
from models.rig.npz import FORMAT, load_npz, load_npz_extra, save_npz


@pytest.fixture
def motion():
    q = Rotation.random(12 * NUM_BONES, random_state=0).as_quat().reshape(12, NUM_BONES, 4)
    return Motion(root_pos=np.random.default_rng(0).normal(size=(12, 3)), rotations=q, fps=25.0)


def test_round_trip_is_exact(tmp_path, motion):
    path = tmp_path / "m.motion"  # any suffix: nothing is appended
    save_npz(path, motion, dance=np.array("DANCE_C_2"), offsets=np.ones((3, 3)))
    again = load_npz(path)
    np.testing.assert_array_equal(again.root_pos, motion.root_pos)
    np.testing.assert_array_equal(again.rotations, motion.rotations)
    assert again.fps == 25.0
    extra = load_npz_extra(path)
    assert set(extra) == {"dance", "offsets"} and str(extra["dance"]) == "DANCE_C_2"
    with np.load(path) as z:
        assert list(z["bones"]) == list(BONES) and str(z["format"]) == FORMAT


def test_missing_and_corrupt_files(tmp_path, motion):
    with pytest.raises(DataError, match="not found"):
        load_npz(tmp_path / "none.npz")
    text = tmp_path / "notes.npz"
    text.write_text("hello")
    with pytest.raises(DataError, match="not a readable") as info:
        load_npz(text)
    assert "notes.npz" in str(info.value)
    good = tmp_path / "good.npz"
    save_npz(good, motion)
    cut = tmp_path / "cut.npz"
    cut.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(DataError, match="cut.npz"):
        load_npz(cut)
    # an entry flagged as encrypted (bit 0 of the general-purpose flags, local and central
    # headers): zipfile raises RuntimeError, the loader a DataError naming the file
    raw = bytearray(good.read_bytes())
    raw[6] |= 1
    central = raw.find(b"PK\x01\x02")
    raw[central + 8] |= 1
    locked = tmp_path / "locked.npz"
    locked.write_bytes(bytes(raw))
    with pytest.raises(DataError, match="locked.npz"):
        load_npz(locked)


def test_wrong_archives(tmp_path, motion):
    other = tmp_path / "other.npz"
    np.savez(other, x=np.zeros(3))
    with pytest.raises(DataError, match="missing"):
        load_npz(other)
    fmt = tmp_path / "fmt.npz"
    np.savez(fmt, format=np.array("something else"), bones=np.array(BONES), fps=np.array(30.0),
             root_pos=motion.root_pos, rotations=motion.rotations)  # fmt: skip
    with pytest.raises(DataError, match="format"):
        load_npz(fmt)
    rig = tmp_path / "rig.npz"
    np.savez(rig, format=np.array(FORMAT), bones=np.array(BONES[::-1]), fps=np.array(30.0),
             root_pos=motion.root_pos, rotations=motion.rotations)  # fmt: skip
    with pytest.raises(RigError, match="rig.npz.*made for bones"):
        load_npz(rig)
    nan = tmp_path / "nan.npz"
    np.savez(nan, format=np.array(FORMAT), bones=np.array(BONES), fps=np.array(30.0),
             root_pos=motion.root_pos * np.nan, rotations=motion.rotations)  # fmt: skip
    with pytest.raises(DataError, match="nan.npz.*non-finite"):
        load_npz(nan)
    shape = tmp_path / "shape.npz"
    np.savez(shape, format=np.array(FORMAT), bones=np.array(BONES), fps=np.array(30.0),
             root_pos=motion.root_pos, rotations=motion.rotations[:, :3])  # fmt: skip
    with pytest.raises(DataError, match="shape.npz"):
        load_npz(shape)


def test_bad_extras(tmp_path, motion):
    with pytest.raises(DataError, match="reserved"):
        save_npz(tmp_path / "a.npz", motion, fps=np.array(1.0))
    with pytest.raises(DataError, match="not numeric or string"):
        save_npz(tmp_path / "b.npz", motion, stuff=np.array([{"a": 1}], dtype=object))
