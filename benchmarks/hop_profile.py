"""Where a live hop's time goes: one paced engine run with timers around each stage.

Plays the bundled clip (or ``--audio FILE``) in real time through the real engine
(``realtime.engine.Engine``, the packaged checkpoint or ``--checkpoint``) with its real
outputs (VMC over UDP to a local socket, a WebSocket server), and times, per call:
the feature extractor's push and its parts (spectral kernel, context columns, beat
tracker), the pose model's push (and, for a dance_vq model, the code step and its
parts: the new row's pass, embedding, sampling, motion matching, the prefix pieces), the
engine's block checks and the outputs' ``send``. Per-hop compute (the engine's own
timer, as ``performer bench latency`` reports it) is also broken down by position in the
8-frame code cycle, wall and the worker thread's CPU time, and the code step is timed in
thread CPU time too. The timers wrap methods, so each call costs about 1 µs more than it
would; the figures are for finding where the time goes, the budgets are checked by
``make bench``::

    .venv/bin/python benchmarks/hop_profile.py --seconds 30
    .venv/bin/python benchmarks/hop_profile.py --seconds 30 --style waltz --guidance 1   # a style, unguided

Prints median, p95 and p99 per stage in ms (the first quarter of each stage's calls,
warm-up included, left out).
"""

from __future__ import annotations

import argparse
import functools
import socket
import sys
import time
from collections import defaultdict
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402


def _timed(table: dict, label: str, fn, clock=time.perf_counter):
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        t0 = clock()
        try:
            return fn(*args, **kwargs)
        finally:
            table[label].append(clock() - t0)
    return wrapper


def _wrap(table: dict, owner, name: str, label: str, clock=time.perf_counter) -> None:
    if hasattr(owner, name):
        setattr(owner, name, _timed(table, label, getattr(owner, name), clock))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--audio", default=None, help="audio file (default: the bundled clip)")
    p.add_argument("--checkpoint", default=None, help="checkpoint (default: the packaged one)")
    p.add_argument("--seconds", type=float, default=30.0, help="seconds of audio played in real time (default 30)")
    p.add_argument("--lead", type=float, default=0.0, help="the performer's lead, ms (default 0; performer run --lead)")
    p.add_argument("--block", type=int, default=512, help="samples per audio block (default 512)")
    p.add_argument("--rate", type=int, default=44100, help="input sample rate the audio is played at (default 44100)")
    p.add_argument("--style", default=None, help="a requested style (performer run --style; default: auto)")
    p.add_argument("--guidance", type=float, default=None,
                   help="STYLE_GUIDANCE for this run (default: the shipped one; 1: a style without guidance)")
    p.add_argument("--no-feet", action="store_true",
                   help="the feet step switched off (dance_stream.FEET_LOCK = False) for this run")
    p.add_argument("--stage", default=None, metavar="WxD",
                   help="a stage to travel on (DanceStream.set_stage, e.g. 3x2; default: as the pipeline builds it)")
    p.add_argument("--facing", default=None, help="free or audience (DanceStream.set_facing; default free)")
    args = p.parse_args(argv)
    if args.guidance is not None and not args.guidance > 0:
        p.error("--guidance must be > 0")

    import models.features.context as context
    import models.features.steadiness as steadiness
    import models.features.spectral as spectral
    import models.features.streaming as streaming
    import models.networks.chooser as chooser
    import models.networks.dance_numpy as dance_numpy
    import models.networks.dance_stream as dance_stream
    import models.networks.dance_vq as dance_vq
    import models.networks.feet as feet
    import models.networks.stage as stage
    from models.errors import PerformerError
    from models.features.audio_io import bundled_clip_path, load_audio
    from realtime.audio_input import FileSource
    from realtime.engine import Engine
    from realtime.engine_config import EngineConfig
    from realtime.osc_out import OscSink
    from realtime.pipeline import build_pipeline
    from realtime.ws_server import WebSocketSink

    t: dict[str, list[float]] = defaultdict(list)
    for owner, name, label in (
        (streaming.StreamingFeatureExtractor, "push", "features: push (every block)"),
        (spectral.SpectralKernel, "spectrum", "features: FFT (spectral kernel and steadiness column)"),
        (spectral.SpectralKernel, "__call__", "features: spectral kernel"),
        (context.ContextTracker, "__call__", "features: context + beat columns"),
        (context.ContextTracker, "_beat", "features: beat tracker"),
        (steadiness.SteadinessTracker, "from_spectrum", "features: steadiness column"),
        (dance_stream.DanceStream, "_next_code", "dance_vq: code step"),
        (dance_stream.DanceStream, "_gate", "dance_vq: idle gate"),
        (dance_numpy.NumpyPredictor, "embed", "dance_vq: code step: embedding (whole: a stream's first)"),
        (dance_numpy.NumpyPredictor, "embed_last", "dance_vq: code step: embedding (its newest frame)"),
        (dance_stream.DanceStream, "_read_ahead", "dance_vq: the handover's rows read ahead (frame before)"),
        (dance_numpy.NumpyPredictor, "logits_after", "dance_vq: code step: new row + head"),
        (dance_vq.DanceVQ, "sample", "dance_vq: code step: sampling"),
        (dance_numpy.Prefix, "step", "dance_vq: prefix piece"),
        (stage.Stage, "step", "dance_vq: stage step (every frame)"),
        (feet.FeetLock, "step", "dance_vq: feet step (every frame)"),
        (Engine, "_sanitize", "engine: block check"),
        (Engine, "_emit", "engine: emit (guard, smoothing, sends)"),
        (OscSink, "send", "outputs: VMC send"),
        (WebSocketSink, "send", "outputs: WebSocket send"),
    ):
        _wrap(t, owner, name, label)
    _wrap(t, dance_stream.DanceStream, "_next_code", "dance_vq: code step, thread CPU", time.thread_time)
    if hasattr(dance_stream, "match_exemplar"):  # (older trees: NumPy steps instead)
        dance_stream.match_exemplar = _timed(t, "dance_vq: code step: motion matching", dance_stream.match_exemplar)
    if args.guidance is not None:  # a script: the module's setting for this one run
        chooser.STYLE_GUIDANCE = args.guidance
    if args.no_feet:
        dance_stream.FEET_LOCK = False

    try:
        pipe = build_pipeline(args.checkpoint, lead=args.lead, style=args.style)
        audio, sr = load_audio(args.audio or bundled_clip_path(), args.rate, mono=False)
    except PerformerError as exc:
        print(f"hop_profile: {exc}", file=sys.stderr)
        return 2
    model = pipe.model
    try:
        if args.stage is not None:
            model.set_stage(args.stage)
        if args.facing is not None:
            model.set_facing(args.facing)
    except (PerformerError, AttributeError) as exc:
        print(f"hop_profile: --stage/--facing: {exc}", file=sys.stderr)
        return 2
    push = model.push
    model.push = _timed(t, "model: push (every frame)", push)

    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    sinks = [OscSink("127.0.0.1", rx.getsockname()[1], mode="vmc"), WebSocketSink("127.0.0.1", 0)]
    frames = int(args.seconds * 30)
    src = FileSource(audio, sr, name="audio", block_size=args.block)
    engine = Engine(src, pipe.extractor_factory, model, sinks,
                    EngineConfig(threads=1, warmup_s=3.0, duration_s=args.seconds, stats_size=frames + 64,
                                 runqueue_wait=True))  # the hop's worker CPU time too
    print(f"playing {args.seconds:.0f} s of {args.audio or 'the bundled clip'} in real time, style "
          f"{args.style or 'auto'}, STYLE_GUIDANCE {chooser.STYLE_GUIDANCE:g} ...", file=sys.stderr)
    engine.start()
    engine.wait()
    hop = np.asarray(engine.compute_ms.values(), float)
    hop_cpu = np.asarray(engine.compute_cpu_ms.values(), float)
    engine.close()
    rx.close()

    def row(label: str, ms: np.ndarray) -> str:
        return (f"| {label} | {len(ms)} | {np.median(ms):.3f} | {np.percentile(ms, 95):.3f} | "
                f"{np.percentile(ms, 99):.3f} |")

    print("| stage | calls | p50 ms | p95 ms | p99 ms |")
    print("|---|---:|---:|---:|---:|")
    print(row("per-hop compute (engine timer)", hop))
    for label in sorted(t):
        v = np.asarray(t[label]) * 1e3
        print(row(label, v[len(v) // 4:]))
    codes = getattr(model, "codes_drawn", None)
    if codes is not None and len(hop) >= 16:
        # the code step falls on the frames the stream numbers 0 mod 8; the engine's stats start after
        # the warm-up's frames, so the cycle position is the stream's frame count minus the frames kept
        first = int(getattr(model, "frame", len(hop))) - len(hop)
        pos = (np.arange(len(hop)) + first) % 8
        print()
        print("| frame in the cycle | " + " | ".join("0 (code step)" if k == 0 else str(k) for k in range(8)) + " |")
        print("|---|" + "---:|" * 8)
        for q, name in ((50, "p50"), (95, "p95"), (99, "p99")):
            print(f"| per-hop {name} ms | " + " | ".join(f"{np.percentile(hop[pos == k], q):.2f}" for k in range(8))
                  + " |")
        if len(hop_cpu) == len(hop):  # the worker thread's CPU time of the hop (no wait for a CPU another process held)
            for q, name in ((50, "p50"), (99, "p99")):
                print(f"| per-hop CPU {name} ms | "
                      + " | ".join(f"{np.percentile(hop_cpu[pos == k], q):.2f}" for k in range(8)) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
