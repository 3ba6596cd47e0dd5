"""Between songs: how fast a dance_vq performer settles on silence or noise and dances again.

Plays, through the model's live stream (:class:`models.networks.dance_stream.DanceStream`,
features as the engine computes them), a programme of validation songs separated by
gaps of silence, applause, crowd and room noise (``models.training.dance_vq.synthetic_noise``,
other seeds than the detector was fitted on), and prints per gap:

* ``settle_s``: seconds from the end of the music to the performer fully idle (target <= 2);
* ``back_s``: seconds from the music's return to the performer fully dancing (target <= 1);
* ``max_step_deg``: the largest frame-to-frame bone rotation during both fades, against the
  dance's own 99th percentile (no visible jump: not above it);
* ``idle_sway_deg``: the largest frame-to-frame bone rotation while idle (calm).

and, over the songs themselves, the share of music frames the gate wrongly took for a
gap (``false_idle``). ``--plot`` draws the idle weight and a hand's height over time.

    .venv/bin/python benchmarks/studies/idle_gate.py --checkpoint models/assets/default.pt \\
        --data ../shared/data/dwm --plot docs/img/idle_gate.png
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

GAPS = ("silence", "applause", "crowd", "room")
SONGS = ("DANCE_C_2", "DANCE_R_5", "DANCE_W_5", "DANCE_W_22", "DANCE_W_28")


def gap_audio(kind: str, seconds: float, rng: np.random.Generator) -> np.ndarray:
    from models.training.dance_vq import synthetic_noise

    if kind == "silence":
        return np.zeros(int(seconds * 22050), np.float32)
    return synthetic_noise(kind, seconds, rng)


def programme(data: Path, song_s: float, gap_s: float, seed: int) -> tuple[np.ndarray, list[tuple[str, int, int]]]:
    """Audio (n,) at 22050 Hz and its parts (name, first frame, end frame at 30 fps)."""
    from models.data.dwm import load_dance
    from models.features.audio_io import load_audio

    rng = np.random.default_rng(seed)
    parts, audio, frame = [], [], 0
    for i, name in enumerate(SONGS):
        song = load_audio(load_dance(data / name).audio_path, 22050)[0]
        start = len(song) // 3  # from the middle of the song: full music, no intro
        pieces = [(name, song[start: start + int(song_s * 22050)])]
        if i < len(GAPS):
            pieces.append((GAPS[i], gap_audio(GAPS[i], gap_s, rng)))
        for label, a in pieces:
            n = len(a) // 735
            audio.append(a[: n * 735])
            parts.append((label, frame, frame + n))
            frame += n
    return np.concatenate(audio).astype(np.float32), parts


def bone_steps_deg(poses: np.ndarray) -> np.ndarray:
    """(T - 1,) largest bone rotation (degrees) between consecutive poses (T, P)."""
    q = poses[:, 3:].reshape(len(poses), -1, 4)
    dot = np.clip(np.abs((q[1:] * q[:-1]).sum(-1)), 0, 1)
    return np.degrees(2 * np.arccos(dot)).max(1)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--checkpoint", default=None, help="a dance_vq checkpoint (default: the packaged one)")
    p.add_argument("--data", required=True, type=Path, help="the DWM dataset directory")
    p.add_argument("--song-s", type=float, default=20.0, help="seconds of each song (default 20)")
    p.add_argument("--gap-s", type=float, default=8.0, help="seconds of each gap (default 8)")
    p.add_argument("--seed", type=int, default=7, help="noise and dance seed (default 7)")
    p.add_argument("--plot", type=Path, help="write a PNG of the idle weight and the right hand's height")
    p.add_argument("--json", type=Path, help="write the results as JSON")
    args = p.parse_args(argv)

    from models.errors import PerformerError
    from models.features.spectral import extract_features
    from models.generate import load_model
    from models.networks.dance_stream import DanceStream

    try:
        lm = load_model(args.checkpoint)
        if not getattr(lm.model, "takes_style", False):
            raise PerformerError(f"{lm.path} is a {lm.name!r} model; the idle gate belongs to dance_vq models")
        audio, parts = programme(args.data, args.song_s, args.gap_s, args.seed)
    except (PerformerError, OSError) as e:
        print(f"idle_gate: {e}", file=sys.stderr)
        return 2
    feats = extract_features(audio, lm.features)
    stream = DanceStream(lm.model, seed=args.seed)
    poses = np.empty((len(feats), lm.model.config.pose_dim), np.float32)
    w = np.empty(len(feats))
    for t in range(len(feats)):
        poses[t] = stream.push(feats[t: t + 1])[0]
        w[t] = stream.idle_weight
    steps = bone_steps_deg(poses)
    dancing = np.concatenate([np.arange(a + 60, b - 1) for name, a, b in parts if name not in GAPS])
    dance_p99 = float(np.percentile(steps[dancing], 99))
    dance_max = float(steps[dancing].max())
    rows = []
    for i, (name, a, b) in enumerate(parts):
        if name not in GAPS:
            continue
        idle_at = a + int(np.argmax(w[a:b] >= 1.0)) if (w[a:b] >= 1.0).any() else None
        nxt = parts[i + 1][2] if i + 1 < len(parts) else len(w)
        back_at = b + int(np.argmax(w[b:nxt] <= 0.0)) if (w[b:nxt] <= 0.0).any() else None
        fades = np.r_[a:(idle_at or b), b:(back_at or nxt)]
        fades = fades[(fades > 0) & (fades < len(steps) + 1)] - 1
        idle = np.arange(idle_at, b - 1) if idle_at else np.array([], int)
        rows.append({
            "gap": name,
            "settle_s": None if idle_at is None else (idle_at - a + 1) / 30.0,
            "back_s": None if back_at is None else (back_at - b + 1) / 30.0,
            "max_step_deg": float(steps[fades].max()) if len(fades) else 0.0,
            "idle_sway_deg": float(steps[idle].max()) if len(idle) else None,
        })
    music = np.concatenate([np.arange(a + 60, b) for name, a, b in parts if name not in GAPS])
    false_idle = float((w[music] > 0).mean())
    print(f"{lm.path}: {len(parts)} parts, {len(feats) / 30:.0f} s; dance frame-to-frame step p99 {dance_p99:.2f}, max {dance_max:.2f} deg; "
          f"music frames taken for a gap (from 2 s into each song): {false_idle:.3f}")
    print("| gap | settle (s) ≤ 2 | back (s) ≤ 1 | largest step in the fades (deg) | largest step while idle (deg) |")
    print("| --- | ---: | ---: | ---: | ---: |")
    for r in rows:
        f = lambda v, d=2: "never" if v is None else f"{v:.{d}f}"  # noqa: E731
        print(f"| {r['gap']} | {f(r['settle_s'])} | {f(r['back_s'])} | {r['max_step_deg']:.2f} | {f(r['idle_sway_deg'])} |")
    if args.json:
        args.json.write_text(json.dumps({"rows": rows, "false_idle": false_idle, "dance_step_p99_deg": dance_p99, "dance_step_max_deg": dance_max}, indent=1))
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        from models.evaluation.evaluate import positions
        from models.rig.humanoid import BONE_INDEX

        pos = positions(poses)
        t = np.arange(len(w)) / 30.0
        fig, ax = plt.subplots(2, 1, figsize=(11, 4.5), sharex=True)
        for name, a, b in parts:
            for axis in ax:
                axis.axvspan(a / 30, b / 30, color="0.9" if name in GAPS else "white", zorder=0)
            ax[0].text((a + b) / 60, 1.08, name.replace("DANCE_", ""), ha="center", fontsize=8)
        ax[0].plot(t, w, color="C3")
        ax[0].set_ylabel("idle weight")
        ax[0].set_ylim(-0.05, 1.2)
        ax[1].plot(t, pos[:, BONE_INDEX["RightHand"], 1], color="C0", lw=0.8)
        ax[1].set_ylabel("right hand height (m)")
        ax[1].set_xlabel("s (grey: silence, applause, crowd, room noise)")
        fig.tight_layout()
        fig.savefig(args.plot, dpi=90)
        print(f"wrote {args.plot}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
