"""What the engine hands to every output: one pose frame, 30 per second of audio."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass(slots=True)
class PoseFrame:
    """One streamed pose.

    Attributes:
        index: frame number since the engine (re)started; frame ``i`` covers audio
            up to ``(i + 1) * HOP`` samples at ``models.timebase.SAMPLE_RATE``.
        audio_sample: index, at the input's own sample rate, of the input sample that
            completed this frame (counted from the start of the stream).
        audio_time: audio time the pose represents, in seconds from the stream start.
        wall_time: ``time.monotonic()`` seconds when the frame was handed to outputs.
        pose: (POSE_DIM,) float32, the flat layout of :mod:`models.rig.motion`: root
            position (metres) then one local quaternion x, y, z, w per humanoid bone,
            project frame (right-handed, Y up, faces +Z).
        released: ``time.monotonic()`` seconds when the audio block holding
            ``audio_sample`` was released (the engine sets it when sending; NaN: unknown),
            so a sink can measure block release -> its own work.
    """

    index: int
    audio_sample: int
    audio_time: float
    wall_time: float
    pose: np.ndarray
    released: float = float("nan")


class Sink(Protocol):
    """An output of the engine (OSC target, WebSocket server, recorder).

    ``send`` is called on the engine's worker thread once per frame and must never
    block on the network, the disk or a slow peer: it queues or drops (and counts
    the drop). ``stats`` returns counters for the status line.

    Optional: ``begin_hop()`` / ``end_hop()``, called by the engine around each hop's
    performers (:meth:`realtime.engine.Engine._run_lanes`): a sink that hands frames to a
    thread of its own may hold the hand-off until ``end_hop``, so that thread does not
    take the interpreter lock from the performers still to run. ``notice()`` returns a
    short text for the status line while something about the output needs saying (an OSC
    target with no receiver listening), else None. ``set_state(state)`` takes the performer's
    stage and facing (``{"stage": [W, D], "facing": "free"}``) at the engine's start and
    whenever a control changes them (the WebSocket viewer draws the stage).
    """

    name: str

    def send(self, frame: PoseFrame) -> None: ...

    def close(self) -> None: ...

    def stats(self) -> dict[str, float]: ...
