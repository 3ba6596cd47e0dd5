"""Writes a suite result: ``<kind>.json``, ``<kind>.md`` and PNG plots (matplotlib, Agg backend).

Latency run → ``latency.json``, ``latency.md``, ``latency_hist.png`` (distributions of
per-hop compute and end-to-end latency), ``latency_timeline.png`` (the same per frame
over the run, plus send-time jitter), ``frames.npz`` (the per-frame arrays).
Stream sweep → ``streams.json``, ``streams.md``, ``streams.png``.
Ensemble → ``ensemble.json``, ``ensemble.md``, ``ensemble.png``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from realtime.bench.budgets import Budget, check
from realtime.bench.measure import FRAME_PERIOD_MS


def _clean(obj):
    """JSON-able copy: NaN/inf become None, numpy scalars become Python numbers."""
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items() if not k.startswith("_")}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def write_result(result: dict, out: Path, budgets: list[Budget] | None = None) -> list[Path]:
    """Write the JSON, Markdown and plots of ``result`` into ``out``; return the paths."""
    out.mkdir(parents=True, exist_ok=True)
    kind = result["kind"]
    paths = [out / f"{kind}.json", out / f"{kind}.md"]
    paths[0].write_text(json.dumps(_clean(result), indent=1) + "\n")
    if kind == "latency":
        paths[1].write_text(latency_markdown(result, budgets))
        series = result.get("_series")
        if series is not None:
            np.savez(out / "frames.npz", **series)
            paths += [out / "frames.npz", *plot_latency(result, series, out)]
    elif kind == "ensemble":
        paths[1].write_text(ensemble_markdown(result, budgets))
        paths.append(plot_ensemble(result, out))
    else:
        paths[1].write_text(streams_markdown(result, budgets))
        paths.append(plot_streams(result, out))
    return paths


def _f(x, digits: int = 2) -> str:
    return "–" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.{digits}f}"


def _g(x) -> str:
    return "–" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.2g}"


def _row(name: str, s: dict, note: str = "") -> str:
    return f"| {name} | {_f(s['p50'])} | {_f(s['p95'])} | {_f(s['p99'])} | {_f(s['max'])} | {note} |"


def _budget_notes(result: dict, budgets: list[Budget] | None) -> dict[str, str]:
    notes = {}
    for v in check([result], budgets or []):
        sign = "≤" if v.budget.op == "max" else "≥"
        status = "n/a" if v.not_applicable is not None else "ok" if v.ok else "**over**"
        notes[v.budget.metric] = f"{sign} {v.limit:g} {status}"
    return notes


def machine_line(r: dict) -> str:
    m = r["machine"]
    la = m.get("loadavg_start", [math.nan])[0], m.get("loadavg_end", [math.nan])[0]
    return (f"{m['nproc']} CPUs ({m['cpu_model']}), this run pinned to CPUs {','.join(map(str, m['cores_used']))}; "
            f"load average (1 min) {_f(la[0])} at start, {_f(la[1])} at end; Python {m['python']}, torch {m['torch']}")


def latency_markdown(r: dict, budgets: list[Budget] | None = None) -> str:
    """The human-readable summary of one latency run (figures defined in docs/latency.md)."""
    s, a, notes = r["streaming"], r["algorithmic"], _budget_notes(r, budgets)
    st = r["settings"]
    lines = [
        f"# Latency: {r['label']}",
        "",
        f"Command: `{r.get('command', '?')}`",
        "",
        f"* Audio: `{r['audio']}`, {s['frames']} frames ({st['seconds']:g} s) replayed in real time at "
        f"{st['sample_rate']} Hz in blocks of {st['block_size']} ({_f(a['block_ms'])} ms)",
        f"* Checkpoint: `{r['checkpoint']}` ({r['checkpoint_source']}, model {r.get('model', '?')}); torch threads "
        f"per performer: {st['threads']}" + (f"; dancing the library `{r['library']}`" if r.get("library") else ""),
        f"* Machine: {machine_line(r)}",
        f"* During the replay all CPUs were {_f(r['machine_busy_percent'], 0)}% busy (any process); this "
        f"performer used {_f(s['cpu_percent'], 1)}% of one CPU ({_f(s['cpu_ms_per_frame'])} ms CPU per frame), "
        f"the loopback receiver {_f(r['receiver_cpu_percent'], 1)}%",
        "",
        "## Real-time replay (ms)",
        "",
        "| figure | p50 | p95 | p99 | max | budget |",
        "|---|---|---|---|---|---|",
        _row("per-hop compute (features + model + blending + encoding + send)", s["per_hop_ms"],
             notes.get("per_hop_ms_p99", "")),
        _row("per-hop compute, own (less the run-queue wait: another process had the CPU)",
             s.get("per_hop_own_ms", {"p50": None, "p95": None, "p99": None, "max": None}),
             notes.get("per_hop_ms_p99_own", "")),
        _row("end-to-end, block release → OSC (VMC) receipt", s["e2e_osc_ms"], notes.get("e2e_osc_ms_p99", "")),
        _row("end-to-end, block release → WebSocket receipt", s["e2e_ws_ms"], notes.get("e2e_ws_ms_p99", "")),
        _row("block release → frame handed to the outputs", s["send_ms"]),
        _row("frame's nominal audio time → block release (algorithmic, measured)", s["release_after_nominal_ms"]),
        _row("frame's nominal audio time → OSC receipt (total)", s["audio_to_osc_ms"],
             notes.get("audio_to_osc_ms_p99", "")),
        _row("frame's nominal audio time → WebSocket receipt (total)", s["audio_to_ws_ms"],
             notes.get("audio_to_ws_ms_p99", "")),
        _row("\\|send time − ideal 30 fps grid\\| (jitter)", s["jitter_ms"], notes.get("jitter_ms_p99", "")),
        _row("\\|block release − ideal 30 fps grid\\| (jitter the audio blocks bring)", s["release_jitter_ms"]),
        _row("interval between consecutive sends", s["interval_ms"]),
        "",
        f"Frames lost: OSC {s['lost_osc']}, WebSocket {s['lost_ws']}; late audio blocks {s['late_blocks']}, "
        f"ring overruns {s['overruns']}, WebSocket queue drops {s['ws_drops']}. "
        f"Peak RSS of the performer process: {_f(s['peak_rss_mb'], 0)} MB {notes.get('peak_rss_mb', '')}.",
        "",
        _reference_line([{"performers": 1, "mode": "streaming run", "reference_ms_p50": s["reference_ms"]["p50"],
                          "reference_ms_p99": s["reference_ms"]["p99"]}], st),
        "",
        "## Algorithmic latency (by design, ms)",
        "",
        "| term | mean | max |",
        "|---|---|---|",
        f"| resampler look-ahead ({st['sample_rate']} → 22050 Hz) | {_f(a['resampler_lookahead_ms_mean'])} | "
        f"{_f(a['resampler_lookahead_ms_max'])} |",
        f"| block quantisation (frame completes inside a {st['block_size']}-sample block) | "
        f"{_f(a['block_wait_ms_mean'])} | {_f(a['block_wait_ms_max'])} |",
        "| feature window look-ahead (windows end at the hop end) | 0.00 | 0.00 |",
        f"| model look-ahead (causal) | {_f(a['model_lookahead_ms'])} | {_f(a['model_lookahead_ms'])} |",
        f"| window blending (128-frame windows, hop 64) | {_f(a['blending_ms'])} | {_f(a['blending_ms'])} |",
        f"| smoothing (off) | {_f(a['smoothing_ms'])} | {_f(a['smoothing_ms'])} |",
        f"| **total beyond the frame's nominal time** | **{_f(a['total_ms_mean'])}** | **{_f(a['total_ms_max'])}** |",
        "",
    ]
    if "components" in r:
        c = r["components"]
        lines += [
            f"## Where a hop goes (in-process, unpaced, mean µs per frame over {c['frames']} frames)",
            "",
            "| mixdown + streaming features | streaming model (+ blending) | OSC (VMC) encode + send "
            "| WebSocket encode + hand-off | total |",
            "|---|---|---|---|---|",
            f"| {_f(c['features_us'], 0)} | {_f(c['model_us'], 0)} | {_f(c['osc_us'], 0)} | {_f(c['ws_us'], 0)} "
            f"| {_f(c['total_us'], 0)} |",
            "",
        ]
    lines += _baseline_lines(r, notes)
    return "\n".join(lines) + "\n"


def _model_step_lines(r: dict, notes: dict[str, str]) -> list[str]:
    """The model-only cost table: streaming against the naive recompute, or (no naive
    baseline: dance_vq) the streaming model alone, its code steps apart; none for a library run."""
    if "model_step" not in r:
        why = (r.get("not_applicable") or {}).get("stream_offline_max_abs", "not in this result")
        return [f"The model alone, the naive baseline and streaming against offline: not measured ({why}).", ""]
    ms = r["model_step"]
    if ms.get("naive_us") is None:
        rows = [("every frame", ms["streaming_us"]),
                (f"code-step frames (1 in {ms.get('code_every', '?')}: the predictor runs, a movement is chosen)",
                 ms.get("code_step_us")),
                ("other frames", ms.get("other_us"))]
        return [
            "## The model alone, same run",
            "",
            f"Streaming model only (in this process, one frame per push), µs per frame over "
            f"{ms['streaming_us']['n']} frames:",
            "",
            "| frames | p50 | p95 | p99 | max | mean |",
            "|---|---|---|---|---|---|",
            *(f"| {name} | {_f(v['p50'], 0)} | {_f(v['p95'], 0)} | {_f(v['p99'], 0)} | {_f(v['max'], 0)} "
              f"| {_f(v['mean'], 0)} |" for name, v in rows if v is not None),
            "",
            f"Naive full-window recompute (the budget on naive / streaming): not applicable. "
            f"{ms.get('naive_reason', '')}.",
        ]
    return [
        "## Baselines, same run",
        "",
        "| figure | streaming (ours) | naive full-window recompute | naive / streaming |",
        "|---|---|---|---|",
        f"| model only, µs per frame, p50 | {_f(ms['streaming_us']['p50'], 0)} | {_f(ms['naive_us']['p50'], 0)} | "
        f"{_f(ms['ratio_p50'], 1)}× {notes.get('model_step_naive_over_streaming', '')} |",
        f"| model only, µs per frame, p99 | {_f(ms['streaming_us']['p99'], 0)} | {_f(ms['naive_us']['p99'], 0)} | "
        f"{_f(ms['naive_us']['p99'] / ms['streaming_us']['p99'], 1)}× |",
    ]


def _baseline_lines(r: dict, notes: dict[str, str]) -> list[str]:
    s = r["streaming"]
    lines = _model_step_lines(r, notes)
    if "naive" in r:
        n = r["naive"]
        lines += [
            f"| per-hop compute in the engine, ms, p50 | {_f(s['per_hop_ms']['p50'])} | {_f(n['per_hop_ms']['p50'])} | "
            f"{_f(n['per_hop_ms']['p50'] / s['per_hop_ms']['p50'], 1)}× {notes.get('per_hop_naive_over_streaming', '')} |",
            f"| per-hop compute in the engine, ms, p99 | {_f(s['per_hop_ms']['p99'])} | {_f(n['per_hop_ms']['p99'])} | "
            f"{_f(n['per_hop_ms']['p99'] / s['per_hop_ms']['p99'], 1)}× |",
            f"| end-to-end OSC, ms, p99 | {_f(s['e2e_osc_ms']['p99'])} | {_f(n['e2e_osc_ms']['p99'])} | |",
            f"| process CPU per frame over the whole replay (naive: incl. its ramp-up), ms | "
            f"{_f(s['cpu_ms_per_frame'])} | {_f(n['cpu_ms_per_frame'])} | "
            f"{_f(n['cpu_ms_per_frame'] / s['cpu_ms_per_frame'], 1)}× |",
        ]
    lines.append("")
    if "stream_vs_offline" in r:
        so = r["stream_vs_offline"]
        lines += [
            f"Streaming against offline: the engine's pose model fed the first {so['frames']} feature frames "
            f"{so['chunks']}, against the offline pass on the same features: largest difference "
            f"{so['max_abs']:.2g} {notes.get('stream_offline_max_abs', '')}.",
            "",
        ]
    if "offline" in r:
        o = r["offline"]
        name = o.get("model", "causal")
        how = "offline pass (dance_stream.generate)" if name == "dance_vq" else "windowed"
        lines += [
            f"## Offline generation of the whole file ({_f(o['audio_s'], 1)} s, {o['threads']} torch threads)",
            "",
            "| stage | seconds | real-time factor (seconds / audio seconds) |",
            "|---|---|---|",
            f"| decode + resample to 22050 Hz | {_f(o['decode_s'])} | {_f(o['decode_s'] / o['audio_s'], 4)} |",
            f"| features | {_f(o['features_s'])} | {_f(o['rtf_features'], 4)} |",
            f"| the checkpoint ({name}), {how} | {_f(o['causal_s'])} | {_f(o['rtf_causal'], 4)} "
            f"{notes.get('rtf_causal', '')} |",
            f"| paper U-Net GAN generator (unet_gan), windowed | {_f(o['unet_gan_s'])} | {_f(o['rtf_unet_gan'], 4)} "
            f"{notes.get('rtf_unet_gan', '')} |",
            "",
        ]
    return lines


def streams_markdown(r: dict, budgets: list[Budget] | None = None) -> str:
    """The sweep table (figures defined in docs/latency.md)."""
    notes = _budget_notes(r, budgets)
    st = r["settings"]
    lines = [
        "# Concurrent performer streams",
        "",
        f"Command: `{r.get('command', '?')}`",
        "",
        f"* Each stream: its own performer process, {st['seconds']:g} s of audio replayed in real time at "
        f"{st['sample_rate']} Hz, blocks of {st['block_size']}, {st['threads']} torch thread(s); streams start "
        "evenly spread over one frame period; one receiver process (OSC + WebSocket per stream)",
        f"* Checkpoint: {r['checkpoint_source']}",
        f"* Machine: {machine_line(r)}",
        f"* A count passes when every stream's p99 end-to-end latency (OSC and WebSocket, lost frames counted as "
        f"late) is under one frame period ({FRAME_PERIOD_MS:.1f} ms)",
        "",
        "| streams | worst p99 e2e ms | worst p99 OSC ms | worst p99 WS ms | median p50 e2e ms | worst p99 per-hop ms "
        "| late or lost frames | performers CPU % | receiver CPU % | all CPUs busy % | peak RSS MB | pass |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in r["rows"]:
        lines.append(
            f"| {row['streams']} | {_f(row['worst_p99_e2e_ms'])} | {_f(row['worst_p99_osc_ms'])} | "
            f"{_f(row['worst_p99_ws_ms'])} | {_f(row['median_p50_e2e_ms'])} | {_f(row['worst_p99_per_hop_ms'])} | "
            f"{row['late_or_lost_frames']} / {row['frames']} | {_f(row['performer_cpu_percent'], 0)} | "
            f"{_f(row['receiver_cpu_percent'], 0)} | {_f(row['machine_busy_percent'], 0)} | "
            f"{_f(row['max_peak_rss_mb'], 0)} | {'yes' if row['pass'] else 'no'} |")
    lines += ["", f"**Sustained: {r['sustained_streams']} concurrent streams** "
              f"{notes.get('sustained_streams', '')}", ""]
    return "\n".join(lines) + "\n"


def ensemble_markdown(r: dict, budgets: list[Budget] | None = None) -> str:
    """The ensemble table: N performers in one process against N processes (docs/latency.md)."""
    notes = _budget_notes(r, budgets)
    st = r["settings"]
    lines = [
        f"# Ensemble: N performers on one input, one process against N processes ({r['label']})",
        "",
        f"Command: `{r.get('command', '?')}`",
        "",
        f"* Audio: `{r['audio']}`, {st['seconds']:g} s replayed in real time at {st['sample_rate']} Hz in blocks of "
        f"{st['block_size']}; model {r.get('model', '?')} ({r['checkpoint_source']}), cost cycle "
        f"{r.get('cycle_frames', '?')} frames; {st['threads']} torch thread(s) per process",
        "* One process: one `performer run`-style engine, one audio input and feature extractor, N performers "
        "(seeds 0..N-1, code steps staggered unless said), each with its own VMC receiver and WebSocket path "
        "`/ws/pJ` on one server",
        "* Separate processes: N single-performer processes, each replaying the same audio with its own extractor "
        "(the streams sweep's harness)",
        f"* Machine: {machine_line(r)}",
        "",
        "| performers | mode | per-hop p50 ms | per-hop p99 ms (own: less the run-queue wait) | of which features p50 | CPU ms per frame (all "
        "performer processes) | worst e2e OSC p99 ms | worst e2e WS p99 ms | lost | peak RSS MB (sum) | "
        "all CPUs busy % |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in r["rows"]:
        note = notes.get(f"per_hop_ms_p99_own_{row['performers']}", "") if row["mode"] == "one process" else ""
        p99 = f"{_f(row['per_hop_ms_p99'])} (own {_f(row.get('per_hop_ms_p99_own'))} {note})".replace(" )", ")")
        lines.append(
            f"| {row['performers']} | {row['mode']} | {_f(row['per_hop_ms_p50'])} | {p99} | "
            f"{_f(row['features_ms_p50'])} | {_f(row['cpu_ms_per_frame'])} | {_f(row['worst_e2e_osc_ms_p99'])} | "
            f"{_f(row['worst_e2e_ws_ms_p99'])} | {row['lost_frames']} / {row['frames']} | "
            f"{_f(row['peak_rss_mb'], 0)} | {_f(row['machine_busy_percent'], 0)} |")
    lines += ["", "Separate processes: per-hop p50 is the median of the processes' p50, p99 the worst process's "
              "(each process's hop includes its own features).", ""]
    lines += [_reference_line(r["rows"], st), ""]
    if r["marginal"]:
        lines += ["## Cost of each added performer", "",
                  "| mode | per-hop p50 ms | per-hop p99 ms | CPU ms per frame | peak RSS MB |",
                  "|---|---|---|---|---|"]
        for mode, fig in r["marginal"].items():
            cells = []
            for key in ("per_hop_ms_p50", "per_hop_ms_p99", "cpu_ms_per_frame", "peak_rss_mb"):
                per_n = ", ".join(f"{_f(v)} at {n}" for n, v in fig[key]["per_n"].items())
                cells.append(f"**{_f(fig[key]['slope'])}** ({per_n})")
            lines.append(f"| {mode} | " + " | ".join(cells) + " |")
        lines += ["", "Bold: the least-squares slope over the counts; in brackets `(figure(N) - figure(1)) / (N - 1)`.",
                  ""]
    parts = [row for row in r["rows"] if row.get("performer_part_ms_p50")]
    if parts:
        lines += ["## Where the one-process hop goes (p50, ms per frame)", "",
                  "| performers | mode | features (input stage) | each performer's part, in lane order (model, "
                  "guard, smoothing, sends) | phases |", "|---|---|---|---|---|"]
        for row in parts:
            lines.append(f"| {row['performers']} | {row['mode']} | {_f(row['features_ms_p50'])} | "
                         f"{' '.join(_f(v) for v in row['performer_part_ms_p50'])} | "
                         f"{' '.join(str(p) for p in row['phases'])} |")
        lines.append("")
    checks = r["stream_vs_offline"]
    lines += [f"Streaming against offline, per stagger phase ({', '.join(str(c['phase']) for c in checks)}): each "
              f"performer's model fed its lead-in of silence frames and then the first {checks[0]['frames']} "
              f"feature frames {checks[0]['chunks']}, against the offline pass on the same frames: largest "
              f"difference {max(c['max_abs'] for c in checks):.2g} {notes.get('stream_offline_max_abs', '')}.", ""]
    return "\n".join(lines) + "\n"


def plot_ensemble(r: dict, out: Path) -> Path:
    """Per-hop p50/p99 and CPU per frame against the number of performers, per mode."""
    plt = _plt()
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    for mode, style in (("one process", "o-"), ("separate processes", "s--"), ("one process, not staggered", "x:")):
        rows = sorted((row for row in r["rows"] if row["mode"] == mode), key=lambda row: row["performers"])
        if not rows:
            continue
        n = [row["performers"] for row in rows]
        ax.plot(n, [row["per_hop_ms_p99"] for row in rows], style, label=f"{mode}, p99")
        ax.plot(n, [row["per_hop_ms_p50"] for row in rows], style, alpha=0.5, label=f"{mode}, p50")
        ax2.plot(n, [row["cpu_ms_per_frame"] for row in rows], style, label=mode)
    ax.axhline(5.0, color="r", lw=0.8, label="5 ms budget (4 performers, one process)")
    ax.set_xlabel("performers")
    ax.set_ylabel("per-hop compute, ms")
    ax.legend(fontsize=7)
    ax2.set_xlabel("performers")
    ax2.set_ylabel("CPU ms per frame, all performer processes")
    ax2.legend(fontsize=7)
    fig.suptitle(f"{r['label']}: ensemble in one process vs separate processes", fontsize=10)
    return _save(plt, fig, out / "ensemble.png")


def _save(plt, fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_latency(r: dict, series: dict[str, np.ndarray], out: Path) -> list[Path]:
    """Histogram and timeline PNGs of one latency run."""
    plt = _plt()
    panels = [("per_hop_ms", "per-hop compute"), ("e2e_osc_ms", "block release → OSC receipt"),
              ("e2e_ws_ms", "block release → WebSocket receipt")]
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    for ax, (key, title) in zip(axes, panels):
        v = series[key][np.isfinite(series[key])]
        if len(v):
            ax.hist(v, bins=60, color="tab:blue", alpha=0.8)
            for q, style in ((50, "--"), (99, "-")):
                p = np.percentile(v, q)
                ax.axvline(p, color="k", ls=style, lw=1, label=f"p{q} {p:.2f} ms")
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("ms")
        ax.set_yscale("log")
        ax.legend(fontsize=8)
    axes[0].set_ylabel("frames")
    fig.suptitle(f"{r['label']}: {len(series['t_s'])} frames replayed in real time", fontsize=10)
    fig.tight_layout()
    hist = out / "latency_hist.png"
    fig.savefig(hist, dpi=110)
    plt.close(fig)

    fig, axes = plt.subplots(3, 1, figsize=(11, 7), sharex=True)
    t = series["t_s"]
    axes[0].plot(t, series["per_hop_ms"], ".", ms=2)
    axes[0].set_ylabel("per-hop ms")
    axes[1].plot(t, series["e2e_osc_ms"], ".", ms=2, label="OSC")
    axes[1].plot(t, series["e2e_ws_ms"], ".", ms=2, label="WebSocket")
    axes[1].axhline(FRAME_PERIOD_MS, color="r", lw=0.8, label="one frame period")
    axes[1].set_ylabel("end-to-end ms")
    axes[1].legend(fontsize=8, loc="upper right")
    axes[2].plot(t, series["jitter_ms"], ".", ms=2)
    axes[2].set_ylabel("send − 30 fps grid, ms")
    axes[2].set_xlabel("seconds since the first frame")
    fig.suptitle(f"{r['label']}: per frame", fontsize=10)
    fig.tight_layout()
    timeline = out / "latency_timeline.png"
    fig.savefig(timeline, dpi=110)
    plt.close(fig)
    return [hist, timeline]


def plot_streams(r: dict, out: Path) -> Path:
    """Worst-stream p99 end-to-end latency and CPU use against the number of streams."""
    plt = _plt()
    rows = r["rows"]
    n = [row["streams"] for row in rows]
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(n, [row["worst_p99_osc_ms"] for row in rows], "o-", label="worst stream p99, OSC")
    ax.plot(n, [row["worst_p99_ws_ms"] for row in rows], "s-", label="worst stream p99, WebSocket")
    ax.plot(n, [row["median_p50_e2e_ms"] for row in rows], "^--", label="median stream p50, OSC")
    ax.axhline(FRAME_PERIOD_MS, color="r", lw=0.8, label="one frame period (33.3 ms)")
    ax.set_xlabel("concurrent performer streams")
    ax.set_ylabel("end-to-end latency, ms")
    ax.set_yscale("log")
    ax2 = ax.twinx()
    ax2.plot(n, [row["machine_busy_percent"] for row in rows], "k:", label="all CPUs busy %")
    ax2.set_ylabel("all CPUs busy, %")
    ax2.set_ylim(0, 105)
    ax.legend(fontsize=8, loc="upper left")
    ax.set_title(f"sustained: {r['sustained_streams']} streams", fontsize=10)
    return _save(plt, fig, out / "streams.png")


def _reference_line(rows: list[dict], settings: dict) -> str:
    """The reference workload's p50 / p99 per run (how fast the machine ran during each), and a planted regression if any."""
    refs = "; ".join(f"{row['performers']} {row['mode']}: {_f(row.get('reference_ms_p50'))} / "
                     f"{_f(row.get('reference_ms_p99'))}" for row in rows)
    text = (f"Reference workload timed between the hops in the same process (p50 / p99 ms; docs/latency.md, "
            f"Budgets on a shared machine): {refs}.")
    cycles = "; ".join(f"{row['performers']} {row['mode']}: {_f(row['lane_cycle_ms'])} ms (performer "
                       f"{row['lane_cycle_at'][0]}, position {row['lane_cycle_at'][1]}) / {_f(row['reference_cpu_ms_p50'])}"
                       f" = {_f(row['lane_cycle_over_reference'])}; whole hop's costliest position over the median "
                       f"one {_f(row.get('hop_cycle_peak'))}" for row in rows
                       if row.get("lane_cycle_ms") is not None and row.get("lane_cycle_over_reference") is not None)
    if cycles:
        text += (" Costliest point of the cost cycle (median lane CPU time at one position of one performer's "
                 f"cycle) over the reference workload's CPU median, same run (docs/latency.md, Budgets on a shared "
                 f"machine): {cycles}.")
    if settings.get("inject_ms"):
        text += (f" **Planted regression (testing hook): {settings['inject_ms']:g} ms of busy work every "
                 f"{settings['inject_every']}th frame in the first performer's lane.**")
    return text


def summary_markdown(results: list[dict]) -> str:
    """One headline table over several results (``performer bench check --summary``).

    A row per latency result (per-hop and end-to-end p50/p99 in ms, peak RSS, the naive /
    streaming ratios, offline real-time factor) and the sustained stream count of each
    sweep, with the commands that produced them: what docs/latency.md and the README quote.
    """
    lat = [r for r in results if r.get("kind") == "latency"]
    lines = []
    if lat:
        lines += ["| recording | per-hop p50 | per-hop p99 (own) | e2e OSC p50 | e2e OSC p99 | e2e WS p50 | e2e WS p99 "
                  "| algorithmic max | jitter p99 | lost | peak RSS MB | CPU % | naive/streaming model p50 "
                  "| naive/streaming per hop p50 | offline RTF | stream vs offline max diff |",
                  "|---|" + "---:|" * 15]
        for r in lat:
            m = r["metrics"]
            lines.append(
                f"| {r['label']} | {_f(m['per_hop_ms_p50'])} | {_f(m['per_hop_ms_p99'])} "
                f"({_f(m.get('per_hop_ms_p99_own'))}) | {_f(m['e2e_osc_ms_p50'])} "
                f"| {_f(m['e2e_osc_ms_p99'])} | {_f(m['e2e_ws_ms_p50'])} | {_f(m['e2e_ws_ms_p99'])} "
                f"| {_f(m['algorithmic_ms_max'])} | {_f(m['jitter_ms_p99'])} | {m['lost_frames']} "
                f"| {_f(m['peak_rss_mb'], 0)} | {_f(m['cpu_percent'], 1)} "
                f"| {_f(m.get('model_step_naive_over_streaming'), 1)}× | {_f(m.get('per_hop_naive_over_streaming'), 1)}× "
                f"| {_f(m.get('rtf_causal'), 4)} | {_g(m.get('stream_offline_max_abs'))} |")
        lines.append("")
        lines.append("Times in ms; own: the hop less its run-queue wait (another process had the CPU); RTF: seconds "
                     "of compute per second of audio.")
        lines.append("")
    for r in (r for r in results if r.get("kind") == "streams"):
        lines.append(f"Concurrent streams sustained (every stream's p99 end-to-end < {FRAME_PERIOD_MS:.1f} ms): "
                     f"**{r['sustained_streams']}** (`{r.get('command', '')}`)")
        lines.append("")
    for r in (r for r in results if r.get("kind") == "ensemble"):
        m = r["metrics"]
        hops = ", ".join(f"{row['performers']}: {_f(row['per_hop_ms_p99'])} (own {_f(row.get('per_hop_ms_p99_own'))})"
                         for row in r["rows"] if row["mode"] == "one process")
        lines.append(f"Ensemble in one process, per-hop p99 ms by performers ({hops}); each added performer "
                     f"+{_f(m.get('added_performer_hop_ms_p50'))} ms per-hop p50, +{_f(m.get('added_performer_cpu_ms'))} "
                     f"ms CPU per frame (a separate process: +{_f(m.get('added_process_cpu_ms'))}) "
                     f"(`{r.get('command', '')}`)")
        lines.append("")
    cmds = [r.get("command") for r in lat if r.get("command")]
    if cmds:
        lines += ["Commands:", "", "```sh", *cmds, "```", ""]
    if lat:
        lines.append(f"Machine: {machine_line(lat[0])}")
    return "\n".join(lines) + "\n"
