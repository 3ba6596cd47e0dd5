"""Fit the match chooser's regression (issue 40's second design; models/networks/motion_match.py).

Music descriptors -> motion descriptor z-scores by ridge regression on the DWM training split,
every code step (8 frames at 30 fps), each row also stretched by 0.8x and 1.25x; written to
``models/assets/match_regression.json``. ``python -m models.training.motion_match ../shared/data/dwm``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from models.networks.motion_match import (ASSET, MOTION_NAMES, MUSIC_NAMES, RIDGE, STRETCH, motion_descriptors,
                                          music_descriptors)


def fit(dwm: Path, out: Path = ASSET, cache: Path | None = None) -> dict:
    """Fit the regression on the DWM training split (``dwm``: ../shared/data/dwm) and write ``out``."""
    from models.data.corpus import build_corpus
    from models.data.split import split_names
    from models.generate import load_model
    from models.networks.tempo import track_periods

    lm = load_model(None)
    m = lm.model
    seg = m.config.seg
    mean, std = m.feat_mean.numpy(), m.feat_std.numpy()
    names = sorted(p.name for p in Path(dwm).iterdir() if p.name.startswith("DANCE_"))
    if not names:
        from models.errors import DataError

        raise DataError(f"{dwm}: no DANCE_* folders (the DWM dances)")
    train, _ = split_names(names)
    clips = build_corpus(dwm, train, lm.features, cache_dir=cache, progress=False)
    xs, ys = [], []
    for c in clips:
        f = c.features
        per = track_periods(f[:, 61], f[:, 60], f[:, 28])
        z = (f[:, : m.config.feature_dim] - mean) / std
        ts = [t for t in range(seg, c.num_frames - 2 * seg, seg) if c.valid[t: t + 2 * seg].all()]
        prev = np.array([t - 1 for t in ts])
        xs.append(music_descriptors(np.stack([z[t - seg: t] for t in ts]), per[prev], 15.0))
        ys.append(motion_descriptors(np.stack([c.poses[t: t + 2 * seg] for t in ts]), seg))
    x, y = np.concatenate(xs), np.concatenate(ys)
    fallback = float(np.exp(np.median(x[:, 0])))
    y_mean, y_std = y.mean(0), y.std(0)
    xa, ya = [x], [y]
    for r in STRETCH:  # the same rows played r times as fast
        xr, yr = x.copy(), y.copy()
        xr[:, 0] -= math.log(r)
        yr[:, 0] += math.log(r)
        yr[:, 1] += math.log(r)
        xa.append(xr)
        ya.append(yr)
    X, Y = np.concatenate(xa), (np.concatenate(ya) - y_mean) / y_std
    x_mean, x_std = X.mean(0), X.std(0)
    Xz = (X - x_mean) / x_std
    w = np.linalg.solve(Xz.T @ Xz + RIDGE * np.eye(Xz.shape[1]), Xz.T @ (Y - Y.mean(0)))
    b = Y.mean(0)
    r2 = 1.0 - ((Xz @ w + b - Y) ** 2).sum(0) / ((Y - Y.mean(0)) ** 2).sum(0)
    xz1 = (x - x_mean) / x_std  # unstretched rows only
    y1 = (y - y_mean) / y_std
    r2_1 = 1.0 - ((xz1 @ w + b - y1) ** 2).sum(0) / ((y1 - y1.mean(0)) ** 2).sum(0)
    d = {"about": "models/networks/motion_match.py: music descriptors -> motion descriptor z-scores, ridge, "
                  "DWM training split; refit: python -m models.training.motion_match ../shared/data/dwm",
         "music": list(MUSIC_NAMES), "motion": list(MOTION_NAMES), "dances": train, "rows": int(len(x)),
         "stretch": list(STRETCH), "ridge": RIDGE, "x_mean": x_mean.tolist(), "x_std": x_std.tolist(),
         "w": w.tolist(), "b": b.tolist(), "y_mean": y_mean.tolist(), "y_std": y_std.tolist(),
         "period_fallback": fallback, "pred_mean": (xz1 @ w + b).mean(0).tolist(), "pred_std": (xz1 @ w + b).std(0).tolist(), "r2_with_stretch": r2.tolist(), "r2_unstretched": r2_1.tolist()}
    Path(out).write_text(json.dumps(d, indent=1))
    return d


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description="Fit the match chooser's music -> motion descriptor regression on the "
                                            "DWM training split (docs/library.md).")
    p.add_argument("dwm", type=Path, help="the DWM dances folder (../shared/data/dwm)")
    p.add_argument("--out", type=Path, default=ASSET, help=f"where to write it (default {ASSET})")
    p.add_argument("--cache", type=Path, default=Path(".cache/corpus"), help="corpus cache (default .cache/corpus)")
    a = p.parse_args(argv)
    if not a.dwm.is_dir():
        print(f"motion_match: {a.dwm}: not a folder", file=sys.stderr)
        return 2
    from models.errors import PerformerError

    try:
        d = fit(a.dwm, a.out, a.cache)
    except (PerformerError, OSError, ValueError) as e:
        print(f"motion_match: {e}", file=sys.stderr)
        return 2
    print(f"wrote {a.out}: {d['rows']} rows of {len(d['dances'])} dances; R^2 (unstretched) "
          + ", ".join(f"{n} {v:.2f}" for n, v in zip(MOTION_NAMES, d["r2_unstretched"])))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
