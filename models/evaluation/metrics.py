"""Motion metrics: pure functions on numpy arrays.

Conventions shared by every function here:

- ``pos``: joint positions after forward kinematics, shape ``(T, J, 3)``, metres,
  at ``fps`` frames per second (default :data:`models.timebase.FPS` = 30). ``J`` is
  generic; hand/wrist metrics take joint indices.
- ``quat``: local bone rotations, shape ``(T, B, 4)``, unit quaternions x, y, z, w.
- A "generated" array and its "reference" (ground truth for the same music) must
  have the same shape unless a docstring says otherwise (DTW and LCSS accept
  different lengths).
- Functions that summarise a set of sequences (:func:`energy_ratio`, :func:`jerk`,
  :func:`band_rms`, :func:`band_ratios`) take one array or a list of arrays, so
  sequence boundaries never create fake velocities or spectra.

Bad input raises :class:`models.errors.DataError` naming the argument.
See docs/metrics.md for one paragraph per metric.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import maximum_bipartite_matching
from scipy.spatial.distance import cdist, pdist

from models.errors import DataError
from models.timebase import FPS

Positions = np.ndarray | Sequence[np.ndarray]

#: Default PCK thresholds (Kao & Su 2020 report alpha = 0.1 and 0.2).
PCK_ALPHAS: tuple[float, float] = (0.1, 0.2)
#: Default matching tolerance for direction-change events, frames at 30 fps (Kao & Su 2020).
DIRECTION_TOLERANCE: int = 3
#: Default velocity dead-band for direction changes, m/s.
DIRECTION_DEADBAND: float = 0.05
#: Default LCSS match threshold: mean per-joint distance, metres.
LCSS_EPSILON: float = 0.1
#: Dance-scale band of :func:`band_ratios`, Hz (both edges included; issue 18).
DANCE_BAND: tuple[float, float] = (0.25, 3.0)
#: Jitter band of :func:`band_ratios`, Hz: 6 Hz up to the Nyquist frequency (15 Hz at 30 fps).
JITTER_BAND: tuple[float, float] = (6.0, math.inf)


# --------------------------------------------------------------------------- checks


def _finite(x: np.ndarray, name: str, what: str, shape_ok: Callable[[np.ndarray], bool], min_rows: int, rows: str) -> np.ndarray:
    """``x`` as float64 if ``shape_ok(x)``, with ``>= min_rows`` rows, all finite; else DataError."""
    a = np.asarray(x, dtype=np.float64)
    if not shape_ok(a):
        raise DataError(f"expected {what}, got {a.shape}", source=name)
    if a.shape[0] < min_rows:
        raise DataError(f"needs at least {min_rows} {rows}, got {a.shape[0]}", source=name)
    if not np.isfinite(a).all():
        raise DataError("contains NaN or infinite values", source=name)
    return a


def _positions(x: np.ndarray, name: str, min_frames: int = 1) -> np.ndarray:
    """``x`` as float64 ``(T, J, 3)`` with ``T >= min_frames``, finite; else DataError."""
    def ok(a: np.ndarray) -> bool:
        return a.ndim == 3 and a.shape[2] == 3 and a.shape[1] > 0

    return _finite(x, name, "joint positions of shape (T, J, 3)", ok, min_frames, "frames")


def _pair(a: np.ndarray, b: np.ndarray, names: tuple[str, str], min_frames: int = 1):
    """Validate two position arrays of identical shape."""
    a = _positions(a, names[0], min_frames)
    b = _positions(b, names[1], min_frames)
    if a.shape != b.shape:
        raise DataError(f"shape {a.shape} does not match {names[1]} shape {b.shape}", source=names[0])
    return a, b


def _joints(indices: Sequence[int], num_joints: int, name: str) -> list[int]:
    idx = [int(i) for i in indices]
    if not idx:
        raise DataError("needs at least one joint index", source=name)
    bad = [i for i in idx if not -num_joints <= i < num_joints]
    if bad:
        raise DataError(f"joint indices {bad} out of range for {num_joints} joints", source=name)
    return idx


def _sequence_list(x: Positions, name: str, min_frames: int) -> list[np.ndarray]:
    """One ``(T, J, 3)`` array or a list of them -> list of validated arrays."""
    if isinstance(x, np.ndarray) and x.ndim == 3:
        items = [x]
    else:
        items = list(x)
    if not items:
        raise DataError("is an empty list of sequences", source=name)
    return [_positions(s, f"{name}[{i}]", min_frames) for i, s in enumerate(items)]


def root_relative(pos: np.ndarray, root: int = 0) -> np.ndarray:
    """Positions ``(T, J, 3)`` m minus joint ``root``'s position in each frame."""
    pos = _positions(pos, "pos")
    _joints([root], pos.shape[1], "root")
    return pos - pos[:, root : root + 1]


# --------------------------------------------------------------------------- losses


def position_l1(pos_gen: np.ndarray, pos_ref: np.ndarray, joints: Sequence[int] | None = None) -> float:
    """Mean absolute coordinate error, metres (Kao & Su, ACM MM 2020, "L1").

    Mean over frames, the selected ``joints`` (all when None) and x/y/z of
    ``|pos_gen - pos_ref|``. 0 for identical sequences; lower is better.
    """
    a, b = _pair(pos_gen, pos_ref, ("pos_gen", "pos_ref"))
    if joints is not None:
        idx = _joints(joints, a.shape[1], "joints")
        a, b = a[:, idx], b[:, idx]
    return float(np.mean(np.abs(a - b)))


def hand_l1(pos_gen: np.ndarray, pos_ref: np.ndarray, hands: Sequence[int]) -> float:
    """:func:`position_l1` restricted to the hand/wrist joints ``hands``, metres.

    Kao & Su (ACM MM 2020) report it for the bowing (right) wrist.
    """
    return position_l1(pos_gen, pos_ref, joints=hands)


def rotation_l1(quat_gen: np.ndarray, quat_ref: np.ndarray) -> float:
    """Mean absolute quaternion-component error (test loss on rotations).

    ``quat_*``: ``(T, B, 4)`` xyzw. Because ``q`` and ``-q`` are the same rotation,
    each generated quaternion is first flipped into the reference's hemisphere
    (``dot >= 0``), so the value is 0 exactly when the rotations agree. Unitless,
    in [0, 1] for unit quaternions; lower is better.
    """
    a = np.asarray(quat_gen, dtype=np.float64)
    b = np.asarray(quat_ref, dtype=np.float64)
    for arr, name in ((a, "quat_gen"), (b, "quat_ref")):
        if arr.ndim != 3 or arr.shape[2] != 4:
            raise DataError(f"expected quaternions of shape (T, B, 4), got {arr.shape}", source=name)
        if not np.isfinite(arr).all():
            raise DataError("contains NaN or infinite values", source=name)
    if a.shape != b.shape:
        raise DataError(f"shape {a.shape} does not match quat_ref shape {b.shape}", source="quat_gen")
    sign = np.where(np.sum(a * b, axis=-1, keepdims=True) < 0.0, -1.0, 1.0)
    return float(np.mean(np.abs(sign * a - b)))


# --------------------------------------------------------------------------- alignment


def _frame_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(Ta, Tb)`` matrix of mean per-joint Euclidean distances between frames, metres."""
    cost = np.zeros((a.shape[0], b.shape[0]))
    for j in range(a.shape[1]):
        cost += cdist(a[:, j], b[:, j])
    return cost / a.shape[1]


def _same_joints(a: np.ndarray, b: np.ndarray) -> None:
    if a.shape[1] != b.shape[1]:
        raise DataError(f"has {a.shape[1]} joints but pos_b has {b.shape[1]}", source="pos_a")


def dtw_distance(pos_a: np.ndarray, pos_b: np.ndarray, band_rad: float | None = None) -> float:
    """Dynamic-time-warping distance of two joint trajectories, metres.

    Following Chen et al., "A Music-driven Deep Generative Adversarial Model for
    Guzheng Playing Animation" (IEEE TVCG 2021), which compares generated and
    captured trajectories with DTW. Frame cost = mean over joints of the Euclidean
    distance between the two frames' joint positions (m); the accumulated cost of
    the optimal warping path (``librosa.sequence.dtw``) is divided by the path
    length, so the result is the mean per-joint distance along the alignment and
    does not grow with duration. ``pos_a (Ta, J, 3)``, ``pos_b (Tb, J, 3)``; the
    lengths may differ. ``band_rad``: optional Sakoe-Chiba band as a fraction of
    the length (librosa's ``band_rad``). 0 for identical sequences; lower is better.
    """
    import librosa  # heavy import kept local

    a = _positions(pos_a, "pos_a")
    b = _positions(pos_b, "pos_b")
    _same_joints(a, b)
    cost = _frame_distances(a, b)
    if band_rad is None:
        acc, path = librosa.sequence.dtw(C=cost, backtrack=True)
    else:
        acc, path = librosa.sequence.dtw(C=cost, backtrack=True, global_constraints=True, band_rad=band_rad)
    return float(acc[-1, -1] / len(path))


def lcss_similarity(
    pos_a: np.ndarray,
    pos_b: np.ndarray,
    epsilon: float = LCSS_EPSILON,
    delta: int | None = None,
) -> float:
    """Longest-common-subsequence (LCSS) similarity of two trajectories, in [0, 1].

    Following Chen et al. (IEEE TVCG 2021), who score generated trajectories by
    LCS against captured ones, with the LCSS form of Vlachos, Kollios & Gunopulos
    (ICDE 2002): frames ``i`` of ``a`` and ``j`` of ``b`` match when their mean
    per-joint Euclidean distance is at most ``epsilon`` metres (default 0.1 m) and,
    if ``delta`` is given, ``|i - j| <= delta`` frames. The length of the longest
    common subsequence of matching frames is divided by ``min(Ta, Tb)``, so 1 means
    every frame of the shorter sequence is matched in order. Higher is better.
    """
    a = _positions(pos_a, "pos_a")
    b = _positions(pos_b, "pos_b")
    _same_joints(a, b)
    if epsilon < 0:
        raise DataError(f"must be >= 0, got {epsilon}", source="epsilon")
    match = _frame_distances(a, b) <= epsilon
    if delta is not None:
        i, j = np.indices(match.shape)
        match &= np.abs(i - j) <= int(delta)
    # Row-wise LCS: L[i, j] = max(L[i-1, j], L[i, j-1], L[i-1, j-1] + match[i, j]);
    # the within-row dependency is a running maximum, so each row is vectorised.
    prev = np.zeros(b.shape[0] + 1, dtype=np.int64)
    for row in match:
        cur = np.empty_like(prev)
        cur[0] = 0
        cur[1:] = np.maximum.accumulate(np.maximum(prev[1:], prev[:-1] + row))
        prev = cur
    return float(prev[-1] / min(a.shape[0], b.shape[0]))


# --------------------------------------------------------------------------- keypoints


def pck(
    pos_gen: np.ndarray,
    pos_ref: np.ndarray,
    alpha: float,
    torso: tuple[int, int] | None = None,
) -> float:
    """Percentage of correct keypoints, as a fraction in [0, 1].

    Kao & Su, "Temporally Guided Music-to-Body-Movement Generation" (ACM MM 2020),
    report PCK at alpha = 0.1 and 0.2. A joint is correct in a frame when its
    Euclidean error is at most ``alpha * L`` where ``L`` is, per frame of the
    reference: by default the largest side of the reference pose's axis-aligned
    bounding box (``max`` over x/y/z of ``max_j - min_j``, as in Kao & Su's code,
    after Yang & Ramanan 2013); or, when ``torso=(i, j)`` is given, the distance
    between reference joints ``i`` and ``j`` (e.g. Neck and Hips). Higher is better.
    """
    a, b = _pair(pos_gen, pos_ref, ("pos_gen", "pos_ref"))
    if alpha <= 0:
        raise DataError(f"must be > 0, got {alpha}", source="alpha")
    if torso is None:
        length = np.max(b.max(axis=1) - b.min(axis=1), axis=-1)  # (T,)
    else:
        i, j = _joints(torso, b.shape[1], "torso")
        length = np.linalg.norm(b[:, i] - b[:, j], axis=-1)
    err = np.linalg.norm(a - b, axis=-1)  # (T, J)
    return float(np.mean(err <= alpha * length[:, None]))


# --------------------------------------------------------------------------- direction changes


def direction_changes(x: np.ndarray, fps: float = FPS, deadband: float = DIRECTION_DEADBAND) -> np.ndarray:
    """Frames where a 1-D trajectory reverses direction.

    ``x``: ``(T,)`` positions along one axis, metres, at ``fps``. Velocity samples
    ``v[k] = (x[k+1] - x[k]) * fps`` (m/s) with ``|v| <= deadband`` count as "still"
    and never start an event; an event is recorded when the velocity's sign differs
    from the sign of the last non-still sample. Its frame is the middle of the
    turn: the mean of the last frame moving the old way and the first frame moving
    the new way, in position frames (so a sampled cosine's turning points land on
    its extrema). Returns sorted int frame indices.
    """
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 1:
        raise DataError(f"expected a 1-D trajectory, got shape {x.shape}", source="x")
    v = np.diff(x) * fps
    moving = np.flatnonzero(np.abs(v) > deadband)
    if moving.size < 2:
        return np.zeros(0, dtype=np.int64)
    signs = np.sign(v[moving])
    turn = np.flatnonzero(signs[1:] != signs[:-1])
    # v[k] lies between frames k and k+1; the turn spans moving[turn] .. moving[turn+1].
    frames = (moving[turn] + moving[turn + 1] + 1) / 2.0
    return np.floor(frames + 0.5).astype(np.int64)


def match_events(gen: np.ndarray, ref: np.ndarray, tolerance: int) -> int:
    """Number of one-to-one matches between two event-frame lists within ``±tolerance`` frames.

    A maximum bipartite matching (``scipy.sparse.csgraph.maximum_bipartite_matching``)
    over the pairs with ``|g - r| <= tolerance``.
    """
    gen = np.asarray(gen, dtype=np.int64).ravel()
    ref = np.asarray(ref, dtype=np.int64).ravel()
    if gen.size == 0 or ref.size == 0:
        return 0
    close = np.abs(gen[:, None] - ref[None, :]) <= tolerance
    if not close.any():
        return 0
    matching = maximum_bipartite_matching(csr_matrix(close.astype(np.int8)), perm_type="column")
    return int(np.count_nonzero(matching >= 0))


def event_f1(gen: np.ndarray, ref: np.ndarray, tolerance: int) -> tuple[float, float, float]:
    """(precision, recall, F1) of event frames ``gen`` against ``ref`` within ``±tolerance``.

    Both empty -> (1, 1, 1) (nothing to find, nothing claimed); exactly one empty
    -> zeros.
    """
    n_gen, n_ref = len(gen), len(ref)
    if n_gen == 0 and n_ref == 0:
        return 1.0, 1.0, 1.0
    hits = match_events(gen, ref, tolerance)
    precision = hits / n_gen if n_gen else 0.0
    recall = hits / n_ref if n_ref else 0.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    return precision, recall, f1


def direction_change_f1(
    pos_gen: np.ndarray,
    pos_ref: np.ndarray,
    hands: Sequence[int],
    tolerance: int = DIRECTION_TOLERANCE,
    deadband: float = DIRECTION_DEADBAND,
    fps: float = FPS,
) -> dict[str, float]:
    """Direction-change ("bowing attack") F1 of the hands, averaged over hands and axes.

    Kao & Su (ACM MM 2020) score bowing attacks as the frames where the right
    wrist's velocity changes sign along x, y or z, matched to the reference within
    ±3 frames. Here, for each joint in ``hands`` and each axis, events come from
    :func:`direction_changes` (velocity dead-band ``deadband`` m/s), are matched
    one-to-one within ``±tolerance`` frames, and precision, recall and F1 are
    averaged over the ``len(hands) * 3`` trajectories. Returns
    ``{"precision", "recall", "f1"}``, each in [0, 1]; higher is better.
    """
    a, b = _pair(pos_gen, pos_ref, ("pos_gen", "pos_ref"), min_frames=2)
    idx = _joints(hands, a.shape[1], "hands")
    scores = [
        event_f1(
            direction_changes(a[:, j, axis], fps, deadband),
            direction_changes(b[:, j, axis], fps, deadband),
            tolerance,
        )
        for j in idx
        for axis in range(3)
    ]
    p, r, f = np.mean(scores, axis=0)
    return {"precision": float(p), "recall": float(r), "f1": float(f)}


# --------------------------------------------------------------------------- similarity


def cosine_similarity(pos_gen: np.ndarray, pos_ref: np.ndarray, joints: Sequence[int] | None = None) -> float:
    """Cosine similarity of mean-centred joint trajectories, in [-1, 1].

    After Kao & Su (ACM MM 2020), who report the cosine similarity of generated and
    reference wrist trajectories. Definition used here: for each selected joint
    (all when ``joints`` is None), subtract its mean position over time from both
    trajectories, flatten each to a ``3T`` vector, take the cosine of the two
    vectors, and average over joints. Centring makes it compare the shape and
    timing of the motion rather than the (near-constant) body position. A joint
    that is still in both sequences scores 1, still in exactly one scores 0.
    Higher is better. (Kao & Su's reference code instead averages
    ``sklearn`` cosine similarities over all frame pairs of uncentred positions.)
    """
    a, b = _pair(pos_gen, pos_ref, ("pos_gen", "pos_ref"))
    if joints is not None:
        idx = _joints(joints, a.shape[1], "joints")
        a, b = a[:, idx], b[:, idx]
    a = (a - a.mean(axis=0)).transpose(1, 0, 2).reshape(a.shape[1], -1)
    b = (b - b.mean(axis=0)).transpose(1, 0, 2).reshape(b.shape[1], -1)
    na, nb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
    tiny = 1e-9
    still_a, still_b = na < tiny, nb < tiny
    cos = np.sum(a * b, axis=1) / np.maximum(na * nb, tiny * tiny)
    cos = np.where(still_a & still_b, 1.0, np.where(still_a | still_b, 0.0, cos))
    return float(np.mean(cos))


# --------------------------------------------------------------------------- dynamics


def joint_velocities(pos: np.ndarray, fps: float = FPS) -> np.ndarray:
    """Finite-difference joint velocities ``(T-1, J, 3)``, m/s."""
    pos = _positions(pos, "pos", min_frames=2)
    return np.diff(pos, axis=0) * fps


def velocity_spread(pos: Positions, fps: float = FPS) -> float:
    """RMS over joints and axes of the per-sequence temporal std of joint velocity, m/s.

    ``sqrt(mean_{j,c} var_t v[t, j, c])``, with the variance pooled over all frames of
    all given sequences (each sequence's velocities about their own mean).
    """
    seqs = _sequence_list(pos, "pos", min_frames=2)
    num, den = 0.0, 0
    for s in seqs:
        v = np.diff(s, axis=0) * fps
        num += float(np.sum((v - v.mean(axis=0)) ** 2))
        den += v.size
    return float(np.sqrt(num / den))


def energy_ratio(pos_gen: Positions, pos_real: Positions, fps: float = FPS) -> float:
    """Motion-energy ratio: :func:`velocity_spread` of generated over real motion.

    1.0 means the generated motion moves as much as real motion; near 0 signals
    collapse to a mean pose; above 1, jitter or exaggeration. Unitless. Each
    argument is one ``(T, J, 3)`` array or a list of them (sequences need not be
    the same length). Better: closer to 1.
    """
    real = velocity_spread(pos_real, fps)
    if real <= 0.0:
        raise DataError("real motion has zero velocity spread (frozen); the ratio is undefined", source="pos_real")
    return velocity_spread(pos_gen, fps) / real


def jerk(pos: Positions, fps: float = FPS) -> float:
    """Mean jerk magnitude, m/s³: mean over frames and joints of ``|d³p/dt³|``.

    Third finite difference times ``fps**3`` (needs >= 4 frames per sequence); one
    ``(T, J, 3)`` array or a list of them. Report it for generated and real motion
    alike: lower means smoother, and a generated value far above the real one means
    jitter. Sensitive to mocap noise, which the third difference amplifies.
    """
    seqs = _sequence_list(pos, "pos", min_frames=4)
    total, count = 0.0, 0
    for s in seqs:
        j = np.linalg.norm(np.diff(s, n=3, axis=0), axis=-1) * fps**3
        total += float(j.sum())
        count += j.size
    return total / count


# --------------------------------------------------------------------------- band power


def in_place(pos: np.ndarray, root: int = 0) -> np.ndarray:
    """Positions ``(T, J, 3)`` m with joint ``root``'s horizontal (x, z) path subtracted.

    Y is up, so this keeps every height (hip bounce included) and removes travel over
    the floor: the frame the models are trained in (``models.data.canonical``),
    where the real dances' root x and z are already 0.
    """
    pos = _positions(pos, "pos")
    _joints([root], pos.shape[1], "root")
    out = pos.copy()
    out[:, :, [0, 2]] -= pos[:, root : root + 1, [0, 2]]
    return out


def band_energy_points(x: np.ndarray, band: tuple[float, float], fps: float) -> np.ndarray:
    """Per joint and axis ``(J, 3)``, the sum over frames of the squared band part of ``x (T, J, 3)``, m²·frames.

    ``x`` minus its mean over time, real FFT along time; by Parseval the energy of
    the band-passed signal is ``sum_k w_k |X_k|² / T`` over the bins ``k`` with
    ``lo <= f_k <= hi``, ``w_k = 2`` except 1 for the DC and (even ``T``) Nyquist bins.
    """
    t = x.shape[0]
    spec = np.fft.rfft(x - x.mean(axis=0), axis=0)
    freq = np.fft.rfftfreq(t, 1.0 / fps)
    weight = np.full(freq.shape, 2.0)
    weight[0] = 1.0
    if t % 2 == 0:
        weight[-1] = 1.0
    keep = (freq >= band[0]) & (freq <= band[1])
    power = spec[keep].real ** 2 + spec[keep].imag ** 2
    return np.tensordot(weight[keep], power, axes=1) / t


def _band_energy(x: np.ndarray, band: tuple[float, float], fps: float) -> float:
    """:func:`band_energy_points` summed over joints and axes, m²·frames."""
    return float(band_energy_points(x, band, fps).sum())


def _band(band: tuple[float, float], name: str = "band") -> tuple[float, float]:
    lo, hi = float(band[0]), float(band[1])
    if not (lo >= 0.0 and hi > lo) or math.isnan(hi):
        raise DataError(f"expected (low, high) Hz with 0 <= low < high, got {band}", source=name)
    return lo, hi


def band_rms(pos: Positions, band: tuple[float, float], fps: float = FPS, root: int | None = 0) -> float:
    """RMS in metres of the part of the motion in a frequency band, pooled over sequences.

    ``pos``: one ``(T, J, 3)`` array of FK positions (m, at ``fps``) or a list of them
    (lengths may differ). Each sequence is put :func:`in_place` (joint ``root``'s
    horizontal path removed; ``root=None``: as given), its mean over time removed,
    and its band energy taken from its own FFT (no windowing) over the bins with
    ``band[0] <= f <= band[1]`` Hz. The energies of all sequences are summed and
    divided by the total number of values (frames x joints x 3), so the result is
    the RMS over frames, joints and axes of the band-passed motion: a sinusoid of
    amplitude ``A`` m on one axis of every joint, at a frequency inside the band,
    gives ``A / sqrt(6)`` (``A / sqrt(2)`` on that axis, 0 on the other two).
    """
    seqs = _sequence_list(pos, "pos", min_frames=2)
    lo_hi = _band(band)
    energy, count = 0.0, 0
    for s in seqs:
        if root is not None:
            s = in_place(s, root)
        energy += _band_energy(s, lo_hi, fps)
        count += s.size
    return math.sqrt(energy / count)


def band_ratios(
    pos_gen: Positions,
    pos_real: Positions,
    fps: float = FPS,
    root: int | None = 0,
    dance_band: tuple[float, float] = DANCE_BAND,
    jitter_band: tuple[float, float] = JITTER_BAND,
) -> dict[str, float]:
    """Dance-scale amplitude and jitter of generated motion relative to real motion.

    ``pos_gen``, ``pos_real``: FK positions ``(T, J, 3)`` m at ``fps`` (30), one array
    or a list (the real dances for the same music, or any real set). With
    :func:`band_rms` of each set in each band (power pooled over sequences),

    - ``band_amp`` = ``band_rms(gen, dance_band) / band_rms(real, dance_band)``:
      1 moves at the dancers' scale, below 1 smaller (0.25-3 Hz by default);
    - ``jitter`` = the same in ``jitter_band`` (6 Hz up to Nyquist): above 1 the
      generated motion trembles more than the real dances (issue 18's target: ≤ 1.5);
    - ``band_amp_gen_m``, ``band_amp_real_m``, ``jitter_gen_m``, ``jitter_real_m``:
      the four RMS values in metres.

    Raises :class:`DataError` when the real motion has no power in a band (RMS below
    1 nm, rounding error: the ratio is undefined).
    """
    out: dict[str, float] = {}
    for key, band in (("band_amp", dance_band), ("jitter", jitter_band)):
        gen = band_rms(pos_gen, band, fps, root)
        real = band_rms(pos_real, band, fps, root)
        if real < 1e-9:
            raise DataError(f"real motion has no power in {band} Hz; the {key} ratio is undefined", source="pos_real")
        out[key] = gen / real
        out[f"{key}_gen_m"] = gen
        out[f"{key}_real_m"] = real
    return out


# --------------------------------------------------------------------------- feature-space statistics


def _features(x: np.ndarray, name: str, min_rows: int) -> np.ndarray:
    return _finite(x, name, "features of shape (N, F)", lambda a: a.ndim == 2, min_rows, "feature vectors")


def _psd_sqrt(cov: np.ndarray) -> np.ndarray:
    """Symmetric square root of a symmetric positive semi-definite matrix."""
    w, v = np.linalg.eigh(cov)
    return (v * np.sqrt(np.clip(w, 0.0, None))) @ v.T


def frechet_distance(feats_a: np.ndarray, feats_b: np.ndarray) -> float:
    """Fréchet distance between Gaussians fitted to two feature sets, in squared feature units.

    ``|mu_a - mu_b|² + Tr(S_a + S_b - 2 (S_a S_b)^½)`` (Heusel et al., NeurIPS 2017,
    "FID"; used for motion by e.g. Li et al., AI Choreographer, ICCV 2021), with
    feature sets ``(Na, F)`` and ``(Nb, F)`` from the style classifier
    (:func:`models.evaluation.classifier.embed`). ``Tr (S_a S_b)^½`` is computed as
    the trace of ``(S_a^½ S_b S_a^½)^½``, which has the same eigenvalues but is
    symmetric PSD, so it is done with ``eigh`` and clipped eigenvalues: always real
    and stable for singular covariances (N < F). It agrees with the
    ``scipy.linalg.sqrtm`` formula wherever that is well conditioned (tested).
    0 for identical sets; lower is better.
    """
    a = _features(feats_a, "feats_a", 2)
    b = _features(feats_b, "feats_b", 2)
    if a.shape[1] != b.shape[1]:
        raise DataError(f"has {a.shape[1]} features but feats_b has {b.shape[1]}", source="feats_a")
    mu_a, mu_b = a.mean(axis=0), b.mean(axis=0)
    cov_a, cov_b = np.cov(a, rowvar=False).reshape(a.shape[1], -1), np.cov(b, rowvar=False).reshape(b.shape[1], -1)
    root_a = _psd_sqrt(cov_a)
    middle = root_a @ cov_b @ root_a
    tr_sqrt = float(np.sum(np.sqrt(np.clip(np.linalg.eigvalsh((middle + middle.T) / 2), 0.0, None))))
    fd = float(np.sum((mu_a - mu_b) ** 2) + np.trace(cov_a) + np.trace(cov_b) - 2.0 * tr_sqrt)
    return max(fd, 0.0)


def diversity(feats: np.ndarray) -> float:
    """Mean pairwise Euclidean distance between feature vectors ``(N, F)``, feature units.

    Lee et al., "Dancing to Music" (NeurIPS 2019) measure diversity as the average
    feature distance between generated dances; pass one classifier embedding per
    generated window or sequence. Compare with the same statistic on real motion:
    higher is more varied, and far below real signals mode collapse.
    """
    f = _features(feats, "feats", 2)
    return float(np.mean(pdist(f)))


def multimodality(groups: Sequence[np.ndarray]) -> float:
    """Mean pairwise Euclidean distance between generations for the same music, averaged over the music.

    Lee et al., "Dancing to Music" (NeurIPS 2019): ``groups[i]`` holds one feature
    vector per generation ``(K_i, F)`` (K_i >= 2) made for music ``i`` with different
    random draws. 0 for a deterministic model; higher means more distinct dances per song.
    """
    if not groups:
        raise DataError("no groups of generations", source="groups")
    return float(np.mean([np.mean(pdist(_features(g, f"groups[{i}]", 2))) for i, g in enumerate(groups)]))


# --------------------------------------------------------------------------- one call per sequence


def sequence_metrics(
    pos_gen: np.ndarray,
    pos_ref: np.ndarray,
    hands: Sequence[int],
    quat_gen: np.ndarray | None = None,
    quat_ref: np.ndarray | None = None,
    torso: tuple[int, int] | None = None,
    fps: float = FPS,
) -> dict[str, float]:
    """Every per-sequence metric of a generated sequence against its reference.

    Keys match :data:`models.evaluation.report.METRICS`: ``pos_l1``, ``hand_l1``,
    ``dtw``, ``lcss``, ``pck@0.1``, ``pck@0.2``, ``dir_f1``, ``cosine`` (of the
    ``hands`` trajectories, as Kao & Su), ``jerk`` (of ``pos_gen``), and
    ``rot_l1`` when both quaternion arrays are given. Defaults as in each
    function. Beat metrics (:mod:`models.evaluation.beats`) and set-level metrics
    (:func:`frechet_distance`, :func:`diversity`, :func:`energy_ratio`) are
    computed separately because they need music or many sequences.
    """
    out = {
        "pos_l1": position_l1(pos_gen, pos_ref),
        "hand_l1": hand_l1(pos_gen, pos_ref, hands),
        "dtw": dtw_distance(pos_gen, pos_ref),
        "lcss": lcss_similarity(pos_gen, pos_ref),
        **{f"pck@{a}": pck(pos_gen, pos_ref, a, torso) for a in PCK_ALPHAS},
        "dir_f1": direction_change_f1(pos_gen, pos_ref, hands, fps=fps)["f1"],
        "cosine": cosine_similarity(pos_gen, pos_ref, joints=hands),
        "jerk": jerk(pos_gen, fps),
    }
    if quat_gen is not None and quat_ref is not None:
        out["rot_l1"] = rotation_l1(quat_gen, quat_ref)
    return out
