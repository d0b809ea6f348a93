#!/usr/bin/env bash
# Membrane-viscosity scan of two diagnostic shear-flow cases (docs/VALIDATION_RESULTS.md, "Membrane
# viscosity scan"): the Table 1 cell (v 0.94, mu 4.99 uN/m, kb 2.10e-19 J, b2 1.84) with eta_m in
# {0.3, 0.42, 0.55, 0.69} Pa s um at 23.9 mPa s / 55 1/s (inclination angle) and 10.7 mPa s / 39 1/s
# (regime), level 3, 10 rotations, plus the 10.7 mPa s case started 7 deg out of the shear plane.
# Usage: scripts/flow_scan_etam.sh TRBC OUT [JOBS]; writes OUT/<case>/ (flow.json, frames.csv, shapes) and OUT/summary.csv; the shipped copy keeps flow.json and frames.csv.
set -euo pipefail
trbc="$1"; out="$2"; jobs="${3:-2}"
mkdir -p "$out"
cell="--v 0.94 --mu 4.99 --kb 2.10e-19 --b2 1.84 --level 3 --rotations 10 --threads 1"
cases=()
for etam in 0.3 0.42 0.55 0.69; do
  cases+=("angle239_etam${etam}|--eta-out 23.9 --shear-rate 55 --etam ${etam}")
  cases+=("regime107_etam${etam}|--eta-out 10.7 --shear-rate 39 --etam ${etam}")
done
cases+=("regime107_etam0.69_tilt7|--eta-out 10.7 --shear-rate 39 --etam 0.69 --tilt-deg 7")
printf '%s\n' "${cases[@]}" | xargs -P "$jobs" -I{} bash -c '
  id="${1%%|*}"; args="${1#*|}"
  [ -f "$2/$id/flow.json" ] || "$3" flow shear $args $4 --out "$2/$id" > "$2/$id.log" 2>&1 || echo "$id failed" >&2
' _ {} "$out" "$trbc" "$cell"
python3 - "$out" <<'PY'
import json, sys, pathlib
out = pathlib.Path(sys.argv[1])
rows = ["case,eta_out_mPa_s,shear_rate_per_s,etam_Pa_s_um,tilt_deg,status,regime,inclination_deg,swing_deg,ttf_4pi_f_over_rate"]
for f in sorted(out.glob("*/flow.json")):
    j = json.load(open(f))
    p, o = j.get("parameters", {}), j.get("observables", {})
    c = p.get("cell", {})
    rows.append(",".join(str(x) for x in [f.parent.name, p.get("eta_out_mPa_s", ""), p.get("shear_rate_per_s", ""),
                c.get("etam_Pa_s_um", ""), p.get("tilt_deg", 0), j.get("status", ""), o.get("regime", ""),
                o.get("inclination_deg", ""), o.get("swing_amplitude_deg", ""), o.get("ttf_4pi_f_over_shear_rate", "")]))
(out / "summary.csv").write_text("\n".join(rows) + "\n")
print("\n".join(rows))
PY
