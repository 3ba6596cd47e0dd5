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
taken over the whole memory at the end). :func:`warp_scale` turns the tempo z the tables give
into the beat warp's depth per code (issue 39: the quickest movements warped less).
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
#: The tempo's tilt reads each code's liveliness (:func:`code_energy`) and quickness
#: (:func:`code_frequency`) on its exemplars' points low-passed (zero-phase: 4th-order Butterworth
#: forwards and back along the frames) at this many Hz first: the dance band's speed and
#: quickness, not the tremble above it. 0: on the points as they are.
TILT_LOWPASS_HZ: float = 0.0
#: The beat warp (``dance_stream.BEAT_WARP``) swings a movement's read-out speed by up to +-45 %
#: at the beat's frequency; on the memory's quickest movements that frequency modulation carries
#: their 3-6 Hz motion above 6 Hz, where it reads as tremble (docs/stage.md, "Between the ends").
#: So the warp's depth is scaled by :func:`warp_scale` of the playing code's tempo z
#: (``DanceStream._tempo_z``: liveliness plus quickness): 1 up to :data:`WARP_QUICK_Z`, falling
#: linearly over :data:`WARP_QUICK_SPAN` to this. 1 (shipped): the same depth for every code.
#: 0.3 lowers the hands' tremble between a song's ends by a fifth but costs the beat hit rate
#: (validation 0.566 -> 0.532, sweetwaltz 0.93 -> 0.80) and on the 3x2 stage leaves the raw
#: jitter no lower (the songs' wrap decides it): an option, not the default (docs/stage.md).
WARP_QUICK_FLOOR: float = 1.0
WARP_QUICK_Z: float = 1.0
WARP_QUICK_SPAN: float = 2.0


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
    gets 0 (the mean). Read on points low-passed at :data:`TILT_LOWPASS_HZ` (shipped 0: as they are)."""
    k, m = members.shape[:2]
    has = counts > 0
    if has.sum() < 2:
        return np.zeros(k, np.float32)
    if speed is None:
        pos = member_positions(members if TILT_LOWPASS_HZ > 0.0 else members[:, :, :seg])  # the filter wants the window
        speed = _speed(_lowpass(pos, TILT_LOWPASS_HZ)[:, :, :seg]).mean(-1)  # (K, M)
    mask = np.arange(m)[None, :] < counts[:, None]
    return _code_z(np.log(np.maximum((speed * mask).sum(1)[has] / counts[has], 1e-9)), has)


def _lowpass(pos: np.ndarray, hz: float) -> np.ndarray:
    """FK points ``pos`` (K, M, F, J + E, 3) at 30 fps, zero-phase low-passed along F at ``hz``
    (4th-order Butterworth forwards and back, odd extension at the ends); 0: as they are."""
    if hz <= 0.0:
        return pos
    from scipy.signal import butter, filtfilt

    b, a = butter(4, hz / (FPS / 2.0))
    return filtfilt(b, a, pos, axis=2, padtype="odd", padlen=min(pos.shape[2] - 1, 15))


def warp_scale(tempo_z: np.ndarray) -> np.ndarray:
    """(K + 1,) float32 factor on the beat warp's depth for codes of tempo z ``tempo_z`` (K,)
    (:data:`WARP_QUICK_FLOOR`), then 1 for index K ("no code yet")."""
    w = np.clip((np.asarray(tempo_z, np.float64) - WARP_QUICK_Z) / max(WARP_QUICK_SPAN, 1e-9), 0.0, 1.0)
    return np.append(1.0 - w * (1.0 - WARP_QUICK_FLOOR), 1.0).astype(np.float32)


def _log_speed_accel(positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(K, M) ln mean joint speed (m/frame) and ln mean joint acceleration (m/frame^2) of FK points
    (K, M, F, J + E, 3), root-relative (the dance, not its travel)."""
    pos = positions - positions[..., :1, :]
    v = np.linalg.norm(np.diff(pos, axis=2), axis=-1).mean((-1, -2))
    a = np.linalg.norm(np.diff(pos, 2, axis=2), axis=-1).mean((-1, -2))
    return np.log(np.maximum(v, 1e-9)), np.log(np.maximum(a, 1e-9))


def _log_frequency(positions: np.ndarray) -> np.ndarray:
    """(K, M) ln(mean joint acceleration / mean joint speed) of FK points (K, M, F, J + E, 3), root-relative."""
    lv, la = _log_speed_accel(positions)
    return la - lv


def _log_size(positions: np.ndarray) -> np.ndarray:
    """(K, M) ln(mean joint speed ** 2 / mean joint acceleration) of FK points (K, M, F, J + E, 3),
    root-relative: for a sinusoid of amplitude A, 2 A / pi (m), whatever its frequency."""
    lv, la = _log_speed_accel(positions)
    return 2.0 * lv - la


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
    (the dance, not its travel), low-passed at :data:`TILT_LOWPASS_HZ` (shipped 0: as they are).
    ``members`` (K, M, F, P), ``counts`` (K,). A code without exemplars gets 0."""
    if (counts > 0).sum() < 2:
        return np.zeros(members.shape[0], np.float32)
    return _frequency_z(_log_frequency(_lowpass(member_positions(members), TILT_LOWPASS_HZ)), counts)


def code_size(members: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """How large each code's movements are, whatever their pace: z-scores (K,) float32, over the
    codes with exemplars, of the mean over its exemplars of ln(mean joint speed ** 2 / mean joint
    acceleration) (:func:`_log_size`; root-relative, whole windows, low-passed at
    :data:`TILT_LOWPASS_HZ`). ``members`` (K, M, F, P), ``counts`` (K,). A code without exemplars gets 0."""
    if (counts > 0).sum() < 2:
        return np.zeros(members.shape[0], np.float32)
    return _frequency_z(_log_size(_lowpass(member_positions(members), TILT_LOWPASS_HZ)), counts)


@dataclasses.dataclass
class MemberTables:
    """A memory's start-up tables (K codes, M members, F = 2 seg frames):
    ``dips`` (K, M, seg) float32 (:func:`member_dips` of the first seg + 2 frames);
    ``speed`` (K, M) float64, mean joint speed over the movement (first seg frames), m/frame;
    ``energy``, ``frequency``, ``size`` (K,) float32 z-scores (:func:`code_energy`, :func:`code_frequency`,
    :func:`code_size`);
    ``contacts`` (K, M, F, 3) float32 and ``floor`` m (:func:`models.networks.feet.member_contacts`)."""

    dips: np.ndarray
    speed: np.ndarray
    energy: np.ndarray
    frequency: np.ndarray
    contacts: np.ndarray
    floor: float
    size: np.ndarray


def member_tables(members: np.ndarray, counts: np.ndarray, seg: int,
                  chunk_frames: int = CHUNK_FRAMES) -> MemberTables:
    """Every table of exemplar windows ``members`` (K, M, F >= seg + 2, P), ``counts`` (K,) real
    ones, from one FK pass over chunks of codes (:data:`CHUNK_FRAMES` frames each): the same
    values as :func:`member_dips`, :func:`code_energy`, :func:`code_frequency`, :func:`code_size` and
    :func:`models.networks.feet.member_contacts` each give, at a fraction of their peak memory."""
    k, m, f = members.shape[:3]
    counts = np.asarray(counts)
    step = max(1, chunk_frames // max(1, m * f))
    dips, speed, band, lf, ls, low, mid = [], [], [], [], [], [], []
    for a in range(0, k, step):
        pos = member_positions(members[a: a + step])  # (c, M, F, J + E, 3) float64
        dips.append(_dips(_speed(pos[:, :, : seg + 2]), seg))
        speed.append(_speed(pos[:, :, :seg]).mean(-1))
        low_pos = _lowpass(pos, TILT_LOWPASS_HZ)  # what the tempo's tilt reads: the dance band
        band.append(speed[-1] if low_pos is pos else _speed(low_pos[:, :, :seg]).mean(-1))
        lv, la = _log_speed_accel(low_pos)
        lf.append(la - lv)
        ls.append(2.0 * lv - la)
        lo, mi = feet_part.member_feet(pos)
        low.append(lo)
        mid.append(mi)
        del pos
    speed_all = np.concatenate(speed)
    contacts, floor = feet_part.feet_contacts(np.concatenate(low), np.concatenate(mid), counts)
    return MemberTables(np.concatenate(dips), speed_all, code_energy(members, counts, seg, np.concatenate(band)),
                        _frequency_z(np.concatenate(lf), counts), contacts, floor, _frequency_z(np.concatenate(ls), counts))
