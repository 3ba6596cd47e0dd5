"""The fold's hold at the top of the danced range, off against on, in one run (issue 43).

For every song of the listening benchmark's stretch set (``models.evaluation.listening``:
recordings of 80-130 bpm, a 45-s excerpt at 0.8x, 1.0x and 1.25x) and every seed, the
performance is generated with :data:`models.networks.tempo.FOLD_HOLD` set to 0 (the fold
halves a tempo the moment it reads over 170 bpm) and as shipped. The stream reads nothing
of the follower but its period and confidence, so where the follower's period is the same on
every frame of an excerpt with the hold off and on (:func:`models.networks.tempo.track_periods`,
the stream's own arithmetic, tests/test_tempo.py) the motion is the same and is generated
once; the table says how many excerpts changed. Per song: the frequency centroid, mean joint
speed and dance-band amplitude ratios 1.25x over 0.8x (each the ratio of the means over the
seeds, as ``benchmarks/listening.py``), and the followed tempo's median at each rate.

The amplitude's own rate effect: the 1.0x performance replayed 1.25x and 0.8x as fast (its
joint positions resampled in time, linear) reads a band-amplitude ratio above 1 by itself
(drift under the band's 0.25 Hz moves into it when played faster). ``amp / replay`` divides
the measured 1.25x-over-0.8x ratio by that replay's ratio: a rate-neutral reading beside the
target's (which stays the measured ratio). A second table splits each centroid ratio (hold on)
into the followed tempo's ratio, the playback rate's (what the stream plays) and the chosen
movements' own speed (the choice); the rate as the tempo asks it (within the rate range, faded
with the pulse), under the speed cap, and as played (after the speed matching and the bone cap)
show which step holds it (each the mean over the frames after 3 s). ``--force SONG BPM BPM BPM`` also dances
SONG with the followed tempo fixed at those three tempi (0.8x, 1.0x, 1.25x; the follower's
confidence kept): what a reading would give, without a rule that reads it. ``--jumps`` also
counts, off and on, the followed tempo's jumps of more than half an octave from one frame to
the next (after 6 s) over every whole recording of ``music/`` and every validation dance (as
``performer evaluate`` feeds it), no motion generated. Run::

    nice -n 5 .venv/bin/python benchmarks/studies/tempo_fold.py --data ../shared/data --jobs 2 --jumps \
        --force trance_mechatribe_assault_kommisar 72 90 112.5 --force trance_mechatribe_assault_kommisar 96 120 150 \
        --force trance_mechatribe_assault_kommisar 144 180 225
"""

from __future__ import annotations

import argparse
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402


def replay(pos: np.ndarray, rate: float) -> np.ndarray:
    """Joint positions (T, J, 3) played ``rate`` times as fast: resampled at t * rate (frames), linear."""
    t = np.arange(0.0, len(pos) - 1, rate)
    i = np.floor(t).astype(int)
    f = (t - i)[:, None, None]
    return pos[i] * (1.0 - f) + pos[np.minimum(i + 1, len(pos) - 1)] * f


def _forced(bpm: float):
    """A :class:`~models.networks.tempo.TempoFollower` whose period is ``bpm`` once it hears a pulse."""
    from models.networks.tempo import TempoFollower
    from models.timebase import FPS

    class Forced(TempoFollower):
        __slots__ = ()

        @property
        def period(self) -> float:
            return 60.0 * FPS / bpm if TempoFollower.period.fget(self) > 0.0 else 0.0

    return Forced


def _job(args: tuple) -> tuple:
    """One performance: (song, rate, seed, variant, scores, followed bpm (T,), replay amplitudes)."""
    song, path, start, seconds, rate, seed, variant, hold, data, cache_dir, beats, force = args
    import torch

    import models.networks.dance_stream as ds
    import models.networks.tempo as tempo
    from models.evaluation import listening as L
    from models.generate import load_model

    torch.set_num_threads(1)
    tempo.FOLD_HOLD = hold
    ds.TempoFollower = _forced(force) if force else tempo.TempoFollower
    lm = _job.lm if hasattr(_job, "lm") else load_model(None)
    _job.lm = lm
    cache = L.AudioCache(cache_dir)
    y = cache.excerpt(Path(path), start, seconds, rate)
    trace: dict = {}
    poses, _ = L.perform(lm, y, seed, trace)
    got = L.score_motion(poses, np.asarray(beats))
    skip = int(L.SETTLE_S * L.FPS)
    got["rate"] = float(trace["rate"][skip:].mean())
    got["rate_asked"] = float(trace["rate_asked"][skip:].mean())
    got["rate_capped"] = float(trace["rate_capped"][skip:].mean())
    got["movement_speed"] = float(trace["movement_speed"][skip:].mean())
    rep = {}
    if rate == 1.0:
        pos = L.positions(poses[int(L.SETTLE_S * L.FPS):])
        rep = {f"{r:g}": L.dance_amplitude(replay(pos, r)) for r in L.STRETCH_RATES}
    return song, rate, seed, variant, got, trace["tempo_bpm"].tolist(), rep


def octave_jumps(lm, data: Path, cache, shipped: float) -> dict[str, list[int]]:
    """Per whole recording of ``data/music`` and validation dance: the followed tempo's jumps of over
    half an octave between frames after 6 s, [FOLD_HOLD 0, shipped]; printed as they come."""
    import models.networks.tempo as tempo
    from models.data.corpus import build_corpus
    from models.data.split import VAL_DANCES
    from models.evaluation import listening as L
    from models.features.spectral import extract_features

    cfg = lm.model.config
    items = [(f.stem, extract_features(np.asarray(cache.audio(f), np.float32), lm.features))
             for f in L.music_files(data / "music")]
    items += [(c.name, c.features) for c in build_corpus(data / "dwm", list(VAL_DANCES), lm.features, (1.0,),
                                                          ".cache/corpus", False)]
    got = {}
    for name, f in items:
        got[name] = []
        for hold in (0.0, shipped):
            tempo.FOLD_HOLD = hold
            per = tempo.track_periods(f[:, cfg.clarity_col + 1], f[:, cfg.clarity_col], f[:, cfg.onset_col])
            per = per[int(6 * L.FPS):]
            per = per[per > 0]
            got[name].append(int((np.abs(np.diff(np.log2(per))) > 0.5).sum()))
        tempo.FOLD_HOLD = shipped
        print(f"{name}: octave jumps of the followed tempo, hold off / on: {got[name][0]} / {got[name][1]}")
    tot = np.sum(list(got.values()), axis=0)
    print(f"all {len(got)}: {tot[0]} / {tot[1]}")
    return got


def _row(res: dict, song: str, variant: str, seeds: list[int], L) -> dict:
    """A song's ratios 1.25x over 0.8x (of the means over ``seeds``) for one variant (off's where it is the same)."""
    get = {r: [res.get((song, r, s, variant)) or res[(song, r, s, "off")] for s in seeds] for r in L.STRETCH_RATES}
    keys = ("centroid_hz", "speed", "amp_m", "rate", "rate_asked", "rate_capped", "movement_speed", "hit", "hit_half")
    m = {r: {k: float(np.mean([g[0][k] for g in get[r]])) for k in keys} for r in L.STRETCH_RATES}
    lo, hi = m[L.STRETCH_RATES[0]], m[L.STRETCH_RATES[-1]]
    reps = [g[2] for g in get[1.0]]
    rep = float(np.mean([x["1.25"] for x in reps]) / np.mean([x["0.8"] for x in reps]))
    return {"centroid_ratio": hi["centroid_hz"] / lo["centroid_hz"], "speed_ratio": hi["speed"] / lo["speed"],
            "amp_ratio": hi["amp_m"] / lo["amp_m"], "replay_amp_ratio": rep,
            "movement_speed_ratio": hi["movement_speed"] / lo["movement_speed"],
            "rate": [m[r]["rate"] for r in L.STRETCH_RATES], "rate_asked": [m[r]["rate_asked"] for r in L.STRETCH_RATES],
            "rate_capped": [m[r]["rate_capped"] for r in L.STRETCH_RATES], "hit": [m[r]["hit"] for r in L.STRETCH_RATES],
            "hit_half": [m[r]["hit_half"] for r in L.STRETCH_RATES],
            "centroid_hz": [m[r]["centroid_hz"] for r in L.STRETCH_RATES],
            "bpm": [float(np.median(np.asarray(get[r][0][1])[int(6 * L.FPS):])) for r in L.STRETCH_RATES]}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("Run::")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", default=str(REPO.parent / "shared" / "data"), metavar="DIR",
                   help="the shared data directory holding dwm/ and music/")
    p.add_argument("--cache", default=".cache/listening", metavar="DIR", help="audio cache (default .cache/listening)")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4, 5], metavar="SEED")
    p.add_argument("--jobs", type=int, default=1, help="worker processes (default 1)")
    p.add_argument("--force", nargs=4, action="append", default=[], metavar=("SONG", "BPM_0.8", "BPM_1.0", "BPM_1.25"),
                   help="also dance SONG with the followed tempo fixed at three tempi (0.8x, 1.0x, 1.25x)")
    p.add_argument("--jumps", action="store_true",
                   help="also count the followed tempo's octave jumps over the whole recordings and validation dances")
    p.add_argument("--json", metavar="FILE", help="write every figure here")
    a = p.parse_args(argv)
    data = Path(a.data)
    if not (data / "dwm").is_dir() or not (data / "music").is_dir():
        p.error(f"{data}: needs dwm/ and music/ (--data names the shared data directory)")

    import models.networks.tempo as tempo
    from models.evaluation import listening as L
    from models.features.spectral import extract_features
    from models.generate import load_model

    shipped = tempo.FOLD_HOLD
    lm = load_model(None)
    cfg = lm.model.config
    opts = L.Options(dwm=data / "dwm", music=data / "music", cache_dir=a.cache, progress=False)
    cache = L.AudioCache(a.cache)
    jobs, same = [], {}
    for path, _bpm in L.stretch_songs(cache, opts):
        song = L.song_name(path)
        start, seconds = L._excerpt_window(cache, path, opts)
        for r in L.STRETCH_RATES:
            y = cache.excerpt(path, start, seconds, r)
            f = extract_features(y, lm.features)
            per = []
            for hold in (0.0, shipped):
                tempo.FOLD_HOLD = hold
                per.append(tempo.track_periods(f[:, cfg.clarity_col + 1], f[:, cfg.clarity_col], f[:, cfg.onset_col]))
            tempo.FOLD_HOLD = shipped
            same[(song, r)] = bool(np.array_equal(per[0], per[1]))
            beats = L.reference_beats(cache, path, start, r, len(f)).tolist()
            for seed in a.seeds:
                jobs.append((song, str(path), start, seconds, r, seed, "off", 0.0, a.data, a.cache, beats, 0.0))
                if not same[(song, r)]:
                    jobs.append((song, str(path), start, seconds, r, seed, "on", shipped, a.data, a.cache, beats, 0.0))
                for k, (name, *bpms) in enumerate(a.force):
                    if name == song:
                        jobs.append((song, str(path), start, seconds, r, seed, f"force{k}", shipped, a.data, a.cache,
                                     beats, float(bpms[L.STRETCH_RATES.index(r)])))
    print(f"{len(jobs)} performances; excerpts whose followed tempo the hold changes: "
          + ", ".join(f"{s} {r:g}x" for (s, r), v in same.items() if not v), flush=True)
    res: dict = {}
    with ProcessPoolExecutor(max_workers=max(1, a.jobs)) as ex:
        for song, r, seed, variant, got, bpm, rep in ex.map(_job, jobs):
            res[(song, r, seed, variant)] = (got, bpm, rep)
    songs = list(dict.fromkeys(s for s, _ in same))
    out = {}
    print("| song | centroid ratio off / on | speed ratio off / on | amplitude ratio off / on | replay of 1.0x | "
          "amp / replay (on) | followed bpm 0.8x / 1.0x / 1.25x, off -> on |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | --- |")
    for song in songs:
        row = {v: _row(res, song, v, a.seeds, L) for v in ("off", "on")}
        out[song] = row
        o, n = row["off"], row["on"]
        print(f"| {song} | {o['centroid_ratio']:.2f} / {n['centroid_ratio']:.2f} | {o['speed_ratio']:.2f} / "
              f"{n['speed_ratio']:.2f} | {o['amp_ratio']:.2f} / {n['amp_ratio']:.2f} | {n['replay_amp_ratio']:.2f} | "
              f"{n['amp_ratio'] / n['replay_amp_ratio']:.2f} | "
              + " / ".join(f"{x:.0f}" for x in o["bpm"]) + " -> " + " / ".join(f"{x:.0f}" for x in n["bpm"]) + " |")
    print()
    print("| song (hold on) | followed tempo ratio | rate asked 0.8x / 1.25x | under the speed cap | "
          "playback rate (ratio) | chosen movements' own speed ratio | centroid ratio |")
    print("| --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    for song in songs:
        n = out[song]["on"]
        print(f"| {song} | {n['bpm'][-1] / n['bpm'][0]:.2f} | {n['rate_asked'][0]:.2f} / {n['rate_asked'][-1]:.2f} | "
              f"{n['rate_capped'][0]:.2f} / {n['rate_capped'][-1]:.2f} | {n['rate'][0]:.2f} / {n['rate'][-1]:.2f} "
              f"({n['rate'][-1] / n['rate'][0]:.2f}) | {n['movement_speed_ratio']:.2f} | {n['centroid_ratio']:.2f} |")
    for k, (name, *bpms) in enumerate(a.force):
        if name not in out:
            print(f"--force {name}: not in the stretch set")
            continue
        f = _row(res, name, f"force{k}", a.seeds, L)
        out[name][f"force {' '.join(bpms)}"] = f
        print(f"{name} danced at {' / '.join(bpms)} bpm: centroid ratio {f['centroid_ratio']:.2f}, speed ratio "
              f"{f['speed_ratio']:.2f}, amplitude ratio {f['amp_ratio']:.2f}, playback rate {f['rate'][0]:.2f} / "
              f"{f['rate'][-1]:.2f}, beat hit at 0.8x {f['hit'][0]:.2f} (half-shifted {f['hit_half'][0]:.2f})")
    for v in ("off", "on"):
        c = [out[s][v]["centroid_ratio"] for s in songs]
        sp = [out[s][v]["speed_ratio"] for s in songs]
        am = [out[s][v]["amp_ratio"] for s in songs]
        print(f"{v}: centroid ratio mean {np.mean(c):.2f} (least {min(c):.2f}), speed ratio mean {np.mean(sp):.2f} "
              f"(least {min(sp):.2f}), amplitude ratio {min(am):.2f}-{max(am):.2f}, "
              f"songs within 0.8-1.2: {sum(0.8 <= x <= 1.2 for x in am)} of {len(am)}")
    if a.jumps:
        out["_jumps"] = octave_jumps(lm, data, cache, shipped)
    if a.json:
        Path(a.json).write_text(json.dumps({"seeds": a.seeds, "changed": [f"{s} {r:g}" for (s, r), v in same.items()
                                                                         if not v], "songs": out}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
