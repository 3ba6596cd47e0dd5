"""``performer library build``: BVH of other rigs onto the humanoid rig (issue 40, item 1).

A known dance is written as BVH the way four exporters would (tests/_bvh_exporters.py: Mixamo
names in cm, CMU names in inches at 120 fps, Bandai-style names with bones along X at 60 fps,
VRM names in metres, Z up, A-pose, 24 fps), imported through the real CLI, and compared with
the original on the rig (FK on the default skeleton, cm): mean <= 3, max <= 8 (issue 40).
Bad files stop the build with one line naming the file, exit 2, nothing written.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from _bvh_exporters import CONVENTIONS, mixamo, write_convention
from _cli import run_cli
from models.data.bvh_import import name_words
from models.data.library import load_library
from models.rig.humanoid import BONE_INDEX, NUM_BONES
from models.rig.kinematics import fk
from models.rig.motion import Motion
from models.rig.skeleton import load_default_skeleton

REPO = Path(__file__).resolve().parents[1]
SAMPLE = Path(os.environ.get("PERFORMER_SHARED", REPO.parent / "shared")) / "data" / "motion"
#: What each convention's file should be read as: (units, up).
DETECTED = {"mixamo_cm": ("cm", "+y"), "cmu_inches": ("in", "+y"), "bandai_style": ("cm", "+y"), "vrm_m_zup": ("m", "+z")}


def performer(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "realtime.cli", *map(str, args)], cwd=REPO,
                          capture_output=True, text=True, timeout=600)


def synthetic_dance(seconds: float = 12.0) -> Motion:
    """A known dance without shared data: every bone swinging at its own rate and phase (up to
    70 degrees), the root travelling a circle and turning with it."""
    t = np.arange(int(seconds * 30)) / 30.0
    rng = np.random.default_rng(40)
    freq = rng.uniform(0.3, 1.5, (NUM_BONES, 3))
    phase = rng.uniform(0, 2 * np.pi, (NUM_BONES, 3))
    amp = rng.uniform(0.1, 0.6, (NUM_BONES, 3))
    for b in ("LeftUpperArm", "RightUpperArm", "LeftLowerArm", "RightLowerArm", "LeftLowerLeg", "RightLowerLeg"):
        amp[BONE_INDEX[b]] *= 2.0
    rotvec = amp[None] * np.sin(2 * np.pi * freq[None] * t[:, None, None] + phase[None])
    rotvec[:, 0, 1] += 0.6 * t  # the body turns
    q = Rotation.from_rotvec(rotvec.reshape(-1, 3)).as_quat().reshape(len(t), NUM_BONES, 4)
    root = np.stack([0.8 * np.sin(0.5 * t), 0.9 + 0.05 * np.sin(4 * t), 0.8 * np.cos(0.5 * t)], 1)
    return Motion(root_pos=root, rotations=q)


@pytest.fixture(scope="module", params=["synthetic", "DWM"])
def known_dance(request) -> Motion:
    if request.param == "synthetic":
        return synthetic_dance()
    from models.data.alignment import resample_positions
    from models.data.dwm import load_dance
    from models.rig.retarget import retarget

    root = request.getfixturevalue("dwm_root")
    aligned = resample_positions(load_dance(root / "DANCE_C_2"))
    return retarget(aligned.positions_m[:900], load_default_skeleton(), source="DANCE_C_2")


def joint_errors_cm(original: Motion, imported: Motion) -> np.ndarray:
    sk = load_default_skeleton()
    a, b = fk(original, sk)[:, :NUM_BONES], fk(imported, sk)[:, :NUM_BONES]
    n = min(len(a), len(b))
    return np.linalg.norm(a[:n] - b[:n], axis=-1) * 100.0


def test_four_exporters_come_back(tmp_path, known_dance):
    folder = tmp_path / "mydances"
    folder.mkdir()
    for name, conv in CONVENTIONS.items():
        write_convention(folder / f"{name}.bvh", known_dance, load_default_skeleton(), conv())
    out = tmp_path / "lib.npz"
    run = performer("library", "build", folder, "--out", out)
    assert run.returncode == 0, run.stderr
    clips = {c.name: c for c in load_library(out)}
    assert set(clips) == set(CONVENTIONS)
    for name, clip in clips.items():
        d = joint_errors_cm(known_dance, clip.motion)
        print(f"{name}: against the original mean {d.mean():.2f} max {d.max():.2f} cm; "
              f"reported {clip.error_mean_cm:.2f} / {clip.error_max_cm:.2f} cm")  # docs/library.md (pytest -s)
        assert d.mean() <= 3.0 and d.max() <= 8.0, (name, d.mean(), d.max())
        assert (clip.units, clip.up) == DETECTED[name]
        assert clip.folder == "mydances" and clip.source == str(folder / f"{name}.bvh")
        assert clip.motion.fps == 30 and abs(clip.motion.num_frames - known_dance.num_frames) <= 1
        assert clip.error_mean_cm < 1.0 and clip.error_max_cm < 3.0, (name, clip.error_mean_cm, clip.error_max_cm)
        assert f"{name} " in run.stdout  # the per-clip report
    assert "retarget error by joint" in run.stdout


def test_map_file_names_an_unknown_rig(tmp_path):
    motion = synthetic_dance(4.0)
    conv = mixamo()
    conv.names = {k: f"bone{i:02d}" for i, k in enumerate(conv.names)}  # no convention knows these
    conv.leaves, conv.insert = {}, {}
    src = write_convention(tmp_path / "odd.bvh", motion, load_default_skeleton(), conv)
    out = tmp_path / "lib.npz"
    run = performer("library", "build", src, "--out", out)
    assert run.returncode == 2 and not out.exists()
    assert "--map" in run.stderr and "LeftUpperArm" in run.stderr
    mapping = tmp_path / "odd.map"
    mapping.write_text("# rig name = joint in the file\n" + "".join(
        f"{k} = {v}\n" for k, v in conv.names.items() if k not in ("LeftShoulder", "RightShoulder")))
    run = performer("library", "build", src, "--out", out, "--map", mapping)
    assert run.returncode == 0, run.stderr
    assert joint_errors_cm(motion, load_library(out)[0].motion).max() <= 8.0


def test_mirrored_file_is_turned_right_handed(tmp_path):
    motion = synthetic_dance(4.0)
    src = write_convention(tmp_path / "a.bvh", motion, load_default_skeleton(), mixamo())
    lines = src.read_text().splitlines()  # negate X of every offset and the root's X position:
    i = lines.index("MOTION")  # the mirror image of the file, left-handed
    for k, ln in enumerate(lines[:i]):
        if ln.strip().startswith("OFFSET"):
            v = ln.split()
            lines[k] = ln[: ln.index("OFFSET")] + f"OFFSET {-float(v[1]):.6f} {v[2]} {v[3]}"
    lines[i + 3:] = [" ".join([f"{-float(r.split()[0]):.5f}"] + r.split()[1:]) for r in lines[i + 3:]]
    # a mirror also flips the sense of the rotations about Y and Z (channels ZXY: z, x, y)
    rows = np.array([[float(x) for x in r.split()] for r in lines[i + 3:]])
    rows[:, 3::3] *= -1  # Z
    rows[:, 5::3] *= -1  # Y
    lines[i + 3:] = [" ".join(f"{x:.5f}" for x in r) for r in rows]
    src.write_text("\n".join(lines) + "\n")
    out = tmp_path / "lib.npz"
    run = performer("library", "build", src, "--out", out)
    assert run.returncode == 0, run.stderr
    clip = load_library(out)[0]
    assert clip.mirrored and "mirrored" in run.stdout
    assert clip.error_max_cm < 3.0 and joint_errors_cm(motion, clip.motion).max() <= 8.0


def test_mmd_english_names(tmp_path):
    """mmd_tools' English names: leg_L is the thigh, knee_L the knee (Mixamo's LeftLeg is a knee)."""
    from _bvh_exporters import LIMBS, Convention, _sided

    names = {"Hips": "center", "Spine": "lower_body", "Chest": "upper_body", "Neck": "neck", "Head": "head",
             **_sided(dict(zip(LIMBS, ("shoulder_{S}", "arm_{S}", "elbow_{S}", "wrist_{S}", "leg_{S}", "knee_{S}",
                                       "ankle_{S}", "toe_{S}"))))}
    motion = synthetic_dance(4.0)
    src = write_convention(tmp_path / "mmd.bvh", motion, load_default_skeleton(), Convention(names=names, units_per_m=12.5))
    out = tmp_path / "lib.npz"
    run = performer("library", "build", src, "--out", out)
    assert run.returncode == 0, run.stderr
    clip = load_library(out)[0]
    assert clip.units == "mmd" and joint_errors_cm(motion, clip.motion).max() <= 8.0


def _bad(case: str, good: str) -> str:
    lines = good.splitlines()
    i = lines.index("MOTION")
    if case == "truncated":
        return good[: int(len(good) * 0.8)]
    if case == "NaN channel":
        lines[i + 10] = lines[i + 10].replace(lines[i + 10].split()[7], "nan", 1)
        return "\n".join(lines)
    if case == "one frame":
        return "\n".join(lines[: i + 1] + ["Frames: 1"] + lines[i + 2 : i + 4])
    raise AssertionError(case)


@pytest.mark.parametrize("case", ["truncated", "NaN channel", "one frame", "no legs", "unknown rig"])
def test_bad_file_is_one_line_exit_2_nothing_written(tmp_path, case):
    motion = synthetic_dance(2.0)
    good = tmp_path / "good.bvh"
    write_convention(good, motion, load_default_skeleton(), mixamo())
    bad = tmp_path / f"bad {case}.bvh"
    if case == "no legs":
        conv = mixamo()
        conv.names = {k: v.replace("UpLeg", "Thing").replace("Leg", "Stick") for k, v in conv.names.items()}
        write_convention(bad, motion, load_default_skeleton(), conv)
    elif case == "unknown rig":
        conv = mixamo()
        conv.names = {k: f"j{i}" for i, k in enumerate(conv.names)}
        conv.leaves, conv.insert = {}, {}
        write_convention(bad, motion, load_default_skeleton(), conv)
    else:
        bad.write_text(_bad(case, good.read_text()))
    out = tmp_path / "lib.npz"
    run = performer("library", "build", good, bad, "--out", out)
    assert run.returncode == 2, run.stdout + run.stderr
    assert not out.exists() and list(tmp_path.glob("*.npz")) == [] and list(tmp_path.glob(".*tmp")) == []
    assert len(run.stderr.strip().splitlines()) == 1 and str(bad) in run.stderr, run.stderr
    assert "Traceback" not in run.stderr
    if case in ("no legs", "unknown rig"):
        assert "LeftUpperLeg" in run.stderr and "--map" in run.stderr


def test_command_line_errors(tmp_path, capsys):
    assert run_cli(capsys, "library", "build", tmp_path / "none.bvh", "--out", tmp_path / "x.npz")[0] == 2
    (tmp_path / "empty").mkdir()
    code, _, err = run_cli(capsys, "library", "build", tmp_path / "empty", "--out", tmp_path / "x.npz")
    assert code == 2 and "no .bvh files" in err
    good = write_convention(tmp_path / "g.bvh", synthetic_dance(1.0), load_default_skeleton(), mixamo())
    code, _, err = run_cli(capsys, "library", "build", good, "--out", tmp_path / "x.pt")
    assert code == 2 and ".npz" in err
    bad_map = tmp_path / "m.map"
    bad_map.write_text("LeftElbow = x\n")
    code, _, err = run_cli(capsys, "library", "build", good, "--out", tmp_path / "x.npz", "--map", bad_map)
    assert code == 2 and "line 1" in err and "LeftElbow" in err
    code, help_text, _ = run_cli(capsys, "library", "build", "--help")
    assert code == 0 and "--map" in help_text and "Mixamo" in help_text and "retarget error" in help_text


@pytest.mark.parametrize("name, expected", [
    ("mixamorig:LeftUpLeg", ("Left", "upleg")), ("UpperArm_L", ("Left", "upperarm")),
    ("LHipJoint", ("Left", "hipjoint")), ("J_Bip_R_LowerLeg", ("Right", "lowerleg")),
    ("Character1_RightForeArm", ("Right", "forearm")), ("leftUpperArm", ("Left", "upperarm")),
    ("upper_arm.R", ("Right", "upperarm")), ("Bip01 L Thigh", ("Left", "thigh")), ("lShldr", ("Left", "shldr")),
    ("LowerBack", (None, "lowerback")), ("Spine1", (None, "spine1")), ("hips", (None, "hips")),
])  # fmt: skip
def test_name_words(name, expected):
    assert name_words(name) == expected


def test_shared_sample(tmp_path):
    """The shared Bandai sample (another rig, cm): imports with a small error, quickly."""
    files = sorted(SAMPLE.glob("*.bvh"))
    if not files:
        pytest.skip(f"shared motion sample not found at {SAMPLE} (set PERFORMER_SHARED)")
    out = tmp_path / "lib.npz"
    run = performer("library", "build", *files, "--out", out)
    assert run.returncode == 0, run.stderr
    clip = load_library(out)[0]
    assert clip.units == "cm" and clip.up == "+y" and not clip.mirrored
    assert clip.error_mean_cm < 1.0 and clip.error_max_cm < 5.0, (clip.error_mean_cm, clip.error_max_cm)
