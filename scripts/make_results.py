#!/usr/bin/env python3
"""Regenerates the shipped result sets of results/ from configs/ and the current build (`make results`).

    scripts/make_results.py [--trbc build/trbc] [--only NAME,...] [--dry-run] [--save-progress] [--work out/results]

--dry-run lists every set with its commands, its cost on the 2-core development machine (from
the wall times its own records carry, where they do) and the command that made the copy shipped
now. A run makes each selected set in WORK/<name> and then replaces results/<name> with it, so a
failed or interrupted set leaves the shipped one untouched; the validation sets resume (`trbc
validate` keeps its finished cases), and so do the flow campaign (`--resume`) and the capsule and
threshold scans (finished cases are skipped); the others start again.
--save-progress ships the finished cases of the sets of many hours that have not finished (the
flow campaign, the threshold scan, the validation sets) under results/<name>/progress/, and a run
on another machine continues from them. Sets are listed cheapest first; the
sets of the calibrated cell read the posterior that the calibration set leaves in WORK: the one
it ships (results/calibration/posterior.tar.xz) unless the calibration is made in the same run,
and made first when none is shipped."""
import argparse
import filecmp
import glob
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import tarfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
POSTERIOR = "{work}/calibration/inference/phase3/theta_new"  # the posterior the calibration set makes
# The calibration's theta_new samples and statistics, shipped beside it: the Markov chains amplify
# the last bit in which two CPUs differ, so a calibration made on another machine is another
# posterior (within its Monte Carlo error), and the sets drawn from it would be other draws. The sets
# read this one unless the calibration itself is made again.
SHIPPED_POSTERIOR = ("posterior.tar.xz", ["inference/posterior_stats.csv", "inference/phase3/theta_new/run.json",
                                          "inference/phase3/theta_new/samples.csv"])

SHEAR_TTF32 = "{trbc} flow shear --eta-out 28.9 --shear-rate 32.39631125836553 --eta-in 10 --step-tol 0.001 "
TUBE_PG40 = ("{trbc} flow tube --radius 3.3 --pressure-gradient 40 --eta-out 1.003 --level 3 --duration 30 --settle 60 "
             "--settle-relax 1.5 --settle-tol 0.002 --threads 2 --vtk-every 50 ")

# A campaign of many hours continues where an interrupted `make results` left it (--resume once its
# campaign.json exists), and so do the case-by-case scans (their scripts skip finished cases); their
# work folders are kept (RESUMED).
# The same design from random starts (the regime network's, the ensemble protocol) and from the
# in-plane start (the tank-treading network's, the start of validate's angle and TTF runs).
CAMPAIGN = ("mpirun -n 2 {{trbc}} flow campaign --cases 4096 --level 3 --seed 20261129 --threads 1 --no-cache "
            "--steady-rule 3,0.1,0.005 --start {start} --out {{out}}/{name} $(test -f {{out}}/{name}/campaign.json && echo --resume)")
RESUMED = ("flow_campaign", "flow_stop_rule", "flow_verification/capsule", "flow_threshold/scan")
# What a set of many hours has finished so far, shipped under results/<name>/progress/ by
# --save-progress so that another machine continues it. A campaign's files go together: a work folder
# without its campaign starts from them. An entry with a * is a set of independent case records
# (validate's, the threshold scan's): validate takes them with --import, and the scan's that the work
# folder lacks are copied in.
PROGRESS = {"flow_campaign": ["level3/campaign.json", "level3/parts", "level3_inplane/campaign.json", "level3_inplane/parts"],
            "flow_threshold/scan": ["cases/*/flow.json"]}
# A case folder the threshold scan set aside (another cell's record, run again): not progress.
SET_ASIDE = ".replaced-"
STOP_RULES = " ".join("--rule " + r for r in ("4,0.1,0.005", "3,0.1,0.005", "3,0.2,0.01", "3,0.3,0.015", "4,0.05,0.0025"))

# name: (what, [commands], cost in CPU hours of the 2-core machine, files kept (None: all of OUT)).
# A kept entry "SRC" copies OUT/SRC to results/<name>/SRC, "SRC=DEST" to results/<name>/DEST; a
# directory is copied whole, and a SRC with a * every match. The set's README.md (the hand-written
# description) is carried over.
# {trbc} is the binary, {out} the set's work directory, {work} the root of all of them.
SETS = {
    "calibration": ("the shipped calibration: posterior statistics, report, stage ledger",
                    ["{trbc} calibrate --config configs/paper.toml --out {out}"], 0.3,
                    ["inference/posterior_stats.csv=posterior_stats.csv", "report.html", "stages.json", SHIPPED_POSTERIOR[0]]),
    "inference": ("trbc infer on the shipped surrogates, seed 1: statistics, corner plots, predictions",
                  ["{trbc} infer --phase all --seed 1 --out {out}",
                   "{trbc} predict --inference {out} --out {out}/predict --threads 2 --quiet",
                   "python3 scripts/plot_posterior.py {out} --out {out}",
                   "python3 scripts/plot_predict.py {out}/predict"], 0.3,
                  ["infer.json", "posterior_stats.csv", "posterior_table.md", "corner_evans_fung_1972.png", "corner_mills_2004.png",
                   "corner_suresh_2005.png", "corner_hochmuth_1979_cell1.png", "corner_hochmuth_1979_cell2.png",
                   "corner_hochmuth_1979_cell3.png", "corner_hochmuth_1979_cell4.png", "corner_theta_new.png", "predict"]),
    "inference_seed_study": ("theta_new of the default trbc infer for seeds 1-8",
                             ["python3 scripts/seed_study.py --trbc {trbc} --out {out} --seeds 1 2 3 4 5 6 7 8"], 0.4,
                             ["seed_study.csv", "seed_study.md", "seed_study_phase1.csv"]),  # not the eight runs' samples (600 MB)
    "sobol": ("Sobol' indices of the six observables", ["{trbc} sobol --samples 4096 --seed 1 --threads 2 --out {out}"], 0.05,
              None),
    "surrogate_vs_direct": ("the surrogates against direct level-4 simulations at 20 points",
                            ["python3 scripts/surrogate_vs_direct.py --trbc {trbc} --n 20 --seed 99 --level 4 --out {out}"], 0.05, None),
    "mesh_convergence": ("the six observables at levels 3-5 at three cells",
                         ["bash scripts/mesh_convergence.sh {trbc} {out}"], 0.3, None),
    "branch_map": ("the two equilibrium branches near v = 1, levels 3 and 4",
                   ["python3 scripts/branch_map.py --trbc {trbc} --jobs 2 --out {out} --figure {out}/branch_map.png",
                    "python3 scripts/branch_map.py --trbc {trbc} --level 4 --v 0.98,0.99,0.995,0.999 --fvk 50,122,200,400 "
                    "--jobs 2 --out {out} --figure {out}/branch_map_L4.png"], 0.1, None),
    "relaxation_low_v": ("tc at v 0.65-0.75, inertial and overdamped at levels 3-4, inertial at level 5",
                         ["bash scripts/relaxation_low_v.sh {trbc} {out} \"3 4\"",
                          "bash scripts/relaxation_low_v.sh {trbc} {out} 5 inertial"], 0.3, None),
    "flow_scan_etam": ("two shear cases of the Table 1 cell over eta_m", ["bash scripts/flow_scan.sh {trbc} {out} 2 etam"], 0.1,
                       None),
    "flow_scan_threshold": ("the 100 mPa s threshold of the Table 1 cell over eta_m, v and a tilt",
                            ["bash scripts/flow_scan.sh {trbc} {out} 2 threshold"], 0.25, None),
    "flow_scan_theta_new": ("three shear cases of the theta_new cell", ["bash scripts/flow_scan.sh {trbc} {out} 2 theta_new " + POSTERIOR], 0.04,
                            None),
    "flow_campaign": ("the shear-flow campaign at level 3 from random and in-plane starts, its networks and learning curves",
                      [CAMPAIGN.format(start="random", name="level3"), CAMPAIGN.format(start="in-plane", name="level3_inplane"),
                       "{trbc} flow train --campaign {out}/level3 --campaign {out}/level3_inplane --folds 5 "
                       "--learning-curve 40,80,160,320 --out {out}/networks",
                       "{trbc} flow train --campaign {out}/level3 --folds 5 --learning-curve 40,80,160,320 "
                       "--out {out}/random_only",
                       "python3 scripts/plot_flow_learning_curve.py {out}/random_only/training.json {out}/networks/training.json "
                       "--label 'random starts only' --label 'angle and TTF from in-plane starts' --out {out}/learning_curve.png"], 100.0,
                      ["level3/campaign.json", "level3/cases.csv", "level3_inplane/campaign.json", "level3_inplane/cases.csv", "networks",
                       "random_only", "learning_curve.png"]),
    "flow_stop_rule": ("stop rules against full-length runs on the first 72 level-3 cases of the flow campaign's design",
                       ["mpirun -n 2 {trbc} flow campaign --cases 72 --level 3 --seed 20261129 --threads 1 --no-cache --full-length "
                        "--out {out}/full_length $(test -f {out}/full_length/campaign.json && echo --resume)",
                        "{trbc} flow steady-rules --campaign {out}/full_length " + STOP_RULES + " > {out}/steady_rules.md"], 1.4,
                       ["full_length/campaign.json", "full_length/cases.csv", "full_length/by_turn", "steady_rules.md"]),
    "flow_verification/capsule": ("the spherical-capsule verification table",
                                  ["python3 scripts/capsule_verification.py --trbc {trbc} --out {out}"], 0.4, None),
    "flow_threshold/scan": ("the threshold under three protocols, three cells, four viscosities",
                            ["python3 scripts/threshold_protocols.py --trbc {trbc} --out {out} --level 3 --members 8 "
                             "--cells theta_new --viscosities 30,100 --protocols ensemble --posterior " + POSTERIOR,
                             "python3 scripts/threshold_protocols.py --trbc {trbc} --out {out} --level 3 --members 8 "
                             "--cells reference,table1,theta_new --viscosities 10.7,23.9,30,100 --protocols in-plane,fluctuating "
                             "--fluctuating 3 --descend --posterior " + POSTERIOR], 7.0,
                            ["command.txt", "cases.csv", "fractions.csv", "threshold_table.md"]),
    "flow_threshold/ramp_theta_new_eta100": ("the theta_new cell's shear ramp at 100 mPa s",
                                             ["{trbc} flow ramp --eta-out 100 --rates 0.3,0.4384,0.6406,0.9362,1.368,2.0 "
                                              "--rotations 10 --level 3 --threads 1 --posterior " + POSTERIOR +
                                              " --vtk-every 1000000 --out {out}"], 0.15, ["ramp.json"]),
    "inference_sensitivity": ("theta_new's sensitivity to the population model, and the two routes of phases 2-3",
                              ["python3 scripts/inference_sensitivity.py --trbc {trbc} --out {out} --seed 1 "
                               "--seed-study results/inference_seed_study/seed_study.csv"], 0.5,
                              ["sensitivity.md", "sensitivity.csv", "routes.md", "routes.csv", "population_sd.csv"]),
    "validation/theta_new_level3": ("the flow-validation set of the theta_new cell, level 3",
                                    ["{trbc} validate --config configs/validation.toml --level 3 --posterior " + POSTERIOR +
                                     " --threshold-protocol in-plane --out {out} --jobs 2 --threads 1"], None, None),
    "validation/reference_cell_level3": ("the reference implementation's shear set-up",
                                         ["{trbc} validate --config configs/validation_reference_cell_subset.toml --out {out} "
                                          "--jobs 2 --threads 1"], None, None),
    "validation/table1_level3_angle": ("the Table 1 cell's angles, level 3",
                                       ["{trbc} validate --config configs/validation.toml --level 3 --only angle --out {out} "
                                        "--jobs 2 --threads 1"], None, None),
    "validation/table1_level3_ttf": ("the Table 1 cell's TTF, level 3",
                                     ["{trbc} validate --config configs/validation.toml --level 3 --only ttf --out {out} "
                                      "--jobs 2 --threads 1"], None, None),
    "validation/table1_level3_threshold": ("the Table 1 cell's thresholds, level 3",
                                           ["{trbc} validate --config configs/validation.toml --level 3 --only threshold "
                                            "--threshold-protocol in-plane --out {out} --jobs 2 --threads 1"], None, None),
    "validation/table1_level3_tube_tol6e-5": ("the Table 1 cell in the microtube, level 3",
                                              ["{trbc} validate --config configs/validation.toml --level 3 --only tube --out {out} "
                                               "--jobs 2 --threads 1"], None, None),
    "validation/theta_new_level2_bands": ("the theta_new bands of the shear sets, 32 draws, level 2",
                                          ["{trbc} validate --config configs/validation_banded.toml --posterior " + POSTERIOR +
                                           " --draws 32 --seed 1 --level 2 --only ttf,threshold,angle --out {out} --jobs 2 --threads 1"], None, None),
    "validation/theta_new_level3_high_viscosity_steady": ("the 55.9 and 104 mPa s angle sets stopped at the steady state, and at full length",
                                                          ["{trbc} validate --config configs/validation_high_viscosity_steady.toml "
                                                           "--posterior " + POSTERIOR + " --out {out} --jobs 2",
                                                           # the full-length runs of the same cases, timed alone
                                                           "{trbc} validate --config configs/validation_high_viscosity.toml "
                                                           "--posterior " + POSTERIOR + " --out {out}/full_length --jobs 2 --threads 1"],
                                                          0.6, ["validation.json", "validation.md", "comparison.csv", "shear.csv",
                                                                 "cases/*.json", "full_length/validation.json",
                                                                 "full_length/validation.md", "full_length/shear.csv"]),
    "validation/shear_levels": ("the resolution check: one TTF case of the Table 1 cell at levels 2, 3 and 4",
                                [SHEAR_TTF32 + "--level 2 --rotations 10 --threads 1 --out {out}/ttf32_L2",
                                 SHEAR_TTF32 + "--level 2 --rotations 4 --threads 1 --out {out}/ttf32_L2_r4",
                                 SHEAR_TTF32 + "--level 3 --rotations 10 --threads 1 --out {out}/ttf32_L3",
                                 SHEAR_TTF32 + "--level 3 --rotations 4 --threads 2 --out {out}/ttf32_L3_r4",
                                 SHEAR_TTF32 + "--level 4 --rotations 4 --threads 2 --out {out}/ttf32_L4_r4"], 0.13,
                                [f"ttf32_{r}/{f}" for r in ("L2", "L2_r4", "L3", "L3_r4", "L4_r4")
                                 for f in ("flow.json", "frames.csv", "steps.csv")]),
    "validation/step_tolerance": ("the step-tolerance checks of a tube case and a shear case, level 3",
                                  [TUBE_PG40 + "--step-tol " + t + " --out {out}/tube_pg40_tol_" + t for t in ("1e-3", "2.5e-4", "6.25e-5")] +
                                  ["{trbc} flow shear --eta-out 28.9 --shear-rate 32.39631125836553 --eta-in 10 --level 3 --rotations 10 "
                                   "--step-tol 0.00025 --threads 1 --out {out}/shear_ttf32_tol_2.5e-4"], 0.4,
                                  [f"tube_pg40_tol_{t}/{f}" for t in ("1e-3", "2.5e-4", "6.25e-5")
                                   for f in ("flow.json", "frames.csv", "settling/frames.csv")] +
                                  ["shear_ttf32_tol_2.5e-4/flow.json", "shear_ttf32_tol_2.5e-4/frames.csv"]),
    # The direct runs the flow networks' bands are checked against (docs/FLOW_NETWORKS.md), and the
    # shipped networks against them (networks/): 16 draws of 4 angle cases, a TTF case and an ensemble threshold.
    "validation/theta_new_level3_cross_check": ("direct level-3 runs of 16 theta_new draws at the cross-check cases of the flow networks",
                                                ["{trbc} validate --config configs/validation_cross_check.toml --posterior " + POSTERIOR +
                                                 " --draws 16 --seed 1 --out {out} --jobs 2 --threads 1 --quiet",
                                                 "{trbc} validate --config configs/validation_cross_check.toml --posterior " + POSTERIOR +
                                                 " --draws 1000 --seed 1 --surrogate data/surrogates/flow --direct {out} --out {out}/networks"],
                                                2.3, ["validation.json", "validation.md", "bands.csv", "draws.csv", "comparison.csv", "shear.csv",
                                                      "threshold.csv", "experimental_data.json", "figures", "networks", "cases/*.json"]),
    # The shipped flow networks (data/surrogates/flow, data/README.md) through the posterior: seconds.
    "validation/theta_new_level3_surrogate_bands": ("the theta_new bands of every shear set through the shipped flow networks, 1000 draws",
                                                    ["{trbc} validate --config configs/validation.toml --posterior " + POSTERIOR +
                                                     " --draws 1000 --seed 1 --surrogate data/surrogates/flow --out {out}"], 0.01, None),
    "flow_sobol": ("Sobol' indices of the angle, the TTF and the critical stress through the shipped flow networks",
                   ["{trbc} flow sobol --surrogate data/surrogates/flow --config configs/validation.toml --samples 4096 --seed 1 "
                    "--out {out}"], 0.01, None),
    "flow_etam_scan": ("the membrane viscosity each shear set asks for through the shipped flow networks, the rest of theta_new held",
                          ["python3 scripts/flow_etam_scan.py --posterior " + POSTERIOR + " --surrogate data/surrogates/flow "
                           "--out {out}"], 0.01, None),
    "validation/theta_new_level3_tube_bands": ("the theta_new bands of the microtube, 32 draws, level 3",
                                               ["{trbc} validate --config configs/validation_banded.toml --posterior " + POSTERIOR +
                                                " --draws 32 --seed 1 --only tube --out {out} --jobs 2 --threads 1 --quiet"], None, None),
}

PROGRESS.update({n: ["cases/*.json"] for n in SETS if n.startswith("validation/")})
PROGRESS["validation/theta_new_level3_high_viscosity_steady"].append("full_length/cases/*.json")
# In a set's work folder once the set has replaced results/<name>: its progress is not shipped.
MADE = ".made"

# *.tmp.*: a record a killed writer left before renaming it into place.
_NOT_SHIPPED = shutil.ignore_patterns("checkpoint", "*.vtk", "*.stdout", ".trbc-output", "*.log", "checkpoint.key", "shapes.pvd",
                                      "*.tmp.*")


def shipped_only(directory, names):
    """copytree's ignore: run files that are not shipped (checkpoints, shapes, logs), and the per-case
    run folders of `trbc validate` (DIR/cases/<id>/ beside its case record DIR/cases/<id>.json: time
    series and shapes); the case records are shipped, and so is a folder without a record beside it."""
    skipped = set(_NOT_SHIPPED(directory, names))
    if os.path.basename(directory) == "cases":
        skipped |= {n for n in names if os.path.isdir(os.path.join(directory, n)) and n + ".json" in names}
    return skipped


def copy_kept(out, staged, keep, ignore=None):
    """Copies the kept entries of OUT into STAGED; an entry with a * copies every match (files the
    ignore patterns name excepted) to the same relative path. Returns the path of the first entry
    that matches nothing (None when all were there). An entry that leaves OUT, or a * with =DEST,
    is refused."""
    os.makedirs(staged, exist_ok=True)
    for entry in keep:
        src, _, to = entry.partition("=")
        if os.path.isabs(src) or os.path.normpath(src).startswith(".."):
            sys.exit(f"make_results: kept entry {entry}: not a path inside the set's work directory")
        if "*" in src:
            if to:
                sys.exit(f"make_results: kept entry {entry}: a pattern keeps its matches' own paths, without =DEST")
            matches = sorted(glob.glob(src, root_dir=out))
            if ignore is not None:
                skipped = ignore(out, [os.path.basename(m) for m in matches])
                matches = [m for m in matches if os.path.basename(m) not in skipped]
            pairs = [(os.path.join(out, m), os.path.join(staged, m)) for m in matches]
        else:
            pairs = [(os.path.join(out, src), os.path.join(staged, to or src))] if os.path.exists(os.path.join(out, src)) else []
        if not pairs:
            return os.path.join(out, src)
        for src_path, to_path in pairs:
            os.makedirs(os.path.dirname(to_path), exist_ok=True)
            if os.path.isdir(src_path):
                shutil.copytree(src_path, to_path, ignore=ignore, dirs_exist_ok=True)
            else:
                shutil.copy2(src_path, to_path)
    return None


def command_line(c, trbc, out, work):
    """The command with its placeholders filled; the scripts run under this interpreter, which has numpy and, under
    `make results` (the venv), the trbc package."""
    line = c.format(trbc=trbc, out=out, work=work)
    return shlex.quote(sys.executable) + line[len("python3"):] if line.startswith("python3 ") else line


def read_json(f):
    with open(f) as text:
        return json.load(text)


def recorded(name):
    """(command, CPU hours) of the shipped copy, from its own records where it has them; the command
    ends with "(revision R)" when the record names the build's revision."""
    d = os.path.join(ROOT, "results", name)

    def made_by(j):
        p = j.get("provenance", {})
        command = p.get("command") or j.get("command", "")
        revision = p.get("revision") or j.get("revision")
        return f"{command} (revision {revision})" if command and revision else command

    for record in ("validation.json", "calibrate.json", "infer.json", "sobol.json"):
        f = os.path.join(d, record)
        if os.path.exists(f):
            try:
                j = read_json(f)
            except (OSError, ValueError):
                continue
            hours = j["case_wall_s_total"] / 3600 if "case_wall_s_total" in j else None
            return made_by(j), hours
    subs = sorted(os.listdir(d)) if os.path.isdir(d) else []
    if "progress" in subs:  # a campaign in progress: its own record
        subs = [os.path.join("progress", s) for s in sorted(os.listdir(os.path.join(d, "progress")))]
    # Sets of single runs: the first run's record (a run's folder, or a run's JSON beside the others).
    records = [os.path.join(d, sub, r) for sub in subs for r in ("flow.json", "campaign.json")]
    records += [os.path.join(d, f) for f in subs if f.endswith(".json")]
    for f in records:
        if os.path.isfile(f):
            try:
                command = made_by(read_json(f))
            except (OSError, ValueError, AttributeError):
                continue
            if command:
                return command, None
    # Tables whose first line is trbc's provenance line "# trbc VERSION (REVISION) | command: ... |".
    for f in [os.path.join(d, t) for t in subs if t.endswith(".csv")]:
        with open(f, errors="replace") as text:
            m = re.match(r"# trbc \S+ \(([^)]*)\) \| command: (.*?) \|", text.readline())
        if m:
            return f"{m.group(2)} (revision {m.group(1)})", None
    # Tables that name their command in a line "Command...: `...`".
    for f in [os.path.join(d, t) for t in subs if t.endswith(".md")]:
        with open(f, errors="replace") as text:
            for line in text:
                if line.startswith("Command") and line.count("`") >= 2:
                    m = re.search(r"\(revision ([^)]*)\)", line)
                    return line.split("`")[1][:160] + (f" (revision {m.group(1)})" if m else ""), None
    for text in ("command.txt", "README.md"):
        f = os.path.join(d, text)
        if os.path.exists(f):
            with open(f) as text:
                return text.readline().strip()[:160], None
    return "", None


def progress_records(name, root):
    """The case records of NAME's * entries of PROGRESS under ROOT, patterns expanded."""
    return [m for f in PROGRESS[name] if "*" in f for m in sorted(glob.glob(f, root_dir=root)) if SET_ASIDE not in m]


def campaign_files(name, root):
    """NAME's campaign entries of PROGRESS (those without a *) that exist under ROOT."""
    return [f for f in PROGRESS[name] if "*" not in f and os.path.exists(os.path.join(root, f))]


def runs_cases(command):
    """The match of a validate command's `--out {out}[/SUB]` when the command runs cases there (not
    a --surrogate one), else None: the commands whose case records resume through --import."""
    m = re.search(r"\bvalidate\b.*?--out \{out\}(/\S+)?", command)
    return m if m and "--surrogate" not in command else None


def with_import(name, command):
    """A validate command of NAME that runs cases into {out}[/SUB], with `--import
    results/<name>/progress[/SUB]` after its --out where such progress is shipped: validate takes
    each record whose key matches and replaces a stale one of the work folder. Any other command as
    it is."""
    m = runs_cases(command)
    if not m:
        return command
    source = os.path.join(ROOT, "results", name, "progress") + (m.group(1) or "")
    if not os.path.isdir(os.path.join(source, "cases")):
        return command
    option = " --import " + shlex.quote(source).replace("{", "{{").replace("}", "}}")
    return command[:m.end()] + option + command[m.end():]


def copy_whole(src, to):
    """A file or folder copied under a temporary name and renamed into place, so that a killed copy
    leaves nothing at TO that a later run would take for finished."""
    os.makedirs(os.path.dirname(to), exist_ok=True)
    tmp = to + ".tmp.copy"
    shutil.rmtree(tmp, ignore_errors=True)
    (shutil.copytree if os.path.isdir(src) else shutil.copy2)(src, tmp)
    if os.path.isdir(to):
        shutil.rmtree(to)
    os.replace(tmp, to)


def save_progress(name, out):
    """WORK/<name>'s finished part (PROGRESS) to results/<name>/progress/: a campaign's files replace
    the shipped ones; case records are added to the shipped ones (another machine's records that
    this work folder lacks stay). The folder's README.md stays."""
    dest = os.path.join(ROOT, "results", name, "progress")
    if os.path.exists(os.path.join(out, MADE)):
        print(f"make_results: {name}: finished and shipped, no progress to save", file=sys.stderr)
        return
    found = campaign_files(name, out) + progress_records(name, out)
    if not found:
        print(f"make_results: {name}: nothing in {out} to save", file=sys.stderr)
        return
    for f in campaign_files(name, dest):  # a campaign shipped before goes
        old = os.path.join(dest, f)
        (shutil.rmtree if os.path.isdir(old) else os.remove)(old)
    for f in found:
        copy_whole(os.path.join(out, f), os.path.join(dest, f))
    print(f"make_results: {name}: {len(found)} entries -> results/{name}/progress", file=sys.stderr)


def restore_progress(name, out):
    """results/<name>/progress/ into a work folder: each campaign (folder of PROGRESS) that has not
    started there is copied whole, so a run continues it; one that has started keeps its own files.
    The case records of a set whose commands do not import them (the threshold scan) are copied one
    by one where the work folder lacks them; the others take theirs with --import (with_import)."""
    src_root = os.path.join(ROOT, "results", name, "progress")
    if not os.path.isdir(src_root):
        return
    if not any(runs_cases(c) for c in SETS[name][1]):
        records = progress_records(name, src_root)
        missing = [f for f in records if not os.path.exists(os.path.join(out, f))]
        for f in missing:
            copy_whole(os.path.join(src_root, f), os.path.join(out, f))
        if records:
            print(f"make_results: {name}: {len(missing)} of {len(records)} case records from results/{name}/progress/",
                  file=sys.stderr)
    campaign = [f for f in PROGRESS[name] if "*" not in f]
    for folder in sorted({os.path.dirname(f) for f in campaign}):
        files = [f for f in campaign if os.path.dirname(f) == folder]
        if any(os.path.exists(os.path.join(out, f)) for f in files):
            continue
        for f in files:
            if os.path.exists(os.path.join(src_root, f)):
                copy_whole(os.path.join(src_root, f), os.path.join(out, f))
                print(f"make_results: {name}: continues from results/{name}/progress/{f}", file=sys.stderr)


def pack_posterior(out):
    """OUT/posterior.tar.xz: the files of SHIPPED_POSTERIOR under their paths in the calibration's OUT,
    without owners or times, so that the same samples give the same archive."""
    def plain(info):
        info.uid = info.gid = 0
        info.uname = info.gname = ""
        info.mtime = 0
        return info
    with tarfile.open(os.path.join(out, SHIPPED_POSTERIOR[0]), "w:xz") as tar:
        for f in SHIPPED_POSTERIOR[1]:
            tar.add(os.path.join(out, f), arcname=f, filter=plain)


def unpack_posterior(work):
    """results/calibration/posterior.tar.xz into WORK/calibration, replacing files that differ (False
    when none is shipped). The archive is read once, into a folder beside the target; files that
    already match are left in place, the others renamed into place, so that a killed unpack leaves
    the earlier posterior or none, never part of one."""
    shipped = os.path.join(ROOT, "results", "calibration", SHIPPED_POSTERIOR[0])
    if not os.path.exists(shipped):
        return False
    target = os.path.join(work, "calibration")
    tmp = target + ".tmp.unpack"
    shutil.rmtree(tmp, ignore_errors=True)
    with tarfile.open(shipped, "r:xz") as tar:
        members = tar.getmembers()
        if sorted(m.name for m in members) != sorted(SHIPPED_POSTERIOR[1]) or not all(m.isfile() for m in members):
            sys.exit(f"make_results: {shipped} holds {', '.join(m.name for m in members)}, "
                     f"not the files {', '.join(SHIPPED_POSTERIOR[1])}")
        tar.extractall(tmp)  # the names are checked above: no path leaves TMP
    differ = [f for f in SHIPPED_POSTERIOR[1] if not os.path.isfile(os.path.join(target, f))
              or not filecmp.cmp(os.path.join(tmp, f), os.path.join(target, f), shallow=False)]
    for f in differ:
        to = os.path.join(target, f)
        os.makedirs(os.path.dirname(to), exist_ok=True)
        os.replace(os.path.join(tmp, f), to)
    shutil.rmtree(tmp)
    print(f"make_results: the sets read the shipped posterior (results/calibration/{SHIPPED_POSTERIOR[0]}"
          + ("" if differ else ", already in place") + ")", file=sys.stderr)
    return True


def posterior_for(names, work):
    """The posterior the sets of the calibrated cell read: the calibration's own when it is among
    NAMES (made first), else the shipped one, unpacked over whatever WORK holds; with none shipped,
    the one WORK holds, or the calibration added first. Returns the names in the order to make them."""
    if not any(POSTERIOR in c for n in names for c in SETS[n][1]) or "calibration" in names:
        return names
    if unpack_posterior(work) or os.path.isdir(POSTERIOR.format(work=work)):
        return names
    return ["calibration"] + names


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trbc", default="build/trbc")
    ap.add_argument("--only", default="", help="comma-separated set names (default: all)")
    ap.add_argument("--work", default="out/results", help="where the sets are made before they replace results/<name>")
    ap.add_argument("--dry-run", action="store_true", help="list the sets, their commands and costs; run nothing")
    ap.add_argument("--save-progress", action="store_true",
                    help="copy the finished cases of the unfinished sets in WORK that resume (the flow campaign, the threshold "
                         "scan, the validation sets) to results/<name>/progress/, to be continued on another machine; run nothing")
    a = ap.parse_args()
    names = [n for n in a.only.split(",") if n] or list(SETS)
    for n in names:
        if n not in SETS:
            sys.exit(f"--only: unknown set '{n}' (valid: {', '.join(SETS)})")
    cost = {n: SETS[n][2] if SETS[n][2] is not None else (recorded(n)[1] or 0.0) for n in names}
    # Cheapest first, but the calibration before every set that reads its posterior.
    names.sort(key=lambda n: (n != "calibration", cost[n]))
    work = os.path.abspath(a.work)
    if a.save_progress:
        for n in names:
            if n in PROGRESS:
                save_progress(n, os.path.join(work, n))
        return
    if a.dry_run:
        total = 0.0
        for n in names:
            what, commands, _, keep = SETS[n]
            command, _ = recorded(n)
            total += cost[n]
            print(f"{n}: {what}\n  cost: about {cost[n]:.2g} CPU h on the 2-core machine")
            for c in commands:
                print("  $ " + command_line(with_import(n, c), a.trbc, os.path.join(work, n), work))
            if keep:
                print("  keeps: " + ", ".join(keep))
            print(f"  shipped copy made by: {command or '(no record)'}")
        print(f"\n{len(names)} sets, about {total:.0f} CPU h in all; the validation sets, the flow campaign and the scans resume, the others start again")
        return
    names = posterior_for(names, work)
    for n in names:
        what, commands, _, keep = SETS[n]
        out = os.path.join(work, n)
        if not n.startswith("validation/") and n not in RESUMED:
            shutil.rmtree(out, ignore_errors=True)
        os.makedirs(out, exist_ok=True)
        if os.path.exists(os.path.join(out, MADE)):
            os.remove(os.path.join(out, MADE))
        if n in PROGRESS:
            restore_progress(n, out)
        t0 = time.time()
        for c in commands:
            line = command_line(with_import(n, c), a.trbc, out, work)
            print(f"make_results: {n}: {line}", file=sys.stderr, flush=True)
            if subprocess.run(line, shell=True, cwd=ROOT).returncode != 0:
                sys.exit(f"make_results: {n} failed: {line}; results/{n} is unchanged")
        if n == "calibration":
            pack_posterior(out)
        # Staged beside results/<name> and swapped in only when every kept file is there.
        dest = os.path.join(ROOT, "results", n)
        staged = dest + ".new"
        shutil.rmtree(staged, ignore_errors=True)
        ignore = shipped_only
        if keep:
            missing = copy_kept(out, staged, keep, ignore)
            if missing:
                shutil.rmtree(staged, ignore_errors=True)
                sys.exit(f"make_results: {n}: {missing} was not made; results/{n} is unchanged")
        else:
            shutil.copytree(out, staged, ignore=ignore)
        readme = os.path.join(dest, "README.md")
        if os.path.exists(readme) and not os.path.exists(os.path.join(staged, "README.md")):
            shutil.copy2(readme, staged)
        if os.path.exists(dest):
            shutil.rmtree(dest)
        os.rename(staged, dest)
        open(os.path.join(out, MADE), "w").close()
        print(f"make_results: {n} made in {(time.time() - t0) / 60:.1f} min -> results/{n}", file=sys.stderr)


if __name__ == "__main__":
    main()
