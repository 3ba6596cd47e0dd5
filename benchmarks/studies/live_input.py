"""The performer on a real live input against the same song from the file, the same seeds (docs/latency.md).

Live: a private PulseAudio server (realtime/pulse.py), the song played into its null sink in real
time by ``pacat``, the engine of ``performer run --input-device pulse`` capturing the monitor through
PortAudio (44.1 kHz), the shipped model with seed s, in this process. Each of ``--runs`` live runs
(seeds --seed, --seed+1, ...) keeps a copy of every captured block (a tap on the engine's ring) to
find where the song starts in the input (cross-correlation, to the sample): the silence it heard
first. Its control: the file after exactly that silence, the same seed, through the same engine as
fast as it goes: the same input but for what the live path changed (a song's start point alone moves
the dance's random draws, so a live run against one file replay compares two draws).

Printed: per run and as mean +- sd [min, max] of each side, the beat hit rate (kinematic beats
within 2 frames of librosa's beats of the song), the mean joint speed, the followed tempo (median
over the song, bpm), the ratios of the means (live / file) and the paired ratios; the live input's
drift (where the song's last 2 s lie in the capture against where its first 2 s put them: samples
the live path lost, negative, or added), its level against the song's RMS (dB), and the sound-to-pose
latency of each frame (its send time minus the moment its last sample was handed to pacat: the audio
server's path and pacat's start are inside it), p50 and p99. Once, the file in real time (run 1's
seed and silence): its latency, the baseline. ``--draws N``: N offline passes of the file after
random silences, their followed tempo (whether the octave depends on where the song starts).

    .venv/bin/python benchmarks/studies/live_input.py --data ../shared/data/dwm --runs 5 --draws 10
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))
RATE = 44100


class Collect:
    """A sink keeping (audio_sample, wall_time, pose, the model's tempo (bpm) and idle weight) of every frame."""

    name = "collect"

    def __init__(self, model) -> None:
        self.model = model
        self.rows: list[tuple[int, float, np.ndarray, float, float]] = []

    def send(self, frame) -> None:
        self.rows.append((frame.audio_sample, frame.wall_time, frame.pose.copy(), self.model.tempo_bpm,
                          self.model.idle_weight))

    def stats(self) -> dict:
        return {"frames": len(self.rows)}

    def close(self) -> None:
        pass


class TapRing:
    """The engine's ring, with a copy of every block written (and its release time) kept."""

    def __init__(self, ring) -> None:
        self._ring, self.blocks, self.started = ring, [], time.monotonic()

    def write(self, block, release_time=None):
        self.blocks.append((np.array(block, np.float32), release_time))
        return self._ring.write(block, release_time)

    def __getattr__(self, name):
        return getattr(self._ring, name)


def run_engine(source, seconds: float, play=None, seed: int = 0) -> tuple[Collect, float | None]:
    """Stream ``source`` through the engine and the shipped model (``seed``); ``play``: started after
    2 s of the input (the live run), the engine stopped 1 s after it ends; else until the source ends.
    Returns the frames and the monotonic time ``play`` was started (None without it)."""
    from realtime.engine import Engine
    from realtime.engine_config import EngineConfig
    from realtime.pipeline import build_pipeline

    pipe = build_pipeline(None, seed=seed)
    sink = Collect(pipe.model)
    engine = Engine(source, pipe.extractor_factory, pipe.model, [sink], EngineConfig(warmup_s=0.5))
    engine.start()
    t_play = None
    if play is not None:
        time.sleep(2.0)
        t_play = time.monotonic()
        proc = play()
        proc.wait(timeout=seconds + 30)
        time.sleep(1.0)
    else:
        engine.wait(seconds + 30)
    engine.stop()
    return sink, t_play


def song_frames(sink: Collect, s0: int, frames: int, t0: float) -> tuple[np.ndarray, np.ndarray]:
    """Poses (frames, P) numbered from the song's start (input sample ``s0``), and each one's
    latency (s): send time minus ``t0 + (audio_sample - s0) / RATE``."""
    from models.timebase import HOP

    step = 2 * HOP  # a frame's samples at 44.1 kHz
    poses, lat = np.full((frames, len(sink.rows[0][2])), np.nan, np.float32), np.full(frames, np.nan)
    state = np.full((frames, 2), np.nan)
    for sample, wall, pose, tempo, idle in sink.rows:
        k = int(round((sample - s0) / step)) - 1
        if 0 <= k < frames:
            poses[k], lat[k], state[k] = pose, wall - (t0 + (sample - s0) / RATE), (tempo, idle)
    return poses, lat, state


def song_figures(poses: np.ndarray, state: np.ndarray, beats: np.ndarray) -> dict:
    """A run's figures over its song frames (frames, P) up to the first missing one: beat hit, mean
    joint speed (m/s), the followed tempo's median (bpm), its share of frames above 95 bpm (the
    faster of the song's two octaves in range: ~126 against ~63) and from when on it stays there (s
    into the song; None: never there), the share of idle frames."""
    from models.evaluation.listening import beat_hits, mean_speed, positions

    ok = ~np.isnan(poses).any(axis=1)
    n = int(np.argmin(ok)) if not ok.all() else len(poses)
    pos = positions(poses[:n])
    hit, control = beat_hits(pos, beats)
    tempo = state[:n, 0]
    return {"frames": n, "beat_hit": hit, "beat_hit_half_shifted": control, "mean_speed": mean_speed(pos),
            "tempo_bpm_median": float(np.nanmedian(tempo)), "fast_octave_share": float(np.mean(tempo > 95.0)),
            "fast_octave_from_s": float(np.flatnonzero(~(tempo > 95.0))[-1] + 1) / 30 if (tempo > 95.0).any() else None,
            "idle_share": float(np.mean(state[:n, 1] > 0.5))}


def file_draws(mono: np.ndarray, frames: int, beats: np.ndarray, n: int, seed: int = 0) -> list[dict]:
    """The octave's spread from the file alone: the excerpt streamed offline (frame by frame, as fast
    as it goes) through the model (``seed``) after ``n`` random silences of 0.5-2.5 s: each one's
    :func:`song_figures` (where a song starts moves the draws and the tempo follower's first seconds)."""
    from models.timebase import HOP
    from realtime.pipeline import build_pipeline

    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        pipe = build_pipeline(None, seed=seed)
        prefix = int(rng.integers(RATE // 2, 5 * RATE // 2))
        audio = np.concatenate([np.zeros(prefix, np.float32), mono.astype(np.float32)])
        feats = pipe.extractor_factory(RATE).push(audio)
        poses, state = [], []
        for f in feats:
            for pose in pipe.model.push(f[None]):
                poses.append(pose)
                state.append((pipe.model.tempo_bpm, pipe.model.idle_weight))
        ends = (np.arange(len(poses)) + 1) * 2 * HOP  # each frame's last input sample
        k = np.rint((ends - prefix) / (2 * HOP)).astype(int) - 1
        keep = k >= 0
        fig = song_figures(np.asarray(poses)[keep][:frames], np.asarray(state)[keep][:frames], beats)
        out.append({"silence_s": prefix / RATE, **fig})
    return out


def spread(values: list[float]) -> dict:
    """Mean, standard deviation (n-1), min and max of ``values``."""
    v = np.asarray(values, np.float64)
    return {"mean": float(v.mean()), "sd": float(v.std(ddof=1)) if len(v) > 1 else 0.0,
            "min": float(v.min()), "max": float(v.max())}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", required=True, help="the dwm directory (../shared/data/dwm)")
    p.add_argument("--song", default="DANCE_C_2", help="a dance of --data (default DANCE_C_2)")
    p.add_argument("--start-s", type=float, default=30.0, help="where the excerpt starts, s (default 30)")
    p.add_argument("--seconds", type=float, default=60.0, help="excerpt length, s (default 60)")
    p.add_argument("--runs", type=int, default=5,
                   help="live runs, seeds --seed.. --seed+runs-1, each against the file with its seed and silence (default 5)")
    p.add_argument("--seed", type=int, default=0, help="the first run's seed (default 0)")
    p.add_argument("--pacat-latency-ms", type=int, default=100,
                   help="the player's buffer (default 100: a shorter one underruns on a busy machine)")
    p.add_argument("--no-file-latency", action="store_true",
                   help="skip the file replayed in real time (the sound-to-pose baseline; one run, 1 min)")
    p.add_argument("--draws", type=int, default=0,
                   help="also N offline passes of the file after random silences (the octave's and the draws' spread)")
    p.add_argument("--json", metavar="FILE", help="write the figures here")
    a = p.parse_args(argv)
    for flag, value, low in (("--runs", a.runs, 1), ("--seconds", a.seconds, 10), ("--draws", a.draws, 0)):
        if value < low:
            p.error(f"{flag} must be >= {low}, got {value}")
    path = Path(a.data) / a.song / "audio.mp3"
    if not path.is_file():
        p.error(f"no song at {path}")
    import soundfile as sf

    x, sr = sf.read(str(path), dtype="float32", always_2d=True, start=int(a.start_s * RATE),
                    frames=int(a.seconds * RATE))
    if sr != RATE:
        p.error(f"{path}: {sr} Hz, expected {RATE}")
    from models.errors import AudioError
    from realtime.pulse import PulseServer

    try:
        pulse = PulseServer()
    except AudioError as exc:
        p.error(str(exc))
    import librosa

    from models.evaluation.listening import heard_beats

    mono = x.mean(axis=1)
    frames = int(a.seconds * 30) - 2
    beats = heard_beats(librosa.resample(mono, orig_sr=RATE, target_sr=22050))
    rms = lambda v: float(10 * np.log10(np.mean(np.asarray(v, np.float64) ** 2) + 1e-20))  # noqa: E731
    out: dict = {"song": a.song, "start_s": a.start_s, "seconds": a.seconds, "pacat_latency_ms": a.pacat_latency_ms,
                 "song_rms_dbfs": rms(mono), "runs": []}
    with pulse:
        os.environ.update(pulse.env)  # before PortAudio starts: its ALSA pulse device reads them
        from realtime.audio_input import DeviceSource, FileSource
        from scipy.signal import correlate

        for i in range(a.runs):
            seed = a.seed + i
            dev = DeviceSource("pulse", sample_rate=RATE)
            start = dev.start
            tap: list[TapRing] = []
            dev.start = lambda ring, start=start, tap=tap: start(tap.append(TapRing(ring)) or tap[0])  # type: ignore[method-assign]
            live, t_play = run_engine(dev, a.seconds, seed=seed,
                                      play=lambda: pulse.play(x, latency_ms=a.pacat_latency_ms))
            heard = np.concatenate([b for b, _ in tap[0].blocks]).mean(axis=1)
            s0 = int(np.argmax(correlate(heard, mono[: 2 * RATE], "valid", method="fft")))  # the song's sample 0
            tail = mono[-2 * RATE:]  # where the song's last 2 s are: samples the live path lost (-) or added (+)
            lo = s0 + len(mono) - len(tail) - RATE
            drift = int(np.argmax(correlate(heard[lo: lo + len(tail) + 2 * RATE], tail, "valid", method="fft"))) - RATE
            poses, lat, state = song_frames(live, s0, frames, t_play)
            ends = np.cumsum([len(b) for b, _ in tap[0].blocks])  # each captured block's last sample
            t_cap = np.array([t for _, t in tap[0].blocks], np.float64)
            song = (ends > s0) & (ends <= s0 + len(mono))
            gaps = np.diff(t_cap[song]) * 1000  # ms between the capture's callbacks during the song
            row = {"seed": seed, "silence_s": s0 / RATE, "drift_samples": drift,
                   "input_overflows": dev.input_overflows, "input_underflows": dev.input_underflows,
                   "heard_rms_dbfs": rms(heard[s0: s0 + len(mono)]),
                   "capture_gap_ms_p50": float(np.median(gaps)), "capture_gap_ms_max": float(gaps.max()),
                   "first_block_after_start_s": float(t_cap[0] - tap[0].started),
                   "live": {**song_figures(poses, state, beats), "latency_ms_p50": float(np.nanmedian(lat) * 1000),
                            "latency_ms_p99": float(np.nanpercentile(lat, 99) * 1000)}}
            # the control: the same seed, the file after exactly the silence this live run heard, through
            # the same engine as fast as it goes (the same input but for what the live path changed)
            same = FileSource(np.concatenate([np.zeros((s0, x.shape[1]), np.float32), x]), RATE, realtime=False)
            filed, _ = run_engine(same, a.seconds, seed=seed)
            fposes, _, state = song_frames(filed, s0, frames, 0.0)
            row["file"] = song_figures(fposes, state, beats)
            heard_song = np.concatenate([b for b, _ in tap[0].blocks])[s0: s0 + len(x)]
            differ = np.flatnonzero((heard_song != x[: len(heard_song)]).any(axis=1))
            row["heard_exact_share"] = 1.0 - len(differ) / len(heard_song)  # samples (frames) as played
            row["heard_differs_until_ms"] = float((differ[-1] + 1) / RATE * 1000) if len(differ) else 0.0
            apart = np.flatnonzero(np.abs(poses - fposes).max(axis=1) > 1e-4)  # NaN (missing) compares False
            row["poses_apart_from_s"] = float(apart[0] / 30) if len(apart) else None
            out["runs"].append(row)
            print(f"run {i + 1}/{a.runs} seed {seed}: silence {s0 / RATE:.2f} s, drift {drift} samples, "
                  f"beat hit live {row['live']['beat_hit']:.3f} file {row['file']['beat_hit']:.3f}, "
                  f"tempo live {row['live']['tempo_bpm_median']:.1f} file {row['file']['tempo_bpm_median']:.1f}",
                  file=sys.stderr, flush=True)
        if not a.no_file_latency:  # the file in real time, the first run's seed and silence: the latency baseline
            s0 = int(round(out["runs"][0]["silence_s"] * RATE))
            source = FileSource(np.concatenate([np.zeros((s0, x.shape[1]), np.float32), x]), RATE, realtime=True)
            t_file: list[float] = []
            fstart = source.start
            source.start = lambda ring: (t_file.append(time.monotonic()), fstart(ring))[1]  # type: ignore[method-assign]
            filed, _ = run_engine(source, a.seconds + s0 / RATE, seed=a.seed)
            poses, lat, state = song_frames(filed, s0, frames, t_file[0] + s0 / RATE)
            out["file_realtime"] = {**song_figures(poses, state, beats), "latency_ms_p50": float(np.nanmedian(lat) * 1000),
                                    "latency_ms_p99": float(np.nanpercentile(lat, 99) * 1000)}
    runs = out["runs"]
    summary = {}
    summary["fast_octave_from_s"] = {side: [r[side]["fast_octave_from_s"] for r in runs] for side in ("live", "file")}
    for key in ("beat_hit", "mean_speed", "tempo_bpm_median", "fast_octave_share"):
        lv, fv = [r["live"][key] for r in runs], [r["file"][key] for r in runs]
        summary[key] = {"live": spread(lv), "file": spread(fv)}
        if key in ("beat_hit", "mean_speed"):
            summary[key]["ratio_of_means"] = summary[key]["live"]["mean"] / summary[key]["file"]["mean"]
            summary[key]["paired_ratios"] = [l / f for l, f in zip(lv, fv)]
    summary["drift_samples"] = [r["drift_samples"] for r in runs]
    summary["level_db_vs_song"] = [r["heard_rms_dbfs"] - out["song_rms_dbfs"] for r in runs]
    summary["heard_exact_share"] = [r["heard_exact_share"] for r in runs]
    summary["heard_differs_until_ms"] = [r["heard_differs_until_ms"] for r in runs]
    summary["poses_apart_from_s"] = [r["poses_apart_from_s"] for r in runs]
    summary["capture_gap_ms_max"] = [r["capture_gap_ms_max"] for r in runs]
    summary["first_block_after_start_s"] = [r["first_block_after_start_s"] for r in runs]
    summary["latency_ms_p50_live"] = spread([r["live"]["latency_ms_p50"] for r in runs])
    summary["latency_ms_p99_live"] = spread([r["live"]["latency_ms_p99"] for r in runs])
    out["summary"] = summary
    if a.draws:
        draws = file_draws(mono, frames, beats, a.draws, seed=a.seed)
        out["file_draws"] = {k: [d[k] for d in draws] for k in ("silence_s", "beat_hit", "mean_speed",
                                                               "tempo_bpm_median", "fast_octave_share",
                                                               "fast_octave_from_s")}
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1))
    print(report(out))
    return 0


def report(out: dict) -> str:
    """The comparison in words: live against the file, the same seeds and silences."""
    s, n = out["summary"], len(out["runs"])
    octave = lambda v: ", ".join("never" if t is None else f"{t:.1f}" for t in v)  # noqa: E731
    f = lambda d, p=3: f"{d['mean']:.{p}f} +- {d['sd']:.{p}f} [{d['min']:.{p}f}, {d['max']:.{p}f}]"  # noqa: E731
    lines = [f"{out['song']} {out['start_s']:g}-{out['start_s'] + out['seconds']:g} s, {n} runs: live (PulseAudio, "
             f"pacat {out['pacat_latency_ms']} ms) against the file after the same silence with the same seed",
             "mean +- sd [min, max]      live                          file",
             f"beat hit                   {f(s['beat_hit']['live'])}   {f(s['beat_hit']['file'])}",
             f"mean joint speed m/s       {f(s['mean_speed']['live'])}   {f(s['mean_speed']['file'])}",
             f"followed tempo bpm         {f(s['tempo_bpm_median']['live'], 1)}   {f(s['tempo_bpm_median']['file'], 1)}",
             "faster octave held from (s into the song) live: " + octave(s["fast_octave_from_s"]["live"])
             + "; file: " + octave(s["fast_octave_from_s"]["file"]),
             f"beat hit ratio of means {s['beat_hit']['ratio_of_means']:.3f} (target >= 0.9; paired "
             + ", ".join(f"{r:.2f}" for r in s["beat_hit"]["paired_ratios"]) + ")",
             f"joint speed ratio of means {s['mean_speed']['ratio_of_means']:.3f} (target 0.9-1.1; paired "
             + ", ".join(f"{r:.2f}" for r in s["mean_speed"]["paired_ratios"]) + ")",
             "live drift (samples): " + ", ".join(str(d) for d in s["drift_samples"])
             + "; level against the song (dB): " + ", ".join(f"{d:+.2f}" for d in s["level_db_vs_song"]),
             "samples heard as played: " + ", ".join(f"{v:.4f}" for v in s["heard_exact_share"])
             + "; the last one not, ms into the song: " + ", ".join(f"{v:.1f}" for v in s["heard_differs_until_ms"])
             + "; live and file poses apart from (s into the song): " + octave(s["poses_apart_from_s"]),
             "live capture: longest gap between callbacks in the song (ms): "
             + ", ".join(f"{g:.1f}" for g in s["capture_gap_ms_max"]) + "; first block after the stream's start (s): "
             + ", ".join(f"{g:.2f}" for g in s["first_block_after_start_s"]),
             f"sound-to-pose live p50 {f(s['latency_ms_p50_live'], 1)} ms, p99 {f(s['latency_ms_p99_live'], 1)} ms"]
    if "file_realtime" in out:
        fr = out["file_realtime"]
        lines.append(f"file in real time (seed {out['runs'][0]['seed']}, run 1's silence): sound-to-pose p50 "
                     f"{fr['latency_ms_p50']:.1f} ms, p99 {fr['latency_ms_p99']:.1f} ms, beat hit {fr['beat_hit']:.3f}")
    if "file_draws" in out:
        d = out["file_draws"]
        lines.append(f"file offline after {len(d['silence_s'])} random silences: tempo bpm "
                     + ", ".join(f"{t:.1f}" for t in d["tempo_bpm_median"]) + "; faster octave held from (s) "
                     + octave(d["fast_octave_from_s"]) + f"; beat hit {spread(d['beat_hit'])['mean']:.3f} "
                     f"[{min(d['beat_hit']):.3f}, {max(d['beat_hit']):.3f}]")
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
