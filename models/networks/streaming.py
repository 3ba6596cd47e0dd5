"""Real-time generation: the causal U-Net run as overlapping windows, frame by frame.

The engine's contract: ``StreamingGenerator.push(features (k, D)) -> poses (k, POSE_DIM)``
returns one pose per input frame at once (no look-ahead, 30 fps). Internally windows
of ``window`` frames start every ``hop`` frames; each is the causal model run from a
ZERO state at its start (as in training on ``window``-frame segments), and frame t is
the rotation-aware crossfade of the windows covering it (:mod:`models.networks.blend`).

:func:`offline_windowed` computes the same thing with the model's batched forward and
is the reference the streaming path is tested against. :class:`NaiveWindowGenerator`
is the naive real-time baseline for benchmarks (full-window recompute per frame).

Input features are sanitised the same way on every path: non-finite values become 0
(counted per frame in ``nonfinite_frames``) and values are clipped to
``±FEATURE_LIMIT``; output quaternions are always finite and unit norm.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager, nullcontext

import numpy as np
import torch

from models.errors import ConfigError
from models.networks.blend import blend_track, num_slots, slot_weights
from models.networks.causal import CausalGenerator
from models.networks.generator import LEVELS, UNetGenerator
from models.networks.numpy_step import NumpyStep

FEATURE_LIMIT = 1e4  # |feature| clip: keeps float32 activations finite (features are O(1..100))


@contextmanager
def torch_threads(n: int) -> Iterator[None]:
    """Run the block with ``torch.set_num_threads(n)``, then restore the previous count.

    The streaming step is many tiny matrix products: one intra-op thread is as fast as
    two, and far steadier when the cores are busy (a second thread that is not
    scheduled stalls every op). The count is process-wide: use from the engine's setup.
    """
    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def sanitize_features(x: np.ndarray) -> tuple[np.ndarray, int]:
    """float32 copy of x (k, D) with non-finite values -> 0, clipped; and the count of bad frames."""
    x = np.asarray(x, dtype=np.float32)
    bad = ~np.isfinite(x)
    n_bad = int(bad.any(axis=1).sum()) if x.ndim == 2 else int(bad.any())
    x = np.where(bad, np.float32(0.0), x)
    return np.clip(x, -FEATURE_LIMIT, FEATURE_LIMIT), n_bad


def _check_features(x: np.ndarray, dim: int) -> np.ndarray:
    x = np.asarray(x)
    if x.ndim != 2 or x.shape[1] != dim:
        raise ConfigError(f"features must have shape (frames, {dim}) for this model, got {x.shape}")
    return x


def _check_windows(window: int, hop: int) -> None:
    mult = 2**LEVELS
    if hop < 1 or hop % mult or not hop <= window:
        raise ConfigError(
            f"hop must be a positive multiple of {mult} (same pooling phase in every window) "
            f"and <= window; got window={window}, hop={hop}"
        )


@torch.inference_mode()
def offline_windowed(
    model: UNetGenerator, features: np.ndarray, window: int = 128, hop: int = 64, batch: int = 32
) -> np.ndarray:
    """Reference windowed generation: features (T, D) -> poses (T, POSE_DIM) float32.

    Runs ``model.forward`` on each window (those past the end are partial: zero-padded
    on the right, which is exact for a causal model) and blends as the stream does.
    ``batch`` windows go through the model at a time. Puts the model in eval mode.
    """
    _check_windows(window, hop)
    x, _ = sanitize_features(_check_features(features, model.config.feature_dim))
    model.eval()
    t = len(x)
    starts = list(range(0, t, hop))
    padded = np.zeros((len(starts), window, x.shape[1]), dtype=np.float32)
    for i, s in enumerate(starts):
        seg = x[s : s + window]
        padded[i, : len(seg)] = seg
    outs = [
        model(torch.from_numpy(padded[i : i + batch]).transpose(1, 2)).transpose(1, 2).numpy()
        for i in range(0, len(starts), batch)
    ]
    win_out = np.concatenate(outs) if outs else np.zeros((0, window, model.config.pose_dim), np.float32)
    index, w = slot_weights(np.arange(t), window, hop)
    frames = np.arange(t)
    cand = win_out[np.clip(index, 0, None), np.clip(frames[None] - index * hop, 0, window - 1)]  # (S, T, P)
    return blend_track(cand, w)


class StreamingGenerator:
    """Frame-by-frame :func:`offline_windowed` for a :class:`CausalGenerator` (eval mode).

    All ``ceil(window / hop)`` window slots advance together as one batch through the
    incremental step (every window has the same pooling phase because hop is a
    multiple of 16), so one frame costs one incremental step, never a window
    recompute. A slot is reset to the zero state when its next window starts.
    Weights are frozen when the stream is made (BN folded); make a new one after training.

    ``step="numpy"`` (default) runs :class:`~models.networks.numpy_step.NumpyStep`, the
    lean real-time implementation; ``step="torch"`` runs :meth:`CausalGenerator.step`,
    the reference. Both give the same poses to float32 rounding.
    """

    def __init__(self, model: CausalGenerator, window: int = 128, hop: int = 64, step: str = "numpy") -> None:
        if not isinstance(model, CausalGenerator):
            raise ConfigError(f"streaming needs a causal generator, got {type(model).__name__}")
        if step not in ("numpy", "torch"):
            raise ConfigError(f"step must be 'numpy' or 'torch', got {step!r}")
        _check_windows(window, hop)
        self.model = model.eval()
        self.window, self.hop = window, hop
        self.n_slots = num_slots(window, hop)
        self.feature_dim = model.config.feature_dim
        self.pose_dim = model.config.pose_dim
        self.step_kind = step
        if step == "numpy":
            self.state = NumpyStep(model, self.n_slots)
            self._step, self._mode = self.state.step, nullcontext
        else:
            with torch.inference_mode():
                self.state = model.init_stream_state(self.n_slots)
            self._step, self._mode = self._torch_step, torch.inference_mode  # its state is inference tensors
        self.frame = 0
        self.nonfinite_frames = 0
        self._prev_quat: np.ndarray | None = None
        # Slot weights repeat every n_slots * hop frames once all slots have started.
        self._period = self.n_slots * hop
        self._steady = slot_weights(np.arange(self._period, 2 * self._period), window, hop)[1]

    def _torch_step(self, rows: np.ndarray) -> np.ndarray:
        return self.model.step(torch.from_numpy(rows), self.state).numpy()

    def _weights(self, frames: np.ndarray) -> np.ndarray:
        """(n_slots, k) crossfade weights of each slot at the given frames."""
        if frames[0] >= self._period:
            return self._steady[:, frames % self._period]
        return slot_weights(frames, self.window, self.hop)[1]

    def reset(self) -> None:
        """Forget all history: the next pushed frame is frame 0 of a new stream."""
        with torch.inference_mode():
            self.state.zero_rows(slice(None))
        self.state.frame = 0
        self.frame = 0
        self.nonfinite_frames = 0
        self._prev_quat = None

    def push(self, features: np.ndarray) -> np.ndarray:
        """Consume k >= 0 feature frames (k, D); return their k poses (k, POSE_DIM) float32."""
        x, n_bad = sanitize_features(_check_features(features, self.feature_dim))
        self.nonfinite_frames += n_bad
        k = len(x)
        slots = np.empty((self.n_slots, k, self.pose_dim), dtype=np.float32)
        frames = np.arange(self.frame, self.frame + k)
        rows = np.empty((self.n_slots, x.shape[1]), np.float32)  # the frame, once per window slot
        with self._mode():
            for i in range(k):
                t = self.frame + i
                if t % self.hop == 0:  # a window starts here: its slot restarts from zero
                    self.state.zero_rows((t // self.hop) % self.n_slots)
                rows[...] = x[i]
                slots[:, i] = self._step(rows)
        self.frame += k
        if k == 0:
            return np.zeros((0, self.pose_dim), dtype=np.float32)
        out = blend_track(slots, self._weights(frames), self._prev_quat)
        self._prev_quat = out[-1, 3:].reshape(-1, 4).copy()
        return out


class NaiveWindowGenerator:
    """Naive real-time baseline: per frame, rerun ``model.forward`` on the last ``window``
    frames (fewer at the start) and emit its last frame. Any causal model."""

    def __init__(self, model: UNetGenerator, window: int = 128) -> None:
        if not getattr(model.config, "causal", False):
            raise ConfigError("the naive window generator needs a causal model (no look-ahead)")
        self.model = model.eval()
        self.window = window
        self.feature_dim = model.config.feature_dim
        self.history = np.zeros((0, self.feature_dim), dtype=np.float32)
        self.nonfinite_frames = 0
        self._prev_quat: np.ndarray | None = None

    def reset(self) -> None:
        self.history = np.zeros((0, self.feature_dim), dtype=np.float32)
        self.nonfinite_frames = 0
        self._prev_quat = None

    def push(self, features: np.ndarray) -> np.ndarray:
        """Consume k feature frames (k, D); return k poses (k, POSE_DIM) float32."""
        x, n_bad = sanitize_features(_check_features(features, self.feature_dim))
        self.nonfinite_frames += n_bad
        out = np.empty((len(x), self.model.config.pose_dim), dtype=np.float32)
        with torch.inference_mode():
            for i, row in enumerate(x):
                self.history = np.concatenate([self.history[max(0, len(self.history) - self.window + 1) :], row[None]])
                y = self.model(torch.from_numpy(self.history.T[None].copy()))
                out[i] = y[0, :, -1].numpy()
        if len(out):
            out = blend_track(out[None], np.ones((1, len(out))), self._prev_quat)
            self._prev_quat = out[-1, 3:].reshape(-1, 4).copy()
        return out
