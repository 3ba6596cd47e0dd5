"""The latency regression suite: statistics, budgets, CLI, and short real-time runs with guard budgets.

The runs marked ``latency`` replay a few seconds of the bundled clip in real time through
real performer processes and loopback receivers. The shipped default (models/assets/default.pt,
the dancing performer) runs against guards of 5x its targets (benchmarks/budgets.toml):
per-hop p99 25 ms (target 5), end-to-end p99 75 ms to the OSC and WebSocket receivers
(target 15), peak RSS 3000 MB (target 600), at most 2 frames lost (target 0). The guards
catch gross regressions on a busy CI machine, not a missed target: ``make bench`` checks
the targets (docs/latency.md). The concurrency sweep and the ensemble bench check their
plumbing on small models (a random-weight causal U-Net, a tiny dance_vq).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
import time

import numpy as np
import pytest

from models.features.audio_io import bundled_clip_path
from models.features.streaming import samples_needed
from models.rig.humanoid import NUM_BONES
from models.timebase import FPS, HOP, SAMPLE_RATE
from realtime.audio_input import FileSource
from realtime.bench import budgets as bud
from realtime.bench.measure import (
    algorithmic_latency, grid_jitter_ms, match_receipts, nominal_times, pacer_origin,
    percentile_counting_losses, summarize, vmc_frame_index, ws_frame_index,
)
from realtime.bench.suite import save_random_checkpoint
from realtime.bench.worker import ScheduledSource, TimingSink
from realtime.cli import main
from realtime.engine import Engine
from realtime.engine_config import EngineConfig
from realtime.pose_filters import rest_pose
from realtime.vmc import VmcEncoder
from realtime.wire import encode_frame

pytestmark = pytest.mark.serial  # wall-clock latency runs against budgets, CPU pinning: the serial pass of make test

REPO = Path(__file__).resolve().parents[1]

#: 5x the targets of benchmarks/budgets.toml's [latency] table (lost frames: 2 for 0).
GUARDS = """
[latency]
per_hop_ms_p99 = { max = 25.0 }
e2e_osc_ms_p99 = { max = 75.0 }
e2e_ws_ms_p99 = { max = 75.0 }
peak_rss_mb = { max = 3000.0 }
lost_frames = { max = 2 }
"""


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    return save_random_checkpoint(tmp_path_factory.mktemp("ckpt") / "random.pt")


# -- statistics -------------------------------------------------------------------------------

def test_summarize_ignores_nan_and_matches_numpy():
    v = np.array([1.0, 2.0, 3.0, 4.0, np.nan, 100.0])
    s = summarize(v)
    finite = v[np.isfinite(v)]
    assert s["n"] == 5 and s["max"] == 100.0 and s["mean"] == pytest.approx(finite.mean())
    assert s["p50"] == pytest.approx(np.percentile(finite, 50)) and s["p99"] == pytest.approx(np.percentile(finite, 99))
    assert math.isnan(summarize(np.array([np.nan]))["p99"])


def test_percentile_counting_losses_treats_lost_frames_as_late():
    v = np.full(1000, 5.0)
    assert percentile_counting_losses(v, 99) == 5.0
    v[:5] = np.nan  # 0.5 % lost: p99 still a real latency
    assert percentile_counting_losses(v, 99) == 5.0
    v[:20] = np.nan  # 2 % lost: more than 1 % never arrived
    assert percentile_counting_losses(v, 99) == math.inf


def test_match_receipts_by_index_first_receipt_wins_lost_is_nan():
    out = match_receipts([0, 1, 2, 3], recv_index=[1, 0, 1, 3], recv_time=[11.0, 10.0, 99.0, 13.0])
    assert out[:2].tolist() == [10.0, 11.0] and np.isnan(out[2]) and out[3] == 13.0


def test_vmc_frame_index_reads_the_frames_last_datagram():
    enc = VmcEncoder(np.full((NUM_BONES, 3), 0.1))
    for i in (0, 1, 29, 1799, 107999):  # up to one hour of frames
        grams = enc.encode(rest_pose(), (i + 1) * HOP / SAMPLE_RATE)
        found = [vmc_frame_index(g) for g in grams]
        assert found[-1] == i and all(f is None for f in found[:-1])
    assert vmc_frame_index(b"#bundle\x00garbage") is None


def test_ws_frame_index_reads_binary_frames_only():
    assert ws_frame_index(encode_frame(123456, 1.0, 2.0, rest_pose())) == 123456
    assert ws_frame_index(b'{"type": "hello"}') is None


def test_grid_jitter_and_pacer_origin_recover_a_known_schedule():
    i = np.arange(300)
    late = np.where(i % 7 == 0, 0.004, 0.0)
    t = 50.0 + i / FPS + late
    j = grid_jitter_ms(i, t)
    assert np.allclose(j[i % 7 != 0], 0.0, atol=1e-6) and np.allclose(j[i % 7 == 0], 4.0, atol=1e-6)
    # paced blocks of 512 at 44100 Hz from t0 = 7.0, each released 0.1 ms late
    sample = np.array([50_000, 90_000, 123_456])
    released = 7.0 + (sample // 512 + 1) * 512 / 44100 + 1e-4
    assert pacer_origin(released, sample, 512, 44100) == pytest.approx(7.0001)
    assert nominal_times(np.array([0, 29]), 7.0) == pytest.approx([7.0 + HOP / SAMPLE_RATE, 8.0])


def test_algorithmic_latency_terms():
    a = algorithmic_latency(22050, 735)  # blocks = hops at the feature rate: nothing to wait for
    assert a["resampler_lookahead_ms_max"] == 0.0 and a["block_wait_ms_max"] == 0.0 and a["total_ms_max"] == 0.0
    b = algorithmic_latency(44100, 512)
    assert b["resampler_lookahead_ms_max"] == pytest.approx(19 / 44100 * 1000)  # docs/features.md
    assert 0 < b["block_wait_ms_max"] <= 511 / 44100 * 1000
    assert b["block_wait_ms_mean"] == pytest.approx(b["block_ms"] / 2, rel=0.1)  # uniform phase over frames
    assert b["total_ms_max"] <= b["resampler_lookahead_ms_max"] + b["block_wait_ms_max"] + 1e-9
    assert algorithmic_latency(44100, 512, smoothing=0.5)["smoothing_ms"] == pytest.approx(1000 / FPS)


# -- the engine hooks the workers use -----------------------------------------------------------

def test_timing_sink_records_release_and_send_of_every_frame(checkpoint):
    from realtime.pipeline import build_pipeline

    p = build_pipeline(checkpoint)
    audio = 0.1 * np.random.default_rng(0).standard_normal(2 * 44100).astype(np.float32)
    asked = []
    src = ScheduledSource(FileSource(audio, 44100, block_size=512, realtime=False), lambda: asked.append(1) or 0.0)
    eng = Engine(src, p.extractor_factory, p.model, [], EngineConfig(warmup_s=0.1, stats_size=128))
    timing = TimingSink(100)
    eng.sinks.append(timing)
    eng.start()
    assert eng.wait(30), "the engine did not finish 2 s of audio within 30 s"
    eng.close()
    n = timing.count
    assert asked == [1] and src.started_at is not None
    expected = int(np.sum(samples_needed(np.arange(100), 44100) <= len(audio)))  # 59: frame 59 needs 19 more
    assert n == eng.frames_out == expected and timing.index[:n].tolist() == list(range(n))
    assert np.all(np.diff(timing.sample[:n]) > 0) and np.all(timing.sample[:n] < len(audio))
    assert np.all(np.isfinite(timing.released[:n])) and np.all(timing.sent[:n] >= timing.released[:n])
    assert np.allclose((timing.sent[:n] - timing.released[:n]) * 1000, eng.latency_ms.values()[:n])


# -- budgets ------------------------------------------------------------------------------------

def test_budgets_diff_names_metric_budget_measured_and_excess(tmp_path):
    f = tmp_path / "b.toml"
    f.write_text('[latency]\nper_hop_ms_p99 = { max = 5.0 }\nlost_frames = { max = 0 }\n'
                 '[streams]\nsustained_streams = { min = 8 }\n')
    budgets = bud.load_budgets(f)
    results = [{"kind": "latency", "label": "song", "metrics": {"per_hop_ms_p99": 7.5, "lost_frames": 0}},
               {"kind": "streams", "label": "streams", "metrics": {"sustained_streams": 6}}]
    verdicts = bud.check(results, budgets)
    assert [v.ok for v in verdicts] == [False, True, False]
    assert verdicts[0].over == pytest.approx(2.5) and verdicts[2].over == pytest.approx(2)
    text = bud.format_verdicts(verdicts)
    line = {ln.split()[1]: ln.split() for ln in text.splitlines()[1:]}
    assert line["per_hop_ms_p99"] == ["song", "per_hop_ms_p99", "<=", "5", "7.5", "2.5", "(+50%)", "OVER", "BUDGET"]
    assert line["lost_frames"][-1] == "ok"
    # a min budget is over by how much the result falls short of it
    assert line["sustained_streams"] == ["streams", "sustained_streams", ">=", "8", "6", "2", "(+25%)", "OVER", "BUDGET"]
    missing = bud.check([{"kind": "latency", "label": "x", "metrics": {}}], budgets[:1])
    assert not missing[0].ok and "not measured" in bud.format_verdicts(missing)


def test_a_metric_the_model_does_not_have_is_not_applicable_with_its_reason():
    budgets = [bud.Budget("latency", "model_step_naive_over_streaming", "min", 10.0),
               bud.Budget("latency", "per_hop_ms_p99", "max", 5.0)]
    r = {"kind": "latency", "label": "song", "metrics": {"per_hop_ms_p99": 2.0},
         "not_applicable": {"model_step_naive_over_streaming": "no naive recompute for this model"}}
    na, hop = bud.check([r], budgets)
    assert na.ok and na.measured is None and na.not_applicable == "no naive recompute for this model" and hop.ok
    text = bud.format_verdicts([na, hop])
    assert "model_step_naive_over_streaming  >= 10" in text and text.splitlines()[1].split()[-1] == "n/a"
    assert text.splitlines()[-1] == "n/a model_step_naive_over_streaming: no naive recompute for this model"
    assert bud.format_verdicts([na, hop], only_failures=True).count("\n") == 0  # header only
    # a metric missing without a reason still fails
    del r["not_applicable"]
    assert not bud.check([r], budgets)[0].ok


def test_model_step_and_stream_vs_offline_measure_both_live_model_kinds(tmp_path, checkpoint):
    """The suite's in-process figures for a causal U-Net (naive baseline, ratio) and a dance_vq
    model (no naive baseline: code steps timed apart, the reason recorded), and streaming ==
    offline for both."""
    from models.generate import load_model
    from realtime.bench.suite import model_step_costs, naive_baseline, stream_vs_offline

    from tests.test_dance_vq import tiny_checkpoint

    vq, _, fcfg = tiny_checkpoint(tmp_path / "vq.pt")
    dim = fcfg.dim
    x = np.random.default_rng(0).normal(scale=0.5, size=(300, dim)).astype(np.float32)
    ms = model_step_costs(vq, x, frames=16)
    assert ms["naive_us"] is None and ms["ratio_p50"] is None and "offline pass" in ms["naive_reason"]
    assert ms["streaming_us"]["n"] == 960 and ms["code_step_us"]["n"] == 120 and ms["other_us"]["n"] == 840
    assert naive_baseline(load_model(vq).model)[0] is None
    so = stream_vs_offline(vq, x)
    assert so["frames"] == 300 and so["max_abs"] < 1e-4

    unet = load_model(checkpoint)
    x = np.random.default_rng(1).normal(scale=0.5, size=(200, unet.features.dim)).astype(np.float32)
    ms = model_step_costs(checkpoint, x, frames=8, rounds=2)
    assert ms["naive_us"]["n"] == ms["streaming_us"]["n"] == 8 and ms["ratio_p50"] > 1
    assert naive_baseline(unet.model)[0] is not None
    assert stream_vs_offline(checkpoint, x)["max_abs"] < 1e-4


def test_not_applicable_checks_are_counted_apart_from_passes():
    budgets = [bud.Budget("latency", "model_step_naive_over_streaming", "min", 10.0),
               bud.Budget("latency", "per_hop_ms_p99", "max", 5.0), bud.Budget("latency", "lost_frames", "max", 0)]
    r = {"kind": "latency", "label": "x", "metrics": {"per_hop_ms_p99": 3.0, "lost_frames": 1},
         "not_applicable": {"model_step_naive_over_streaming": "no naive recompute"}}
    assert bud.tally(bud.check([r], budgets)) == ("1 of 2 budget checks within budget, 1 over budget; "
                                                  "1 not applicable (not counted)")


def test_quiet_budget_is_not_applicable_while_other_processes_hold_the_cpus(tmp_path):
    f = tmp_path / "b.toml"
    f.write_text("[quiet]\nothers_busy_percent = 10\n"
                 "[latency]\ne2e_osc_ms_p99 = { max = 15.0, quiet = true }\nlost_frames = { max = 0 }\n")
    budgets = bud.load_budgets(f)

    def verdicts(busy: float | None) -> list[bud.Verdict]:
        m = {"e2e_osc_ms_p99": 40.0, "lost_frames": 0} | ({} if busy is None else {"others_busy_percent": busy})
        return bud.check([{"kind": "latency", "label": "clip", "metrics": m}], budgets)

    e2e, lost = verdicts(63.4)  # a shared machine: the wall-clock target is n/a, with the share
    assert e2e.ok and e2e.not_applicable is not None and "63% of the CPUs" in e2e.not_applicable and lost.ok
    assert bud.format_verdicts([e2e]).splitlines()[1].split()[-3:] == ["40", "-", "n/a"]  # the figure, shown
    assert bud.tally([e2e, lost]) == "1 of 1 budget checks within budget, 0 over budget; 1 not applicable (not counted)"
    import os

    from realtime.bench.suite import others_busy_percent

    # the machine's busy share less the benchmark's own processes (performers, receiver)
    run = {"streams": [{"cpu_s": 3.0}, {"cpu_s": 1.0}], "receiver_cpu_s": 1.0, "wall_s": 10.0, "machine_busy_percent": 80.0}
    assert others_busy_percent(run) == pytest.approx(80.0 - 50.0 / (os.cpu_count() or 1))
    assert others_busy_percent({**run, "machine_busy_percent": 1.0}) == 0.0
    for busy in (4.0, None):  # a quiet machine, or a result without the figure: checked
        e2e, _ = verdicts(busy)
        assert e2e.not_applicable is None and not e2e.ok


def test_lane_cycle_is_the_costliest_cycle_position_of_any_performer_robust_to_a_busy_few_frames():
    """Per performer and position of its 8-frame cycle, the median lane CPU time: 1 ms more
    on one performer's code steps (1 frame in 8) moves the figure by 1 ms; slow frames
    on a busy machine (10% of all, anywhere) do not."""
    from realtime.bench.suite import lane_cycle_ms

    rng = np.random.default_rng(0)
    idx = np.arange(600)

    def lanes(extra_ms: float) -> list[dict]:
        out = []
        for j, phase in enumerate((0, 2, 4, 6)):
            cpu = 0.3 + 0.01 * rng.random(600) + 0.6 * ((idx + phase) % 8 == 0)  # code step: +0.6 ms
            cpu += rng.choice([0.0, 5.0], size=600, p=[0.9, 0.1])  # a busy machine's slow frames
            if j == 0:
                cpu += extra_ms * (idx % 8 == 0)
            out.append({"index": idx.tolist(), "phase": phase, "lane_cpu_ms": cpu.tolist()})
        return out

    clean, planted = lane_cycle_ms(lanes(0.0), 8), lane_cycle_ms(lanes(1.0), 8)
    assert clean["ms"] == pytest.approx(0.905, abs=0.01) and clean["position"] == 0
    assert planted["ms"] == pytest.approx(1.905, abs=0.01) and (planted["lane"], planted["position"]) == (0, 0)
    assert np.shape(planted["medians"]) == (4, 8)


def test_hop_cycle_peak_sees_code_steps_piled_on_one_hop():
    """4 performers whose code steps (+0.6 ms) fall on 4 of the 8 positions: the costliest
    position stands little above the median one; all 4 on position 0 (no stagger): far above."""
    from realtime.bench.suite import hop_cycle_peak

    idx = np.arange(600)
    staggered = 2.0 + 0.6 * (idx % 2 == 0)  # one code step on every other hop
    piled = 2.0 + 2.4 * (idx % 8 == 0)
    assert hop_cycle_peak(idx, staggered, 8) == pytest.approx(2.6 / 2.3)
    assert hop_cycle_peak(idx, piled, 8) == pytest.approx(2.2) and hop_cycle_peak(idx, piled, 1) == 1.0


def test_hop_cycle_medians_see_work_added_to_every_hop():
    """The whole hop's median per position (hop_cycle_over_reference's numerator): 1 ms more on
    every hop (an input-stage regression, which no lane ratio sees) moves every median by 1 ms,
    rare slow hops (a busy machine) move none."""
    from realtime.bench.suite import hop_cycle_medians

    idx = np.arange(600)
    base = 2.0 + 0.6 * (idx % 2 == 0)
    busy = base + 20.0 * (idx % 37 == 0)  # a slow hop now and then, on every position
    assert hop_cycle_medians(idx, base, 8) == pytest.approx([2.6, 2.0] * 4)
    assert hop_cycle_medians(idx, busy, 8) == pytest.approx([2.6, 2.0] * 4)
    assert hop_cycle_medians(idx, base + 1.0, 8) == pytest.approx([3.6, 3.0] * 4)
    nan = hop_cycle_medians(idx[:3], base[:3], 8)
    assert nan[:3] == pytest.approx([2.6, 2.0, 2.6]) and np.isnan(nan[3:]).all()


def test_own_hop_time_is_the_wall_time_less_the_run_queue_wait():
    from realtime.bench.suite import own_hop_ms

    np.testing.assert_allclose(own_hop_ms([3.0, 9.0, 2.0], [0.0, 6.5, 0.1]), [3.0, 2.5, 1.9])
    assert np.isnan(own_hop_ms([3.0, 4.0], [0.5])[1]) and np.isnan(own_hop_ms([3.0], None)).all()


def test_run_queue_clock_counts_the_time_another_thread_held_the_cpu():
    """Two busy threads on one CPU: the clock the engine reads around each hop
    (EngineConfig.runqueue_wait) sees each run about half of the time and the process wait
    for the CPU, and a hop's wait never leaves less than the worker's CPU time (Linux)."""
    import os
    import threading

    from realtime.runqueue_clock import RunQueueClock, hop_wait

    assert hop_wait(wall=10.0, waited=9.0, on_cpu=3.0) == 7.0 and hop_wait(10.0, 2.0, 3.0) == 2.0
    if not os.path.exists("/proc/thread-self/schedstat") or not hasattr(os, "sched_setaffinity"):
        pytest.skip("no /proc/thread-self/schedstat here")
    cpu = min(os.sched_getaffinity(0))
    got = {}
    both = threading.Barrier(2)

    def spin(key: str) -> None:
        os.sched_setaffinity(0, {cpu})  # this thread only
        clock = RunQueueClock()
        both.wait()
        (w0, c0), t0 = clock(), time.perf_counter()
        while time.perf_counter() - t0 < 0.6:
            pass
        (w1, c1), wall = clock(), time.perf_counter() - t0
        got[key] = ((w1 - w0) / wall, (c1 - c0) / wall)

    threads = [threading.Thread(target=spin, args=(k,)) for k in "ab"]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for waited, on_cpu in got.values():  # each thread ran about half the time and waited for the other
        assert 0 < on_cpu < 0.8 and waited > 0.1, got  # (a wait is booked when the thread gets the CPU back)


def test_run_queue_clock_reads_open_files_and_follows_the_threads():
    """The clock keeps each thread's schedstat open (a read is one pread: the engine reads it
    around every audio block, outside the hop it times), opens a new thread's at the next
    refresh and closes an ended one's; ``after=True`` gives the same figures (Linux)."""
    import os
    import threading

    from realtime.runqueue_clock import RunQueueClock

    if not os.path.exists("/proc/thread-self/schedstat"):
        pytest.skip("no /proc/thread-self/schedstat here")
    clock = RunQueueClock()
    clock()
    assert set(clock._fds) == set(os.listdir("/proc/self/task"))
    fds = dict(clock._fds)
    for _ in range(3):
        clock()
        clock(after=True)
    assert clock._fds == fds, "the files were opened again"
    stop = threading.Event()
    t = threading.Thread(target=stop.wait)
    t.start()
    clock._listed = -1e9  # the next read lists the threads again
    clock()
    assert str(t.native_id) in clock._fds
    stop.set()
    t.join()
    for _ in range(200):  # the ended thread's file: its read fails once the kernel is done with it
        waited, on_cpu = clock(after=True)
        if str(t.native_id) not in clock._fds:
            break
        time.sleep(0.01)
    assert str(t.native_id) not in clock._fds and waited >= 0 and on_cpu > 0


@pytest.mark.parametrize("text, needle", [
    ("[latency]\nper_hop_ms_p99 = 5.0\n", "expected { max = X }"),
    ("[latency]\nper_hop_ms_p99 = { most = 5.0 }\n", "expected { max = X }"),
    ("[latency]\nper_hop_ms_p99 = { max = 'five' }\n", "must be a number"),
    ("[speed]\nx = { max = 1 }\n", "unknown budget table [speed]"),
    ("[latency\n", "cannot read budgets"),
    ("[latency]\nper_hop_ms_p99 = { max = 5.0, scaled_by = \"reference_ms\" }\n", "expected { max = X }"),
    ("[reference]\np50_ms = 1.0\n", "unknown budget table [reference]"),
    ("[streams]\nsustained_streams = { min = 8, quiet = true }\n", "needs a [quiet] table"),
    ("[quiet]\nothers_busy_percent = 10\n[streams]\nsustained_streams = { min = 8, quiet = 1 }\n",
     "quiet must be true or false"),
    ("[quiet]\nothers_busy_percent = 120\n", "expected others_busy_percent = a percentage"),
])
def test_bad_budgets_file_is_a_config_error_naming_the_file(tmp_path, text, needle):
    from models.errors import ConfigError

    f = tmp_path / "b.toml"
    f.write_text(text)
    with pytest.raises(ConfigError) as e:
        bud.load_budgets(f)
    assert str(f) in str(e.value) and needle in str(e.value)


def test_bench_check_cli_exit_status_and_diff(tmp_path, capsys):
    (tmp_path / "r").mkdir()
    (tmp_path / "r" / "latency.json").write_text(json.dumps(
        {"kind": "latency", "label": "clip", "metrics": {"per_hop_ms_p99": 3.0, "e2e_osc_ms_p99": 40.0}}))
    ok, over = tmp_path / "ok.toml", tmp_path / "over.toml"
    ok.write_text("[latency]\nper_hop_ms_p99 = { max = 5.0 }\n")
    over.write_text("[latency]\nper_hop_ms_p99 = { max = 5.0 }\ne2e_osc_ms_p99 = { max = 15.0 }\n")
    assert main(["bench", "check", "--budgets", str(ok), str(tmp_path / "r")]) == 0
    capsys.readouterr()
    assert main(["bench", "check", "--budgets", str(over), str(tmp_path / "r")]) == 1
    err = capsys.readouterr().err
    assert "1 of 2 budget checks within budget, 1 over budget" in err and "e2e_osc_ms_p99" in err
    assert "25 (+167%)" in err
    assert main(["bench", "check", "--budgets", str(ok), str(tmp_path / "nothing")]) == 2


def test_bench_cli_bad_inputs_exit_2_with_one_line(tmp_path, capsys):
    assert main(["bench", "latency", "--audio", str(tmp_path / "missing.wav"), "--out", str(tmp_path)]) == 2
    assert "missing.wav: audio file not found" in capsys.readouterr().err
    assert main(["bench", "latency", "--cores", "0,999", "--out", str(tmp_path), "--seconds", "1"]) == 2
    assert "CPU(s) [999] not available" in capsys.readouterr().err
    assert main(["bench", "streams", "--counts", "0", "--out", str(tmp_path)]) == 2
    with pytest.raises(SystemExit):
        main(["bench", "latency", "--cores", "a,b", "--out", str(tmp_path)])


def test_bench_latency_lead_reaches_the_performer_process(tmp_path, capsys, checkpoint):
    """--lead goes to the performer process's pipeline: a causal U-Net there refuses it."""
    code = main(["bench", "latency", "--seconds", "1", "--naive-seconds", "0", "--no-offline", "--warmup", "0.2",
                 "--checkpoint", str(checkpoint), "--out", str(tmp_path), "--lead", "67"])
    assert code == 2 and "model 'causal' has no lead control" in capsys.readouterr().err


# -- short real-time runs (guard budgets) --------------------------------------------------------

@pytest.mark.latency
@pytest.mark.slow
def test_shipped_default_latency_run_within_guard_budgets(tmp_path, capsys):
    """8 s of the clip through the shipped default (no --checkpoint) against :data:`GUARDS`."""
    from models.generate import default_checkpoint_path, load_model

    assert load_model(default_checkpoint_path()).name == "dance_vq"
    guards = tmp_path / "guards.toml"
    guards.write_text(GUARDS)
    budgets = {b.metric: b.limit for b in bud.load_budgets(REPO / "benchmarks" / "budgets.toml") if b.kind == "latency"}
    for b in bud.load_budgets(guards):  # the guards are what the docstring says: 5x the targets
        own = "per_hop_ms_p99_own" if b.metric == "per_hop_ms_p99" else b.metric  # the wall time against 5x the own-time budget
        assert b.limit == (2 if b.metric == "lost_frames" else 5 * budgets[own]), b
    out = tmp_path / "out"
    code = main(["bench", "latency", "--audio", str(bundled_clip_path()), "--seconds", "8", "--naive-seconds", "0",
                 "--no-offline", "--warmup", "1", "--out", str(out), "--budgets", str(guards)])
    printed = capsys.readouterr().out
    assert code == 0, printed
    for name in ("latency.json", "latency.md", "latency_hist.png", "latency_timeline.png", "frames.npz"):
        assert (out / name).stat().st_size > 0
    r = json.loads((out / "latency.json").read_text())
    assert r["checkpoint_source"] == "packaged default" and r["checkpoint"] == str(default_checkpoint_path())
    s, a = r["streaming"], r["algorithmic"]
    assert s["frames"] == 8 * FPS - 1 and s["lost_osc"] == 0 and s["lost_ws"] == 0
    # causality of the measurement: release <= send <= receipt, per the medians
    assert 0 < s["send_ms"]["p50"] <= s["e2e_osc_ms"]["p50"] and s["send_ms"]["p50"] <= s["e2e_ws_ms"]["p50"]
    # the measured wait from a frame's nominal time to its block's release is the designed one
    assert -1.0 < s["release_after_nominal_ms"]["p50"] < a["total_ms_max"] + 5.0
    assert s["audio_to_osc_ms"]["p50"] == pytest.approx(
        s["release_after_nominal_ms"]["p50"] + s["e2e_osc_ms"]["p50"], abs=a["block_ms"])
    assert 30 < s["interval_ms"]["mean"] < 37 and s["peak_rss_mb"] > 50
    assert "per_hop_ms_p99" in printed and "OVER BUDGET" not in printed
    assert r["command"].startswith("performer ")


@pytest.mark.latency
@pytest.mark.slow
def test_stream_sweep_runs_concurrent_performers(tmp_path, checkpoint):
    from realtime.bench.suite import BenchConfig, run_streams

    r = run_streams([bundled_clip_path()], BenchConfig(checkpoint=checkpoint, warmup_s=0.5), counts=[2],
                    seconds=3.0, stop_on_fail=False)
    (row,) = r["rows"]
    # at 44.1 kHz the last frame of the 3 s would need 19 samples more (resampler look-ahead)
    assert row["streams"] == 2 and row["frames"] == 2 * (3 * FPS - 1) and row["lost_frames"] <= 2
    assert row["worst_p99_e2e_ms"] < 150.0  # guard, not the 33.3 ms criterion
    assert r["sustained_streams"] == (2 if row["pass"] else 0)


@pytest.mark.latency
@pytest.mark.slow
def test_ensemble_bench_runs_performers_in_one_process_and_apart(tmp_path, capsys):
    """``performer bench ensemble``: 2 dance_vq performers in one process (one extractor, code
    steps staggered 0 and 4) and as 2 processes, every frame received, the markdown table, and
    each stagger phase's stream equal to its offline pass."""
    from tests.test_dance_vq import tiny_checkpoint

    vq, _, _ = tiny_checkpoint(tmp_path / "vq.pt")
    out = tmp_path / "out"
    budgets = tmp_path / "b.toml"
    budgets.write_text("[ensemble]\nstream_offline_max_abs = { max = 1e-4 }\nlost_frames = { max = 0 }\n"
                       "per_hop_ms_p99_2 = { max = 150 }\n")
    code = main(["bench", "ensemble", "--counts", "2", "--unstaggered", "--seconds", "3", "--warmup", "0.5",
                 "--checkpoint", str(vq), "--out", str(out), "--budgets", str(budgets)])
    printed = capsys.readouterr().out
    assert code == 0, printed
    r = json.loads((out / "ensemble.json").read_text())
    one, apart = r["rows"]
    assert (one["mode"], apart["mode"]) == ("one process", "separate processes")
    assert one["extractors"] == 1 and apart["extractors"] == 2 and one["phases"] == [0, 4]
    assert one["frames"] == apart["frames"] == 2 * (3 * FPS - 1) and one["lost_frames"] == 0
    assert one["per_hop_ms_p99"] >= one["features_ms_p50"] > 0 and len(one["performer_part_ms_p50"]) == 2
    assert [c["phase"] for c in r["stream_vs_offline"]] == [0, 4] and r["metrics"]["stream_offline_max_abs"] < 1e-4
    assert "| 2 | one process |" in printed and "| 2 | separate processes |" in printed
    assert (out / "ensemble.md").stat().st_size > 0 and (out / "ensemble.png").stat().st_size > 0


@pytest.mark.latency
@pytest.mark.slow
def _with_absolute_guards(src: Path, dst: Path) -> Path:
    """``src`` (budgets.toml) written to ``dst`` with every absolute wall-clock limit (``quiet =
    true``, ``max``) at 5x its target, as :data:`GUARDS` does for the latency run: a test asserts a guard
    against gross regressions, ``make bench`` the targets. One 10-s run of 4 performers on this
    AVX-512 Xeon, nothing else running, reads own p99 4.0-6.1 ms against the 5 ms target (a CI run
    failed on 7.34), and the same code reads 3.3-3.5 in `make bench`'s longer runs."""
    lines = []
    for line in src.read_text().splitlines():
        if not line.lstrip().startswith("#") and "quiet = true" in line and "{ max = " in line:
            head, rest = line.split("{ max = ", 1)
            limit, tail = rest.split(",", 1)
            line = f"{head}{{ max = {5 * float(limit):g},{tail}"
        lines.append(line)
    dst.write_text("\n".join(lines) + "\n")
    want = [(b.kind, b.metric, b.op, 5 * b.limit if b.quiet and b.op == "max" else b.limit)
            for b in bud.load_budgets(src)]
    assert [(b.kind, b.metric, b.op, b.limit) for b in bud.load_budgets(dst)] == want
    assert ("ensemble", "per_hop_ms_p99_own_4", "max", 25.0) in want
    return dst


def test_ensemble_budget_passes_clean_and_fails_a_planted_regression(tmp_path, capsys):
    """`make bench`'s ensemble part with benchmarks/budgets.toml, on the shipped model, 4
    performers in one process for 10 s: clean, every budget holds (the absolute wall-clock
    ones as guards of 5x their targets, :func:`_with_absolute_guards`; n/a while other
    processes hold the CPUs); with 1 ms of extra work every 8th frame
    in one performer's lane (the hidden --inject-ms hook, on that performer's code-step
    frames), the budget on the costliest point of the cost cycle over the reference
    workload of the same run, lane_cycle_over_reference_4, fails (docs/latency.md, "Budgets
    on a shared machine"); with 2 ms on every frame, as an input-stage regression would add
    to every hop, the whole hop's budget hop_cycle_over_reference_4 fails."""
    budgets = _with_absolute_guards(REPO / "benchmarks" / "budgets.toml", tmp_path / "budgets.toml")
    verdicts, lines = {}, []
    # the clean run twice at most: a ratio of two CPU times on a shared 2-core machine reads
    # 1.77-1.91 against its 2.6 budget on an AVX-512 Xeon (planted 3.18-3.38 there);
    # a real regression fails both tries, as the planted ones below do
    runs = (("clean", []), ("clean, again", []), ("planted", ["--inject-ms", "1", "--inject-every", "8"]),
            ("every hop", ["--inject-ms", "2", "--inject-every", "1"]))
    for name, extra in runs:
        if name == "clean, again" and verdicts["clean"][0] == 0 and all(x.ok for x in verdicts["clean"][1].values()):
            continue
        out = tmp_path / name.replace(" ", "_").replace(",", "")
        code = main(["bench", "ensemble", "--counts", "4", "--no-separate", "--unstaggered", "--seconds", "10",
                     "--out", str(out), "--budgets", str(budgets), *extra])
        printed = capsys.readouterr().out
        r = json.loads((out / "ensemble.json").read_text())
        verdicts[name] = (code, {v.budget.metric: v for v in bud.check([r], bud.load_budgets(budgets))}, printed)
        m = r["metrics"]
        lines.append(f"{name}: lane cycle {m['lane_cycle_ms_4']:.2f} ms / reference CPU {r['rows'][0]['reference_cpu_ms_p50']:.2f}"
              f" = {m['lane_cycle_over_reference_4']:.2f}; hop cycle peak {m['hop_cycle_peak_4']:.2f}; hop cycle / reference "
              f"{m['hop_cycle_over_reference_4']:.2f}; own p99 {m['per_hop_ms_p99_own_4']:.2f}; wall p99 "
              f"{m['per_hop_ms_p99_4']:.2f}; other processes {m['others_busy_percent']:.0f}% of the CPUs")
    print("\n".join(lines))
    code, v, printed = verdicts.get("clean, again", verdicts["clean"])
    assert code == 0 and all(x.ok for x in v.values()), printed
    code, v, printed = verdicts["every hop"]  # work on every hop, as an input-stage regression would add
    assert code == 1 and not v["hop_cycle_over_reference_4"].ok, printed
    code, v, printed = verdicts["planted"]
    assert code == 1 and not v["lane_cycle_over_reference_4"].ok, printed
    assert r["rows"][0]["lane_cycle_at"] == [0, 0]  # the first performer's code step, where the work was planted
    assert "Planted regression" in (tmp_path / "planted" / "ensemble.md").read_text()
