#!/usr/bin/python3
"""The equilibrium's two branches near v = 1 (docs/EQUILIBRIUM.md "The lowest-energy equilibrium").

For a grid of (v, FvK) at the other parameters of the reference point (mu 4, b2 1.5), runs
``trbc simulate --experiments eq`` twice: with ``--equilibrium-symmetry inversion`` (the dimpled
disc) and with the default ``--equilibrium-symmetry lowest`` (the lowest-energy state of the disc
and the seeded thermal kicks of it). Writes

  OUT/branch_map.csv   one row per (v, FvK): D, hmin, hmax and energy of both branches, the chosen
                       branch, the energy gap, the kicks' rms and what the search cost
  OUT/command.txt      the command that made it
  FIG                  hmin, hmax, D against v for both branches, one line per FvK, and the
                       (v, FvK) plane with the relative energy gap, the switch marked

Usage:
  scripts/branch_map.py [--trbc build/trbc] [--level 3] [--v 0.95,0.97,...] [--fvk 10,50,...]
                        [--out results/branch_map] [--figure results/branch_map/branch_map.png] [--jobs 2]

Rows already in OUT/branch_map.csv with the same level are kept (a killed run continues).
Only numpy and matplotlib are needed.
"""

import argparse
import csv
import json
import os
import shlex
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
DEFAULT_V = "0.95,0.96,0.97,0.98,0.985,0.99,0.993,0.995,0.997,0.999"
DEFAULT_FVK = "10,25,50,100,122,200,400,1000"
COLUMNS = ["level", "v", "FvK", "v_sfs",
           "D_um_disc", "hmin_um_disc", "hmax_um_disc", "energy_J_disc",
           "D_um_lowest", "hmin_um_lowest", "hmax_um_lowest", "energy_J_lowest",
           "branch", "energy_gap_J", "energy_gap_rel", "kick_rms_um", "kick_rounds",
           "evaluations_disc", "evaluations_lowest", "wall_s_disc", "wall_s_lowest"]


def simulate(trbc, level, v, fvk, symmetry):
    cmd = [trbc, "simulate", "--experiments", "eq", "--level", str(level), "--v", repr(v), "--FvK", repr(fvk),
           "--mu", "4", "--b2", "1.5", "--equilibrium-symmetry", symmetry, "--threads", "1"]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True, env={**os.environ, "OMP_NUM_THREADS": "1"})
    return json.loads(out.stdout)


def point(trbc, level, v, fvk):
    disc = simulate(trbc, level, v, fvk, "inversion")
    low = simulate(trbc, level, v, fvk, "lowest")
    od, ol = disc["observables"], low["observables"]
    ed, el = disc["diagnostics"]["equilibrium"], low["diagnostics"]["equilibrium"]
    gap = el["energy_gap_J"]
    return {"level": level, "v": v, "FvK": fvk, "v_sfs": disc["diagnostics"]["sfs"]["v_imposed"],
            "D_um_disc": od["D_um"], "hmin_um_disc": od["hmin_um"], "hmax_um_disc": od["hmax_um"],
            "energy_J_disc": ed["energy_J"],
            "D_um_lowest": ol["D_um"], "hmin_um_lowest": ol["hmin_um"], "hmax_um_lowest": ol["hmax_um"],
            "energy_J_lowest": el["energy_J"], "branch": el["branch"], "energy_gap_J": gap,
            "energy_gap_rel": gap / ed["energy_J"], "kick_rms_um": el["kick_rms_um"],
            "kick_rounds": max(c["round"] for c in el["candidates"]),
            "evaluations_disc": ed["force_evaluations"], "evaluations_lowest": el["force_evaluations"],
            "wall_s_disc": ed["wall_s"], "wall_s_lowest": el["wall_s"]}


def read_rows(path, level):
    if not path.exists():
        return {}
    with open(path) as f:
        rows = [r for r in csv.DictReader((ln for ln in f if not ln.startswith("#"))) if int(r["level"]) == level]
    return {(float(r["v"]), float(r["FvK"])): r for r in rows}


def write_rows(path, rows):
    tmp = path.with_suffix(".tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS)
        w.writeheader()
        for key in sorted(rows):
            w.writerow({k: rows[key][k] for k in COLUMNS})
    tmp.replace(path)


def plot(rows, figure, level):
    vs = sorted({k[0] for k in rows})
    fvks = sorted({k[1] for k in rows})
    fig, axes = plt.subplots(2, 2, figsize=(12, 9))
    axes = axes.ravel()
    cmap = plt.get_cmap("viridis")
    for i, fvk in enumerate(fvks):
        color = cmap(i / max(1, len(fvks) - 1))
        for ax, q in zip(axes[:3], ("hmin_um", "hmax_um", "D_um")):
            d = [float(rows[(v, fvk)][q + "_disc"]) for v in vs]
            lo = [float(rows[(v, fvk)][q + "_lowest"]) for v in vs]
            ax.plot(vs, d, "--", color=color, lw=1)
            ax.plot(vs, lo, "-", color=color, lw=1.6, label=f"FvK {fvk:g}")
            switched = [v for v in vs if rows[(v, fvk)]["branch"] != "symmetric"]
            if switched:
                ax.plot(switched, [float(rows[(v, fvk)][q + "_lowest"]) for v in switched], "o", color=color, ms=4)
    for ax, q in zip(axes[:3], ("hmin (um)", "hmax (um)", "D (um)")):
        ax.set_xlabel("v (SFS)")
        ax.set_ylabel(q)
    axes[0].set_title("solid: lowest energy (dots: kicked branch), dashed: symmetric disc", fontsize=9)
    axes[0].legend(fontsize=7)
    ax = axes[3]
    V, F = np.meshgrid(vs, fvks)
    gap = np.array([[100 * float(rows[(v, f)]["energy_gap_rel"]) for v in vs] for f in fvks])
    pc = ax.pcolormesh(np.arange(len(vs) + 1), np.arange(len(fvks) + 1), gap, cmap="magma_r", shading="flat")
    for j, f in enumerate(fvks):
        for i, v in enumerate(vs):
            r = rows[(v, f)]
            ax.text(i + 0.5, j + 0.5, "disc" if r["branch"] == "symmetric" else f"{gap[j, i]:.1f}",
                    ha="center", va="center", fontsize=6, color="k" if gap[j, i] < 4 else "w")
    ax.set_xticks(np.arange(len(vs)) + 0.5, [f"{v:g}" for v in vs], rotation=60, fontsize=7)
    ax.set_yticks(np.arange(len(fvks)) + 0.5, [f"{f:g}" for f in fvks], fontsize=7)
    ax.set_xlabel("v")
    ax.set_ylabel("FvK")
    ax.set_title("energy gap disc - lowest (% of the disc's)", fontsize=9)
    fig.colorbar(pc, ax=ax)
    fig.suptitle(f"Equilibrium branches near v = 1 (level {level}, mu 4 uN/m, b2 1.5)")
    fig.tight_layout()
    fig.savefig(figure, dpi=130)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--trbc", default=str(REPO / "build" / "trbc"))
    ap.add_argument("--level", type=int, default=3)
    ap.add_argument("--v", default=DEFAULT_V, help="comma-separated reduced volumes")
    ap.add_argument("--fvk", default=DEFAULT_FVK, help="comma-separated FvK numbers")
    ap.add_argument("--out", default=str(REPO / "results" / "branch_map"))
    ap.add_argument("--figure", default=str(REPO / "results" / "branch_map" / "branch_map.png"))
    ap.add_argument("--jobs", type=int, default=2, help="points computed at once")
    a = ap.parse_args()
    if not 2 <= a.level <= 6:
        sys.exit(f"--level {a.level} is outside [2, 6]")
    if a.jobs < 1:
        sys.exit(f"--jobs {a.jobs} must be >= 1")
    vs = [float(x) for x in a.v.split(",")]
    fvks = [float(x) for x in a.fvk.split(",")]
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    csv_path = out / "branch_map.csv" if a.level == 3 else out / f"branch_map_L{a.level}.csv"
    rows = read_rows(csv_path, a.level)
    todo = [(v, f) for v in vs for f in fvks if (v, f) not in rows]
    with ThreadPoolExecutor(a.jobs) as pool:
        for key, row in zip(todo, pool.map(lambda k: point(a.trbc, a.level, *k), todo)):
            rows[key] = row
            print(f"v {key[0]:g} FvK {key[1]:g}: {row['branch']}, gap {100 * row['energy_gap_rel']:.2f} %, "
                  f"hmin {row['hmin_um_disc']:.3f} -> {row['hmin_um_lowest']:.3f} um", file=sys.stderr)
            write_rows(csv_path, rows)
    (out / ("command.txt" if a.level == 3 else f"command_L{a.level}.txt")).write_text(
        " ".join(shlex.quote(x) for x in [os.path.relpath(__file__, REPO)] + sys.argv[1:]) + "\n")
    selected = {k: r for k, r in rows.items() if k[0] in vs and k[1] in fvks}
    if len(selected) == len(vs) * len(fvks) and len(vs) > 1 and len(fvks) > 0:
        plot(selected, a.figure, a.level)


if __name__ == "__main__":
    main()
