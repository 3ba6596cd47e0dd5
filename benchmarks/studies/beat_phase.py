"""How well the causal beat-phase columns (models/features/context.py) predict the beats.

For every dance's song: the causal tracker's phase and tempo (``FeatureConfig(beat_phase=True)``)
against the offline ``librosa.beat.beat_track`` beats that ``performer evaluate`` scores
with (models/evaluation/beats.py). Reported per song and pooled, after the tracker's
6-s window has filled:

* ``R at beats``: length of the mean unit phase vector at the librosa beat frames (1 = the
  tracker's phase is the same at every beat, 0 = unrelated); ``R random``: the same at
  as many random frames (the baseline);
* ``phase at beats``: the circular mean phase there, degrees (0 = the tracker says "beat now");
* ``tracker period`` / ``librosa period``: median beat period, frames at 30 fps.

Usage::

    .venv/bin/python benchmarks/studies/beat_phase.py --data ../shared/data/dwm [--seconds 120]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from models.features.audio_io import load_audio
from models.features.context import PRIOR_PERIOD, TEMPO_WINDOW
from models.features.spectral import FeatureConfig, extract_features
from models.evaluation.beats import music_beats


def song_stats(audio: np.ndarray, rng: np.random.Generator) -> dict[str, float]:
    """Tracker-vs-librosa statistics of one song (22050 Hz mono)."""
    f = extract_features(audio, FeatureConfig(beat_phase=True))
    beats = music_beats(audio)  # round(30 * time); feature frame t ends at (t + 1) / 30 s
    frames = beats[(beats - 1 >= TEMPO_WINDOW) & (beats - 1 < len(f))] - 1
    phase = np.arctan2(f[:, -3], f[:, -4])
    unit = np.exp(1j * phase)
    rand = rng.integers(TEMPO_WINDOW, len(f), frames.size)
    return {
        "beats": int(frames.size),
        "r_beats": float(abs(unit[frames].mean())),
        "r_random": float(abs(unit[rand].mean())),
        "phase_deg": float(np.degrees(np.angle(unit[frames].mean()))),
        "tracker_period": float(np.median(PRIOR_PERIOD * 2.0 ** f[frames, -1])),
        "librosa_period": float(np.median(np.diff(beats))),
        "_unit": unit[frames],
        "_rand": unit[rand],
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", required=True, help="DWM root (directories DANCE_*/audio.mp3)")
    p.add_argument("--seconds", type=float, default=0.0, help="analyse only the first N s of each song (0 = all)")
    args = p.parse_args(argv)
    songs = sorted(Path(args.data).glob("DANCE_*/audio.mp3"))
    if not songs:
        p.error(f"no DANCE_*/audio.mp3 under {args.data}")
    rng = np.random.default_rng(0)
    rows, beats_all, rand_all = [], [], []
    print(f"{'song':<12} {'beats':>5} {'R at beats':>10} {'R random':>8} {'phase deg':>9} {'tracker P':>9} {'librosa P':>9}")
    for path in songs:
        audio, _ = load_audio(path)
        if args.seconds > 0:
            audio = audio[: int(args.seconds * 22050)]
        s = song_stats(audio, rng)
        beats_all.append(s.pop("_unit"))
        rand_all.append(s.pop("_rand"))
        rows.append(s)
        print(f"{path.parent.name:<12} {s['beats']:>5} {s['r_beats']:>10.3f} {s['r_random']:>8.3f} "
              f"{s['phase_deg']:>9.1f} {s['tracker_period']:>9.2f} {s['librosa_period']:>9.1f}")
    b, r = np.concatenate(beats_all), np.concatenate(rand_all)
    ratio = np.array([x["tracker_period"] / x["librosa_period"] for x in rows])
    print(f"\npooled over {len(rows)} songs, {b.size} beats: R at beats {abs(b.mean()):.3f} "
          f"(random frames {abs(r.mean()):.3f}), mean phase {np.degrees(np.angle(b.mean())):.1f} deg; "
          f"share of beats within +-45 deg of phase 0: {np.mean(np.abs(np.angle(b)) < np.pi / 4):.3f} "
          f"(random frames {np.mean(np.abs(np.angle(r)) < np.pi / 4):.3f})")
    print(f"tracker period within 10 % of librosa's in {np.mean(np.abs(ratio - 1) < 0.1):.2f} of songs, "
          f"half of it in {np.mean(np.abs(ratio - 0.5) < 0.05):.2f}, double in {np.mean(np.abs(ratio - 2) < 0.2):.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
