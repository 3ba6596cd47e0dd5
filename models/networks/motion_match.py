"""Issue 40's second design: music -> motion descriptors -> motion matching (``chooser="match"``).

The library performer (models/networks/library_player.py) normally lets the default's code
predictor choose (``chooser="codes"``). Here the music chooses by descriptors instead, and
everything after the choice (motion matching on continuity and the expected beat, tempo
following, beat warp, handover blending) is the same player:

* **music descriptors** (:func:`music_descriptors`), one row a code step (8 frames at 30 fps),
  causal: ln of the tempo follower's beat period (frames), and the means over the last 8
  frames of the standardised feature columns loudness (13), loudness over its 60-s mean
  (13 - 42), onset strength (28), pulse clarity (60) and MFCC 1 (spectral tilt, 1);
* **motion descriptors** (:func:`motion_descriptors`) of a 16-frame window: ln mean joint
  speed of its first 8 frames (m a frame, world FK), quickness ln(mean joint acceleration /
  mean joint speed) (root-relative, whole window) and ln amplitude (root-relative points'
  standard deviation over the window, m, mean over points);
* a ridge regression (:func:`fit`) from the first to the second, fitted on the DWM training
  split (``models.data.split``: the 34 training dances), every 8 frames, in z-scores of the
  training set; each row is also used stretched by 0.8x and 1.25x (the tempo period over r,
  speed and acceleration/speed times r, amplitude kept: what the corpus' tempo augmentation
  does to these descriptors). Coefficients: ``models/assets/match_regression.json``;
* the library's windows are z-scored within the library, clustered into the codebook's K
  slots by k-means (:func:`match_windows`: a code is a cluster of similar windows), and
  :class:`MatchChooser` gives the stream logits ``-|z_target - centre_k|^2 / (2 TAU^2)``, the
  target the regression's prediction rescaled to unit spread (:class:`Regression`).

Refit: ``python -m models.training.motion_match ../shared/data/dwm`` (models/training/motion_match.py).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

#: Standardised feature columns the music descriptors average (mfcc_onset + context + beat kind).
COL_LOUD, COL_LOUD_CTX, COL_ONSET, COL_CLARITY, COL_TILT = 13, 42, 28, 60, 1
MUSIC_NAMES = ("ln_period", "loudness", "loudness_vs_60s", "onset", "clarity", "mfcc1")
MOTION_NAMES = ("ln_speed", "quickness", "ln_amplitude")
#: Width (z units) of the chooser's softmax around the regression's target.
TAU: float = 0.35
#: Ridge penalty of the regression (on z-scored inputs).
RIDGE: float = 1.0
#: Tempo factors each training row is also used at (besides 1.0).
STRETCH: tuple[float, ...] = (0.8, 1.25)
ASSET = Path(__file__).resolve().parents[1] / "assets" / "match_regression.json"


def music_descriptors(hist: np.ndarray, period: np.ndarray, fallback: float) -> np.ndarray:
    """(n, 6) music descriptors (:data:`MUSIC_NAMES`): ``hist`` (n, seg, D) standardised feature
    frames (the stream's ``_hist``), ``period`` (n,) the tempo follower's beat period in frames
    (<= 0: no pulse, ``fallback`` used)."""
    h = np.asarray(hist, np.float64)
    p = np.where(np.asarray(period, np.float64) > 0, period, fallback)
    m = h.mean(1)
    return np.stack([np.log(p), m[:, COL_LOUD], m[:, COL_LOUD] - m[:, COL_LOUD_CTX], m[:, COL_ONSET],
                     m[:, COL_CLARITY], m[:, COL_TILT]], 1)


def motion_descriptors(windows: np.ndarray, seg: int, chunk: int = 2048) -> np.ndarray:
    """(N, 3) motion descriptors (:data:`MOTION_NAMES`) of pose windows (N, F >= seg + 2, P)."""
    from models.networks.member_tables import member_positions

    out = np.empty((len(windows), 3))
    for a in range(0, len(windows), chunk):
        pos = member_positions(np.asarray(windows[a: a + chunk])[None])[0]  # (n, F, J, 3)
        speed = np.linalg.norm(np.gradient(pos, axis=1), axis=-1).mean(-1)[:, :seg].mean(1)
        rel = pos - pos[:, :, :1]
        v = np.linalg.norm(np.diff(rel, axis=1), axis=-1).mean((-1, -2))
        acc = np.linalg.norm(np.diff(rel, 2, axis=1), axis=-1).mean((-1, -2))
        amp = rel.std(1).mean((-1, -2))
        out[a: a + chunk] = np.stack([np.log(np.maximum(speed, 1e-6)), np.log(np.maximum(acc, 1e-9) / np.maximum(v, 1e-9)),
                                      np.log(np.maximum(amp, 1e-6))], 1)
    return out


class Regression:
    """Music descriptors (n, 6) -> target motion descriptors (n, 3): linear, then rescaled so that
    its predictions on the training rows have mean 0 and standard deviation 1 (R^2 is about 0.1:
    unscaled, every target would sit near the mean window). The library's windows are z-scored
    too, so the music's rank among the training music picks the window of that rank."""

    def __init__(self, d: dict) -> None:
        self.x_mean, self.x_std = np.array(d["x_mean"]), np.array(d["x_std"])
        self.w, self.b = np.array(d["w"]), np.array(d["b"])
        self.fallback = float(d["period_fallback"])
        self.p_mean, self.p_std = np.array(d["pred_mean"]), np.array(d["pred_std"])
        self.meta = d

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """(n, 3): the prediction as z-scores of the training set's predictions (its spread widened to 1)."""
        return (((np.asarray(x) - self.x_mean) / self.x_std) @ self.w + self.b - self.p_mean) / self.p_std


def load_regression(path: Path = ASSET) -> Regression:
    """The fitted regression (:func:`fit`); DataError naming the file if it is missing or unreadable."""
    from models.errors import DataError

    try:
        return Regression(json.loads(Path(path).read_text()))
    except (OSError, ValueError, KeyError) as e:
        raise DataError(f"{path}: cannot read the match regression ({e})") from None


class MatchChooser:
    """The stream's code chooser for ``chooser="match"`` (DanceStream calls it every code step):
    ``(hist (seg, D) standardised, period frames) -> logits (K,) float32``. ``centres`` (K, 3)
    the clusters' descriptor z-scores; ``regression`` maps the music to a target in them.
    ``last_target`` keeps the latest target (3,) for measuring."""

    def __init__(self, regression: Regression, centres: np.ndarray, tau: float = TAU) -> None:
        self.regression, self.centres, self.tau = regression, np.asarray(centres, np.float64), float(tau)
        self.last_target = np.zeros(3)

    def target(self, hist: np.ndarray, period: float) -> np.ndarray:
        """(3,) target z-scores for one code step."""
        return self.regression(music_descriptors(hist[None], np.array([period]), self.regression.fallback))[0]

    def __call__(self, hist: np.ndarray, period: float) -> np.ndarray:
        z = self.target(hist, period)
        self.last_target = z
        d2 = ((self.centres - z) ** 2).sum(1)
        return (-(d2 - d2.min()) / (2.0 * self.tau ** 2)).astype(np.float32)


def match_windows(windows_poses: list[np.ndarray], starts: list[np.ndarray], clip: list[np.ndarray], seg: int,
                  k: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cluster a library's windows by descriptor: (code (N,) int64, dist (N, k) float32 to every
    centre, centres (k, 3) z-scores). ``windows_poses`` per clip its poses (T, P); ``starts``
    and ``clip`` (N,) each window's start frame and clip index (windows of 2 seg frames)."""
    import warnings

    from scipy.cluster.vq import kmeans2

    win = np.stack([windows_poses[c][s: s + 2 * seg] for c, s in zip(clip, starts)])
    d = motion_descriptors(win, seg)
    z = (d - d.mean(0)) / np.maximum(d.std(0), 1e-9)
    n = min(k, len(z))
    rng = np.random.default_rng(seed)
    with warnings.catch_warnings():  # an empty cluster is filled by library_model with the nearest windows
        warnings.simplefilter("ignore", UserWarning)
        centres, _ = kmeans2(z, z[rng.choice(len(z), n, replace=False)], iter=20, minit="matrix", seed=seed)
    if n < k:  # fewer windows than codes: the rest repeat centres
        centres = np.concatenate([centres, centres[rng.integers(0, n, k - n)]])
    dist = np.sqrt(((z[:, None, :] - centres[None]) ** 2).sum(-1)).astype(np.float32)
    return dist.argmin(1), dist, centres
