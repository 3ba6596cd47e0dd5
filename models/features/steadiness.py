"""Spectral steadiness: does the fine structure of the spectrum hold still for 67 ms?

One optional feature column (:class:`~models.features.spectral.FeatureConfig` ``steadiness``)
for the idle gate's presence detector (models/networks/music_gate.py): music holds notes, so
the harmonics of one frame sit where they sat two frames (67 ms) before; a speaking voice
glides in pitch and changes its sound every syllable, so they do not; noise, applause and
crowds have no harmonics to hold. Frame t (30 fps, its hop-ending window of ``n_fft``
samples at 22050 Hz, as the spectral features):

* ``L[t]``: log magnitude of the Hann-windowed spectrum in :data:`BAND` (150-3000 Hz: the
  voice's and most instruments' harmonics; 10.8-Hz bins at n_fft = 2048);
* ``F[t] = L[t] - `` its moving average over :data:`SMOOTH_BINS` bins (the envelope removed:
  what remains is where the peaks are, not how loud or bright the sound is), minus its mean;
* the column is the correlation of ``F[t]`` and ``F[t - LAG]``, in [-1, 1]; 0 for the
  first :data:`LAG` frames of a stream and where either frame is silent.

Measured on recordings (median of 1-s means, benchmarks/studies/steadiness.py): read
speech 0.02-0.06, applause 0.10, room tone 0.00, crowd babble 0.20, espeak-ng speech
0.10-0.31; music and the validation songs 0.30-0.60, except trance (0.06: its dense detuned
synthesizers hold no fine structure; the detector's other statistics call it music). The detector reads the
column's running mean; the predictor never reads it (``DanceVQConfig.gate_col``).

It reads the spectral kernel's FFT of the frame (the same Hann window and ``n_fft``) and
costs one compiled pass over 260 bins a frame (:func:`_steady_rows`); docs/features.md
gives the figures. The tracker keeps the last
:data:`LAG` rows ``F``; streamed in any chunking it equals the offline column
(tests/test_steadiness.py).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from models.timebase import SAMPLE_RATE

#: Frames between the two spectra compared (2 frames = 67 ms at 30 fps).
LAG: int = 2
#: Frequency band (Hz) whose fine structure is compared.
BAND: tuple[float, float] = (150.0, 3000.0)
#: Width (bins) of the moving average that is the spectral envelope.
SMOOTH_BINS: int = 9
#: Magnitude floor before the log (silence: every bin at the floor, no fine structure).
FLOOR: float = 1e-6


@njit(cache=True, nogil=True)
def _steady_rows(spec, smooth, prev, prev_norm, out):  # pragma: no cover - compiled
    """The column for consecutive frames' band spectra ``spec`` (k, nb) complex128, in place:
    ``out`` (k,) float64; ``prev`` (LAG, nb - smooth + 1) and ``prev_norm`` (LAG,) the last
    frames' centred fine structure and its norm, oldest first, updated."""
    k, nb = spec.shape
    lag = prev.shape[0]
    m = nb - smooth + 1
    h = smooth // 2
    logm = np.empty(nb)
    f = np.empty(m)
    for t in range(k):
        for j in range(nb):
            a = math.sqrt(spec[t, j].real ** 2 + spec[t, j].imag ** 2)
            logm[j] = math.log(a if a > FLOOR else FLOOR)
        run = 0.0
        for j in range(smooth):
            run += logm[j]
        mean = 0.0
        for j in range(m):
            if j > 0:
                run += logm[j + smooth - 1] - logm[j - 1]
            f[j] = logm[j + h] - run / smooth
            mean += f[j]
        mean /= m
        norm = 0.0
        dot = 0.0
        for j in range(m):
            f[j] -= mean
            norm += f[j] * f[j]
            dot += f[j] * prev[0, j]
        norm = math.sqrt(norm)
        den = norm * prev_norm[0]
        out[t] = dot / den if den > 1e-9 else 0.0
        for i in range(lag - 1):  # shift: the oldest row out, this frame's in
            prev_norm[i] = prev_norm[i + 1]
            for j in range(m):
                prev[i, j] = prev[i + 1, j]
        prev_norm[lag - 1] = norm
        for j in range(m):
            prev[lag - 1, j] = f[j]


class SteadinessTracker:
    """The steadiness column, frame by frame, for hop-ending windows of ``n_fft`` samples.

    ``__call__(frames)``: frames (k, n_fft) float64 -> (k,) float32, in stream order;
    ``from_spectrum(spec)`` the same from their Hann-windowed FFT (k, n_fft // 2 + 1), as the
    spectral kernel computes it (``models.features.spectral.SpectralKernel.spectrum``: the extractors
    pass theirs, so the column costs no second FFT); ``reset()`` starts a new stream. The
    FFT is NumPy's; the rest one compiled call
    (:func:`_steady_rows`: as a dozen NumPy calls it took 0.1 ms a frame on the live path,
    where caches are cold after each wait for audio).
    """

    def __init__(self, n_fft: int) -> None:
        from scipy.signal import get_window

        self.n_fft = int(n_fft)
        self.window = get_window("hann", self.n_fft, fftbins=True).astype(np.float64)
        self.lo = int(np.ceil(BAND[0] * self.n_fft / SAMPLE_RATE))
        self.hi = int(np.floor(BAND[1] * self.n_fft / SAMPLE_RATE)) + 1
        self.reset()

    def reset(self) -> None:
        nb = self.hi - self.lo - SMOOTH_BINS + 1
        self._prev = np.zeros((LAG, nb))  # the last LAG rows F (zeros: no frame yet)
        self._norm = np.zeros(LAG)  # their norms

    def __call__(self, frames: np.ndarray) -> np.ndarray:
        return self.from_spectrum(np.fft.rfft(np.asarray(frames, np.float64) * self.window, axis=-1))

    def from_spectrum(self, spec: np.ndarray) -> np.ndarray:
        out = np.zeros(len(spec))
        if len(spec):
            _steady_rows(np.ascontiguousarray(spec[:, self.lo: self.hi]), SMOOTH_BINS, self._prev, self._norm, out)
        return out.astype(np.float32)


def steadiness(frames: np.ndarray, n_fft: int) -> np.ndarray:
    """The column (T,) float32 of a whole stream's hop-ending windows (T, n_fft)."""
    return SteadinessTracker(n_fft)(np.asarray(frames, np.float64))
