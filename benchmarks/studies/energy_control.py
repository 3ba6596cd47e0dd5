"""The energy control, measured: does ``/performer/energy`` make the performer calmer or livelier?

For every validation dance (``models.data.split``, the split ``performer evaluate`` uses)
the checkpoint generates the whole tempo-1 corpus clip from the song's features once per
energy level (``dance_stream.generate(model, ..., energy=e)``: the live stream's frames, all at once;
the same seed for every level, so the levels differ only by the control), and each dance
is compared with the real dancer's on the same song (forward kinematics of both):

* motion energy: ``models.evaluation.metrics.energy_ratio`` (velocity spread, generated
  over real; 1 moves as much as the dancer);
* hand speed: the mean speed of both hands, generated over real (what an audience
  watches most);
* dance-scale amplitude and jitter: ``band_ratios`` (0.25-3 Hz and 6+ Hz power, generated
  over real), as ``performer evaluate`` reports them;
* mean code energy: the z-score (``dance_stream.code_energy``) of the movements the
  stream played, averaged over its code steps (0: as lively as the average code);
* the largest bone step: the largest rotation of any bone from one frame to the next,
  degrees (a whip would show here; the dancers' own largest are 30-50).

Prints one table (mean over songs, and the smallest and largest song) and writes a plot:
motion energy against the control, one line per song, and the first song's right-hand
height over 20 s at the lowest, default and highest level beside the real dancer's::

    .venv/bin/python benchmarks/studies/energy_control.py --data ../shared/data/dwm \\
        --plot docs/img/energy_control.png --json runs/energy_control.json

Exit status 2 on a missing or unreadable checkpoint or dataset, or a checkpoint whose
model has no energy control.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

#: Energy levels, in table order (1 = the default: as the music asks).
LEVELS: tuple[float, ...] = (0.0, 0.5, 1.0, 1.5, 2.0)


def hand_speed(pos: np.ndarray) -> float:
    """Mean speed of both hands, m/s, of FK positions (T, J, 3) at 30 fps."""
    from models.rig.humanoid import BONE_INDEX
    from models.timebase import FPS

    hands = [BONE_INDEX["LeftHand"], BONE_INDEX["RightHand"]]
    return float(np.linalg.norm(np.diff(pos[:, hands], axis=0), axis=-1).mean() * FPS)


def largest_bone_step(poses: np.ndarray) -> float:
    """The largest rotation of any bone between consecutive frames, degrees; poses (T, P)."""
    from models.evaluation.listening import bone_steps_deg

    return float(bone_steps_deg(poses).max()) if len(poses) > 1 else 0.0


def measure_song(model, features: np.ndarray, real_pos: np.ndarray, levels: Sequence[float],
                 seed: int = 0, traces: dict | None = None) -> dict[str, dict[str, float]]:
    """``{str(level): {"energy_ratio", "hand_speed", "band_amp", "jitter", "code_energy", "max_step_deg"}}``
    for one song.

    ``features`` (T, D) the song's model features, ``real_pos`` (T, J, 3) the dancer's FK
    positions on it. Each level's dance: a fresh stream with ``seed``, energy ``level``.
    ``traces``: a dict that receives each level's FK positions (T, J, 3) by level string."""
    from models.evaluation.evaluate import positions
    from models.evaluation.metrics import band_ratios, energy_ratio
    from models.networks.dance_stream import DanceStream
    from models.networks.streaming import sanitize_features

    x, _ = sanitize_features(np.asarray(features))
    out: dict[str, dict[str, float]] = {}
    for level in levels:
        stream = DanceStream(model, seed=seed, energy=level)
        poses = stream.push(x)
        pos = positions(poses)
        if traces is not None:
            traces[f"{level:g}"] = pos
        bands = band_ratios(pos, real_pos)
        codes = np.asarray(stream.codes_drawn, np.int64)
        out[f"{level:g}"] = {"energy_ratio": energy_ratio(pos, real_pos),
                             "hand_speed": hand_speed(pos) / hand_speed(real_pos), "band_amp": bands["band_amp"],
                             "jitter": bands["jitter"],
                             "code_energy": float(stream._chooser.code_energy[codes].mean()) if len(codes) else 0.0,
                             "max_step_deg": largest_bone_step(poses)}
    return out


def table(results: dict[str, dict], levels: Sequence[float]) -> str:
    """Markdown: per level, each figure's mean over songs with [smallest, largest song]."""
    keys = (("energy_ratio", "motion energy / dancer's"), ("hand_speed", "hand speed / dancer's"),
            ("band_amp", "dance-scale amplitude / dancer's"),
            ("jitter", "jitter / dancer's"), ("code_energy", "mean code energy (z)"),
            ("max_step_deg", "largest bone step, deg a frame"))
    lines = ["| energy | " + " | ".join(k[1] for k in keys) + " |", "| ---: |" + " ---: |" * len(keys)]
    for level in levels:
        cells = []
        for key, _ in keys:
            v = np.array([row[f"{level:g}"][key] for row in results.values()])
            fmt = ".1f" if key == "max_step_deg" else ".2f"
            cells.append(f"{v.mean():{fmt}} [{v.min():{fmt}}, {v.max():{fmt}}]")
        lines.append(f"| {level:g}{' (default)' if level == 1.0 else ''} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot(results: dict[str, dict], levels: Sequence[float], out: Path, title: str,
         trace: tuple[str, dict[str, np.ndarray], np.ndarray] | None = None) -> Path:
    """Left: motion energy (generated over real) against the control, one thin line per song
    and the mean. Right (``trace``: song, {level: positions (T, J, 3)}, real positions): the
    right hand's height over the first 20 s at the lowest, default and highest level and the
    real dancer's."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from models.rig.humanoid import BONE_INDEX
    from models.timebase import FPS

    fig, axes = plt.subplots(1, 2 if trace else 1, figsize=(12.0 if trace else 6.4, 4.0), dpi=110, squeeze=False)
    ax = axes[0, 0]
    lv = np.asarray(levels)
    rows = np.array([[row[f"{x:g}"]["energy_ratio"] for x in levels] for row in results.values()])
    for r in rows:
        ax.plot(lv, r, color="0.7", lw=0.8)
    ax.plot(lv, rows.mean(0), "o-", color="C3", lw=2, label=f"mean of {len(rows)} validation dances (grey: each)")
    ax.axhline(1.0, color="k", lw=0.8, ls=":", label="the real dancer")
    ax.set_xlabel("energy control (1 = as the music asks)")
    ax.set_ylabel("motion energy, generated / real dancer")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8, loc="upper left")
    ax.grid(alpha=0.3)
    if trace:
        song, pos, real = trace
        ax = axes[0, 1]
        hand = BONE_INDEX["RightHand"]
        n = min(len(real), int(20 * FPS))
        t = np.arange(n) / FPS
        ax.plot(t, real[:n, hand, 1], color="k", lw=1.2, label="real dancer")
        shown = [f"{min(levels):g}", "1", f"{max(levels):g}"]
        for key, color in zip(dict.fromkeys(shown), ("C0", "C2", "C3")):
            if key in pos:
                ax.plot(t, pos[key][:n, hand, 1], color=color, lw=1.0, label=f"energy {key}")
        ax.set_xlabel("time, s")
        ax.set_ylabel("right hand height, m")
        ax.set_title(f"{song}: the right hand, first 20 s", fontsize=9)
        ax.legend(fontsize=8, loc="upper right", ncol=2)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)
    return out


def run(checkpoint: str, data_root: str | Path, cache_dir: str | Path | None, levels: Sequence[float],
        seed: int = 0, songs: Sequence[str] | None = None, log=print,
        trace: list | None = None) -> dict[str, dict]:
    """Load, generate and measure (see the module docstring); ``{song: measure_song(...)}``.
    ``trace``: a list that receives (song, {level: positions}, real positions) of the first song."""
    import torch

    from models.errors import ConfigError
    from models.evaluation.evaluate import EvalOptions, load_clips, positions, validation_names
    from models.generate import load_model
    from models.networks.dance_vq import DanceVQ

    lm = load_model(checkpoint)
    if not isinstance(lm.model, DanceVQ):
        raise ConfigError(f"{checkpoint}: model {type(lm.model).__name__} has no energy control (dance_vq models do)")
    opts = EvalOptions(cache_dir=cache_dir, progress=False)
    clips = load_clips(data_root, validation_names(data_root, songs, opts), lm.features, opts)
    out: dict[str, dict] = {}
    with torch.no_grad():
        for i, c in enumerate(clips, 1):
            log(f"  [{i}/{len(clips)}] {c.name}: energy {', '.join(f'{x:g}' for x in levels)}")
            real = positions(c.poses)
            pos: dict[str, np.ndarray] = {}
            out[c.name] = measure_song(lm.model, c.features, real, levels, seed, traces=pos)
            if trace is not None and not trace:
                trace.append((c.name, pos, real))
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\nExit status")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog="Exit status 2 on a missing or unreadable checkpoint or dataset, "
                                       "or a checkpoint whose model has no energy control.")
    p.add_argument("--checkpoint", default="models/assets/default.pt", metavar="CKPT",
                   help="a dance_vq checkpoint (default: models/assets/default.pt)")
    p.add_argument("--data", required=True, metavar="DIR", help="the DWM dataset directory (holds DANCE_* dirs)")
    p.add_argument("--cache", default=".cache/corpus", metavar="DIR", help="corpus cache (default .cache/corpus)")
    p.add_argument("--levels", type=float, nargs="+", default=list(LEVELS), metavar="E",
                   help=f"energy levels, each in [0, 2] (default {' '.join(f'{x:g}' for x in LEVELS)})")
    p.add_argument("--songs", nargs="+", metavar="NAME", help="only these validation dances (default: all)")
    p.add_argument("--seed", type=int, default=0, help="generation seed, the same for every level (default 0)")
    p.add_argument("--plot", metavar="PNG", help="also plot motion energy against the control")
    p.add_argument("--json", metavar="OUT", help="also write every song's figures as JSON")
    a = p.parse_args(argv)
    if any(not 0.0 <= x <= 2.0 for x in a.levels):
        p.error("--levels must each be in [0, 2]")
    import torch

    from models.errors import PerformerError

    torch.set_num_threads(1)
    try:
        trace: list = []
        results = run(a.checkpoint, a.data, a.cache, a.levels, a.seed, a.songs,
                      log=lambda m: print(m, file=sys.stderr), trace=trace)
    except (PerformerError, OSError) as e:
        print(f"energy_control.py: {e}", file=sys.stderr)
        return 2
    print(f"The energy control on {len(results)} validation dances ({a.checkpoint}, seed {a.seed}); "
          "mean over songs [smallest, largest]\n")
    print(table(results, a.levels))
    if a.plot:
        title = f"{Path(a.checkpoint).name}: the energy control, seed {a.seed}"
        print(f"wrote {plot(results, a.levels, Path(a.plot), title, trace[0] if trace else None)}")
    if a.json:
        Path(a.json).parent.mkdir(parents=True, exist_ok=True)
        Path(a.json).write_text(json.dumps({"checkpoint": a.checkpoint, "seed": a.seed, "levels": a.levels,
                                            "songs": results}, indent=1) + "\n", encoding="utf-8")
        print(f"wrote {a.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
