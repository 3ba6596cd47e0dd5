"""Heights of three joints over time, real dancer against generated motion (issue 18).

For one dance of the DWM dataset (default DANCE_W_5, a validation dance) and one or more
checkpoints, plots the height (forward kinematics y, metres) of the right hand, the left
hand and the head over ``--seconds`` (20) of the song, one panel per joint: the captured
dance in black, each checkpoint's generated motion in colour. Both come from the same
path as ``performer evaluate``: the tempo-1 corpus clip (canonical poses on the 30 fps
grid, in place, heading removed), the whole clip generated the way the model runs
(``models.generate.run_model``: causal models in streamed 128-frame windows), forward
kinematics on the default skeleton. The legend gives each curve's standard deviation
over the plotted span (cm), so the picture's point, how far the joints swing, reads as
a number too::

    .venv/bin/python benchmarks/studies/joint_heights.py --checkpoint models/assets/default.pt \\
        --data ../shared/data/dwm --out docs/img/joint_heights_before.png

Exit status 2 on a missing or unreadable checkpoint, dataset or dance.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from models.timebase import FPS  # noqa: E402

#: Plotted joints: FK point name (models.rig.skeleton.POINT_INDEX) -> panel title.
JOINTS: dict[str, str] = {"RightHand": "right hand (wrist)", "LeftHand": "left hand (wrist)", "Head": "head"}


def joint_heights(checkpoints: list[str], data_root: str | Path, dance: str, cache_dir: str | Path | None,
                  window: int = 128, hop: int = 64) -> dict[str, np.ndarray]:
    """``{"real": (T, 3), <checkpoint>: (T, 3), ...}``: heights (m) of :data:`JOINTS` at 30 fps
    over the whole clip of ``dance``, real first, then each checkpoint's generation."""
    import torch

    from models.evaluation.evaluate import EvalOptions, _audio_kw, load_clips, positions
    from models.generate import load_model, run_model
    from models.rig.skeleton import POINT_INDEX

    idx = [POINT_INDEX[j] for j in JOINTS]
    opts = EvalOptions(cache_dir=cache_dir, progress=False)
    loaded = [load_model(c) for c in checkpoints]
    clips: dict[str, object] = {}
    out: dict[str, np.ndarray] = {}
    for c, lm in zip(checkpoints, loaded):
        key = lm.features.fingerprint()
        if key not in clips:
            (clips[key],) = load_clips(data_root, [dance], lm.features, opts)
        clip = clips[key]
        if "real" not in out:
            out["real"] = positions(clip.poses)[:, idx, 1]
        with torch.no_grad():
            poses = run_model(lm.model, clip.features, window, hop, **_audio_kw(lm.model, data_root, clip))
        out[c] = positions(poses)[:, idx, 1]
    return out


def plot(heights: dict[str, np.ndarray], start_s: float, seconds: float, title: str, path: str | Path) -> None:
    """One panel per joint of ``heights`` (see :func:`joint_heights`) from ``start_s`` for ``seconds``, as PNG."""
    from matplotlib.figure import Figure

    a = int(round(start_s * FPS))
    b = a + int(round(seconds * FPS))
    fig = Figure(figsize=(10, 7.5), layout="constrained")
    fig.suptitle(title, fontsize=11)
    axes = fig.subplots(len(JOINTS), 1, sharex=True)
    for j, (ax, name) in enumerate(zip(axes, JOINTS.values())):
        for k, (label, h) in enumerate(heights.items()):
            y = h[a:b, j]
            t = (a + np.arange(len(y))) / FPS
            real = label == "real"
            ax.plot(t, y, color="k" if real else f"C{k - 1}", lw=1.6 if real else 1.2,
                    label=f"{'real dancer' if real else Path(label).name} (std {np.std(y) * 100:.1f} cm)")
        ax.set_title(name, fontsize=10, loc="left")
        ax.set_ylabel("height (m)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper right")
    axes[-1].set_xlabel("time in the dance (s, 30 fps)")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\nExit status")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog="Exit status 2 on a missing or unreadable checkpoint, dataset or dance. "
                                       "Prints each curve's height std per joint.")
    p.add_argument("--checkpoint", nargs="+", metavar="CKPT", default=["models/assets/default.pt"],
                   help="one or more checkpoints (default: models/assets/default.pt)")
    p.add_argument("--data", required=True, metavar="DIR", help="the DWM dataset directory (holds DANCE_* dirs)")
    p.add_argument("--dance", default="DANCE_W_5", metavar="NAME",
                   help="the dance (default DANCE_W_5, a validation dance)")
    p.add_argument("--start", type=float, default=0.0, metavar="S",
                   help="first plotted second of the dance (default 0)")
    p.add_argument("--seconds", type=float, default=20.0, metavar="S", help="plotted seconds (default 20)")
    p.add_argument("--cache", default=".cache/corpus", metavar="DIR", help="corpus cache (default .cache/corpus)")
    p.add_argument("--window", type=int, default=128, help="causal models: window in frames (default 128)")
    p.add_argument("--hop", type=int, default=64, help="causal models: hop in frames (default 64)")
    p.add_argument("--out", default="joint_heights.png", metavar="PNG", help="PNG to write (default joint_heights.png)")
    a = p.parse_args(argv)
    if a.seconds <= 0 or a.start < 0:
        p.error("--seconds must be > 0 and --start >= 0")
    import torch

    from models.errors import PerformerError

    torch.set_num_threads(1)
    try:
        heights = joint_heights(a.checkpoint, a.data, a.dance, a.cache, a.window, a.hop)
    except (PerformerError, OSError) as e:
        print(f"joint_heights.py: {e}", file=sys.stderr)
        return 2
    frames = len(heights["real"])
    if a.start * FPS >= frames:
        print(f"joint_heights.py: --start {a.start:g} s is past the end of {a.dance} ({frames / FPS:.1f} s)",
              file=sys.stderr)
        return 2
    title = (f"{a.dance}: joint heights, real dancer vs generated "
             f"({a.start:g}-{min(a.start + a.seconds, frames / FPS):.0f} s)")
    plot(heights, a.start, a.seconds, title, a.out)
    for label, h in heights.items():
        s = h[int(a.start * FPS) : int((a.start + a.seconds) * FPS)]
        print(f"{label}: height std over the span (cm) " +
              ", ".join(f"{n} {v * 100:.1f}" for n, v in zip(JOINTS, np.std(s, axis=0))))
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
