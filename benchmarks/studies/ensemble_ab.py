"""The ensemble's hop, a git revision against the working tree, runs interleaved.

Runs ``performer bench ensemble --counts 1 4 --no-separate --unstaggered --cores 0,1``
(the clip replayed in real time; one performer alone, then 4 on their 3x2 spots in one
process, code steps staggered) alternately on REF (checked out in a temporary git worktree,
run with this interpreter and PYTHONPATH pointing at it) and on the working tree, PAIRS
times, and prints for each run and each count the whole hop per frame, ms: wall p50, own
(wall less the run-queue wait) p50 / p99 / p99.9, the worker thread's CPU time p50 / p99 /
p99.9, the same CPU time's p50 / p99 on the even and on the odd frame indices apart (4
staggered performers: the code steps on the even ones), the input stage (features) p50, the
share of the CPUs other processes held; then the median of each side's runs. On a shared machine only the interleaved pairs compare:
docs/latency.md. A REF older than the p50 / p99.9 fields of the ensemble rows
(``realtime/bench/suite.py`` ``_hop_tails``, ``_hop_parity``) prints – for them::

    .venv/bin/python benchmarks/studies/ensemble_ab.py --ref HEAD~3 --pairs 3 --out out/ensemble_ab
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
COLS = (("per_hop_ms_p50_wall", "wall p50"), ("per_hop_ms_p50_own", "own p50"), ("per_hop_ms_p99_own", "own p99"),
        ("per_hop_ms_p999_own", "own p99.9"), ("per_hop_ms_p50_cpu", "CPU p50"), ("per_hop_ms_p99_cpu", "CPU p99"),
        ("per_hop_ms_p999_cpu", "CPU p99.9"), ("per_hop_ms_p50_cpu_even", "CPU p50 even"),
        ("per_hop_ms_p99_cpu_even", "CPU p99 even"), ("per_hop_ms_p50_cpu_odd", "CPU p50 odd"),
        ("per_hop_ms_p99_cpu_odd", "CPU p99 odd"), ("features_ms_p50", "features p50"),
        ("others_busy_percent", "others busy %"))


def _run(tree: Path, out: Path, seconds: float, counts: list[int]) -> list[dict]:
    """One ``bench ensemble`` on ``tree``'s code; its one-process rows."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    cmd = [sys.executable, "-m", "realtime.cli", "bench", "ensemble", "--counts", *map(str, counts), "--no-separate",
           "--unstaggered", "--seconds", str(seconds), "--cores", "0,1", "--out", str(out)]
    log = out.with_suffix(".log")
    with open(log, "w") as f:
        if subprocess.run(cmd, cwd=tree, env=env, stdout=f, stderr=subprocess.STDOUT).returncode:
            raise SystemExit(f"ensemble_ab: the run in {tree} failed, see {log}")
    rows = json.loads((out / "ensemble.json").read_text())["rows"]
    return [r for r in rows if r["mode"] == "one process"]


def _cell(v: object) -> str:
    return "–" if v is None else f"{v:.2f}"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--ref", required=True, help="git revision to compare the working tree against")
    p.add_argument("--pairs", type=int, default=3, help="runs of each side, alternated (default 3)")
    p.add_argument("--seconds", type=float, default=20.0, help="seconds of the clip per run (default 20)")
    p.add_argument("--counts", type=int, nargs="+", default=[1, 4], help="performer counts (default 1 4)")
    p.add_argument("--out", default="out/ensemble_ab", help="results: OUT/{ref,tree}N/ensemble.json")
    args = p.parse_args(argv)
    if args.pairs < 1 or args.seconds < 5:
        p.error("--pairs must be >= 1 and --seconds >= 5")
    if subprocess.run(["git", "rev-parse", "--verify", "-q", f"{args.ref}^{{commit}}"], cwd=REPO,
                      capture_output=True).returncode:
        p.error(f"--ref: unknown git revision {args.ref!r}")
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    wt = Path(tempfile.mkdtemp(prefix="ensemble-ab."))
    subprocess.run(["git", "worktree", "add", "-q", "--detach", str(wt), args.ref], cwd=REPO, check=True)
    results: dict[str, list[list[dict]]] = {"ref": [], "tree": []}
    try:
        for i in range(1, args.pairs + 1):
            for side, tree in (("ref", wt), ("tree", REPO)):
                results[side].append(_run(tree, out / f"{side}{i}", args.seconds, args.counts))
                print(f"ensemble_ab: {side}{i} done", file=sys.stderr, flush=True)
    finally:
        subprocess.run(["git", "worktree", "remove", "--force", str(wt)], cwd=REPO, capture_output=True)
        shutil.rmtree(wt, ignore_errors=True)
    print(f"ref {args.ref} against the working tree, {args.pairs} pairs of {args.seconds:g} s, interleaved; ms per frame")
    print("| run | performers | " + " | ".join(c for _, c in COLS) + " |\n|---|---:|" + "---:|" * len(COLS))
    for i in range(args.pairs):
        for side in ("ref", "tree"):
            for row in results[side][i]:
                print(f"| {side}{i + 1} | {row['performers']} | " + " | ".join(_cell(row.get(k)) for k, _ in COLS) + " |")
    for side in ("ref", "tree"):
        for j, n in enumerate(args.counts):
            cells = []
            for k, _ in COLS:
                vals = [runs[j].get(k) for runs in results[side] if runs[j].get(k) is not None]
                cells.append(_cell(statistics.median(vals) if vals else None))
            print(f"| {side} median | {n} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
