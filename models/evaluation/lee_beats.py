"""Kinematic beats as Lee et al. define them ("Dancing to Music", NeurIPS 2019, eqs. 1-2).

Lee et al. compute, per keypoint, the motion between neighbouring poses as a
magnitude and an angle, collect the magnitudes into angle bins over time (a
"motion spectrogram"), and take as kinematic beats the frames where that matrix
drops sharply: the joints stop (the magnitude falls) or turn (the magnitude leaves
its angle bin for another). This module follows that description on 3-D joint
positions ``pos (T, J, 3)`` in metres at ``fps`` (30):

* eq. 1, :func:`motion_matrix`: for every step ``t -> t+1`` and joint ``j`` the
  displacement ``v = p[t+1, j] - p[t, j]``, its magnitude ``|v| * fps`` (m/s) and its
  direction bin; ``M[t, k]`` is the summed speed of the joints moving in direction
  bin ``k``. The paper's keypoints are 2-D, so its angle is one planar angle; in 3-D
  the direction is binned by azimuth about the vertical +Y axis
  (``azimuth_bins`` sectors) and by elevation (down / level / up, split at
  ``±elevation_deg``);
* eq. 2, :func:`offset_strength`: ``O[t] = sum_k max(0, M[t-1, k] - M[t, k])``, the
  half-wave rectified decrease of the matrix at frame ``t`` (between the step into
  ``t`` and the step out of it): large where joints stop or change direction, like
  the spectral-flux onset envelope of audio with the sign reversed ("offsets");
* :func:`kinematic_offsets`: peaks of ``O`` (Gaussian-smoothed by ``sigma`` frames)
  picked with ``librosa.util.peak_pick``: local maxima within ±``peak_radius`` frames
  that exceed the mean over ±``avg_radius`` frames by ``delta`` (``O`` is first
  divided by its 95th percentile, so ``delta`` has no unit), at least
  ``min_spacing`` frames apart.

The paper's exact thresholds are not published; the defaults here are chosen on
synthetic motion (tests/test_dtm.py) and stated in docs/dtm.md. The
beat-coverage metric keeps using :func:`models.evaluation.beats.kinematic_beats`
(speed minima), so existing evaluation numbers do not move.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d

from models.evaluation.metrics import _positions
from models.timebase import FPS

#: Azimuth sectors of the direction bins (45° each).
AZIMUTH_BINS: int = 8
#: Elevation above which (below minus which) a displacement counts as up (down), degrees.
ELEVATION_DEG: float = 30.0
#: Smoothing of the offset envelope, frames.
OFFSET_SIGMA: float = 1.0
#: Peak picking: local-max radius, local-mean radius (frames), threshold over the local mean.
PEAK_RADIUS: int = 3
AVG_RADIUS: int = 8
DELTA: float = 0.15
#: Minimum spacing of kinematic offsets, frames (0.2 s at 30 fps).
MIN_SPACING: int = 6
#: Joints slower than this (m/s) on a step are treated as still (mocap jitter).
MIN_SPEED: float = 0.05


def direction_bins(v: np.ndarray, azimuth_bins: int = AZIMUTH_BINS, elevation_deg: float = ELEVATION_DEG) -> np.ndarray:
    """Direction bin in ``[0, 3 * azimuth_bins)`` of displacement vectors ``v (..., 3)`` (Y up).

    bin = elevation band (0 down, 1 level, 2 up) * azimuth_bins + azimuth sector,
    sector 0 centred on +Z (the character's forward), counted towards +X.
    """
    az = np.arctan2(v[..., 0], v[..., 2])  # (-pi, pi], 0 = +Z
    sector = np.floor((az + np.pi / azimuth_bins) / (2 * np.pi / azimuth_bins)).astype(np.int64) % azimuth_bins
    horiz = np.linalg.norm(v[..., [0, 2]], axis=-1)
    elev = np.degrees(np.arctan2(v[..., 1], horiz))
    band = np.where(elev < -elevation_deg, 0, np.where(elev > elevation_deg, 2, 1))
    return band * azimuth_bins + sector


def motion_matrix(pos: np.ndarray, fps: float = FPS, azimuth_bins: int = AZIMUTH_BINS,
                  elevation_deg: float = ELEVATION_DEG, min_speed: float = MIN_SPEED) -> np.ndarray:
    """Eq. 1: ``M (T-1, 3 * azimuth_bins)``, summed joint speed (m/s) per direction bin per step.

    Row ``t`` is the step from frame ``t`` to ``t + 1``. Joints slower than
    ``min_speed`` on a step contribute nothing.
    """
    pos = _positions(pos, "pos", min_frames=3)
    v = np.diff(pos, axis=0)  # (T-1, J, 3)
    speed = np.linalg.norm(v, axis=-1) * fps
    speed = np.where(speed >= min_speed, speed, 0.0)
    bins = direction_bins(v, azimuth_bins, elevation_deg)
    m = np.zeros((v.shape[0], 3 * azimuth_bins))
    rows = np.repeat(np.arange(v.shape[0]), v.shape[1])
    np.add.at(m, (rows, bins.ravel()), speed.ravel())
    return m


def offset_strength(m: np.ndarray) -> np.ndarray:
    """Eq. 2: ``O (T,)``, ``O[t] = sum_k max(0, M[t-1, k] - M[t, k])`` for ``t = 1 .. T-2``; 0 at both ends.

    ``m``: :func:`motion_matrix` of a ``T``-frame sequence (``T - 1`` steps).
    """
    drop = np.maximum(m[:-1] - m[1:], 0.0).sum(axis=1)  # frame t = 1 .. T-2
    return np.concatenate([[0.0], drop, [0.0]])


def kinematic_offsets(
    pos: np.ndarray,
    fps: float = FPS,
    sigma: float = OFFSET_SIGMA,
    peak_radius: int = PEAK_RADIUS,
    avg_radius: int = AVG_RADIUS,
    delta: float = DELTA,
    min_spacing: int = MIN_SPACING,
) -> np.ndarray:
    """Kinematic beats (sorted int frames) of ``pos (T, J, 3)``: peaks of the smoothed :func:`offset_strength`.

    A motionless sequence has none.
    """
    import librosa

    o = offset_strength(motion_matrix(pos, fps))
    if sigma > 0:
        o = gaussian_filter1d(o, sigma, mode="constant")
    scale = np.percentile(o, 95)
    if scale <= 1e-9:
        return np.zeros(0, dtype=np.int64)
    peaks = librosa.util.peak_pick(o / scale, pre_max=peak_radius, post_max=peak_radius + 1, pre_avg=avg_radius,
                                   post_avg=avg_radius + 1, delta=delta, wait=max(0, int(min_spacing) - 1))
    return np.asarray(peaks, dtype=np.int64)
