#!/usr/bin/env bash
# Diagnostic shear-flow scans of the Table 1 cell (v 0.94, mu 4.99 uN/m, kb 2.10e-19 J, b2 1.84,
# eta_m 0.69 Pa s um), level 3, 10 rotations (docs/VALIDATION_RESULTS.md, "Membrane viscosity, reduced
# volume and an out-of-plane start at level 3"). Three sets:
#   etam       eta_m in {0.3, 0.42, 0.55, 0.69} Pa s um at 23.9 mPa s / 55 1/s (inclination angle) and
#              10.7 mPa s / 39 1/s (regime), plus the 10.7 mPa s case started 7 deg out of the shear plane
#   threshold  the tumbling / tank-treading threshold at 100 mPa s, at three rates around it (0.5477,
#              0.7401, 1 1/s: the level-3 bracket of the Table 1 cell is [1, 1.41] 1/s, the largest
#              measured critical stress is at 0.59 1/s) for eta_m in {0.3, 0.42, 0.55, 0.69},
#              v in {0.90, 0.94, 0.97} and a start tilted 7 deg out of the shear plane
#   theta_new  the three diagnostic cases (23.9 mPa s / 55 1/s, 10.7 mPa s / 39 1/s, 100 mPa s / 0.7401
#              1/s) for the calibrated cell of the theta_new posterior POSTERIOR (`flow shear --posterior`)
# Usage: scripts/flow_scan.sh TRBC OUT [JOBS] [SET] [POSTERIOR]; SET etam (default), threshold or theta_new
# (which needs POSTERIOR, DIR/inference/phase3/theta_new of `trbc calibrate`). Writes OUT/<case>/
# (flow.json, frames.csv, steps.csv, shapes) and OUT/summary.csv; `make results` keeps all but the shapes,
# the checkpoints and the logs.
set -euo pipefail
trbc="$1"; out="$2"; jobs="${3:-2}"; set="${4:-etam}"; posterior="${5:-}"
mkdir -p "$out"
table1="--mu 4.99 --kb 2.10e-19 --b2 1.84"
common="--level 3 --rotations 10 --threads 1"
cases=()
case "$set" in
  etam)
    for etam in 0.3 0.42 0.55 0.69; do
      cases+=("angle239_etam${etam}|$table1 --v 0.94 --eta-out 23.9 --shear-rate 55 --etam ${etam}")
      cases+=("regime107_etam${etam}|$table1 --v 0.94 --eta-out 10.7 --shear-rate 39 --etam ${etam}")
    done
    cases+=("regime107_etam0.69_tilt7|$table1 --v 0.94 --eta-out 10.7 --shear-rate 39 --etam 0.69 --tilt-deg 7")
    ;;
  threshold)
    for rate in 0.5477 0.7401 1; do
      for etam in 0.3 0.42 0.55 0.69; do
        cases+=("eta100_rate${rate}_etam${etam}|$table1 --v 0.94 --eta-out 100 --shear-rate ${rate} --etam ${etam}")
      done
      for v in 0.90 0.97; do
        cases+=("eta100_rate${rate}_v${v}|$table1 --v ${v} --eta-out 100 --shear-rate ${rate} --etam 0.69")
      done
      cases+=("eta100_rate${rate}_tilt7|$table1 --v 0.94 --eta-out 100 --shear-rate ${rate} --etam 0.69 --tilt-deg 7")
    done
    ;;
  theta_new)
    if [ -z "$posterior" ]; then echo "flow_scan.sh: SET theta_new needs POSTERIOR (DIR/inference/phase3/theta_new)" >&2; exit 2; fi
    case "$posterior" in *[[:space:]\'\"\\]*) echo "flow_scan.sh: POSTERIOR '$posterior' has white space, quotes or backslashes; give a path without" >&2; exit 2 ;; esac
    [ -d "$posterior" ] || [ -f "$posterior" ] || { echo "flow_scan.sh: POSTERIOR '$posterior' does not exist" >&2; exit 2; }
    own="--posterior $posterior"
    cases+=("own_angle239|$own --eta-out 23.9 --shear-rate 55")
    cases+=("own_regime107|$own --eta-out 10.7 --shear-rate 39")
    cases+=("own_eta100_rate0.7401|$own --eta-out 100 --shear-rate 0.7401")
    ;;
  *) echo "flow_scan.sh: SET must be etam, threshold or theta_new, not '$set'" >&2; exit 2 ;;
esac
printf '%s\n' "${cases[@]}" | xargs -P "$jobs" -I{} bash -c '
  id="${1%%|*}"; args="${1#*|}"
  [ -f "$2/$id/flow.json" ] || "$3" flow shear $args $4 --out "$2/$id" > "$2/$id.log" 2>&1 || echo "$id failed" >&2
' _ {} "$out" "$trbc" "$common"
python3 - "$out" <<'PY'
import json, sys, pathlib
out = pathlib.Path(sys.argv[1])
rows = ["case,eta_out_mPa_s,shear_rate_per_s,v,etam_Pa_s_um,tilt_deg,status,regime,inclination_deg,swing_deg,ttf_4pi_f_over_rate"]
for f in sorted(out.glob("*/flow.json")):
    j = json.load(open(f))
    p, o = j.get("parameters", {}), j.get("observables", {})
    c = p.get("cell", {})
    rows.append(",".join(str(x) for x in [f.parent.name, p.get("eta_out_mPa_s", ""), p.get("shear_rate_per_s", ""),
                c.get("v", ""), c.get("etam_Pa_s_um", ""), p.get("tilt_deg", 0), j.get("status", ""), o.get("regime", ""),
                o.get("inclination_deg", ""), o.get("swing_amplitude_deg", ""), o.get("ttf_4pi_f_over_shear_rate", "")]))
(out / "summary.csv").write_text("\n".join(rows) + "\n")
print("\n".join(rows))
PY
# A case without its flow.json failed (its log says why): the scan is incomplete.
missing=0
for c in "${cases[@]}"; do id="${c%%|*}"; [ -f "$out/$id/flow.json" ] || { echo "flow_scan.sh: $id has no flow.json (see $out/$id.log)" >&2; missing=1; }; done
exit "$missing"
