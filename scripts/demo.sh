#!/usr/bin/env bash
# make demo: the paper's calibration from the shipped training set and surrogates, one command:
#   trbc calibrate --config configs/paper.toml --out out/paper
# (Sobol' indices, the three-phase hierarchical inference with 50,000 samples per TMCMC run,
# posterior predictions, the calibrated cell) and the report out/paper/report.html + report.md.
# A second `make demo` finds every stage up to date and only prints where the report is.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-out/paper}
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-2}
start=$(date +%s)
build/trbc calibrate --config configs/paper.toml --out "$OUT"
echo "make demo: done in $(( $(date +%s) - start )) s"
echo "open $OUT/report.html (self-contained) or read $OUT/report.md"
