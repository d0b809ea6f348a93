#!/usr/bin/env bash
# make showcase: a short tour of the membrane engine and the forward model.
#  1. a level-4 icosphere (Nv = 2562) and the Evans-Fung resting cell, scaled to A0 = 135 um^2;
#  2. forces of the full model on the cell (cross-check command);
#  3. relaxation of a sphere to the biconcave discocyte at reduced volume 0.64 (the dimensionless units of docs/MEMBRANE_MODEL.md);
#  4. one forward-model sample at the reference point with a stretching curve, and its figures
#     (scripts/plot_forward.py, with trbc's Python module from this build).
# Outputs go to out/showcase/ (VTK files open in ParaView with force, mean curvature and area fields).
set -euo pipefail
cd "$(dirname "$0")/.."
T=build/trbc
O=out/showcase
mkdir -p "$O"
# One thread by default: at Nv = 2562 a second thread gains little, and a busy second core makes
# OpenMP barriers spin.
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1}

echo "== icosphere L4 and Evans-Fung cell (A = 135 um^2)"
$T mesh icosphere --level 4 --out "$O/sphere_L4.off" > "$O/sphere_L4.json"
$T mesh icosphere --level 4 --biconcave --area 135 --out "$O/evans_fung_L4.off" > "$O/evans_fung_L4.json"
$T mesh icosphere --level 4 --biconcave --area 135 --out "$O/evans_fung_L4.vtk" > /dev/null
python3 -c "import json;d=json.load(open('$O/evans_fung_L4.json'));print(f\"   Nv={d['vertices']}  A={d['area']:.3f} um^2  V={d['volume']:.3f} um^3  v={d['reduced_volume']:.4f}\")"

echo "== forces of the full model on the Evans-Fung cell (kb = 0.0429 pN um, mu = 4 uN/m, SFS = sphere)"
$T mesh icosphere --level 4 --area 135 --out "$O/sphere_L4_135.off" > /dev/null
$T forces --mesh "$O/evans_fung_L4.off" --reference "$O/sphere_L4_135.off" \
  --kb 0.0429 --ka 4 --a3 -2 --a4 8 --mu 4 --b1 0.7 --b2 1.5 \
  --kA 5e5 --A0 135 --kV 7.23e5 --V0 94 --out "$O/evans_fung_forces.csv" | tee "$O/evans_fung_energy.json"

echo "== sphere -> discocyte at v = 0.64 (bending + Lim + area + volume, the dimensionless units of docs/MEMBRANE_MODEL.md)"
$T minimize --mesh "$O/sphere_L4.off" --reference "$O/sphere_L4.off" \
  --kb 1 --ka 11.140846 --a3 -2 --a4 8 --mu 2.228169 --b1 0.7 --b2 0.75 \
  --kA 1e4 --kV 1e4 --A0 12.566370614359172 --reduced-volume 0.64 --oblate-seed 0.8 \
  --tol 1e-6 --out "$O/discocyte_L4.vtk" > "$O/discocyte_L4.json"
python3 - "$O/discocyte_L4.json" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
g, m = d["diagnostics"], d["mesh"]
e = m["principal_extents"]
print(f"   converged={g['converged']} iterations={g['iterations']} max force={g['max_vertex_force']:.2e} "
      f"wall={g['wall_s']:.2f} s")
print(f"   v={m['reduced_volume']:.4f}  extents={e[0]:.3f} x {e[1]:.3f} x {e[2]:.3f} (units of R_A')")
PY
echo "== forward model at the reference point (level 4): SFS, equilibrium, stretching curve, relaxation"
$T simulate --level 4 --force-curve 0,16.4,30.78,47.6,67.2,88.3,108.9,130.3,150.5,173.1,193.1 \
  --save-shapes "$O/simulate_L4" > "$O/simulate_L4.json"
python3 - "$O/simulate_L4.json" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
o, t = d["observables"], d["diagnostics"]["total"]
print("   " + "  ".join(f"{k}={v:.4g}" for k, v in o.items()))
print(f"   {t['force_evaluations']} force evaluations ({t['reduction_factor']:.0f}x fewer than the reference protocol), "
      f"{t['wall_s']:.2f} s")
PY
# plot_forward.py takes the Evans-Fung shape and the Hochmuth fit from trbc's Python module: the
# package sources in src/python with the extension module of this build (build/python).
export PYTHONPATH="$PWD/src/python:$PWD/build/python${PYTHONPATH:+:$PYTHONPATH}"
if ! /usr/bin/python3 -c "import matplotlib" 2>/dev/null; then
  echo "   figures skipped: matplotlib is not installed for /usr/bin/python3"
elif ! /usr/bin/python3 -c "import trbc; trbc.fit_hochmuth" 2>/dev/null; then
  echo "   figures skipped: trbc's Python module is not built (cmake -DTRBC_BUILD_PYTHON=ON, target trbc_python)"
else
  /usr/bin/python3 scripts/plot_forward.py "$O/simulate_L4" --out "$O/figures" > /dev/null
  echo "   figures in $O/figures/"
fi
echo "demo outputs in $O/ (open the .vtk files in ParaView)"
