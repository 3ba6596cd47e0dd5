"""What the paired metrics reward: constant mean poses against the models, and beat phase.

Two questions about the issue-3 targets, answered on the validation dances with the
same clips, forward kinematics and metric code as ``performer evaluate``:

1. **How much of rotation L1 / DTW is the mean pose?** Every checkpoint is scored
   next to constant poses that never move: the training dances' mean pose, the mean
   pose of the dance's own style (an oracle: the style is read from the dance name),
   the dance's own mean (an oracle on the answer), and, per checkpoint, the time-mean
   of its own output ("model held still"). A constant pose that beats a model on
   these metrics means the metric rewards hedging towards the style's average pose
   more than it rewards motion.
2. **Is a model's motion locked to the beat at some other phase?** The beat hit rate
   (``models.evaluation.beats``) with every music beat shifted by d frames, for
   d = -8 .. 8, for the real dances and each checkpoint. A flat profile is motion
   independent of the beat; a periodic one is motion locked to it, hitting the beat
   best at the shift where the profile peaks.

::

    .venv/bin/python benchmarks/studies/paired_floor.py --data ../shared/data/dwm \\
        --checkpoint models/assets/default.pt runs/lstm/best.pt

Prints two Markdown tables (quoted in docs/training.md). The mean poses are
sign-aligned per bone, averaged and renormalised (nlerp mean); their root is the mean
root position.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

METRICS = ("rot_l1", "pos_l1", "dtw", "pck@0.2")
SHIFTS = range(-8, 9)


def mean_pose(poses: np.ndarray) -> np.ndarray:
    """The nlerp mean of flat poses (T, POSE_DIM): (POSE_DIM,) float32."""
    q = poses[:, 3:].reshape(len(poses), -1, 4).astype(np.float64)
    s = np.where(np.sum(q * q[0], axis=-1, keepdims=True) < 0, -1.0, 1.0)
    m = (q * s).mean(axis=0)
    out = np.empty(poses.shape[1], np.float32)
    out[:3] = poses[:, :3].mean(axis=0)
    out[3:] = (m / np.linalg.norm(m, axis=-1, keepdims=True)).ravel()
    return out


def shift_profile(positions: list[np.ndarray], beats: list[np.ndarray], shifts=SHIFTS) -> list[float]:
    """Pooled beat hit rate of motions ``positions`` ((T, J, 3) m each) with every music beat
    (frame indices, one array per motion) moved by d frames, for each d in ``shifts``."""
    from models.evaluation.evaluate import pooled_beats

    return [pooled_beats(positions, [np.asarray(b) + d for b in beats])["beat_hit_rate"] for d in shifts]


def style_of(name: str) -> str:
    """DWM dance names are DANCE_<style>_<id>."""
    return name.split("_")[1]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", required=True, help="the DWM dataset directory")
    p.add_argument("--checkpoint", nargs="+", default=[], help="checkpoints to score beside the constant poses")
    p.add_argument("--cache", default=".cache/corpus", help="corpus cache (as performer evaluate)")
    a = p.parse_args(argv)
    import torch

    from models.evaluation.evaluate import (EvalOptions, _quats, clip_music_beats, load_clips, paired_metrics,
                                            positions, split_dances)
    from models.features.spectral import FeatureConfig
    from models.generate import load_model, run_model

    torch.set_num_threads(1)
    opts = EvalOptions(cache_dir=Path(a.cache), progress=False)
    train_names, val_names = split_dances(a.data, opts)
    models = [load_model(c) for c in a.checkpoint]
    fcfg = models[0].features if models else FeatureConfig()
    val = load_clips(a.data, val_names, fcfg, opts)
    train = load_clips(a.data, train_names, fcfg, opts)
    real_pos = [positions(c.poses) for c in val]
    beats = [clip_music_beats(a.data, c) for c in val]

    everyone = mean_pose(np.concatenate([c.poses for c in train]))
    by_style = {s: mean_pose(np.concatenate([c.poses for c in train if style_of(c.name) == s]))
                for s in sorted({style_of(c.name) for c in train})}
    rows: dict[str, list[np.ndarray]] = {
        "constant: mean pose of the training dances": [np.tile(everyone, (c.num_frames, 1)) for c in val],
        "constant: mean pose of the dance's style (oracle style)": [
            np.tile(by_style[style_of(c.name)], (c.num_frames, 1)) for c in val],
        "constant: the dance's own mean pose (oracle)": [np.tile(mean_pose(c.poses), (c.num_frames, 1)) for c in val],
    }
    generated: dict[str, list[np.ndarray]] = {}
    for lm in models:  # each model on its own feature config (same dances, same frames)
        own = val if lm.features == fcfg else load_clips(a.data, val_names, lm.features, opts)
        gen = [run_model(lm.model, c.features)[: v.num_frames] for c, v in zip(own, val)]
        label = f"{lm.name} ({lm.path.name})"
        generated[label] = gen
        rows[label] = gen
        rows[f"{label} held still (its own time-mean)"] = [np.tile(mean_pose(g), (len(g), 1)) for g in gen]

    print("| poses | " + " | ".join(METRICS) + " |")
    print("| --- |" + " ---: |" * len(METRICS))
    for label, poses in rows.items():
        total, frames = dict.fromkeys(METRICS, 0.0), 0
        for c, g, pr in zip(val, poses, real_pos):
            m = paired_metrics(positions(g), pr, _quats(g), _quats(c.poses))
            for k in METRICS:
                total[k] += len(g) * m[k]
            frames += len(g)
        print(f"| {label} | " + " | ".join(f"{total[k] / frames:.4g}" for k in METRICS) + " |")

    print()
    print("| motion | " + " | ".join(f"{d:+d}" for d in SHIFTS) + " |")
    print("| --- |" + " ---: |" * len(SHIFTS))
    for label, pos in [("real dances", real_pos)] + [(k, [positions(g) for g in v]) for k, v in generated.items()]:
        hits = shift_profile(pos, beats)
        print(f"| {label} | " + " | ".join(f"{h:.3f}" for h in hits) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
