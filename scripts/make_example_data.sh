#!/usr/bin/env bash
# Makes data/examples/synthetic_stretching.csv: an optical-tweezers stretching curve of a virtual
# cell with known parameters (trbc simulate, level 4), in the format of the experimental stretching
# files (Fext, D0, D1). configs/own_data.toml uses it to show how a user swaps in a data set of
# their own; because the truth is known, the calibration's answer can be checked against it.
set -euo pipefail
cd "$(dirname "$0")/.."
T=${TRBC:-build/trbc}
out=data/examples/synthetic_stretching.csv
cmd="$T simulate --v 0.92 --mu 6 --FvK 300 --b2 1.5 --etam 0.7 --Fext 0 --force-curve 20,40,60,80,100,120,140,160,180,200 --experiments eq,stretch --level 4"
json=$($cmd)
/usr/bin/python3 - "$out" "$cmd" <<PY
import json, sys
d = json.loads('''$json''')
rows = [(0.0, d["observables"]["D0_um"], d["observables"]["D1_um"])]
rows += [(p["Fext_pN"], p["D0_um"], p["D1_um"]) for p in d["stretching_curve"]]
with open(sys.argv[1], "w") as f:
    f.write(f"# synthetic stretching data of a virtual cell (v 0.92, mu 6 uN/m, FvK 300, b2 1.5), trbc {d['provenance']['version']}\n")
    f.write(f"# made by scripts/make_example_data.sh: {sys.argv[2]}\n")
    f.write("Fext,D0,D1\n")
    for F, d0, d1 in rows:
        f.write(f"{F:g},{d0:.4f},{d1:.4f}\n")
print(f"wrote {sys.argv[1]} ({len(rows)} forces)")
PY
