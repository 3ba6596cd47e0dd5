"""A kick past the hip while a foot is handed back (docs/feet.md): the live-controls library machine's stream.

The shared motion sample's library (built now from ``--motion DIR``, or given as ``--library``)
dances on spot (1, 2) of a 3x2 stage, seed 3, to the bundled clip looped, through the lead and energy
changes the live-controls test's library machine (tests/test_live_controls.py) shrank its failure to;
its dancer kicks a released left foot up past the hip near frame 2571. Prints, for the feet step as
set, with its hand-back in rotation space switched off (``feet.ROTATION_RELEASE``) and with the feet
step off: the stream's largest per-frame bone turn (degrees) and its bone, the legs' largest, the left
thigh's largest over frames 2560-2590, and the frames whose releases switched to rotation space;
``--plot PNG``: the left ankle's height, the left thigh's local angle and its per-frame turn over frames
2540-2598, the step as set against the rotation hand-back off::

    .venv/bin/python benchmarks/studies/kick_handback.py --motion ../shared/data/motion --plot docs/img/feet_kick.png

Exit status 0; 2 without ``--motion`` or ``--library``, or with a ``--motion`` that is not a folder.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:  # run as a script from anywhere (it imports foot_skating's --set)
    sys.path.insert(0, str(REPO))
#: The library machine's shrunk steps: (control, value, frames of music after it).
STEPS: tuple[tuple[str, float, int], ...] = (
    ("lead", 66.37924453487464, 258), ("lead", 133.33131126389597, 99), ("lead", 182.6531606726096, 135),
    ("lead", 97.67861591889371, 110), ("lead", 176.47700482032894, 147), ("lead", 50.5322734219635, 189),
    ("energy", 7.273952666284658e-75, 128), ("energy", 0.0, 220), ("lead", 178.67928548658605, 117),
    ("energy", 1.2113504042198417, 293), ("lead", 35.48055129737074, 88), ("energy", 0.0, 200),
    ("energy", 1.0593803790275709, 57), ("energy", 1.3, 153), ("energy", 0.0, 118), ("lead", 0.0, 216),
    ("energy", 1.6229385162383934, 70))
#: Frames (1-based) around the kick that the thigh's largest turn and the plot look at.
NEAR = (2560, 2590)
PLOT = (2540, 2598)


def stream(model, music: np.ndarray, feet: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(poses (T, P), each frame's hand-back mode per leg (T, 2): 1 in rotation space) of the machine's steps."""
    from models.networks.dance_stream import DanceStream

    s = DanceStream(model, seed=3, stage="3x2", spot=(1, 2), feet=feet)
    modes: list[np.ndarray] = []
    if s._feet is not None:  # the feet part's mode each frame, read after its step
        step = s._feet.step

        def recorded(pose, left, right, lift=0.0):
            out = step(pose, left, right, lift)
            modes.append(s._feet._target[:, 4].copy())
            return out

        s._feet.step = recorded
    pos, outs = 0, []
    for control, value, then in STEPS:
        getattr(s, f"set_{control}")(value)
        outs.append(s.push(music[(pos + np.arange(then)) % len(music)]))
        pos = (pos + then) % len(music)
    return np.concatenate(outs), np.array(modes) if modes else np.zeros((0, 2))


def main(argv: list[str] | None = None) -> int:
    from benchmarks.studies.foot_skating import apply_sets

    p = argparse.ArgumentParser(description=__doc__.split("\nExit status")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--motion", metavar="DIR", help="the shared motion sample's folder (../shared/data/motion): its library is built now")
    p.add_argument("--library", metavar="NPZ", help="a library already built from the shared sample (instead of --motion)")
    p.add_argument("--set", action="append", default=[], metavar="PART.NAME=VALUE", help="a feet/stage constant")
    p.add_argument("--plot", metavar="PNG", help="write the kick's plot")
    a = p.parse_args(argv)
    apply_sets(p, a.set)

    from models.features.audio_io import load_audio
    from models.features.spectral import extract_features
    from models.generate import load_library_model, load_model
    from models.networks import feet
    from models.rig.humanoid import BONES
    from models.rig.kinematics import rotation_jumps_deg

    lm = load_model(None)
    with tempfile.TemporaryDirectory() as tmp:
        library = a.library
        if library is None:
            sample = Path(a.motion) if a.motion else None
            if sample is None or not sample.is_dir():
                print(f"kick_handback.py: {'no folder at ' + str(sample) if sample else 'give --motion DIR or --library NPZ'}",
                      file=sys.stderr)
                return 2
            library = str(Path(tmp) / "sample.npz")
            subprocess.run([sys.executable, "-m", "realtime.cli", "library", "build", str(sample), "--out", library],
                           cwd=REPO, check=True, capture_output=True)
        model = load_library_model(lm.model, library)
    y, _ = load_audio(REPO / "models" / "assets" / "clip.ogg", 22050)  # as the test's clip_features: 20 s of silence after
    music = extract_features(np.concatenate([y, np.zeros(20 * 22050, np.float32)]), lm.features)[:len(y) // (22050 // 30)]
    legs = [BONES.index(f"{s}{b}") for s in ("Left", "Right") for b in ("UpperLeg", "LowerLeg", "Foot")]
    thigh = BONES.index("LeftUpperLeg")
    shown = feet.ROTATION_RELEASE
    runs = {}
    for label, rotation, on in (("feet step as set", shown, True), ("rotation hand-back off", False, True),
                                ("feet step off", shown, False)):
        feet.ROTATION_RELEASE = rotation
        poses, modes = stream(model, music, on)
        turns = rotation_jumps_deg(poses[:, 3:].reshape(len(poses), -1, 4).astype(np.float64))  # (T-1, B)
        f, b = np.unravel_index(turns.argmax(), turns.shape)
        switched = [i + 1 for i in range(1, len(modes)) for k in (0, 1) if modes[i, k] == 1 and modes[i - 1, k] != 1]
        print(f"{label:<24} largest {turns.max():5.1f} deg ({BONES[b]}, frame {f + 1}), legs {turns[:, legs].max():5.1f}, "
              f"left thigh over frames {NEAR[0]}-{NEAR[1]} {turns[NEAR[0] - 1:NEAR[1] - 1, thigh].max():5.1f}; "
              f"switched to rotation space at frames {switched}")
        runs[label] = poses
    feet.ROTATION_RELEASE = shown
    if a.plot:
        plot(runs, a.plot)
        print(f"wrote {a.plot}")
    return 0


def plot(runs: dict[str, np.ndarray], path: str) -> None:
    """The left ankle's height, the left thigh's local angle and per-frame turn over :data:`PLOT`."""
    from matplotlib.figure import Figure
    from scipy.spatial.transform import Rotation

    from models.evaluation.evaluate import positions
    from models.rig.humanoid import BONE_INDEX
    from models.rig.kinematics import rotation_jumps_deg

    a, b = PLOT
    frames = np.arange(a, b) + 1
    c = 3 + 4 * BONE_INDEX["LeftUpperLeg"]
    fig = Figure(figsize=(10, 8))
    ax = fig.subplots(3, 1, sharex=True)
    for label, style in (("feet step off", "k:"), ("rotation hand-back off", "-"), ("feet step as set", "-")):
        p = runs[label]
        ax[0].plot(frames, positions(p[a:b])[:, BONE_INDEX["LeftFoot"], 1], style, label=label)
        ax[1].plot(frames, np.degrees(Rotation.from_quat(p[a:b, c:c + 4]).magnitude()), style, label=label)
        turns = rotation_jumps_deg(p[:, 3:].reshape(len(p), -1, 4).astype(np.float64))[:, BONE_INDEX["LeftUpperLeg"]]
        ax[2].plot(frames, turns[a - 1:b - 1], style, label=label)
    ax[0].set_ylabel("left ankle height, m")
    ax[1].set_ylabel("left thigh's local angle, deg")
    ax[2].set_ylabel("left thigh's turn, deg/frame")
    ax[2].set_xlabel("frame (30 fps): the shared sample's library on 3x2, spot (1, 2), the library machine's steps")
    ax[0].legend(fontsize=8)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)


if __name__ == "__main__":
    raise SystemExit(main())
