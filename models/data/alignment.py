"""Audio-time alignment of DWM mocap frames and resampling to the project's 30 fps.

The reading (established by ``benchmarks/studies/alignment_study.py``; numbers in
docs/data.md, "Audio-to-motion alignment"): the ``N`` stored frames of a dance span
its music interval ``[S/25, E/25]`` seconds evenly, so frame ``i`` sits at audio time

    t_i = (S + i * (E - S) / (N - 1)) / 25        (i = 0 .. N-1)

The effective frame rate ``(N - 1) * 25 / (E - S)`` is 14-29 fps for Cha-cha and
Rumba and about 5.9 fps for Waltz: the motion is stored beat-synchronously (25
frames per 2 beats, Waltz 12 frames per 3-beat bar), not at a fixed clock rate.
The study confirms this for 28 of the 40 dances; the other 12 are listed in
:data:`UNVERIFIED_ALIGNMENT`.

Held frames: a few Cha-cha/Rumba dances hold one pose exactly for 11 or 36 frames;
the motion continues smoothly afterwards (no jump), so the hold is part of the
stored timeline and is kept, but resampled frames inside it are marked invalid.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline

from models.data.dwm import CONFIG_FPS, Dance, dance_dirs, load_dance
from models.errors import DataError
from models.timebase import FPS

#: Dances for which benchmarks/studies/alignment_study.py could not confirm the reading:
#: the H1 metre test fails (|err| >= 3 %) and the motion locks to the music's beat
#: grid at a rate more than 2.5 % away from the H1 rate (or, for W_23, the motion
#: period estimate is unreliable).  Their timestamps follow the same rule; leave
#: them out of anything that measures or learns music-motion synchrony.
UNVERIFIED_ALIGNMENT: dict[str, str] = {
    "DANCE_C_4": "metre test -9.8 %, beat lock peaks at 0.905 x the H1 rate",
    "DANCE_C_7": "metre test -16.6 %, beat lock peaks at 0.861 x the H1 rate",
    "DANCE_R_4": "metre test -12.9 %, beat lock peaks at 0.874 x the H1 rate",
    "DANCE_R_7": "metre test +8.7 %, beat lock peaks at 1.109 x the H1 rate",
    "DANCE_W_7": "metre test +10.2 %, beat lock peaks at 1.070 x the H1 rate",
    "DANCE_W_11": "metre test +7.2 %, beat lock peaks at 1.087 x the H1 rate",
    "DANCE_W_12": "metre test +3.9 %, beat lock peaks at 1.046 x the H1 rate",
    "DANCE_W_14": "metre test +9.2 %, beat lock peaks at 1.106 x the H1 rate",
    "DANCE_W_16": "metre test +6.5 %, beat lock peaks at 1.061 x the H1 rate",
    "DANCE_W_18": "metre test -5.9 %, beat lock peaks at 0.951 x the H1 rate",
    "DANCE_W_23": "metre test +13.3 %, beat lock peaks at 0.932 x the H1 rate",
    "DANCE_W_30": "metre test +13.9 %, beat lock peaks at 1.150 x the H1 rate",
}


@dataclass(frozen=True)
class AlignedDance:
    """One dance on the project's time base.

    Attributes:
        name: directory name, e.g. ``DANCE_C_2``.
        style: ``C``, ``R`` or ``W``.
        audio_path: the song; frame ``t`` is at audio time ``audio_start_s + t / fps``.
        positions_m: (T, 23, 3) float64 world joint positions in metres (Y up),
            cubic-spline resampled at ``fps``.
        valid: (T,) bool; False for frames inside (or one source frame around) a
            held-pose run, where the stored motion is frozen.
        audio_start_s: audio time (s) of frame 0 (= S / 25).
        fps: frame rate of ``positions_m`` (the project's ``FPS`` unless asked otherwise).
        source_fps: effective rate of the stored frames, ``(N - 1) * 25 / (E - S)``.
    """

    name: str
    style: str
    audio_path: Path
    positions_m: np.ndarray
    valid: np.ndarray
    audio_start_s: float
    fps: float
    source_fps: float

    @property
    def T(self) -> int:  # noqa: N802 - the conventional name for a frame count
        """Number of frames."""
        return int(self.positions_m.shape[0])

    @property
    def duration_s(self) -> float:
        return self.T / self.fps

    def times_s(self) -> np.ndarray:
        """(T,) audio time in seconds of every frame."""
        return self.audio_start_s + np.arange(self.T) / self.fps


def motion_timestamps(dance: Dance) -> np.ndarray:
    """(N,) audio time in seconds of every stored mocap frame (even span of [S/25, E/25])."""
    n = dance.num_frames
    i = np.arange(n, dtype=np.float64)
    return (dance.start_frame + i * (dance.end_frame - dance.start_frame) / (n - 1)) / CONFIG_FPS


def source_fps(dance: Dance) -> float:
    """Effective frame rate (frames per second of audio) of the stored frames."""
    return (dance.num_frames - 1) * CONFIG_FPS / (dance.end_frame - dance.start_frame)


def held_frames(dance: Dance) -> np.ndarray:
    """(N,) bool: True for a frame exactly equal (every joint, every axis) to its predecessor."""
    w = dance.world_positions_m()
    held = np.zeros(dance.num_frames, dtype=bool)
    held[1:] = np.all(w[1:] == w[:-1], axis=(1, 2))
    return held


def held_runs(dance: Dance) -> list[tuple[int, int]]:
    """Runs of held frames as (first held frame, length); the pose held is frame ``first - 1``."""
    held = held_frames(dance)
    edges = np.diff(np.concatenate([[0], held.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [(int(s), int(e - s)) for s, e in zip(starts, ends)]


def resample_positions(dance: Dance, fps: float = FPS) -> AlignedDance:
    """Resample a dance's world joint positions onto a regular ``fps`` grid of audio time.

    Frame ``t`` is at ``S/25 + t/fps`` s, for every ``t`` with that time inside the
    span of :func:`motion_timestamps`; positions come from a cubic spline
    (``scipy.interpolate.CubicSpline``, not-a-knot ends) through all stored frames.
    Held-pose runs are kept as stored (they are part of the timeline) and the output
    frames from one source frame before to one after each run get ``valid=False``.
    """
    if not fps > 0:
        raise DataError(f"resampling rate must be positive, got {fps!r}", source=dance.directory)
    ts = motion_timestamps(dance)
    t_out = ts[0] + np.arange(int(np.floor((ts[-1] - ts[0]) * fps + 1e-9)) + 1) / fps
    spline = CubicSpline(ts, dance.world_positions_m().reshape(dance.num_frames, -1), axis=0)
    positions = spline(t_out).reshape(len(t_out), -1, 3)

    valid = np.ones(len(t_out), dtype=bool)
    for first, length in held_runs(dance):
        lo = ts[max(first - 2, 0)]
        hi = ts[min(first + length, dance.num_frames - 1)]
        valid &= ~((t_out >= lo) & (t_out <= hi))
    return AlignedDance(
        name=dance.name,
        style=dance.style,
        audio_path=dance.audio_path,
        positions_m=positions,
        valid=valid,
        audio_start_s=float(ts[0]),
        fps=float(fps),
        source_fps=source_fps(dance),
    )


def load_aligned_dataset(
    root: str | Path, names: list[str] | None = None, *, exclude_unverified: bool = False, fps: float = FPS
) -> list[AlignedDance]:
    """Load and resample the dances under ``root`` (all, or only ``names``), sorted by style and id.

    ``exclude_unverified`` drops the dances in :data:`UNVERIFIED_ALIGNMENT`. Raises
    :class:`DataError` for an unknown name or any malformed dance.
    """
    dirs = dance_dirs(root)
    if names is not None:
        by_name = {d.name: d for d in dirs}
        unknown = sorted(set(names) - by_name.keys())
        if unknown:
            raise DataError(f"no such dance(s): {', '.join(unknown)}", source=root)
        dirs = [d for d in dirs if d.name in set(names)]
    if exclude_unverified:
        dirs = [d for d in dirs if d.name not in UNVERIFIED_ALIGNMENT]
    return [resample_positions(load_dance(d), fps) for d in dirs]
