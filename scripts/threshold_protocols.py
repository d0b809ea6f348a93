#!/usr/bin/env python3
"""The tumbling / tank-treading threshold under three protocols (docs/FLOW_THERMAL.md): the
in-plane start (the disc exactly in the shear plane), the ensemble start (`--start random`,
MEMBERS seeds per flow condition, scored as the fraction that tank-treads) and the fluctuating
cell (`--temperature 293.15` from the in-plane start, FLUCTUATING seeds per flow condition). Each case is one
`trbc flow shear` run kept as OUT/cases/<id>/flow.json (a re-run skips finished cases, so the scan
resumes after a kill), then OUT/cases.csv, OUT/fractions.csv and OUT/threshold_table.md.

    scripts/threshold_protocols.py --trbc build/trbc --out results/threshold_protocols [--level 3]
        [--members 8] [--fluctuating 0] [--thermal-step 0.2] [--jobs 2] [--full-length] [--cells reference,table1,theta_new] [--viscosities 10.7,23.9,30,100]
        [--protocols in-plane,ensemble,fluctuating] [--descend] [--posterior DIR] [--dry-run]

Cells: the reference implementation's shear set-up (Table 1 means for mu, kappa_b, b2; eta_m 0.42
Pa s um; v 0.95), the paper's Table 1 means, and theta_new: the calibrated cell of --posterior
(trbc.calibrated_cell, the cell of every trbc command's --posterior). A kept case whose record
holds another cell (another posterior) runs again. Stresses: six per
outer viscosity, log-spaced over the range where that viscosity's thresholds lie.

The critical stress of a protocol is where the tank-treading fraction crosses 1/2, interpolated
in log stress between the two bracketing stresses; its standard error comes from a parametric
bootstrap of the fractions (binomial, 2000 resamples, seed 1). The in-plane start has one member
per stress and gives a bracket only.

With --descend the fluctuating cases of a cell and viscosity run one stress at a time, from the
lowest stress at which the in-plane start tank-treads, downwards until no seed tank-treads (upwards
if none does at the start). Fluctuations only lower the threshold in every row measured, so the
stresses left out lie where the fraction is already 0 or 1; the table lists the stresses run."""
import argparse
import concurrent.futures
import csv
import json
import math
import os
import random
import subprocess
import sys
import time

CELLS = {
    "reference": dict(v=0.95, mu=4.99, kb=2.10e-19, b2=1.84, etam=0.42),
    "table1": dict(v=0.94, mu=4.99, kb=2.10e-19, b2=1.84, etam=0.69),
}  # "theta_new" comes from --posterior
# Shear stresses (Pa) per outer viscosity (mPa s): around the brackets that the in-plane start found.
STRESS_RANGE = {10.7: (0.2, 1.5), 23.9: (0.03, 0.25), 30.0: (0.03, 0.25), 100.0: (0.03, 0.2)}
ETA_IN = 10.0


def logspace(lo, hi, n):
    return [lo * (hi / lo) ** (k / (n - 1)) for k in range(n)]


def cases(cells, viscosities, members, fluctuating, level, rotations):
    out = []
    for cell in cells:
        for eta in viscosities:
            for stress in logspace(*STRESS_RANGE[eta], 6):
                rate = stress / (eta * 1e-3)
                base = dict(cell=cell, eta=eta, stress=stress, rate=rate, level=level, rotations=rotations)
                out.append(dict(base, protocol="in-plane", seed=0, id=f"{cell}_eta{eta:g}_tau{stress:.4g}_inplane"))
                for seed in range(1, members + 1):
                    out.append(dict(base, protocol="ensemble", seed=seed, id=f"{cell}_eta{eta:g}_tau{stress:.4g}_s{seed}"))
                for seed in range(1, fluctuating + 1):
                    out.append(dict(base, protocol="fluctuating", seed=seed, id=f"{cell}_eta{eta:g}_tau{stress:.4g}_T{seed}"))
    return out


THERMAL_STEP = 0.2
STOP_WHEN_STEADY = True
# Cheap, decisive cases first: the in-plane table is complete before the first ensemble member runs.
PROTOCOL_ORDER = {"in-plane": 0, "ensemble": 1, "fluctuating": 2}


def command(trbc, c, out):
    p = CELLS[c["cell"]]
    cmd = [trbc, "flow", "shear", "--eta-out", f"{c['eta']:g}", "--shear-rate", repr(c["rate"]), "--eta-in", f"{ETA_IN:g}",
           "--level", str(c["level"]), "--rotations", f"{c['rotations']:g}", "--threads", "1",
           "--v", repr(p["v"]), "--mu", repr(p["mu"]), "--kb", repr(p["kb"]), "--b2", repr(p["b2"]), "--etam", repr(p["etam"]),
           "--vtk-every", "1000000", "--out", os.path.join(out, "cases", c["id"])]
    if STOP_WHEN_STEADY:
        cmd += ["--stop-when-steady"]
    if c["protocol"] == "ensemble":
        cmd += ["--start", "random", "--seed", str(c["seed"])]
    if c["protocol"] == "fluctuating":
        cmd += ["--temperature", "293.15", "--thermal-step", f"{THERMAL_STEP:g}", "--seed", str(c["seed"])]
    return cmd


RECORD_CELL = {"v": "v", "mu": "mu_uN_per_m", "kb": "kb_J", "b2": "b2", "etam": "etam_Pa_s_um"}


def same_cell(recorded, p):
    """The record's parameters.cell is the cell p, to 1e-9 relative (a record without it is not)."""
    return all(RECORD_CELL[k] in recorded and abs(recorded[RECORD_CELL[k]] - p[k]) <= 1e-9 * abs(p[k]) for k in RECORD_CELL)


def finished_record(out, c):
    """The case's record when it is one of the current cell and protocol, else None. A fluctuating
    case made before trbc capped the thermal step at eta_m/mu (its record lacks
    diagnostics.thermal.step_times_rate), where the cap shortens the step, is not."""
    try:
        with open(os.path.join(out, "cases", c["id"], "flow.json")) as fh:
            j = json.load(fh)
    except (OSError, ValueError):
        return None
    return j if is_current(j, c) else None


def finished(out, c):
    return finished_record(out, c) is not None


def is_current(j, c):
    p = CELLS[c["cell"]]
    if not same_cell(j.get("parameters", {}).get("cell", {}), p):
        return False
    if c["protocol"] != "fluctuating" or THERMAL_STEP <= c["rate"] * p["etam"] / p["mu"]:
        return True
    return "step_times_rate" in j.get("diagnostics", {}).get("thermal", {}) or j.get("thermal_step_capped", False)


def run(trbc, c, out):
    d = os.path.join(out, "cases", c["id"])
    if finished(out, c):
        return c["id"], "kept", 0.0
    if os.path.exists(os.path.join(d, "flow.json")):  # another cell or the uncapped step: kept aside, run again
        aside, k = d + time.strftime(".replaced-%Y%m%dT%H%M%S"), 1
        while os.path.exists(aside):
            aside, k = f"{d}{time.strftime('.replaced-%Y%m%dT%H%M%S')}-{k}", k + 1
        os.replace(d, aside)
    t0 = time.time()
    r = subprocess.run(command(trbc, c, out), capture_output=True, text=True)
    if r.returncode < 0:  # killed by a signal: not a result, the next run repeats the case
        return c["id"], f"killed (signal {-r.returncode})", time.time() - t0
    if r.returncode != 0 and not os.path.exists(os.path.join(d, "flow.json")):
        os.makedirs(d, exist_ok=True)
        with open(os.path.join(d, "flow.json"), "w") as f:
            p = CELLS[c["cell"]]
            json.dump({"status": "failed", "reason": r.stderr.strip().splitlines()[-1:] or ["exit %d" % r.returncode],
                       "observables": {"regime": None}, "thermal_step_capped": c["protocol"] == "fluctuating",
                       "parameters": {"cell": {RECORD_CELL[k]: p[k] for k in RECORD_CELL}}}, f)
    return c["id"], "ran", time.time() - t0


def descend_row(trbc, out, row, inplane, log):
    """Run one row's fluctuating cases stress by stress (see --descend); returns the cases run."""
    stresses = sorted({c["stress"] for c in row})
    tt = [c["stress"] for c in inplane if regime(out, c)[0] == "tank-treading"]
    k = stresses.index(min(tt)) if tt else len(stresses) - 1
    step, ran = 0, 0
    while 0 <= k < len(stresses):
        seeds = [c for c in row if c["stress"] == stresses[k]]
        for c in seeds:
            cid, what, wall = run(trbc, c, out)
            ran += what == "ran"
            log(cid, what, wall)
        res = [regime(out, c) for c in seeds]
        finished_ = [r for r, st in res if st == "ok"]
        # A killed seed leaves the row to the next run; a failed one counts in neither the members
        # nor the fraction (as in the tables), so the seeds that finished decide the direction.
        if any(st is None for _, st in res) or not finished_:
            break
        n_tt = sum(r == "tank-treading" for r in finished_)
        if step == 0:
            step = 1 if n_tt == 0 else -1
        if (step < 0 and n_tt == 0) or (step > 0 and n_tt > 0):
            break
        k += step
    return ran


def regime(out, c):
    """(regime, status) of a finished case, (None, None) otherwise."""
    j = finished_record(out, c)
    return (None, None) if j is None else (j.get("observables", {}).get("regime"), j.get("status"))


def crossing(stresses, fractions):
    """log-stress where the fraction first crosses 1/2 going up; None without a crossing."""
    for k in range(len(stresses) - 1):
        f0, f1 = fractions[k], fractions[k + 1]
        if f0 < 0.5 <= f1:
            w = (0.5 - f0) / (f1 - f0)
            return math.exp(math.log(stresses[k]) + w * (math.log(stresses[k + 1]) - math.log(stresses[k])))
    return None


def provenance_line(revisions, all_cases, command):
    """The table's first line: the command, the builds' revisions of the finished records, the cells."""
    revisions = sorted(r for r in revisions if r) or ["not recorded"]
    cells = "; ".join(f"{name}: " + ", ".join(f"{k} {CELLS[name][k]:.6g}" for k in RECORD_CELL)
                      for name in dict.fromkeys(c["cell"] for c in all_cases))
    return f"Command: `{command}`; trbc (revision {', '.join(revisions)}). Cells: {cells}."


def summarise(out, all_cases, members, command):
    rows, groups, revisions = [], {}, set()
    for c in all_cases:
        j = finished_record(out, c)
        reg, status = (None, None) if j is None else (j.get("observables", {}).get("regime"), j.get("status"))
        rows.append(dict(c, regime=reg, status=status))
        if j is not None:
            revisions.add(j.get("provenance", {}).get("revision"))
        if reg is None and status is None:
            continue
        key = (c["cell"], c["eta"], c["protocol"])
        g = groups.setdefault(key, {})
        n, k, bad = g.get(c["stress"], (0, 0, 0))
        # A failed case (the solver gave up) has no regime: it counts in neither the members nor
        # the fraction, and the table says how many failed.
        if status == "ok":
            g[c["stress"]] = (n + 1, k + (reg == "tank-treading"), bad)
        else:
            g[c["stress"]] = (n, k, bad + 1)
    with open(os.path.join(out, "cases.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["id", "cell", "eta_out_mPa_s", "shear_stress_Pa", "shear_rate_per_s", "protocol", "seed", "regime", "status"])
        for r in rows:
            w.writerow([r["id"], r["cell"], r["eta"], f"{r['stress']:.6g}", f"{r['rate']:.6g}", r["protocol"], r["seed"],
                        r["regime"] or "", r["status"] or "not run"])
    rng = random.Random(1)
    table = ["| cell | eta_out (mPa s) | protocol | TT fraction per stress (Pa) | critical stress (Pa) |", "|---|---|---|---|---|"]
    with open(os.path.join(out, "fractions.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["cell", "eta_out_mPa_s", "protocol", "shear_stress_Pa", "members", "tank_treading", "fraction", "se", "failed"])
        for (cell, eta, protocol), g_all in sorted(groups.items()):
            for x in sorted(g_all):
                if g_all[x][0] == 0:
                    w.writerow([cell, eta, protocol, f"{x:.6g}", 0, 0, "", "", g_all[x][2]])
            g = {x: v for x, v in g_all.items() if v[0] > 0}
            s = sorted(g)
            fr = [g[x][1] / g[x][0] for x in s]
            for x, p in zip(s, fr):
                n = g[x][0]
                w.writerow([cell, eta, protocol, f"{x:.6g}", n, g[x][1], f"{p:.4f}", f"{math.sqrt(max(p * (1 - p), 0.25 / n) / n):.4f}",
                            g[x][2]])
            tc = crossing(s, fr)
            if protocol != "in-plane" and tc is not None:
                boots = []
                for _ in range(2000):
                    fb = [sum(rng.random() < p for _ in range(g[x][0])) / g[x][0] for x, p in zip(s, fr)]
                    b = crossing(s, fb)
                    if b is not None:
                        boots.append(math.log(b))
                sd = (sum((b - sum(boots) / len(boots)) ** 2 for b in boots) / (len(boots) - 1)) ** 0.5 if len(boots) > 1 else float("nan")
                k = next(i for i in range(len(s) - 1) if fr[i] < 0.5 <= fr[i + 1])
                # Fractions that jump from 0 to 1 give every resample the same crossing: the bootstrap
                # then says nothing, and the bracket is the uncertainty.
                step = fr[k] == 0.0 and fr[k + 1] == 1.0
                crit = (f"{tc:.3g} in [{s[k]:.3g}, {s[k + 1]:.3g}] (bootstrap log-SE {sd:.2f}, {len(boots)}/2000 resamples cross"
                        + ("; a step from 0 to 1 pins the interpolation, the bracket is the uncertainty)" if step else ")"))
            elif tc is not None:
                k = next(i for i in range(len(s) - 1) if fr[i] < 0.5 <= fr[i + 1])
                crit = f"[{s[k]:.3g}, {s[k + 1]:.3g}]"
            else:
                crit = "not bracketed"
            cells_ = ", ".join(f"{x:.3g}: {g_all[x][1]}/{g_all[x][0]}" + (f" ({g_all[x][2]} failed)" if g_all[x][2] else "")
                               for x in sorted(g_all))
            table.append(f"| {cell} | {eta:g} | {protocol} | {cells_} | {crit} |")
    with open(os.path.join(out, "threshold_table.md"), "w") as f:
        f.write(provenance_line(revisions, all_cases, command) + "\n\n" + "\n".join(table) + "\n")
    return table


def posterior_cell(posterior):
    try:
        import trbc
    except ImportError as e:
        sys.exit(f"--posterior: the trbc Python package is needed to read it ({e})")
    try:
        c = trbc.calibrated_cell(posterior)
    except Exception as e:  # the binding's error names the file and what is missing
        sys.exit(f"--posterior {posterior}: {e}")
    return dict(v=c["v"], mu=c["mu_uN_per_m"], kb=c["kb_J"], b2=c["b2"], etam=c["etam_Pa_s_um"])


def main():
    global THERMAL_STEP, STOP_WHEN_STEADY
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trbc", default="build/trbc")
    ap.add_argument("--out", required=True)
    ap.add_argument("--level", type=int, default=3)
    ap.add_argument("--rotations", type=float, default=10)
    ap.add_argument("--members", type=int, default=8)
    ap.add_argument("--fluctuating", type=int, default=0, help="seeds of the fluctuating protocol per condition")
    ap.add_argument("--thermal-step", type=float, default=THERMAL_STEP, help="fixed step of the fluctuating runs, 1/rate (trbc shortens it to the membrane's viscous time eta_m/mu)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--full-length", action="store_true",
                    help="run every case its full --rotations (default: stop at the steady state, `flow shear --stop-when-steady`)")
    ap.add_argument("--cells", default="reference,table1,theta_new")
    ap.add_argument("--posterior", help="theta_new posterior (DIR/inference/phase3/theta_new of `trbc calibrate`): the theta_new cell")
    ap.add_argument("--viscosities", default="10.7,23.9,30,100")
    ap.add_argument("--protocols", default="in-plane,ensemble,fluctuating",
                    help="which protocols' cases to run now (the table always shows every finished case)")
    ap.add_argument("--descend", action="store_true",
                    help="fluctuating cases stress by stress from the in-plane threshold down, until none tank-treads")
    ap.add_argument("--dry-run", action="store_true")
    ap.add_argument("--summary-only", action="store_true", help="tabulate the finished cases, run nothing")
    a = ap.parse_args()
    cells = a.cells.split(",")
    for c in cells:
        if c not in CELLS and c != "theta_new":
            sys.exit(f"--cells: unknown cell '{c}' (valid: {', '.join(CELLS)}, theta_new)")
    try:
        viscosities = [float(x) for x in a.viscosities.split(",")]
    except ValueError:
        sys.exit(f"--viscosities: '{a.viscosities}' is not a comma-separated list of numbers")
    for v in viscosities:
        if v not in STRESS_RANGE:
            sys.exit(f"--viscosities: {v:g} mPa s has no stress range (valid: {', '.join(f'{x:g}' for x in STRESS_RANGE)})")
    if a.descend and a.fluctuating < 1:
        sys.exit("--descend runs the fluctuating cases stress by stress: give --fluctuating N >= 1 seeds")
    if a.members < 1 or a.jobs < 1 or a.fluctuating < 0 or not 1 <= a.level <= 4 or not 0 < a.thermal_step <= 1:
        sys.exit("--members and --jobs must be >= 1, --fluctuating >= 0, --level in [1, 4], --thermal-step in (0, 1]")
    protocols = a.protocols.split(",")
    for p in protocols:
        if p not in PROTOCOL_ORDER:
            sys.exit(f"--protocols: unknown protocol '{p}' (valid: {', '.join(PROTOCOL_ORDER)})")
    if "theta_new" in cells:
        if not a.posterior:
            sys.exit("--cells theta_new needs --posterior DIR (the calibration's inference/phase3/theta_new)")
        CELLS["theta_new"] = posterior_cell(a.posterior)
    THERMAL_STEP = a.thermal_step
    STOP_WHEN_STEADY = not a.full_length
    all_cases = cases(cells, viscosities, a.members, a.fluctuating, a.level, a.rotations)
    if a.dry_run:
        for c in all_cases:
            if c["protocol"] in protocols:
                print(" ".join(command(a.trbc, c, a.out)))
        return
    os.makedirs(os.path.join(a.out, "cases"), exist_ok=True)
    with open(os.path.join(a.out, "command.txt"), "a") as f:  # one line per invocation of a resumed scan
        f.write(" ".join(sys.argv) + "\n")
    descend = a.descend and "fluctuating" in protocols
    pooled = [p for p in protocols if not (descend and p == "fluctuating")]
    if not a.summary_only and pooled:  # the in-plane cases first: a descending row starts from their threshold
        t0, done = time.time(), 0
        todo = [c for c in all_cases if c["protocol"] in pooled and not finished(a.out, c)]
        todo.sort(key=lambda c: PROTOCOL_ORDER[c["protocol"]])
        done_before = sum(finished(a.out, c) for c in all_cases)
        print(f"{len(all_cases)} cases, {done_before} finished earlier, {len(todo)} of protocols {','.join(pooled)} to run", file=sys.stderr)
        with concurrent.futures.ThreadPoolExecutor(a.jobs) as ex:
            for cid, what, wall in ex.map(lambda c: run(a.trbc, c, a.out), todo):
                done += 1
                el = time.time() - t0
                print(f"[{done}/{len(todo)}] {cid} {what} {wall:.0f} s; elapsed {el / 60:.0f} min, "
                      f"ETA {el / done * (len(todo) - done) / 60:.0f} min", file=sys.stderr, flush=True)
    if not a.summary_only and descend:
        t0, ran = time.time(), [0]

        def log(cid, what, wall):
            ran[0] += 1
            print(f"[{ran[0]}] {cid} {what} {wall:.0f} s; elapsed {(time.time() - t0) / 60:.0f} min", file=sys.stderr, flush=True)

        rows = []
        for cell in cells:
            for eta in viscosities:
                sel = [c for c in all_cases if c["cell"] == cell and c["eta"] == eta]
                rows.append(([c for c in sel if c["protocol"] == "fluctuating"], [c for c in sel if c["protocol"] == "in-plane"]))
        with concurrent.futures.ThreadPoolExecutor(a.jobs) as ex:
            list(ex.map(lambda r: descend_row(a.trbc, a.out, r[0], r[1], log), rows))
    print("\n".join(summarise(a.out, all_cases, a.members, " ".join(["scripts/threshold_protocols.py"] + sys.argv[1:]))))


if __name__ == "__main__":
    main()
