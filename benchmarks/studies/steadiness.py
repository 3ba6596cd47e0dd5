"""Does the spectral steadiness column tell a talking voice from music? (issue 25, target 4)

For every recording of ``../shared/data/speech``, ``../shared/data/music`` and the validation
songs of ``--data``, and for synthetic material of the presence detector's fit (espeak-ng
speech, crowd babble, applause, room tone, synthetic electronic and acoustic-like music;
seed ``--seed``, other than the fit's 0), the column (models/features/steadiness.py) is
computed as the feature extractor computes it and averaged over 1-s windows (30 frames) of
sound (log energy above -57 dB, the default model's silence threshold); the table gives the
10th, 50th and 90th percentiles of those means per recording, the plot their spread.

    .venv/bin/python benchmarks/studies/steadiness.py --data ../shared/data/dwm --plot docs/img/steadiness.png \
        --end-plot docs/img/brahms_end.png

``--end-plot`` draws, for each recording whose music ends before its last sound
(``models.evaluation.listening.MUSIC_ENDS_S``: a live recording that goes on with applause),
its last 16 s: the spectrogram with the annotated end of the music, and the column.

Exit status 2 when a directory is missing.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

#: Log energy (dB, feature column 13) at or below which a frame is silence (the default model's threshold).
SILENCE_DB: float = -57.0
#: Frames per window of the running mean the table and plot summarise (1 s).
WINDOW: int = 30


def window_means(col: np.ndarray, energy: np.ndarray) -> np.ndarray:
    """Means of the column over consecutive :data:`WINDOW`-frame windows whose frames all sound."""
    n = len(col) // WINDOW
    c, e = col[: n * WINDOW].reshape(n, WINDOW), energy[: n * WINDOW].reshape(n, WINDOW)
    keep = (e > SILENCE_DB).all(axis=1)
    return c[keep].mean(axis=1)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__.split("\n\n", 1)[1])
    p.add_argument("--data", required=True, metavar="DIR", help="the DWM dataset directory (its validation songs)")
    p.add_argument("--shared", metavar="DIR", help="the directory holding music/ and speech/ (default: --data's parent)")
    p.add_argument("--seconds", type=float, default=60.0, help="seconds read of each recording (default 60)")
    p.add_argument("--seed", type=int, default=5, help="seed of the synthetic material (default 5)")
    p.add_argument("--plot", metavar="PNG", help="draw the spread of the 1-s means per recording")
    p.add_argument("--end-plot", metavar="PNG", help="draw the end of each recording whose music ends before its sound")
    a = p.parse_args(argv)

    from models.data.split import split_names
    from models.features.audio_io import load_audio
    from models.features.spectral import FeatureConfig, extract_features
    from models.training import music_gate as tm

    data = Path(a.data)
    shared = Path(a.shared) if a.shared else data.parent
    for d in (data, shared / "music", shared / "speech"):
        if not d.is_dir():
            print(f"steadiness: {d} is not a directory", file=sys.stderr)
            return 2
    cfg = FeatureConfig(kind="mfcc_onset", n_mels=128, steadiness=True)
    rows: list[tuple[str, str, np.ndarray]] = []  # (group, name, 1-s means)

    def add(group: str, name: str, y: np.ndarray) -> None:
        f = extract_features(np.asarray(y, np.float32), cfg)
        rows.append((group, name, window_means(f[:, -1], f[:, 13])))
        print(f"  {group}: {name}", file=sys.stderr, flush=True)

    from models.data.dwm import dance_dirs, load_dance

    val = split_names([d.name for d in dance_dirs(data)])[1]
    for f in sorted((shared / "speech").iterdir()):
        add("speech", f.stem, load_audio(f, tm.SR)[0][: int(a.seconds * tm.SR)])
    for f in sorted((shared / "music").iterdir()):
        add("music", f.stem, load_audio(f, tm.SR)[0][: int(a.seconds * tm.SR)])
    for n in val:
        add("validation song", n, load_audio(load_dance(data / n).audio_path, tm.SR)[0][: int(a.seconds * tm.SR)])
    rng = np.random.default_rng(a.seed)
    if tm.espeak_available():
        pool = [tm.utterance(rng) for _ in range(12)]
        for i in range(3):
            add("synthetic, not music", f"espeak-ng speech {i}", tm.speech(20, rng, pool))
        add("synthetic, not music", "crowd babble", tm.babble(20, rng, pool))
    add("synthetic, not music", "applause", tm.applause(20, rng))
    add("synthetic, not music", "room tone", tm.room(20, rng))
    for i in range(2):
        add("synthetic music", f"electronic {i}", tm.electronic(20, rng))
        add("synthetic music", f"acoustic-like {i}", tm.tonal(20, rng))

    print("| group | recording | 1-s means: p10 | median | p90 |")
    print("| --- | --- | ---: | ---: | ---: |")
    for g, n, v in rows:
        q = np.percentile(v, [10, 50, 90]) if len(v) else [np.nan] * 3
        print(f"| {g} | {n} | {q[0]:.2f} | {q[1]:.2f} | {q[2]:.2f} |")
    if a.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        colours = {"speech": "tab:red", "music": "tab:blue", "validation song": "tab:green",
                   "synthetic, not music": "tab:orange", "synthetic music": "tab:purple"}
        fig, ax = plt.subplots(figsize=(8, 0.28 * len(rows) + 1.2))
        for i, (g, n, v) in enumerate(rows):
            if not len(v):
                continue
            lo, med, hi = np.percentile(v, [10, 50, 90])
            ax.plot([lo, hi], [i, i], color=colours[g], lw=2)
            ax.plot([med], [i], "o", color=colours[g])
        ax.set_yticks(range(len(rows)), [f"{n} ({g})" for g, n, _ in rows], fontsize=7)
        ax.invert_yaxis()
        ax.set_xlabel("spectral steadiness, 1-s means (dot: median, line: 10th-90th percentile)")
        ax.grid(axis="x", alpha=0.3)
        fig.tight_layout()
        fig.savefig(a.plot, dpi=110)
        print(f"wrote {a.plot}", file=sys.stderr)
    if a.end_plot:
        end_plot(shared / "music", cfg, a.end_plot)
    return 0


def end_plot(music: Path, cfg, out: str) -> None:
    """The last 16 s of every recording of :data:`listening.MUSIC_ENDS_S`: spectrogram, the end
    of its music, and the steadiness column (1-s running mean)."""
    import matplotlib

    matplotlib.use("Agg")
    import librosa
    import librosa.display
    import matplotlib.pyplot as plt

    from models.evaluation.listening import MUSIC_ENDS_S
    from models.features.audio_io import load_audio
    from models.features.spectral import extract_features
    from models.timebase import FPS, SAMPLE_RATE

    names = [n for n in MUSIC_ENDS_S if any(music.glob(n + ".*"))]
    fig, axes = plt.subplots(2 * len(names), 1, figsize=(9, 4.2 * len(names)), squeeze=False,
                             gridspec_kw={"height_ratios": [3, 1] * len(names)})
    for i, n in enumerate(names):
        y = load_audio(next(music.glob(n + ".*")), SAMPLE_RATE)[0]
        t0 = max(0.0, len(y) / SAMPLE_RATE - 16.0)
        seg = y[int(t0 * SAMPLE_RATE):]
        ax, bx = axes[2 * i, 0], axes[2 * i + 1, 0]
        spec = librosa.amplitude_to_db(np.abs(librosa.stft(seg, n_fft=2048, hop_length=256)), ref=np.max)
        librosa.display.specshow(spec, sr=SAMPLE_RATE, hop_length=256, x_axis="time", y_axis="log", ax=ax)
        end = MUSIC_ENDS_S[n] - t0
        ax.axvline(end, color="w", ls="--")
        ax.set_title(f"{n}: the last {len(seg) / SAMPLE_RATE:.0f} s (from {t0:.1f} s); dashed: the music ends, "
                     f"{MUSIC_ENDS_S[n]:.1f} s", fontsize=9)
        ax.set_xlabel("")
        col = extract_features(np.asarray(y, np.float32), cfg)[:, -1]
        m = np.convolve(col, np.ones(FPS) / FPS, mode="full")[: len(col)]
        t = np.arange(len(col)) / FPS
        keep = t >= t0
        bx.plot(t[keep] - t0, m[keep], color="k")
        bx.axvline(end, color="tab:red", ls="--")
        bx.set_xlim(0, len(seg) / SAMPLE_RATE)
        bx.set_ylabel("steadiness\n(1-s mean)", fontsize=8)
        bx.set_xlabel("seconds")
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    print(f"wrote {out}", file=sys.stderr)


if __name__ == "__main__":
    raise SystemExit(main())
