"""Where does the followed tempo's lag on the listening ramp come from? (issue 43)

The ramp of ``benchmarks/listening.py`` (``models.evaluation.listening.ramp``: one song at
0.85x for 6 s, up to 1.2x over 30 s, back over 30 s) scores a curve against the real tempo
by smoothing both over ``SMOOTH_S`` (4 s, centred) and finding the lag of the best
correlation (0-5 s). This script puts each stage of the tempo's path through that same
measure, with no motion generated:

* ``perfect``: the real tempo itself, and the same 2 s late: what the measure reads of a
  follower with no lag and with a known one (is the lag partly the smoothing's?);
* ``tracker``: the feature extractor's beat tracker (6-s window), at the octave of the
  real tempo, on the frames that read the running level (within 0.1 octave of it);
* ``follower, no lead`` and ``follower``: :class:`models.networks.tempo.TempoFollower`
  without its drift lead (``DRIFT_LEAD = 0``) and as shipped.

With ``--seeds N`` it then runs the performer over the ramp at seeds 0..N-1 with the lead
off and on (the same seeds, one process): the speed's correlation and lag (the benchmark's
figure), the followed tempo's, the movements' nominal rate's (the memory's tempo over the
followed one, each movement's rate taken at its start and ramped over it) and the largest
bone rotation a frame. With ``--stretch`` it reads the follower over every stretch-set
excerpt at 0.8x, 1.0x and 1.25x, lead off and on: how much the followed tempo wanders on a
steady song (the standard deviation of its log over the excerpt after 6 s, in per cent) and
the largest lead::

    nice -n 5 .venv/bin/python benchmarks/studies/tempo_lag.py --data ../shared/data --seeds 48 --stretch

``--grid LEAD,TAU ...`` tries other settings of the lead (the ramp's lag against the wander
each adds on the stretch set); ``--stretch-motion`` adds the stretch set's figures (speed and centroid ratios, band
amplitudes, beat hit rates; ``benchmarks/listening.py --sets stretch``) with the lead off and on.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

#: Seconds of each stretch-set reading left out at its start (the tracker's window fills).
SKIP_S: float = 6.0


def lag_through_the_measure(truth: np.ndarray, curve: np.ndarray, smooth_s: float) -> tuple[float, float]:
    """(best correlation, its lag in s) of ``curve`` following ``truth`` (both (T,) per frame),
    each smoothed over ``smooth_s`` and compared from the ramp's hold on, as the ramp does."""
    from models.evaluation import listening as L
    from models.timebase import FPS

    a, lags = int(L.RAMP_HOLD_S * FPS), int(L.MAX_LAG_S * FPS)
    c, lag, _ = L.lagged_correlation(L.smooth(truth, smooth_s)[a:], L.smooth(curve, smooth_s)[a:], lags)
    return c, lag / FPS


@contextlib.contextmanager
def drift_lead(on: bool):
    """The follower's drift lead (``tempo.DRIFT_LEAD``) as shipped (``on``) or off, within the block."""
    from models.networks import tempo as TM

    keep = TM.DRIFT_LEAD
    TM.DRIFT_LEAD = keep if on else 0.0
    try:
        yield
    finally:
        TM.DRIFT_LEAD = keep


def followed_bpm(logp: np.ndarray, clarity: np.ndarray, onset: np.ndarray, lead: bool) -> np.ndarray:
    """The follower's tempo (bpm, (T,)) over beat columns, its drift lead on or off (NaN before a pulse)."""
    from models.networks.tempo import track_periods
    from models.timebase import FPS

    with drift_lead(lead):
        p = track_periods(logp, clarity, onset)
    return np.where(p > 0, 60.0 * FPS / np.maximum(p, 1e-9), np.nan)


def _filled(x: np.ndarray) -> np.ndarray:
    """``x`` with its NaNs filled from the nearest frames that have a value."""
    i = np.arange(len(x))
    good = np.isfinite(x)
    return np.interp(i, i[good], x[good])


def beat_columns(lm, audio: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(log2 P/15, clarity, onset) columns of ``audio`` as ``performer generate`` extracts them."""
    from models.features.spectral import extract_features

    f = extract_features(np.asarray(audio, np.float32), lm.features).astype(np.float64)
    c = lm.model.config
    return f[:, c.clarity_col + 1], f[:, c.clarity_col], f[:, c.onset_col]


def stages(lm, y: np.ndarray, bpm: float) -> list[tuple[str, float, float, float, float]]:
    """(stage, correlation and lag at 4-s smoothing, the same at 1 s) of each stage of the
    tempo's path over the ramp's audio ``y`` (module docstring)."""
    from models.evaluation import listening as L
    from models.timebase import FPS

    logp, clarity, onset = beat_columns(lm, y)
    t = (np.arange(len(logp)) + 1) / FPS
    truth = bpm * L.ramp_rate(t)
    late = np.concatenate([np.full(2 * FPS, truth[0]), truth[: -2 * FPS]])
    raw = 60.0 * FPS / (15.0 * 2.0 ** logp)
    raw = raw * 2.0 ** np.round(np.log2(truth / raw))  # at the real tempo's octave
    near = np.abs(np.log2(raw / truth)) <= 0.1
    curves = [("perfect: the real tempo", truth), ("perfect, 2 s late", late),
              (f"tracker, frames at the running level ({near.mean():.0%})", _filled(np.where(near, raw, np.nan))),
              ("follower, no lead (DRIFT_LEAD 0)", _filled(followed_bpm(logp, clarity, onset, False))),
              ("follower (shipped)", _filled(followed_bpm(logp, clarity, onset, True)))]
    out = []
    for name, x in curves:
        c4, l4 = lag_through_the_measure(truth, x, L.SMOOTH_S)
        c1, l1 = lag_through_the_measure(truth, x, 1.0)
        out.append((name, c4, l4, c1, l1))
    return out


def perform_ramp(lm, y: np.ndarray, bpm: float, seeds: int, lead: bool) -> dict:
    """The performer over the ramp at seeds 0..``seeds``-1 with the follower's lead on or off:
    per seed the speed's, the followed tempo's and the nominal rate's (correlation, lag s)
    and the largest bone rotation a frame."""
    from models.evaluation import listening as L
    from models.timebase import FPS

    runs = []
    with drift_lead(lead):
        for seed in range(seeds):
            trace: dict = {}
            poses, _ = L.perform(lm, y, seed, trace)
            t = (np.arange(len(poses)) + 1) / FPS
            truth = bpm * L.ramp_rate(t)
            speed = L.motion_speed(L.positions(poses))
            nominal = _nominal_rate(trace["tempo_bpm"])
            runs.append({"speed": lag_through_the_measure(truth, speed, L.SMOOTH_S),
                         "follower": lag_through_the_measure(truth, trace["tempo_bpm"], L.SMOOTH_S),
                         "nominal": lag_through_the_measure(truth, nominal, L.SMOOTH_S),
                         "played": lag_through_the_measure(truth, trace["rate"], L.SMOOTH_S),
                         "step": float(L.bone_steps_deg(poses[int(L.SETTLE_S * FPS):]).max())})
    return {"runs": runs}


def _nominal_rate(tempo_bpm: np.ndarray, seg: int = 8) -> np.ndarray:
    """The tempo's share of each movement's rate: the followed tempo taken at each movement's
    start (every ``seg`` frames) and ramped from the last movement's over the movement, as
    ``Player.advance`` ramps it (caps, speed matching and the pulse's fade left out)."""
    x = np.asarray(tempo_bpm, np.float64)
    at = x[::seg]
    prev = np.concatenate([at[:1], at[:-1]])
    j = (np.arange(len(x)) % seg) / seg
    k = np.arange(len(x)) // seg
    return prev[k] + (at[k] - prev[k]) * j


def steadiness(lm, cache, songs, opts) -> list[tuple[str, str, float, float, float, float]]:
    """Per stretch-set song and rate: (song, rate, wander % lead off, wander % lead on, median
    ratio on / off, largest lead %) of the followed tempo after :data:`SKIP_S`."""
    from models.evaluation import listening as L
    from models.timebase import FPS

    rows = []
    for p, _ in songs:
        start, seconds = L._excerpt_window(cache, p, opts)
        for r in L.STRETCH_RATES:
            logp, clarity, onset = beat_columns(lm, cache.excerpt(p, start, seconds, r))
            off, on = (followed_bpm(logp, clarity, onset, lead)[int(SKIP_S * FPS):] for lead in (False, True))
            wander = [100.0 * float(np.nanstd(np.log(x))) for x in (off, on)]
            rows.append((L.song_name(p), f"{r:g}", *wander, float(np.nanmedian(on) / np.nanmedian(off)),
                         100.0 * float(np.nanmax(np.abs(on / off - 1.0)))))
    return rows


def lead_grid(lm, y: np.ndarray, bpm: float, cache, songs, opts, grid) -> list[tuple[float, float, float, float, float]]:
    """Per (DRIFT_LEAD, DRIFT_TAU) of ``grid``: (lead, tau, the followed tempo's lag on the ramp
    (s, 4-s smoothing), the mean and the largest over the stretch-set excerpts of the wander
    the lead adds: the standard deviation of ln(followed bpm with it / without it), %)."""
    from models.evaluation import listening as L
    from models.networks import tempo as TM
    from models.timebase import FPS

    logp, clarity, onset = beat_columns(lm, y)
    truth = bpm * L.ramp_rate((np.arange(len(logp)) + 1) / FPS)
    steady = []
    for p, _ in songs:
        start, seconds = L._excerpt_window(cache, p, opts)
        steady += [beat_columns(lm, cache.excerpt(p, start, seconds, r)) for r in L.STRETCH_RATES]
    skip = int(SKIP_S * FPS)
    off = [followed_bpm(*c, False)[skip:] for c in steady]
    keep = TM.DRIFT_LEAD, TM.DRIFT_TAU
    rows = []
    try:
        for lead, tau in grid:
            TM.DRIFT_LEAD, TM.DRIFT_TAU = lead, tau
            lag = lag_through_the_measure(truth, _filled(followed_bpm(logp, clarity, onset, True)), L.SMOOTH_S)[1]
            added = [100.0 * float(np.nanstd(np.log(followed_bpm(*c, True)[skip:] / o))) for c, o in zip(steady, off)]
            rows.append((lead, tau, lag, float(np.mean(added)), float(np.max(added))))
    finally:
        TM.DRIFT_LEAD, TM.DRIFT_TAU = keep
    return rows


#: The stretch set's figures ``--stretch-motion`` compares (keys of ``listening.summary``).
MOTION_KEYS: tuple[str, ...] = ("speed_ratio", "centroid_ratio", "amp_min", "amp_max", "hit_0.8", "hit_1", "hit_1.25",
                                "hit_half_min")


def stretch_motion(lm, cache, songs, opts) -> dict[bool, dict[str, float]]:
    """The stretch set's target figures (:data:`MOTION_KEYS`) with the lead off and on."""
    from models.evaluation import listening as L

    out = {}
    for lead in (False, True):
        with drift_lead(lead):
            s = L.summary({"stretch": L.stretch_set(lm, cache, songs, opts)})
        out[lead] = {k: s[k] for k in MOTION_KEYS}
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("::")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", default=str(REPO.parent / "shared" / "data"), metavar="DIR",
                   help="the shared data directory holding dwm/ and music/ (default: ../shared/data)")
    p.add_argument("--checkpoint", default=None, metavar="CKPT", help="dance_vq checkpoint (default: the shipped one)")
    p.add_argument("--cache", default=".cache/listening", metavar="DIR", help="audio cache (default .cache/listening)")
    p.add_argument("--seeds", type=int, default=0, metavar="N", help="run the performer over the ramp at seeds 0..N-1")
    p.add_argument("--stretch", action="store_true", help="the follower's wander over the stretch set")
    p.add_argument("--grid", nargs="+", metavar="LEAD,TAU",
                   help="other DRIFT_LEAD,DRIFT_TAU (frames) pairs: the ramp's lag and the wander each adds")
    p.add_argument("--stretch-motion", action="store_true",
                   help="the stretch set's figures (benchmarks/listening.py), lead off and on")
    p.add_argument("--stretch-seeds", type=int, nargs="+", default=None, metavar="SEED",
                   help="--stretch-motion's sampling seeds (default: the benchmark's, 0-5)")
    a = p.parse_args(argv)
    import torch

    from models.evaluation import listening as L
    from models.generate import load_model

    torch.set_num_threads(1)
    data = Path(a.data)
    opts = L.Options(dwm=data / "dwm", music=data / "music", cache_dir=a.cache, progress=False, sets=("ramp",),
                     seeds=tuple(a.stretch_seeds or L.SEEDS))
    lm = load_model(a.checkpoint)
    cache = L.AudioCache(opts.cache_dir)
    songs = L.stretch_songs(cache, opts)
    path, bpm = L.ramp_song(cache, songs, opts)
    y, _ = L.ramp_audio(cache, path, opts)
    print(f"Ramp on {L.song_name(path)} ({bpm:.0f} bpm as recorded), no motion: each stage against the real tempo\n")
    print("| stage | corr, 4-s smoothing | lag (s) | corr, 1-s smoothing | lag (s) |\n| --- | ---: | ---: | ---: | ---: |")
    for name, c4, l4, c1, l1 in stages(lm, y, bpm):
        print(f"| {name} | {c4:.3f} | {l4:.2f} | {c1:.3f} | {l1:.2f} |")
    if a.seeds > 0:
        print(f"\nThe performer over the ramp, seeds 0-{a.seeds - 1} (correlation: mean; lag: median; step: largest)\n")
        print("| lead | speed corr | lag (s) | followed tempo corr | lag (s) | nominal rate lag (s) "
              "| played rate corr | bone step (deg) |\n| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
        each = {}
        for lead in (False, True):
            runs = perform_ramp(lm, y, bpm, a.seeds, lead)["runs"]
            each[lead] = np.array([r["speed"][0] for r in runs])
            m = lambda k, i: float(np.mean([r[k][i] for r in runs]))  # noqa: E731
            med = lambda k: float(np.median([r[k][1] for r in runs]))  # noqa: E731
            print(f"| {'on' if lead else 'off'} | {m('speed', 0):.3f} | {med('speed'):.2f} | {m('follower', 0):.3f} "
                  f"| {med('follower'):.2f} | {med('nominal'):.2f} | {m('played', 0):.3f} "
                  f"| {max(r['step'] for r in runs):.1f} |")
        d = each[True] - each[False]
        print(f"\nspeed correlation, on - off, paired over the seeds: {d.mean():+.3f} "
              f"(standard error {d.std(ddof=1) / math.sqrt(len(d)) if len(d) > 1 else float('nan'):.3f})")
    if a.stretch:
        print("\nThe followed tempo over the stretch set after the first 6 s: its wander (standard deviation "
              "of ln bpm, %), lead off and on\n")
        print("| song | rate | wander off (%) | wander on (%) | median on / off | largest lead (%) |\n"
              "| --- | ---: | ---: | ---: | ---: | ---: |")
        for row in steadiness(lm, cache, songs, opts):
            print("| {} | {} | {:.2f} | {:.2f} | {:.4f} | {:.1f} |".format(*row))
    if a.grid:
        grid = [tuple(float(v) for v in g.split(",")) for g in a.grid]
        print("\n| DRIFT_LEAD | DRIFT_TAU | ramp: followed tempo's lag (s) | wander added, mean (%) | largest (%) |\n"
              "| ---: | ---: | ---: | ---: | ---: |")
        for row in lead_grid(lm, y, bpm, cache, songs, opts, grid):
            print("| {:.0f} | {:.0f} | {:.2f} | {:.2f} | {:.2f} |".format(*row))
    if a.stretch_motion:
        got = stretch_motion(lm, cache, songs, opts)
        print(f"\nThe stretch set (seeds {', '.join(map(str, opts.seeds))}), lead off and on\n\n"
              "| figure | off | on |\n| --- | ---: | ---: |")
        for k in MOTION_KEYS:
            print(f"| {k} | {got[False][k]:.3f} | {got[True][k]:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
