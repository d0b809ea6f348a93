#!/usr/bin/env bash
# Runs the Google Benchmark programs and prints the table that docs/PERFORMANCE.md quotes.
set -euo pipefail
cd "$(dirname "$0")/.."
./build/bench_forces --benchmark_repetitions=5 --benchmark_report_aggregates_only=true \
  --benchmark_min_time=0.5 "$@"
