"""Stability of a long generated pose stream: does the performer keep dancing (issue 18, target 5)?

The stream is cut into consecutive stretches of :data:`STRETCH_S` (30) seconds at 30 fps
(a shorter tail is not judged). Each stretch goes through forward kinematics on the
default skeleton (:func:`models.evaluation.evaluate.positions`: 30 points, metres) and
must:

- **amplitude**: its dance-scale amplitude (:func:`~models.evaluation.metrics.band_rms`
  in :data:`~models.evaluation.metrics.DANCE_BAND`, 0.25-3 Hz, in place, the
  stretch's own mean removed) is between :data:`AMP_RANGE` (0.5x and 1.5x) the real
  dances' (``ref_m``, see :func:`real_reference_m`);
- **root**: the root (Hips) stays within :data:`ROOT_RADIUS_M` (0.5 m) of its position
  in the stream's first frame, horizontally (distance in x-z) and vertically (|dy|); a
  performer on a stage (``stage`` (W, D) m, models/networks/stage.py) travels: horizontally
  it must then stay inside the stage (``root_horizontal_m`` is how far outside it went, 0
  inside; :data:`STAGE_TOL_M` allowed);
- **no freeze**: amplitude above :data:`FROZEN_RATIO` (0.05x) the real dances', and no
  run of :data:`FREEZE_S` (1 s) or more in which no point moves faster than
  :data:`STILL_SPEED` (0.02 m/s, in place);
- **no explosion**: every value finite, quaternions unit (norm within
  :data:`QUAT_NORM_TOL`), no point faster than :data:`MAX_SPEED` (20 m/s, in place).

:func:`stability_check` judges a whole ``(T, POSE_DIM)`` array; :class:`StabilityMonitor`
does the same frame by frame with a fixed buffer of one stretch (the soak's hour of
frames never has to be held). Both return a :class:`StabilityReport`.
The thresholds and the real dances' own values are in docs/metrics.md.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from models.errors import DataError
from models.rig.motion import POSE_DIM
from models.timebase import FPS

#: Length of one judged stretch, seconds.
STRETCH_S: float = 30.0
#: Allowed stretch amplitude, as multiples of the real dances' band RMS.
AMP_RANGE: tuple[float, float] = (0.5, 1.5)
#: Largest allowed distance of the root from its first-frame position, metres (horizontal and vertical each).
ROOT_RADIUS_M: float = 0.5
#: How far (m) a performer on a stage may be found outside it before a stretch fails (the stage
#: part never lets it cross an edge: this is float slack, not a margin of the dance).
STAGE_TOL_M: float = 0.01
#: Below this multiple of the real amplitude a stretch is frozen.
FROZEN_RATIO: float = 0.05
#: A point slower than this is still, m/s (in place).
STILL_SPEED: float = 0.02
#: A run of at least this many seconds with every point still is a freeze.
FREEZE_S: float = 1.0
#: Faster than this, m/s (any point, in place), the motion has exploded.
MAX_SPEED: float = 20.0
#: Largest allowed deviation of a quaternion's norm from 1.
QUAT_NORM_TOL: float = 0.01


@dataclass
class StabilityReport:
    """What :func:`stability_check` / :meth:`StabilityMonitor.result` found.

    ``stretches``: one dict per judged stretch with ``index``, ``start_s``, ``end_s``,
    ``amp_m`` (band RMS, m), ``amp_ratio`` (over ``ref_m``), ``root_horizontal_m`` and
    ``root_vertical_m`` (largest distance from the first frame's root, m; on a stage the
    horizontal one is how far outside the stage the root went), ``still_s``
    (longest run with every point still, s), ``max_speed`` (fastest point, m/s),
    ``finite`` and ``reasons`` (empty when the stretch passes). Values that cannot be
    computed (non-finite stretch) are None. ``tail_frames``: frames after the last
    whole stretch, not judged.
    """

    ref_m: float
    stretch_s: float
    fps: float
    stretches: list[dict] = field(default_factory=list)
    tail_frames: int = 0
    stage: list[float] | None = None  # (width, depth) m of the stage the performer travels on; None: in place

    @property
    def failures(self) -> list[str]:
        """One line per failing stretch, ``"stretch 3 (90-120 s): reason; reason"``; or why nothing was judged."""
        if not self.stretches:
            return [f"no whole {self.stretch_s:g}-s stretch to judge ({self.tail_frames} frames)"]
        return [f"stretch {s['index']} ({s['start_s']:g}-{s['end_s']:g} s): " + "; ".join(s["reasons"])
                for s in self.stretches if s["reasons"]]

    @property
    def ok(self) -> bool:
        return not self.failures

    def summary(self, most: int = 3) -> str:
        """One line: how many stretches pass, and the first ``most`` failures."""
        fails = self.failures
        if self.ok:
            amps = [s["amp_ratio"] for s in self.stretches]
            return (f"{len(self.stretches)} stretches of {self.stretch_s:g} s all pass "
                    f"(amplitude {min(amps):.2f}-{max(amps):.2f}x the real {self.ref_m * 100:.1f} cm)")
        if not self.stretches:
            return fails[0]
        more = f"; and {len(fails) - most} more" if len(fails) > most else ""
        return f"{len(fails)} of {len(self.stretches)} stretches of {self.stretch_s:g} s fail: " + \
            "; ".join(fails[:most]) + more

    def to_dict(self) -> dict:
        """JSON-ready: the fields plus ``ok`` and ``failures``."""
        return {**asdict(self), "ok": self.ok, "failures": self.failures}


def _check_ref(ref_m: float) -> float:
    r = float(ref_m)
    if not (math.isfinite(r) and r > 0.0):
        raise DataError(f"must be a positive band RMS in metres, got {ref_m}", source="ref_m")
    return r


def _longest_run(flags: np.ndarray) -> int:
    """Length of the longest run of True in a 1-D bool array."""
    if not flags.any():
        return 0
    edges = np.diff(np.concatenate([[0], flags.astype(np.int8), [0]]))
    return int(np.max(np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)))


def judge_stretch(poses: np.ndarray, root0: np.ndarray, ref_m: float, index: int = 0, fps: float = FPS,
                  stage: tuple[float, float] | None = None) -> dict:
    """Values and failure reasons of one stretch ``poses (n, POSE_DIM)`` (see the module docstring).

    ``root0``: the stream's first root position (3,) m; ``index``: the stretch's number
    (its start is ``index * n / fps`` s); ``stage``: (width, depth) m of the stage the
    performer travels on, centred on the origin (None or zeros: it dances in place).
    """
    from models.evaluation.evaluate import positions
    from models.evaluation.metrics import DANCE_BAND, band_rms, in_place

    n = len(poses)
    out: dict = {"index": index, "start_s": round(index * n / fps, 3), "end_s": round((index + 1) * n / fps, 3),
                 "amp_m": None, "amp_ratio": None, "root_horizontal_m": None, "root_vertical_m": None,
                 "still_s": None, "max_speed": None, "finite": bool(np.isfinite(poses).all())}
    reasons: list[str] = []
    if not out["finite"]:
        bad = int(np.argmax(~np.isfinite(poses).all(axis=1)))
        reasons.append(f"exploded: non-finite values from {out['start_s'] + bad / fps:.2f} s")
        out["reasons"] = reasons
        return out
    quat_err = float(np.max(np.abs(np.linalg.norm(poses[:, 3:].reshape(n, -1, 4), axis=-1) - 1.0)))
    if quat_err > QUAT_NORM_TOL:
        reasons.append(f"exploded: a quaternion norm is off by {quat_err:.3g}")
        out["reasons"] = reasons
        return out
    d = poses[:, :3] - root0
    on_stage = stage is not None and min(stage) > 0.0
    if on_stage:  # how far outside the stage the root went (0: inside throughout)
        ox = np.maximum(np.abs(poses[:, 0]) - 0.5 * stage[0], 0.0)
        oz = np.maximum(np.abs(poses[:, 2]) - 0.5 * stage[1], 0.0)
        out["root_horizontal_m"] = float(np.max(np.hypot(ox, oz)))
    else:
        out["root_horizontal_m"] = float(np.max(np.hypot(d[:, 0], d[:, 2])))
    out["root_vertical_m"] = float(np.max(np.abs(d[:, 1])))
    pos = in_place(positions(poses))
    amp = band_rms(pos, DANCE_BAND, fps, root=None)
    speed = np.linalg.norm(np.diff(pos, axis=0), axis=-1).max(axis=1) * fps  # (n-1,) fastest point per step
    out.update(amp_m=amp, amp_ratio=amp / ref_m, max_speed=float(speed.max()),
               still_s=_longest_run(speed < STILL_SPEED) / fps)
    lo, hi = AMP_RANGE
    if out["max_speed"] > MAX_SPEED:
        reasons.append(f"exploded: a point moves at {out['max_speed']:.1f} m/s (> {MAX_SPEED:g})")
    if out["amp_ratio"] < FROZEN_RATIO or out["still_s"] >= FREEZE_S:
        reasons.append(f"frozen: amplitude {amp * 100:.2f} cm ({out['amp_ratio']:.3f}x real), "
                       f"still for {out['still_s']:.1f} s")
    elif not lo <= out["amp_ratio"] <= hi:
        reasons.append(f"amplitude {out['amp_ratio']:.2f}x real, outside {lo:g}-{hi:g}x")
    if on_stage and out["root_horizontal_m"] > STAGE_TOL_M:
        reasons.append(f"root {out['root_horizontal_m']:.2f} m outside the {stage[0]:g}x{stage[1]:g} m stage")
    for key, what in ((("root_vertical_m", "vertically"),) if on_stage else
                      (("root_horizontal_m", "horizontally"), ("root_vertical_m", "vertically"))):
        if out[key] > ROOT_RADIUS_M:
            reasons.append(f"root {out[key]:.2f} m from its start {what} (> {ROOT_RADIUS_M:g} m)")
    out["reasons"] = reasons
    return out


class StabilityMonitor:
    """:func:`stability_check`, fed a few poses at a time; memory: one stretch of poses.

    ``ref_m``: the real dances' band RMS, metres (:func:`real_reference_m`); ``stage``: the
    stage (width, depth) m the performer travels on (None: in place; :func:`judge_stretch`).
    """

    def __init__(self, ref_m: float, fps: float = FPS, stretch_s: float = STRETCH_S,
                 stage: tuple[float, float] | None = None) -> None:
        self.stage = stage
        self.report = StabilityReport(_check_ref(ref_m), float(stretch_s), float(fps),
                                     stage=None if stage is None else [float(v) for v in stage])
        self._n = int(round(stretch_s * fps))
        if self._n < 4:
            raise DataError(f"a stretch needs at least 4 frames, got {stretch_s} s at {fps} fps", source="stretch_s")
        self._buf = np.empty((self._n, POSE_DIM))
        self._fill = 0
        self._root0: np.ndarray | None = None

    def add(self, poses: np.ndarray) -> None:
        """Frames ``(POSE_DIM,)`` or ``(n, POSE_DIM)``: root position (m) then 21 xyzw quaternions.

        Each stretch is judged as soon as its last frame arrives.
        """
        a = np.asarray(poses, dtype=np.float64)
        if a.ndim == 1:
            a = a[None]
        if a.ndim != 2 or a.shape[1] != POSE_DIM:
            raise DataError(f"expected poses of shape (POSE_DIM={POSE_DIM},) or (n, {POSE_DIM}), got {a.shape}",
                            source="poses")
        if self._root0 is None and len(a):
            self._root0 = a[0, :3].copy()
        while len(a):
            k = min(len(a), self._n - self._fill)
            self._buf[self._fill : self._fill + k] = a[:k]
            self._fill += k
            a = a[k:]
            if self._fill == self._n:
                idx = len(self.report.stretches)
                self.report.stretches.append(judge_stretch(self._buf, self._root0, self.report.ref_m, idx,
                                                           self.report.fps, self.stage))
                self._fill = 0
        self.report.tail_frames = self._fill

    def result(self) -> StabilityReport:
        return self.report


def stability_check(poses: np.ndarray, ref_m: float, fps: float = FPS, stretch_s: float = STRETCH_S,
                    stage: tuple[float, float] | None = None) -> StabilityReport:
    """Judge every whole ``stretch_s`` stretch of a generated stream ``poses (T, POSE_DIM)`` at ``fps``.

    ``ref_m``: the real dances' dance-band RMS in metres (:func:`real_reference_m`); ``stage``:
    the stage (width, depth) m the performer travels on (None: in place).
    Returns a :class:`StabilityReport` (``ok``, ``failures``, per-stretch values).
    """
    a = np.asarray(poses, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != POSE_DIM:
        raise DataError(f"expected poses of shape (T, {POSE_DIM}), got {a.shape}", source="poses")
    mon = StabilityMonitor(ref_m, fps, stretch_s, stage)
    mon.add(a)
    return mon.result()


def real_reference_m(data_root: str | Path, cache_dir: str | Path | None = ".cache/corpus", feature_config=None,
                     split: str = "val") -> float:
    """The real dances' dance-scale amplitude, metres: band RMS (0.25-3 Hz) of the ``split``
    dances' FK positions (tempo-1 corpus clips, 30 fps), power pooled over the dances.

    The same number as ``band_rms_m.band_amp`` of the real row in ``performer evaluate``'s
    per_dance.json. ``feature_config``: only picks the corpus cache entries (poses do not
    depend on it); None: :class:`~models.features.spectral.FeatureConfig` defaults.
    """
    from models.evaluation.evaluate import EvalOptions, load_clips, positions, split_dances
    from models.evaluation.metrics import DANCE_BAND, band_rms
    from models.features.spectral import FeatureConfig

    opts = EvalOptions(split=split, cache_dir=cache_dir, progress=False)
    _, names = split_dances(data_root, opts)
    if not names:
        raise DataError(f"no {split} dances found", source=data_root)
    clips = load_clips(data_root, names, feature_config or FeatureConfig(), opts)
    return band_rms([positions(c.poses) for c in clips], DANCE_BAND)
