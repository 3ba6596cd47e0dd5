"""Does the performer listen? Tempo, beat, tempo-ramp and music-presence figures (issue 25).

Runs the three sets of :mod:`models.evaluation.listening` for one or more dance_vq
checkpoints (default: the packaged ``models/assets/default.pt``), prints PASS/FAIL per
target and writes OUT/listening.json, OUT/listening.md and the ramp plot:

* stretch set: recordings between 80 and 130 bpm (the DWM validation songs and
  ``--music``), a 45-s excerpt of each time-stretched to 0.8x, 1.0x and 1.25x (pitch kept);
  mean joint speed, frequency centroid, kinematic bpm, dance-scale amplitude, beat hit rate
  against the music's beats and against beats shifted by half a beat;
* ramp: one song played from 0.85x up to 1.2x over 30 s and back; joint speed against the
  real tempo (both smoothed over 4 s): correlation, lag, largest bone rotation a frame;
* presence: idle fraction of every ``--music`` recording after 3 s; a song interrupted by
  each ``--speech`` recording at the music's RMS level: seconds to idle, idle held, seconds
  to dance again.

Stretched audio and tempi are cached under ``--cache`` (default .cache/listening). On a
2-core machine the full run takes about 10 minutes (first run, nothing cached)::

    nice -n 5 .venv/bin/python benchmarks/listening.py --data ../shared/data \\
        --out runs/listening --plot docs/img/listening_ramp.png

Exit status 2 on a missing or unreadable checkpoint or data directory.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402


def plot_ramp(result: dict, path: str | Path) -> None:
    """Real tempo (bpm), each model's mean joint speed at the first seed (m/s) and the tempo
    it follows (bpm, dashed) over the ramp, one plot, as PNG."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 4), layout="constrained")
    ax = fig.subplots()
    ax2 = ax.twinx()
    first = True
    for k, (name, m) in enumerate(result["models"].items()):
        r = m.get("ramp")
        if not r:
            continue
        t = np.asarray(r["time_s"])
        if first:
            ax.plot(t, r["tempo_bpm"], color="k", lw=2, label=f"real tempo ({r['song']}, {r['bpm']:.0f} bpm x rate)")
            first = False
        seeds = result.get("options", {}).get("ramp_seeds") or [0]
        each = r.get("corr_seeds") or [r["corr"]]
        ax2.plot(t, r["speed"], color=f"C{k}", lw=1.5,
                 label=f"{name}: speed at seed {seeds[0]}, corr {each[0]:.2f}"
                       + (f" (mean over {len(each)} seeds {r['corr']:.2f})" if len(each) > 1 else ""))
        if r.get("follows_tempo"):  # a model that plays its movements at the tempo it follows
            ax.plot(t, r["followed_bpm"], color=f"C{k}", lw=1, ls="--",
                    label=f"{name}: the tempo it follows, corr {r['follower_corr']:.2f}")
    ax.set_xlabel("time (s); all curves smoothed over 4 s")
    ax.set_ylabel("real tempo (bpm)")
    ax2.set_ylabel("performer's mean joint speed (m/s)")
    h1, l1 = ax.get_legend_handles_labels()
    h2, l2 = ax2.get_legend_handles_labels()
    ax.legend(h1 + h2, l1 + l2, fontsize=8, loc="upper left")
    ax.set_title("Tempo ramp 0.85x -> 1.2x -> 0.85x: the music's tempo and the performer's speed", fontsize=10)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    from models.evaluation.listening import RAMP_SEEDS, SEEDS

    p = argparse.ArgumentParser(description=__doc__.split("\nExit status")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog="Exit status 2 on a missing or unreadable checkpoint or data directory.")
    p.add_argument("--checkpoint", nargs="+", default=[None], metavar="CKPT",
                   help="one or more dance_vq checkpoints, compared in one run (default: models/assets/default.pt)")
    p.add_argument("--data", default=str(REPO.parent / "shared" / "data"), metavar="DIR",
                   help="the shared data directory holding dwm/, music/ and speech/ (default: ../shared/data)")
    p.add_argument("--sets", default="stretch,ramp,presence", help="comma-separated sets to run (default: all)")
    p.add_argument("--quick", action="store_true", help="3 songs, 25-s excerpts, 30 s of each recording: a look")
    p.add_argument("--songs", type=int, metavar="N", help="at most N songs in the stretch set")
    p.add_argument("--excerpt-s", type=float, default=45.0, help="seconds of each stretch-set excerpt (default 45)")
    p.add_argument("--ramp-song", metavar="NAME", help="the ramp's recording (file stem or DANCE_* name; "
                   "default: the first stretch-set song long enough)")
    p.add_argument("--seeds", type=int, nargs="+", default=list(SEEDS), metavar="SEED",
                   help="sampling seeds of the stretch set, figures the mean over them "
                        f"(default {' '.join(map(str, SEEDS))}; --quick: the first)")
    p.add_argument("--ramp-seeds", type=int, default=len(RAMP_SEEDS), metavar="N",
                   help=f"the ramp runs at seeds 0..N-1, figures the mean over them (default {len(RAMP_SEEDS)}: "
                        "one seed's correlation spreads from about 0.2 to 0.9; --quick: the first)")
    p.add_argument("--cache", default=".cache/listening", metavar="DIR", help="audio cache (default .cache/listening)")
    p.add_argument("--out", default="runs/listening", metavar="DIR", help="report directory (default runs/listening)")
    p.add_argument("--plot", metavar="PNG", help="the ramp plot (default OUT/listening_ramp.png)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    a = p.parse_args(argv)
    a.sets = tuple(s.strip() for s in a.sets.split(",") if s.strip())
    bad = [s for s in a.sets if s not in ("stretch", "ramp", "presence")]
    if bad or not a.sets:
        p.error(f"--sets takes stretch, ramp, presence; got {','.join(bad) or 'nothing'}")
    if a.excerpt_s <= 5 or (a.songs is not None and a.songs < 1):
        p.error("--excerpt-s must be > 5 and --songs >= 1")
    return a


def main(argv: list[str] | None = None) -> int:
    a = parse_args(argv)
    import torch

    from models.errors import PerformerError
    from models.evaluation import listening as L

    torch.set_num_threads(1)
    data = Path(a.data)
    opts = L.Options(dwm=data / "dwm", music=data / "music", speech=data / "speech", cache_dir=a.cache,
                     excerpt_s=a.excerpt_s, max_songs=a.songs, ramp_song=a.ramp_song, seeds=tuple(a.seeds),
                     ramp_seeds=tuple(range(a.ramp_seeds)),
                     quick=a.quick, progress=not a.quiet, sets=a.sets)
    for d in (data / "dwm", data / "music", data / "speech"):
        if not d.is_dir():
            print(f"listening.py: {d}: no such directory (--data names the directory holding dwm/, music/, speech/)",
                  file=sys.stderr)
            return 2
    t0 = time.perf_counter()
    try:
        result = L.run(a.checkpoint, opts, log=print)
    except (PerformerError, OSError) as e:
        print(f"listening.py: {e}", file=sys.stderr)
        return 2
    result["seconds"] = time.perf_counter() - t0
    command = "nice -n 5 .venv/bin/python benchmarks/listening.py " + " ".join(
        shlex.quote(x) for x in (argv if argv is not None else sys.argv[1:]))
    result["command"] = command
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "listening.json").write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")
    md = L.markdown(result, command)
    (out / "listening.md").write_text(md, encoding="utf-8")
    print(md)
    for line in L.verdict_lines(result):
        print(line)
    if "ramp" in a.sets:
        png = a.plot or out / "listening_ramp.png"
        plot_ramp(result, png)
        print(f"wrote {png}")
    print(f"wrote {out / 'listening.json'}, {out / 'listening.md'} in {result['seconds']:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
