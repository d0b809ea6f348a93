#!/usr/bin/env python3
"""How theta_new moves with the choices of the population model, and the two routes of phases 2-3
against each other (docs/BAYESIAN_INFERENCE.md).

    scripts/inference_sensitivity.py --trbc build/trbc --out OUT [--seed 1]
        [--seed-study results/inference_seed_study/seed_study.csv]

Runs (each skipped when OUT/<run>/sensitivity_run.json records the same commands, so the study
resumes):
- default: `trbc infer --phase all --seed S`;
- one variant per option: phases 2 and 3 rerun with the option on a copy of the default's phase 1
  (`--hyper-sd-scale 0.5`, `--hyper-sd-scale 2`, `--population-truncation off`), and phase 3 alone
  on a copy of the whole default run (`--theta-new-box off`), so that a variant differs from the
  default by its option, not by its phase-1 populations;
- the re-weighting route: `trbc infer --method reweighting --phase all --seed S` for S = 1, 2.

Writes OUT/sensitivity.csv and OUT/sensitivity.md (theta_new's mean and SD per variant, the shift
of the mean in posterior SDs of the default and the ratio of the SDs, with the largest MCSE of a
mean in SDs) and OUT/routes.csv and OUT/routes.md (the joint route, over the seeds of --seed-study
when given, else the default run, against the re-weighting route's two seeds: the difference of
the means over their combined MCSE, the re-weighting MCSE being the larger of its stated one and
the standard error of its two seeds), with the posterior medians of the population SDs of the
three runs (OUT/population_sd.csv)."""
import argparse
import csv
import math
import os
import re
import shlex
import shutil
import subprocess
import sys
import time

import finished_runs

PARAMS = [("v", "v", 1.0), ("mu_uN_per_m", "µ (µN/m)", 1.0), ("kb_J", "κ_b (1e-19 J)", 1e19), ("b2", "b2", 1.0),
          ("etam_Pa_s_um", "η_m (Pa s µm)", 1.0)]
VARIANTS = [  # name, label, option, phases rerun on a copy of the default
    ("sd_half", "population-SD bounds halved", ["--hyper-sd-scale", "0.5"], ("2", "3")),
    ("sd_double", "population-SD bounds doubled", ["--hyper-sd-scale", "2"], ("2", "3")),
    ("no_truncation", "no truncation of v and κ_b in the population", ["--population-truncation", "off"], ("2", "3")),
    ("box_off", "θ_new not restricted to the paper's box", ["--theta-new-box", "off"], ("3",)),
]
REWEIGHTING_SEEDS = (1, 2)


def read_theta_new(path):
    """theta_new's rows of a posterior_stats.csv, {parameter: {column: float}}, and its provenance line."""
    with open(path) as f:
        first = f.readline()
        f.seek(0)
        rows = {r["parameter"]: {k: float(v) for k, v in r.items() if k not in ("posterior", "parameter")}
                for r in csv.DictReader(ln for ln in f if not ln.startswith("#")) if r["posterior"] == "theta_new"}
    missing = [p for p, _, _ in PARAMS if p not in rows]
    if missing:
        sys.exit(f"inference_sensitivity: {path} has no theta_new row for {', '.join(missing)}")
    return rows, first.strip() if first.startswith("#") else ""


def run_commands(d, commands, setup=None):
    """Runs the commands into d unless d/sensitivity_run.json records the same ones, run by a build
    of the same revision (a finished run)."""
    marker = os.path.join(d, "sensitivity_run.json")
    if finished_runs.finished(marker, commands, commands[0][0]):
        return
    shutil.rmtree(d, ignore_errors=True)
    os.makedirs(d)
    if setup:
        setup(d)
    t0 = time.time()
    for cmd in commands:
        print("inference_sensitivity: " + " ".join(shlex.quote(c) for c in cmd), file=sys.stderr, flush=True)
        r = subprocess.run(cmd, stdout=subprocess.DEVNULL)
        if r.returncode != 0:
            sys.exit(f"inference_sensitivity: {' '.join(cmd)} exited with {r.returncode}; {d} is left unfinished")
    finished_runs.mark_finished(marker, commands, commands[0][0], time.time() - t0)


def joint_from_seed_study(path):
    """The joint route over the seeds of a seed_study.csv: per parameter the mean over seeds of the
    mean and SD, the MCSE of the seeds' average mean (sqrt(sum mcse^2) / n) and the seed count."""
    by = {}
    with open(path) as f:
        for r in csv.DictReader(ln for ln in f if not ln.startswith("#")):
            by.setdefault(r["parameter"], []).append(r)
    out = {}
    for p, _, _ in PARAMS:
        rows = by.get(p)
        if not rows:
            sys.exit(f"inference_sensitivity: --seed-study {path} has no rows of {p}")
        n = len(rows)
        out[p] = dict(mean=sum(float(r["mean"]) for r in rows) / n, sd=sum(float(r["sd"]) for r in rows) / n,
                      mcse=math.sqrt(sum(float(r["mcse_mean"]) ** 2 for r in rows)) / n, n=n)
    return out


def g(x, digits=4):
    return f"{x:#.{digits}g}"


def sensitivity_table(out, default, variants, header):
    worst = max(s[p]["mcse_mean"] / default[p]["sd"] for s in [default] + [v for _, v in variants] for p, _, _ in PARAMS)
    rows, md = [], [
        "# Sensitivity of theta_new to the population model", "", header, "",
        "Each variant reruns phases 2-3 (the box: phase 3) of the default run on a copy of its phase 1, with one option changed. "
        "In brackets: the shift of the mean in posterior SDs of the default, and the ratio of the SDs. "
        f"The largest MCSE of a mean is {worst:.3f} SD.", "",
        "| variant | option | " + " | ".join(f"{label} mean / SD" for _, label, _ in PARAMS) + " |",
        "|---|---|" + "---|" * len(PARAMS)]
    md.append("| default | `trbc infer --phase all` | " + " | ".join(
        f"{g(default[p]['mean'] * s)} / {g(default[p]['sd'] * s, 3)}" for p, _, s in PARAMS) + " |")
    for p, _, _ in PARAMS:
        rows.append(dict(variant="default", option="", parameter=p, mean=default[p]["mean"], sd=default[p]["sd"],
                         mcse_mean=default[p]["mcse_mean"], shift_sd=0.0, sd_ratio=1.0))
    for (name, label, option, _), (_, st) in zip(VARIANTS, variants):
        cells = []
        for p, _, s in PARAMS:
            shift = (st[p]["mean"] - default[p]["mean"]) / default[p]["sd"]
            ratio = st[p]["sd"] / default[p]["sd"]
            cells.append(f"{g(st[p]['mean'] * s)} / {g(st[p]['sd'] * s, 3)} ({shift:+.2f} SD, x{ratio:.2f})")
            rows.append(dict(variant=name, option=" ".join(option), parameter=p, mean=st[p]["mean"], sd=st[p]["sd"],
                             mcse_mean=st[p]["mcse_mean"], shift_sd=shift, sd_ratio=ratio))
        md.append(f"| {label} | `{' '.join(option)}` | " + " | ".join(cells) + " |")
    write_table(out, "sensitivity", header, rows, md)
    return md


def routes_table(out, joint, joint_label, rw, header):
    rows, md = [], [
        "# theta_new by the joint route and by the re-weighting route", "", header, "",
        f"Joint: {joint_label}; ± the MCSE of that mean. Re-weighting: `trbc infer --method reweighting --phase all --seed S`, "
        "± its stated MCSE (a lower bound). The difference of the means (re-weighting's average of its seeds against the joint) "
        "is over the combined MCSE, taking for the re-weighting route the larger of its stated MCSE and the standard error of its seeds.", "",
        "| parameter | joint | " + " | ".join(f"re-weighting, seed {s}" for s in REWEIGHTING_SEEDS) +
        " | difference / combined MCSE | joint SD | re-weighting SD (" + ", ".join(f"seed {s}" for s in REWEIGHTING_SEEDS) + ") |",
        "|---|---|" + "---|" * len(REWEIGHTING_SEEDS) + "---|---|---|"]
    for p, label, s in PARAMS:
        means = [r[p]["mean"] for r in rw]
        m_rw = sum(means) / len(means)
        stated = math.sqrt(sum(r[p]["mcse_mean"] ** 2 for r in rw)) / len(rw)
        spread = (max(means) - min(means)) / 2 if len(means) == 2 else float("nan")
        combined = math.sqrt(joint[p]["mcse"] ** 2 + max(stated, spread) ** 2)
        z = (m_rw - joint[p]["mean"]) / combined
        md.append(f"| {label} | {g(joint[p]['mean'] * s)} ± {g(joint[p]['mcse'] * s, 2)} | " +
                  " | ".join(f"{g(r[p]['mean'] * s)} ± {g(r[p]['mcse_mean'] * s, 2)}" for r in rw) +
                  f" | {z:+.1f} | {g(joint[p]['sd'] * s, 3)} | " + ", ".join(g(r[p]["sd"] * s, 3) for r in rw) + " |")
        rows.append(dict(parameter=p, joint_mean=joint[p]["mean"], joint_mcse=joint[p]["mcse"], joint_sd=joint[p]["sd"],
                         **{f"reweighting_seed{sd}_{k}": r[p][c] for sd, r in zip(REWEIGHTING_SEEDS, rw)
                            for k, c in (("mean", "mean"), ("mcse", "mcse_mean"), ("sd", "sd"))},
                         difference_over_combined_mcse=z))
    write_table(out, "routes", header, rows, md)
    return md


def population_sd_medians(run_dir):
    """Posterior medians of the population SDs (sd_* of DIR/phase2/hyper/samples.csv)."""
    path = os.path.join(run_dir, "phase2", "hyper", "samples.csv")
    with open(path) as f:
        rows = list(csv.DictReader(ln for ln in f if not ln.startswith("#")))
    if not rows:
        sys.exit(f"inference_sensitivity: {path} holds no samples")
    out = {}
    for k in (c for c in rows[0] if c.startswith("sd_")):
        x = sorted(float(r[k]) for r in rows)
        n = len(x)
        out[k] = x[n // 2] if n % 2 else 0.5 * (x[n // 2 - 1] + x[n // 2])
    return out


def population_table(out, runs, header):
    """The posterior median of every population SD, one column per run [(label, medians)]."""
    names = list(runs[0][1])
    md = ["", "## Population SDs", "", "Posterior medians of the population-SD hyper-parameters (phase 2), in the units of "
          "`posterior_stats.csv` (κ_b in J).", "",
          "| hyper-parameter | " + " | ".join(label for label, _ in runs) + " |", "|---|" + "---|" * len(runs)]
    for k in names:
        md.append(f"| {k} | " + " | ".join(g(m[k], 3) for _, m in runs) + " |")
    with open(os.path.join(out, "population_sd.csv"), "w", newline="") as f:
        f.write(header_line(header) + "\n")
        w = csv.writer(f)
        w.writerow(["hyper_parameter"] + [label for label, _ in runs])
        for k in names:
            w.writerow([k] + [m[k] for _, m in runs])
    with open(os.path.join(out, "routes.md"), "a") as f:
        f.write("\n".join(md) + "\n")
    return md


def write_table(out, stem, header, rows, md):
    """OUT/STEM.csv (the header as its '#' line, then the rows) and OUT/STEM.md."""
    with open(os.path.join(out, stem + ".csv"), "w", newline="") as f:
        f.write(header_line(header) + "\n")
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    with open(os.path.join(out, stem + ".md"), "w") as f:
        f.write("\n".join(md) + "\n")


def header_line(header):
    return "# " + header.replace("\n", " ")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trbc", default="build/trbc")
    ap.add_argument("--out", required=True)
    ap.add_argument("--seed", type=int, default=1, help="seed of the default run and its variants")
    ap.add_argument("--seed-study", help="seed_study.csv of scripts/seed_study.py: the joint route over its seeds")
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    if a.seed_study and not os.path.isfile(a.seed_study):
        sys.exit(f"--seed-study {a.seed_study}: no such file")
    if a.threads < 1:
        sys.exit(f"--threads {a.threads}: give at least 1")
    finished_runs.trbc_version(a.trbc)  # a --trbc that is no trbc stops here, before any folder is touched
    os.makedirs(a.out, exist_ok=True)
    common = ["--seed", str(a.seed), "--threads", str(a.threads), "--quiet"]
    default_dir = os.path.join(a.out, "default")
    run_commands(default_dir, [[a.trbc, "infer", "--phase", "all", "--out", default_dir] + common])

    def copy_phase1(d):
        shutil.copytree(os.path.join(default_dir, "phase1"), os.path.join(d, "phase1"))
        shutil.copy2(os.path.join(default_dir, "phase1_prior_box.json"), d)

    def copy_all(d):
        shutil.copytree(default_dir, d, dirs_exist_ok=True, ignore=shutil.ignore_patterns("sensitivity_run.json"))

    variants = []
    for name, _, option, phases in VARIANTS:
        d = os.path.join(a.out, name)
        run_commands(d, [[a.trbc, "infer", "--phase", ph, "--out", d] + option + common for ph in phases],
                     copy_phase1 if phases == ("2", "3") else copy_all)
        variants.append((name, read_theta_new(os.path.join(d, "posterior_stats.csv"))[0]))
    rw = []
    for s in REWEIGHTING_SEEDS:
        d = os.path.join(a.out, f"reweighting_seed{s}")
        run_commands(d, [[a.trbc, "infer", "--method", "reweighting", "--phase", "all", "--seed", str(s), "--out", d,
                          "--threads", str(a.threads), "--quiet"]])
        rw.append(read_theta_new(os.path.join(d, "posterior_stats.csv"))[0])
    default, provenance = read_theta_new(os.path.join(default_dir, "posterior_stats.csv"))
    m = re.match(r"# trbc (\S+) \(([^)]*)\)", provenance)
    build = f"trbc {m.group(1)} (revision {m.group(2)})" if m else "trbc (revision not recorded)"
    header = f"Command: `{' '.join(['scripts/inference_sensitivity.py'] + sys.argv[1:])}`; {build}."
    print("\n".join(sensitivity_table(a.out, default, variants, header)))
    if a.seed_study:
        joint = joint_from_seed_study(a.seed_study)
        label = f"the mean over the {joint['v']['n']} seeds of `{a.seed_study}`"
    else:
        joint = {p: dict(mean=default[p]["mean"], sd=default[p]["sd"], mcse=default[p]["mcse_mean"], n=1) for p, _, _ in PARAMS}
        label = f"the default run (seed {a.seed})"
    print("\n".join(routes_table(a.out, joint, label, rw, header)))
    medians = [(f"joint (seed {a.seed})", population_sd_medians(default_dir))] + [
        (f"re-weighting, seed {sd}", population_sd_medians(os.path.join(a.out, f"reweighting_seed{sd}"))) for sd in REWEIGHTING_SEEDS]
    print("\n".join(population_table(a.out, medians, header)))


if __name__ == "__main__":
    main()
