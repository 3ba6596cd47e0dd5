"""Live feature extraction: push audio blocks, get each 30 fps frame as soon as it exists.

:class:`StreamingFeatureExtractor` runs the offline pipeline (``to_mono`` ->
resample to 22050 Hz -> hop-ending STFT frames -> :class:`SpectralKernel`)
incrementally: the resampler carries its filter state, the extractor keeps the last
``n_fft - HOP`` resampled samples, the previous log-mel row and (when the config adds
context or beat columns) a :class:`~models.features.context.ContextTracker` (and, with the
steadiness column, a :class:`~models.features.steadiness.SteadinessTracker`), and every
push computes only the frames completed by that push. Streamed frames equal
:func:`extract_features` on the whole signal (tests/test_features_streaming.py).

Latency: frame t's nominal time is the end of its hop, ``(t + 1) * HOP`` samples at
22050 Hz (:func:`models.features.spectral.frame_time_s`). With hop-ending windows
the frame needs no audio after that instant except the resampler's zero-phase
look-ahead; :func:`feature_latency_samples` is the largest such excess over all
frames, in input samples (0 at 22050 Hz, 19 at 44100 Hz; run
``python -m models.features.streaming`` for the table).
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from models.errors import AudioError, ConfigError
from models.features.audio_io import check_finite, to_mono
from models.features.context import ContextTracker
from models.features.resample import StreamingResampler, check_rate
from models.features.spectral import FeatureConfig, SpectralKernel
from models.features.steadiness import SteadinessTracker
from models.timebase import HOP, SAMPLE_RATE

COMMON_RATES: tuple[int, ...] = (8000, 16000, 22050, 24000, 32000, 44100, 48000, 96000)


def samples_needed(t: int | np.ndarray, input_sr: int) -> int | np.ndarray:
    """Input samples (at ``input_sr``) that must have arrived for frame t to be emitted."""
    return StreamingResampler(input_sr, SAMPLE_RATE).inputs_needed((np.asarray(t) + 1) * HOP - 1)


def feature_latency_samples(input_sr: int) -> int:
    """Worst-case input samples a frame needs after its nominal time (end of its hop).

    Exact: the max over all frames t of ``samples_needed(t) - (t + 1) * HOP * input_sr
    / 22050``, rounded up (the pattern repeats every ``up`` frames, so one period is
    checked). It does not depend on the FeatureConfig (windows end at the hop end).
    """
    rs = StreamingResampler(input_sr, SAMPLE_RATE)
    t = np.arange(rs.up)
    excess = samples_needed(t, input_sr) - (t + 1) * HOP * rs.down / rs.up
    return max(0, math.ceil(float(excess.max()) - 1e-9))


def feature_latency_s(cfg: FeatureConfig | None, input_sr: int) -> float:
    """:func:`feature_latency_samples` in seconds; ``cfg`` does not change it (kept for callers)."""
    return feature_latency_samples(input_sr) / check_rate(input_sr)


class StreamingFeatureExtractor:
    """Causal, incremental :func:`extract_features` for live audio at ``input_sr`` Hz.

    push(block) takes (n,) or (n, channels) samples (float +-1 or integer PCM),
    n >= 0, and returns the (k, cfg.dim) float32 frames completed by it.
    """

    def __init__(self, cfg: FeatureConfig | None = None, input_sr: int = SAMPLE_RATE) -> None:
        self.cfg = cfg or FeatureConfig()
        self.input_sr = check_rate(input_sr, source="stream")
        self._resampler = StreamingResampler(self.input_sr, SAMPLE_RATE)
        self._kernel = SpectralKernel(self.cfg)
        self._extra = ContextTracker(self.cfg.base_dim, self.cfg.context_s, self.cfg.beat_phase)
        self._steady = SteadinessTracker(self.cfg.n_fft) if self.cfg.steadiness else None
        self.latency_samples: int = feature_latency_samples(self.input_sr)
        self.reset()

    def reset(self) -> None:
        """Start a new stream: the next sample pushed is sample 0 of frame 0."""
        self._resampler.reset()
        self._history = np.zeros(self.cfg.n_fft - HOP)  # 22050 Hz samples before the next hop
        self._prev_logmel: np.ndarray | None = None
        self._extra.reset()
        if self._steady is not None:
            self._steady.reset()
        self._frames = 0
        self._held: list[np.ndarray] = []  # mono input blocks that complete no frame yet (not resampled)
        self._held_n = 0  # samples in them
        self._next_need = self.samples_needed(0)  # input samples after which the next frame is due

    @property
    def frames_emitted(self) -> int:
        """Frames returned since the last reset."""
        return self._frames

    @property
    def samples_pushed(self) -> int:
        """Input samples pushed since the last reset."""
        return self._resampler.samples_in + self._held_n

    def samples_needed(self, t: int) -> int:
        """Input samples after which frame t (0-based) is returned by push."""
        return int(self._resampler.inputs_needed((t + 1) * HOP - 1))

    def push(self, block: np.ndarray) -> np.ndarray:
        """Feed input samples; return every newly completed frame, (k, D) float32.

        A block after which no frame is due is only kept (copied, a few µs); the next block that
        completes a frame resamples it and itself in one pass. At 44.1 kHz in 512-sample blocks two
        blocks of three complete no frame: one resampling and one spectral pass a frame, not three
        (the same samples in the same order: the frames are bit for bit those of pushing every
        block through at once, tests/test_features_streaming.py).
        """
        mono = to_mono(block, source="audio stream")
        check_finite(mono, self.input_sr, source="audio stream block")
        if self._resampler.samples_in + self._held_n + mono.size < self._next_need:
            if mono.size:
                self._held.append(mono.copy())  # the caller may reuse its buffer
                self._held_n += mono.size
            return np.zeros((0, self.cfg.dim), np.float32)
        out = self._frames_from(self._resampler.process(self._take_held(mono)))
        self._next_need = self.samples_needed(self._frames)
        return out

    def _take_held(self, mono: np.ndarray) -> np.ndarray:
        """The held blocks followed by ``mono``, one array; nothing held afterwards."""
        if not self._held:
            return mono
        joined = np.concatenate([*self._held, mono])
        self._held.clear()
        self._held_n = 0
        return joined

    def flush(self) -> np.ndarray:
        """End of stream: emit the frames the resampler's tail completes (zeros after the end).

        Afterwards frames_emitted equals ``len(extract_features(load_audio(...)))`` for
        the same samples. Call reset() before pushing again.
        """
        held = self._frames_from(self._resampler.process(self._take_held(np.zeros(0, np.float32))))
        out = self._frames_from(self._resampler.flush())
        return np.concatenate([held, out]) if len(held) else out

    def _frames_from(self, new: np.ndarray) -> np.ndarray:
        # Round to float32 like the offline path's load_audio output does.
        new = new.astype(np.float32).astype(np.float64)
        buf = np.concatenate([self._history, new]) if new.size else self._history
        k = (buf.size - (self.cfg.n_fft - HOP)) // HOP
        if k <= 0:
            self._history = buf
            return np.zeros((0, self.cfg.dim), np.float32)
        if k == 1:  # the live case: one window, a plain view (sliding_window_view costs ~30 µs a call)
            frames = buf[None, : self.cfg.n_fft]
        else:
            frames = np.lib.stride_tricks.sliding_window_view(buf, self.cfg.n_fft)[::HOP][:k]
        spec = self._kernel.spectrum(frames)
        out, self._prev_logmel = self._kernel(frames, self._prev_logmel, spec)
        if self._extra.extra_dim:
            out = np.concatenate([out, self._extra(out)], axis=1)
        if self._steady is not None:  # the same spectrum, not a second FFT
            out = np.concatenate([out, self._steady.from_spectrum(spec)[:, None]], axis=1)
        self._history = buf[k * HOP :]
        self._frames += k
        return out


def _latency_table() -> None:
    print("input_sr  up/down    latency_samples  latency_ms")
    for sr in COMMON_RATES:
        rs = StreamingResampler(sr, SAMPLE_RATE)
        n = feature_latency_samples(sr)
        print(f"{sr:>8}  {rs.up:>3}/{rs.down:<4}  {n:>15}  {1000 * n / sr:>10.3f}")


def _bench(input_sr: int, block: int | None, seconds: float, cfg: FeatureConfig) -> None:
    import time

    block = block or round(input_sr / 30)
    rng = np.random.default_rng(0)
    audio = (0.1 * rng.standard_normal((int(seconds * input_sr), 2))).astype(np.float32)
    ex = StreamingFeatureExtractor(cfg, input_sr)
    per_frame, total = [], 0.0
    for lo in range(0, audio.shape[0], block):
        t0 = time.perf_counter()
        k = ex.push(audio[lo : lo + block]).shape[0]
        dt = time.perf_counter() - t0
        total += dt
        if k:
            per_frame.append(dt / k)
    us = 1e6 * np.array(per_frame)
    print(
        f"{cfg.fingerprint()}, {input_sr} Hz stereo in blocks of {block}: {ex.frames_emitted} frames; "
        f"per frame: median {np.median(us):.0f} us, p95 {np.percentile(us, 95):.0f} us, "
        f"all pushes / frames {1e6 * total / ex.frames_emitted:.0f} us"
    )


def _compare(seconds: float) -> None:
    """Stream the bundled clip (resampled to each common rate) in random blocks vs offline."""
    from models.features.audio_io import bundled_clip_path, load_audio
    from models.features.resample import resample
    from models.features.spectral import extract_features

    clip = load_audio(bundled_clip_path())[0][: int(seconds * SAMPLE_RATE)]
    rng = np.random.default_rng(0)
    for cfg in (FeatureConfig(), FeatureConfig.linear(), FeatureConfig.mfcc()):
        for sr in COMMON_RATES:
            x = resample(clip, SAMPLE_RATE, sr)
            offline = extract_features(resample(x, sr, SAMPLE_RATE), cfg)
            ex = StreamingFeatureExtractor(cfg, sr)
            out, lo = [], 0
            while lo < x.size:
                n = int(rng.integers(1, 4097))
                out.append(ex.push(x[lo : lo + n]))
                lo += n
            out.append(ex.flush())
            diff = float(np.abs(np.concatenate(out) - offline).max())
            print(f"{cfg.kind:>12} {sr:>6} Hz: {offline.shape[0]} frames, max |streamed - offline| = {diff:.2e}")


def main(argv: list[str] | None = None) -> int:
    """``python -m models.features.streaming [--bench | --compare]``: latency table, per-frame cost, or
    streamed-vs-offline check."""
    p = argparse.ArgumentParser(description=main.__doc__)
    p.add_argument("--bench", action="store_true", help="time push() per emitted frame")
    p.add_argument("--compare", action="store_true", help="max streamed-vs-offline difference on the bundled clip")
    p.add_argument("--rate", type=int, default=48000, help="input sample rate for --bench (Hz)")
    p.add_argument("--block", type=int, default=None, help="samples per push for --bench (default: one frame)")
    p.add_argument("--seconds", type=float, default=60.0, help="audio length for --bench/--compare (s)")
    p.add_argument("--kind", default="logmel_onset", choices=("logmel_onset", "linear", "mfcc", "mfcc_onset"),
                   help="feature kind for --bench")
    p.add_argument("--context-s", type=float, default=0.0,
                   help="for --bench: add the running-mean context columns with this time constant (s)")
    p.add_argument("--beat-phase", action="store_true", help="for --bench: add the beat-phase columns")
    p.add_argument("--steadiness", action="store_true", help="for --bench: add the spectral steadiness column")
    args = p.parse_args(argv)
    if args.compare:
        _compare(args.seconds)
        return 0
    if not args.bench:
        _latency_table()
        return 0
    import dataclasses

    cfg = {"logmel_onset": FeatureConfig, "linear": FeatureConfig.linear, "mfcc": FeatureConfig.mfcc,
           "mfcc_onset": lambda: FeatureConfig(kind="mfcc_onset", n_mels=128)}[args.kind]()
    try:
        cfg = dataclasses.replace(cfg, context_s=args.context_s, beat_phase=args.beat_phase,
                                  steadiness=args.steadiness)
    except ConfigError as exc:
        p.error(str(exc))
    _bench(args.rate, args.block, args.seconds, cfg)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
