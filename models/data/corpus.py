"""Training corpus: per dance (and per tempo factor), audio features and target poses
on one 30 fps grid.

Alignment: feature frame ``f`` of a song ends at audio time ``(f + 1) / 30`` s
(:func:`models.features.spectral.frame_time_s`). Target poses are the mocap joint
positions resampled by cubic spline at exactly those times (within the span the
mocap covers, :func:`models.data.alignment.motion_timestamps`), retargeted onto the
humanoid rig and canonicalised (:mod:`models.data.canonical`). So pose ``t`` of a
clip and feature ``t`` describe the same instant, and the pose never depends on
audio after it.

Tempo augmentation (Chen et al. 2021): a factor ``r`` plays the song ``r`` times as
fast (``librosa.effects.time_stretch``, constant speed, pitch kept) and the motion
with it: the stretched pose at time ``tau`` is the original pose at ``r * tau``.

Clips are cached as ``.npz`` under ``cache_dir`` keyed by the dance's files, the
feature config and the tempo, so a second training run starts in seconds.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline

from models.data.alignment import held_runs, motion_timestamps
from models.data.dwm import Dance, load_dance
from models.features.audio_io import load_audio
from models.features.spectral import FeatureConfig, extract_features, frame_time_s
from models.rig.retarget import retarget
from models.rig.skeleton import load_default_skeleton
from models.data.canonical import canonicalize
from models.timebase import FPS, SAMPLE_RATE

CORPUS_VERSION = 1


@dataclass
class Clip:
    """One training clip: features (T, D) and target poses (T, POSE_DIM), float32, 30 fps."""

    name: str
    style: str
    tempo: float
    features: np.ndarray
    poses: np.ndarray
    valid: np.ndarray  # (T,) bool; False near held-pose runs of the mocap
    first_frame: int = 0  # feature frame of the (stretched) song that clip frame 0 is

    @property
    def num_frames(self) -> int:
        return int(self.poses.shape[0])


def _key(dance: Dance, cfg: FeatureConfig, tempo: float) -> str:
    h = hashlib.sha1()
    for name in ("skeletons.json", "config.json"):
        st = (dance.directory / name).stat()
        h.update(f"{name}:{st.st_size}:{int(st.st_mtime)}".encode())
    st = dance.audio_path.stat()
    h.update(f"audio:{st.st_size}:{int(st.st_mtime)}:{cfg.fingerprint()}:{tempo:.4f}:{CORPUS_VERSION}".encode())
    return f"{dance.name}-t{tempo:.3f}-{h.hexdigest()[:12]}.npz"


def first_frame(dance: Dance, tempo: float = 1.0) -> int:
    """First feature frame ``f0`` of the tempo-stretched song inside the mocap span.

    Clip frame ``t`` is song frame ``f0 + t``: it ends at audio time
    ``frame_time_s(f0 + t)`` of the stretched song (``(f0 + t + 1) / 30`` s).
    """
    t0 = motion_timestamps(dance)[0]
    f = np.arange(int(np.ceil(t0 / tempo * FPS)) + 2)
    return int(np.argmax(tempo * frame_time_s(f) >= t0))


def clip_motion(dance: Dance, n_frames: int, tempo: float = 1.0) -> tuple:
    """The motion of a clip of ``dance`` at a tempo factor whose stretched song has
    ``n_frames`` feature frames: (the retargeted, **not** canonicalised
    :class:`~models.rig.motion.Motion` of clip frames ``f0 .. f1 - 1``, valid (T,) bool, f0, f1).
    :func:`make_clip` canonicalises it; models.training.travel_memory reads the root's travel
    and heading from it."""
    ts = motion_timestamps(dance)  # (N,) seconds of original audio time
    spline = CubicSpline(ts, dance.world_positions_m(), axis=0)
    # frame f (stretched song) ends at frame_time_s(f); original time = tempo * that.
    orig_t = tempo * frame_time_s(np.arange(n_frames))
    keep = np.flatnonzero((orig_t >= ts[0]) & (orig_t <= ts[-1]))
    if len(keep) < 2:
        raise ValueError(f"{dance.name}: motion does not overlap the audio")
    f0, f1 = int(keep[0]), int(keep[-1]) + 1
    positions = spline(orig_t[f0:f1])
    motion = retarget(positions, load_default_skeleton(), source=dance.name)
    valid = np.ones(f1 - f0, dtype=bool)
    for first, length in held_runs(dance):  # the mocap froze here: not a target to learn
        lo, hi = ts[max(first - 2, 0)], ts[min(first + length, len(ts) - 1)]
        valid &= ~((orig_t[f0:f1] >= lo) & (orig_t[f0:f1] <= hi))
    return motion, valid, f0, f1


def make_clip(dance: Dance, cfg: FeatureConfig, tempo: float = 1.0, audio: np.ndarray | None = None) -> Clip:
    """Build one clip from a dance at a tempo factor (no cache). ``audio``: the song at 22050 Hz."""
    import librosa

    if audio is None:
        audio = load_audio(dance.audio_path, SAMPLE_RATE)[0]
    if tempo != 1.0:
        audio = librosa.effects.time_stretch(audio, rate=tempo).astype(np.float32)
    feats = extract_features(audio, cfg)
    motion, valid, f0, f1 = clip_motion(dance, len(feats), tempo)
    poses = canonicalize(motion).to_vector()
    q = poses[:, 3:].reshape(len(poses), -1, 4)
    q *= np.where(q[..., 3:] < 0, -1.0, 1.0).astype(np.float32)  # canonical hemisphere w >= 0
    return Clip(dance.name, dance.style, float(tempo), feats[f0:f1].astype(np.float32), poses, valid, f0)


def _save(path: Path, clip: Clip) -> None:
    fd, tmp = tempfile.mkstemp(prefix=path.name, suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        with open(tmp, "wb") as fh:
            np.savez(fh, features=clip.features, poses=clip.poses, valid=clip.valid, style=clip.style, tempo=clip.tempo,
                     first_frame=clip.first_frame)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _load(path: Path, name: str) -> Clip | None:
    """A cached clip; ``first_frame`` is -1 for entries written before it was stored."""
    try:
        with np.load(path) as z:
            f0 = int(z["first_frame"]) if "first_frame" in z.files else -1
            return Clip(name, str(z["style"]), float(z["tempo"]), z["features"], z["poses"], z["valid"], f0)
    except Exception:  # a corrupt cache entry is rebuilt, never trusted
        return None


@contextlib.contextmanager
def _build_lock(path: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``path``'s sibling ``.lock`` file while one process builds it.

    Several processes (pytest-xdist workers, two training runs) may ask for the same clip on a
    fresh cache; the first builds it, the others wait and then load it instead of building it
    again. Where ``fcntl`` is missing (Windows) nobody waits: writes still replace whole files."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - POSIX here
        yield
        return
    with open(path.with_name(path.name + ".lock"), "a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def _cached_or_built(path: Path | None, dance: Dance, cfg: FeatureConfig, tempo: float,
                     audio: list[np.ndarray]) -> Clip:
    """The clip from the cache at ``path``, else built (and saved there); ``audio`` holds the
    song once loaded, shared between the tempo factors of one dance."""
    clip = _load(path, dance.name) if path and path.exists() else None
    if clip is None:
        if not audio:
            audio.append(load_audio(dance.audio_path, SAMPLE_RATE)[0])
        clip = make_clip(dance, cfg, tempo, audio[0])
        if path:
            _save(path, clip)
    return clip


def build_corpus(
    data_root: str | Path,
    names: list[str],
    cfg: FeatureConfig,
    tempos: tuple[float, ...] = (1.0,),
    cache_dir: str | Path | None = None,
    progress: bool = True,
) -> list[Clip]:
    """Clips for the named dances at every tempo factor, cached under ``cache_dir``."""
    from tqdm import tqdm

    cache = Path(cache_dir) if cache_dir else None
    if cache:
        cache.mkdir(parents=True, exist_ok=True)
    clips: list[Clip] = []
    bar = tqdm(total=len(names) * len(tempos), desc="corpus", unit="clip", disable=not progress)
    for name in names:
        dance = load_dance(Path(data_root) / name)
        audio: list[np.ndarray] = []
        for tempo in tempos:
            path = cache / _key(dance, cfg, tempo) if cache else None
            clip = _load(path, name) if path and path.exists() else None
            if clip is None:  # another process may be building it: wait for it, then load
                with _build_lock(path) if path else contextlib.nullcontext():
                    clip = _cached_or_built(path, dance, cfg, tempo, audio)
            if clip.first_frame < 0:  # older cache entry
                clip.first_frame = first_frame(dance, tempo)
            clips.append(clip)
            bar.update(1)
    bar.close()
    return clips


assert FPS == 30
