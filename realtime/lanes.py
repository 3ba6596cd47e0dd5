"""The engine's per-configuration and per-performer state: :class:`FeatureGroup` and :class:`Lane`.

A :class:`FeatureGroup` is the input stage's part for one feature configuration (one extractor,
the lanes it feeds, its frame numbering and time stamps); a :class:`Lane` is one performer inside
the engine (its model, guard, smoothing, idle fade, offset queue, sinks and counters). Both are
written on the engine's worker thread only, but for the settings (docs/architecture.md, "Where
state lives").
"""

from __future__ import annotations

import logging
import threading
from collections import deque

import numpy as np

from models.errors import ConfigError
from models.timebase import FPS
from realtime.contracts import ExtractorFactory, FeatureStream
from realtime.engine_config import EngineConfig, check_live_setting
from realtime.frame import PoseFrame, Sink
from realtime.performer import Performer, check_performer_name, cycle_frames, silence_features
from realtime.pose_filters import IdleFader, PoseSmoother, idle_pose, rest_pose
from realtime.rolling_stats import RollingStats

log = logging.getLogger("realtime.engine")  # the engine's log


class FeatureGroup:
    """The input stage's part for one feature configuration: one extractor, the performers it
    feeds, and the frame numbering and time stamps of its frames."""

    def __init__(self, factory: ExtractorFactory, key: object) -> None:
        self.factory = factory
        self.key = key
        self.extractor: FeatureStream | None = None
        self.lanes: list[Lane] = []
        self.index = 0  # frames emitted since the last full reset
        self.seg_index0 = 0  # frame index where the current extractor segment began
        self.time0 = 0.0  # stream audio time (s) where it began
        self._silence: list[np.ndarray | None] = []

    def silence_row(self) -> np.ndarray | None:
        """:func:`silence_features` of this group's extractor, computed once."""
        if not self._silence:
            self._silence.append(silence_features(self.factory))
        return self._silence[0]


class Lane:
    """One performer inside the engine: its model, guard, smoothing, idle fade, offset queue,
    sinks and counters (all touched on the worker thread only, but for the settings)."""

    def __init__(self, spec: Performer, config: EngineConfig, phase: int) -> None:
        self.name = check_performer_name(spec.name)
        self.model = spec.model
        self.sinks: list[Sink] = spec.sinks if isinstance(spec.sinks, list) else list(spec.sinks)
        self.offset_ms = float(config.offset_ms if spec.offset_ms is None else
                               check_live_setting("offset_ms", spec.offset_ms))
        self.smoother = PoseSmoother(config.smoothing if spec.smoothing is None else
                                     check_live_setting("smoothing", spec.smoothing))
        self.fader = IdleFader(idle_pose(), max(1, round(config.idle_fade_s * FPS)))
        self.cycle = cycle_frames(spec.model)
        if phase < 0:
            raise ConfigError(f"performer {self.name!r}: phase must be >= 0, got {phase}")
        self.phase = int(phase) % self.cycle
        self.idle = False
        self.group: FeatureGroup | None = None
        self.last_good = rest_pose()
        self.delayed: deque[tuple[float, PoseFrame, float]] = deque()
        self.sink_errors: dict[str, int] = {}
        self.compute_ms = RollingStats(config.stats_size)
        self.compute_cpu_ms = RollingStats(config.stats_size)  # the worker thread's CPU time in compute_ms
        self.latency_ms = RollingStats(config.stats_size)
        self.reset_requested = threading.Event()
        self.last_frame: PoseFrame | None = None
        self.zero()

    def zero(self) -> None:
        self.frames_out = 0
        self.nan_frames = 0
        self.resets = 0

    def sink_stats(self) -> dict[str, dict]:
        """Each sink's ``stats()`` by its name (``{"stats_error": 1.0}`` for one that raised)."""
        sinks = {}
        for s in self.sinks:
            try:
                sinks[s.name] = dict(s.stats())
            except Exception as exc:  # noqa: BLE001
                sinks[s.name] = {"stats_error": 1.0}
                log.debug("stats() of %s failed: %s", s.name, exc)
        return sinks

    def sink_notices(self) -> list[str]:
        """What the lane's sinks with a ``notice()`` say now (e.g. no OSC receiver listening)."""
        out = []
        for s in self.sinks:
            notice = getattr(s, "notice", None)
            try:
                text = notice() if notice is not None else None
            except Exception as exc:  # noqa: BLE001
                text = None
                log.debug("notice() of %s failed: %s", getattr(s, "name", s), exc)
            if text:
                out.append(str(text))
        return out

    def stats(self, sinks: dict[str, dict]) -> dict:
        """This performer's part of :meth:`realtime.engine.Engine.stats`: frames, settings, stagger,
        compute and latency p50/p99 (ms), faults and its ``sinks`` (:meth:`sink_stats`)."""
        return {
            "frames": self.frames_out,
            "idle": self.idle,
            "offset_ms": self.offset_ms,
            "smoothing": self.smoother.alpha,
            "phase": self.phase,
            "cycle": self.cycle,
            "compute_ms_p50": self.compute_ms.percentile(50),
            "compute_ms_p99": self.compute_ms.percentile(99),
            "latency_ms_p50": self.latency_ms.percentile(50),
            "latency_ms_p99": self.latency_ms.percentile(99),
            "nan_frames": self.nan_frames,
            "sink_errors": sum(self.sink_errors.values()),
            "resets": self.resets,
            "sinks": sinks,
        }
