"""What the engine needs of a live pose model and of a streaming feature extractor.

:class:`PoseModel` and :class:`FeatureStream` are the protocols :class:`realtime.engine.Engine`
runs (docs/architecture.md, "The contracts"); :data:`ExtractorFactory` builds a feature stream
for an input rate. Protocols only: no state.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class FeatureStream(Protocol):
    """Streaming audio features (e.g. ``StreamingFeatureExtractor``).

    ``push(block)`` takes (n,) float32 mono samples at the rate it was built for and
    returns (k, D) float32: every 30 fps frame whose audio is complete, in order. It
    must copy what it keeps (the engine reuses the block's buffer). Optional, for
    exact time stamps: ``samples_needed(i)``, the input samples after which frame ``i``
    is returned; otherwise ``latency_samples`` (input samples needed after the frame's
    nominal end ``(i + 1) * HOP / 22050`` s) is used.
    """

    def push(self, block: np.ndarray) -> np.ndarray: ...

    def reset(self) -> None: ...


@runtime_checkable
class PoseModel(Protocol):
    """Streaming pose model (e.g. ``StreamingGenerator``): one pose out per feature frame in.

    ``push(features)`` takes (k, feature_dim) float32 and returns (k, POSE_DIM)
    float32 in the :mod:`models.rig.motion` flat layout, causally.

    Optional show controls, used by :meth:`~realtime.engine.Engine.control` when present (looked up with
    ``getattr``, so a model without them still fits): ``set_idle(bool)`` (True: settle
    into the model's idle pose and hold it, False: dance again; the model does the
    transition, without a jump), ``set_style(name: str)``, ``set_energy(x: float)`` and
    ``set_lead(ms: float)`` (send the poses that far ahead, for a display chain's delay).
    Each validates its value and raises :class:`~models.errors.ConfigError` (one line
    naming it) for a bad one without changing anything. They are called on a control
    thread (OSC or WebSocket), not the engine's worker, so they must be cheap, must not
    block, and should only record the setting for the next ``push`` to use.
    """

    feature_dim: int

    def push(self, features: np.ndarray) -> np.ndarray: ...

    def reset(self) -> None: ...


ExtractorFactory = Callable[[int], FeatureStream]
"""Builds a fresh feature stream for a given input sample rate (Hz)."""
