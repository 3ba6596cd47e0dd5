"""Evaluation driver: generate motion for every validation dance and score it.

For each checkpoint, every dance of the split is generated from its tempo-1 corpus
clip (:mod:`models.data.corpus`: features and canonical target poses on one
30 fps grid) the way the model runs (:func:`models.generate.run_model`). Generated
and real poses go through forward kinematics on the default skeleton
(:func:`models.rig.kinematics.fk`: 21 bone heads + 9 end sites, metres) and are
scored with :mod:`models.evaluation`:

* per-sequence metrics (:func:`~models.evaluation.metrics.sequence_metrics`: rotation
  and position L1, hand L1, DTW, LCSS, PCK@0.1/0.2, direction-change F1 and cosine of
  the hands) on consecutive segments of about ``segment`` frames (default 300 = 10 s),
  averaged weighted by segment length, so DTW/LCSS compare 10 s excerpts rather
  than warping whole songs;
* beat coverage / hit rate (:func:`~models.evaluation.beats.beat_scores`) against
  music beats of the clip's own audio span, pooled over dances;
* energy ratio, jerk, and the dance-scale amplitude (0.25-3 Hz) and jitter (above
  6 Hz) band ratios (:func:`~models.evaluation.metrics.band_ratios`) pooled over dances;
* Fréchet distance and diversity in the feature space of a style classifier
  trained on the TRAIN split's real motion (cached, trained once).

A reference row ``real data`` scores the real validation motion against itself
(identity values for the paired metrics; beats, jerk and diversity of real motion;
energy ratio and band ratios 1; FD of real validation vs real training windows).

Frame alignment: clip frame ``t`` ends at audio time ``(first_frame + t + 1) / 30`` s,
so the clip's audio is samples ``[(first_frame + 1) * HOP, (first_frame + T + 1) * HOP)``
and a music beat at ``tau`` seconds into that span is clip frame ``round(30 * tau)``.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from models.errors import DataError
from models.evaluation.classifier import classifier_windows
from models.timebase import FPS, HOP, SAMPLE_RATE

#: Frames per segment of the per-sequence metrics (10 s at 30 fps).
SEGMENT: int = 300
#: Joints (FK points) whose trajectories the hand metrics use: the wrists.
HANDS: tuple[str, ...] = ("LeftHand", "RightHand")
REAL_ROW = "real data"
SPLITS = ("val", "train")
#: Metric keys every row of :func:`evaluate` holds.
ROW_KEYS: tuple[str, ...] = (
    "rot_l1", "pos_l1", "hand_l1", "dtw", "lcss", "pck@0.1", "pck@0.2", "dir_f1", "cosine",
    "beat_coverage", "beat_hit_rate", "beat_hit_chance", "fd", "diversity", "energy_ratio", "jerk",
    "band_amp", "jitter",
)


@dataclass
class EvalOptions:
    """Knobs of :func:`evaluate`.

    split: "val" (default) or "train": which dances are generated and scored.
    cache_dir: corpus and classifier cache (None: no cache).
    dances_per_style: use at most this many dances per style in each split (None: all).
    max_frames: keep only the first frames of every clip (None: whole clips).
    window, hop: causal models' streaming windows, frames.
    segment: frames per segment of the per-sequence metrics.
    """

    split: str = "val"
    cache_dir: str | Path | None = ".cache/corpus"
    classifier_epochs: int = 10
    dances_per_style: int | None = None
    max_frames: int | None = None
    window: int = 128
    hop: int = 64
    segment: int = SEGMENT
    seed: int = 0
    multimodality_samples: int = 5  # generations per dance behind "multimodality" (stochastic models; < 2: off)
    progress: bool = True
    gan_scores: bool = False  # add GAN-train / GAN-test (models.evaluation.gan_scores); generates the train split too


@dataclass
class RealSet:
    """Real motion of a set of dances: clips (tempo 1), FK positions, music beat frames."""

    clips: list
    positions: list[np.ndarray]
    beats: list[np.ndarray]


# --------------------------------------------------------------------------- data


def _limit(names: list[str], per_style: int | None) -> list[str]:
    """At most ``per_style`` names per style (DANCE_<S>_<id>), in the given order."""
    if per_style is None:
        return list(names)
    kept: dict[str, int] = {}
    out = []
    for n in names:
        style = n.split("_")[1]
        if kept.get(style, 0) < per_style:
            kept[style] = kept.get(style, 0) + 1
            out.append(n)
    return out


def split_dances(data_root: str | Path, opts: EvalOptions) -> tuple[list[str], list[str]]:
    """(classifier training dances, evaluated dances) under ``data_root`` for ``opts.split``."""
    from models.data.dwm import dance_dirs
    from models.data.split import split_names

    if opts.split not in SPLITS:
        raise DataError(f"unknown split {opts.split!r}; choose one of {SPLITS}", source="--split")
    names = [d.name for d in dance_dirs(data_root)]
    train, val = split_names(names)
    train, val = _limit(train, opts.dances_per_style), _limit(val, opts.dances_per_style)
    return train, (val if opts.split == "val" else train)


def validation_names(data_root: str | Path, songs: list[str] | None, opts: EvalOptions) -> list[str]:
    """The evaluated dances of :func:`split_dances`, only ``songs`` of them when given (in the
    split's order); DataError naming any of ``songs`` that is not one of them."""
    _, names = split_dances(data_root, opts)
    if songs:
        missing = sorted(set(songs) - set(names))
        if missing:
            raise DataError(f"not validation dances: {', '.join(missing)} (they are: {', '.join(names)})",
                            source=str(data_root))
        names = [n for n in names if n in songs]
    return names


def load_clips(data_root: str | Path, names: list[str], feature_config, opts: EvalOptions) -> list:
    """Tempo-1 corpus clips of ``names``, cut to ``opts.max_frames``."""
    from models.data.corpus import build_corpus

    clips = build_corpus(data_root, names, feature_config, (1.0,), opts.cache_dir, opts.progress)
    if opts.max_frames is not None:
        m = int(opts.max_frames)
        for c in clips:
            c.features, c.poses, c.valid = c.features[:m], c.poses[:m], c.valid[:m]
    return clips


def positions(poses: np.ndarray) -> np.ndarray:
    """FK positions ``(T, 30, 3)`` m (bone heads then end sites) of flat poses ``(T, POSE_DIM)``."""
    from models.rig.kinematics import fk
    from models.rig.motion import Motion
    from models.rig.skeleton import load_default_skeleton

    return fk(Motion.from_vector(poses), load_default_skeleton())


def span_beats(audio: np.ndarray, first_frame: int, num_frames: int) -> np.ndarray:
    """Music beats of a clip, in clip frames: ``audio`` is the whole song (n,) at 22050 Hz.

    Clip frame ``t`` is song frame ``first_frame + t`` and ends at ``(first_frame + t + 1) / 30``
    s, so the clip's span starts at sample ``(first_frame + 1) * HOP`` and a beat
    ``tau`` seconds into it is clip frame ``round(30 * tau)``.
    """
    from models.evaluation.beats import music_beats

    lo = (int(first_frame) + 1) * HOP
    return music_beats(audio[lo : lo + int(num_frames) * HOP], SAMPLE_RATE, FPS)


def clip_music_beats(data_root: str | Path, clip) -> np.ndarray:
    """:func:`span_beats` of a corpus clip, from its dance's audio file."""
    from models.data.dwm import load_dance
    from models.features.audio_io import load_audio

    audio, _ = load_audio(load_dance(Path(data_root) / clip.name).audio_path, SAMPLE_RATE)
    return span_beats(audio, clip.first_frame, clip.num_frames)


def clip_audio(data_root: str | Path, clip) -> np.ndarray:
    """The song of a corpus clip at 22050 Hz from the clip's first frame on: clip frame ``t``
    ends at sample ``(t + 1) * HOP`` (for models that listen to the waveform, ``needs_audio``)."""
    from models.data.dwm import load_dance
    from models.features.audio_io import load_audio

    audio, _ = load_audio(load_dance(Path(data_root) / clip.name).audio_path, SAMPLE_RATE)
    return audio[max(int(clip.first_frame), 0) * HOP :]


def _audio_kw(model, data_root: str | Path, clip) -> dict:
    return {"audio": clip_audio(data_root, clip)} if getattr(model, "needs_audio", False) else {}


def real_set(data_root: str | Path, clips: list, with_beats: bool = True, progress: bool = True) -> RealSet:
    """FK positions and (``with_beats``) music beats of real clips."""
    from tqdm import tqdm

    pos, beats = [], []
    for c in tqdm(clips, desc="real motion", unit="dance", disable=not progress):
        pos.append(positions(c.poses))
        if with_beats:
            beats.append(clip_music_beats(data_root, c))
    return RealSet(clips, pos, beats)


# --------------------------------------------------------------------------- classifier


def classifier_cache_key(x: np.ndarray, y: np.ndarray, epochs: int, seed: int, styles: Sequence[str]) -> str:
    """12 hex digits of sha1 over everything a trained style classifier depends on.

    Its training windows ``x`` (N, 64, C) float32 and labels ``y`` (N,) byte for byte (so
    the dances, their corpus poses, the FK and the numpy/scipy that computed them), the
    epochs, seed and class names, the classifier's code (the bytes of
    ``models/evaluation/classifier.py``: architecture and training loop), the torch version,
    the CPU (:func:`cpu_kernels`) and the training thread count
    (:data:`~models.evaluation.classifier.TRAIN_THREADS`): the weights depend on each of
    them, and FD, diversity and GAN-test with the weights.
    """
    import torch

    from models.evaluation import classifier as clf

    h = hashlib.sha1()
    h.update(np.ascontiguousarray(x, dtype=np.float32).tobytes())
    h.update(np.ascontiguousarray(y, dtype=np.int64).tobytes())
    h.update(Path(clf.__file__).read_bytes())
    h.update(json.dumps([list(x.shape), int(epochs), int(seed), list(styles), torch.__version__,
                         cpu_kernels(), clf.TRAIN_THREADS]).encode())
    return h.hexdigest()[:12]


def cpu_kernels() -> list[str]:
    """What picks torch's float kernels on this machine: ATen's CPU capability, the CPU's feature
    flags (Linux ``/proc/cpuinfo``; oneDNN trains other weights on an AVX2 CPU than on an AVX-512
    one, measured with ``ONEDNN_MAX_CPU_ISA=AVX2``) and the variables that cap them."""
    import os
    import platform

    import torch

    flags = platform.processor()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            flags = next((line.split(":", 1)[1].strip() for line in f if line.startswith("flags")), flags)
    except OSError:
        pass
    return [torch.backends.cpu.get_cpu_capability(), flags,
            *(f"{v}={os.environ.get(v, '')}" for v in ("ONEDNN_MAX_CPU_ISA", "ATEN_CPU_CAPABILITY", "MKL_CBWR"))]


#: The packaged style classifier: the judge behind FD, diversity, GAN-test and the style
#: benchmarks, trained once on the training split's real motion (10 epochs, seed 0) and
#: shipped like FID's fixed network, because one trained afresh differs from machine to
#: machine (the oneDNN kernels of AVX2 and AVX-512 CPUs, the thread count give other
#: weights) and FD with it (8.0 to 16.0 for the default, real 4.4 to 5.2). Rewrite it only
#: on purpose: ``python -m models.evaluation.evaluate --write-classifier --data DWM``, then
#: ``python tests/test_eval_reference.py headline --data DWM --write`` and the docs' FD figures.
PACKAGED_CLASSIFIER = Path(__file__).resolve().parents[1] / "assets" / "style_classifier.pt"


def packaged_classifier(dances: Sequence[str], epochs: int, seed: int, path: Path = PACKAGED_CLASSIFIER):
    """The classifier at ``path`` if it was trained on exactly ``dances`` with ``epochs`` and ``seed``, else None."""
    from models.evaluation.classifier import load_classifier

    if not path.is_file():
        return None
    model = load_classifier(path)
    meta = model.trained_on or {}
    if meta.get("dances") != list(dances) or meta.get("epochs") != epochs or meta.get("seed") != seed:
        return None
    model.cache_key = f"packaged:{meta.get('key')}"
    return model


def style_classifier(train: RealSet, epochs: int, seed: int, cache_dir: str | Path | None, packaged: bool = True):
    """Style classifier trained on real training motion.

    The packaged one (:data:`PACKAGED_CLASSIFIER`) when it was trained on these dances with
    these epochs and seed and ``packaged`` is set (the default evaluation: the same judge on
    every machine); otherwise trained and cached under ``cache_dir`` as
    ``style-classifier-<key>.pt`` with the key of :func:`classifier_cache_key`, so a classifier
    trained on other motion, by other code, torch or CPU kernels is never reused. The key
    (``packaged:<key>`` for the packaged one) is the model's ``cache_key``.
    """
    from models.evaluation.classifier import load_classifier, save_classifier, train_style_classifier

    if packaged and (model := packaged_classifier([c.name for c in train.clips], epochs, seed)) is not None:
        return model
    styles = sorted({c.style for c in train.clips})
    if len(styles) < 2:
        raise DataError(f"the style classifier needs at least 2 styles in the training dances, got {styles}")
    xs, ys = [], []
    for c, p in zip(train.clips, train.positions):
        w = classifier_windows([p])
        xs.append(w)
        ys.append(np.full(len(w), styles.index(c.style)))
    x, y = np.concatenate(xs), np.concatenate(ys)
    if len(x) == 0:
        raise DataError("training clips are shorter than one classifier window (64 frames)")
    key = classifier_cache_key(x, y, epochs, seed, styles)
    path = Path(cache_dir) / f"style-classifier-{key}.pt" if cache_dir else None
    if path is not None and path.is_file():
        model = load_classifier(path)
    else:
        model = train_style_classifier(x, y, epochs=epochs, seed=seed, class_names=styles)
        model.trained_on = {"dances": [c.name for c in train.clips], "epochs": epochs, "seed": seed, "key": key}
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=path.name, suffix=".tmp", dir=path.parent)  # one per writer:
            os.close(fd)  # two processes training the same classifier at once each replace whole files
            try:
                save_classifier(model, tmp, model.trained_on)
                os.replace(tmp, path)
            finally:
                Path(tmp).unlink(missing_ok=True)
    model.cache_key = key
    return model


def write_packaged_classifier(data_root: str | Path, out: Path = PACKAGED_CLASSIFIER, cache_dir: str | Path | None = ".cache/corpus",
                              log=print) -> None:
    """Train the default evaluation's classifier afresh (training split, 10 epochs, seed 0) and write it to ``out``."""
    from models.evaluation.classifier import save_classifier
    from models.generate import load_model

    opts = EvalOptions(cache_dir=cache_dir, progress=False)
    train_names, _ = split_dances(data_root, opts)
    train = real_set(data_root, load_clips(data_root, train_names, load_model().features, opts), False, False)
    model = style_classifier(train, opts.classifier_epochs, opts.seed, None, packaged=False)
    save_classifier(model, out, model.trained_on)
    log(f"wrote {out} (key {model.cache_key}, {len(train_names)} training dances)")


# --------------------------------------------------------------------------- metrics


def segments(num_frames: int, segment: int) -> list[slice]:
    """Consecutive slices of nearly equal length, about ``segment`` frames each (at least one)."""
    n = max(1, round(num_frames / segment))
    edges = np.linspace(0, num_frames, n + 1).round().astype(int)
    return [slice(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]


def paired_metrics(pos_gen: np.ndarray, pos_ref: np.ndarray, quat_gen: np.ndarray, quat_ref: np.ndarray,
                   segment: int = SEGMENT) -> dict[str, float]:
    """:func:`~models.evaluation.metrics.sequence_metrics` averaged over segments, weighted by length.

    ``pos_*`` (T, 30, 3) m, ``quat_*`` (T, 21, 4); jerk is left out (set-level).
    """
    from models.evaluation.metrics import sequence_metrics
    from models.rig.skeleton import POINT_INDEX

    hands = [POINT_INDEX[h] for h in HANDS]
    total: dict[str, float] = {}
    for s in segments(len(pos_gen), segment):
        m = sequence_metrics(pos_gen[s], pos_ref[s], hands, quat_gen[s], quat_ref[s])
        m.pop("jerk")
        w = s.stop - s.start
        for k, v in m.items():
            total[k] = total.get(k, 0.0) + w * v
    return {k: v / len(pos_gen) for k, v in total.items()}


def pooled_beats(pos: Sequence[np.ndarray], beats: Sequence[np.ndarray]) -> dict[str, float]:
    """Beat coverage and hit rate pooled over sequences (:func:`~models.evaluation.beats.beat_scores`).

    coverage = all kinematic beats / all music beats; hit rate = share of all kinematic
    beats near a music beat; chance = frame-weighted mean of the per-sequence chance.
    """
    from models.evaluation.beats import beat_scores

    kin = mus = hits = chance = frames = 0.0
    for p, b in zip(pos, beats):
        s = beat_scores(p, b)
        kin += s["kinematic_beats"]
        mus += s["music_beats"]
        hits += s["beat_hit_rate"] * s["kinematic_beats"]
        chance += s["beat_hit_chance"] * len(p)
        frames += len(p)
    if mus == 0:
        raise DataError("no music beats in the evaluated audio: beat coverage is undefined")
    return {
        "beat_coverage": kin / mus,
        "beat_hit_rate": hits / kin if kin else 0.0,
        "beat_hit_chance": chance / frames,
    }


def score(gen_pos: list[np.ndarray], gen_poses: list[np.ndarray], real: RealSet, real_emb: np.ndarray,
          classifier, segment: int = SEGMENT, desc: str | None = None) -> tuple[dict[str, float], dict[str, dict[str, float]]]:
    """One row: metrics of generated sequences against the real ones (same order).

    Returns (row, per-dance metrics: the paired ones plus each dance's own ``band_amp``
    and ``jitter``). The row's ``band_amp``/``jitter`` pool power over all dances
    (:func:`~models.evaluation.metrics.band_ratios`); the band RMS values in metres
    are left to :func:`band_rms_m`. ``desc``: show a progress bar with this label.
    """
    from tqdm import tqdm

    from models.evaluation.metrics import band_ratios

    per_dance: dict[str, dict[str, float]] = {}
    weighted: dict[str, float] = {}
    frames = 0
    pairs = zip(real.clips, gen_pos, gen_poses, real.positions)
    for c, pg, qg, pr in tqdm(pairs, desc=desc, total=len(gen_pos), unit="dance", disable=desc is None):
        t = len(pg)
        m = paired_metrics(pg, pr, _quats(qg), _quats(c.poses), segment)
        for k, v in m.items():
            weighted[k] = weighted.get(k, 0.0) + t * v
        frames += t
        bands = band_ratios(pg, pr)
        per_dance[c.name] = {**m, "band_amp": bands["band_amp"], "jitter": bands["jitter"]}
    row = {k: v / frames for k, v in weighted.items()}
    row.update(set_metrics(gen_pos, real, real_emb, classifier))
    return row, per_dance


def set_metrics(gen_pos: list[np.ndarray], real: RealSet, real_emb: np.ndarray, classifier) -> dict[str, float]:
    """The row's set-level metrics of generated FK positions ``(T, 30, 3)`` m (same dance order as
    ``real``): beat coverage, hit rate and chance, FD against ``real_emb``, diversity, energy
    ratio, jerk (m/s³) and the band ratios ``band_amp`` and ``jitter``."""
    from models.evaluation.classifier import embed
    from models.evaluation.metrics import band_ratios, diversity, energy_ratio, frechet_distance, jerk

    emb = embed(classifier, _windows_or_fail(gen_pos))
    bands = band_ratios(gen_pos, real.positions)
    return {
        **pooled_beats(gen_pos, real.beats),
        "fd": frechet_distance(emb, real_emb),
        "diversity": diversity(emb),
        "energy_ratio": energy_ratio(gen_pos, real.positions),
        "jerk": jerk(gen_pos),
        "band_amp": bands["band_amp"],
        "jitter": bands["jitter"],
    }


def band_rms_m(pos: Sequence[np.ndarray]) -> dict[str, float]:
    """``{"band_amp": m, "jitter": m}``: :func:`~models.evaluation.metrics.band_rms` of FK
    positions ``(T, 30, 3)`` m at 30 fps in the dance band (0.25-3 Hz) and the jitter
    band (6 Hz and up), power pooled over the sequences."""
    from models.evaluation.metrics import DANCE_BAND, JITTER_BAND, band_rms

    return {"band_amp": band_rms(pos, DANCE_BAND), "jitter": band_rms(pos, JITTER_BAND)}


def _quats(poses: np.ndarray) -> np.ndarray:
    return np.asarray(poses)[:, 3:].reshape(len(poses), -1, 4)


def _windows_or_fail(pos: Sequence[np.ndarray]) -> np.ndarray:
    w = classifier_windows(pos)
    if len(w) < 2:
        raise DataError(f"only {len(w)} classifier windows of 64 frames: the clips are too short (raise --max-frames)")
    return w


def model_multimodality(lm, clips: list, data_root: str | Path, classifier, opts: EvalOptions) -> float | None:
    """Multimodality (Lee et al., NeurIPS 2019) of a loaded model on ``clips``, or None (n/a).

    Only for stochastic models (``model.stochastic``, a seedable generation): each
    dance is generated ``opts.multimodality_samples`` times with seeds ``opts.seed + 1``,
    ``+ 2``, ..., every generation becomes the mean style-classifier feature of its
    64-frame windows, and :func:`~models.evaluation.metrics.multimodality` averages
    their pairwise distances over the dances. Deterministic models give the same
    dance every time: None, shown as n/a.
    """
    import torch
    from tqdm import tqdm

    from models.evaluation.classifier import embed
    from models.evaluation.metrics import multimodality
    from models.generate import run_model

    k = int(opts.multimodality_samples)
    if not getattr(lm.model, "stochastic", False) or k < 2:
        return None
    groups = []
    for c in tqdm(clips, desc=f"multimodality {lm.path.name}", unit="dance", disable=not opts.progress):
        gens = []
        for i in range(1, k + 1):
            with torch.no_grad():
                p = run_model(lm.model, c.features, opts.window, opts.hop, seed=opts.seed + i,
                              **_audio_kw(lm.model, data_root, c))
            gens.append(embed(classifier, _windows_or_fail([positions(p)])).mean(axis=0))
        groups.append(np.stack(gens))
    return multimodality(groups)


# --------------------------------------------------------------------------- driver


def _row_name(path: Path, model_name: str, taken: set[str]) -> str:
    name = f"{model_name} ({path.name})"
    if name in taken:
        name = f"{model_name} ({path})"
    return name


def evaluate(checkpoints: Sequence[str | Path], data_root: str | Path, opts: EvalOptions | None = None,
             log=print) -> tuple[dict[str, dict[str, float]], dict[str, dict]]:
    """Score each checkpoint on ``opts.split`` of the DWM dataset at ``data_root``.

    Returns ``(results, details)``: ``results`` maps a row name (one per checkpoint,
    then :data:`REAL_ROW`) to its :data:`ROW_KEYS` metrics; ``details`` maps each row to
    its per-dance metrics and run information. ``log`` receives progress notes.
    """
    import torch
    from tqdm import tqdm

    from models.evaluation.classifier import embed
    from models.evaluation.metrics import frechet_distance
    from models.generate import load_model, run_model

    opts = opts or EvalOptions()
    if not checkpoints:
        raise DataError("no checkpoint to evaluate", source="--checkpoint")
    loaded = [load_model(c) for c in checkpoints]  # fail fast on a bad checkpoint
    train_names, eval_names = split_dances(data_root, opts)
    log(f"{len(eval_names)} {opts.split} dances: {', '.join(eval_names)}")

    fcfg0 = loaded[0].features
    real = real_set(data_root, load_clips(data_root, eval_names, fcfg0, opts), progress=opts.progress)
    train = real
    if opts.split != "train":
        train = real_set(data_root, load_clips(data_root, train_names, fcfg0, opts), False, opts.progress)
    classifier = style_classifier(train, opts.classifier_epochs, opts.seed, opts.cache_dir)
    real_emb = embed(classifier, _windows_or_fail(real.positions))
    train_emb = embed(classifier, _windows_or_fail(train.positions))

    results: dict[str, dict[str, float]] = {}
    details: dict[str, dict] = {}
    for lm in loaded:
        val_dances = set(lm.meta.get("extra", {}).get("val_dances") or [])
        leaked = [n for n in eval_names if val_dances and n not in val_dances]
        if leaked and opts.split == "val":
            log(f"warning: {lm.path} was validated on other dances; {', '.join(leaked)} may be in its training set")
        clips = real.clips
        if lm.features.fingerprint() != fcfg0.fingerprint():
            clips = load_clips(data_root, eval_names, lm.features, opts)
        gen_poses, gen_pos = [], []
        for c in tqdm(clips, desc=f"generate {lm.path.name}", unit="dance", disable=not opts.progress):
            with torch.no_grad():
                p = run_model(lm.model, c.features, opts.window, opts.hop, **_audio_kw(lm.model, data_root, c))
            gen_poses.append(p)
            gen_pos.append(positions(p))
        row, per_dance = score(gen_pos, gen_poses, real, real_emb, classifier, opts.segment,
                               f"score {lm.path.name}" if opts.progress else None)
        row["multimodality"] = model_multimodality(lm, clips, data_root, classifier, opts)
        if opts.gan_scores:
            from models.evaluation.gan_scores import gan_scores

            def generate_train(lm=lm) -> list[np.ndarray]:
                tclips = train.clips if lm.features.fingerprint() == fcfg0.fingerprint() else \
                    load_clips(data_root, [c.name for c in train.clips], lm.features, opts)
                with torch.no_grad():
                    return [positions(run_model(lm.model, c.features, opts.window, opts.hop,
                                                **_audio_kw(lm.model, data_root, c)))
                            for c in tqdm(tclips, desc=f"GAN-train {lm.path.name}", unit="dance",
                                          disable=not opts.progress)]

            row.update(gan_scores(generate_train, [c.style for c in train.clips], gen_pos, real, classifier,
                                  opts.classifier_epochs, opts.seed))
        name = _row_name(lm.path, lm.name, set(results))
        results[name] = row
        details[name] = {"checkpoint": str(lm.path), "model_name": lm.name, "per_dance": per_dance,
                         "band_rms_m": band_rms_m(gen_pos)}

    row, per_dance = score(real.positions, [c.poses for c in real.clips], real, real_emb, classifier, opts.segment,
                           "score real data" if opts.progress else None)
    row["fd"] = frechet_distance(real_emb, train_emb)
    row["multimodality"] = None  # n/a: one real dance per song
    if opts.gan_scores:
        from models.evaluation.gan_scores import real_reference

        row.update(real_reference(real, classifier))
    results[REAL_ROW] = row
    details[REAL_ROW] = {"per_dance": per_dance, "fd_against": "real training-split windows",
                         "band_rms_m": band_rms_m(real.positions)}
    details["_run"] = {
        "options": {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(opts).items()},
        "dances": eval_names,
        "frames": [c.num_frames for c in real.clips],
        "classifier_train_dances": [c.name for c in train.clips],
        "classifier_key": classifier.cache_key,
    }
    return results, details


def run_evaluation(checkpoints: Sequence[str | Path], data_root: str | Path, out_dir: str | Path,
                   command: str, opts: EvalOptions | None = None, log=print) -> dict[str, Path]:
    """:func:`evaluate`, then write results.json / results.md / results.png and per_dance.json to ``out_dir``."""
    from models.evaluation.report import markdown_table, write_report

    opts = opts or EvalOptions()
    results, details = evaluate(checkpoints, data_root, opts, log)
    n = len(details["_run"]["dances"])
    frames = sum(details["_run"]["frames"])
    title = f"Evaluation on the {opts.split} split ({n} dances, {frames} frames at 30 fps)"
    paths = write_report(results, out_dir, title, [command])
    paths["per_dance"] = Path(out_dir) / "per_dance.json"
    paths["per_dance"].write_text(json.dumps(details, indent=1) + "\n", encoding="utf-8")
    log(title)
    log(markdown_table(results))
    return paths


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description="Rewrite the packaged style classifier (PACKAGED_CLASSIFIER).")
    parser.add_argument("--write-classifier", action="store_true", required=True, help="train it afresh and write it")
    parser.add_argument("--data", required=True, help="the DWM dataset directory")
    parser.add_argument("--cache", default=".cache/corpus", help="corpus cache (default .cache/corpus)")
    a = parser.parse_args()
    write_packaged_classifier(a.data, cache_dir=a.cache)
