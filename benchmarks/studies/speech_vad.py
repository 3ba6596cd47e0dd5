"""Knowing when music plays: does a field-made speech detector tell read speech from music?

The presence detector (models/networks/music_gate.py) reads only the model's feature columns
and takes parts of a read-speech recording for music (docs/listening.md, "Knowing when music
plays"). This study runs silero-vad (the ``silero-vad`` wheel, its model inside the package;
it needs only torch and ``packaging``) on the same recordings the presence targets are judged
on, alone: ``../shared/data/music``, the validation songs of ``--data`` and
``../shared/data/speech``. The recordings are read at 16 kHz and fed in 512-sample chunks
(32 ms, the model's step), the model's state carried over, as a live stream would feed it.

Per recording: ``speech``, the share of chunks with speech probability above 0.5 (music: near
0; speech: near 1); ``windows``, the share of 1-s windows (31 chunks) in which more than half
of the chunks are speech, the scale at which a gate would act. It also prints the model's
cost per chunk (median and 99th percentile, microseconds, one torch thread).

Between songs, as ``benchmarks/listening.py`` plays it: 20 s of DANCE_C_2 from 10 s in, each
speech recording at the song's RMS level, the song's next 20 s, through one stream; the
speech share of each part, and of the song's second part heard alone from a fresh state
(the model carries a state: what it heard before changes what it says).

    .venv/bin/python benchmarks/studies/speech_vad.py --data ../shared/data/dwm

Exit status 2 when silero-vad is not installed (``pip install silero-vad==6.2.3``, in the
``dev`` extras) or a directory is missing.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

SR: int = 16000
CHUNK: int = 512  # silero-vad's step at 16 kHz (32 ms)
WINDOW: int = 31  # chunks in about 1 s


def speech_probability(model, audio: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(speech probability per 512-sample chunk (n // 512,), seconds each chunk took) of mono
    16-kHz ``audio`` (n,), one chunk at a time from a fresh state."""
    import torch

    model.reset_states()
    x = np.ascontiguousarray(audio, np.float32)
    n = len(x) // CHUNK
    p, cost = np.empty(n), np.empty(n)
    with torch.no_grad():
        for i in range(n):
            t0 = time.perf_counter()
            p[i] = float(model(torch.from_numpy(x[i * CHUNK: (i + 1) * CHUNK]), SR))
            cost[i] = time.perf_counter() - t0
    return p, cost


def shares(p: np.ndarray) -> dict[str, float]:
    """``speech``: chunks above 0.5; ``windows``: 1-s windows with more than half of them."""
    speech = p > 0.5
    k = len(p) // WINDOW
    win = speech[: k * WINDOW].reshape(k, WINDOW).mean(1) > 0.5 if k else np.zeros(0, bool)
    return {"speech": float(speech.mean()) if len(p) else 0.0, "windows": float(win.mean()) if k else 0.0}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", required=True, type=Path, help="the DWM dataset directory (validation songs)")
    p.add_argument("--music", type=Path, default=Path("../shared/data/music"), help="recordings of other genres")
    p.add_argument("--speech", type=Path, default=Path("../shared/data/speech"), help="read-speech recordings")
    p.add_argument("--json", type=Path, help="write the results as JSON")
    a = p.parse_args(argv)

    try:
        from silero_vad import load_silero_vad
    except ImportError:
        print("speech_vad: needs silero-vad (pip install silero-vad==6.2.3; the dev extras have it)", file=sys.stderr)
        return 2
    import torch

    from models.data.dwm import load_dance
    from models.data.split import VAL_DANCES
    from models.errors import PerformerError
    from models.features.audio_io import load_audio

    torch.set_num_threads(1)
    try:
        for d in (a.music, a.speech, a.data):
            if not d.is_dir():
                raise PerformerError(f"{d}: no such directory")
        items = [("music", f.stem, f) for f in sorted(a.music.glob("*.ogg"))]
        items += [("validation song", n, load_dance(a.data / n).audio_path) for n in VAL_DANCES]
        items += [("speech", f.stem, f) for f in sorted(a.speech.glob("*.ogg"))]
        model = load_silero_vad()
        rows, cost = [], []
        for kind, name, path in items:
            prob, c = speech_probability(model, load_audio(path, SR)[0])
            cost.append(c)
            rows.append({"kind": kind, "recording": name, "s": len(prob) * CHUNK / SR, **shares(prob)})
        song = load_audio(load_dance(a.data / "DANCE_C_2").audio_path, SR)[0]
        n = 20 * SR
        first, second = song[10 * SR: 10 * SR + n], song[10 * SR + n: 10 * SR + 2 * n]
        level = np.sqrt(np.mean(np.concatenate([first, second]).astype(np.float64) ** 2))
        alone = shares(speech_probability(model, second)[0])["speech"]
        gaps = []
        for _, name, path in (i for i in items if i[0] == "speech"):
            sp = load_audio(path, SR)[0]
            sp = sp * (level / max(np.sqrt(np.mean(sp.astype(np.float64) ** 2)), 1e-9))
            prob = speech_probability(model, np.concatenate([first, sp, second]))[0]
            k0, k1 = len(first) // CHUNK, (len(first) + len(sp)) // CHUNK
            gaps.append({"speech": name, "song_before": shares(prob[:k0])["speech"],
                         "during": shares(prob[k0:k1])["speech"], "song_after": shares(prob[k1:])["speech"],
                         "song_after_alone": alone})
    except (PerformerError, OSError) as e:
        print(f"speech_vad: {e}", file=sys.stderr)
        return 2
    us = np.concatenate(cost) * 1e6
    print(f"silero-vad's cost per 32-ms chunk: median {np.median(us):.0f} us, p99 {np.percentile(us, 99):.0f} us "
          f"over {len(us)} chunks (one torch thread)")
    print("\n| recording | kind | s | chunks of speech | 1-s windows of speech |\n| --- | --- | ---: | ---: | ---: |")
    for r in rows:
        print(f"| {r['recording']} | {r['kind']} | {r['s']:.0f} | {r['speech']:.3f} | {r['windows']:.3f} |")
    print("\n| DANCE_C_2, speech, DANCE_C_2 | song before | speech | song after | song after, heard alone |\n"
          "| --- | ---: | ---: | ---: | ---: |")
    for g in gaps:
        print(f"| {g['speech']} | {g['song_before']:.3f} | {g['during']:.3f} | {g['song_after']:.3f} | "
              f"{g['song_after_alone']:.3f} |")
    if a.json:
        a.json.write_text(json.dumps({"chunk_us_median": float(np.median(us)), "chunk_us_p99": float(np.percentile(us, 99)),
                                      "recordings": rows, "between_songs": gaps}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
