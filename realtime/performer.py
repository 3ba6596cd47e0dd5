"""One performer of the engine: its spec (:class:`Performer`), its name check, and its stagger.

An ensemble's performers share one input; :func:`stagger_lead` and :func:`cycle_frames` say how
many feature frames of silence (:func:`silence_features`) a performer's model hears after a
reset, so that the expensive frames of the performers' cycles fall on different hops. No state
(a :class:`Performer` is a plain record the engine reads at construction).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from models.errors import ConfigError, short_repr
from models.timebase import SAMPLE_RATE
from realtime.contracts import ExtractorFactory, PoseModel


#: Longest performer name, characters (names appear in OSC addresses and WebSocket paths).
MAX_NAME_CHARS: int = 32
_NAME_CHARS = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_-")


def check_performer_name(value: object) -> str:
    """A performer name: 1..:data:`MAX_NAME_CHARS` ASCII letters, digits, ``_`` or ``-`` (it becomes
    part of OSC addresses and WebSocket paths); :class:`ConfigError` otherwise."""
    if not isinstance(value, str) or not value or len(value) > MAX_NAME_CHARS or not set(value) <= _NAME_CHARS:
        raise ConfigError(f"performer name must be 1..{MAX_NAME_CHARS} letters, digits, '_' or '-', "
                          f"got {short_repr(value)}")
    return value


def cycle_frames(model: object) -> int:
    """The period, in frames, of a pose model's cost: ``cycle_frames`` when the model declares it,
    else a :class:`~models.networks.dance_stream.DanceStream`'s ``seg`` (its code step, the
    expensive frame, comes once every ``seg`` frames), else 1 (an even cost: nothing to stagger)."""
    for attr in ("cycle_frames", "seg"):
        value = getattr(model, attr, None)
        if isinstance(value, int) and not isinstance(value, bool) and value >= 1:
            return value
    return 1


def silence_features(extractor_factory: ExtractorFactory) -> np.ndarray | None:
    """The feature frame a fresh extractor gives for digital silence (built for 22050 Hz, so
    the same whatever the input rate): what a staggered performer hears before the input's
    first frame (:attr:`Performer.phase`). None if the extractor gives no frame for 1 s of it."""
    feats = np.asarray(extractor_factory(SAMPLE_RATE).push(np.zeros(SAMPLE_RATE, dtype=np.float32)))
    return feats[0].astype(np.float32, copy=True) if len(feats) else None


def stagger_lead(model: PoseModel, extractor_factory: ExtractorFactory, phase: int) -> np.ndarray | None:
    """The feature frames a performer with this ``phase`` hears after a reset, before the input:
    ``phase % cycle_frames(model)`` copies of :func:`silence_features` ((k, D); None for none). Its
    stream then equals the offline pass on these frames followed by the input's, from frame k on."""
    k = int(phase) % cycle_frames(model)
    row = silence_features(extractor_factory) if k else None
    return None if row is None else np.repeat(row[None], k, axis=0)


@dataclass
class Performer:
    """One performer of an :class:`~realtime.engine.Engine`: a pose model and everything after it.

    ``extractor_factory`` builds its feature stream; performers whose ``feature_key`` is
    equal (and not None) share one extractor (:func:`realtime.pipeline.build_pipeline`
    sets it to the feature config's fingerprint), the others get one each.
    ``smoothing`` / ``offset_ms``: None takes :class:`~realtime.engine_config.EngineConfig`'s.
    ``phase``: feature frames of silence the model hears after every reset, before the input's
    first frame (taken modulo :func:`cycle_frames`), so that the expensive frames of the
    performers' cycles fall on different hops; None spreads the engine's performers evenly (performer
    ``i`` of ``n``: ``i * cycle // n``). Phase 0 is today's single performer exactly.
    """

    name: str
    model: PoseModel
    extractor_factory: ExtractorFactory
    sinks: list = field(default_factory=list)
    feature_key: object = None
    smoothing: float | None = None
    offset_ms: float | None = None
    phase: int | None = None
