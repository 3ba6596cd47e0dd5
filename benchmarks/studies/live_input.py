"""The performer on a real live input against the same song replayed from the file (docs/latency.md).

Live: a private PulseAudio server (realtime/pulse.py), the song played into its null sink in real
time by ``pacat``, the engine of ``performer run --input-device pulse`` capturing the monitor through
PortAudio (44.1 kHz). File: the same excerpt replayed by the engine from a file in real time at
44.1 kHz. The same shipped model, seed 0, in this process, one after the other.

The live run keeps a copy of every captured block (a tap on the engine's ring) to find where the
song starts in the input (cross-correlation, to the sample); its frames are then numbered from the
song's start like the file run's; the excerpt is also streamed offline from the file after exactly
the silence the live run heard before it (the same input but for what the live path changed).
Printed: the beat hit rate of each (kinematic beats within 2
frames of librosa's beats of the song) and their ratio, the mean joint speed of each and their
ratio, and the sound-to-pose latency of each frame: its send time minus the moment its last audio
sample was handed over (file: the replay's clock; live: the song's sample 0 handed to pacat, so the
audio server's path and pacat's start are inside it), median and p99; and the live input's drift:
where the song's last 2 s lie in the capture against where its first 2 s put them (samples the
live path lost, negative, or added).

    .venv/bin/python benchmarks/studies/live_input.py --data ../shared/data/dwm --song DANCE_C_2 \\
        --start-s 30 --seconds 60
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
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
        self._ring, self.blocks = ring, []

    def write(self, block, release_time=None):
        self.blocks.append((np.array(block, np.float32), release_time))
        return self._ring.write(block, release_time)

    def __getattr__(self, name):
        return getattr(self._ring, name)


def run_engine(source, seconds: float, play=None) -> tuple[Collect, float | None]:
    from realtime.engine import Engine, EngineConfig
    from realtime.pipeline import build_pipeline

    pipe = build_pipeline(None, seed=0)
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


def file_draws(mono: np.ndarray, frames: int, beats: np.ndarray, n: int, seed: int = 0,
               prefixes: list[int] | None = None) -> list[dict]:
    """The control: the excerpt streamed through the same model from the file (offline, as fast as it
    goes) after ``n`` random silences of 0.5-2.5 s, as the live input hears it after some silence:
    each its beat hit rate and mean joint speed over the song's frames (the draws a start point moves).
    ``prefixes``: these silences (samples) instead of random ones."""
    from models.evaluation.listening import beat_hits, mean_speed, positions
    from models.timebase import HOP
    from realtime.pipeline import build_pipeline

    rng = np.random.default_rng(seed)
    out = []
    for j in range(n if prefixes is None else len(prefixes)):
        pipe = build_pipeline(None, seed=0)
        prefix = int(rng.integers(RATE // 2, 5 * RATE // 2)) if prefixes is None else int(prefixes[j])
        audio = np.concatenate([np.zeros(prefix, np.float32), mono.astype(np.float32)])
        feats = pipe.extractor_factory(RATE).push(audio)
        poses = pipe.model.push(feats)
        ends = (np.arange(len(poses)) + 1) * 2 * HOP  # each frame's last input sample
        k = np.rint((ends - prefix) / (2 * HOP)).astype(int) - 1
        song = poses[(k >= 0)][:frames]
        pos = positions(song)
        out.append({"silence_s": prefix / RATE, "beat_hit": beat_hits(pos, beats)[0], "mean_speed": mean_speed(pos)})
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", required=True, help="the dwm directory (../shared/data/dwm)")
    p.add_argument("--song", default="DANCE_C_2", help="a dance of --data (default DANCE_C_2)")
    p.add_argument("--start-s", type=float, default=30.0, help="where the excerpt starts, s (default 30)")
    p.add_argument("--seconds", type=float, default=60.0, help="excerpt length, s (default 60)")
    p.add_argument("--pacat-latency-ms", type=int, default=100,
                   help="the player's buffer (default 100: a shorter one underruns on a busy machine)")
    p.add_argument("--draws", type=int, default=0,
                   help="also N offline passes of the excerpt after random silences (the draws' spread)")
    p.add_argument("--json", metavar="FILE", help="write the figures here")
    a = p.parse_args(argv)
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
    with pulse, tempfile.TemporaryDirectory() as tmp:
        os.environ.update(pulse.env)  # before PortAudio starts: its ALSA pulse device reads them
        from models.evaluation.listening import beat_hits, heard_beats, mean_speed, positions
        from realtime.audio_input import DeviceSource, FileSource
        from scipy.signal import correlate
        import librosa

        dev = DeviceSource("pulse", sample_rate=RATE)
        start = dev.start
        tap: list[TapRing] = []
        dev.start = lambda ring: start(tap.append(TapRing(ring)) or tap[0])  # type: ignore[method-assign]
        live, t_play = run_engine(dev, a.seconds, play=lambda: pulse.play(x, latency_ms=a.pacat_latency_ms))
        heard = np.concatenate([b for b, _ in tap[0].blocks]).mean(axis=1)
        mono = x.mean(axis=1)
        ref = mono[: 2 * RATE]
        s0 = int(np.argmax(correlate(heard, ref, "valid", method="fft")))  # the song's sample 0 in the input
        tail = mono[-2 * RATE:]  # where the song's last 2 s are: samples the live path lost (-) or added (+)
        lo = s0 + len(mono) - len(tail) - RATE
        drift = int(np.argmax(correlate(heard[lo: lo + len(tail) + 2 * RATE], tail, "valid", method="fft"))) - RATE
        wav = Path(tmp) / "excerpt.wav"
        sf.write(str(wav), x, RATE)
        source = FileSource.open(wav, sample_rate=RATE, realtime=True)
        t_file: list[float] = []
        fstart = source.start
        source.start = lambda ring: (t_file.append(time.monotonic()), fstart(ring))[1]  # type: ignore[method-assign]
        filed, _ = run_engine(source, a.seconds)

    frames = int(a.seconds * 30) - 2
    beats = heard_beats(librosa.resample(mono, orig_sr=RATE, target_sr=22050))
    out = {"song": a.song, "start_s": a.start_s, "seconds": a.seconds, "pacat_latency_ms": a.pacat_latency_ms,
           "song_start_sample": s0, "drift_samples": drift,
           "song_rms_dbfs": float(10 * np.log10(np.mean(mono.astype(np.float64) ** 2)))}
    for name, sink, t0, first in (("live", live, t_play, s0), ("file", filed, t_file[0], 0)):
        poses, lat, state = song_frames(sink, first, frames, t0)
        ok = ~np.isnan(poses).any(axis=1)
        n = int(np.argmin(ok)) if not ok.all() else frames  # the frames up to the first missing one
        pos = positions(poses[:n])
        hit, control = beat_hits(pos, beats)
        out[name] = {"frames": n, "beat_hit": hit, "beat_hit_half_shifted": control, "mean_speed": mean_speed(pos),
                     "tempo_bpm_median": float(np.nanmedian(state[:n, 0])), "idle_share": float(np.mean(state[:n, 1] > 0.5)),
                     "latency_ms_p50": float(np.nanmedian(lat) * 1000), "latency_ms_p99": float(np.nanpercentile(lat, 99) * 1000)}
    same = file_draws(mono, frames, beats, 0, prefixes=[s0])[0]  # the file after the live run's own silence
    out["file_same_silence"] = same
    out["beat_hit_ratio_same_silence"] = out["live"]["beat_hit"] / same["beat_hit"]
    out["speed_ratio_same_silence"] = out["live"]["mean_speed"] / same["mean_speed"]
    if a.draws:
        draws = file_draws(mono, frames, beats, a.draws)
        out["file_draws"] = {k: [d[k] for d in draws] for k in ("silence_s", "beat_hit", "mean_speed")}
    out["beat_hit_ratio"] = out["live"]["beat_hit"] / out["file"]["beat_hit"]
    out["speed_ratio"] = out["live"]["mean_speed"] / out["file"]["mean_speed"]
    print(json.dumps(out, indent=1))
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
