"""Offline generation: a whole audio file -> poses at 30 fps -> BVH or NPZ.

Each model kind runs the way it is meant to run (:func:`run_model`):

* ``causal``: :func:`models.networks.streaming.offline_windowed` (128-frame windows,
  64-frame hop, crossfaded), which equals what the real-time engine streams;
* offline U-Nets (``unet_gan``, ``unet_plain``) and the violinist model (``violin``,
  offline only, docs/violin.md): one full forward over the song, the
  features padded at the end to a multiple of 16 frames by repeating the last frame,
  the output cropped back;
* ``lstm``: one forward over the features padded at the end with ``output_delay``
  repeated frames; output frame ``t + delay`` is pose ``t``;
* ``dance_vq`` (the dancing performer, docs/training.md): :func:`models.networks.dance_stream.generate`,
  the live stream (:class:`models.networks.dance_stream.DanceStream`) run over the whole song
  with a seed (default 0) and a style (default: the music decides);
* ``gcn``: :meth:`models.networks.gcn.GCNDancer.generate_poses` on the whole song: its
  music classifier hears the raw audio (passed as ``audio``), seeded GP noise, one
  generator forward, cubic-spline smoothing (offline only, docs/gcn.md).

Pose ``t`` describes the instant feature frame ``t`` ends: audio time ``(t + 1) / 30`` s
(:func:`models.features.spectral.frame_time_s`). A file of ``n`` samples at 22050 Hz
gives ``n // 735`` poses. Any length of at least one frame (33 ms) is generated; the
first ~2 s (one window rise) of a causal model have seen less music.

Output quaternions are always unit and sign-continuous (:func:`models.networks.blend.blend_track`).
"""

from __future__ import annotations

import importlib.resources
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from models.errors import AudioError, CheckpointError, ConfigError, PerformerError
from models.timebase import FPS, HOP, SAMPLE_RATE

DEFAULT_CHECKPOINT = "default.pt"
#: Output suffixes :func:`export_motion` writes.
OUTPUT_SUFFIXES: tuple[str, ...] = (".bvh", ".npz")


def default_checkpoint_path() -> Path:
    """Path of the packaged default checkpoint ``models/assets/default.pt`` (may not exist yet)."""
    return Path(str(importlib.resources.files("models").joinpath("assets", DEFAULT_CHECKPOINT)))


def checkpoint_feature_config(meta: dict, path: str | Path):
    """The :class:`~models.features.spectral.FeatureConfig` a checkpoint was trained with.

    Raises :class:`CheckpointError` naming ``path`` if the stored config cannot be
    rebuilt or its stored fingerprint differs from what this code computes for it
    (the feature code changed since training).
    """
    from models.features.spectral import FeatureConfig

    raw = meta.get("feature_config") or {}
    if not isinstance(raw, dict):
        raise CheckpointError(f"feature_config must be a table of settings, got {type(raw).__name__}", source=path)
    d = dict(raw)
    stored = d.pop("fingerprint", None)
    try:
        cfg = FeatureConfig.from_dict(d)
    except PerformerError as exc:
        raise CheckpointError(f"cannot rebuild the checkpoint's feature configuration: {exc}", source=path) from None
    if stored is not None and stored != cfg.fingerprint():
        raise CheckpointError(
            f"checkpoint was trained on features {stored!r} but this code computes {cfg.fingerprint()!r} "
            "for the same configuration (feature code changed); retrain or use a matching version",
            source=path,
        )
    return cfg


@dataclass
class LoadedModel:
    """A checkpoint ready to generate: network (eval mode), metadata, feature config, file."""

    model: object  # torch.nn.Module
    meta: dict
    features: object  # FeatureConfig
    path: Path

    @property
    def name(self) -> str:
        return str(self.meta.get("model_name", "?"))


def load_model(checkpoint: str | Path | None = None) -> LoadedModel:
    """Load ``checkpoint`` (default: :func:`default_checkpoint_path`) for generation.

    Raises a one-line :class:`CheckpointError` naming the file if it is missing,
    truncated or corrupt, made for another rig, or trained on features this code no
    longer computes, or if its feature config does not fit the network's input.
    """
    from models.networks.checkpoint import load_checkpoint
    from models.rig.humanoid import BONES

    path = Path(checkpoint) if checkpoint is not None else default_checkpoint_path()
    if not path.is_file():
        hint = "" if checkpoint is not None else " (no default checkpoint is packaged yet; pass --checkpoint)"
        raise CheckpointError(f"checkpoint not found{hint}", source=path)
    try:
        net, meta = load_checkpoint(path, expect_bones=BONES)
    except CheckpointError as exc:  # one line: torch's messages can span several
        raise CheckpointError(str(exc).splitlines()[0].rstrip()) from None
    cfg = checkpoint_feature_config(meta, path)
    takes = getattr(net.config, "input_dim", net.config.feature_dim)  # dance_vq: + its gate column
    if takes != cfg.dim:
        raise CheckpointError(
            f"model takes {takes} features per frame but its feature config gives {cfg.dim}",
            source=path,
        )
    return LoadedModel(net, meta, cfg, path)


def _pad_end(x: np.ndarray, n: int) -> np.ndarray:
    """(T, D) -> (T + n, D) by repeating the last row n times."""
    return np.concatenate([x, np.repeat(x[-1:], n, axis=0)]) if n else x


def run_model(model, features: np.ndarray, window: int = 128, hop: int = 64, seed: int | None = None,
              audio: np.ndarray | None = None, style: str | None = None, energy: float = 1.0,
              lead: float = 0.0, stage=0, facing: str = "free") -> np.ndarray:
    """Poses ``(T, POSE_DIM)`` float32 for features ``(T, D)`` at 30 fps, one per frame.

    ``window``/``hop`` (frames) apply to causal U-Nets only (see the module docstring
    for how each model kind is run). A model with a ``generate(features)`` method
    (``dtm``) runs that; ``seed`` (default 0) is passed to stochastic ones
    (``model.stochastic``), so the same seed gives the same dance. Non-finite features
    become 0 and values are clipped, as on the live path. Quaternions come out unit
    and sign-continuous.

    ``audio``: the song (n,) at 22050 Hz with frame t ending at sample (t + 1) * HOP, for
    models that listen to the waveform themselves (``model.needs_audio``: ``gcn``'s
    music style classifier); they raise ConfigError without it.

    ``style``: for models that take one (``dance_vq``): None/"auto" (the music decides),
    "chacha", "rumba" or "waltz"; ConfigError for any other model given a style. ``energy``:
    the same models' energy control, 0..2 (1: as the music asks; ConfigError out of range, or
    other than 1 for any other model). ``lead``: the same models' lead, ms, 0..200 (the poses
    sent that far ahead of the audio for a display chain's delay; ConfigError out of range,
    or other than 0 for any other model). ``stage``, ``facing``: the same models' stage
    (``"WxD"`` metres, or 0: in place, facing +Z) and facing (free, audience;
    models/networks/stage.py); ConfigError for a bad value, or a stage other than 0 or
    facing other than free for any other model.
    """
    import torch

    from models.networks.blend import blend_track
    from models.networks.causal import CausalGenerator
    from models.networks.dance_vq import DanceVQ
    from models.networks.generator import LEVELS
    from models.networks.streaming import offline_windowed, sanitize_features

    x = np.asarray(features)
    if x.ndim != 2 or x.shape[0] < 1:
        raise ConfigError(f"features must have shape (frames >= 1, D), got {x.shape}")
    takes_style = getattr(model, "takes_style", False)
    if style not in (None, "auto") and not takes_style:
        raise ConfigError(f"model {type(model).__name__} takes no style; --style works with dance_vq models")
    if energy != 1.0 and not takes_style:
        raise ConfigError(f"model {type(model).__name__} has no energy control; --energy works with dance_vq models")
    if lead != 0.0 and not takes_style:
        raise ConfigError(f"model {type(model).__name__} has no lead control; --lead works with dance_vq models")
    from models.networks.stage import check_facing, parse_stage

    if (parse_stage(stage) != (0.0, 0.0) or check_facing(facing) != "free") and not takes_style:
        raise ConfigError(f"model {type(model).__name__} dances in place; --stage and --facing work with dance_vq models")
    if isinstance(model, CausalGenerator):
        return offline_windowed(model, x, window=window, hop=hop)
    x, _ = sanitize_features(x)
    if getattr(model, "needs_audio", False):  # gcn: style from the raw waveform, whole song at once
        return model.generate_poses(x, audio, seed=seed)
    if isinstance(model, DanceVQ):  # its live stream, every frame at once
        from models.networks.dance_stream import generate as stream_generate

        return stream_generate(model, x, seed=int(seed or 0), style=style, energy=energy, lead=lead, stage=stage,
                               facing=facing)
    if callable(getattr(model, "generate", None)):  # a whole-song procedure of its own (dtm)
        kw = {"seed": int(seed or 0)} if getattr(model, "stochastic", False) else {}
        return model.generate(x, **kw)
    t = len(x)
    delay = int(getattr(model, "output_delay", 0))
    mult = 1 if delay or getattr(model.config, "causal", False) else 2**LEVELS
    padded = _pad_end(x, delay + (-(t + delay)) % mult)
    model.eval()
    with torch.inference_mode():
        y = model(torch.from_numpy(np.ascontiguousarray(padded.T))[None])[0].T.numpy()
    out = np.ascontiguousarray(y[delay : delay + t], dtype=np.float32)
    return blend_track(out[None], np.ones((1, t)))


@dataclass
class Generation:
    """What :func:`generate` returns. Times in seconds of wall clock."""

    poses: np.ndarray  # (T, POSE_DIM) float32, frame t ends at audio time (t + 1) / 30 s
    audio_s: float  # duration of the audio file
    timings: dict[str, float] = field(default_factory=dict)  # decode, features, model, export

    @property
    def num_frames(self) -> int:
        return int(self.poses.shape[0])

    @property
    def compute_s(self) -> float:
        return float(sum(self.timings.values()))

    @property
    def realtime_factor(self) -> float:
        """Audio seconds per compute second (> 1: faster than real time)."""
        return self.audio_s / max(self.compute_s, 1e-9)


def frame_times(num_frames: int) -> np.ndarray:
    """Audio time (s) at which each pose's feature frame ends: ``(t + 1) * HOP / SAMPLE_RATE``."""
    return (np.arange(num_frames) + 1) * HOP / SAMPLE_RATE


def check_output_path(out: str | Path) -> Path:
    """``out`` if its suffix is one :func:`export_motion` writes (.bvh, .npz); else ConfigError."""
    out = Path(out)
    if out.suffix.lower() not in OUTPUT_SUFFIXES:
        raise ConfigError(
            f"unknown output format {out.suffix or '(no suffix)'!r}; use one of {', '.join(OUTPUT_SUFFIXES)}",
            source=out,
        )
    if not out.parent.is_dir():
        raise ConfigError("output directory does not exist", source=out.parent)
    return out


def export_motion(poses: np.ndarray, out: str | Path, **extra: object) -> Path:
    """Write poses ``(T, POSE_DIM)`` as BVH (default skeleton) or NPZ by ``out``'s suffix.

    The NPZ (:func:`models.rig.npz.save_npz`) also holds ``index`` (T,), ``audio_time``
    (T,) seconds (:func:`frame_times`), ``pose`` (T, POSE_DIM) and ``extra``.
    """
    from models.rig.bvh import write_bvh
    from models.rig.motion import Motion
    from models.rig.npz import save_npz

    out = check_output_path(out)
    motion = Motion.from_vector(poses, fps=FPS)
    if out.suffix.lower() == ".bvh":
        write_bvh(out, motion)
    else:
        t = motion.num_frames
        save_npz(out, motion, index=np.arange(t), audio_time=frame_times(t), pose=np.asarray(poses, np.float32), **extra)
    return out


def generate(
    audio_path: str | Path,
    out: str | Path,
    loaded: LoadedModel,
    window: int = 128,
    hop: int = 64,
    seed: int | None = None,
    style: str | None = None,
    energy: float = 1.0,
    lead: float = 0.0,
    stage=0,
    facing: str = "free",
) -> Generation:
    """Generate motion for a whole audio file with a loaded model and write it to ``out``
    (``seed``, ``style``, ``energy``, ``lead``, ``stage``, ``facing``: as :func:`run_model` takes them).

    Raises :class:`AudioError` naming the file if it cannot be read, holds NaN/inf
    samples, or is shorter than one frame (735 samples at 22050 Hz, 33 ms);
    :class:`ConfigError` for an output suffix other than .bvh/.npz.
    """
    from models.features.audio_io import load_audio
    from models.features.spectral import extract_features

    out = check_output_path(out)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    audio, _ = load_audio(audio_path, SAMPLE_RATE)
    timings["decode"] = time.perf_counter() - t0
    if len(audio) < HOP:
        raise AudioError(
            f"audio is {len(audio) / SAMPLE_RATE * 1000:.1f} ms long; generation needs at least one "
            f"{HOP / SAMPLE_RATE * 1000:.1f} ms frame",
            source=audio_path,
        )
    t0 = time.perf_counter()
    feats = extract_features(audio, loaded.features)
    timings["features"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    poses = run_model(loaded.model, feats, window=window, hop=hop, audio=audio, seed=seed, style=style,
                      energy=energy, lead=lead, stage=stage, facing=facing)
    timings["model"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    export_motion(poses, out, source_audio=str(audio_path), checkpoint=str(loaded.path), model_name=loaded.name)
    timings["export"] = time.perf_counter() - t0
    return Generation(poses, len(audio) / SAMPLE_RATE, timings)


def load_library_model(model, path: str | Path, mix: bool = False, chooser: str = "codes"):
    """A copy of the dance_vq ``model`` dancing the motion library file ``path``
    (:func:`models.data.library.load_library`; ``mix``: with the model's own exemplars;
    :func:`models.networks.library_player.library_model`), with the tempi given at build time
    (``--bpm``) where there are any; it keeps the file's path as ``library_path``. ``chooser``:
    "codes" (the predictor) or "match" (music descriptors, docs/library.md; a comparison)."""
    from models.data.library import clip_tracks, load_library
    from models.networks.library_player import library_model

    clips = load_library(path)
    folders, bpm = [c.folder for c in clips], [c.bpm for c in clips]
    poses, travel = [], []
    while clips:  # each clip's motion let go once its tracks are out: the build's peak is what it holds then
        p, t = clip_tracks(clips.pop(0).motion)
        poses.append(p)
        travel.append(t)
    _release_freed()
    out = library_model(model, poses, travel, folders, mix=mix, bpm=bpm, chooser=chooser)
    out.library_path = Path(path)
    del poses, travel
    _release_freed()
    return out


def _release_freed() -> None:
    """Hand the heap pages freed by a start-up step back to the system (glibc's ``malloc_trim``;
    nothing elsewhere). A 30-minute library's build freed ~80 MB of clips, window codes and
    distances that the allocator kept, which the stream's start-up then stacked its own peak on."""
    import ctypes
    import ctypes.util

    try:
        ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass


def with_library(loaded: LoadedModel, library: str | Path | None, mix: bool = False) -> LoadedModel:
    """``loaded`` with its model's memory replaced by the library file ``library`` (or mixed with
    it: ``mix``), as ``performer run|generate --library`` load it; None: ``loaded`` as it is.
    ConfigError for ``mix`` without a library or a model that is not dance_vq."""
    import dataclasses

    if library is None:
        if mix:
            raise ConfigError("--mix plays the checkpoint's dancers together with a library: give --library FILE.npz")
        return loaded
    if not getattr(loaded.model, "takes_style", False):
        raise ConfigError(f"--library needs a dance_vq model; {loaded.path} is a {loaded.name!r} model")
    return dataclasses.replace(loaded, model=load_library_model(loaded.model, library, mix=mix))
