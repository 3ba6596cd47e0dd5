"""Reading audio files into the project's mono 22050 Hz float32 signals.

:func:`load_audio` decodes with soundfile (libsndfile: WAV, FLAC, OGG, MP3, ...),
falls back to ``librosa.load`` only if soundfile cannot read the file, mixes down
with :func:`to_mono` and resamples with :func:`models.features.resample.resample`,
the same code (and filter) the live path runs block by block, so a file's features
equal the features streamed from the same samples.
"""

from __future__ import annotations

import importlib.resources
import math
import os
import warnings
from pathlib import Path

import numpy as np

from models.errors import AudioError
from models.features.resample import check_rate, resample
from models.timebase import SAMPLE_RATE

CLIP_NAME = "clip.ogg"


def to_mono(x: np.ndarray, *, source: str | None = None) -> np.ndarray:
    """Mix (n,) or (n, channels) samples down to float32 (n,) by the channel mean.

    Floats are taken as full scale +-1; integer PCM is scaled to it (int16 / 2**15,
    uint8 centred on 128), as soundfile does.
    """
    x = np.asarray(x)
    if x.dtype.kind == "f":
        x = x.astype(np.float32, copy=False)
    elif x.dtype.kind == "i":
        x = x.astype(np.float32) / np.float32(2 ** (8 * x.dtype.itemsize - 1))
    elif x.dtype.kind == "u":
        half = 2 ** (8 * x.dtype.itemsize - 1)
        x = (x.astype(np.float32) - np.float32(half)) / np.float32(half)
    else:
        raise AudioError(f"audio samples must be numbers, got dtype {x.dtype}", source=source)
    if x.ndim == 2:
        return x.mean(axis=1, dtype=np.float32) if x.shape[1] != 1 else x[:, 0]
    if x.ndim != 1:
        raise AudioError(f"audio must have shape (n,) or (n, channels), got {x.shape}", source=source)
    return x


def check_finite(x: np.ndarray, sr: int, *, source: str | os.PathLike | None = None) -> None:
    """Raise AudioError saying how many samples of (n,) or (n, C) ``x`` are NaN/inf and where.

    For samples of 4 bytes or less (float32, PCM) the common case is one float64 sum, finite
    exactly when every sample is (such samples cannot overflow it): the live path calls this
    for every block.
    """
    if x.dtype.itemsize <= 4 and math.isfinite(float(np.add.reduce(x, axis=None, dtype=np.float64))):
        return
    bad = ~np.isfinite(x)
    if bad.any():
        first = np.argwhere(bad)[0]
        where = f"sample {first[0]} ({first[0] / sr:.3f} s)"
        if x.ndim == 2:
            where += f", channel {first[1]}"
        raise AudioError(f"{int(bad.sum())} non-finite samples (NaN/inf), the first at {where}", source=source)


def _decode(path: Path) -> tuple[np.ndarray, int]:
    """(n, channels) float32 samples and their rate; soundfile first, then librosa."""
    import soundfile as sf

    try:
        data, sr = sf.read(path, dtype="float32", always_2d=True)
        return data, int(sr)
    except Exception as sf_err:  # libsndfile raises several types for unreadable files
        try:
            import librosa

            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                y, sr = librosa.load(path, sr=None, mono=False, dtype=np.float32)
        except Exception as lr_err:
            raise AudioError(
                f"cannot decode audio (soundfile: {sf_err}; librosa: {type(lr_err).__name__}: {lr_err})",
                source=path,
            ) from lr_err
        return np.atleast_2d(y).T, int(sr)


def load_audio(path: str | os.PathLike, sr: int = SAMPLE_RATE, mono: bool = True) -> tuple[np.ndarray, int]:
    """Decode an audio file and resample it to ``sr`` Hz.

    Returns (float32 (n,) samples, sr) when mono, (float32 (n, channels), sr)
    otherwise; n = ceil(n_file * sr / file_rate) (reduced ratio). Raises AudioError
    naming the file when it is missing, empty, undecodable, holds NaN/inf samples, or
    has a sample rate outside 4000..192000 Hz.
    """
    path = Path(path)
    if not path.exists():
        raise AudioError("audio file not found", source=path)
    if not path.is_file():
        raise AudioError("not a regular file", source=path)
    if path.stat().st_size == 0:
        raise AudioError("audio file is empty (0 bytes)", source=path)
    sr = check_rate(sr, source=f"{path} (requested rate)")
    data, file_sr = _decode(path)
    if data.shape[0] == 0:
        raise AudioError("audio file holds no samples", source=path)
    check_rate(file_sr, source=path)
    check_finite(data, file_sr, source=path)
    if mono:
        return resample(to_mono(data, source=str(path)), file_sr, sr), sr
    return np.stack([resample(data[:, c], file_sr, sr) for c in range(data.shape[1])], axis=1), sr


def bundled_clip_path() -> Path:
    """Path of the bundled 32 s music clip (models/assets/clip.ogg; see docs/features.md)."""
    path = Path(str(importlib.resources.files("models").joinpath("assets", CLIP_NAME)))
    if not path.is_file():
        raise AudioError("bundled clip is missing from the installed package", source=path)
    return path
