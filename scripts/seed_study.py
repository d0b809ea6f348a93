#!/usr/bin/env python3
"""Seed study of `trbc infer`: the same inference with several seeds, and how far its theta_new
statistics scatter across seeds compared with the posterior SD and with the stated Monte Carlo
standard errors.

    scripts/seed_study.py --trbc build/trbc --out OUT --seeds 1 2 3 4 5 6 7 8 [-- extra infer options]

Each seed runs `trbc infer --phase all --seed S --out OUT/seed_S` (skipped when OUT/seed_S already
holds a finished run with the same options by a build of the same revision, so the study resumes). Writes OUT/seed_study.csv (one
row per seed and parameter), OUT/seed_study_phase1.csv (the same for every data set's phase-1
posterior) and OUT/seed_study.md: per parameter of theta_new the mean over seeds
of each statistic, the SD over seeds of the mean and median in units of the posterior SD, the
relative SD over seeds of the posterior SD, the mean stated MCSE beside the observed scatter, and
the wall time per run.
"""
import argparse
import csv
import math
import os
import shlex
import subprocess
import sys
import time

import finished_runs


def read_stats(path, posterior="theta_new"):
    """{parameter: statistics} of one posterior of a posterior_stats.csv, or with posterior=None
    {(posterior, parameter): statistics} of all of them."""
    rows = {}
    with open(path) as f:
        for r in csv.DictReader((ln for ln in f if not ln.startswith("#"))):
            if posterior is None or r["posterior"] == posterior:
                key = (r["posterior"], r["parameter"]) if posterior is None else r["parameter"]
                rows[key] = {k: float(v) for k, v in r.items() if k not in ("posterior", "parameter")}
    return rows


def sd(values):
    m = sum(values) / len(values)
    return math.sqrt(sum((v - m) ** 2 for v in values) / (len(values) - 1)) if len(values) > 1 else float("nan")


def scatter(stats, seeds, key):
    """One posterior parameter over the seeds (stats[seed][key]): the mean over the seeds of each
    statistic (and of its MCSE), and the SD over the seeds of the mean, the median and the SD, each
    divided by the posterior SD (the mean over the seeds of the SD)."""
    col = lambda stat: [stats[s][key][stat] for s in seeds]
    avg = {stat: sum(col(stat)) / len(seeds) for stat in stats[seeds[0]][key]}
    return avg, {stat: sd(col(stat)) / avg["sd"] for stat in ("mean", "median", "sd")}


def phase1_scatter(phase1, seeds, out):
    """The same scatter for phase 1, the single-data-set posteriors that start phases 2-3: writes
    OUT/seed_study_phase1.csv and returns the table's lines, largest scatter of the mean first."""
    keys = list(phase1[seeds[0]].keys())
    with open(os.path.join(out, "seed_study_phase1.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["seed", "data_set", "parameter", "mean", "sd", "mcse_mean", "mcse_sd"])
        for seed in seeds:
            for k in keys:
                r = phase1[seed][k]
                w.writerow([seed, k[0], k[1], r["mean"], r["sd"], r["mcse_mean"], r["mcse_sd"]])
    rows = []
    for k in keys:
        avg, spread = scatter(phase1, seeds, k)
        rows.append((spread["mean"], k, avg["mean"], avg["mcse_mean"] / avg["sd"], avg["sd"], spread["sd"]))
    rows.sort(key=lambda r: -r[0])
    lines = ["", "## Phase 1", "",
             "The same scatter for each data set's phase-1 posterior (`phase1/posterior_stats.csv` of each run; "
             "`seed_study_phase1.csv`), largest scatter of the mean first.", "",
             "| data set | parameter | mean | SD over seeds of the mean (in SD) | stated MCSE of the mean (in SD) | posterior SD "
             "| SD over seeds of the SD (rel.) |", "|---|---|---|---|---|---|---|"]
    for smean, (ds, p), m, mcse, psd, ssd in rows:
        lines.append(f"| {ds} | {p} | {m:.4g} | {smean:.3f} | {mcse:.3f} | {psd:.4g} | {ssd:.3f} |")
    return lines


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--trbc", default="build/trbc")
    ap.add_argument("--out", required=True)
    ap.add_argument("--seeds", type=int, nargs="+", default=list(range(1, 9)))
    ap.add_argument("extra", nargs=argparse.REMAINDER, help="options passed to trbc infer (after --)")
    a = ap.parse_args()
    extra = [x for x in a.extra if x != "--"]
    finished_runs.trbc_version(a.trbc)  # a --trbc that is no trbc stops here, before any folder is touched
    os.makedirs(a.out, exist_ok=True)
    results, phase1, walls = {}, {}, {}
    for seed in a.seeds:
        d = os.path.join(a.out, f"seed_{seed}")
        cmd = [a.trbc, "infer", "--phase", "all", "--seed", str(seed), "--out", d, "--quiet"] + extra
        marker = os.path.join(d, "seed_study_run.json")
        done = finished_runs.finished(marker, [cmd], a.trbc)
        if done:
            walls[seed] = done["wall_s"]
        else:
            t0 = time.time()
            print("seed study:", " ".join(shlex.quote(c) for c in cmd), file=sys.stderr, flush=True)
            if subprocess.run(cmd, stdout=subprocess.DEVNULL).returncode != 0:
                sys.exit(f"seed_study: {' '.join(cmd)} failed; {d} is left unfinished")
            walls[seed] = time.time() - t0
            finished_runs.mark_finished(marker, [cmd], a.trbc, walls[seed])
        results[seed] = read_stats(os.path.join(d, "posterior_stats.csv"))
        phase1[seed] = read_stats(os.path.join(d, "phase1", "posterior_stats.csv"), posterior=None)

    params = list(results[a.seeds[0]].keys())
    with open(os.path.join(a.out, "seed_study.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["seed", "parameter", "mean", "median", "sd", "q05", "q95", "mcse_mean", "mcse_median", "mcse_sd", "wall_s"])
        for seed in a.seeds:
            for p in params:
                r = results[seed][p]
                w.writerow([seed, p, r["mean"], r["median"], r["sd"], r["q05"], r["q95"], r["mcse_mean"], r["mcse_median"], r["mcse_sd"],
                            f"{walls[seed]:.1f}"])

    lines = [f"# Seed study of `trbc infer`", "",
             f"Command per seed: `{' '.join([a.trbc, 'infer', '--phase', 'all', '--seed', 'S', '--out', 'DIR'] + extra)}`, "
             f"seeds {', '.join(map(str, a.seeds))}. Made by `scripts/seed_study.py`.", "",
             "Scatter over seeds (SD over the seeds) of each theta_new statistic, the mean over the seeds of the statistic "
             "and of its stated MCSE. 'in SD' divides by the posterior SD (mean over the seeds); 'rel.' divides by the statistic.", "",
             "| parameter | mean | SD over seeds of the mean (in SD) | stated MCSE of the mean (in SD) | median | SD over seeds of the median (in SD) "
             "| stated MCSE of the median (in SD) | posterior SD | SD over seeds of the SD (rel.) | stated MCSE of the SD (rel.) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    worst = {"mean": 0.0, "median": 0.0, "sd": 0.0}
    for p in params:
        m, spread = scatter(results, a.seeds, p)
        psd = m["sd"]
        worst = {k: max(worst[k], spread[k]) for k in worst}
        lines.append(f"| {p} | {m['mean']:.4g} | {spread['mean']:.3f} | {m['mcse_mean'] / psd:.3f} | {m['median']:.4g} | "
                     f"{spread['median']:.3f} | {m['mcse_median'] / psd:.3f} | {psd:.4g} | {spread['sd']:.3f} | {m['mcse_sd'] / psd:.3f} |")
    ws = sorted(walls.values())
    lines += ["", f"Largest scatter over seeds: mean {worst['mean']:.3f} SD, median {worst['median']:.3f} SD, posterior SD "
                  f"{100 * worst['sd']:.1f} %.",
              f"Wall time per run: median {ws[len(ws) // 2]:.0f} s, min {ws[0]:.0f} s, max {ws[-1]:.0f} s (this machine, as run)."]
    lines += phase1_scatter(phase1, a.seeds, a.out)
    open(os.path.join(a.out, "seed_study.md"), "w").write("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
