"""Per-frame inference cost and size of every model, side by side, on one song.

For each checkpoint: parameter count, file size, and the time ``models.generate.run_model``
takes over the whole song's features (offline, the way ``performer generate`` and
``performer evaluate`` run it), median of ``--repeat`` runs in this one process, as ms
per 30 fps frame and real-time factor (seconds of compute per second of audio). Causal
models also get the streaming engine's cost: ``StreamingGenerator.push`` one frame at a
time (what ``performer run`` does per hop), median and p99 per frame, with the engine's
NumPy step and with the torch reference step, and the torch ops one frame dispatches. Feature extraction
is not included (it is shared: docs/features.md); ``--threads`` torch threads (default 1,
the engine's setting). Pin to two cores as the latency suite does::

    taskset -c 0,1 .venv/bin/python benchmarks/studies/model_cost.py --audio ../shared/data/dwm/DANCE_R_5/audio.mp3 \\
        --checkpoint models/assets/default.pt runs/unet_gan/best.pt runs/lstm/best.pt

Prints a Markdown table (docs/models.md quotes it) and, with ``--json``, writes the figures.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np


def _params(model) -> int:
    return sum(p.numel() for p in model.parameters())


def measure(checkpoint: str, audio: np.ndarray, repeat: int, stream_frames: int) -> dict:
    """Cost figures of one checkpoint on ``audio`` (mono 22050 Hz)."""
    from models.features.spectral import extract_features
    from models.generate import load_model, run_model
    from models.networks.causal import CausalGenerator
    from models.timebase import FPS

    lm = load_model(checkpoint)
    feats = extract_features(audio, lm.features)
    t = len(feats)
    run_model(lm.model, feats[: min(t, 256)], audio=audio[: min(t, 256) * 735])  # warm-up
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        run_model(lm.model, feats, audio=audio)
        times.append(time.perf_counter() - t0)
    med = statistics.median(times)
    out = {"checkpoint": checkpoint, "model": lm.name, "params": _params(lm.model),
           "file_mb": Path(checkpoint).stat().st_size / 2**20, "frames": t,
           "offline_ms_per_frame": med / t * 1000.0, "offline_rtf": med / (t / FPS),
           "causal": isinstance(lm.model, CausalGenerator), "live": not getattr(lm.model, "offline_only", False)}
    if out["causal"]:
        from models.networks.streaming import StreamingGenerator

        n = min(stream_frames, t)
        for kind, key in (("numpy", "stream"), ("torch", "stream_torch")):  # the engine's step, the reference
            gen = StreamingGenerator(lm.model, step=kind)
            for i in range(64):  # warm-up
                gen.push(feats[i : i + 1])
            gen.reset()
            per = np.empty(n)
            for i in range(n):
                t0 = time.perf_counter()
                gen.push(feats[i : i + 1])
                per[i] = time.perf_counter() - t0
            out[f"{key}_ms_p50"] = float(np.percentile(per, 50) * 1000.0)
            out[f"{key}_ms_p99"] = float(np.percentile(per, 99) * 1000.0)
        out["stream_ops_per_frame"] = count_ops(StreamingGenerator(lm.model, step="torch"), feats[:64])
    return out


def count_ops(gen, feats: np.ndarray) -> float:
    """Mean number of aten operations one ``gen.push`` of a single frame dispatches (torch step)."""
    from torch.utils._python_dispatch import TorchDispatchMode

    class _Count(TorchDispatchMode):
        n = 0

        def __torch_dispatch__(self, func, types, args=(), kwargs=None):
            _Count.n += 1
            return func(*args, **(kwargs or {}))

    with _Count():
        for i in range(len(feats)):
            gen.push(feats[i : i + 1])
    return _Count.n / max(len(feats), 1)


def table(rows: list[dict]) -> str:
    head = ("| model | checkpoint | parameters | file MB | offline ms/frame | offline RTF "
            "| streaming ms/frame p50 / p99 (engine, NumPy step) | same, torch step | torch ops per streamed frame "
            "| runs live |\n|---|---|---:|---:|---:|---:|---:|---:|---:|---|")
    lines = [head]

    def ms(r: dict, key: str) -> str:
        return f"{r[key + '_ms_p50']:.2f} / {r[key + '_ms_p99']:.2f}" if key + "_ms_p50" in r else "–"

    for r in rows:
        ops = f"{r['stream_ops_per_frame']:.0f}" if "stream_ops_per_frame" in r else "–"
        lines.append(f"| {r['model']} | `{r['checkpoint']}` | {r['params'] / 1e6:.2f} M | {r['file_mb']:.1f} "
                     f"| {r['offline_ms_per_frame']:.3f} | {r['offline_rtf']:.4f} | {ms(r, 'stream')} "
                     f"| {ms(r, 'stream_torch')} | {ops} | {'yes' if r['live'] and r['causal'] else 'no'} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--checkpoint", nargs="+", required=True, help="checkpoints to measure")
    p.add_argument("--audio", required=True, help="song to generate for (any format soundfile reads)")
    p.add_argument("--repeat", type=int, default=3, help="offline runs per model; the median is reported")
    p.add_argument("--stream-frames", type=int, default=1500, help="frames pushed one by one (causal models)")
    p.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    p.add_argument("--json", help="also write the figures here")
    a = p.parse_args(argv)

    import torch

    from models.errors import PerformerError
    from models.features.audio_io import load_audio

    torch.set_num_threads(a.threads)
    try:
        audio = load_audio(a.audio)[0]
        rows = [measure(c, audio, a.repeat, a.stream_frames) for c in a.checkpoint]
    except PerformerError as exc:
        print(f"model_cost.py: error: {exc}", file=sys.stderr)
        return 2
    print(f"{Path(a.audio).name}: {rows[0]['frames']} frames; torch threads {a.threads}\n")
    print(table(rows))
    if a.json:
        Path(a.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
