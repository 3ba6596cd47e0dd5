"""Optional long-context and beat-phase channels, appended after the base features.

A causal generator that sees 128-frame windows (4.3 s) knows neither what the song has
been like so far nor where the next beat falls (docs/training.md, "Why two targets are
still open"). Two optional :class:`~models.features.spectral.FeatureConfig` settings add
that, both causal functions of the base feature frames ``<= t``:

* ``context_s = tau > 0``: a running mean of every base column with time constant
  ``tau`` seconds, ``m[t] = b * m[t-1] + (1 - b) * f[t]`` with ``b = exp(-1 / (30 tau))``,
  ``m[-1] = 0``, bias-corrected as ``m[t] / (1 - b**(t+1))`` (Adam's correction): at
  stream start it is the plain mean of the frames so far, later an exponential one.
  Adds ``base_dim`` columns.
* ``beat_phase = True`` (``logmel_onset`` only): a beat tracker on the onset column.
  For each frame it takes the last :data:`TEMPO_WINDOW` onset values (6 s, zeros before
  the stream), removes their weighted mean and weights them by a half-Hann window
  ``w[j] = (1 + cos(pi j / W)) / 2`` (``j`` frames ago): ``x[j]``. The beat period
  ``P`` is the lag in :data:`LAGS` (10..40 frames = 180..45 BPM) with the largest
  autocorrelation of ``x`` times a log-normal tempo prior centred on 120 BPM with one
  octave deviation (librosa's ``beat_track`` defaults ``start_bpm=120, std_bpm=1``;
  like it, the autocorrelation prefers the beat to its off-beat eighths), refined to
  a fraction of a frame by a parabola through the neighbouring lags. The phase is
  that of one Fourier coefficient, ``z = sum_j x[j] exp(2 pi i j / P)``: onsets every
  ``P`` frames, the last one ``phi`` frames ago, give ``arg z = 2 pi phi / P``. Adds 4 columns: ``c cos(theta)``, ``c sin(theta)``, ``c`` and
  ``log2(P / 15)``, where ``theta = arg z(P)`` is the beat phase (0 on a beat, rising
  by ``2 pi / P`` per frame) and ``c = |z(P)| / sum_j w[j] |x[j]|`` in [0, 1] the
  pulse clarity (0 in silence, so the phase columns fade out instead of jumping).

Column order: ``[base | context | beat]``. The tracker is O(W log W) per
frame (one 256-point FFT pair and a 180-term sum, tens of microseconds) and keeps ``base_dim + W`` numbers
of state, so the live extractor carries it at no noticeable cost.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

from models.timebase import FPS

#: Onset-envelope frames the beat tracker reads (6 s at 30 fps).
TEMPO_WINDOW: int = 180
#: Candidate beat periods, whole frames (10..40 = 180..45 beats per minute).
LAGS: np.ndarray = np.arange(10, 41)
#: Centre of the tempo prior, frames per beat (120 beats per minute).
PRIOR_PERIOD: float = 15.0
#: Columns the beat tracker adds.
BEAT_COLUMNS: int = 4
_NFFT = 256  # >= TEMPO_WINDOW + max lag + 1: the circular autocorrelation does not wrap at the lags read


def _prior(period: np.ndarray) -> np.ndarray:
    return np.exp(-0.5 * np.log2(period / PRIOR_PERIOD) ** 2)


class ContextTracker:
    """Stateful maker of the context/beat columns for one stream (see module docstring).

    ``tracker(base)`` takes the next ``(k, base_dim)`` base feature frames of the stream
    and returns their ``(k, extra_dim)`` float32 extra columns; ``reset()`` starts a new
    stream. Chunking does not matter: frames pushed in any split give the same columns.
    """

    def __init__(self, base_dim: int, context_s: float = 0.0, beat_phase: bool = False) -> None:
        self.base_dim = int(base_dim)
        self.context_s = float(context_s)
        self.beat_phase = bool(beat_phase)
        self.decay = float(np.exp(-1.0 / (FPS * self.context_s))) if self.context_s > 0 else 0.0
        self.extra_dim = (self.base_dim if self.context_s > 0 else 0) + (BEAT_COLUMNS if self.beat_phase else 0)
        if self.beat_phase:
            self._j = np.arange(TEMPO_WINDOW, dtype=np.float64)
            self._w = 0.5 * (1.0 + np.cos(np.pi * self._j / TEMPO_WINDOW))
            self._lag_prior = _prior(LAGS.astype(np.float64))
        self.reset()

    def reset(self) -> None:
        """Start a new stream: no frames seen, running mean 0, onset history zeros."""
        self._frames = 0
        self._mean = np.zeros(self.base_dim)
        self._onsets = np.zeros(TEMPO_WINDOW - 1)

    def __call__(self, base: np.ndarray) -> np.ndarray:
        """(k, base_dim) base frames -> (k, extra_dim) float32 extra columns."""
        base = np.asarray(base, np.float64)
        k = base.shape[0]
        cols = []
        if self.context_s > 0:
            b = self.decay
            y, zf = lfilter([1.0 - b], [1.0, -b], base, axis=0, zi=(b * self._mean)[None, :])
            self._mean = y[-1].copy() if k else self._mean
            n = np.arange(self._frames + 1, self._frames + k + 1, dtype=np.float64)
            cols.append(y / (1.0 - b**n)[:, None])
        if self.beat_phase:
            cols.append(self._beats(base[:, -1]))
        self._frames += k
        if not cols:
            return np.zeros((k, 0), np.float32)
        return np.concatenate(cols, axis=1).astype(np.float32)

    def _beats(self, onset: np.ndarray) -> np.ndarray:
        env = np.concatenate([self._onsets, onset])
        self._onsets = env[env.size - (TEMPO_WINDOW - 1) :]
        # Row i: the W onsets ending at frame i of this chunk, newest first (j = frames ago).
        win = np.lib.stride_tricks.sliding_window_view(env, TEMPO_WINDOW)[:, ::-1]
        w = self._w
        xw = (win - ((win @ w) / w.sum())[:, None]) * w  # weighted, mean removed
        spec = np.fft.rfft(xw, _NFFT, axis=1)
        ac = np.fft.irfft(spec.real**2 + spec.imag**2, _NFFT, axis=1)[:, : LAGS[-1] + 2]
        score = ac[:, LAGS] * self._lag_prior
        best = np.argmax(score, axis=1)
        rows = np.arange(onset.size)
        # Parabolic refinement of the best lag (clamped to half a frame).
        lag = LAGS[best].astype(np.float64)
        y0, y1, y2 = ac[rows, LAGS[best] - 1], ac[rows, LAGS[best]], ac[rows, LAGS[best] + 1]
        den = y0 - 2.0 * y1 + y2
        period = lag + np.clip(np.where(den < 0, 0.5 * (y0 - y2) / np.where(den < 0, den, -1.0), 0.0), -0.5, 0.5)
        ang = 2.0 * np.pi * self._j[None, :] / period[:, None]
        re, im = (xw * np.cos(ang)).sum(axis=1), (xw * np.sin(ang)).sum(axis=1)
        m = np.hypot(re, im)
        norm = np.abs(xw).sum(axis=1)
        clarity = np.where(norm > 1e-9, m / np.maximum(norm, 1e-9), 0.0)
        unit = np.where(m > 1e-12, 1.0 / np.maximum(m, 1e-12), 0.0)
        return np.stack([clarity * re * unit, clarity * im * unit, clarity, np.log2(period / PRIOR_PERIOD)], axis=1)
