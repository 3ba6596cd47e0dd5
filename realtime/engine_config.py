"""The engine's knobs: :class:`EngineConfig`, and which of them may change while it runs.

:data:`LIVE_SETTINGS` names the settings :meth:`realtime.engine.Engine.update` (and the
``set_offset`` / ``set_smoothing`` controls) change live; :func:`check_live_setting` checks one.
No state.
"""

from __future__ import annotations

from dataclasses import dataclass

from models.errors import ConfigError, short_repr
from realtime.controls import check_finite


@dataclass
class EngineConfig:
    """Knobs of :class:`~realtime.engine.Engine`. ``performer run`` sets the first five from ``--smoothing``,
    ``--offset-ms``, ``--threads``, ``--warmup`` and ``--duration``."""

    smoothing: float = 0.0  # [0, 1): exponential smoothing weight (see PoseSmoother)
    offset_ms: float = 0.0  # >0 delays sending and shifts audio_time; <0 only shifts audio_time
    threads: int | None = 1  # torch.set_num_threads at start (None: leave torch alone)
    warmup_s: float = 3.0  # s of silence run through the pipeline at start after KERNEL_NOISE_S of noise (0: none)
    duration_s: float | None = None  # stop after this much input audio (None: until the source ends)
    ring_seconds: float = 2.0  # audio ring capacity
    max_read: int = 8192  # most input samples processed per worker step
    stall_timeout_s: float = 1.0  # no audio for this long (source alive) -> state "stalled"
    retry_s: float = 1.0  # after a source error, retry start() this often
    stats_size: int = 2048  # frames kept for p50/p99
    fallback_after_s: float = 2.0  # no audio from the source this long -> switch to the fallback source
    idle_fade_s: float = 1.0  # the engine's own idle crossfade, each way (models without set_idle)
    # Linux, for the benchmark: also keep each hop's run-queue wait (the time this process's
    # threads were ready to run but other processes had the CPUs, /proc/self/task/*/schedstat,
    # at most the hop less the worker's CPU time) in compute_wait_ms
    runqueue_wait: bool = False


#: Settings :meth:`~realtime.engine.Engine.update` can change while running.
LIVE_SETTINGS: tuple[str, ...] = ("offset_ms", "smoothing")


def check_live_setting(name: str, value: object) -> float:
    """Validate one live setting; return it as a float or raise :class:`ConfigError` naming it."""
    if name not in LIVE_SETTINGS:
        raise ConfigError(f"{short_repr(name)} cannot be changed while running "
                          f"(live settings: {', '.join(LIVE_SETTINGS)})")
    value = check_finite(name, value)
    if name == "offset_ms" and not -10000 <= value <= 10000:
        raise ConfigError(f"offset_ms must be -10000..10000 ms, got {value!r}")
    if name == "smoothing" and not 0.0 <= value < 1.0:
        raise ConfigError(f"smoothing must be in [0, 1), got {value!r}")
    return value
