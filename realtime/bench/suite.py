"""The latency suite (:func:`run_latency`), the concurrency sweep (:func:`run_streams`) and
the ensemble comparison (:func:`run_ensemble`).

All replay recorded audio in real time through whole performer processes
(:mod:`realtime.bench.harness`) and return JSON-able dicts; :mod:`realtime.bench.report`
writes them out. Every figure is defined in docs/latency.md.
"""

from __future__ import annotations

import contextlib
import math
import os
import platform
import tempfile
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from models.errors import ConfigError
from models.timebase import SAMPLE_RATE
from realtime.bench.harness import RunSettings, StreamSpec, run_performers
from realtime.bench.measure import (
    FRAME_PERIOD_MS, algorithmic_latency, grid_jitter_ms, nominal_times, pacer_origin,
    percentile_counting_losses, summarize,
)

NAIVE_FULL_WINDOW = 127  # frame index from which the naive baseline recomputes a full 128-frame window


@dataclass
class BenchConfig:
    """Settings shared by ``performer bench latency`` and ``performer bench streams``."""

    checkpoint: Path | None = None  # None: packaged default, else a random default-size model
    sample_rate: int = 44100  # replay (sound card) rate, Hz
    block_size: int = 512  # samples per audio block
    threads: int = 1  # torch threads per performer (the engine's default)
    warmup_s: float = 3.0  # engine warm-up (as `performer run`)
    cores: tuple[int, ...] | None = None  # CPU affinity of every process (None: leave as is)
    lead_ms: float = 0.0  # the performer's lead (`performer run --lead`; latency only)
    inject_ms: float = 0.0  # testing hook: ms of extra work in the first performer's lane ...
    inject_every: int = 8  # ... every this many frames (realtime/bench/reference.py)
    library: Path | None = None  # a user's library (`performer run --library`; latency only)
    notes: list[str] = field(default_factory=list)


# -- setup ---------------------------------------------------------------------------------

def pin_cores(cores: Sequence[int] | None) -> tuple[int, ...]:
    """Restrict this process (and the children it starts) to ``cores``; return the CPUs allowed.

    ConfigError if a core does not exist or is not allowed here.
    """
    allowed = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else list(range(os.cpu_count() or 1))
    if cores:
        bad = [c for c in cores if c not in allowed]
        if bad:
            raise ConfigError(f"--cores {','.join(map(str, cores))}: CPU(s) {bad} not available here "
                              f"(this process may use CPUs {allowed})")
        os.sched_setaffinity(0, set(cores))
        return tuple(sorted(cores))
    return tuple(allowed)


def resolve_checkpoint(checkpoint: str | Path | None, workdir: Path) -> tuple[Path, str]:
    """The checkpoint to run and how it was chosen.

    Given a path: that file (CheckpointError later if bad). Else the packaged default
    ``models/assets/default.pt``; if there is none, a default-size causal model with random
    weights (same architecture and cost as a trained one) saved into ``workdir``.
    """
    from realtime.pipeline import default_checkpoint_path

    if checkpoint is not None:
        return Path(checkpoint), "given"
    if default_checkpoint_path().is_file():
        return default_checkpoint_path(), "packaged default"
    return save_random_checkpoint(workdir / "random-default.pt"), "random weights (no packaged checkpoint)"


def save_random_checkpoint(path: Path, seed: int = 0) -> Path:
    """Save a default-size causal generator with random weights and random BN statistics."""
    import torch

    from models.features.spectral import FeatureConfig
    from models.networks.blocks import randomize_batchnorm
    from models.networks.checkpoint import build_model, save_checkpoint
    from models.rig.humanoid import BONES
    from models.rig.motion import POSE_DIM

    torch.manual_seed(seed)
    cfg = FeatureConfig()
    model = randomize_batchnorm(build_model("causal", {"feature_dim": cfg.dim}), seed)
    return save_checkpoint(path, model, model_name="causal", generator_config=model.config,
                           feature_config={**cfg.to_dict(), "fingerprint": cfg.fingerprint()},
                           rig={"bones": list(BONES), "pose_dim": POSE_DIM}, extra={"note": "random weights"})


def machine_info(cores: Sequence[int]) -> dict:
    """nproc, CPU model, the CPUs used, load average, Python and torch versions."""
    import torch

    model = platform.processor() or "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "nproc": os.cpu_count(),
        "cpu_model": model,
        "cores_used": list(cores),
        "loadavg_start": list(os.getloadavg()),
        "python": platform.python_version(),
        "torch": torch.__version__,
        "platform": platform.platform(),
    }


def audio_segment(path: Path, sample_rate: int, seconds: float, offset_s: float, out: Path) -> Path:
    """Decode ``path`` at ``sample_rate``, take ``seconds`` from ``offset_s`` (wrapping around
    the end, so a short clip loops), save as float32 ``.npy`` to ``out``."""
    from models.features.audio_io import load_audio

    x, sr = load_audio(path, sample_rate, mono=False)
    n = int(round(seconds * sr)) + 4096  # a little spare: the engine stops at `seconds`
    start = int(round(offset_s * sr)) % len(x)
    idx = (start + np.arange(n)) % len(x)
    np.save(out, np.ascontiguousarray(x[idx], dtype=np.float32))
    return out


# -- per-stream analysis -------------------------------------------------------------------

def stream_metrics(rec: dict, skip_frames: int = 0) -> dict:
    """Latency figures of one performer's frames (``rec`` from the harness), ms.

    ``skip_frames``: leave out frames with a smaller index (the naive baseline's ramp-up).
    """
    a = {k: np.asarray(rec[k], dtype=np.float64) for k in
         ("index", "audio_sample", "released", "sent", "compute_ms", "osc_received", "ws_received")}
    keep = a["index"] >= skip_frames
    a = {k: v[keep] for k, v in a.items()}
    t0 = pacer_origin(a["released"], a["audio_sample"], rec["block_size"], rec["sample_rate"])
    nominal = nominal_times(a["index"], t0)
    osc_ms = (a["osc_received"] - a["released"]) * 1000.0
    ws_ms = (a["ws_received"] - a["released"]) * 1000.0
    jitter = grid_jitter_ms(a["index"], a["sent"])
    consecutive = np.diff(a["index"]) == 1
    return {
        "frames": int(len(a["index"])),
        "per_hop_ms": summarize(a["compute_ms"]),
        "per_hop_own_ms": summarize(own_hop_ms(rec["compute_ms"], rec.get("compute_wait_ms"))[keep]),
        "per_hop_cpu_ms": summarize(_cpu_ms(rec, len(keep))[keep]),
        "send_ms": summarize((a["sent"] - a["released"]) * 1000.0),
        "e2e_osc_ms": summarize(osc_ms),
        "e2e_ws_ms": summarize(ws_ms),
        "e2e_osc_ms_p99_counting_losses": percentile_counting_losses(osc_ms, 99),
        "e2e_ws_ms_p99_counting_losses": percentile_counting_losses(ws_ms, 99),
        "lost_osc": int(np.isnan(a["osc_received"]).sum()),
        "late_or_lost": int(np.sum(~(np.fmax(osc_ms, ws_ms) <= FRAME_PERIOD_MS) | np.isnan(osc_ms + ws_ms))),
        "lost_ws": int(np.isnan(a["ws_received"]).sum()),
        "release_after_nominal_ms": summarize((a["released"] - nominal) * 1000.0),
        "audio_to_osc_ms": summarize((a["osc_received"] - nominal) * 1000.0),
        "audio_to_ws_ms": summarize((a["ws_received"] - nominal) * 1000.0),
        "jitter_ms": summarize(np.abs(jitter)) | {"std": float(np.nanstd(jitter))},
        "release_jitter_ms": summarize(np.abs(grid_jitter_ms(a["index"], a["released"]))),
        "interval_ms": summarize(np.diff(a["sent"])[consecutive] * 1000.0),
        "cpu_percent": 100.0 * rec["cpu_s"] / max(rec["wall_s"], 1e-9),
        "cpu_ms_per_frame": 1000.0 * rec["cpu_s"] / max(len(rec["index"]), 1),
        "peak_rss_mb": rec["peak_rss_mb"],
        "late_blocks": rec["late_blocks"],
        "overruns": rec["overruns"],
        "ws_drops": rec["ws_drops"],
        "osc_errors": rec["osc_errors"],
        "nan_frames": rec["nan_frames"],
        "reference_ms": summarize(np.asarray(rec.get("reference_ms", []), dtype=np.float64)),
    }


def own_hop_ms(compute_ms, wait_ms) -> np.ndarray:
    """The hop's own time per frame: its wall time less the time it waited for a CPU that
    another thread held (the engine's ``compute_wait_ms``); NaN where the wait is unknown."""
    hop = np.asarray(compute_ms, dtype=np.float64)
    wait = np.full(len(hop), np.nan) if wait_ms is None else np.asarray(wait_ms, dtype=np.float64)
    wait = np.concatenate([wait[: len(hop)], np.full(max(0, len(hop) - len(wait)), np.nan)])
    return hop - wait


def _hop_tails(wall_ms: np.ndarray, own_ms: np.ndarray, cpu_ms: np.ndarray) -> dict[str, float | None]:
    """The whole hop's wall, own and worker CPU time per frame (ms): p50 and p99.9 of each
    (None where none is known), for A/B tables (benchmarks/studies/ensemble_ab.py)."""
    out: dict[str, float | None] = {}
    for name, v in (("wall", wall_ms), ("own", own_ms), ("cpu", cpu_ms)):
        v = np.asarray(v, dtype=np.float64)
        v = v[np.isfinite(v)]
        for q, key in ((50, "p50"), (99.9, "p999")):
            out[f"per_hop_ms_{key}_{name}"] = float(np.percentile(v, q)) if len(v) else None
    return out


def _hop_parity(index, cpu_ms: np.ndarray) -> dict[str, float | None]:
    """The whole hop's worker CPU time per frame (ms), p50 and p99, on the even and on the odd
    frame indices apart: with 4 staggered dance_vq performers (phases 0, 2, 4, 6) every code
    step falls on an even hop and every lane is at an odd position of its cycle on the odd ones
    (for A/B tables, benchmarks/studies/ensemble_ab.py)."""
    idx = np.asarray(index, dtype=np.int64)
    cpu = np.asarray(cpu_ms, dtype=np.float64)[: len(idx)]
    odd = idx[: len(cpu)] % 2 == 1
    out: dict[str, float | None] = {}
    for name, sel in (("even", ~odd), ("odd", odd)):
        v = cpu[sel]
        v = v[np.isfinite(v)]
        for q, key in ((50, "p50"), (99, "p99")):
            out[f"per_hop_ms_{key}_cpu_{name}"] = float(np.percentile(v, q)) if len(v) else None
    return out


def _cpu_ms(rec: dict, n: int) -> np.ndarray:
    """The worker thread's CPU time of each of ``n`` hops, ms (NaN where not recorded)."""
    cpu = np.asarray(rec.get("compute_cpu_ms", []), dtype=np.float64)[:n]
    return np.concatenate([cpu, np.full(n - len(cpu), np.nan)])


def others_busy_percent(run: dict) -> float:
    """The share of all the machine's CPUs that processes other than the benchmark's held
    during a run of :func:`~realtime.bench.harness.run_performers`, percent: the machine's
    busy share less the CPU time of the performer and receiver processes (at least 0; NaN
    off Linux)."""
    ours_s = sum(r["cpu_s"] for r in ([run["process"]] if "process" in run else run["streams"])) + run["receiver_cpu_s"]
    ours = 100.0 * ours_s / max(run["wall_s"], 1e-9) / (os.cpu_count() or 1)
    return max(0.0, run["machine_busy_percent"] - ours)


def lane_cycle_ms(streams: list[dict], cycle: int) -> dict:
    """The costliest point of the performers' cost cycle, from their lanes' CPU time.

    For every performer (a record with ``index``, ``phase`` and ``lane_cpu_ms``: the worker
    thread's CPU time in its lane, ms per frame) and every position ``m`` of its cycle of
    ``cycle`` frames (its frames whose ``(index + phase) % cycle == m``; 0 is the code step
    of a dance_vq model), the median lane CPU time. Returns the largest of these medians
    (``ms``), whose performer (``lane``, 0-based) and ``position``, and every median
    (``medians``: performers x positions). A median over a run's ~75 frames per position
    ignores the few frames a busy machine slows; extra work on 1 frame in ``cycle`` moves
    it by the whole amount.
    """
    med = np.full((len(streams), cycle), np.nan)
    for j, rec in enumerate(streams):
        idx = np.asarray(rec["index"], dtype=np.int64)
        cpu = np.asarray(rec.get("lane_cpu_ms", []), dtype=np.float64)[: len(idx)]
        pos = (idx[: len(cpu)] + int(rec.get("phase", 0))) % cycle
        for m in range(cycle):
            if np.any(pos == m):
                med[j, m] = np.median(cpu[pos == m])
    if not np.isfinite(med).any():
        return {"ms": float("nan"), "lane": None, "position": None, "medians": med.tolist()}
    j, m = np.unravel_index(np.nanargmax(med), med.shape)
    return {"ms": float(med[j, m]), "lane": int(j), "position": int(m), "medians": med.tolist()}


def hop_cycle_medians(index, hop_cpu_ms, cycle: int) -> np.ndarray:
    """Per position ``m`` of the cost cycle (frames whose ``index % cycle == m``), the median of
    the worker thread's CPU time per frame for the whole hop (``hop_cpu_ms``: input stage and
    every lane), ms (cycle,); NaN for a position without data."""
    idx = np.asarray(index, dtype=np.int64)
    cpu = np.asarray(hop_cpu_ms, dtype=np.float64)[: len(idx)]
    pos = idx[: len(cpu)] % cycle
    return np.array([np.nanmedian(cpu[pos == m]) if np.any(pos == m) and np.isfinite(cpu[pos == m]).any()
                     else np.nan for m in range(cycle)])


def hop_cycle_peak(index, hop_cpu_ms, cycle: int) -> float:
    """How far the costliest position of the cost cycle stands above the others, for the whole
    hop: the largest of :func:`hop_cycle_medians` over their median (1.0 for a cycle of 1
    frame; NaN without data). Staggered performers spread their code steps over the positions
    (about 1.03 for 4 dance_vq performers); code steps piled on one hop (a broken stagger) or
    work added on one position raise it."""
    return _peak_over_median(hop_cycle_medians(index, hop_cpu_ms, cycle))


def _peak_over_median(med: np.ndarray) -> float:
    """The largest of per-position medians over their median (NaN without data)."""
    if not np.isfinite(med).any():
        return float("nan")
    return float(np.nanmax(med) / np.nanmedian(med))


def frame_series(rec: dict) -> dict[str, np.ndarray]:
    """Per-frame arrays for the plots: time since start (s), per-hop, e2e OSC/WS, jitter (ms)."""
    idx = np.asarray(rec["index"], dtype=np.float64)
    rel = np.asarray(rec["released"])
    sent = np.asarray(rec["sent"])
    return {
        "t_s": sent - sent[0] if len(sent) else sent,
        "per_hop_ms": np.asarray(rec["compute_ms"]),
        "e2e_osc_ms": (np.asarray(rec["osc_received"]) - rel) * 1000.0,
        "e2e_ws_ms": (np.asarray(rec["ws_received"]) - rel) * 1000.0,
        "jitter_ms": grid_jitter_ms(idx, sent),
    }


# -- in-process baselines -------------------------------------------------------------------

def naive_baseline(net) -> tuple[object | None, str]:
    """The naive full-window recompute of ``net`` for the engine (a PoseModel), or None and why not.

    A causal U-Net has one: :class:`~models.networks.streaming.NaiveWindowGenerator` reruns
    the whole 128-frame window every frame and emits the same poses as the streaming step,
    so the two differ in cost only. A ``dance_vq`` model has none: its stream is its
    offline pass (:func:`~models.networks.dance_stream.generate` pushes the song
    through the same :class:`~models.networks.dance_stream.DanceStream`), it carries state
    from code to code (the playing movement, the sampler), and a window rerun from scratch
    would dance a different dance; its predictor already reads its whole 16-code window
    at each code step.
    """
    from models.networks.causal import CausalGenerator
    from models.networks.streaming import NaiveWindowGenerator

    if isinstance(net, CausalGenerator):
        return NaiveWindowGenerator(net), ""
    return None, (f"{type(net).__name__} has no naive window recompute: its stream is its offline pass, with state "
                  "carried from code to code, so a window rerun from scratch would not give the same poses")


def model_step_costs(checkpoint: Path, features: np.ndarray, frames: int = 240, rounds: int = 4) -> dict:
    """Microseconds per frame of the model alone: the engine's streaming model vs the naive 128-frame recompute.

    Both run the same weights on the same feature frames, one frame per ``push`` (the
    engine's case), in the current torch thread setting, interleaved over ``rounds``
    so that load changes hit both alike. The naive generator is primed with 127 frames,
    so every timed call recomputes a full window.

    A model without a naive baseline (:func:`naive_baseline`; ``dance_vq``) is timed
    alone over ``max(frames, 960)`` frames, and its ``code_step_us`` (frames on which the
    predictor runs, one in ``seg``) and ``other_us`` are reported apart; ``naive_us`` and
    the ratios are None and ``naive_reason`` says why.
    """
    import torch

    from realtime.pipeline import build_pipeline

    pipeline = build_pipeline(checkpoint)
    fast = pipeline.model
    naive, reason = naive_baseline(getattr(fast, "model", None))
    if naive is None:
        n = max(frames, 960)
        x = np.resize(features.astype(np.float32), (NAIVE_FULL_WINDOW + n, features.shape[1]))
        fast.push(x[:NAIVE_FULL_WINDOW])  # past the stream's start (idle fade-in), as in a song
        first = fast.frame
        t_fast = []
        with torch.inference_mode():
            for row in x[NAIVE_FULL_WINDOW:]:
                t = time.perf_counter()
                fast.push(row[None])
                t_fast.append(time.perf_counter() - t)
        us = np.array(t_fast) * 1e6
        code = (first + np.arange(n)) % fast.seg == 0
        return {
            "streaming_us": summarize(us),
            "code_step_us": summarize(us[code]),
            "other_us": summarize(us[~code]),
            "code_every": int(fast.seg),
            "naive_us": None,
            "ratio_p50": None,
            "ratio_mean": None,
            "naive_reason": reason,
        }
    x = np.resize(features.astype(np.float32), (NAIVE_FULL_WINDOW + frames, features.shape[1]))
    fast.push(x[:NAIVE_FULL_WINDOW])
    naive.push(x[:NAIVE_FULL_WINDOW])
    t_fast, t_naive = [], []
    per = max(1, frames // rounds)
    with torch.inference_mode():
        for r in range(rounds):
            rows = x[NAIVE_FULL_WINDOW + r * per : NAIVE_FULL_WINDOW + (r + 1) * per]
            for gen, out in ((fast, t_fast), (naive, t_naive)):
                for row in rows:
                    t = time.perf_counter()
                    gen.push(row[None])
                    out.append(time.perf_counter() - t)
    s_us = summarize(np.array(t_fast) * 1e6)
    n_us = summarize(np.array(t_naive) * 1e6)
    return {
        "streaming_us": s_us,
        "naive_us": n_us,
        "ratio_p50": n_us["p50"] / s_us["p50"],
        "ratio_mean": n_us["mean"] / s_us["mean"],
    }


def stream_vs_offline(checkpoint: Path, features: np.ndarray, seed: int = 0, phase: int = 0) -> dict:
    """Streaming equals offline: the engine's pose model fed ``features`` a few frames per push
    (0-3 frames, seeded: the engine pushes 0, 1 or 2 per audio block) against the offline pass
    (:func:`models.generate.run_model`: ``offline_windowed`` for a causal U-Net,
    ``dance_stream.generate`` for dance_vq) on the same features. Returns frames, the chunking
    and the largest absolute difference of any pose value.

    ``phase``: a staggered performer of an ensemble (:attr:`realtime.performer.Performer.phase`):
    its model first hears :func:`~realtime.performer.stagger_lead`'s silence frames, as the engine
    feeds them after a reset, and the offline pass runs on those frames followed by
    ``features``; the frames after the lead-in are compared."""
    from models.generate import run_model
    from realtime.performer import stagger_lead
    from realtime.pipeline import build_pipeline

    pipeline = build_pipeline(checkpoint)
    x = features.astype(np.float32)
    lead = stagger_lead(pipeline.model, pipeline.extractor_factory, phase)
    st = getattr(pipeline.model, "stage", None)  # the offline pass on the live model's stage (run's default 3x2)
    kw = {"stage": (st.width, st.depth), "facing": st.facing} if st is not None and hasattr(st, "width") else {}
    if lead is not None:
        pipeline.model.push(lead)
        offline = run_model(pipeline.model.model, np.concatenate([lead, x]), **kw)[len(lead):]
    else:
        offline = run_model(pipeline.model.model, x, **kw)
    rng = np.random.default_rng(seed)
    parts, i = [], 0
    while i < len(x):
        k = int(rng.integers(0, 4))
        parts.append(pipeline.model.push(x[i : i + k]))
        i += k
    live = np.concatenate(parts)
    return {"frames": int(len(x)), "chunks": "0-3 frames per push, seeded", "phase": int(phase),
            "lead_frames": 0 if lead is None else len(lead),
            "max_abs": float(np.abs(live - offline).max()) if len(x) else 0.0}


def component_costs(checkpoint: Path, samples: np.ndarray, sample_rate: int, block_size: int,
                    frames: int = 300) -> dict:
    """Where a hop's time goes: microseconds per frame of each stage, in this process, unpaced.

    The engine's steps on ``samples`` ((n, channels) float32 at ``sample_rate``) in blocks
    of ``block_size``: channel mixdown + streaming features, the streaming model (steps and
    blending), then the VMC OSC sink (encode + send to a loopback socket) and the WebSocket
    sink (encode + hand-off to its server thread; no client). Means over ``frames``
    frames after a warm-up of the same length. A 2 ms pause after each frame (untimed)
    lets the WebSocket server thread run between frames, as it does in real time;
    back to back, its GIL hand-offs would be charged to the next timed call.
    """
    import socket

    from realtime.frame import PoseFrame
    from realtime.osc_out import OscSink
    from realtime.pipeline import build_pipeline
    from realtime.ws_server import WebSocketSink

    pipeline = build_pipeline(checkpoint)
    ext, model = pipeline.extractor_factory(sample_rate), pipeline.model
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    rx.bind(("127.0.0.1", 0))
    osc, ws = OscSink("127.0.0.1", rx.getsockname()[1]), WebSocketSink("127.0.0.1", 0)
    x = samples if samples.ndim == 2 else samples[:, None]
    spent = {"features": 0.0, "model": 0.0, "osc": 0.0, "ws": 0.0}
    try:
        for phase in ("warm-up", "timed"):
            ext.reset()
            model.reset()
            spent = dict.fromkeys(spent, 0.0)
            done, pos = 0, 0
            while done < frames:
                block = x[pos % len(x) : pos % len(x) + block_size]
                pos += len(block)
                t = time.perf_counter()
                feats = ext.push(block.mean(axis=1) if block.shape[1] > 1 else block[:, 0])
                spent["features"] += time.perf_counter() - t
                if not len(feats):
                    continue
                t = time.perf_counter()
                poses = model.push(feats)
                spent["model"] += time.perf_counter() - t
                for pose in poses:
                    frame = PoseFrame(done, pos - 1, (done + 1) / 30.0, time.monotonic(), pose)
                    for key, sink in (("osc", osc), ("ws", ws)):
                        t = time.perf_counter()
                        sink.send(frame)
                        spent[key] += time.perf_counter() - t
                    done += 1
                    time.sleep(0.002)  # let the WebSocket server thread run, as between real frames
                while True:  # drain the loopback socket outside the timed sections
                    try:
                        rx.recv(65536, socket.MSG_DONTWAIT)
                    except BlockingIOError:
                        break
    finally:
        osc.close()
        ws.close()
        rx.close()
    out = {f"{k}_us": 1e6 * v / done for k, v in spent.items()}
    out["total_us"] = sum(out.values())
    out["frames"] = done
    return out


def offline_rtf(audio: Path, checkpoint: Path, baseline_checkpoint: Path | None = None) -> dict:
    """Real-time factor (processing seconds / audio seconds) of offline generation on a whole file.

    Decoding to 22050 Hz, :func:`~models.features.spectral.extract_features`, then the
    checkpoint's offline pass, :func:`models.generate.run_model` (what ``performer
    generate`` runs: :func:`~models.networks.streaming.offline_windowed`, 128-frame windows,
    hop 64, batches of 32, for a causal U-Net; :func:`~models.networks.dance_stream.generate`
    for dance_vq), and the offline paper generator ("unet_gan", non-causal, windowed;
    random weights unless ``baseline_checkpoint``: same cost). Wall and process-CPU
    seconds for each stage; current torch thread setting. The checkpoint's figures are
    keyed ``causal`` (every live model is causal); ``model`` names its kind.
    """
    import torch

    from models.features.audio_io import load_audio
    from models.features.spectral import extract_features
    from models.generate import load_model, run_model
    from models.networks.checkpoint import build_model, load_checkpoint
    from models.networks.streaming import offline_windowed

    loaded = load_model(checkpoint)
    net, cfg = loaded.model, loaded.features
    if baseline_checkpoint is not None:
        paper, _ = load_checkpoint(baseline_checkpoint)
    else:
        torch.manual_seed(0)
        paper = build_model("unet_gan", {"feature_dim": cfg.dim}).eval()
    out: dict = {"threads": torch.get_num_threads(), "model": loaded.name}

    def timed(name, fn):
        w, c = time.perf_counter(), time.process_time()
        r = fn()
        out[f"{name}_s"] = time.perf_counter() - w
        out[f"{name}_cpu_s"] = time.process_time() - c
        return r

    x, _ = timed("decode", lambda: load_audio(audio, SAMPLE_RATE))
    feats = timed("features", lambda: extract_features(x, cfg))
    with torch.inference_mode():
        timed("causal", lambda: run_model(net, feats))
        timed("unet_gan", lambda: offline_windowed(paper, feats))
    dur = len(x) / SAMPLE_RATE
    out["audio_s"] = dur
    out["frames"] = int(len(feats))
    out["rtf_features"] = out["features_s"] / dur
    out["rtf_causal"] = out["causal_s"] / dur
    out["rtf_unet_gan"] = out["unet_gan_s"] / dur
    out["rtf_causal_with_features"] = (out["features_s"] + out["causal_s"]) / dur
    out["rtf_unet_gan_with_features"] = (out["features_s"] + out["unet_gan_s"]) / dur
    out["unet_gan_over_causal"] = out["unet_gan_s"] / out["causal_s"]
    return out


# -- the two suites ---------------------------------------------------------------------------

@contextlib.contextmanager
def _sweep(cfg: BenchConfig):
    """A sweep's setup: pin to ``cfg.cores``, a scratch directory, the checkpoint and the machine
    (its end load average added on the way out); yields (workdir, checkpoint, how chosen, machine)."""
    cores = pin_cores(cfg.cores)
    with tempfile.TemporaryDirectory(prefix="performer-bench-") as tmp:
        work = Path(tmp)
        checkpoint, how = resolve_checkpoint(cfg.checkpoint, work)
        info = machine_info(cores)
        yield work, checkpoint, how, info
        info["loadavg_end"] = list(os.getloadavg())


def _settings(cfg: BenchConfig, checkpoint: Path, seconds: float, model: str = "streaming") -> RunSettings:
    return RunSettings(checkpoint, seconds, cfg.block_size, cfg.threads, cfg.warmup_s, model,
                       lead_ms=cfg.lead_ms, inject_ms=cfg.inject_ms, inject_every=cfg.inject_every,
                       library=cfg.library)


def run_latency(audio: Path, cfg: BenchConfig, seconds: float = 30.0, naive_seconds: float = 10.0,
                offline: bool = True, label: str | None = None) -> dict:
    """The latency suite on one recording; returns the result dict (``kind = "latency"``).

    1. ``seconds`` of ``audio`` replayed in real time through one performer process
       (streaming model) with an OSC and a WebSocket receiver on loopback;
    2. the same for ``naive_seconds`` with the naive full-window baseline in the engine
       (0 skips it; its first 127 frames, before the window is full, are left out);
    3. model-only cost per frame, streaming vs naive, interleaved (:func:`model_step_costs`;
       a model without a naive baseline, dance_vq, skips step 2 and the ratio, and the
       result says why under ``not_applicable``), the per-stage breakdown of a hop
       (:func:`component_costs`) and streaming against offline on the first 60 s
       (:func:`stream_vs_offline`), in this process;
    4. offline real-time factor on the whole file, the checkpoint's offline pass vs the
       paper's U-Net (``offline``).

    With ``cfg.library`` (a user's library, as ``performer run --library``) the performer of
    step 1 dances it; steps 2-4 measure the checkpoint alone, so they are skipped and the
    result names them under ``not_applicable``.
    """
    import torch

    from models.features.audio_io import load_audio
    from models.features.spectral import extract_features
    from models.generate import load_model
    from realtime.performer import cycle_frames
    from realtime.pipeline import build_pipeline

    audio = Path(audio)
    cores = pin_cores(cfg.cores)
    with tempfile.TemporaryDirectory(prefix="performer-bench-") as tmp:
        work = Path(tmp)
        checkpoint, how = resolve_checkpoint(cfg.checkpoint, work)
        result: dict = {
            "kind": "latency",
            "label": label or audio.stem,
            "audio": str(audio),
            "checkpoint": str(checkpoint if how != "random weights (no packaged checkpoint)" else "random"),
            "checkpoint_source": how,
            "machine": machine_info(cores),
            "settings": {"seconds": seconds, "naive_seconds": naive_seconds, **{
                k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(cfg).items()
                if k not in ("checkpoint", "notes")}},
            "algorithmic": algorithmic_latency(cfg.sample_rate, cfg.block_size),
        }
        seg = audio_segment(audio, cfg.sample_rate, max(seconds, naive_seconds), 0.0, work / "audio.npy")
        spec = StreamSpec(result["label"], seg, cfg.sample_rate)

        run = run_performers([spec], _settings(cfg, checkpoint, seconds), work / "streaming")
        rec = run["streams"][0]
        result["streaming"] = stream_metrics(rec)
        result["machine_busy_percent"] = run["machine_busy_percent"]
        result["others_busy_percent"] = others_busy_percent(run)
        result["receiver_cpu_percent"] = 100.0 * run["receiver_cpu_s"] / max(run["wall_s"], 1e-9)
        series = frame_series(rec)

        loaded = load_model(checkpoint)
        result["model"] = loaded.name
        result["lane_cycle"] = lane_cycle_ms([rec], cycle_frames(build_pipeline(checkpoint).model))
        result["lane_cycle"].pop("medians")
        result["lane_cycle"]["reference_cpu_ms_p50"] = summarize(
            np.asarray(rec.get("reference_cpu_ms", []), dtype=np.float64))["p50"]
        if cfg.library is not None:  # steps 2-4 would measure the checkpoint, not the library it dances
            why = f"measures the checkpoint alone, not the library {Path(cfg.library).name} it dances"
            result["library"] = rec.get("library")  # as the performer's model reports it
            if result["library"] is None:
                raise RuntimeError(f"the bench performer did not dance the library {cfg.library}")
            result["not_applicable"] = {k: why for k in ("model_step_naive_over_streaming",
                                                         "per_hop_naive_over_streaming", "stream_offline_max_abs",
                                                         "rtf_causal", "rtf_unet_gan")}
        else:
            naive, reason = naive_baseline(loaded.model)
            if naive_seconds > 0 and naive is not None:
                nrun = run_performers([spec], _settings(cfg, checkpoint, naive_seconds, "naive"), work / "naive")
                result["naive"] = stream_metrics(nrun["streams"][0], skip_frames=NAIVE_FULL_WINDOW)
            elif naive is None:
                result["not_applicable"] = {"model_step_naive_over_streaming": reason}

            torch.set_num_threads(cfg.threads)
            x, _ = load_audio(audio, SAMPLE_RATE)
            feats = extract_features(x[: 60 * SAMPLE_RATE], loaded.features)  # the model's own features
            result["model_step"] = model_step_costs(checkpoint, feats)
            result["stream_vs_offline"] = stream_vs_offline(checkpoint, feats)
            result["components"] = component_costs(checkpoint, np.load(seg), cfg.sample_rate, cfg.block_size)
            if offline:
                torch.set_num_threads(len(cores))
                result["offline"] = offline_rtf(audio, checkpoint)
        result["machine"]["loadavg_end"] = list(os.getloadavg())
    result["metrics"] = latency_metrics(result)
    result["_series"] = series
    return result


def latency_metrics(r: dict) -> dict[str, float]:
    """The flat figures budgets are checked against (keys of ``[latency]`` in budgets.toml)."""
    s = r["streaming"]
    m = {
        "per_hop_ms_p50": s["per_hop_ms"]["p50"],
        "per_hop_ms_p99": s["per_hop_ms"]["p99"],
        "per_hop_ms_p99_own": s["per_hop_own_ms"]["p99"],  # less the run-queue wait (scaled budget)
        "per_hop_ms_p99_cpu": s["per_hop_cpu_ms"]["p99"],  # the worker thread's CPU time
        "e2e_osc_ms_p50": s["e2e_osc_ms"]["p50"],
        "e2e_osc_ms_p99": s["e2e_osc_ms"]["p99"],
        "e2e_ws_ms_p50": s["e2e_ws_ms"]["p50"],
        "e2e_ws_ms_p99": s["e2e_ws_ms"]["p99"],
        "audio_to_osc_ms_p99": s["audio_to_osc_ms"]["p99"],
        "audio_to_ws_ms_p99": s["audio_to_ws_ms"]["p99"],
        "algorithmic_ms_max": r["algorithmic"]["total_ms_max"],
        "jitter_ms_p99": s["jitter_ms"]["p99"],
        "lost_frames": s["lost_osc"] + s["lost_ws"],
        "cpu_percent": s["cpu_percent"],
        "peak_rss_mb": s["peak_rss_mb"],
        "reference_ms_p50": s["reference_ms"]["p50"],  # the machine's speed during the run
        "reference_ms_p99": s["reference_ms"]["p99"],
        "others_busy_percent": r["others_busy_percent"],  # other processes' share of the CPUs (quiet budgets)
        # the costliest point of the model's cost cycle (lane CPU median) over the reference's CPU median
        "lane_cycle_ms": r["lane_cycle"]["ms"],
        "lane_cycle_over_reference": r["lane_cycle"]["ms"] / r["lane_cycle"]["reference_cpu_ms_p50"],
    }
    if "stream_vs_offline" in r:
        m["stream_offline_max_abs"] = r["stream_vs_offline"]["max_abs"]
    if r.get("model_step", {}).get("ratio_p50") is not None:
        m["model_step_naive_over_streaming"] = r["model_step"]["ratio_p50"]
    if "naive" in r:
        m["per_hop_naive_over_streaming"] = r["naive"]["per_hop_ms"]["p50"] / s["per_hop_ms"]["p50"]
    if "offline" in r:
        m["rtf_causal"] = r["offline"]["rtf_causal"]
        m["rtf_unet_gan"] = r["offline"]["rtf_unet_gan"]
    return m


def run_streams(audios: Sequence[Path], cfg: BenchConfig, counts: Sequence[int] = (1, 2, 4, 8, 12, 16, 20, 24),
                seconds: float = 20.0, offset_step_s: float = 7.0, stop_on_fail: bool = True) -> dict:
    """Concurrency sweep: N performer processes at once, for each N in ``counts``.

    Stream ``j`` replays ``audios[j % len(audios)]`` from ``(j // len(audios)) * offset_step_s``
    (wrapping), so no two streams play the same audio at the same moment. N passes when
    every stream's p99 end-to-end latency, OSC and WebSocket, counting lost frames as
    infinitely late, is under one frame period (33.3 ms). The sweep stops after the
    first failing N unless ``stop_on_fail`` is False. ``sustained`` is the largest
    passing N below the first failure.
    """
    if not audios:
        raise ConfigError("the stream sweep needs at least one --audio file")
    rows = []
    with _sweep(cfg) as (work, checkpoint, how, info):
        segs: dict[int, Path] = {}
        for n in counts:
            specs = []
            for j in range(n):
                if j not in segs:
                    src = Path(audios[j % len(audios)])
                    segs[j] = audio_segment(src, cfg.sample_rate, seconds, (j // len(audios)) * offset_step_s,
                                            work / f"audio{j:02d}.npy")
                specs.append(StreamSpec(f"{Path(audios[j % len(audios)]).stem}+{(j // len(audios)) * offset_step_s:g}s",
                                        segs[j], cfg.sample_rate))
            run = run_performers(specs, _settings(cfg, checkpoint, seconds), work / f"n{n}")
            rows.append(_sweep_row(n, run))
            if stop_on_fail and not rows[-1]["pass"]:
                break
    sustained = 0
    for row in rows:
        if not row["pass"]:
            break
        sustained = row["streams"]
    return {
        "kind": "streams",
        "label": "streams",
        "audio": [str(a) for a in audios],
        "checkpoint_source": how,
        "machine": info,
        "settings": {"seconds": seconds, "counts": list(counts), "offset_step_s": offset_step_s,
                     **{k: v for k, v in asdict(cfg).items() if k not in ("checkpoint", "notes")}},
        "frame_period_ms": FRAME_PERIOD_MS,
        "rows": rows,
        "sustained_streams": sustained,
        "metrics": {"sustained_streams": sustained,  # other processes' share of the CPUs, worst row (quiet budgets)
                    "others_busy_percent": max(row["others_busy_percent"] for row in rows)},
    }


def _sweep_row(n: int, run: dict) -> dict:
    per = [stream_metrics(r) for r in run["streams"]]
    worst = max(max(m["e2e_osc_ms_p99_counting_losses"], m["e2e_ws_ms_p99_counting_losses"]) for m in per)
    cpu_s = sum(r["cpu_s"] for r in run["streams"])
    return {
        "streams": n,
        "worst_p99_e2e_ms": worst,
        "worst_p99_osc_ms": max(m["e2e_osc_ms"]["p99"] for m in per),
        "worst_p99_ws_ms": max(m["e2e_ws_ms"]["p99"] for m in per),
        "median_p50_e2e_ms": float(np.median([m["e2e_osc_ms"]["p50"] for m in per])),
        "worst_p99_per_hop_ms": max(m["per_hop_ms"]["p99"] for m in per),
        "late_or_lost_frames": sum(m["late_or_lost"] for m in per),
        "lost_frames": sum(m["lost_osc"] + m["lost_ws"] for m in per),
        "frames": sum(m["frames"] for m in per),
        "performer_cpu_percent": 100.0 * cpu_s / max(run["wall_s"], 1e-9),
        "receiver_cpu_percent": 100.0 * run["receiver_cpu_s"] / max(run["wall_s"], 1e-9),
        "machine_busy_percent": run["machine_busy_percent"],
        "others_busy_percent": others_busy_percent(run),
        "max_peak_rss_mb": max(m["peak_rss_mb"] for m in per),
        "overruns": sum(m["overruns"] for m in per),
        "pass": bool(math.isfinite(worst) and worst < FRAME_PERIOD_MS),
    }


# -- the ensemble: N performers in one process against N processes ---------------------------

def run_ensemble(audio: Path, cfg: BenchConfig, counts: Sequence[int] = (1, 2, 4, 8), seconds: float = 20.0,
                 separate: bool = True, unstaggered: Sequence[int] = (4,), label: str | None = None) -> dict:
    """The ensemble comparison on one recording: for each N in ``counts``, N performers (seeds
    0..N-1, the engine's stagger) in ONE process on the one audio input, and, with
    ``separate``, the same N as N single-performer processes each replaying the same audio
    (the streams sweep's machinery, :func:`~realtime.bench.harness.run_performers`); for each
    N in ``unstaggered``, one process again with every performer at phase 0 (their code steps
    on the same hops). Every performer has its own loopback VMC receiver and WebSocket client.

    Figures per row (:func:`_ensemble_row`): the whole hop (one process: the engine's timer
    over every performer; separate: each process's own hop, median p50 and worst p99), the
    CPU time per frame of all performer processes together, the worst performer's end-to-end
    latency, lost frames, memory. The cost of each added performer is
    ``(figure(N) - figure(1)) / (N - 1)`` and the least-squares slope over ``counts``.
    Streaming equals offline for every phase the largest N uses (:func:`stream_vs_offline`,
    first 60 s).
    """
    import torch

    from models.features.audio_io import load_audio
    from models.features.spectral import extract_features
    from models.generate import load_model
    from realtime.performer import cycle_frames
    from realtime.pipeline import build_pipeline

    if not counts or min(counts) < 1:
        raise ConfigError(f"--counts must be positive, got {list(counts)}")
    audio = Path(audio)
    rows = []
    with _sweep(cfg) as (work, checkpoint, how, info):
        cycle = cycle_frames(build_pipeline(checkpoint).model)
        seg = audio_segment(audio, cfg.sample_rate, seconds, 0.0, work / "audio.npy")
        settings = _settings(cfg, checkpoint, seconds)
        plan = [(n, "one process", True) for n in counts]
        if separate:
            plan = [step for n in counts for step in ((n, "one process", True), (n, "separate processes", True))]
        plan += [(n, "one process, not staggered", False) for n in unstaggered]
        for n, mode, stagger in plan:
            specs = [StreamSpec(label or audio.stem, seg, cfg.sample_rate)] * n
            run = run_performers(specs, settings, work / f"n{n}-{len(rows)}", ensemble=mode != "separate processes",
                                 stagger=stagger)
            rows.append(_ensemble_row(n, mode, run, cycle))
        phases = sorted({j * cycle // max(counts) for j in range(max(counts))})
        loaded = load_model(checkpoint)
        torch.set_num_threads(cfg.threads)
        x, _ = load_audio(audio, SAMPLE_RATE)
        feats = extract_features(x[: 60 * SAMPLE_RATE], loaded.features)
        checks = [stream_vs_offline(checkpoint, feats, phase=p) for p in phases]
    result = {
        "kind": "ensemble",
        "label": label or audio.stem,
        "audio": str(audio),
        "checkpoint_source": how,
        "model": loaded.name,
        "cycle_frames": cycle,
        "machine": info,
        "settings": {"seconds": seconds, "counts": list(counts), "separate": separate,
                     "unstaggered": list(unstaggered),
                     **{k: v for k, v in asdict(cfg).items() if k not in ("checkpoint", "notes")}},
        "rows": rows,
        "marginal": _marginal(rows),
        "stream_vs_offline": checks,
    }
    result["metrics"] = ensemble_metrics(result)
    return result


def _ensemble_row(n: int, mode: str, run: dict, cycle: int = 1) -> dict:
    """One row of the ensemble table from :func:`~realtime.bench.harness.run_performers`;
    ``cycle``: the model's cost cycle, frames (:func:`lane_cycle_ms`, one process only)."""
    per = [stream_metrics(r) for r in run["streams"]]
    lanes = {"ms": None, "lane": None, "position": None, "medians": None}
    frames = per[0]["frames"]
    if "process" in run:  # one process: its whole hop, its own CPU and memory
        proc = run["process"]
        hop = summarize(np.asarray(proc["compute_ms"]))
        hop_p50, hop_p99 = hop["p50"], hop["p99"]
        own = summarize(own_hop_ms(proc["compute_ms"], proc.get("compute_wait_ms")))
        cpu = summarize(_cpu_ms(proc, len(proc["compute_ms"])))
        own_p99, cpu_p99, own_p95, cpu_p95 = own["p99"], cpu["p99"], own["p95"], cpu["p95"]
        tails = _hop_tails(proc["compute_ms"], own_hop_ms(proc["compute_ms"], proc.get("compute_wait_ms")),
                           _cpu_ms(proc, len(proc["compute_ms"])))
        tails.update(_hop_parity(run["streams"][0]["index"], _cpu_ms(proc, len(proc["compute_ms"]))))
        features_p50 = summarize(np.asarray(proc["features_ms"]))["p50"]
        cpu_s, rss = proc["cpu_s"], proc["peak_rss_mb"]
        extractors = proc["extractors"]
        reference = summarize(np.asarray(proc.get("reference_ms", []), dtype=np.float64))
        reference_cpu = summarize(np.asarray(proc.get("reference_cpu_ms", []), dtype=np.float64))["p50"]
        lanes = lane_cycle_ms(run["streams"], cycle)
        hop_med = hop_cycle_medians(run["streams"][0]["index"], _cpu_ms(proc, len(proc["compute_ms"])), cycle)
        peak = _peak_over_median(hop_med)  # hop_cycle_peak, from the same medians
        hop_cycle = float(np.nanmax(hop_med)) if np.isfinite(hop_med).any() else None
    else:  # separate processes: each its own hop (features included); CPU and memory summed
        hop_p50 = float(np.median([m["per_hop_ms"]["p50"] for m in per]))
        hop_p99 = max(m["per_hop_ms"]["p99"] for m in per)
        own_p99 = max(m["per_hop_own_ms"]["p99"] for m in per)
        cpu_p99 = max(m["per_hop_cpu_ms"]["p99"] for m in per)
        own_p95 = max(m["per_hop_own_ms"]["p95"] for m in per)
        cpu_p95 = max(m["per_hop_cpu_ms"]["p95"] for m in per)
        features_p50, tails = None, {}
        cpu_s, rss = sum(r["cpu_s"] for r in run["streams"]), sum(m["peak_rss_mb"] for m in per)
        extractors = n
        reference = summarize(np.concatenate([np.asarray(r.get("reference_ms", []), dtype=np.float64)
                                              for r in run["streams"]]))
        reference_cpu = peak = hop_cycle = None
    return {
        "performers": n,
        "mode": mode,
        "per_hop_ms_p50": hop_p50,
        "per_hop_ms_p99": hop_p99,
        "per_hop_ms_p99_own": own_p99,  # less the run-queue wait (docs/latency.md)
        "per_hop_ms_p99_cpu": cpu_p99,  # the worker thread's CPU time
        "per_hop_ms_p95_own": own_p95,
        "per_hop_ms_p95_cpu": cpu_p95,
        "features_ms_p50": features_p50,
        **tails,  # one process: wall, own and CPU p50 / p99.9 of the whole hop, CPU p50 / p99 on even and odd hops
        "performer_part_ms_p50": [m["per_hop_ms"]["p50"] for m in per] if "process" in run else None,
        "phases": [r.get("phase", 0) for r in run["streams"]],
        "cpu_ms_per_frame": 1000.0 * cpu_s / max(frames, 1),
        "peak_rss_mb": rss,
        "extractors": extractors,
        "worst_e2e_osc_ms_p99": max(m["e2e_osc_ms_p99_counting_losses"] for m in per),
        "worst_e2e_ws_ms_p99": max(m["e2e_ws_ms_p99_counting_losses"] for m in per),
        "lost_frames": sum(m["lost_osc"] + m["lost_ws"] for m in per),
        "frames": sum(m["frames"] for m in per),
        "overruns": sum(m["overruns"] for m in per) if "process" not in run else per[0]["overruns"],
        "machine_busy_percent": run["machine_busy_percent"],
        "receiver_cpu_percent": 100.0 * run["receiver_cpu_s"] / max(run["wall_s"], 1e-9),
        "reference_ms_p50": reference["p50"],
        "reference_ms_p99": reference["p99"],
        "reference_cpu_ms_p50": reference_cpu,  # the reference workload's CPU time (one process)
        "lane_cycle_ms": lanes["ms"],  # costliest point of the cost cycle, lane CPU median (one process)
        "lane_cycle_at": [lanes["lane"], lanes["position"]],  # its performer, cycle position
        "lane_cycle_medians": lanes["medians"],
        "lane_cycle_over_reference": (lanes["ms"] / reference_cpu if lanes["ms"] is not None and reference_cpu
                                      else None),
        "hop_cycle_peak": peak,  # the whole hop's costliest cycle position over the others (one process)
        # the whole hop's (input stage and lanes) costliest cycle position, CPU median, over the reference's
        "hop_cycle_over_reference": (hop_cycle / reference_cpu if hop_cycle is not None and reference_cpu else None),
        "others_busy_percent": others_busy_percent(run),
    }


def _marginal(rows: list[dict]) -> dict:
    """The cost of each added performer, per mode (staggered ones): per figure, the slope of
    a least-squares line over the counts, and ``(figure(N) - figure(1)) / (N - 1)`` per N."""
    out: dict = {}
    for mode in ("one process", "separate processes"):
        mine = sorted((r for r in rows if r["mode"] == mode), key=lambda r: r["performers"])
        if len(mine) < 2:
            continue
        n = np.array([r["performers"] for r in mine], dtype=np.float64)
        figures = {}
        for key in ("per_hop_ms_p50", "per_hop_ms_p99", "cpu_ms_per_frame", "peak_rss_mb"):
            y = np.array([r[key] for r in mine], dtype=np.float64)
            first = mine[0]
            per_n = {str(r["performers"]): (r[key] - first[key]) / (r["performers"] - first["performers"])
                     for r in mine[1:]}
            figures[key] = {"slope": float(np.polyfit(n, y, 1)[0]), "per_n": per_n}
        out[mode] = figures
    return out


def ensemble_metrics(r: dict) -> dict[str, float]:
    """The flat figures budgets are checked against (keys of ``[ensemble]`` in budgets.toml):
    ``per_hop_ms_p99_N`` / ``per_hop_ms_p50_N`` (one process, staggered) for every N run,
    ``lane_cycle_ms_N`` and its ratio to the reference workload's CPU time of the same run
    (``lane_cycle_over_reference_N``, :func:`lane_cycle_ms`), ``hop_cycle_peak_N``
    (:func:`hop_cycle_peak`), the whole hop's costliest position over the reference
    (``hop_cycle_over_reference_N``, :func:`hop_cycle_medians`), the slopes of the added
    performer's cost in one process, lost frames (one process), the largest
    stream-vs-offline difference over the phases and the other processes' largest share of
    the CPUs during a run (``others_busy_percent``)."""
    m: dict[str, float] = {}
    for row in r["rows"]:
        if row["mode"] == "one process":
            m[f"per_hop_ms_p99_{row['performers']}"] = row["per_hop_ms_p99"]
            m[f"per_hop_ms_p50_{row['performers']}"] = row["per_hop_ms_p50"]
            m[f"per_hop_ms_p99_own_{row['performers']}"] = row["per_hop_ms_p99_own"]
            m[f"per_hop_ms_p99_cpu_{row['performers']}"] = row["per_hop_ms_p99_cpu"]
            m[f"per_hop_ms_p95_own_{row['performers']}"] = row["per_hop_ms_p95_own"]
            m[f"per_hop_ms_p95_cpu_{row['performers']}"] = row["per_hop_ms_p95_cpu"]
            m[f"reference_ms_{row['performers']}_p50"] = row["reference_ms_p50"]
            m[f"reference_ms_{row['performers']}_p99"] = row["reference_ms_p99"]
            m[f"lane_cycle_ms_{row['performers']}"] = row["lane_cycle_ms"]
            m[f"lane_cycle_over_reference_{row['performers']}"] = row["lane_cycle_over_reference"]
            m[f"hop_cycle_peak_{row['performers']}"] = row["hop_cycle_peak"]
            m[f"hop_cycle_over_reference_{row['performers']}"] = row.get("hop_cycle_over_reference")
    one = r["marginal"].get("one process")
    if one is not None:
        m["added_performer_hop_ms_p50"] = one["per_hop_ms_p50"]["slope"]
        m["added_performer_cpu_ms"] = one["cpu_ms_per_frame"]["slope"]
    sep = r["marginal"].get("separate processes")
    if sep is not None:
        m["added_process_cpu_ms"] = sep["cpu_ms_per_frame"]["slope"]
    m["lost_frames"] = sum(row["lost_frames"] for row in r["rows"] if row["mode"] != "separate processes")
    m["stream_offline_max_abs"] = max(c["max_abs"] for c in r["stream_vs_offline"])
    m["others_busy_percent"] = max(row["others_busy_percent"] for row in r["rows"])  # quiet budgets
    return m
