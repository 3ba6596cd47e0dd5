"""A user's motion library (docs/library.md) danced live like the default (issue 40, items 2-3).

The default's codebook encoder reads motion only, and its code predictor (trained on music
and motion together) picks a code every ``seg`` frames. :func:`library_model` gives a copy of
a ``dance_vq`` model a new choreographic memory made of the library's own windows:

1. every clip is put in place facing +Z (:func:`models.data.canonical.canonicalize`, as the
   training motion is) and cut into ``2 seg``-frame windows every :data:`WINDOW_STRIDE` frames;
   the model's encoder codes each window's first ``seg`` frames with its codebook;
2. per code and per folder (a folder is a style) up to :data:`LIBRARY_MEMBERS` windows are kept:
   those the encoder assigned to that code, nearest its vector first, then, where the folder
   has fewer, the folder's windows nearest the code vector (every code of every folder plays
   the user's motion); windows of one clip closer than ``seg`` frames are not kept twice;
3. each window's tempo is its clip's: a beats-per-minute value given at build time
   (``performer library build --bpm``), else the clip's kinematic tempo
   (:func:`kinematic_period`: the autocorrelation of its mean joint speed), so the tempo
   following, the speed caps and the beat warp of :class:`~models.networks.dance_stream.DanceStream`
   work as for the default; its travel and turns come from the clip's own root
   (``member_travel``, the stage's format: models/training/travel_memory.py);
4. the style prior of a folder is how much likelier each code is among its windows than
   among the other folders' (``models.training.dance_vq.prior_from_counts``' formula).

How its stream chooses (:func:`member_choice`, read by DanceStream; the attributes ``code_draws``,
``handover_guard``, ``exemplar_tilt``, ``idle_base`` on the model): where the drawn code's exemplars
would all bend the motion past :data:`HANDOVER_GUARD`, the next drawn code's join the matching (up
to :data:`LIBRARY_DRAWS`), then the :data:`NEAREST` exemplars of any code; above the memory's
tempo the tempo's tilt also favours livelier exemplars (:data:`EXEMPLAR_TILT`); the idle between
songs is the clips' own mean pose (:func:`_mean_pose`), not the default dancers'; under ``auto`` a
library of two or more folders plays one at a time, the one the music chooses (library_folders.py).
With ``mix`` the stream chooses as the default's does (the guard kept it in the dancers it began with).

Style tokens: 1..3 are the default's dancers (cha-cha, rumba, waltz), :data:`STYLE_BASE` + i
the library's i-th folder. The predictor hears a library style as "auto" (it knows only its
three); the stream plays that folder's exemplars and adds its prior (:func:`resolve_style`).

``mix=True`` keeps the default's exemplars in front of the library's (together: the music and
the motion matching choose among both; ``--style waltz`` or ``--style FOLDER`` picks one).
The checkpoint file is never changed: the library model lives in memory only.
"""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import torch

from models.errors import ConfigError, DataError
from models.networks.dance_vq import STYLES, DanceVQ, style_token

#: Exemplars kept per code and per library folder (style). 8 x 512 codes = 4,096 windows a folder at most.
LIBRARY_MEMBERS: int = 8
#: Frames between the starts of two candidate windows of a clip (the default's memory: 4).
WINDOW_STRIDE: int = 2
#: member_style token of the library's first folder (0 unknown, 1..3 the default's dancers).
STYLE_BASE: int = 4
#: Most folders (styles) one library may bring (the memory grows by LIBRARY_MEMBERS slots per code each).
MAX_STYLES: int = 16
#: Most exemplars per code in all (mixed in or not; more folders share it, at least one each): the
#: motion matching's cost per code step and a stream's start-up memory grow with it (a 29-minute
#: library in 4 folders, benchmarks/studies/startup_memory.py: 32 a code holds 604 MB once started,
#: over the 600-MB budget; 16 a code 517-520 MB; docs/library.md).
MAX_MEMBERS: int = 16
#: Codes a library's stream may draw a code step (the default's: 1, chooser.DRAWS). Most of a
#: library's codes hold windows that the encoder gave to other codes (the shared 63-s sample's windows
#: chose 99 of the 512), so all of one drawn code's exemplars can be far from the playing pose; on a
#: calm song such a handover bent the motion by 35 degrees a bone (125 the worst bone), the worst
#: seams. Where the matched exemplar would bend it past :data:`HANDOVER_GUARD`, the next drawn code's
#: exemplars join the matching, up to this many codes, then the :data:`NEAREST` (docs/library.md).
LIBRARY_DRAWS: int = 4
#: Exemplars of any code, those whose first pose is nearest the motion, matched where none of the
#: drawn codes' continues it within :data:`HANDOVER_GUARD`.
NEAREST: int = 16
#: Mean bone rotation (degrees) between the playing pose and the matched exemplar's first pose past
#: which the next drawn code's exemplars are matched too (:data:`LIBRARY_DRAWS`). At 8 the stream
#: never left the folder it started in nor a still stretch of a clip (it always found an exemplar
#: that near); handovers on lively songs bend 5-16 degrees (median), so 20 stops only the far ones.
HANDOVER_GUARD: float = 20.0
#: Above the memory's tempo, the tempo's tilt (chooser.TEMPO_ENERGY: +0.5 to +0.9 at 1.25x on
#: the listening songs) times this times an exemplar's liveliness (z-score of ln its mean joint
#: speed over the memory) is taken off its matching cost: livelier exemplars of the drawn codes. A
#: library's exemplars of one code come from unlike clips (a pop dance, a waltz), and the matching
#: alone kept to whichever clip played, so a faster tempo did not reach the choice. Below it nothing
#: (the calmest exemplars continue each other best: the performer stood still on a slow song).
EXEMPLAR_TILT: float = 0.5
#: Lags (frames) the kinematic tempo searches (:func:`kinematic_period`): 225 down to 25 bpm.
KIN_LAGS: tuple[int, int] = (8, 72)
#: Beats per minute the kinematic tempo is folded into (its octave is not in the motion).
KIN_BAND: tuple[float, float] = (75.0, 150.0)


def kinematic_period(poses: np.ndarray) -> float:
    """A clip's beat period (frames at 30 fps) from its motion alone: the lag of the highest
    autocorrelation peak of its mean joint speed (FK on the default skeleton, smoothed over 2
    frames, its 4-s trend removed) between :data:`KIN_LAGS` frames, moved by octaves into
    :data:`KIN_BAND`; 0 for a clip under 4 s or without a periodic pulse. ``poses`` (T, P).

    Dancers dip in speed on every beat or on every other one (DANCE_C_2, a 129-bpm cha-cha:
    a peak at 29.5 frames, 61 bpm), so the octave is not in the motion; the band takes the
    one nearest common dance music. ``performer library build --bpm`` gives the tempo instead."""
    from scipy.ndimage import gaussian_filter1d

    from models.rig.kinematics import fk
    from models.rig.motion import Motion
    from models.rig.skeleton import load_default_skeleton
    from models.timebase import FPS

    if len(poses) < 4 * FPS:
        return 0.0
    pos = fk(Motion.from_vector(np.asarray(poses, np.float32), fps=FPS), load_default_skeleton())
    speed = np.linalg.norm(np.gradient(pos, axis=0) * FPS, axis=-1).mean(axis=1)  # models.evaluation.beats.motion_speed
    v = gaussian_filter1d(speed, 2.0, mode="nearest")
    v = v - gaussian_filter1d(v, 4.0 * FPS, mode="nearest")
    v = v - v.mean()
    f = np.fft.rfft(v, 2 * len(v))
    ac = np.fft.irfft(f * np.conj(f))[: len(v)]
    if ac[0] <= 0:
        return 0.0
    ac = ac / ac[0]
    lo, hi = KIN_LAGS
    lags = [k for k in range(lo, min(hi, len(ac) - 2) + 1) if ac[k] > ac[k - 1] and ac[k] >= ac[k + 1]]
    if not lags:
        return 0.0
    k = max(lags, key=lambda j: ac[j])
    if ac[k] <= 0.05:
        return 0.0
    a, b, c = ac[k - 1], ac[k], ac[k + 1]
    den = a - 2 * b + c
    p = k + (0.5 * (a - c) / den if den < 0 else 0.0)
    slow, fast = 60.0 * FPS / KIN_BAND[0], 60.0 * FPS / KIN_BAND[1]
    while p > slow:
        p *= 0.5
    while p < fast:
        p *= 2.0
    return float(p)


def member_choice(model, speed: np.ndarray, real: np.ndarray, draws: int) -> tuple[int, float, np.ndarray | None]:
    """(codes a code step may draw, the bend in degrees past which it draws the next (0: all at
    once), each exemplar's liveliness weight (K, M) or None) of a stream of ``model``: a library
    model's ``code_draws``, ``handover_guard`` and ``exemplar_tilt`` (:func:`library_model`) times
    the z-score of ln ``speed`` (K, M, m/frame) over the ``real`` (K, M) exemplars; (draws, 0, None)
    for a checkpoint's own memory (its choice as it always was: ``draws``, chooser.DRAWS)."""
    draws, guard = int(getattr(model, "code_draws", draws)), float(getattr(model, "handover_guard", 0.0))
    gain = float(getattr(model, "exemplar_tilt", 0.0))
    if gain == 0.0 or not real.any():
        return draws, guard, None
    ln = np.log(np.maximum(speed, 1e-6))
    mu, sd = float(ln[real].mean()), float(ln[real].std())
    return draws, guard, np.where(real, gain * (ln - mu) / max(sd, 1e-6), 0.0)


def bend_deg(pose: np.ndarray, target: np.ndarray) -> float:
    """Mean over the bones of the rotation (degrees) between two poses (P,) of unit quaternions."""
    dot = np.abs(np.add.reduce((pose[3:] * target[3:]).reshape(-1, 4), axis=1))
    return float(np.degrees(2.0 * np.arccos(np.minimum(dot, 1.0))).mean())


def _mean_pose(poses: list[np.ndarray], ref: np.ndarray) -> torch.Tensor:
    """The clips' mean pose (P,): the mean hips position and, per bone, the mean of the rotations
    put on ``ref``'s (P,) hemisphere, normalised. The stream's idle (idle_fade.idle_pose) stands in it:
    the user's own rest between songs, which the fades into and out of the dance start from (the
    default dancers' mean pose is 18 degrees a bone from the shared sample's, its hips 17 cm higher)."""
    r = ref[3:].reshape(-1, 4)
    m, hips, n = 0.0, 0.0, 0
    for p in poses:  # clip by clip: all clips at once in float64 was +95 MB of a 30-min library's build peak
        x = p.astype(np.float64)
        q = x[:, 3:].reshape(len(x), -1, 4)
        m = m + (q * np.where((q * r).sum(-1, keepdims=True) < 0, -1.0, 1.0)).sum(0)
        hips, n = hips + x[:, :3].sum(0), n + len(x)
    m /= np.maximum(np.linalg.norm(m, axis=-1, keepdims=True), 1e-12)
    return torch.from_numpy(np.concatenate([hips / n, m.reshape(-1)]).astype(np.float32))


def library_styles(model) -> tuple[str, ...]:
    """The library folders a model plays (:func:`library_model`), in token order; () for a checkpoint's own."""
    return tuple(getattr(model, "library_styles", ()))


def resolve_style(model, style: str | None) -> tuple[int, int]:
    """(member token, predictor token) of ``style`` for ``model``: None/"auto" (0, 0); a default
    style (1..3, the same) where the model plays the default's exemplars; a library folder
    (:data:`STYLE_BASE` + i, 0: the predictor hears "auto"). ConfigError naming the choices otherwise."""
    names = library_styles(model)
    if style is None or style == "auto":
        return 0, 0
    if style in names:
        return STYLE_BASE + names.index(style), 0
    own = getattr(model, "default_styles", True)
    if own and not names:
        tok = style_token(style)  # its own error for an unknown name
        return tok, tok
    if own and style in STYLES:
        tok = style_token(style)
        return tok, tok
    choices = ", ".join(("auto",) + (STYLES if own else ()) + names)
    raise ConfigError(f"unknown style {style!r}; this performer dances: {choices}")


@dataclasses.dataclass
class _Windows:
    """Candidate windows of a library: clip index, start frame, folder index, code (N,), and the
    distance of each window's encoding to every code vector (N, K) float32."""

    clip: np.ndarray
    start: np.ndarray
    folder: np.ndarray
    code: np.ndarray
    dist: np.ndarray


@torch.no_grad()
def _encode(model: DanceVQ, poses: list[np.ndarray], folders: list[int], stride: int) -> _Windows:
    s = model.config.seg
    clip, start, folder, zs = [], [], [], []
    for ci, p in enumerate(poses):
        for ph in range(0, s, stride):
            n = (len(p) - ph) // s
            if n < 3:
                continue
            z = model.encoder(model.standardize_poses(torch.from_numpy(p[ph: ph + n * s])[None]))[0].T  # (n, C)
            k = np.arange(n - 1)  # windows of 2 seg frames inside the clip
            zs.append(z[: n - 1])
            clip.append(np.full(len(k), ci))
            start.append(ph + k * s)
            folder.append(np.full(len(k), folders[ci]))
    if not zs:
        raise DataError(f"every clip is shorter than {3 * s} frames: nothing to dance", source="library")
    z = torch.cat(zs)
    # in blocks, into one array: the quantizer's own nearest-code search over all windows at once
    # held three (N, K) matrices (160 MB for a 30-minute library), a list of blocks concatenated two
    dist = np.empty((len(z), len(model.quantizer.embed)), np.float32)
    for a in range(0, len(z), 2048):
        dist[a: a + 2048] = torch.cdist(z[a: a + 2048], model.quantizer.embed).numpy()
    return _Windows(np.concatenate(clip), np.concatenate(start), np.concatenate(folder), dist.argmin(1), dist)


def _match_memory(w: _Windows, poses: list[np.ndarray], seg: int) -> np.ndarray:
    """``chooser="match"``: the windows' codes and code distances replaced, in place, by clusters of
    their motion descriptors (models/networks/motion_match.py); returns the centres (K, 3)."""
    from models.networks.motion_match import match_windows

    w.code, w.dist, centres = match_windows(poses, w.start, w.clip, seg, w.dist.shape[1])
    return centres


def _pick(order: np.ndarray, w: _Windows, n: int, seg: int) -> list[int]:
    """Up to ``n`` windows from ``order`` (best first), none within ``seg`` frames of a kept one of the same clip."""
    kept: list[int] = []
    for i in order:
        if all(w.clip[i] != w.clip[j] or abs(int(w.start[i]) - int(w.start[j])) >= seg for j in kept):
            kept.append(int(i))
            if len(kept) == n:
                break
    return kept


@torch.no_grad()
def library_model(model: DanceVQ, poses: list[np.ndarray], tracks: list[np.ndarray], folders: list[str],
                  mix: bool = False, members: int = LIBRARY_MEMBERS, bpm: list[float] | None = None,
                  chooser: str = "codes") -> DanceVQ:
    """A copy of ``model`` whose choreographic memory is a library's clips (see the module
    docstring): per clip its poses (T, P) in place facing +Z with w >= 0 quaternions and its
    root track (T, 3) (:func:`models.data.library.clip_tracks`), the name of its folder, and
    ``bpm`` its tempo (beats per minute; 0 or None: from its motion, :func:`kinematic_period`).
    ``mix``: the default's exemplars stay too. The copy has ``library_styles`` (the folder
    names, in token order) and ``clip_periods`` (frames per beat per clip, 0 unknown);
    :func:`models.generate.load_library_model` adds ``library_path``. ``model`` is left as it
    was. ``chooser``: "codes" (the default's predictor picks codes) or "match" (issue 40's second
    design, :func:`_match_memory`: the music's descriptors pick among clusters of the windows).
    ConfigError for too many folders or an unknown chooser, DataError for clips too short."""
    from models.networks.tempo import fold_period
    from models.rig.travel import window_travel

    if not isinstance(model, DanceVQ):
        raise ConfigError(f"a library plays through a dance_vq model, got {type(model).__name__}")
    if not poses:
        raise DataError("the library has no clips", source="library")
    c = model.config
    s = c.seg
    names: list[str] = list(dict.fromkeys(folders))
    if len(names) > MAX_STYLES:
        raise ConfigError(f"the library has {len(names)} folders (styles); at most {MAX_STYLES}")
    lib_slots = members * len(names)
    base = c.members if mix else 0
    if base + lib_slots > MAX_MEMBERS:
        members = max(1, (MAX_MEMBERS - base) // len(names))
        lib_slots = members * len(names)
    folder_of = [names.index(f) for f in folders]
    periods = []
    for i, p in enumerate(poses):
        given = float(bpm[i]) if bpm is not None and bpm[i] else 0.0
        periods.append(fold_period(1800.0 / given) if given > 0 else kinematic_period(p))
    if chooser not in ("codes", "match"):
        raise ConfigError(f"unknown chooser {chooser!r}; choose codes or match")
    model.eval()
    w = _encode(model, poses, folder_of, WINDOW_STRIDE)
    centres = _match_memory(w, poses, s) if chooser == "match" else None
    d_all = w.dist  # (N, K) distance of every window to every code vector

    out = copy.deepcopy(model)
    new_cfg = dataclasses.replace(c, members=base + lib_slots)
    out.config = new_cfg
    K = c.codebook
    poses_t = torch.zeros(K, new_cfg.members, 2 * s, c.pose_dim, dtype=torch.float16)
    count = torch.zeros(K, dtype=torch.int64)
    style = torch.zeros(K, new_cfg.members, dtype=torch.int64)
    period = torch.zeros(K, new_cfg.members)
    travel = torch.zeros(K, new_cfg.members, 2 * s, 3, dtype=torch.float16)
    prior = torch.zeros(K, STYLE_BASE + len(names))
    if mix:  # the default's exemplars first, as they are
        poses_t[:, :base] = model.member_poses
        count += model.member_count
        style[:, :base] = model.member_style
        period[:, :base] = model.member_period
        travel[:, :base] = model.member_travel
        prior[:, :4] = model.style_prior
    counts = np.zeros((K, len(names)), np.int64)
    np.add.at(counts, (w.code, w.folder), 1)
    for f in range(len(names)):
        mine = np.flatnonzero(w.folder == f)
        for k in range(K):
            own = mine[w.code[mine] == k]
            order = np.concatenate([own[np.argsort(d_all[own, k])], mine[np.argsort(d_all[mine, k])]])
            for i in _pick(order, w, members, s):
                j = int(count[k])
                a, ci = int(w.start[i]), int(w.clip[i])
                poses_t[k, j] = torch.from_numpy(poses[ci][a: a + 2 * s])
                style[k, j] = STYLE_BASE + f
                period[k, j] = periods[ci]
                travel[k, j] = torch.from_numpy(window_travel(tracks[ci][a: a + 2 * s]))
                count[k] = j + 1
    if len(names) > 1:  # a folder's prior: how much likelier each code is among its windows
        lik = (counts + 1.0) / (counts.sum(0, keepdims=True) + K)
        prior[:, STYLE_BASE:] = torch.from_numpy(np.log(lik / lik.sum(1, keepdims=True))).float()
    for name, value in (("member_poses", poses_t), ("member_count", count), ("member_style", style),
                        ("member_period", period), ("member_travel", travel), ("style_prior", prior)):
        setattr(out, name, value)  # registered buffers: replaced, shapes of the new memory
    out.library_styles = tuple(names)
    out.default_styles = bool(mix)
    out.clip_periods = tuple(periods)
    # read by DanceStream (member_choice, its idle). Not with the default's dancers (mix): the guard kept the
    # stream in whichever dancers' exemplars it began with; nor for the compared "match" design, as measured
    if chooser == "codes" and not mix:
        out.code_draws, out.handover_guard, out.exemplar_tilt = LIBRARY_DRAWS, HANDOVER_GUARD, EXEMPLAR_TILT
        out.idle_base = _mean_pose(poses, model.destandardize_poses(model.pose_mean * 0).numpy())
    if centres is not None:
        from models.networks.motion_match import MatchChooser, load_regression

        out.code_chooser = MatchChooser(load_regression(), centres)  # read by DanceStream every code step
    for attr in [a for a in vars(out) if a.endswith("_cache") or a == "_numpy_predictor"]:
        delattr(out, attr)  # caches of the original's memory (dance_stream)
    return out.eval()
