"""The beat warp, seen: motion speed against the music's beats, with and without it (issue 18).

For one dance of the DWM dataset (default DANCE_W_5, a validation dance) and the dancing
checkpoint, plots over ``--seconds`` (10) the smoothed mean joint speed (m/s, as
``models.evaluation.beats.kinematic_beats`` computes it: forward kinematics, central
differences, Gaussian sigma 2 frames) of the real dancer and of the generated motion with
the beat warp off (``BEAT_WARP = 0``) and on (the shipped depth), one panel each. Grey lines
are the music beats ``performer evaluate`` scores against (``librosa.beat.beat_track`` on
the song), dots the kinematic beats (speed dips); the legend gives each panel's beat hit
rate on the plotted span and on the whole dance::

    .venv/bin/python benchmarks/studies/beat_warp.py --data ../shared/data/dwm --out docs/img/beat_warp.png

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


def speeds(checkpoint: str | None, data_root: str | Path, dance: str, cache_dir: str | Path | None,
           seed: int = 0) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """(``{label: FK positions (T, 30, 3) m}`` for the real dance, the warp off and on; the
    music beat frames (n,) at 30 fps) of ``dance``'s whole tempo-1 clip."""
    import models.networks.player as ds
    from models.errors import PerformerError
    from models.evaluation.evaluate import EvalOptions, clip_music_beats, load_clips, positions
    from models.generate import load_model, run_model

    lm = load_model(checkpoint)
    if lm.name != "dance_vq":
        raise PerformerError(f"{lm.path} is a {lm.name!r} model; the beat warp is dance_vq's")
    (clip,) = load_clips(data_root, [dance], lm.features, EvalOptions(cache_dir=cache_dir, progress=False))
    depth = ds.BEAT_WARP
    out = {"real dancer": positions(clip.poses)}
    try:
        for label, warp in (("warp off (BEAT_WARP = 0)", 0.0), (f"warp on (BEAT_WARP = {depth:g})", depth)):
            ds.BEAT_WARP = warp
            out[label] = positions(run_model(lm.model, clip.features, seed=seed))
    finally:
        ds.BEAT_WARP = depth
    return out, clip_music_beats(data_root, clip)


def plot(pos: dict[str, np.ndarray], beats: np.ndarray, start_s: float, seconds: float, title: str,
         path: str | Path) -> list[str]:
    """One panel per entry of ``pos`` from ``start_s`` for ``seconds``, as PNG; returns one summary line each."""
    from matplotlib.figure import Figure
    from scipy.ndimage import gaussian_filter1d

    from models.evaluation.beats import SPEED_SIGMA, beat_hit_rate, kinematic_beats, motion_speed

    a = int(round(start_s * FPS))
    b = a + int(round(seconds * FPS))
    fig = Figure(figsize=(10, 7.5), layout="constrained")
    fig.suptitle(title, fontsize=11)
    axes = fig.subplots(len(pos), 1, sharex=True)
    lines = []
    for k, (ax, (label, p)) in enumerate(zip(axes, pos.items())):
        speed = gaussian_filter1d(motion_speed(p), SPEED_SIGMA, mode="nearest")
        kin = kinematic_beats(p)
        mus = beats[beats < len(p)]
        span_k, span_m = kin[(kin >= a) & (kin < b)], mus[(mus >= a) & (mus < b)]
        whole, span = beat_hit_rate(kin, mus), beat_hit_rate(span_k, span_m)
        for m in span_m:
            ax.axvline(m / FPS, color="0.75", lw=1.0, zorder=0)
        t = np.arange(a, min(b, len(speed))) / FPS
        color = "k" if k == 0 else f"C{k - 1}"
        ax.plot(t, speed[a:b], color=color, lw=1.4, label=f"{label}: beat hit rate {span:.2f} here, {whole:.3f} "
                                                                 f"over the dance")
        ax.plot(span_k / FPS, speed[span_k], "o", color=color, ms=5)
        ax.set_ylabel("mean joint speed (m/s)")
        ax.grid(alpha=0.25, axis="y")
        ax.legend(fontsize=8, loc="upper right")
        lines.append(f"{label}: beat hit rate {whole:.4f} over the dance ({len(kin)} kinematic beats, "
                     f"{len(mus)} music beats), {span:.3f} in the plotted span")
    axes[-1].set_xlabel("time in the dance (s, 30 fps); grey: music beats; dots: kinematic beats (speed dips)")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    return lines


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\nExit status")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog="Exit status 2 on a missing or unreadable checkpoint, dataset or dance.")
    p.add_argument("--checkpoint", default=None, metavar="CKPT",
                   help="a dance_vq checkpoint (default: the packaged models/assets/default.pt)")
    p.add_argument("--data", required=True, metavar="DIR", help="the DWM dataset directory (holds DANCE_* dirs)")
    p.add_argument("--dance", default="DANCE_W_5", metavar="NAME", help="the dance (default DANCE_W_5, validation)")
    p.add_argument("--start", type=float, default=20.0, metavar="S", help="first plotted second (default 20)")
    p.add_argument("--seconds", type=float, default=10.0, metavar="S", help="plotted seconds (default 10)")
    p.add_argument("--seed", type=int, default=0, help="sampling seed (default 0, as performer evaluate)")
    p.add_argument("--cache", default=".cache/corpus", metavar="DIR", help="corpus cache (default .cache/corpus)")
    p.add_argument("--out", default="beat_warp.png", metavar="PNG", help="PNG to write (default beat_warp.png)")
    a = p.parse_args(argv)
    if a.seconds <= 0 or a.start < 0:
        p.error("--seconds must be > 0 and --start >= 0")
    import torch

    from models.errors import PerformerError

    torch.set_num_threads(1)
    try:
        pos, beats = speeds(a.checkpoint, a.data, a.dance, a.cache, a.seed)
    except (PerformerError, OSError) as e:
        print(f"beat_warp.py: {e}", file=sys.stderr)
        return 2
    frames = len(pos["real dancer"])
    if a.start * FPS >= frames:
        print(f"beat_warp.py: --start {a.start:g} s is past the end of {a.dance} ({frames / FPS:.1f} s)",
              file=sys.stderr)
        return 2
    title = (f"{a.dance}: smoothed mean joint speed against the music's beats "
             f"({a.start:g}-{min(a.start + a.seconds, frames / FPS):.0f} s)")
    for line in plot(pos, beats, a.start, a.seconds, title, a.out):
        print(line)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
