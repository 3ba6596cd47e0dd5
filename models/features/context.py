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

Column order: ``[base | context | beat]``. The tracker costs the autocorrelation at 33
lags of 180 values and 180 cosines and sines per frame, as one compiled call
(:func:`_beat_columns`: on the live path, where caches are cold after each wait for
audio, its 15 NumPy calls and two FFTs took 0.2 ms a frame) and keeps ``base_dim + 2 W``
numbers of state and a :data:`WORK_SIZE` scratch (the compiled call allocates nothing). The
window and its autocorrelation are :func:`_weighted_autocorrelation`, which the lead's
forecast (:mod:`models.networks.lead`) reads too. It runs frame by frame, offline too, so
that the live and offline columns are the same arithmetic.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from models.timebase import FPS

#: Onset-envelope frames the beat tracker reads (6 s at 30 fps).
TEMPO_WINDOW: int = 180
#: Candidate beat periods, whole frames (10..40 = 180..45 beats per minute).
LAGS: np.ndarray = np.arange(10, 41)
#: Centre of the tempo prior, frames per beat (120 beats per minute).
PRIOR_PERIOD: float = 15.0
#: Columns the beat tracker adds.
BEAT_COLUMNS: int = 4
#: Floats of the scratch :func:`_beat_columns` works in: the weighted window (W), then the
#: autocorrelation indexed by lag (0 .. the largest lag + 1, the parabola's neighbour).
WORK_SIZE: int = TEMPO_WINDOW + int(LAGS[-1]) + 2


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
        j = np.arange(TEMPO_WINDOW, dtype=np.float64)
        self._w = 0.5 * (1.0 + np.cos(np.pi * j / TEMPO_WINDOW))
        self._w_sum = float(self._w.sum())
        self._two_pi_j = 2.0 * np.pi * j
        self._lag_prior = _prior(LAGS.astype(np.float64))
        self._work = np.empty(WORK_SIZE)  # scratch of _beat_columns, no state between frames
        self.reset()

    def reset(self) -> None:
        """Start a new stream: no frames seen, running mean 0, onset history zeros."""
        self._frames = 0
        self._mean = np.zeros(self.base_dim)
        # Onset history twice over, so the last W values are always one contiguous slice:
        # value i of the stream sits at (i % W) and (i % W) + W.
        self._ring = np.zeros(2 * TEMPO_WINDOW)

    def __call__(self, base: np.ndarray) -> np.ndarray:
        """(k, base_dim) base frames -> (k, extra_dim) float32 extra columns.

        One frame at a time, the same arithmetic offline and live, so any chunking of
        a stream gives bit-identical columns (the live extractor calls it once per frame
        with k = 1, where a per-frame loop is also the cheapest form).
        """
        base = np.asarray(base, np.float64)
        out = np.empty((base.shape[0], self.extra_dim), np.float32)
        ctx = self.base_dim if self.context_s > 0 else 0
        for i, row in enumerate(base):
            if ctx:
                self._mean = self.decay * self._mean + (1.0 - self.decay) * row
                out[i, :ctx] = self._mean / (1.0 - self.decay ** (self._frames + 1))
            if self.beat_phase:
                out[i, ctx:] = self._beat(float(row[-1]))
            self._frames += 1
        return out

    def _beat(self, onset: float) -> tuple[float, float, float, float]:
        """The 4 beat columns of the frame whose onset value is ``onset`` (module docstring)."""
        W = TEMPO_WINDOW
        pos = self._frames % W
        self._ring[pos] = self._ring[pos + W] = onset
        return _beat_columns(self._ring, pos, self._w, self._w_sum, self._two_pi_j, self._lag_prior,
                             int(LAGS[0]), int(LAGS[-1]), self._work)


@njit(cache=True, nogil=True)
def _weighted_autocorrelation(ring, pos, w, w_sum, lo, hi, xw, ac):  # pragma: no cover - compiled
    """The tracker's window and its autocorrelation, into scratch: ``xw[j]`` (W,) the last W
    onsets ``ring[pos + W - j]`` (j frames ago), their ``w``-weighted mean removed, times ``w[j]``;
    ``ac[lag]`` the sum over j of ``xw[j] xw[j + lag]`` for lags ``lo..hi`` (frames; ``ac`` at
    least ``hi + 1`` long, its other entries left as they are). Loops, not NumPy: no temporaries,
    and one summation order for :func:`_beat_columns` and the lead's runner-up (the same bits)."""
    n = w.shape[0]
    mean = 0.0
    for j in range(n):
        mean += ring[pos + n - j] * w[j]
    mean /= w_sum
    for j in range(n):
        xw[j] = (ring[pos + n - j] - mean) * w[j]
    for lag in range(lo, hi + 1):
        acc = 0.0
        for j in range(n - lag):
            acc += xw[j] * xw[j + lag]
        ac[lag] = acc


@njit(cache=True, nogil=True)
def _beat_columns(ring, pos, w, w_sum, two_pi_j, lag_prior, lag_lo, lag_hi, work):  # pragma: no cover - compiled
    """The beat columns from the onset ring (module docstring): the last W onsets are
    ``ring[pos + W - j]``, j frames ago; lags ``lag_lo..lag_hi`` are the candidate periods;
    ``work`` a (:data:`WORK_SIZE`,) float64 scratch."""
    n = w.shape[0]
    xw, ac = work[:n], work[n:]  # ac: the autocorrelation at lags lag_lo - 1 .. lag_hi + 1 (the parabola's)
    _weighted_autocorrelation(ring, pos, w, w_sum, lag_lo - 1, lag_hi + 1, xw, ac)
    lag = lag_lo
    best = ac[lag_lo] * lag_prior[0]
    for i in range(1, lag_hi - lag_lo + 1):
        v = ac[lag_lo + i] * lag_prior[i]
        if v > best:
            best, lag = v, lag_lo + i
    y0, y1, y2 = ac[lag - 1], ac[lag], ac[lag + 1]
    den = y0 - 2.0 * y1 + y2  # parabola through the neighbours, vertex clamped to +-0.5
    period = lag + (min(0.5, max(-0.5, 0.5 * (y0 - y2) / den)) if den < 0 else 0.0)
    re = 0.0
    im = 0.0
    norm = 0.0
    for j in range(n):
        ang = two_pi_j[j] / period
        re += xw[j] * math.cos(ang)
        im += xw[j] * math.sin(ang)
        norm += abs(xw[j])
    m = math.hypot(re, im)
    clarity = m / norm if norm > 1e-9 else 0.0
    unit = 1.0 / m if m > 1e-12 else 0.0
    return clarity * re * unit, clarity * im * unit, clarity, math.log2(period / PRIOR_PERIOD)
