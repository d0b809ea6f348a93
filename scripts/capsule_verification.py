#!/usr/bin/env python3
"""The capsule verification set of docs/flow_verification.md: `trbc flow capsule` over the cases
below, two at a time, each result kept as OUT/cases/<id>.json (a re-run skips finished cases),
then OUT/capsule_table.md and OUT/cases.csv.

    scripts/capsule_verification.py --trbc build/trbc --out results/flow_verification/capsule [--jobs 2] [--dry-run]

Cases: the small-deformation law for three in-plane laws and three viscosity ratios at Ca = 0.01
(levels 3 and 4), Ca = 0.005 and 0.02 at level 3, the regularising bending's own effect (EB 1e-3
and 2e-3), the finite-Ca neo-Hookean deformation at Ca = 0.075-0.6 (levels 3 and 4), the bending
case of Pozrikidis (2001), and the membrane-viscosity trend. Every run without a bending modulus
of its own carries EB = 1e-3: without bending the compressed part of the membrane wrinkles at the
grid scale (Lac et al. 2004) and D12 does not settle."""
import argparse
import concurrent.futures
import csv
import json
import os
import subprocess
import sys
import time

REG = 1e-3  # regularising bending E_b / (a^2 G_s)
SLOPE = {"neo-hookean": 25.0 / 12.0, "skalak": 25.0 / 12.0, "lim": 2.5}  # (5/8)(3 + G_s/K_s)


def cases():
    out = []

    def add(group, law, ca, lam, level, eb=REG, em=0.0, strain=6.0):
        cid = f"{group}_{law}_ca{ca:g}_lam{lam:g}_eb{eb:g}_em{em:g}_L{level}"
        out.append(dict(id=cid, group=group, law=law, ca=ca, lam=lam, level=level, eb=eb, em=em, strain=strain))

    for level in (3, 4):
        for law in ("neo-hookean", "skalak", "lim"):
            for lam in (0.2, 1.0, 5.0):
                add("small", law, 0.01, lam, level)
        add("regularisation", "neo-hookean", 0.01, 1.0, level, eb=2 * REG)
    for ca in (0.005, 0.02):
        add("small", "neo-hookean", ca, 1.0, 3)
    for level in (3, 4):
        for ca in (0.075, 0.15, 0.3, 0.6):
            add("finite", "neo-hookean", ca, 1.0, level, strain=12.0)
        add("bending", "neo-hookean", 0.15, 1.0, level, eb=0.1125, strain=12.0)
    for em in (1.0, 3.0):
        add("viscosity", "neo-hookean", 0.075, 1.0, 3, em=em, strain=12.0)
    return out


def command(trbc, c):
    cmd = [trbc, "flow", "capsule", "--law", c["law"], "--ca", f"{c['ca']:g}", "--viscosity-ratio", f"{c['lam']:g}",
           "--bending", f"{c['eb']:g}", "--membrane-viscosity", f"{c['em']:g}", "--level", str(c["level"]),
           "--strain", f"{c['strain']:g}", "--threads", "1"]
    if c["law"] == "skalak":
        cmd += ["--skalak-c", "1"]
    return cmd


def run(trbc, outdir, c):
    """(case id, whether it has a record, what happened)."""
    path = os.path.join(outdir, "cases", c["id"] + ".json")
    if os.path.exists(path):
        return c["id"], True, "finished earlier"
    t0 = time.time()
    p = subprocess.run(command(trbc, c), capture_output=True, text=True)
    if p.returncode != 0:
        return c["id"], False, f"failed (exit {p.returncode}): {p.stderr.strip()[-300:]}"
    try:
        j = json.loads(p.stdout)
    except json.JSONDecodeError as e:
        return c["id"], False, f"failed: its output is not a JSON record ({e})"
    j.pop("series", None)  # the observables and diagnostics are kept; the series is re-made by the command
    tmp = path + f".tmp.{os.getpid()}"
    with open(tmp, "w") as f:
        json.dump({"case": c, "result": j}, f, indent=1)
    os.replace(tmp, path)
    return c["id"], True, f"done in {time.time() - t0:.0f} s"


def table(outdir, command_line):
    rows = []
    for c in cases():
        path = os.path.join(outdir, "cases", c["id"] + ".json")
        if not os.path.exists(path):
            continue
        r = json.load(open(path))["result"]
        o, d = r["observables"], r["diagnostics"]
        rows.append(dict(c, D12=o["taylor_D12"], theta_deg=o["inclination_deg"], omega_over_rate=o["membrane_frequency_over_rate"],
                         steady=o["steady_state_reached"], area_change=o["area_change"], steps=d["steps"], wall_s=d["wall_s"],
                         vertices=r["provenance"]["vertices"], version=r["provenance"]["version"],
                         revision=r["provenance"].get("revision", "not recorded")))
    with open(os.path.join(outdir, "cases.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
        w.writeheader()
        w.writerows(rows)
    get = {(r["group"], r["law"], r["ca"], r["lam"], r["eb"], r["em"], r["level"]): r for r in rows}
    revisions = ", ".join(sorted({r["revision"] for r in rows}))  # more than one: cases of different builds
    md = ["# Capsule verification", "", f"Command: `{command_line}`; trbc {rows[0]['version']} (revision {revisions}). "
          "Regularising bending EB = 1e-3 unless stated.", "", "## Small deformation, Ca = 0.01: D12 / Ca against (5/8)(3 + G_s/K_s)", "",
          "| law | lambda | theory | level 3 | level 4 | deviation L3 / L4 | theta L4 (deg) | omega / rate L4 |", "|---|---|---|---|---|---|---|---|"]
    for law in ("neo-hookean", "skalak", "lim"):
        for lam in (0.2, 1.0, 5.0):
            r3, r4 = get.get(("small", law, 0.01, lam, REG, 0.0, 3)), get.get(("small", law, 0.01, lam, REG, 0.0, 4))
            s = SLOPE[law]
            f3 = f"{r3['D12'] / 0.01:.4f}" if r3 else "-"
            f4 = f"{r4['D12'] / 0.01:.4f}" if r4 else "-"
            dev = " / ".join(f"{100 * (r['D12'] / 0.01 / s - 1):+.2f} %" if r else "-" for r in (r3, r4))
            md.append(f"| {law} | {lam:g} | {s:.4f} | {f3} | {f4} | {dev} | "
                      f"{r4['theta_deg']:.2f} | {r4['omega_over_rate']:.4f} |" if r4 else f"| {law} | {lam:g} | {s:.4f} | {f3} | - | {dev} | - | - |")
    md += ["", "## The regularising bending's effect (neo-Hookean, lambda = 1, Ca = 0.01)", "",
           "| level | D12/Ca, EB 1e-3 | D12/Ca, EB 2e-3 | linear extrapolation to EB = 0 | deviation |", "|---|---|---|---|---|"]
    for level in (3, 4):
        a, b = get.get(("small", "neo-hookean", 0.01, 1.0, REG, 0.0, level)), get.get(("regularisation", "neo-hookean", 0.01, 1.0, 2 * REG, 0.0, level))
        if a and b:
            x = 2 * a["D12"] / 0.01 - b["D12"] / 0.01
            md.append(f"| {level} | {a['D12'] / 0.01:.4f} | {b['D12'] / 0.01:.4f} | {x:.4f} | {100 * (x / SLOPE['neo-hookean'] - 1):+.2f} % |")
    md += ["", "## Ca -> 0 (neo-Hookean, lambda = 1, level 3)", "", "| Ca | D12 / Ca | theta (deg) | omega / rate |", "|---|---|---|---|"]
    for ca in (0.005, 0.01, 0.02):
        r = get.get(("small", "neo-hookean", ca, 1.0, REG, 0.0, 3))
        if r:
            md.append(f"| {ca:g} | {r['D12'] / ca:.4f} | {r['theta_deg']:.2f} | {r['omega_over_rate']:.4f} |")
    md += ["", "## Finite deformation (neo-Hookean, lambda = 1)", "", "| Ca | D12 level 3 | D12 level 4 | theta L3 / L4 (deg) | steady L3 / L4 |", "|---|---|---|---|---|"]
    for ca in (0.075, 0.15, 0.3, 0.6):
        r3, r4 = get.get(("finite", "neo-hookean", ca, 1.0, REG, 0.0, 3)), get.get(("finite", "neo-hookean", ca, 1.0, REG, 0.0, 4))
        fmt = lambda r, k, p: f"{r[k]:.{p}f}" if r else "-"
        md.append(f"| {ca:g} | {fmt(r3, 'D12', 4)} | {fmt(r4, 'D12', 4)} | {fmt(r3, 'theta_deg', 2)} / {fmt(r4, 'theta_deg', 2)} | "
                  f"{r3['steady'] if r3 else '-'} / {r4['steady'] if r4 else '-'} |")
    md += ["", "## Bending (neo-Hookean, Ca = 0.15, E_b/(a^2 G_s) = 0.1125, i.e. Ca_E = 0.05, E_b/(a^2 E_s) = 0.0375)", "",
           "| level | D12 | theta (deg) |", "|---|---|---|"]
    for level in (3, 4):
        r = get.get(("bending", "neo-hookean", 0.15, 1.0, 0.1125, 0.0, level))
        if r:
            md.append(f"| {level} | {r['D12']:.4f} | {r['theta_deg']:.2f} |")
    md += ["", "## Membrane viscosity (neo-Hookean, Ca = 0.075, lambda = 1, level 3)", "", "| EM | D12 | theta (deg) | omega / rate |", "|---|---|---|---|"]
    for em in (0.0, 1.0, 3.0):
        r = get.get(("finite" if em == 0.0 else "viscosity", "neo-hookean", 0.075, 1.0, REG, em, 3))
        if r:
            md.append(f"| {em:g} | {r['D12']:.4f} | {r['theta_deg']:.2f} | {r['omega_over_rate']:.4f} |")
    md += ["", "## Cost", "", f"{len(rows)} cases, {sum(r['wall_s'] for r in rows) / 60:.1f} min of single-thread wall time in all "
           f"(level 4: {sum(r['wall_s'] for r in rows if r['level'] == 4) / 60:.1f} min).", ""]
    with open(os.path.join(outdir, "capsule_table.md"), "w") as f:
        f.write("\n".join(md))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--trbc", default="build/trbc")
    ap.add_argument("--out", default="results/flow_verification/capsule")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--dry-run", action="store_true")
    ap.add_argument("--table-only", action="store_true", help="only gather the finished cases into the tables")
    a = ap.parse_args()
    os.makedirs(os.path.join(a.out, "cases"), exist_ok=True)
    todo = cases()
    if a.dry_run:
        for c in todo:
            done = os.path.exists(os.path.join(a.out, "cases", c["id"] + ".json"))
            print(("[finished] " if done else "") + " ".join(command(a.trbc, c)))
        return 0
    if not a.table_only:
        # The level-4 cases first: they set the wall time.
        todo.sort(key=lambda c: -c["level"])
        failed = []
        with concurrent.futures.ThreadPoolExecutor(max_workers=a.jobs) as pool:
            for cid, ok, status in pool.map(lambda c: run(a.trbc, a.out, c), todo):
                print(f"capsule_verification: {cid}: {status}", flush=True)
                if not ok:
                    failed.append(cid)
    if not any(os.path.exists(os.path.join(a.out, "cases", c["id"] + ".json")) for c in todo):
        print(f"capsule_verification: no finished case in {a.out}/cases: no table", file=sys.stderr)
        return 1
    table(a.out, " ".join(["scripts/capsule_verification.py"] + sys.argv[1:]))
    print(f"capsule_verification: tables in {a.out}/capsule_table.md and cases.csv")
    if not a.table_only and failed:
        # The table lacks their rows: not a complete set (a re-run repeats only these).
        print(f"capsule_verification: {len(failed)} case(s) failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
