"""Per-frame cost of the streaming causal generator vs the naive full-window recompute.

Run:  .venv/bin/python benchmarks/studies/stream_cost.py [--threads 2] [--frames 300] [--naive-frames 100]

Prints parameter counts of every registered model, then, for an untrained causal model
of the default size (BN statistics randomised; cost does not depend on training), the
median and p99 microseconds per frame of ``StreamingGenerator.push`` one frame at a
time (the engine's case) and of ``NaiveWindowGenerator`` (128-frame forward per
frame), and the time of one generator+discriminator training step on a 16 x 128-frame
batch, to size the training budget. Timings on a shared machine vary with its load.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from models.networks.blocks import randomize_batchnorm
from models.networks.checkpoint import MODELS, build_model
from models.networks.discriminator import MultiScaleDiscriminator, mean_score
from models.networks.generator import count_parameters
from models.networks.streaming import NaiveWindowGenerator, StreamingGenerator, torch_threads


def per_frame_us(gen, x: np.ndarray) -> np.ndarray:
    """Microseconds of each ``gen.push`` of one frame of x (k, D)."""
    times = np.empty(len(x))
    for i, row in enumerate(x):
        t0 = time.perf_counter()
        gen.push(row[None])
        times[i] = time.perf_counter() - t0
    return times * 1e6


def train_step_ms(batch: int = 16, frames: int = 128, repeats: int = 5) -> float:
    """Median ms of one generator + discriminator forward/backward (LSGAN-style losses)."""
    gen, disc = build_model("causal").train(), MultiScaleDiscriminator().train()
    x, real = torch.randn(batch, 65, frames), torch.randn(batch, 87, frames)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fake = gen(x)
        d_loss = (mean_score(disc(x, real)) - 1).square().mean() + mean_score(disc(x, fake.detach())).square().mean()
        d_loss.backward()
        g_loss = (mean_score(disc(x, fake)) - 1).square().mean() + (fake - real).abs().mean()
        g_loss.backward()
        times.append(time.perf_counter() - t0)
    return float(np.median(times) * 1e3)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--threads", type=int, default=2, help="torch intra-op threads (default 2)")
    ap.add_argument("--frames", type=int, default=300, help="frames pushed to the streaming generator")
    ap.add_argument("--naive-frames", type=int, default=100, help="frames pushed to the naive generator")
    ap.add_argument("--skip-train", action="store_true", help="do not time a training step")
    args = ap.parse_args()

    for name in sorted(MODELS):
        print(f"params {name:10s} {count_parameters(build_model(name)):>9,d}")
    print(f"params {'disc':10s} {count_parameters(MultiScaleDiscriminator()):>9,d}")

    torch.manual_seed(0)
    model = randomize_batchnorm(build_model("causal")).eval()
    x = np.random.default_rng(0).normal(size=(args.frames + 128, 65)).astype(np.float32)
    with torch_threads(args.threads):
        fast = per_frame_us(StreamingGenerator(model), x[: args.frames])
        naive = NaiveWindowGenerator(model)
        naive.push(x[:127])  # time it at full window length
        slow = per_frame_us(naive, x[127 : 127 + args.naive_frames])
        train = None if args.skip_train else train_step_ms()
    print(f"threads {args.threads}")
    for label, t in (("streaming", fast), ("naive", slow)):
        print(f"{label:9s} per frame: median {np.median(t):8.0f} us   p99 {np.percentile(t, 99):8.0f} us   (n={len(t)})")
    print(f"naive / streaming median: {np.median(slow) / np.median(fast):.1f}x")
    if train is not None:
        print(f"train step (G+D fwd/bwd, 16 x 128 frames): {train:.0f} ms")


if __name__ == "__main__":
    main()
