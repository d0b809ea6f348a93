#!/usr/bin/env bash
# The relaxation time at low reduced volume: tc at v = 0.65, 0.70, 0.75 (the other parameters of the
# reference point: mu 4, FvK 250, b2 1.5, eta_m 0.7) with the reference's inertial dynamics (vertex
# mass 1e-11 kg, the default) and the overdamped dynamics (--overdamped), at mesh levels 3, 4 and 5.
# Writes OUT/<protocol>_v<v>_L<level>.json and OUT/table.md (docs/FORWARD_MODEL.md "Relaxation at low v").
# Usage: scripts/relaxation_low_v.sh [build/trbc] [out-dir] [levels] [protocols]
# (the overdamped relaxation at level 5 takes more than 10 min per point on one core).
set -euo pipefail
TRBC=${1:-build/trbc}
OUT=${2:-results/relaxation_low_v}
LEVELS=${3:-"3 4 5"}
PROTOCOLS=${4:-"inertial overdamped"}
mkdir -p "$OUT"
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1}
for level in $LEVELS; do
  for v in 0.65 0.70 0.75; do
    for protocol in $PROTOCOLS; do
      f="$OUT/${protocol}_v${v}_L${level}.json"
      [[ -s "$f" ]] && continue
      extra=""
      [[ $protocol == overdamped ]] && extra="--overdamped"
      echo "$protocol v $v level $level" >&2
      "$TRBC" simulate --v "$v" --mu 4 --FvK 250 --b2 1.5 --etam 0.7 --experiments eq,relax --level "$level" $extra \
        > "$f.tmp" || true
      mv "$f.tmp" "$f"
    done
  done
done
/usr/bin/python3 - "$OUT" <<'PY'
import json, sys, os
out = sys.argv[1]
lines = ["| v | level | tc inertial (s) | tc overdamped (s) | overdamped / inertial | relaxation evals (inertial / overdamped) |",
         "|---|---|---|---|---|---|"]
for v in ("0.65", "0.70", "0.75"):
    for L in (3, 4, 5):
        r = {}
        for p in ("inertial", "overdamped"):
            f = f"{out}/{p}_v{v}_L{L}.json"
            if os.path.exists(f) and os.path.getsize(f):
                j = json.load(open(f))
                if j.get("status") == "ok":
                    r[p] = j
        if not r:
            continue
        tc = {p: r[p]["observables"]["tc_s"] if p in r else None for p in ("inertial", "overdamped")}
        ev = {p: str(r[p]["diagnostics"]["relaxation"]["force_evaluations"]) if p in r else "-" for p in tc}
        cell = lambda x: f"{x:.4f}" if x is not None else "-"
        ratio = f"{tc['overdamped'] / tc['inertial']:.3f}" if None not in tc.values() else "-"
        lines.append(f"| {v} | {L} | {cell(tc['inertial'])} | {cell(tc['overdamped'])} | {ratio} | {ev['inertial']} / {ev['overdamped']} |")
open(f"{out}/table.md", "w").write("\n".join(lines) + "\n")
print("\n".join(lines))
PY
