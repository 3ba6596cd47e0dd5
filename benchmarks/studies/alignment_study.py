"""How do the DWM mocap frames map onto audio time?  A rhythm study.

Each timing hypothesis maps mocap frame ``i`` (of ``N``) to an audio time ``t_i``
(``S``, ``E``: config.json music frames at 25 fps):

- ``H1-span``:   the N frames span ``[S/25, E/25]`` evenly (rate ``(N-1)*25/(E-S)``);
- ``H1-dedup``:  as H1 after deleting exact-repeat frames (frozen runs);
- ``H2-25@S``:   25 fps from ``S/25``;
- ``H3-25@0``:   25 fps from audio time 0;
- ``H4-6.25@S``: 6.25 fps (25/4) from ``S/25``: a lower fixed rate for Waltz.

Tests, per dance (music: ``librosa.beat.beat_track`` on the song; motion: summed
joint speed of the world positions):

1. Metre test (rate).  The motion's dominant period ``P`` (frames) comes from the
   autocorrelation of the speed.  Under a hypothesis of rate ``r`` it lasts ``P/r``
   seconds; a dance keeps time with its music when that is a metrical multiple
   ``m`` of the beat period ``T_b`` (``m`` in 1/2, 1, 3/2, 2, 3, 4, 6, 8, 12, which also
   absorbs beat-tracker octave errors).  ``err`` = relative distance to the nearest
   multiple; a *match* is ``|err| < 3 %``.  Chance level: the probability that a
   random period ratio (log-uniform over 0.35..14 beats) matches, about 0.15.
2. Locking (fine rate).  ``lock`` = strength of the speed component locked to the
   music's beat grid at ``1/m`` cycles per beat (1 = pure beat-locked sinusoid,
   about 0.05 for unrelated signals).  Scanned over rates 0.85..1.15 x the H1 rate
   (at the metrical level ``m`` of H1's metre test), its peak gives the rate at which
   motion and music keep time.  H1 is *verified* for a dance when it passes the
   metre test or that peak lies within 2.5 % of the H1 rate, *unverified* otherwise.
3. Offset scan (phase).  Beat-alignment score ``BAS`` (AIST++/Bailando style: mean
   over kinematic beats -- local minima of the speed, half window 0.167 s -- of
   ``exp(-d^2 / (2 * 0.1^2))``, ``d`` the distance to the nearest music beat) for
   offsets ``-0.5..0.5`` s added to ``t_i``; null: the beats of another song.

Run (about 1.5 minutes on 2 cores; audio features are cached under OUT/cache)::

    .venv/bin/python benchmarks/studies/alignment_study.py --data ../shared/data/dwm --out /tmp/alignment_study

Writes ``OUT/alignment_study.json`` (everything), ``OUT/alignment_study.md`` (the
tables in docs/data.md) and ``OUT/alignment_study.png``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from models.data.alignment import held_frames  # noqa: E402
from models.data.dwm import CONFIG_FPS, Dance, load_dataset  # noqa: E402

SR = 22050
ONSET_HOP = 256  # 11.6 ms onset frames
GRID_HZ = 100.0  # kinematic signal resolution after spline upsampling
MIN_ORDER_S = 0.167  # local-minimum half window (10 frames at 60 fps, as in AIST++)
SIGMA_S = 0.1  # BAS tolerance (s)
METRE = np.array([0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0])  # motion period / beat period
MATCH_TOL = 0.03
OFFSETS = np.round(np.arange(-0.5, 0.5001, 0.02), 3)
RATE_FACTORS = np.round(np.arange(0.85, 1.15001, 0.001), 4)
VERIFY_TOL = 0.025  # H1 is verified for a dance when the fitted rate is within 2.5 % of it
HYPOTHESES = ("H1-span", "H1-dedup", "H2-25@S", "H3-25@0", "H4-6.25@S")


# ----------------------------------------------------------------------------- music
def music_features(audio_path: Path, cache: Path) -> dict[str, np.ndarray]:
    """Beat times (s), tracker tempo (BPM) and duration (s), cached as .npz."""
    if cache.is_file():
        z = np.load(cache)
        return {k: z[k] for k in z.files}
    import librosa
    import soundfile as sf
    from scipy.signal import resample_poly

    y, sr = sf.read(str(audio_path), dtype="float32", always_2d=True)
    y = y.mean(axis=1)
    y = resample_poly(y, 1, 2).astype(np.float32) if sr == 2 * SR else librosa.resample(y, orig_sr=sr, target_sr=SR)
    env = librosa.onset.onset_strength(y=y, sr=SR, hop_length=ONSET_HOP)
    tempo, beats = librosa.beat.beat_track(onset_envelope=env, sr=SR, hop_length=ONSET_HOP, units="time")
    out = {
        "beats": np.asarray(beats, dtype=np.float64),
        "tempo": np.atleast_1d(np.asarray(tempo, dtype=np.float64)),
        "duration": np.array([len(y) / SR]),
    }
    cache.parent.mkdir(parents=True, exist_ok=True)
    np.savez(cache, **out)
    return out


def beat_period(beats: np.ndarray, t0: float, t1: float) -> float:
    """Median inter-beat interval (s) of the beats inside [t0, t1] (all beats if too few)."""
    inside = beats[(beats >= t0) & (beats <= t1)]
    return float(np.median(np.diff(inside if len(inside) > 8 else beats)))


# ---------------------------------------------------------------------------- motion
def speed(positions: np.ndarray) -> np.ndarray:
    """(N,) summed joint speed in metres per frame (central differences)."""
    return np.linalg.norm(np.gradient(positions, axis=0), axis=2).sum(axis=1)


def motion_period(x: np.ndarray, lags: tuple[int, int] = (8, 40)) -> float:
    """Dominant period (frames, fractional) of a 1-D signal.

    Among the autocorrelation peaks with lag in ``lags`` (prominence >= 0.02), the
    fundamental is the shortest one at least half as high as the highest.  It is
    refined to 0.01 frame by maximising the cubic-interpolated autocorrelation
    summed over its first four multiples (a comb, which averages out jitter).
    """
    from scipy.interpolate import CubicSpline
    from scipy.signal import find_peaks

    x = x - x.mean()
    n = len(x)
    raw = np.correlate(x, x, "full")[n - 1 :] / (x @ x)
    peaks, _ = find_peaks(raw[: lags[1] + 2], prominence=0.02)
    peaks = peaks[(peaks >= lags[0]) & (peaks <= lags[1])]
    if len(peaks) == 0:
        return float("nan")
    h = raw[peaks]
    lag0 = int(peaks[int(np.argmax(h >= 0.5 * h.max()))])
    q = np.arange(1, 1 + max(1, min(4, (n // 3) // lag0)))
    cand = np.arange(lag0 - 1.0, lag0 + 1.0, 0.01)
    comb = CubicSpline(np.arange(n), raw)(cand[:, None] * q[None, :]).sum(axis=1)
    return float(cand[int(np.argmax(comb))])


def kinematic_beats(positions: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Kinematic beats (s): local minima of summed joint speed of (N, J, 3) positions at ``times``.

    The trajectory is spline-interpolated onto a ``GRID_HZ`` grid first, so the
    minima window (``MIN_ORDER_S``) means the same in every hypothesis.
    """
    from scipy.interpolate import CubicSpline
    from scipy.signal import argrelextrema

    grid = np.arange(times[0], times[-1], 1.0 / GRID_HZ)
    pos = CubicSpline(times, positions.reshape(len(times), -1), axis=0)(grid)
    sp = np.linalg.norm(np.gradient(pos, axis=0).reshape(len(grid), -1, 3), axis=2).sum(axis=1)
    return grid[argrelextrema(sp, np.less, order=max(1, int(round(MIN_ORDER_S * GRID_HZ))))[0]]


# -------------------------------------------------------------------------- measures
def metre_err(period_s: float, beat_s: float) -> tuple[float, float]:
    """(nearest metrical multiple m, relative error of period_s vs m * beat_s)."""
    rho = period_s / beat_s
    m = float(METRE[int(np.argmin(np.abs(np.log(rho / METRE))))])
    return m, float(rho / m - 1.0)


def chance_match_rate() -> float:
    """Probability that a period with a random ratio to the beat (log-uniform over
    0.35..14 beats) lies within MATCH_TOL of a metrical multiple: the chance level of
    the metre test."""
    rho = np.exp(np.linspace(np.log(0.35), np.log(14.0), 20001))
    m = METRE[np.argmin(np.abs(np.log(rho[:, None] / METRE[None, :])), axis=1)]
    return float(np.mean(np.abs(rho / m - 1.0) < MATCH_TOL))


def lock(times: np.ndarray, x: np.ndarray, beats: np.ndarray, cycles_per_beat: float) -> float:
    """Beat-locked strength of signal ``x`` sampled at ``times`` (s).

    ``sqrt(2) |mean(x' exp(2 pi i k b(t)))| / std(x')`` with ``x'`` = x minus its mean and
    ``b(t)`` the fractional beat index interpolated between tracked beats: 1 for a
    sinusoid at ``k`` cycles per beat locked to the grid, ~sqrt(2/n) for noise.
    """
    m = (times >= beats[0]) & (times <= beats[-1])
    if m.sum() < 16:
        return float("nan")
    b = np.interp(times[m], beats, np.arange(len(beats)))
    xx = x[m] - x[m].mean()
    return float(np.sqrt(2) * np.abs(np.mean(xx * np.exp(2j * np.pi * cycles_per_beat * b))) / xx.std())


def bas(kin: np.ndarray, beats: np.ndarray, sigma: float = SIGMA_S) -> float:
    """Mean over kinematic beats of exp(-d^2 / 2 sigma^2), d = distance (s) to the nearest music beat."""
    kin = kin[(kin >= beats[0]) & (kin <= beats[-1])]
    if len(kin) == 0:
        return float("nan")
    j = np.clip(np.searchsorted(beats, kin), 1, len(beats) - 1)
    d = np.minimum(np.abs(kin - beats[j - 1]), np.abs(beats[j] - kin))
    return float(np.mean(np.exp(-(d**2) / (2 * sigma**2))))


# ------------------------------------------------------------------------ hypotheses
def hypotheses(dance: Dance) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """name -> (frame mask, audio time in s of each kept frame)."""
    n, s, e = dance.num_frames, dance.start_frame, dance.end_frame
    i = np.arange(n, dtype=np.float64)
    allf = np.ones(n, dtype=bool)
    keep = ~held_frames(dance)
    k = int(keep.sum())
    return {
        "H1-span": (allf, (s + i * (e - s) / (n - 1)) / CONFIG_FPS),
        "H1-dedup": (keep, (s + np.arange(k) * (e - s) / (k - 1)) / CONFIG_FPS),
        "H2-25@S": (allf, s / CONFIG_FPS + i / 25.0),
        "H3-25@0": (allf, i / 25.0),
        "H4-6.25@S": (allf, s / CONFIG_FPS + i / 6.25),
    }


def study_dance(dance: Dance, feats: dict, others: list[dict]) -> dict:
    """All measures for one dance; ``others``: music features of the other songs of its style."""
    pos = dance.world_positions_m()
    x = speed(pos)
    beats = feats["beats"]
    t0, t1 = dance.start_seconds, dance.end_seconds
    tb = beat_period(beats, t0, t1)
    p = motion_period(x)
    p_dedup = motion_period(speed(pos[~held_frames(dance)]))
    out: dict = {
        "name": dance.name, "style": dance.style, "N": dance.num_frames, "S": dance.start_frame,
        "E": dance.end_frame, "held_frames": int(held_frames(dance).sum()),
        "tempo_bpm": float(feats["tempo"][0]), "beat_s": tb, "audio_s": float(feats["duration"][0]),
        "motion_period_frames": p, "hyp": {},
    }
    for name, (mask, t) in hypotheses(dance).items():
        rate = (len(t) - 1) / (t[-1] - t[0])
        period = (p_dedup if name == "H1-dedup" else p) / rate
        m, err = metre_err(period, tb)
        kin = kinematic_beats(pos[mask], t)
        curve = [bas(kin + d, beats) for d in OFFSETS]
        null_curve = np.nanmean([[bas(kin + d, o["beats"]) for d in OFFSETS] for o in others[:3]], axis=0)
        out["hyp"][name] = {
            "rate_fps": rate,
            "metre": m,
            "err": err,
            "lock": lock(t, x[mask], beats, 1.0 / m),
            "null_lock": float(np.nanmean([lock(t, x[mask], o["beats"], 1.0 / m) for o in others[:3]])),
            "bas_curve": curve,
            "bas_0": curve[len(OFFSETS) // 2],
            "bas_best": float(np.nanmax(curve)),
            "best_offset_s": float(OFFSETS[int(np.nanargmax(curve))]),
            "null_bas_best": float(np.nanmax(null_curve)),
            "end_s": float(t[-1]),
        }
    # Fine rate: where does the motion lock to the beat grid, around the H1 rate,
    # at the metrical level the metre test found for H1?
    i = np.arange(dance.num_frames)
    k = 1.0 / out["hyp"]["H1-span"]["metre"]
    scan = [lock(t0 + i * (t1 - t0) / (dance.num_frames - 1) / f, x, beats, k) for f in RATE_FACTORS]
    j = int(np.nanargmax(scan))
    out["fit"] = {
        "cycles_per_beat": k,
        "rate_factor": float(RATE_FACTORS[j]),
        "lock": float(scan[j]),
        "lock_at_h1": float(scan[int(np.argmin(np.abs(RATE_FACTORS - 1.0)))]),
        "scan": scan,
        "verified": bool(abs(RATE_FACTORS[j] - 1.0) <= VERIFY_TOL or abs(out["hyp"]["H1-span"]["err"]) < MATCH_TOL),
    }
    return out


# ------------------------------------------------------------------------- summaries
def summarize(results: list[dict]) -> dict:
    summary: dict = {}
    for style in "CRW":
        rs = [r for r in results if r["style"] == style]
        per = {}
        for h in HYPOTHESES:
            v = {k: np.array([r["hyp"][h][k] for r in rs], dtype=float) for k in ("err", "lock", "null_lock", "bas_0", "bas_best", "null_bas_best", "best_offset_s")}
            per[h] = {
                "matches": int(np.sum(np.abs(v["err"]) < MATCH_TOL)),
                "expected_by_chance": chance_match_rate() * len(rs),
                "median_abs_err": float(np.median(np.abs(v["err"]))),
                "lock": float(np.mean(v["lock"])),
                "null_lock": float(np.mean(v["null_lock"])),
                "bas_0": float(np.mean(v["bas_0"])),
                "bas_best": float(np.mean(v["bas_best"])),
                "null_bas_best": float(np.mean(v["null_bas_best"])),
                "best_offset_mean_s": float(np.mean(v["best_offset_s"])),
                "best_offset_sd_s": float(np.std(v["best_offset_s"])),
                "bas_curve": np.nanmean([r["hyp"][h]["bas_curve"] for r in rs], axis=0).tolist(),
                "past_audio_end": int(sum(r["hyp"][h]["end_s"] > r["audio_s"] for r in rs)),
            }
        ok = [r for r in rs if r["fit"]["verified"]]
        fac = np.array([r["fit"]["rate_factor"] for r in ok])
        summary[style] = {
            "dances": len(rs),
            "hyp": per,
            "h1_fit_rate_factor_median": float(np.median(fac)) if len(ok) else float("nan"),
            "h1_fit_rate_factor_range": [float(fac.min()), float(fac.max())] if len(ok) else [],
            "h1_verified": len(ok),
            "h1_unverified": {r["name"]: r["fit"]["rate_factor"] for r in rs if not r["fit"]["verified"]},
        }
    return summary


def markdown(results: list[dict], summary: dict) -> str:
    lines = [
        "| style | hypothesis | metre matches (chance) | median abs err | lock (null) | BAS at 0 s | best BAS in ±0.5 s (null) | best offset s | ends after the song |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for style, s in summary.items():
        for h, v in s["hyp"].items():
            lines.append(
                f"| {style} ({s['dances']}) | {h} | {v['matches']} ({v['expected_by_chance']:.1f}) | "
                f"{100 * v['median_abs_err']:.1f} % | {v['lock']:.2f} ({v['null_lock']:.2f}) | {v['bas_0']:.2f} | "
                f"{v['bas_best']:.2f} ({v['null_bas_best']:.2f}) | {v['best_offset_mean_s']:+.2f} ± {v['best_offset_sd_s']:.2f} | "
                f"{v['past_audio_end']} |"
            )
    lines += [
        "",
        "| dance | N | E−S | held | P (frames) | beat s | H1 fps | H1 metre, err | H2 metre, err | H4 metre, err | lock at H1 | fitted rate / H1 (lock) | H1 |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        h = r["hyp"]
        cell = lambda k: f"{h[k]['metre']:g}, {100 * h[k]['err']:+.1f} %"  # noqa: E731
        lines.append(
            f"| {r['name']} | {r['N']} | {r['E'] - r['S']} | {r['held_frames']} | {r['motion_period_frames']:.2f} | "
            f"{r['beat_s']:.3f} | {h['H1-span']['rate_fps']:.2f} | {cell('H1-span')} | {cell('H2-25@S')} | "
            f"{cell('H4-6.25@S')} | {r['fit']['lock_at_h1']:.2f} | {r['fit']['rate_factor']:.3f} ({r['fit']['lock']:.2f}) | "
            f"{'verified' if r['fit']['verified'] else '**unverified**'} |"
        )
    return "\n".join(lines) + "\n"


def plot(results: list[dict], summary: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 4), dpi=65)
    ax = axes[0]
    tb = np.linspace(0.3, 0.75, 10)
    for m in (2, 3, 4, 6):
        ax.plot(tb, m * tb, color="0.85", lw=1)
        ax.text(0.75, m * 0.75, f"{m} beats", fontsize=7, color="0.5")
    for h, mk in (("H1-span", "o"), ("H2-25@S", "x")):
        for style, col in zip("CRW", ("C0", "C1", "C2")):
            rs = [r for r in results if r["style"] == style]
            ax.scatter([r["beat_s"] for r in rs], [r["motion_period_frames"] / r["hyp"][h]["rate_fps"] for r in rs],
                       marker=mk, color=col, s=14, label=f"{style} {h}")
    ax.set_xlabel("music beat period (s)")
    ax.set_ylabel("motion period (s) under the hypothesis")
    ax.set_yscale("log")
    ax.legend(fontsize=6, ncol=2)
    ax.set_title("motion period vs beat period")
    ax = axes[1]
    for style in "CRW":
        for h in ("H1-span", "H2-25@S", "H3-25@0"):
            ax.plot(OFFSETS, summary[style]["hyp"][h]["bas_curve"], label=f"{style} {h}")
    ax.set_xlabel("offset added to frame times (s)")
    ax.set_ylabel("BAS (mean over dances)")
    ax.set_ylim(0.3, 0.7)
    ax.legend(fontsize=6)
    ax.set_title("beat alignment vs offset")
    ax = axes[2]
    for style in "CRW":
        rs = [r for r in results if r["style"] == style]
        ax.plot(RATE_FACTORS, np.nanmean([r["fit"]["scan"] for r in rs], axis=0), label=f"{style} (all {len(rs)})")
    ax.set_ylim(bottom=0)
    ax.axvline(1.0, color="0.6", lw=0.8)
    ax.set_xlabel("rate / H1 rate")
    ax.set_ylabel("beat lock (mean)")
    ax.legend(fontsize=7)
    ax.set_title("beat lock vs frame rate")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True, type=Path, help="the dwm directory")
    ap.add_argument("--out", required=True, type=Path, help="output directory (cache, JSON, markdown, PNG)")
    args = ap.parse_args(argv)

    dances = load_dataset(args.data)
    args.out.mkdir(parents=True, exist_ok=True)
    feats = {d.name: music_features(d.audio_path, args.out / "cache" / f"{d.name}.npz") for d in dances}
    results = []
    for d in dances:
        others = [feats[o.name] for o in dances if o.style == d.style and o.name != d.name]
        results.append(study_dance(d, feats[d.name], others))
        h = results[-1]["hyp"]
        print(d.name, {k: f"m={v['metre']:g} err={100 * v['err']:+.1f}%" for k, v in h.items() if k in ("H1-span", "H2-25@S")}, flush=True)
    summary = summarize(results)
    (args.out / "alignment_study.json").write_text(json.dumps({"dances": results, "summary": summary}, indent=1))
    md = markdown(results, summary)
    (args.out / "alignment_study.md").write_text(md)
    plot(results, summary, args.out / "alignment_study.png")
    print(md)
    for style, s in summary.items():
        print(f"{style}: H1 verified for {s['h1_verified']}/{s['dances']}, fitted rate / H1 median "
              f"{s['h1_fit_rate_factor_median']:.3f} range {s['h1_fit_rate_factor_range']}; unverified {s['h1_unverified']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
