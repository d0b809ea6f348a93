#!/usr/bin/env bash
# Campaign throughput at the training level : one campaign of CELLS cells of 20 forces at
# level 4, run with 1 and with 2 threads (cells concurrently) and, when trbc was built with MPI,
# as 2 MPI ranks of one thread each; whole-process wall, user and system seconds of each of RUNS
# runs (bash's time), then their median wall time.
# Usage: bench/campaign_throughput.sh [CELLS=4] [RUNS=3] [SEED=7]
# Samples per core-hour = 20 CELLS * 3600 / (wall * cores).
set -euo pipefail
cd "$(dirname "$0")/.."
cells=${1:-4}
runs=${2:-3}
seed=${3:-7}
samples=$((20 * cells))
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
args="campaign --samples $samples --forces-per-cell 20 --level 4 --design uniform --seed $seed --no-cache"

if ! [[ "$runs" =~ ^[1-9][0-9]*$ ]]; then
  echo "campaign_throughput.sh: RUNS = '$runs' must be an integer >= 1" >&2
  exit 2
fi

# timed CMD...: RUNS runs of CMD (its output in $tmp/log), one line "wall user sys" each, then the
# median wall; a failing run stops the script with its log.
timed() {
  local walls=() line
  for ((k = 1; k <= runs; ++k)); do
    rm -rf "$tmp/c"
    TIMEFORMAT='%R %U %S'
    if ! line=$( { time "$@" >"$tmp/log" 2>&1; } 2>&1 ); then
      echo "run $k failed: $*" >&2
      tail -n 20 "$tmp/log" >&2
      exit 1
    fi
    echo "run $k: wall user sys = $line s"
    walls+=("${line%% *}")
  done
  printf '%s\n' "${walls[@]}" | sort -n |
    awk '{w[NR] = $1} END {m = NR % 2 ? w[(NR + 1) / 2] : (w[NR / 2] + w[NR / 2 + 1]) / 2; print "median wall", m, "s"}'
}

for threads in 1 2; do
  echo "== $samples samples ($cells cells x 20 forces), level 4, seed $seed, --threads $threads"
  OMP_NUM_THREADS=1 timed ./build/trbc $args --threads "$threads" --out "$tmp/c"
done
if command -v mpirun >/dev/null && ldd ./build/trbc | grep libmpi >/dev/null; then
  echo "== the same, mpirun -n 2 (one thread per rank)"
  OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMP_NUM_THREADS=1 \
    timed mpirun -n 2 ./build/trbc $args --threads 1 --out "$tmp/c"
else
  echo "== mpirun -n 2: skipped (trbc built without MPI)"
fi
