"""Seed-to-seed spread of `performer evaluate` metrics, grouped by training recipe.

One training recipe run with different seeds gives different checkpoints, and a
comparison of two recipes through one checkpoint each can be decided by the luck of
the draw. This script reads one ``performer evaluate`` run over many checkpoints and
prints, per group of checkpoints (a name and a glob over checkpoint paths), the
mean, standard deviation, minimum and maximum of each metric, then every
checkpoint's own row::

    performer evaluate --checkpoint models/assets/default.pt runs/v100_s*/best.pt \\
        runs/lstm/best.pt runs/lstm_s*/best.pt --data ../shared/data/dwm --out runs/eval_seeds --quiet
    .venv/bin/python benchmarks/studies/seed_spread.py runs/eval_seeds \\
        --group "causal fine-tune=runs/beat_ctx60_w5_v100/best.pt,runs/v100_s*/best.pt" \\
        --group "lstm=runs/lstm/best.pt,runs/lstm_s*/best.pt"

Reads ``per_dance.json`` (row -> checkpoint path) and ``results.json`` (row ->
metrics) from the evaluation directory; prints Markdown.
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import sys
from pathlib import Path

import numpy as np

DEFAULT_METRICS = ("rot_l1", "dtw", "energy_ratio", "beat_hit_rate")


def load_rows(eval_dir: Path) -> dict[str, dict[str, float]]:
    """Checkpoint path -> metrics of one ``performer evaluate`` output directory."""
    for name in ("results.json", "per_dance.json"):
        if not (eval_dir / name).is_file():
            raise SystemExit(f"{eval_dir / name}: not found (the --out directory of performer evaluate?)")
    results = json.loads((eval_dir / "results.json").read_text())["results"]
    details = json.loads((eval_dir / "per_dance.json").read_text())
    return {d["checkpoint"]: results[row] for row, d in details.items()
            if isinstance(d, dict) and d.get("checkpoint") and row in results}


def group_rows(rows: dict[str, dict[str, float]], patterns: list[str]) -> list[str]:
    """Checkpoint paths of ``rows`` that match any of the globs, in sorted order."""
    return sorted(p for p in rows if any(fnmatch.fnmatch(p, g) for g in patterns))


def spread(values: list[float]) -> dict[str, float]:
    """Mean, sample standard deviation (0 for one value), minimum and maximum."""
    v = np.asarray(values, dtype=np.float64)
    return {"mean": float(v.mean()), "std": float(v.std(ddof=1)) if v.size > 1 else 0.0,
            "min": float(v.min()), "max": float(v.max())}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("eval_dir", type=Path, help="the --out directory of a performer evaluate run")
    p.add_argument("--group", action="append", required=True, metavar="NAME=GLOB[,GLOB...]",
                   help="a recipe: its name and globs over the evaluated checkpoint paths (repeatable)")
    p.add_argument("--metrics", default=",".join(DEFAULT_METRICS), help="comma-separated metric keys")
    a = p.parse_args(argv)
    rows = load_rows(a.eval_dir)
    metrics = [m for m in a.metrics.split(",") if m]
    groups = []
    for spec in a.group:
        name, sep, globs = spec.partition("=")
        members = group_rows(rows, globs.split(",")) if sep else []
        if not members:
            print(f"--group {spec!r}: no evaluated checkpoint matches (evaluated: {', '.join(sorted(rows))})",
                  file=sys.stderr)
            return 2
        groups.append((name, members))
    grouped = [rows[c] for _, members in groups for c in members]
    known = {k for k in grouped[0] if all(isinstance(r.get(k), (int, float)) for r in grouped)}
    if unknown := [m for m in metrics if m not in known]:
        print(f"--metrics: unknown key(s) {unknown} (or n/a for a grouped checkpoint); known: {sorted(known)}",
              file=sys.stderr)
        return 2

    print("| recipe | seeds | " + " | ".join(f"{m} mean ± std (min-max)" for m in metrics) + " |")
    print("| --- | ---: | " + " | ".join("---:" for _ in metrics) + " |")
    for name, members in groups:
        cells = []
        for m in metrics:
            s = spread([rows[c][m] for c in members])
            cells.append(f"{s['mean']:.4g} ± {s['std']:.2g} ({s['min']:.4g}-{s['max']:.4g})")
        print(f"| {name} | {len(members)} | " + " | ".join(cells) + " |")
    print()
    print("| recipe | checkpoint | " + " | ".join(metrics) + " |")
    print("| --- | --- | " + " | ".join("---:" for _ in metrics) + " |")
    for name, members in groups:
        for c in members:
            print(f"| {name} | {c} | " + " | ".join(f"{rows[c][m]:.4g}" for m in metrics) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
