"""A motion library: a user's clips on the humanoid rig at 30 fps, in one ``.npz`` file.

Written by ``performer library build`` (:mod:`models.data.bvh_import` reads the BVH files),
read by :func:`load_library`; the format is documented in docs/library.md. Arrays (numpy,
read without pickle; C clips, N frames in all, K scored points):

- ``format`` "live-performer library v1"; ``bones`` (21,) the rig's bone names; ``fps`` 30.0
- ``root_pos`` (N, 3) float32 metres and ``rotations`` (N, 21, 4) float32 xyzw local
  quaternions (the pose format of :mod:`models.rig.motion`), all clips one after another
- ``clip_start``, ``clip_frames`` (C,) int64: where each clip lies in those arrays
- ``clip_name``, ``clip_source`` (the BVH path as given), ``clip_folder`` (its folder's name),
  ``clip_units``, ``clip_up`` (C,) str; ``clip_mirrored`` (C,) bool; ``clip_source_fps``,
  ``clip_scale`` (rig metres per file unit), ``clip_error_mean_cm``, ``clip_error_max_cm`` (C,)
  float64
- ``error_points`` (K,) str and ``clip_point_error_mean_cm``, ``clip_point_error_max_cm``
  (C, K) float64, NaN where a clip's file has no joint for that point
- ``clip_offsets`` (C, 21, 3), ``clip_end_offsets`` (C, 9, 3) float64: each clip's own rest
  skeleton at the rig's scale (the one its error is measured on)
- ``clip_bpm`` (C,) float64, optional: the clip's tempo given at build time (``--bpm``), 0 where
  none was (the player then reads it from the motion: models/networks/library_player.py)
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from models.data.bvh_import import SCORED_POINTS, ImportedClip
from models.errors import DataError, RigError
from models.rig.humanoid import BONES, NUM_BONES
from models.rig.motion import Motion
from models.rig.npz import read_arrays
from models.rig.skeleton import Skeleton
from models.timebase import FPS

FORMAT = "live-performer library v1"


@dataclass
class LibraryClip:
    """One clip of a library as read back."""

    name: str
    source: str
    folder: str
    motion: Motion
    skeleton: Skeleton
    units: str
    up: str
    mirrored: bool
    source_fps: float
    scale: float
    error_mean_cm: float
    error_max_cm: float
    bpm: float = 0.0  # given at build time; 0: from the motion when played


def save_library(path: str | Path, clips: list[ImportedClip], bpm: list[float] | None = None) -> None:
    """Write ``clips`` to ``path`` (.npz) atomically: a temporary file renamed into place.
    ``bpm``: per clip its tempo in beats per minute, 0 unknown (None: all unknown)."""
    path = Path(path)
    if not clips:
        raise DataError("no clips to write", source=path)
    lengths = np.array([c.motion.num_frames for c in clips], dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64)

    def per_point(table: str) -> np.ndarray:
        return np.array([[getattr(c, table).get(p, np.nan) for p in SCORED_POINTS] for c in clips])

    arrays = {
        "format": np.array(FORMAT),
        "bones": np.array(BONES),
        "fps": np.array(float(FPS)),
        "root_pos": np.concatenate([c.motion.root_pos for c in clips]).astype(np.float32),
        "rotations": np.concatenate([c.motion.rotations for c in clips]).astype(np.float32),
        "clip_start": starts,
        "clip_frames": lengths,
        "clip_name": np.array([c.name for c in clips]),
        "clip_source": np.array([c.source for c in clips]),
        "clip_folder": np.array([c.folder for c in clips]),
        "clip_units": np.array([c.units for c in clips]),
        "clip_up": np.array([c.up for c in clips]),
        "clip_mirrored": np.array([c.mirrored for c in clips]),
        "clip_source_fps": np.array([c.source_fps for c in clips]),
        "clip_scale": np.array([c.scale for c in clips]),
        "clip_error_mean_cm": np.array([c.mean_error_cm for c in clips]),
        "clip_error_max_cm": np.array([c.max_error_cm for c in clips]),
        "error_points": np.array(SCORED_POINTS),
        "clip_point_error_mean_cm": per_point("error_mean_cm"),
        "clip_point_error_max_cm": per_point("error_max_cm"),
        "clip_offsets": np.stack([c.skeleton.offsets for c in clips]),
        "clip_end_offsets": np.stack([c.skeleton.end_offsets for c in clips]),
        "clip_bpm": np.array([float(b) for b in bpm] if bpm is not None else [0.0] * len(clips)),
    }
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as fh:  # a file object: numpy would append ".npz" to a bare path
            np.savez_compressed(fh, **arrays)
        os.replace(tmp, path)
    except OSError as exc:
        raise DataError(f"cannot write the library ({exc.strerror or exc})", source=path) from None
    finally:
        tmp.unlink(missing_ok=True)


def clip_tracks(motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """(poses (T, P) float32 in place facing +Z with w >= 0 quaternions, as the training clips
    are; root track (T, 3) float64: x, z (m) and unwrapped Hips heading (rad),
    :func:`models.rig.travel.root_track`) of a clip's motion at 30 fps: what a library is danced
    from (models/networks/library_player.py)."""
    from models.data.canonical import canonicalize
    from models.rig.travel import root_track

    poses = canonicalize(motion).to_vector().astype(np.float32)
    q = poses[:, 3:].reshape(len(poses), -1, 4)
    q *= np.where(q[..., 3:] < 0, -1.0, 1.0).astype(np.float32)
    return poses, root_track(motion)


_KEYS = ("format", "bones", "fps", "root_pos", "rotations", "clip_start", "clip_frames", "clip_name",
         "clip_source", "clip_folder", "clip_units", "clip_up", "clip_mirrored", "clip_source_fps",
         "clip_scale", "clip_error_mean_cm", "clip_error_max_cm", "clip_offsets", "clip_end_offsets")  # fmt: skip


def load_library(path: str | Path) -> list[LibraryClip]:
    """The clips of a library written by :func:`save_library`.

    Raises :class:`DataError` naming the file if it is missing, corrupt or not a library, and
    :class:`RigError` if it was made for other bones.
    """
    path = Path(path)
    data = read_arrays(path, "library file")
    missing = [k for k in _KEYS if k not in data]
    if missing:
        raise DataError(f"not a motion library: missing {missing}", source=path)
    if str(data["format"]) != FORMAT:
        raise DataError(f"format is {str(data['format'])!r}, expected {FORMAT!r}", source=path)
    bones = tuple(str(b) for b in np.atleast_1d(data["bones"]))
    if bones != BONES:
        raise RigError(f"made for bones {list(bones)}, this rig has {list(BONES)}", source=path)
    out = []
    try:
        fps = float(data["fps"])
        for i, (s, n) in enumerate(zip(data["clip_start"], data["clip_frames"])):
            s, n = int(s), int(n)
            if s < 0 or n < 1 or s + n > len(data["root_pos"]):
                raise ValueError(f"clip {i} spans frames {s}..{s + n}, the archive has {len(data['root_pos'])}")
            q = data["rotations"][s : s + n].astype(np.float64)
            q /= np.linalg.norm(q, axis=-1, keepdims=True)
            out.append(LibraryClip(
                name=str(data["clip_name"][i]), source=str(data["clip_source"][i]), folder=str(data["clip_folder"][i]),
                motion=Motion(root_pos=data["root_pos"][s : s + n], rotations=q, fps=fps),
                skeleton=Skeleton(offsets=data["clip_offsets"][i], end_offsets=data["clip_end_offsets"][i]),
                units=str(data["clip_units"][i]), up=str(data["clip_up"][i]), mirrored=bool(data["clip_mirrored"][i]),
                source_fps=float(data["clip_source_fps"][i]), scale=float(data["clip_scale"][i]),
                error_mean_cm=float(data["clip_error_mean_cm"][i]), error_max_cm=float(data["clip_error_max_cm"][i]),
                bpm=float(data["clip_bpm"][i]) if "clip_bpm" in data else 0.0,
            ))
    except (RigError, TypeError, ValueError, IndexError) as exc:
        raise DataError(f"bad library arrays: {exc}", source=path) from None
    assert all(c.motion.rotations.shape[1] == NUM_BONES for c in out)
    return out
