"""Causal audio features at 30 frames per second (offline; see streaming.py for live).

Framing (the whole project's convention):

* Audio is at ``SAMPLE_RATE`` = 22050 Hz; frame ``t`` owns hop ``t``, the samples
  ``[t * HOP, (t + 1) * HOP)`` (HOP = 735, 33.3 ms).
* Frame ``t``'s analysis window is the ``n_fft`` samples that END with its hop:
  ``x[(t + 1) * HOP - n_fft : (t + 1) * HOP]``, zeros before the start. It is the
  frame librosa's ``stft(center=False)`` gives on the signal left-padded with
  ``n_fft - HOP`` zeros, so nothing in frame t comes from after its hop.
* Frame ``t``'s nominal time is the END of its hop, ``(t + 1) * HOP / SAMPLE_RATE``
  seconds (:func:`frame_time_s`): the instant by which all of its audio has been
  heard. A signal of ``n`` samples gives ``T = n // HOP`` frames.

Feature kinds (:class:`FeatureConfig`):

* ``"logmel_onset"`` (default, D = n_mels + 1): columns ``[0, n_mels)`` are the
  log-mel power spectrogram in dB, ``10 * log10(max(amin, mel @ |STFT|**2))``
  (``librosa.power_to_db`` with ``ref=1``, ``top_db=None``: the top_db clip is off
  because it depends on the whole signal's maximum, which is not causal); column
  ``n_mels`` is onset strength as librosa defines it, the mean over mel bands of
  ``max(0, logmel[t] - logmel[t - 1])`` (lag 1, no max filter), 0 for frame 0.
* ``"linear"`` (D = n_fft // 2 + 1): the log-compressed linear-magnitude STFT,
  ``10 * log10(max(amin, |STFT|**2))`` dB per FFT bin (= ``librosa.amplitude_to_db``
  with ``amin = sqrt(amin)``), the linear-spectrogram input the Guzheng-playing work
  used; :meth:`FeatureConfig.linear` gives n_fft = 1024, i.e. 513 bins.
* ``"mfcc"`` (D = 28, the input of A2B and of Kao & Su's violinist model): columns
  ``[0, 13)`` are 13 MFCCs as ``librosa.feature.mfcc`` defines them on the log-mel
  above (DCT-II, ``norm="ortho"``, no liftering; librosa's ``top_db=80`` clip is off,
  as for ``logmel_onset``); column 13 is the log mean energy of the frame's ``n_fft``
  raw samples, ``10 * log10(max(amin, mean(x**2)))`` dB (= ``power_to_db`` of the
  square of ``librosa.feature.rms(center=False)``); columns ``[14, 28)`` are the first
  derivatives of those 14 as a BACKWARD difference, ``f[t] - f[t - 1]`` (0 for frame
  0). librosa's ``feature.delta`` is a centred 9-frame Savitzky-Golay filter that
  needs 4 future frames (133 ms); the backward difference keeps the kind causal and
  streamable. :meth:`FeatureConfig.mfcc` gives librosa's mfcc defaults (n_fft = 2048,
  n_mels = 128).
* ``"mfcc_onset"`` (D = 29): the 28 ``"mfcc"`` columns, then the onset strength of
  ``"logmel_onset"`` (same definition, on the same log-mel the MFCCs come from) as
  column 28. The onset column is what the beat tracker (``beat_phase``) follows, so
  this is the MFCC kind that can carry beat-phase columns.

STFT: periodic Hann window (``scipy.signal.get_window('hann', n_fft)``, librosa's
default), no normalisation; mel filterbank ``librosa.filters.mel`` (Slaney scale and
area normalisation, librosa's defaults). :func:`frames_to_features` is the one place
the per-frame math lives; the offline and streaming paths both call it.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from models.errors import AudioError, ConfigError
from models.features.context import BEAT_COLUMNS, ContextTracker
from models.features.steadiness import SteadinessTracker
from models.timebase import HOP, SAMPLE_RATE

# Bump when the numbers any config produces change (definitions, resampler, framing):
# it is part of every fingerprint, so caches and checkpoints notice.
FEATURE_VERSION: int = 1
KINDS: tuple[str, ...] = ("logmel_onset", "linear", "mfcc", "mfcc_onset")
ONSET_KINDS: tuple[str, ...] = ("logmel_onset", "mfcc_onset")  # last base column = onset strength
N_MFCC: int = 13  # MFCCs of the "mfcc" kind (fixed: a config field would change every fingerprint)
_OFFLINE_CHUNK = 1024  # frames per batch in extract_features (bounds memory)


@dataclass(frozen=True)
class FeatureConfig:
    """What the audio features are. Frozen; compare with :meth:`fingerprint`.

    kind: "logmel_onset", "linear", "mfcc" or "mfcc_onset" (see module docstring).
    n_fft: STFT window length in samples at 22050 Hz (>= HOP = 735).
    n_mels, fmin, fmax: mel filterbank (Hz; used by every kind but "linear").
    amin: power floor before the log (1e-10 = -100 dB).
    sample_rate, hop: fixed by models.timebase; stored so fingerprints cover them.
    context_s: time constant (s) of the running mean of the base columns appended
        after them; 0 = off (models/features/context.py).
    beat_phase: append the 4 beat-tracker columns (kinds with an onset column:
        ``logmel_onset``, ``mfcc_onset``; context.py).
    steadiness: append one column, last: how still the spectrum's fine structure holds
        over 67 ms (models/features/steadiness.py). Only the idle gate of a dance_vq model
        reads it (``DanceVQConfig.gate_col``); the predictor never does.
    All three are off by default and then left out of :meth:`to_dict`, so configs without
    them keep the fingerprints they had before the options existed.
    """

    kind: str = "logmel_onset"
    n_fft: int = 2048
    n_mels: int = 64
    fmin: float = 0.0
    fmax: float = SAMPLE_RATE / 2
    amin: float = 1e-10
    sample_rate: int = SAMPLE_RATE
    hop: int = HOP
    context_s: float = 0.0
    beat_phase: bool = False
    steadiness: bool = False

    def __post_init__(self) -> None:
        # Canonical types, so that equal configs give equal fingerprints (JSON 0 vs 0.0).
        for name in ("n_fft", "n_mels", "sample_rate", "hop"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise ConfigError(f"feature config {name}={value!r} must be an integer")
            object.__setattr__(self, name, int(value))
        for name in ("fmin", "fmax", "amin", "context_s"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
                raise ConfigError(f"feature config {name}={value!r} must be a number")
            object.__setattr__(self, name, float(value))
        if self.kind not in KINDS:
            raise ConfigError(f"feature kind {self.kind!r} is not one of {KINDS}")
        if self.sample_rate != SAMPLE_RATE or self.hop != HOP:
            raise ConfigError(
                f"features run at {SAMPLE_RATE} Hz with hop {HOP} (models.timebase); "
                f"got sample_rate={self.sample_rate}, hop={self.hop}"
            )
        if not HOP <= self.n_fft <= 16384:
            raise ConfigError(f"n_fft={self.n_fft!r} must be an int in [{HOP}, 16384] (window >= one hop)")
        if not 1 <= self.n_mels <= 512:
            raise ConfigError(f"n_mels={self.n_mels!r} must be an int in [1, 512]")
        if self.kind in ("mfcc", "mfcc_onset") and self.n_mels < N_MFCC:
            raise ConfigError(f"the {self.kind} kind needs n_mels >= {N_MFCC} (it keeps {N_MFCC} coefficients), got {self.n_mels}")
        if not 0.0 <= self.fmin < self.fmax <= SAMPLE_RATE / 2:
            raise ConfigError(f"need 0 <= fmin < fmax <= {SAMPLE_RATE / 2} Hz; got fmin={self.fmin}, fmax={self.fmax}")
        if not 0.0 < self.amin < 1.0:
            raise ConfigError(f"amin={self.amin!r} must be in (0, 1)")
        if not 0.0 <= self.context_s <= 3600.0:
            raise ConfigError(f"context_s={self.context_s!r} must be in [0, 3600] seconds (0 = no context columns)")
        if not isinstance(self.beat_phase, (bool, np.bool_)):
            raise ConfigError(f"feature config beat_phase={self.beat_phase!r} must be true or false")
        object.__setattr__(self, "beat_phase", bool(self.beat_phase))
        if not isinstance(self.steadiness, (bool, np.bool_)):
            raise ConfigError(f"feature config steadiness={self.steadiness!r} must be true or false")
        object.__setattr__(self, "steadiness", bool(self.steadiness))
        if self.beat_phase and self.kind not in ONSET_KINDS:
            raise ConfigError(
                f"beat_phase needs a kind with an onset column ({', '.join(ONSET_KINDS)}), got {self.kind!r}"
            )

    @classmethod
    def linear(cls, n_fft: int = 1024) -> FeatureConfig:
        """The linear-magnitude spectrogram option: n_fft=1024 gives 513 dB bins."""
        return cls(kind="linear", n_fft=n_fft)

    @classmethod
    def mfcc(cls, n_mels: int = 128, n_fft: int = 2048) -> FeatureConfig:
        """The MFCC option (13 MFCC + log mean energy + backward differences, D = 28) with
        librosa.feature.mfcc's defaults n_mels = 128, n_fft = 2048."""
        return cls(kind="mfcc", n_fft=n_fft, n_mels=n_mels)

    @property
    def base_dim(self) -> int:
        """Columns of the kind itself, before any context/beat columns."""
        if self.kind == "mfcc":
            return 2 * (N_MFCC + 1)
        if self.kind == "mfcc_onset":
            return 2 * (N_MFCC + 1) + 1
        return self.n_mels + 1 if self.kind == "logmel_onset" else self.n_fft // 2 + 1

    @property
    def dim(self) -> int:
        """Feature dimension D of one frame: base, + base again with context, + 4 with beat phase,
        + 1 with steadiness."""
        return (self.base_dim * (2 if self.context_s > 0 else 1) + (BEAT_COLUMNS if self.beat_phase else 0)
                + int(self.steadiness))

    def base(self) -> FeatureConfig:
        """This config without the context/beat/steadiness columns (its columns are a prefix of ours)."""
        return dataclasses.replace(self, context_s=0.0, beat_phase=False, steadiness=False)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict, including the feature code version (options at their off value left out)."""
        d = {"version": FEATURE_VERSION, **dataclasses.asdict(self)}
        for name in ("context_s", "beat_phase", "steadiness"):
            if not d[name]:
                del d[name]
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> FeatureConfig:
        """Inverse of :meth:`to_dict`; ConfigError on unknown keys or another version."""
        d = dict(d)
        version = d.pop("version", FEATURE_VERSION)
        if version != FEATURE_VERSION:
            raise ConfigError(f"feature config version {version} != this code's version {FEATURE_VERSION}")
        unknown = set(d) - {f.name for f in dataclasses.fields(cls)}
        if unknown:
            raise ConfigError(f"unknown feature config keys {sorted(unknown)}")
        return cls(**d)

    def fingerprint(self) -> str:
        """Stable short id of the config, e.g. ``logmel_onset-d65-3f2a9c01b7e4``.

        Equal fingerprints mean equal features for equal audio; it covers
        FEATURE_VERSION, so a definition change gives new fingerprints.
        """
        blob = json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))
        return f"{self.kind}-d{self.dim}-{hashlib.sha1(blob.encode()).hexdigest()[:12]}"


def banded(mel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A mel filterbank (n_mels, n_bins) as bands: each filter's first nonzero bin (n_mels,) int64
    and its weights from there (n_mels, width) float64, zero-padded to the widest filter."""
    nz = mel != 0
    lo = np.where(nz.any(1), nz.argmax(1), 0).astype(np.int64)
    hi = np.where(nz.any(1), mel.shape[1] - nz[:, ::-1].argmax(1), 0)
    width = int((hi - lo).max(initial=1))
    w = np.zeros((mel.shape[0], width))
    for m, (a, b) in enumerate(zip(lo, hi)):
        w[m, : b - a] = mel[m, a:b]
    return lo, w


@njit(cache=True, nogil=True)
def _log_mel(spec, lo, w, amin):  # pragma: no cover - compiled
    """``10 log10(max(amin, mel @ |spec|**2))`` of STFT rows ``spec`` (k, n_bins) complex, the
    filterbank as :func:`banded` gives it -> (k, n_mels) float64.

    Why compiled: a dense 1025 x 128 float64 filterbank is a 1 MB matrix product per live
    frame (0.15 ms with cold caches) for about 2,000 nonzero weights.
    """
    k, nb = spec.shape
    n_mels, width = w.shape
    out = np.empty((k, n_mels))
    power = np.empty(nb)
    for f in range(k):
        for j in range(nb):
            power[j] = spec[f, j].real ** 2 + spec[f, j].imag ** 2
        for m in range(n_mels):
            acc = 0.0
            top = min(width, nb - lo[m])
            for j in range(top):
                acc += w[m, j] * power[lo[m] + j]
            out[f, m] = 10.0 * np.log10(max(acc, amin))
    return out


class SpectralKernel:
    """Precomputed window and filterbank for one config; turns frames into features."""

    def __init__(self, cfg: FeatureConfig) -> None:
        import librosa
        from scipy.signal import get_window

        self.cfg = cfg
        self.window = get_window("hann", cfg.n_fft, fftbins=True).astype(np.float64)
        self.mel_lo = self.mel_w = None  # the mel filterbank as bands (:func:`banded`)
        self.dct_t = None
        if cfg.kind != "linear":
            mel = librosa.filters.mel(
                sr=cfg.sample_rate, n_fft=cfg.n_fft, n_mels=cfg.n_mels, fmin=cfg.fmin, fmax=cfg.fmax, dtype=np.float64
            )
            self.mel_lo, self.mel_w = banded(mel)
        if cfg.kind in ("mfcc", "mfcc_onset"):
            from scipy.fft import dct

            # Columns of the orthonormal DCT-II (librosa.feature.mfcc's dct_type=2, norm="ortho").
            self.dct_t = np.ascontiguousarray(dct(np.eye(cfg.n_mels), type=2, norm="ortho", axis=-1)[:, :N_MFCC])

    def spectrum(self, frames: np.ndarray) -> np.ndarray:
        """The Hann-windowed FFT (k, n_fft // 2 + 1) complex128 of frames (k, n_fft): what
        :meth:`__call__` reads, computed once when another column needs it too."""
        return np.fft.rfft(frames * self.window, axis=-1)

    def __call__(self, frames: np.ndarray, prev_logmel: np.ndarray | None,
                 spec: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """Features of consecutive frames.

        frames: (k, n_fft) float64 windows of 22050 Hz audio (frame t = hop-ending window).
        prev_logmel: the state row of the frame before ``frames[0]``, None at stream start:
        its log-mel (n_mels,) for "logmel_onset", its 13 MFCC + log energy (14,) for "mfcc",
        both of those (14 + n_mels,) for "mfcc_onset".
        spec: the frames' :meth:`spectrum`, if already computed.
        Returns ((k, base_dim) float32 base features, last state row to pass as the next prev_logmel).
        """
        if spec is None:
            spec = self.spectrum(frames)
        amin = self.cfg.amin
        if self.mel_w is None:
            power = spec.real**2 + spec.imag**2  # (k, n_fft//2+1)
            return (10.0 * np.log10(np.maximum(power, amin))).astype(np.float32), None
        logmel = _log_mel(spec, self.mel_lo, self.mel_w, amin)  # (k, n_mels)
        out = np.empty((logmel.shape[0], self.cfg.base_dim), np.float32)
        state = []
        if self.dct_t is not None:  # "mfcc", "mfcc_onset": static 14 + backward differences
            n = N_MFCC + 1
            static = np.empty((logmel.shape[0], n))
            static[:, :N_MFCC] = logmel @ self.dct_t
            static[:, N_MFCC] = 10.0 * np.log10(np.maximum((frames * frames).mean(axis=-1), amin))
            first = static[:1] if prev_logmel is None else prev_logmel[None, :n]
            out[:, :n] = static
            out[:, n : 2 * n] = static - np.concatenate([first, static[:-1]])
            state.append(static[-1])
            if self.cfg.kind == "mfcc":
                return out, state[0].copy()
            prev_logmel = None if prev_logmel is None else prev_logmel[n:]
        else:
            out[:, :-1] = logmel
        # Predecessor rows; frame 0 of a stream is its own predecessor (onset 0, as librosa pads).
        first = logmel[:1] if prev_logmel is None else prev_logmel[None]
        out[:, -1] = np.maximum(logmel - np.concatenate([first, logmel[:-1]]), 0.0).mean(axis=1)
        state.append(logmel[-1])
        return out, np.concatenate(state)


def frame_time_s(t: int | np.ndarray) -> float | np.ndarray:
    """Nominal time (s) of frame t: the END of its hop, (t + 1) * HOP / SAMPLE_RATE."""
    return (np.asarray(t) + 1) * HOP / SAMPLE_RATE


def num_frames(n_samples: int) -> int:
    """Frames in a 22050 Hz signal of n_samples: floor(n / HOP)."""
    return int(n_samples) // HOP


def causal_frames(audio: np.ndarray, n_fft: int) -> np.ndarray:
    """(T, n_fft) read-only view of the hop-ending analysis windows of ``audio`` (n,).

    Row t is ``audio[(t+1)*HOP - n_fft : (t+1)*HOP]`` with zeros before sample 0.
    """
    t = num_frames(audio.shape[0])
    if t == 0:
        return np.zeros((0, n_fft))
    padded = np.concatenate([np.zeros(n_fft - HOP), np.asarray(audio, np.float64)])
    return np.lib.stride_tricks.sliding_window_view(padded, n_fft)[:: HOP][:t]


def extract_features(audio: np.ndarray, cfg: FeatureConfig | None = None) -> np.ndarray:
    """Causal features of a whole mono 22050 Hz signal.

    audio: (n,) float samples at SAMPLE_RATE (load with models.features.audio_io.load_audio).
    Returns (n // HOP, cfg.dim) float32; row t uses only samples < (t + 1) * HOP.
    Columns ``[base | context | beat | steadiness]`` as the config asks.
    """
    cfg = cfg or FeatureConfig()
    audio = np.asarray(audio)
    if audio.ndim != 1:
        raise AudioError(f"extract_features wants mono audio of shape (n,), got shape {audio.shape}")
    if not np.all(np.isfinite(audio)):
        raise AudioError(f"audio holds {int(np.sum(~np.isfinite(audio)))} non-finite samples (NaN/inf)")
    kernel = SpectralKernel(cfg)
    extra = ContextTracker(cfg.base_dim, cfg.context_s, cfg.beat_phase)
    frames = causal_frames(audio, cfg.n_fft)
    steady = SteadinessTracker(cfg.n_fft) if cfg.steadiness else None
    end = cfg.base_dim + extra.extra_dim
    out = np.empty((frames.shape[0], cfg.dim), np.float32)
    prev = None
    for lo in range(0, frames.shape[0], _OFFLINE_CHUNK):
        spec = kernel.spectrum(frames[lo : lo + _OFFLINE_CHUNK])
        base, prev = kernel(frames[lo : lo + _OFFLINE_CHUNK], prev, spec)
        out[lo : lo + base.shape[0], : cfg.base_dim] = base
        out[lo : lo + base.shape[0], cfg.base_dim : end] = extra(base)
        if steady is not None:
            out[lo : lo + base.shape[0], end] = steady.from_spectrum(spec)
    return out
