"""Start-up tables of a dance_vq memory's exemplars, from one forward-kinematics pass.

A :class:`~models.networks.dance_stream.DanceStream` reads, per exemplar window (K codes x M
members x F = 2 seg frames at 30 fps): its kinematic beats (:func:`member_dips`), its mean joint
speed (:func:`member_speed`: the speed cap, :func:`code_energy`), its quickness
(:func:`code_frequency`) and its feet's contacts (:func:`models.networks.feet.member_contacts`).
Each was its own FK of the whole memory (float64, ~200 MB of points and rotations for a
16-member memory, 4 times over: a 30-minute library's start-up peaked at 833 MB).
:func:`member_tables` runs the FK once, :data:`CHUNK_FRAMES` exemplar frames at a time, and keeps
only each chunk's small per-exemplar results; every table is bit for bit what the function of
its own computes (FK, gradients and filters work per window; the z-scores and the floor are
taken over the whole memory at the end).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from models.networks import feet as feet_part
from models.rig.skeleton import load_default_skeleton
from models.timebase import FPS

#: Exemplar frames (K x M x F rows) put through forward kinematics at once by :func:`member_tables`:
#: ~6 MB of float64 points a chunk, ~15 MB transient with the rotations.
CHUNK_FRAMES: int = 8192


def member_positions(windows: np.ndarray) -> np.ndarray:
    """(K, M, F, J + E, 3) world positions (m) of every point of exemplar windows (K, M, F, P)
    by forward kinematics on the default skeleton; empty member slots (zeros) read as the rest pose."""
    from models.rig.kinematics import fk
    from models.rig.motion import Motion

    k, m, f, p = windows.shape
    flat = windows.reshape(-1, p).astype(np.float64)
    q = flat[:, 3:].reshape(len(flat), -1, 4)
    ok = np.linalg.norm(q, axis=-1).min(1) > 0.5  # empty member slots are zeros
    q[~ok] = [0.0, 0.0, 0.0, 1.0]
    flat[:, 3:] = q.reshape(len(flat), -1)
    return fk(Motion.from_vector(flat.astype(np.float32), fps=FPS), load_default_skeleton()).reshape(k, m, f, -1, 3)


def _speed(positions: np.ndarray) -> np.ndarray:
    """(K, M, F) mean joint speed, m a frame, of FK points (K, M, F, J + E, 3)."""
    return np.linalg.norm(np.gradient(positions, axis=2), axis=-1).mean(-1)


def member_speed(windows: np.ndarray) -> np.ndarray:
    """(K, M, F) mean joint speed of each exemplar frame, m a frame (:func:`member_positions`).
    windows: (K, M, F, P) poses."""
    return _speed(member_positions(windows))


def _dips(speed: np.ndarray, seg: int) -> np.ndarray:
    """(K, M, seg) float32 local minima of the 2-frame-smoothed ``speed`` (K, M, F)."""
    from scipy.ndimage import gaussian_filter1d

    k, m, f = speed.shape
    v = gaussian_filter1d(speed.reshape(k * m, f), 2.0, axis=1, mode="nearest")
    dip = np.zeros_like(v)
    dip[:, 1:-1] = (v[:, 1:-1] < v[:, :-2]) & (v[:, 1:-1] <= v[:, 2:])
    return dip[:, :seg].reshape(k, m, seg).astype(np.float32)


def member_dips(windows: np.ndarray, seg: int) -> np.ndarray:
    """(K, M, seg) 1.0 where an exemplar's smoothed mean joint speed has a local minimum at
    frame j of its movement (a kinematic beat, as models.evaluation.beats counts them), else 0.

    windows: (K, M, F >= seg + 2, P) poses; speed: :func:`member_speed`.
    """
    return _dips(member_speed(windows), seg)


def _code_z(per_code: np.ndarray, has: np.ndarray) -> np.ndarray:
    """(K,) float32: ``per_code`` (values of the codes ``has``) as z-scores, 0 for the others."""
    z = np.zeros(len(has), np.float32)
    z[has] = (per_code - per_code.mean()) / max(per_code.std(), 1e-9)
    return z


def code_energy(members: np.ndarray, counts: np.ndarray, seg: int, speed: np.ndarray | None = None) -> np.ndarray:
    """How lively each code's movements are: z-scores (K,) float32, over the codes with
    exemplars, of the log mean joint speed (:func:`member_speed`) of its exemplars' movements
    (their first seg frames). ``members`` (K, M, >= seg, P), ``counts`` (K,) exemplars per
    code; ``speed`` (K, M): those mean speeds, if already computed. A code without exemplars
    gets 0 (the mean)."""
    k, m = members.shape[:2]
    has = counts > 0
    if has.sum() < 2:
        return np.zeros(k, np.float32)
    if speed is None:
        speed = _speed(member_positions(members[:, :, :seg])).mean(-1)  # (K, M)
    mask = np.arange(m)[None, :] < counts[:, None]
    return _code_z(np.log(np.maximum((speed * mask).sum(1)[has] / counts[has], 1e-9)), has)


def _log_frequency(positions: np.ndarray) -> np.ndarray:
    """(K, M) ln mean joint acceleration (m/frame^2) less ln mean joint speed (m/frame) of FK points
    (K, M, F, J + E, 3), root-relative (the dance, not its travel)."""
    pos = positions - positions[..., :1, :]
    v = np.linalg.norm(np.diff(pos, axis=2), axis=-1).mean((-1, -2))
    a = np.linalg.norm(np.diff(pos, 2, axis=2), axis=-1).mean((-1, -2))
    return np.log(np.maximum(a, 1e-9)) - np.log(np.maximum(v, 1e-9))


def _frequency_z(lf: np.ndarray, counts: np.ndarray) -> np.ndarray:
    has = counts > 0
    if has.sum() < 2:
        return np.zeros(len(counts), np.float32)
    mask = np.arange(lf.shape[1])[None, :] < counts[:, None]
    return _code_z((lf * mask).sum(1)[has] / counts[has], has)


def code_frequency(members: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """How quick each code's movements are: z-scores (K,) float32, over the codes with
    exemplars, of the mean over its exemplars of ln(mean joint acceleration / mean joint speed)
    (for a sinusoid 2 pi f a frame) over their whole windows, positions relative to the root
    (the dance, not its travel). ``members`` (K, M, F, P), ``counts`` (K,). A code without exemplars gets 0."""
    if (counts > 0).sum() < 2:
        return np.zeros(members.shape[0], np.float32)
    return _frequency_z(_log_frequency(member_positions(members)), counts)


@dataclasses.dataclass
class MemberTables:
    """A memory's start-up tables (K codes, M members, F = 2 seg frames):
    ``dips`` (K, M, seg) float32 (:func:`member_dips` of the first seg + 2 frames);
    ``speed`` (K, M) float64, mean joint speed over the movement (first seg frames), m/frame;
    ``energy``, ``frequency`` (K,) float32 z-scores (:func:`code_energy`, :func:`code_frequency`);
    ``contacts`` (K, M, F, 3) float32 and ``floor`` m (:func:`models.networks.feet.member_contacts`)."""

    dips: np.ndarray
    speed: np.ndarray
    energy: np.ndarray
    frequency: np.ndarray
    contacts: np.ndarray
    floor: float


def member_tables(members: np.ndarray, counts: np.ndarray, seg: int,
                  chunk_frames: int = CHUNK_FRAMES) -> MemberTables:
    """Every table of exemplar windows ``members`` (K, M, F >= seg + 2, P), ``counts`` (K,) real
    ones, from one FK pass over chunks of codes (:data:`CHUNK_FRAMES` frames each): the same
    values as :func:`member_dips`, :func:`code_energy`, :func:`code_frequency` and
    :func:`models.networks.feet.member_contacts` each give, at a fraction of their peak memory."""
    k, m, f = members.shape[:3]
    counts = np.asarray(counts)
    step = max(1, chunk_frames // max(1, m * f))
    dips, speed, lf, low, mid = [], [], [], [], []
    for a in range(0, k, step):
        pos = member_positions(members[a: a + step])  # (c, M, F, J + E, 3) float64
        dips.append(_dips(_speed(pos[:, :, : seg + 2]), seg))
        speed.append(_speed(pos[:, :, :seg]).mean(-1))
        lf.append(_log_frequency(pos))
        lo, mi = feet_part.member_feet(pos)
        low.append(lo)
        mid.append(mi)
        del pos
    speed_all = np.concatenate(speed)
    contacts, floor = feet_part.feet_contacts(np.concatenate(low), np.concatenate(mid), counts)
    return MemberTables(np.concatenate(dips), speed_all, code_energy(members, counts, seg, speed_all),
                        _frequency_z(np.concatenate(lf), counts), contacts, floor)
