"""``performer bench``: the latency regression suite (latency, streams, ensemble, check)."""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

DESCRIPTION = """\
Latency regression suite: replays recorded audio in real time through whole performer
processes (the real engine, OSC/VMC and WebSocket outputs) with loopback receivers in a
separate process, and measures where the time goes. See docs/latency.md.

  latency   one recording: per-hop compute, end-to-end latency, algorithmic latency,
            jitter, CPU and memory, the naive baseline and the offline real-time factor
  streams   how many concurrent performer streams one machine sustains
  ensemble  N performers on one input in one process against N processes: per-hop
            p50/p99 and the cost of each added performer
  check     compare result files with a budgets file; exit 1 with a diff when over
"""

LATENCY_HELP = """\
Figures (all in ms unless stated; p50/p95/p99/max over the frames of the run):

  per-hop compute     worker-thread time per 30 fps frame: feature extraction, the
                      streaming model, window blending, NaN guard/smoothing, OSC + WebSocket
                      encoding and send calls (the engine's own per-frame timer)
  end-to-end          from the release of the audio block that completes a frame (the
                      instant a sound card would deliver it; the file pacer records it) to
                      the frame's receipt by a loopback OSC (VMC) receiver and by a loopback
                      WebSocket client in another process (CLOCK_MONOTONIC on both ends,
                      frames matched by index)
  algorithmic         latency by design, before any compute: resampler look-ahead + block
                      quantisation (a frame completes inside a block and waits for its end);
                      features, model and blending add none. Shown per term.
  nominal → receipt   from the frame's nominal audio time (end of its hop) to receipt:
                      algorithmic + end-to-end, what a listener experiences
  jitter              |send time - ideal 30 fps grid| (median offset removed)
  naive baseline      the same engine with NaiveWindowGenerator (whole 128-frame window
                      rerun every hop, no cached state); ratios naive / streaming, both
                      model-only (interleaved in one process) and per hop in the engine
  offline RTF         processing seconds / audio seconds of offline windowed generation on
                      the whole file: causal model and the paper's U-Net GAN generator
  CPU, peak RSS       the performer process's CPU time over the replay and its VmHWM

Writes OUT/latency.json, latency.md, latency_hist.png, latency_timeline.png, frames.npz.
exit status: 0, 1 when --budgets is given and a budget is exceeded, 2 on bad input.
"""

STREAMS_HELP = """\
For each N in --counts, N performer processes (each its own engine, OSC and WebSocket
outputs, its own audio: the --audio files in turn, each later copy starting
--offset-step seconds further in) replay --seconds of audio at once, starting evenly
spread over one frame period; one receiver process takes all their outputs. N passes
when every stream's p99 end-to-end latency (OSC and WebSocket, lost frames counted as
late) is under one frame period, 33.3 ms. The sweep stops at the first failing N.

Writes OUT/streams.json, streams.md, streams.png.
exit status: 0, 1 when --budgets is given and a budget is exceeded, 2 on bad input.
"""


ENSEMBLE_HELP = """\
For each N in --counts, N performers on the one recording replayed in real time:

  one process          one engine (as `performer run --performer ...`): one audio input,
                       one feature extractor, N performers (seeds 0..N-1, code steps
                       staggered), each its own VMC receiver and WebSocket path /ws/pJ
  separate processes   N single-performer processes, each replaying the same audio with
                       its own extractor (the streams sweep's harness); --no-separate skips
  not staggered        one process again for each N of --unstaggered (default 4), every
                       performer at phase 0: their code steps on the same hops

Figures: per-hop compute p50/p99 (one process: the whole hop over every performer;
separate: each process's own), its input stage (features), CPU ms per frame of all
performer processes, worst end-to-end p99 (OSC and WebSocket, lost frames counted as
late), lost frames, memory; the cost of each added performer ((figure(N) - figure(1)) /
(N - 1), and the slope over the counts); streaming equal to offline for every stagger
phase; the costliest point of the performers' cost cycle (median lane CPU time) over the
reference workload's CPU median of the same run. Budgets (benchmarks/budgets.toml
[ensemble]): lane_cycle_over_reference_4 (any machine), per_hop_ms_p99_own_4 (a quiet one).

Writes OUT/ensemble.json, ensemble.md, ensemble.png.
exit status: 0, 1 when --budgets is given and a budget is exceeded, 2 on bad input.
"""


def _cores(text: str) -> tuple[int, ...]:
    try:
        cores = tuple(int(c) for c in text.split(",") if c.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected CPU numbers like 0,1, got {text!r}") from None
    if not cores or min(cores) < 0:
        raise argparse.ArgumentTypeError(f"expected CPU numbers like 0,1, got {text!r}")
    return cores


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", required=True, metavar="DIR", help="directory for the JSON, Markdown and PNG results")
    p.add_argument("--checkpoint", metavar="CKPT",
                   help="causal checkpoint (default: models/assets/default.pt, else a default-size model with "
                        "random weights: same cost)")
    p.add_argument("--cores", type=_cores, metavar="0,1",
                   help="pin every process of the run to these CPUs (like taskset -c); default: no pinning")
    p.add_argument("--threads", type=int, default=1, metavar="N",
                   help="torch threads per performer (default 1, as performer run)")
    p.add_argument("--sample-rate", type=int, default=44100, metavar="HZ",
                   help="replay rate, as a sound card would deliver (default 44100)")
    p.add_argument("--block-size", type=int, default=512, metavar="N", help="samples per audio block (default 512)")
    p.add_argument("--warmup", type=float, default=3.0, metavar="S", help="engine warm-up seconds (default 3)")
    p.add_argument("--budgets", metavar="TOML", help="check the result against this budgets file (exit 1 if over)")
    # Testing hook (hidden): a planted regression, MS of busy work every EVERY-th frame in the first
    # performer's lane, to show that the budgets catch one (tests/test_bench_budgets.py).
    p.add_argument("--inject-ms", type=float, default=0.0, help=argparse.SUPPRESS)
    p.add_argument("--inject-every", type=int, default=8, help=argparse.SUPPRESS)


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("bench", help="latency regression suite (latency, streams, ensemble, check)",
                              description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="bench_command", metavar="SUITE")

    lat = sub.add_parser("latency", help="latency figures of one recording replayed in real time",
                         description=LATENCY_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    lat.add_argument("--audio", metavar="FILE", help="recording to replay (default: the bundled 32 s clip); "
                                                     "shorter than --seconds: it loops")
    lat.add_argument("--seconds", type=float, default=30.0, metavar="S", help="seconds replayed (default 30)")
    lat.add_argument("--naive-seconds", type=float, default=10.0, metavar="S",
                     help="seconds replayed with the naive baseline in the engine (default 10; 0 skips)")
    lat.add_argument("--no-offline", action="store_true", help="skip the offline real-time factor")
    lat.add_argument("--label", help="name of the recording in reports (default: file name)")
    lat.add_argument("--lead", type=float, default=0.0, metavar="MS",
                     help="the performer's lead, ms, as `performer run --lead` (default 0; dance_vq models)")
    lat.add_argument("--library", metavar="FILE.npz",
                     help="the performer dances this library, as `performer run --library` (performer library "
                          "build); the in-process model figures (naive ratio, stream vs offline, offline RTF) "
                          "measure the checkpoint alone and are skipped")
    _common(lat)
    lat.set_defaults(func=latency)

    st = sub.add_parser("streams", help="how many concurrent performer streams stay within one frame period",
                        description=STREAMS_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    st.add_argument("--audio", action="append", metavar="FILE",
                    help="recording(s) the streams replay in turn (default: the bundled clip)")
    st.add_argument("--counts", type=int, nargs="+", default=[1, 2, 4, 8, 12, 16, 20, 24], metavar="N",
                    help="stream counts to try, in order (default 1 2 4 8 12 16 20 24)")
    st.add_argument("--seconds", type=float, default=20.0, metavar="S", help="seconds per count (default 20)")
    st.add_argument("--offset-step", type=float, default=7.0, metavar="S",
                    help="start offset between copies of one file (default 7)")
    st.add_argument("--no-stop", action="store_true", help="try every count even after one fails")
    _common(st)
    st.set_defaults(func=streams)

    en = sub.add_parser("ensemble", help="N performers on one input: one process against N processes",
                        description=ENSEMBLE_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    en.add_argument("--audio", metavar="FILE", help="recording every performer dances to (default: the bundled clip)")
    en.add_argument("--counts", type=int, nargs="+", default=[1, 2, 4, 8], metavar="N",
                    help="performer counts, in order (default 1 2 4 8)")
    en.add_argument("--seconds", type=float, default=20.0, metavar="S", help="seconds per run (default 20)")
    en.add_argument("--no-separate", action="store_true", help="skip the separate-processes runs")
    en.add_argument("--unstaggered", type=int, nargs="*", default=[4], metavar="N",
                    help="counts also run in one process with the stagger off (default 4; none: give no N)")
    en.add_argument("--label", help="name of the recording in reports (default: file name)")
    _common(en)
    en.set_defaults(func=ensemble)

    ck = sub.add_parser("check", help="compare result files with budgets; print a diff, exit 1 when over",
                        description="Apply a budgets file (benchmarks/budgets.toml) to latency.json / "
                                    "streams.json results and print, per metric, the budget, the measured "
                                    "value and how far over it is. Exit 1 when any budget is exceeded.")
    ck.add_argument("results", nargs="+", metavar="RESULT", help="result JSON files, or directories searched for them")
    ck.add_argument("--budgets", required=True, metavar="TOML", help="budgets file")
    ck.add_argument("--summary", metavar="FILE.md",
                    help="also write one headline table of every result (what docs/latency.md quotes)")
    ck.set_defaults(func=check)
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])


def _config(args):
    from models.errors import ConfigError
    from realtime.bench.suite import BenchConfig

    for name in ("threads", "block_size", "sample_rate"):
        if getattr(args, name) < 1:
            raise ConfigError(f"--{name.replace('_', '-')} must be at least 1, got {getattr(args, name)}")
    if args.seconds <= 0:
        raise ConfigError(f"--seconds must be positive, got {args.seconds}")
    if args.inject_ms < 0 or args.inject_every < 1:
        raise ConfigError(f"--inject-ms must be >= 0 and --inject-every >= 1, got {args.inject_ms} and "
                          f"{args.inject_every}")
    return BenchConfig(checkpoint=None if args.checkpoint is None else Path(args.checkpoint),
                       sample_rate=args.sample_rate, block_size=args.block_size, threads=args.threads,
                       warmup_s=args.warmup, cores=args.cores, lead_ms=getattr(args, "lead", 0.0),
                       inject_ms=args.inject_ms, inject_every=args.inject_every, library=_library(args))


def _library(args) -> Path | None:
    """``--library`` as a Path (latency only); ConfigError naming it when the file is missing."""
    from models.errors import ConfigError

    lib = getattr(args, "library", None)
    if lib is None:
        return None
    if not Path(lib).is_file():
        raise ConfigError(f"--library {lib}: no such file (build one with `performer library build`)")
    return Path(lib)


def _audio(path: str | None) -> Path:
    from models.errors import AudioError
    from models.features.audio_io import bundled_clip_path

    if path is None:
        return bundled_clip_path()
    p = Path(path)
    if not p.is_file():
        raise AudioError("audio file not found", source=p)
    return p


def _budgets(path: str | None):
    from realtime.bench.budgets import load_budgets

    return None if path is None else load_budgets(path)


def _command() -> str:
    argv = sys.argv[1:] if Path(sys.argv[0]).name == "performer" else ["bench", "..."]
    return "performer " + shlex.join(argv)


def _finish(result: dict, out: Path, budgets) -> int:
    from realtime.bench.budgets import check as apply, format_verdicts, tally
    from realtime.bench.report import write_result

    for path in write_result(result, out, budgets):
        print(f"performer bench: wrote {path}", file=sys.stderr)
    print((out / f"{result['kind']}.md").read_text())
    if budgets:
        verdicts = apply([result], budgets)
        print(format_verdicts(verdicts))
        print(tally(verdicts))
        return 0 if all(v.ok for v in verdicts) else 1
    return 0


def latency(args: argparse.Namespace) -> int:
    from realtime.bench.suite import run_latency

    cfg, audio, budgets = _config(args), _audio(args.audio), _budgets(args.budgets)
    result = run_latency(audio, cfg, seconds=args.seconds, naive_seconds=max(0.0, args.naive_seconds),
                         offline=not args.no_offline, label=args.label)
    result["command"] = _command()
    return _finish(result, Path(args.out), budgets)


def streams(args: argparse.Namespace) -> int:
    from models.errors import ConfigError
    from realtime.bench.suite import run_streams

    cfg, budgets = _config(args), _budgets(args.budgets)
    if any(n < 1 for n in args.counts):
        raise ConfigError(f"--counts must be positive, got {args.counts}")
    audios = [_audio(a) for a in (args.audio or [None])]
    result = run_streams(audios, cfg, counts=args.counts, seconds=args.seconds, offset_step_s=args.offset_step,
                         stop_on_fail=not args.no_stop)
    result["command"] = _command()
    return _finish(result, Path(args.out), budgets)


def ensemble(args: argparse.Namespace) -> int:
    from models.errors import ConfigError
    from realtime.bench.suite import run_ensemble

    cfg, audio, budgets = _config(args), _audio(args.audio), _budgets(args.budgets)
    if any(n < 1 for n in args.counts + args.unstaggered):
        raise ConfigError(f"--counts and --unstaggered must be positive, got {args.counts + args.unstaggered}")
    result = run_ensemble(audio, cfg, counts=args.counts, seconds=args.seconds, separate=not args.no_separate,
                          unstaggered=args.unstaggered, label=args.label)
    result["command"] = _command()
    return _finish(result, Path(args.out), budgets)


def check(args: argparse.Namespace) -> int:
    import json

    from models.errors import ConfigError
    from realtime.bench.budgets import check as apply, format_verdicts, load_budgets, tally

    budgets = load_budgets(args.budgets)
    files: list[Path] = []
    for r in args.results:
        p = Path(r)
        if p.is_dir():
            files += sorted(p.rglob("latency.json")) + sorted(p.rglob("streams.json")) + sorted(p.rglob("ensemble.json"))
        elif p.is_file():
            files.append(p)
        else:
            raise ConfigError("result file or directory not found", source=p)
    if not files:
        raise ConfigError(f"no latency.json, streams.json or ensemble.json under {', '.join(args.results)}")
    results = []
    for f in files:
        try:
            results.append(json.loads(f.read_text()))
        except (OSError, ValueError) as exc:
            raise ConfigError(f"unreadable result: {exc}", source=f) from None
    verdicts = apply(results, budgets)
    if args.summary:
        from realtime.bench.report import summary_markdown

        Path(args.summary).write_text(summary_markdown(results))
        print(f"performer bench: wrote {args.summary}", file=sys.stderr)
    print(format_verdicts(verdicts))
    failed = [v for v in verdicts if not v.ok]
    if failed:
        print(f"\n{tally(verdicts)}:\n{format_verdicts(failed)}", file=sys.stderr)
        return 1
    print(f"\n{tally(verdicts)}")
    return 0
