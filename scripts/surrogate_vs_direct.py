#!/usr/bin/env python3
"""Surrogate against the direct forward model on fresh random points.

Draws N points uniformly in the training box (seeded), runs `trbc simulate` at the training level
for each and `trbc surrogate eval` on all of them, and writes OUT/points.csv (inputs, direct and
surrogate outputs) and OUT/summary.md (per output: RMSE, relative RMSE, max error).

Usage: scripts/surrogate_vs_direct.py [--n 20] [--seed 99] [--level 4] [--model DIR] [--out DIR]
       [--reuse-direct]   (re-evaluate the surrogate only; direct values from OUT/points.csv)
"""
import argparse
import csv
import json
import math
import os
import random
import subprocess
import sys

BOX = [("v", 0.65, 1.0), ("mu_uN_per_m", 1.0, 10.0), ("FvK", 10.0, 1000.0), ("b2", 0.0, 4.0),
       ("etam_Pa_s_um", 0.1, 1.0), ("Fext_pN", 0.0, 200.0)]
OUTS = ["D_um", "hmin_um", "hmax_um", "D0_um", "D1_um", "tc_s"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=20)
    ap.add_argument("--seed", type=int, default=99)
    ap.add_argument("--level", type=int, default=4)
    ap.add_argument("--model", default="")
    ap.add_argument("--trbc", default=os.path.join(os.path.dirname(__file__), "..", "build", "trbc"))
    ap.add_argument("--out", default="out/surrogate_vs_direct")
    ap.add_argument("--reuse-direct", action="store_true",
                    help="take the points and direct outputs from OUT/points.csv (they do not depend on the surrogate)")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    rng = random.Random(a.seed)
    pts = [[lo + (hi - lo) * rng.random() for _, lo, hi in BOX] for _ in range(a.n)]
    env = dict(os.environ, OMP_NUM_THREADS="1")
    direct = []
    if a.reuse_direct:
        try:
            with open(os.path.join(a.out, "points.csv")) as f:
                old = list(csv.DictReader((ln for ln in f if not ln.startswith("#"))))
            with open(os.path.join(a.out, "summary.md")) as f:
                head = f.readline()
        except OSError as e:
            sys.exit(f"--reuse-direct: {e}")
        if f"(level {a.level}," not in head:
            sys.exit(f"{a.out}/summary.md: its direct runs are not at --level {a.level}: {head.strip()}")
        olds = [[float(r[b[0]]) for b in BOX] for r in old]
        if len(olds) != a.n or any(abs(x - y) > 1e-12 * max(1.0, abs(y)) for p, q in zip(pts, olds) for x, y in zip(p, q)):
            sys.exit(f"{a.out}/points.csv: its points are not those of --n {a.n} --seed {a.seed}")
        direct = [[float(r[k + "_direct"]) for k in OUTS] for r in old]
    for i, p in enumerate([] if a.reuse_direct else pts):
        args = [a.trbc, "simulate", "--level", str(a.level), "--no-cache"]
        for (name, _, _), x in zip(BOX, p):
            flag = {"v": "--v", "mu_uN_per_m": "--mu", "FvK": "--FvK", "b2": "--b2", "etam_Pa_s_um": "--etam",
                    "Fext_pN": "--Fext"}[name]
            args += [flag, repr(x)]
        r = subprocess.run(args, capture_output=True, text=True, env=env)
        j = json.loads(r.stdout) if r.stdout.strip().startswith("{") else {"status": "failed", "reason": r.stderr}
        obs = j.get("observables", {}) if j.get("status") == "ok" else {}
        direct.append([obs.get(k) if obs.get(k) is not None else math.nan for k in OUTS])
        print(f"[{i + 1}/{a.n}] {j.get('status')}", file=sys.stderr, flush=True)
    inp = os.path.join(a.out, "inputs.csv")
    with open(inp, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow([b[0] for b in BOX])
        w.writerows(pts)
    sur = os.path.join(a.out, "surrogate.csv")
    cmd = [a.trbc, "surrogate", "eval", "--in", inp, "--out", sur] + (["--model", a.model] if a.model else [])
    subprocess.run(cmd, check=True, env=env)
    with open(sur) as f:
        srows = list(csv.DictReader((ln for ln in f if not ln.startswith("#"))))
    pred = [[float(r[k]) for k in OUTS] for r in srows]
    with open(os.path.join(a.out, "points.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow([b[0] for b in BOX] + [k + "_direct" for k in OUTS] + [k + "_surrogate" for k in OUTS])
        for p, d, s in zip(pts, direct, pred):
            w.writerow(p + d + s)
    lines = [f"# Surrogate vs direct `trbc simulate` (level {a.level}, {a.n} uniform points, seed {a.seed})", "",
             f"Command: `{' '.join(sys.argv)}`", "",
             "| output | n | RMSE | relative RMSE | max abs error |", "|---|---|---|---|---|"]
    for k, name in enumerate(OUTS):
        pairs = [(d[k], s[k]) for d, s in zip(direct, pred) if not math.isnan(d[k])]
        if not pairs:
            continue
        rmse = math.sqrt(sum((s - d) ** 2 for d, s in pairs) / len(pairs))
        rel = math.sqrt(sum(((s - d) / d) ** 2 for d, s in pairs) / len(pairs))
        mx = max(abs(s - d) for d, s in pairs)
        lines.append(f"| {name} | {len(pairs)} | {rmse:.4g} | {100 * rel:.2f} % | {mx:.4g} |")
    failed = sum(1 for d in direct if all(math.isnan(x) for x in d))
    lines += ["", f"Direct runs that failed: {failed}."]
    open(os.path.join(a.out, "summary.md"), "w").write("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
