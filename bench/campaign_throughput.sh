#!/usr/bin/env bash
# Campaign throughput at the training level (issue 5): one campaign of CELLS cells of 20 forces at
# level 4, run with 1 and with 2 threads (cells concurrently), timed by farm-bench (median of RUNS).
# Usage: bench/campaign_throughput.sh [CELLS=4] [RUNS=3]
# Prints wall seconds per run; samples per core-hour = 20 CELLS * 3600 / (wall * threads).
set -euo pipefail
cd "$(dirname "$0")/.."
cells=${1:-4}
runs=${2:-3}
samples=$((20 * cells))
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
for threads in 1 2; do
  echo "== $samples samples ($cells cells x 20 forces), level 4, --threads $threads"
  OMP_NUM_THREADS=1 farm-bench -n "$runs" --warmup 0 --timeout 3600 -- \
    sh -c "rm -rf $tmp/c && exec ./build/trbc campaign --samples $samples --forces-per-cell 20 --level 4 \
           --seed 7 --no-cache --threads $threads --out $tmp/c"
done
