"""Where the jitter on a stage comes from (issue 39): the FFT's wrap at a song's ends, or the motion.

``performer evaluate``'s jitter (:func:`models.evaluation.metrics.band_ratios`, above 6 Hz, 30 fps
positions put in place) takes one FFT over each whole song, which sees the song as periodic: the
step from its last frame back to its first counts as motion in every band, the jitter band most.
Where that energy lies in time is exact: the band's bins transformed back give the band-passed
motion, whose squares, summed over frames, points and axes, are the band energy (Parseval).

For the validation dances, the performer (the shipped checkpoint's live stream, seeds ``--seeds``)
on each of ``--stages`` (0 = in place) and the dancers in place, per run:

- ``raw``: the headline's jitter ratio (performer / dancers);
- ``ends``: the share of the band energy within ``--ends`` s of a song's first or last frame;
- ``step``: the wrap step, mean over the 30 points (in place) of |last frame - first| (cm), and
  ``turned``: the performer's heading at the end against the start (degrees, mean of songs);
- ``interior``: the jitter ratio with the first and last ``--ends`` s of every song (the
  performer's and the dancers') left out of the energy, the FFT still over the whole song;
- ``mirrored``: each song followed by itself backwards (``foot_skating.mirrored``: no wrap step);
- ``hands`` / ``feet``: the interior jitter ratio of those points alone (hands: lower arms, hands,
  finger tips; feet: feet, toes, heels, toe tips);
- ``amp``: band amplitude (0.25-3 Hz), ``jerk``: jerk ratio (travel included), as ``performer evaluate``;
- ``turns``: the share of the interior frames whose heading turns at 0.9 ``stage.MAX_TURN`` or
  more, then the share of the interior energy they hold; ``edge``: the same for the frames
  within ``stage.MARGIN`` (at most 0.4 of the half side) of the stage's edge.

``--travelling`` compares with the dancers travelling instead (their own root path and heading,
retargeted from the mocap: ``foot_skating.travelling_poses``; the root's x, z put in place as for
the performer, their turns kept). ``--worst N`` then lists each run's N 1-s windows (``--ends`` clear of the song's ends) with the
most band energy: song, seconds, share of the run's interior energy, and the point that holds most
of it. ``--set feet.NAME=VALUE`` (``foot_skating.py``'s) runs with a constant changed, e.g.
``feet.KNEE_WRAP_FORWARD=0`` (the knee IK as before); ``--no-feet`` without the feet step::

    .venv/bin/python benchmarks/studies/jitter_wrap.py --data ../shared/data/dwm --seeds 0 1 2 3 --worst 2

Exit status 2 on a missing or unreadable checkpoint or dataset.
"""

from __future__ import annotations

import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(REPO))
if str(Path(__file__).resolve().parent) not in sys.path:
    sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

HANDS = ("LeftLowerArm", "RightLowerArm", "LeftHand", "RightHand", "LeftHandTip", "RightHandTip")
FEET = ("LeftFoot", "RightFoot", "LeftToes", "RightToes", "LeftHeel", "RightHeel", "LeftToesEnd", "RightToesEnd")


def band_frames(pos: np.ndarray, band: tuple[float, float], fps: float = 30.0) -> np.ndarray:
    """(T, J) energy of ``pos`` (T, J, 3) m in ``band`` Hz per frame and point (m^2), as
    ``metrics._band_energy`` counts it: the mean over time removed, one FFT over the whole
    sequence, the band's bins back to time, squared and summed over the axes. Sums to the
    band energy (Parseval)."""
    t = pos.shape[0]
    spec = np.fft.rfft(pos - pos.mean(axis=0), axis=0)
    freq = np.fft.rfftfreq(t, 1.0 / fps)
    spec[~((freq >= band[0]) & (freq <= band[1]))] = 0.0
    return (np.fft.irfft(spec, n=t, axis=0) ** 2).sum(axis=2)


def heading(poses: np.ndarray) -> np.ndarray:
    """(T,) the Hips' heading (rad, unwrapped; 0 = facing +Z) of flat poses (T, 87)."""
    from scipy.spatial.transform import Rotation

    f = Rotation.from_quat(poses[:, 3:7]).apply([0.0, 0.0, 1.0])
    return np.unwrap(np.arctan2(f[:, 0], f[:, 2]))


def where(poses: dict[str, np.ndarray], frames: dict[str, np.ndarray], cut: int,
          stage: str) -> tuple[tuple[float, float], tuple[float, float]]:
    """((share of interior frames turning fast, share of the interior energy they hold), (the same
    for the frames near the stage's edge)): see the module docstring."""
    from models.networks.stage import MARGIN, MARGIN_FRACTION, MAX_TURN, parse_stage

    w, d = parse_stage(stage)
    mx, mz = min(MARGIN, MARGIN_FRACTION * w / 2), min(MARGIN, MARGIN_FRACTION * d / 2)
    n = e_all = 0.0
    fast, near = [0.0, 0.0], [0.0, 0.0]
    for name, p in poses.items():
        e = frames[name].sum(axis=1)[cut:-cut]
        h = heading(p)
        turn = np.abs(np.diff(h, prepend=h[0]))[cut:-cut] >= 0.9 * MAX_TURN / 30.0
        x, z = p[cut:-cut, 0], p[cut:-cut, 2]
        edge = (np.abs(x) > w / 2 - mx) | (np.abs(z) > d / 2 - mz) if w > 0 else np.zeros(len(e), bool)
        for acc, m in ((fast, turn), (near, edge)):
            acc[0] += m.sum()
            acc[1] += e[m].sum()
        n += len(e)
        e_all += e.sum()
    return (fast[0] / n, fast[1] / e_all), (near[0] / n, near[1] / e_all)


def summary(pos: dict[str, np.ndarray], cut: int) -> dict:
    """Per run: band energies of the whole songs, within ``cut`` frames of their ends, and of the
    interior, overall and per point (pooled over songs), and the values counted."""
    from models.evaluation.metrics import JITTER_BAND

    out = {"all": 0.0, "ends": 0.0, "inner": 0.0, "inner_j": 0.0, "n": 0, "n_inner": 0, "frames": {}}
    for name, p in pos.items():
        e = band_frames(p, JITTER_BAND)
        out["frames"][name] = e
        out["all"] += e.sum()
        out["ends"] += e[:cut].sum() + e[-cut:].sum()
        out["inner"] += e[cut:-cut].sum()
        out["inner_j"] = out["inner_j"] + e[cut:-cut].sum(axis=0)
        out["n"] += p.size
        out["n_inner"] += p[cut:-cut].size
    return out


def validation_clips(data_root: str, checkpoint: str, cache: str) -> tuple:
    """(the loaded checkpoint, the validation dances' clips: features and the dancers' poses)."""
    from models.evaluation.evaluate import EvalOptions, load_clips, validation_names
    from models.generate import load_model

    lm = load_model(checkpoint)
    opts = EvalOptions(cache_dir=cache, progress=False)
    return lm, load_clips(data_root, validation_names(data_root, None, opts), lm.features, opts)


def style_judge(data_root: str, lm, clips: list, cache: str) -> tuple:
    """``performer evaluate``'s judge for :func:`models.evaluation.evaluate.set_metrics`: (the
    validation dances' real set, its style classifier, the real dances' classifier embeddings)."""
    from models.evaluation.classifier import embed
    from models.evaluation.evaluate import (EvalOptions, classifier_windows, load_clips, real_set, split_dances,
                                            style_classifier)

    opts = EvalOptions(cache_dir=cache, progress=False)
    val = real_set(data_root, clips, progress=False)
    train = real_set(data_root, load_clips(data_root, split_dances(data_root, opts)[0], lm.features, opts),
                     False, False)
    classifier = style_classifier(train, opts.classifier_epochs, opts.seed, cache)
    return val, classifier, embed(classifier, classifier_windows(val.positions))


def run(data_root: str, checkpoint: str, seeds: list[int], stages: list[str], ends_s: float, feet: bool,
        worst: int, cache: str, travelling: bool = False) -> None:
    """Print the table (see the module docstring)."""
    import torch

    from models.evaluation.evaluate import positions
    from models.evaluation.metrics import band_ratios, in_place, jerk
    from models.networks import dance_stream
    from models.rig.skeleton import POINT_INDEX

    from foot_skating import mirrored, travelling_poses

    lm, clips = validation_clips(data_root, checkpoint, cache)
    cut = int(round(ends_s * 30))
    real = {c.name: in_place(positions(travelling_poses(data_root, c.name, c.num_frames, c.first_frame)
                                       if travelling else c.poses)) for c in clips}
    rs = summary(real, cut)
    step = np.mean([np.linalg.norm(p[-1] - p[0], axis=1).mean() for p in real.values()])
    print(f"dancers {'travelling' if travelling else 'in place'}: jitter RMS {np.sqrt(rs['all'] / rs['n']) * 100:.3f} cm, {rs['ends'] / rs['all']:.1%} of it "
          f"within {ends_s:g} s of the ends; interior RMS {np.sqrt(rs['inner'] / rs['n_inner']) * 100:.3f} cm; "
          f"wrap step {step * 100:.1f} cm")
    for name, e in rs["frames"].items():
        print(f"  {name:<11} {len(e):>5} frames, {(e[:cut].sum() + e[-cut:].sum()) / e.sum():.1%} within the ends")
    groups = {g: [POINT_INDEX[n] for n in names] for g, names in (("hands", HANDS), ("feet", FEET))}
    names_by_index = {i: n for n, i in POINT_INDEX.items()}
    print(f"{'stage':<6} {'seed':>4} {'raw':>6} {'ends':>6} {'step cm':>8} {'turned':>7} {'interior':>8} "
          f"{'mirrored':>8} {'hands':>6} {'feet':>6} {'amp':>6} {'jerk':>6} {'turns':>13} {'edge':>13}")
    tops = []
    for stage in stages:
        for seed in seeds:
            kw = {} if stage in ("0", "") else {"stage": stage}
            raw_poses, pos, world = {}, {}, []
            for c in clips:
                with torch.no_grad():
                    raw_poses[c.name] = dance_stream.DanceStream(lm.model, seed=seed, feet=feet, **kw).push(c.features)
                world.append(positions(raw_poses[c.name]))
                pos[c.name] = in_place(world[-1])
            gs = summary(pos, cut)
            bands = band_ratios(list(pos.values()), list(real.values()), root=None)
            ends = band_ratios(mirrored(list(pos.values())), mirrored(list(real.values())), root=None)
            stepg = np.mean([np.linalg.norm(p[-1] - p[0], axis=1).mean() for p in pos.values()])
            turned = np.mean([abs(np.degrees((h[-1] - h[0] + np.pi) % (2 * np.pi) - np.pi))
                              for h in map(heading, raw_poses.values())])
            inner = np.sqrt((gs["inner"] / gs["n_inner"]) / (rs["inner"] / rs["n_inner"]))
            turns, edge = where(raw_poses, gs["frames"], cut, stage)
            part = {g: np.sqrt(gs["inner_j"][ix].sum() / rs["inner_j"][ix].sum()) for g, ix in groups.items()}
            print(f"{stage:<6} {seed:>4} {bands['jitter']:>6.3f} {gs['ends'] / gs['all']:>6.1%} {stepg * 100:>8.1f} "
                  f"{turned:>7.1f} {inner:>8.3f} {ends['jitter']:>8.3f} {part['hands']:>6.2f} {part['feet']:>6.2f} "
                  f"{bands['band_amp']:>6.3f} {jerk(world) / jerk(list(real.values())):>6.3f} "
                  f"{turns[0]:>5.1%} {turns[1]:>6.1%} {edge[0]:>5.1%} {edge[1]:>6.1%}", flush=True)
            wins = []
            for name, e in gs["frames"].items():
                per = e.sum(axis=1)
                for start in range(cut, len(per) - cut - 30, 15):
                    wins.append((per[start:start + 30].sum(), name, start, int(e[start:start + 30].sum(axis=0).argmax())))
            wins.sort(reverse=True)
            for energy, name, start, point in wins[:worst]:
                tops.append(f"  {stage} seed {seed}: {name} {start / 30:.1f}-{(start + 30) / 30:.1f} s holds "
                            f"{energy / gs['inner']:.1%} of the interior energy, most in {names_by_index[point]}")
    if tops:
        print("the 1-s windows with the most jitter energy:")
        print("\n".join(tops))


def main(argv: list[str] | None = None) -> int:
    from foot_skating import apply_sets, study_parser

    p = study_parser(__doc__)
    p.add_argument("--seeds", type=int, nargs="+", default=[0], metavar="N", help="the stream's seeds (default 0)")
    p.add_argument("--stages", nargs="+", default=["0", "3x2", "6x5"], metavar="WxD",
                   help="stages to dance on, 0 = in place (default: 0 3x2 6x5)")
    p.add_argument("--ends", type=float, default=0.5, metavar="S",
                   help="seconds at each end of a song counted as the wrap's (default 0.5)")
    p.add_argument("--no-feet", action="store_true", help="the performer with its feet step switched off")
    p.add_argument("--travelling", action="store_true",
                   help="compare with the dancers travelling (their own path and turns) instead of in place")
    p.add_argument("--worst", type=int, default=0, metavar="N", help="list each run's N 1-s windows of most jitter")
    a = p.parse_args(argv)
    if a.ends <= 0 or a.ends > 10:
        p.error(f"--ends must be in (0, 10] seconds, got {a.ends:g}")
    import torch

    from models.errors import PerformerError

    torch.set_num_threads(1)
    apply_sets(p, a.set)
    try:
        run(a.data, a.checkpoint, a.seeds, a.stages, a.ends, not a.no_feet, a.worst, a.cache, a.travelling)
    except (PerformerError, OSError) as e:
        print(f"jitter_wrap.py: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
