"""NPZ export and import of a :class:`~models.rig.motion.Motion`.

An archive holds ``format`` (:data:`FORMAT`), ``bones`` (the bone names, in the
order of the rotation axis), ``fps``, ``root_pos`` (T, 3) metres, ``rotations``
(T, J, 4) xyzw local quaternions, plus any extra arrays given to :func:`save_npz`.
It is written with :func:`numpy.savez_compressed` and read without pickle.
"""

from __future__ import annotations

import zipfile
import zlib
from pathlib import Path

import numpy as np

from models.errors import DataError, RigError
from models.rig.humanoid import BONES
from models.rig.motion import Motion

FORMAT = "live-performer motion v1"
_RESERVED = ("format", "bones", "fps", "root_pos", "rotations")


def save_npz(path: str | Path, motion: Motion, **extra: object) -> None:
    """Write ``motion`` and ``extra`` arrays (numbers or strings, not objects) to ``path``."""
    clash = sorted(set(extra) & set(_RESERVED))
    if clash:
        raise DataError(f"extra names {clash} are reserved", source=path)
    arrays = {k: np.asarray(v) for k, v in extra.items()}
    bad = [k for k, v in arrays.items() if v.dtype == object]
    if bad:
        raise DataError(f"extra arrays {bad} are not numeric or string arrays", source=path)
    with open(path, "wb") as fh:  # a file object: numpy would append ".npz" to a bare path
        np.savez_compressed(
            fh,
            format=np.array(FORMAT),
            bones=np.array(BONES),
            fps=np.array(float(motion.fps)),
            root_pos=motion.root_pos,
            rotations=motion.rotations,
            **arrays,
        )


def read_arrays(path: Path, what: str = "motion file") -> dict[str, np.ndarray]:
    """Every array of an .npz archive, read without pickle; :class:`DataError` naming the file
    if it is missing or not a readable archive."""
    if not path.is_file():
        raise DataError(f"{what} not found", source=path)
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error, NotImplementedError,
            RuntimeError) as exc:  # RuntimeError: zipfile's "File ... is encrypted, password required"
        raise DataError(f"not a readable .npz archive ({exc})", source=path) from None


def _open(path: Path) -> dict[str, np.ndarray]:
    data = read_arrays(path)
    missing = [k for k in _RESERVED if k not in data]
    if missing:
        raise DataError(f"not a motion archive: missing {missing}", source=path)
    if str(data["format"]) != FORMAT:
        raise DataError(f"format is {str(data['format'])!r}, expected {FORMAT!r}", source=path)
    return data


def load_npz(path: str | Path) -> Motion:
    """Read a motion written by :func:`save_npz`.

    Raises :class:`DataError` naming the file if it is missing, corrupt or not a
    motion archive, and :class:`RigError` if it was made for other bones.
    """
    path = Path(path)
    data = _open(path)
    bones = tuple(str(b) for b in np.atleast_1d(data["bones"]))
    if bones != BONES:
        raise RigError(f"made for bones {list(bones)}, this rig has {list(BONES)}", source=path)
    try:
        fps = float(data["fps"])
        if not 0 < fps < 1e6:  # NaN fails too
            raise ValueError(f"fps must be a positive frame rate, got {fps}")
        return Motion(root_pos=data["root_pos"], rotations=data["rotations"], fps=fps)
    except (RigError, TypeError, ValueError) as exc:
        raise DataError(f"bad motion arrays: {exc}", source=path) from None


def load_npz_extra(path: str | Path) -> dict[str, np.ndarray]:
    """The extra arrays stored by :func:`save_npz` (everything but the motion itself)."""
    return {k: v for k, v in _open(Path(path)).items() if k not in _RESERVED}
