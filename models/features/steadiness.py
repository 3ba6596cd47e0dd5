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

It costs one real FFT of ``n_fft`` samples and a few vector operations on 260 bins a frame,
as NumPy on blocks of frames (it does not reuse the spectral kernel's FFT, so that the
spectral columns stay one compiled call): about 60 us a frame on the live path, one frame
a push (docs/features.md). The tracker keeps the last
:data:`LAG` rows ``F``; streamed in any chunking it equals the offline column
(tests/test_steadiness.py).
"""

from __future__ import annotations

import numpy as np

from models.timebase import SAMPLE_RATE

#: Frames between the two spectra compared (2 frames = 67 ms at 30 fps).
LAG: int = 2
#: Frequency band (Hz) whose fine structure is compared.
BAND: tuple[float, float] = (150.0, 3000.0)
#: Width (bins) of the moving average that is the spectral envelope.
SMOOTH_BINS: int = 9
#: Magnitude floor before the log (silence: every bin at the floor, no fine structure).
FLOOR: float = 1e-6


class SteadinessTracker:
    """The steadiness column, frame by frame, for hop-ending windows of ``n_fft`` samples.

    ``__call__(frames)``: frames (k, n_fft) float64 -> (k,) float32, in stream order;
    ``reset()`` starts a new stream.
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
        k = len(frames)
        if k == 0:
            return np.zeros(0, np.float32)
        spec = np.abs(np.fft.rfft(frames * self.window, axis=-1)[:, self.lo: self.hi])
        logm = np.log(np.maximum(spec, FLOOR))
        c = np.cumsum(logm, axis=1)
        c = np.concatenate([np.zeros((k, 1)), c], axis=1)
        env = (c[:, SMOOTH_BINS:] - c[:, :-SMOOTH_BINS]) / SMOOTH_BINS  # (k, nb) moving average
        h = SMOOTH_BINS // 2
        f = logm[:, h: h + env.shape[1]] - env
        f -= f.mean(axis=1, keepdims=True)
        norm = np.sqrt((f * f).sum(axis=1))
        allf = np.concatenate([self._prev, f])
        alln = np.concatenate([self._norm, norm])
        dot = (allf[LAG:] * allf[:-LAG]).sum(axis=1)
        den = alln[LAG:] * alln[:-LAG]
        out = np.where(den > 1e-9, dot / np.maximum(den, 1e-9), 0.0)
        self._prev, self._norm = allf[-LAG:].copy(), alln[-LAG:].copy()
        return out.astype(np.float32)


def steadiness(frames: np.ndarray, n_fft: int) -> np.ndarray:
    """The column (T,) float32 of a whole stream's hop-ending windows (T, n_fft)."""
    return SteadinessTracker(n_fft)(np.asarray(frames, np.float64))
