"""Does speech's 4-Hz modulation tell hosts and crowds from music (issue 43, from a stream's start)?

The classic speech/music discriminators (Scheirer & Slaney 1997) rely most on the **4-Hz modulation energy**:
each band's energy modulated at speech's syllable rate (3-6 Hz), over about 1 s, relative to the band's
mean. The idle gate's presence networks (models/networks/music_gate.py) have no such statistic. This
study computes three causal versions at 30 fps on the idle gate study's material
(benchmarks/studies/idle_gate.py) and prints their distribution per class:

* ``mel``: each of the feature extractor's log-mel bands (dB, 128 bands) band-passed at 3-6 Hz (a
  causal 2nd-order Butterworth band-pass at 30 fps), squared, averaged over the bands, its exponential
  mean over :data:`TAU` frames (1 s; ``--tau``), 10 log10 (dB^2 in dB). In dB the band's mean is already out:
  the figure is the modulation depth. Not in the feature frame today (it would take a new column);
* ``mfcc``: the same on the frame's 13 MFCCs (the orthonormal DCT of the log-mel: the sum over the
  coefficients is the sum over the bands of the smoothed spectrum's modulation), divided by 128 bands;
* ``energy``: the same on the frame's log energy column (dB) alone;
* ``*_share``: the 3-6 Hz energy over the whole modulation above 1 Hz (a 1-Hz causal high-pass), the same
  means: syllable rate against any other (a beat at 2 Hz, 16th notes at 8).

Classes (frames above the model's silence threshold, from 1 s in; ``start``: 1-3 s, a stream's start):
the hosts (:data:`idle_gate.LEADIN_HOSTS` espeak-ng hosts) and the noises of ``--parts leadin`` at its
nine draws, the shared readers, the shared and validation recordings whole, the shared recordings with
the readers over them at 0 and -6 dB, and :data:`idle_gate.ESPEAK_SONGS` training songs' first 30 s with
an espeak-ng host over them at 0 and -6 dB (``--parts espeak``'s "from its start"). Then the gate's own
false starts (the frames of the hosts and noises its shipped networks do not hold fully idle) against
music's 90th / 95th percentile, and the separation each version adds to the networks' first 12 statistics
(the dancing time constant): a logistic regression and the networks' own fit (``fit_network``: 16 tanh, ``--fit-seeds``) on
the 12 and on the 12 plus it, fitted on draws 0-3 and judged on draws 4-8 and the study's draw (the music
and mixes split by recording): AUC and the share of each class's frames above the threshold that keeps
98 % of the music frames; and the share of each version's variance the 12 explain (linear). ``--tau``: the
modulation's time constant (frames); ``--cache``: keep the cases' figures (the tables again in seconds).

    PYTHONPATH=. .venv/bin/python benchmarks/studies/modulation.py --data ../shared/data/dwm --fit-seeds 4
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import idle_gate as ig  # noqa: E402

#: Exponential mean time constant (frames) of the modulation energy (1 s).
TAU: float = 30.0
#: Syllable-rate band (Hz).
BAND: tuple[float, float] = (3.0, 6.0)
#: High-pass (Hz) of the whole modulation the share divides by.
LOW_HZ: float = 1.0
#: Floor (dB) of each log-mel band (the extractor's is -100 dB: a silent band's steps would be modulation).
MEL_FLOOR_DB: float = -80.0
VERSIONS: tuple[str, ...] = ("mel", "mfcc", "energy", "mel_share", "mfcc_share")


def modulation(tracks: np.ndarray, sound: np.ndarray, tau: float = TAU) -> tuple[np.ndarray, np.ndarray]:
    """Causal 4-Hz modulation of ``tracks`` (T, B) (dB trajectories at 30 fps) over the sounding frames
    ``sound`` (T,) bool (held through silence, as the gate's statistics): (energy (T,): 10 log10 of the
    band-mean exponential mean (time constant ``tau`` frames) of the squared 3-6 Hz band-pass; share (T,): that over the same of the
    1-Hz high-pass)."""
    from scipy.signal import butter, lfilter

    idx = np.maximum.accumulate(np.where(sound, np.arange(len(sound)), -1))  # the last sounding frame
    if not sound.any():
        return np.full(len(sound), -60.0), np.zeros(len(sound))
    e, s = _modulation(tracks[sound], tau)
    e = np.r_[e[0], e][np.searchsorted(np.flatnonzero(sound), idx, side="left") + (idx >= 0)]
    s = np.r_[s[0], s][np.searchsorted(np.flatnonzero(sound), idx, side="left") + (idx >= 0)]
    return e, s


def _modulation(tracks: np.ndarray, tau: float) -> tuple[np.ndarray, np.ndarray]:
    from scipy.signal import butter, lfilter

    b, a = butter(1, BAND, btype="band", fs=30.0)
    bh, ah = butter(2, LOW_HZ, btype="high", fs=30.0)
    x = tracks - tracks[:1]  # no step at the stream's start
    bp = lfilter(b, a, x, axis=0) ** 2
    hp = lfilter(bh, ah, x, axis=0) ** 2
    k = math.exp(-1.0 / tau)
    e_bp = lfilter([1 - k], [1, -k], bp.mean(1))
    e_hp = lfilter([1 - k], [1, -k], hp.mean(1))
    return 10 * np.log10(e_bp + 1e-6), e_bp / (e_hp + 1e-6)


def case_stats(lm, audio: np.ndarray, tau: float = TAU) -> dict[str, np.ndarray]:
    """Per frame: the versions (:data:`VERSIONS`), the 12 statistics at the dancing time constant, the log
    energy and whether the frame sounds (above the model's silence threshold)."""
    from models.features.spectral import SpectralKernel, causal_frames, extract_features
    from models.networks import music_gate as mg

    feats = extract_features(audio, lm.features)
    kern = SpectralKernel(lm.features)
    frames = causal_frames(audio, lm.features.n_fft)
    logmel = np.concatenate([__import__("models.features.spectral", fromlist=["_log_mel"])._log_mel(
        kern.spectrum(frames[i: i + 512]), kern.mel_lo, kern.mel_w, lm.features.amin) for i in range(0, len(frames), 512)])
    m = lm.model
    sound = feats[:, 13] > float(m.gate[0])
    mel, mel_s = modulation(np.maximum(logmel, MEL_FLOOR_DB), sound, tau)
    mf, mf_s = modulation(feats[:, :13].astype(np.float64), sound, tau)
    en, _ = modulation(np.maximum(feats[:, 13:14].astype(np.float64), float(m.gate[0])), sound, tau)
    stats = mg.stats_trace(feats, m.feat_mean.numpy(), m.feat_std.numpy(), m.config.clarity_col, m.config.gate_tau,
                           m.config.gate_col)[:, :12]
    w = ig.new_stream(lm, 7).listen(feats)  # the gate as the study runs it: idle weight, 1 fully idle
    return {"mel": mel, "mfcc": mf - 10 * np.log10(128), "energy": en, "mel_share": mel_s, "mfcc_share": mf_s,
            "stats": stats, "sound": sound, "idle_w": w}


def fit_tanh(x: np.ndarray, y: np.ndarray, seed: int = 0):
    """The networks' own fit (:func:`models.training.music_gate.fit_network`, music frames weighted as the shipped
    fit's) on any number of statistics ``x`` (N, S), labels ``y`` (N,) bool: a function from statistics (M, S) to
    logits (M,)."""
    from models.networks.music_gate import HIDDEN
    from models.training.music_gate import STEADY_MUSIC_WEIGHT, fit_network

    p = fit_network(x, y.astype(np.float32), seed, music_weight=STEADY_MUSIC_WEIGHT).astype(np.float64)
    s, h = x.shape[1], HIDDEN
    mean, std, w1 = p[:s], p[s: 2 * s], p[2 * s: 2 * s + h * s].reshape(h, s)
    b1, w2, b2 = p[2 * s + h * s: 2 * s + h * s + h], p[2 * s + h * s + h: -1], p[-1]
    return lambda z: np.tanh(((z - mean) / np.maximum(std, 1e-6)) @ w1.T + b1) @ w2 + b2


def auc(pos: np.ndarray, neg: np.ndarray) -> float:
    """P(a positive scores above a negative): the ranks' AUC."""
    from scipy.stats import rankdata

    r = rankdata(np.r_[pos, neg])
    return float((r[: len(pos)].sum() - len(pos) * (len(pos) + 1) / 2) / (len(pos) * len(neg)))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--checkpoint", default="models/assets/default.pt", help="a dance_vq checkpoint (its features)")
    p.add_argument("--data", required=True, type=Path, help="the DWM dataset directory")
    p.add_argument("--music", type=Path, default=Path("../shared/data/music"))
    p.add_argument("--speech", type=Path, default=Path("../shared/data/speech"))
    p.add_argument("--draws", type=int, default=ig.LEADIN_DRAWS, help="other draws of the hosts and noises (0..N-1)")
    p.add_argument("--tau", type=float, default=TAU, help=f"the modulation energy's time constant, frames (default {TAU:g})")
    p.add_argument("--fit-seeds", type=int, default=1, help="seeds of the networks' own fit, 0 to N-1 (default 1)")
    p.add_argument("--cache", type=Path, help="a pickle of the cases' statistics: read if it exists, else written")
    args = p.parse_args(argv)
    if args.cache and args.cache.exists():
        import pickle

        return report(pickle.loads(args.cache.read_bytes()), args.fit_seeds)

    from models.data.dwm import load_dance
    from models.features.audio_io import load_audio
    from models.generate import load_model
    from models.training import music_gate as tmg

    lm = load_model(args.checkpoint)
    speech = [(f.name, load_audio(f, ig.SR)[0]) for f in sorted(args.speech.glob("*.ogg"))]
    shared = [(f.name, load_audio(f, ig.SR)[0]) for f in sorted(args.music.glob("*.ogg"))]
    val = [(n, load_audio(load_dance(args.data / n).audio_path, ig.SR)[0]) for n in ig.VAL_DANCES]
    cases: list[tuple[str, str, int, dict]] = []  # (class, name, split 0 fit / 1 judge, stats)

    def add(cls: str, name: str, split: int, x: np.ndarray) -> None:
        cases.append((cls, name, split, case_stats(lm, x.astype(np.float32), args.tau)))

    for k in list(range(args.draws)) + [ig.LEADIN_SEED]:
        for name, x in ig.leadin_audio(speech if k == ig.LEADIN_SEED else [], k):
            cls = ("host" if name.startswith("espeak") else "reader" if name.startswith("librispeech")
                   else name.split()[0])
            add(cls, f"{name}/{k}", int(k >= 4), x)
    for i, (name, x) in enumerate(shared + val):
        add("music", name, i % 2, x)
    talk = np.concatenate([s for _, s in speech])
    for i, (name, x) in enumerate(shared):
        for db in ig.MIX_DB:
            add(f"readers over music {db:g} dB", f"{name}@{db:g}", i % 2, ig.with_speech(x, talk, db, len(x) // ig.HOP))
    rng = np.random.default_rng(ig.ESPEAK_SEED)
    names = tmg.training_songs(args.data)
    pick = [names[i] for i in rng.choice(len(names), ig.ESPEAK_SONGS, replace=False)]
    songs = tmg.song_audio(args.data, pick)
    pool = [tmg.utterance(rng) for _ in range(30)]
    for i, (name, song) in enumerate(zip(pick, songs)):
        talk_h = tmg.speech(70.0, rng, pool)
        a0 = song[: 30 * ig.SR][: 30 * ig.SR // ig.HOP * ig.HOP]
        for db in ig.MIX_DB:
            add(f"host over a song's start {db:g} dB", f"{name}@{db:g}", i % 2, ig.with_speech(a0, talk_h, db, len(a0) // ig.HOP))
        add("song's start alone", name, i % 2, a0)

    if args.cache:
        import pickle

        args.cache.write_bytes(pickle.dumps(cases))
    return report(cases, args.fit_seeds)


def report(cases: list, fit_seeds: int = 1) -> int:
    """Print the tables of :func:`main` for ``cases`` ((class, name, split, statistics) tuples); the networks' own
    fit at seeds 0 to ``fit_seeds`` - 1."""
    classes = list(dict.fromkeys(c for c, *_ in cases))

    def pool_of(cls: str, v: str, lo: int = 30, hi: int | None = None, split: int | None = None) -> np.ndarray:
        out = [s[v][lo:hi][s["sound"][lo:hi]] for c, _, sp, s in cases if c == cls and (split is None or sp == split)]
        return np.concatenate(out) if out else np.zeros(0)

    for v in VERSIONS:
        print(f"\n### {v}: percentiles 5 / 25 / 50 / 75 / 95 of the frames from 1 s in; at 1-3 s (a stream's start) the median")
        print("| class | frames | p5 | p25 | p50 | p75 | p95 | 1-3 s p50 |\n| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
        for cls in classes:
            x, st = pool_of(cls, v), pool_of(cls, v, 30, 90)
            q = np.percentile(x, [5, 25, 50, 75, 95])
            print(f"| {cls} | {len(x)} | " + " | ".join(f"{e:.2f}" for e in q) + f" | {np.median(st):.2f} |")
        mus = np.r_[pool_of("music", v), pool_of("song's start alone", v)]
        voiced = np.r_[pool_of("readers over music 0 dB", v), pool_of("host over a song's start 0 dB", v)]
        print(f"AUC (the class above music, music = the recordings and the songs' starts; speech-like high): "
              + ", ".join(f"{c} {auc(pool_of(c, v), mus):.3f}" for c in classes if c not in ("music", "song's start alone"))
              + f"; host vs voiced music at 0 dB {auc(pool_of('host', v), voiced):.3f}")

    # What each version adds to the 12 statistics: logistic regression, fit on split 0, judged on split 1.
    print("\n### the false starts: frames of the hosts and noises the gate does not hold fully idle, and the share of "
          "them over music's 90th / 95th percentile (of each version, frames from 1 s in)")
    print("| class | frames not fully idle | " + " | ".join(VERSIONS) + " |\n| --- | ---: |" + " ---: |" * len(VERSIONS))
    for cls in ("host", "crowd", "applause", "pink", "reader", "room"):
        fs = [s for c, _, _, s in cases if c == cls]
        n = sum(int(((s["idle_w"] < 1.0) & s["sound"]).sum()) for s in fs)
        cells = []
        for v in VERSIONS:
            q90, q95 = np.percentile(np.r_[pool_of("music", v), pool_of("song's start alone", v)], [90, 95])
            x = np.concatenate([s[v][(s["idle_w"] < 1.0) & s["sound"]] for s in fs]) if n else np.zeros(0)
            cells.append(f"{float((x > q90).mean()):.2f} / {float((x > q95).mean()):.2f}" if n else "-")
        print(f"| {cls} | {n} | " + " | ".join(cells) + " |")

    from sklearn.linear_model import LogisticRegression
    from sklearn.preprocessing import StandardScaler

    no_music = {"host", "reader", "applause", "crowd", "room", "pink"}
    music = {"music", "song's start alone"}

    def xy(split: int, extra: str | None, hi: int | None = None):
        xs, ys, cs = [], [], []
        for c, _, sp, s in cases:
            if sp != split or (c not in no_music and c not in music):
                continue
            keep = s["sound"].copy()
            keep[:30] = False
            if hi:
                keep[hi:] = False
            f = s["stats"][keep]
            if extra:
                f = np.c_[f, s[extra][keep]]
            xs.append(f)
            ys.append(np.full(len(f), c in music))
            cs.append(np.full(len(f), c, object))
        return np.concatenate(xs), np.concatenate(ys), np.concatenate(cs)

    print("\n### a logistic regression, fit on draws 0-3 (half the recordings), judged on the rest: AUC music vs not; "
          "not-music frames over the threshold that keeps 98 % of music frames, per class, from 1 s in (at 1-3 s: a stream's start)")
    for extra in (None,) + VERSIONS:
        x0, y0, _ = xy(0, extra)
        x1, y1, c1 = xy(1, extra)
        xs, _, cs = xy(1, extra, 90)
        sc = StandardScaler().fit(x0)
        net = LogisticRegression(max_iter=2000, class_weight="balanced").fit(sc.transform(x0), y0)
        z, zs = net.decision_function(sc.transform(x1)), net.decision_function(sc.transform(xs))
        thr = np.percentile(z[y1], 2)
        over = ", ".join(f"{c} {float((z[c1 == c] > thr).mean()):.3f} ({float((zs[cs == c] > thr).mean()):.3f})"
                         for c in sorted(no_music))
        print(f"12 statistics{' + ' + extra if extra else ''}: AUC {auc(z[y1], z[~y1]):.4f}; {over}")
    print("\n### the networks' own fit (models.training.music_gate.fit_network's: 16 tanh, L-BFGS 400 steps, classes "
          "weighted, music frames 2x as the shipped fit), the same split and figures, at each fit seed")
    for seed in range(fit_seeds):
        for extra in (None,) + VERSIONS:
            x0, y0, _ = xy(0, extra)
            x1, y1, c1 = xy(1, extra)
            xs, _, cs = xy(1, extra, 90)
            net = fit_tanh(x0, y0, seed)
            z, zs = net(x1), net(xs)
            thr = np.percentile(z[y1], 2)
            over = ", ".join(f"{c} {float((z[c1 == c] > thr).mean()):.3f} ({float((zs[cs == c] > thr).mean()):.3f})"
                             for c in sorted(no_music))
            print(f"seed {seed}, 12 statistics{' + ' + extra if extra else ''}: AUC {auc(z[y1], z[~y1]):.4f}; {over}")
    x, e = np.concatenate([s["stats"][30:][s["sound"][30:]] for *_, s in cases]), {}
    for v in VERSIONS:
        y = np.concatenate([s[v][30:][s["sound"][30:]] for *_, s in cases])
        e[v] = 1 - np.var(y - np.c_[x, np.ones(len(x))] @ np.linalg.lstsq(np.c_[x, np.ones(len(x))], y, rcond=None)[0]) / np.var(y)
    print("share of each version's variance the 12 statistics explain (linear R^2, every sounding frame from 1 s in): "
          + ", ".join(f"{v} {r:.2f}" for v, r in e.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
