"""The rest skeleton of the humanoid rig: bone offsets plus end sites.

A skeleton gives, for every point of the rig, its offset in metres from its parent
bone's head in the rest T-pose, in the project frame (right-handed, Y up, character
faces +Z, its left is +X). Rest global rotations are the identity for every bone, so
an offset is also the child's position in the parent bone's local frame.

Points are the :data:`~models.rig.humanoid.BONES` (bone heads) followed by the
:data:`END_SITES`, markers fixed to a bone that FK also places: the tips of the leaf
bones (written as BVH ``End Site``) and extra points the dataset tracks (the two sides
of the head, the heels). Networks and wire formats only see the bones.

``offsets`` is (J, 3) for an ordinary skeleton, or (T, J, 3) for a per-frame skeleton
(a skeleton fitted to each frame of one dance: the chain bones keep their rest
directions with each frame's measured lengths, the end sites and toe points sit
where that frame measured them; see :func:`models.rig.retarget.fit_skeleton`). A
per-frame skeleton carries the ordinary skeleton that retargeting solves rotations
against (:meth:`Skeleton.rest_skeleton`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from models.errors import DataError, RigError
from models.rig.humanoid import BONE_INDEX, BONES, NUM_BONES, PARENT_INDEX

#: End sites, each fixed to one bone (its parent). ``*End`` ones are synthetic tips.
END_SITE_PARENT: dict[str, str] = {
    "HeadEnd": "Head",  # midpoint of the two head points
    "HeadLeft": "Head",
    "HeadRight": "Head",
    "LeftHandTip": "LeftHand",
    "RightHandTip": "RightHand",
    "LeftHeel": "LeftFoot",
    "RightHeel": "RightFoot",
    "LeftToesEnd": "LeftToes",  # synthetic: 2 cm ahead of the toe point
    "RightToesEnd": "RightToes",
}
END_SITES: tuple[str, ...] = tuple(END_SITE_PARENT)
NUM_END_SITES: int = len(END_SITES)
#: Bones then end sites: the points that :func:`models.rig.kinematics.fk` returns.
POINTS: tuple[str, ...] = BONES + END_SITES
NUM_POINTS: int = len(POINTS)
POINT_INDEX: dict[str, int] = {name: i for i, name in enumerate(POINTS)}
#: Parent bone index of every point (-1 for the root).
POINT_PARENT_INDEX: tuple[int, ...] = PARENT_INDEX + tuple(BONE_INDEX[END_SITE_PARENT[e]] for e in END_SITES)
#: The one end site written as BVH ``End Site`` under each leaf bone.
LEAF_END_SITE: dict[str, str] = {
    "Head": "HeadEnd",
    "LeftHand": "LeftHandTip",
    "RightHand": "RightHandTip",
    "LeftToes": "LeftToesEnd",
    "RightToes": "RightToesEnd",
}

DEFAULT_REST_PATH: Path = Path(__file__).resolve().parents[1] / "assets" / "humanoid_rest.json"


def point_index(name: str) -> int:
    """Index of a bone or end site in :data:`POINTS`; :class:`RigError` if unknown."""
    try:
        return POINT_INDEX[name]
    except KeyError:
        raise RigError(f"unknown rig point {name!r}; known points: {', '.join(POINTS)}") from None


def mirror_name(name: str) -> str:
    """The left/right counterpart of a point name (the name itself for centre points)."""
    if name.startswith("Left") or name.startswith("Right"):
        return "Right" + name[4:] if name.startswith("Left") else "Left" + name[5:]
    for a, b in (("Left", "Right"), ("Right", "Left")):
        if name.endswith(a):
            return name[: -len(a)] + b
    return name


@dataclass
class Skeleton:
    """Rest offsets in metres: ``offsets`` (J, 3) or (T, J, 3), ``end_offsets`` (E, 3) or (T, E, 3).

    ``offsets[j]`` is bone j's head relative to its parent's head (the root's entry is
    its rest position and is ignored by FK, which uses the motion's root position);
    ``end_offsets[e]`` is end site e relative to the head of its parent bone. Both are
    in the parent bone's rest-aligned frame (rest global rotations are the identity).
    ``rest``, for a per-frame skeleton only: the ordinary skeleton whose directions
    retargeting solves against (default: the median over frames of the rest pose).
    """

    offsets: np.ndarray
    end_offsets: np.ndarray
    rest: "Skeleton | None" = None

    def __post_init__(self) -> None:
        self.offsets = np.asarray(self.offsets, dtype=np.float64)
        self.end_offsets = np.asarray(self.end_offsets, dtype=np.float64)
        o, e = self.offsets, self.end_offsets
        ok = (
            o.ndim in (2, 3)
            and o.shape[-2:] == (NUM_BONES, 3)
            and e.ndim == o.ndim
            and e.shape[-2:] == (NUM_END_SITES, 3)
            and o.shape[:-2] == e.shape[:-2]
        )
        if not ok:
            raise RigError(
                f"skeleton needs offsets (J={NUM_BONES}, 3) and end_offsets (E={NUM_END_SITES}, 3), "
                f"optionally with a leading frame axis; got {o.shape} and {e.shape}"
            )
        if not (np.isfinite(o).all() and np.isfinite(e).all()):
            raise RigError("skeleton offsets hold non-finite values")
        if self.rest is not None and (not self.per_frame or self.rest.per_frame):
            raise RigError("only a per-frame skeleton takes a rest skeleton, and that one must not be per-frame")

    @property
    def per_frame(self) -> bool:
        """True when offsets carry a leading frame axis (T, J, 3)."""
        return self.offsets.ndim == 3

    def point_offsets(self) -> np.ndarray:
        """Offsets of all :data:`POINTS`, (J + E, 3) or (T, J + E, 3)."""
        return np.concatenate([self.offsets, self.end_offsets], axis=-2)

    def rest_skeleton(self) -> "Skeleton":
        """The ordinary skeleton that retargeting solves rotations against: this one, or for a
        per-frame skeleton its ``rest`` (if none was given: the median over frames of the
        rest pose, turned back into offsets)."""
        if not self.per_frame:
            return self
        if self.rest is not None:
            return self.rest
        pos = np.median(self.rest_positions(), axis=0)
        parents = np.array(POINT_PARENT_INDEX)
        off = pos - np.where(parents[:, None] < 0, 0.0, pos[np.maximum(parents, 0)])
        return Skeleton(offsets=off[:NUM_BONES], end_offsets=off[NUM_BONES:])

    def rest_positions(self) -> np.ndarray:
        """Positions of all points in the rest pose, root at its rest offset: (…, J + E, 3)."""
        off = self.point_offsets()
        pos = np.zeros_like(off)
        for i, p in enumerate(POINT_PARENT_INDEX):
            pos[..., i, :] = off[..., i, :] if p < 0 else pos[..., p, :] + off[..., i, :]
        return pos

    def bone_lengths(self) -> dict[str, float]:
        """Length in metres of each non-root point's offset (median over frames if per-frame)."""
        n = np.linalg.norm(self.point_offsets(), axis=-1)
        if self.per_frame:
            n = np.median(n, axis=0)
        return {name: float(n[i]) for i, name in enumerate(POINTS) if POINT_PARENT_INDEX[i] >= 0}

    # -- persistence ---------------------------------------------------------------

    def to_json(self, path: str | Path, note: str = "") -> None:
        """Write a (non per-frame) skeleton as JSON: point names, parents, offsets in metres."""
        if self.per_frame:
            raise RigError("a per-frame skeleton cannot be saved as a rest skeleton")
        off = self.point_offsets()
        doc = {
            "format": "live-performer humanoid rest skeleton v1",
            "units": "metres; right-handed, Y up, faces +Z, left = +X; T-pose",
            "note": note,
            "points": [
                {
                    "name": name,
                    "parent": None if POINT_PARENT_INDEX[i] < 0 else POINTS[POINT_PARENT_INDEX[i]],
                    "offset": [round(float(v), 6) for v in off[i]],
                }
                for i, name in enumerate(POINTS)
            ],
        }
        Path(path).write_text(json.dumps(doc, indent=1) + "\n")

    @classmethod
    def from_json(cls, path: str | Path) -> "Skeleton":
        """Read a skeleton written by :meth:`to_json`; :class:`DataError` naming the file if malformed."""
        path = Path(path)
        try:
            doc = json.loads(path.read_text())
            points = {p["name"]: p for p in doc["points"]}
        except FileNotFoundError:
            raise DataError("skeleton file not found", source=path) from None
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise DataError(f"not a rest-skeleton JSON ({exc!r})", source=path) from None
        missing = [n for n in POINTS if n not in points]
        unknown = [n for n in points if n not in POINT_INDEX]
        if missing or unknown:
            raise DataError(f"skeleton points differ from the rig: missing {missing}, unknown {unknown}", source=path)
        for i, name in enumerate(POINTS):
            want = None if POINT_PARENT_INDEX[i] < 0 else POINTS[POINT_PARENT_INDEX[i]]
            if points[name].get("parent") != want:
                raise DataError(f"point {name!r} has parent {points[name].get('parent')!r}, expected {want!r}", source=path)
        try:
            off = np.array([points[n]["offset"] for n in POINTS], dtype=np.float64)
        except (KeyError, TypeError, ValueError) as exc:
            raise DataError(f"bad offsets ({exc!r})", source=path) from None
        if off.shape != (NUM_POINTS, 3) or not np.isfinite(off).all():
            raise DataError(f"offsets must be {NUM_POINTS} finite [x, y, z] triples", source=path)
        return cls(offsets=off[:NUM_BONES], end_offsets=off[NUM_BONES:])


def load_default_skeleton(path: str | Path | None = None) -> Skeleton:
    """The canonical rest skeleton shipped in ``models/assets/humanoid_rest.json``.

    It is the symmetric median fit over the whole DWM dataset, written by
    ``.venv/bin/python benchmarks/studies/retarget_accuracy.py --data /path/to/dwm
    --write-rest models/assets/humanoid_rest.json``.
    """
    return Skeleton.from_json(DEFAULT_REST_PATH if path is None else path)
