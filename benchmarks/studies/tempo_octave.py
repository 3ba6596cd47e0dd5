"""Does the tempo follower read the same metrical level at every stretch rate? (issue 25 part 1)

No motion is generated: for every song of the listening benchmark's stretch set
(``models.evaluation.listening.stretch_songs``: recordings of 80-130 bpm) and every rate of
``STRETCH_RATES`` (0.8, 1.0, 1.25; stretched audio cached as the benchmark caches it), the
features are extracted as ``performer generate`` does and each tracker's median tempo over
the excerpt after its first 6 s is divided by the rate. A song is *consistent* when that
value is the same (within 4 %) at all three rates; a reading is *accurate* when it is within
4 % of the song's ground truth (``librosa.beat.beat_track`` on the whole recording, times
the rate, which stretching makes exact) at some octave (x 2 ** k).

A second table gives the onsets a beat the follower's octave rule counts
(:func:`models.networks.tempo.onset_density` over 8 s, every 8 frames, median after the first
6 s, per beat of the ground truth's tempo at that rate): stretching keeps the music's onsets
a beat, so any difference between the rates is the counter's (or the stretch's) doing.

Trackers: ``follower`` (:func:`models.networks.tempo.song_period`, the shipped rule),
``tracker`` (the feature extractor's causal beat tracker, its own octave, folded like the
follower) and, with ``--madmom PYTHON``, madmom's online RNN + DBN beat tracker (the median
interval of its beats, folded the same way), run by another Python that has madmom.

madmom 0.16.1 (the PyPI release) does not install into the project's venv: its setup.py
imports Cython before any build requirement is declared (``ModuleNotFoundError: No module
named 'Cython'``), its shipped C files include ``longintrepr.h``, gone in Python 3.11, and it
uses aliases NumPy 2 removed. It was measured from a separate venv: Python 3.11, numpy
1.23.5, Cython < 3, scipy 1.10.1, the sdist's .c files deleted so Cython regenerates them,
``pip install --no-build-isolation .``, and ``from collections import MutableSequence`` in
madmom/processors.py changed to ``collections.abc``. BeatNet 1.1.3 requires madmom and pins
numba 0.54.1 (the project runs numba 0.68), so it was not tried::

    nice -n 5 .venv/bin/python benchmarks/studies/tempo_octave.py --cache .cache/listening
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

#: Relative tolerance of "the same tempo" and "the ground truth's tempo at some octave".
TOLERANCE: float = 0.04
#: Seconds of each reading left out at its start (the tracker's 6-s window fills).
SKIP_S: float = 6.0

MADMOM_SCRIPT = r"""
import sys, json, numpy as np
from madmom.features.beats import RNNBeatProcessor, DBNBeatTrackingProcessor
out = {}
for wav in sys.argv[1:]:
    act = RNNBeatProcessor(online=True)(wav)  # causal networks
    beats = DBNBeatTrackingProcessor(fps=100, online=True)(act)  # forward filtering, frame by frame
    out[wav] = [float(b) for b in np.atleast_1d(beats)]
print(json.dumps(out))
"""


def octave_error(bpm: float, truth: float) -> float:
    """Relative distance of ``bpm`` from ``truth`` x 2 ** k, the nearest octave k."""
    if bpm <= 0 or truth <= 0:
        return math.inf
    x = math.log2(bpm / truth)
    return abs(2.0 ** (x - round(x)) - 1.0)


def follower_bpm(feats: np.ndarray, clarity_col: int, onset_col: int) -> float:
    from models.networks.tempo import song_period
    from models.timebase import FPS

    p = song_period(feats[:, clarity_col + 1], feats[:, clarity_col], feats[:, onset_col])
    return 60.0 * FPS / p if p > 0 else 0.0


def tracker_bpm(feats: np.ndarray, clarity_col: int) -> float:
    from models.networks.tempo import fold_period
    from models.timebase import FPS

    logp, c = feats[:, clarity_col + 1], feats[:, clarity_col]
    keep = (np.arange(len(c)) >= SKIP_S * FPS) & (c >= 0.05)
    if not keep.any():
        return 0.0
    return 60.0 * FPS / fold_period(float(np.median(15.0 * 2.0 ** logp[keep])))


def beats_bpm(times: list[float]) -> float:
    """Median tempo (bpm) of beat times (s) after :data:`SKIP_S`, folded like the follower."""
    from models.networks.tempo import fold_period
    from models.timebase import FPS

    t = np.asarray(times)
    t = t[t >= SKIP_S]
    if len(t) < 3:
        return 0.0
    return 60.0 * FPS / fold_period(float(np.median(np.diff(t))) * FPS)


def onsets_a_beat(onset: np.ndarray, bpm: float) -> float:
    """Median :func:`~models.networks.tempo.onset_density` (onsets a second) of an onset column
    (T,) at 30 fps, every 8 frames over the last 8 s, after :data:`SKIP_S`, per beat at ``bpm``."""
    from models.networks.tempo import DENSITY_WINDOW, onset_density
    from models.timebase import FPS

    t = np.arange(int(SKIP_S * FPS), len(onset), 8)
    if not len(t) or bpm <= 0:
        return 0.0
    d = [onset_density(onset[max(0, i + 1 - DENSITY_WINDOW): i + 1]) for i in t]
    return float(np.median(d)) * 60.0 / bpm


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("::")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", default=str(REPO.parent / "shared" / "data"), metavar="DIR")
    p.add_argument("--cache", default=".cache/listening", metavar="DIR")
    p.add_argument("--checkpoint", default=None, help="dance_vq checkpoint (its feature config; default the packaged one)")
    p.add_argument("--madmom", metavar="PYTHON", help="a Python with madmom 0.16 installed: also score its online DBN tracker")
    p.add_argument("--json", metavar="FILE", help="write every reading here")
    a = p.parse_args(argv)

    from models.evaluation import listening as L
    from models.features.spectral import extract_features
    from models.generate import load_model
    from models.timebase import SAMPLE_RATE

    lm = load_model(a.checkpoint)
    cfg = lm.model.config
    data = Path(a.data)
    opts = L.Options(dwm=data / "dwm", music=data / "music", cache_dir=a.cache, progress=False)
    cache = L.AudioCache(a.cache)
    songs = L.stretch_songs(cache, opts)
    readings: dict[str, dict[str, dict[str, float]]] = {}  # tracker -> song -> rate -> bpm / rate
    wavs: dict[tuple[str, str], str] = {}
    tmp = Path(tempfile.mkdtemp(prefix="tempo_octave_"))
    truth: dict[str, float] = {}
    onsets: dict[str, dict[str, float]] = {}  # song -> rate -> onsets a beat at the truth's tempo x rate
    for path, bpm in songs:
        name = L.song_name(path)
        truth[name] = bpm
        start, seconds = L._excerpt_window(cache, path, opts)
        for r in L.STRETCH_RATES:
            y = cache.excerpt(path, start, seconds, r)
            feats = extract_features(y, lm.features)
            k = f"{r:g}"
            readings.setdefault("follower", {}).setdefault(name, {})[k] = \
                follower_bpm(feats, cfg.clarity_col, cfg.onset_col) / r
            readings.setdefault("tracker", {}).setdefault(name, {})[k] = tracker_bpm(feats, cfg.clarity_col) / r
            onsets.setdefault(name, {})[k] = onsets_a_beat(feats[:, cfg.onset_col], bpm * r)
            if a.madmom:  # madmom reads 44.1-kHz files without ffmpeg
                import librosa
                import soundfile

                w = tmp / f"{name}-{k}.wav"
                soundfile.write(w, librosa.resample(y, orig_sr=SAMPLE_RATE, target_sr=44100), 44100, subtype="PCM_16")
                wavs[(name, k)] = str(w)
    if a.madmom:
        out = subprocess.run([a.madmom, "-W", "ignore", "-c", MADMOM_SCRIPT, *wavs.values()], capture_output=True, text=True,
                             check=True)
        beats = json.loads(out.stdout)
        for (name, k), w in wavs.items():
            readings.setdefault("madmom online DBN", {}).setdefault(name, {})[k] = beats_bpm(beats[w]) / float(k)
    rates = [f"{r:g}" for r in L.STRETCH_RATES]
    print("| tracker | song | truth (bpm) | " + " | ".join(f"{k}x: bpm / rate" for k in rates)
          + " | consistent | accurate (of 3) |")
    print("| --- | --- | ---: | " + " | ".join("---:" for _ in rates) + " | --- | ---: |")
    totals = {}
    for tr, by_song in readings.items():
        n_cons = n_acc = 0
        for name, v in by_song.items():
            vals = [v[k] for k in rates]
            cons = all(x > 0 for x in vals) and max(vals) / min(vals) <= 1.0 + TOLERANCE
            acc = sum(octave_error(x, truth[name]) <= TOLERANCE for x in vals)
            n_cons += cons
            n_acc += acc
            print(f"| {tr} | {name} | {truth[name]:.0f} | " + " | ".join(f"{x:.1f}" for x in vals)
                  + f" | {'yes' if cons else 'NO'} | {acc} |")
        totals[tr] = (n_cons, n_acc, len(by_song))
    print()
    for tr, (c, acc, n) in totals.items():
        print(f"{tr}: consistent on {c} of {n} songs; accurate (within {100 * TOLERANCE:g} % at some octave) "
              f"on {acc} of {3 * n} readings")
    print()
    print("| song | truth (bpm) | " + " | ".join(f"onsets a beat at {k}x" for k in rates) + " |")
    print("| --- | ---: | " + " | ".join("---:" for _ in rates) + " |")
    for name, v in onsets.items():
        print(f"| {name} | {truth[name]:.0f} | " + " | ".join(f"{v[k]:.2f}" for k in rates) + " |")
    for k in rates:
        if k != "1":
            ratio = np.mean([v[k] / v["1"] for v in onsets.values() if v["1"] > 0])
            print(f"onsets a beat at {k}x over 1x, mean over the songs: {ratio:.2f}")
    if a.json:
        Path(a.json).write_text(json.dumps({"truth": truth, "readings": readings, "onsets_a_beat": onsets},
                                           indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
