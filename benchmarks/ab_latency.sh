#!/usr/bin/env bash
# A/B latency comparison: a git revision, or a checkpoint, against the working tree, interleaved.
#
#   benchmarks/ab_latency.sh REF [PAIRS] [OUT] [-- extra `performer bench latency` args]
#   benchmarks/ab_latency.sh HEAD~1 3 out/ab -- --audio ../shared/data/dwm/DANCE_W_1/audio.mp3
#   benchmarks/ab_latency.sh runs/prev_default.pt 3 out/ab_prev   # a checkpoint file: same code, two models
#
# REF a checkpoint file (an existing path ending in .pt): the "ref" side is the working
# tree with `--checkpoint REF`, the "tree" side the working tree with its packaged default,
# so the two models' costs are compared on the same engine code.
#
# On a shared machine the p99 of a real-time replay moves with the neighbours by more than
# most code changes (docs/latency.md), so runs minutes apart cannot be compared. This runs
# `performer bench latency` (30 s, no offline RTF, no naive run, pinned to CPUs 0,1)
# alternately on REF (checked out in a temporary git worktree, run with this checkout's
# .venv and PYTHONPATH pointing at it) and on the working tree, PAIRS times, and prints
# one line per run plus the medians of each side. Results: OUT/{ref,tree}N/latency.json.
set -euo pipefail
cd "$(dirname "$0")/.."
ref=${1:?usage: benchmarks/ab_latency.sh REF [PAIRS] [OUT] [-- bench args]}
pairs=${2:-3}
out=${3:-out/ab}
shift $(( $# < 3 ? $# : 3 ))
[ "${1:-}" = "--" ] && shift
py=$PWD/.venv/bin/python
[ -x "$py" ] || { echo "ab_latency: run 'make setup' first (.venv missing)" >&2; exit 2; }
ref_args=()
if [[ "$ref" == *.pt && -f "$ref" ]]; then  # a checkpoint: the working tree runs it on the ref side
  wt=$PWD
  ref_args=(--checkpoint "$(cd "$(dirname "$ref")" && pwd)/$(basename "$ref")")
else
  git rev-parse --verify -q "$ref^{commit}" >/dev/null || { echo "ab_latency: unknown revision '$ref'" >&2; exit 2; }
  wt=$(mktemp -d /tmp/ab-latency.XXXXXX)
  trap 'git worktree remove --force "$wt" >/dev/null 2>&1 || true; rm -rf "$wt"' EXIT
  git worktree add -q --detach "$wt" "$ref"
fi
mkdir -p "$out"
out=$(cd "$out" && pwd)
for i in $(seq 1 "$pairs"); do
  for side in ref tree; do
    dir=$PWD; extra=(); [ "$side" = ref ] && { dir=$wt; extra=("${ref_args[@]}"); }
    (cd "$dir" && PYTHONPATH="$dir" "$py" -m realtime.cli bench latency --cores 0,1 --no-offline \
        --naive-seconds 0 --seconds 30 --label "$side$i" --out "$out/$side$i" "${extra[@]}" "$@" > "$out/$side$i.log" 2>&1) \
      || { echo "ab_latency: $side run $i failed, see $out/$side$i.log" >&2; exit 1; }
  done
done
"$py" - "$out" "$pairs" <<'EOF'
import json, statistics, sys
out, pairs = sys.argv[1], int(sys.argv[2])
keys = ("per_hop_ms_p50", "per_hop_ms_p99", "e2e_osc_ms_p99", "e2e_ws_ms_p99", "cpu_percent", "peak_rss_mb")
rows = {s: [json.load(open(f"{out}/{s}{i}/latency.json"))["metrics"] for i in range(1, pairs + 1)] for s in ("ref", "tree")}
print("| run | " + " | ".join(keys) + " |\n|---|" + "---:|" * len(keys))
for i in range(pairs):
    for s in ("ref", "tree"):
        print(f"| {s}{i + 1} | " + " | ".join(f"{rows[s][i][k]:.2f}" for k in keys) + " |")
for s in ("ref", "tree"):
    print(f"| {s} median | " + " | ".join(f"{statistics.median(r[k] for r in rows[s]):.2f}" for k in keys) + " |")
EOF
