"""scripts/inference_sensitivity.py on a stand-in for `trbc infer` whose theta_new moves by a known
amount with each option: the variants rerun on a copy of the default's phase 1, the shifts and SD
ratios, the two routes' table, and the resume."""
import csv
import math
import os
import shlex
import stat
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "inference_sensitivity.py"

# theta_new's v: mean 0.93 + 0.01 per unit of log2(--hyper-sd-scale), +0.02 without truncation,
# 0.90 + 0.01 * seed by re-weighting; SD 0.05 (0.1 by re-weighting); MCSE 0.001. Every other
# parameter: mean 2, SD 1. The population's sd_v has median 0.05 (0.08 by re-weighting). A
# phase-2 or phase-3 run needs the earlier phases in --out.
FAKE = r'''
import math, os, sys
a = sys.argv[1:]
if a == ["--version"]:
    sys.exit(print("0.1.0 (" + os.environ.get("FAKE_REVISION", "abc1234") + ")"))
val = lambda k, d=None: a[a.index(k) + 1] if k in a else d
out, phase = val("--out"), val("--phase")
need = {"2": "phase1", "3": "phase2"}.get(phase)
if need and not os.path.isdir(os.path.join(out, need)):
    sys.exit(f"no {need} in {out}")
for p in {"all": ("phase1", "phase2", "phase3"), "2": ("phase2",), "3": ("phase3",)}[phase]:
    os.makedirs(os.path.join(out, p), exist_ok=True)
if phase == "all":
    open(os.path.join(out, "phase1_prior_box.json"), "w").write("{}")
if phase in ("all", "2"):
    os.makedirs(os.path.join(out, "phase2", "hyper"), exist_ok=True)
    sd_v = (0.09, 0.07, 0.08) if val("--method") == "reweighting" else (0.05, 0.04, 0.06)
    with open(os.path.join(out, "phase2", "hyper", "samples.csv"), "w") as f:
        f.write("# trbc\nmean_v,sd_v,sd_b2\n" + "".join(f"0.9,{x},1\n" for x in sd_v))
seed = int(val("--seed"))
if val("--method") == "reweighting":
    v, sd = 0.90 + 0.01 * seed, 0.1
else:
    v, sd = 0.93 + 0.01 * math.log2(float(val("--hyper-sd-scale", "1"))) + (0.02 if val("--population-truncation") == "off" else 0), 0.05
with open(os.path.join(out, "posterior_stats.csv"), "w") as f:
    f.write("# trbc 0.1.0 (abc1234) | command: fake | seed: 1\nposterior,parameter,mean,sd,mcse_mean\n")
    f.write(f"theta_new,v,{v},{sd},0.001\n")
    for p in ("mu_uN_per_m", "kb_J", "b2", "etam_Pa_s_um"):
        f.write(f"theta_new,{p},2,1,0.001\n")
with open(os.environ["FAKE_LOG"], "a") as f:
    f.write(f"{os.path.basename(out)}:{phase}\n")
'''


def run(tmp_path, *args, revision="abc1234"):
    fake = tmp_path / "trbc"
    (tmp_path / "fake.py").write_text(FAKE)
    fake.write_text(f"#!/bin/sh\nexec {shlex.quote(sys.executable)} {shlex.quote(str(tmp_path / 'fake.py'))} \"$@\"\n")
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
    log = tmp_path / "ran.log"
    r = subprocess.run([sys.executable, str(SCRIPT), "--trbc", str(fake), "--out", str(tmp_path / "s"), *args],
                       capture_output=True, text=True, env=dict(os.environ, FAKE_LOG=str(log), FAKE_REVISION=revision))
    ran = log.read_text().split() if log.exists() else []
    log.unlink(missing_ok=True)
    return r, ran


def test_variants_shift_by_their_option_and_the_routes_compare(tmp_path):
    r, ran = run(tmp_path)
    assert r.returncode == 0, r.stderr
    assert ran == ["default:all", "sd_half:2", "sd_half:3", "sd_double:2", "sd_double:3", "no_truncation:2", "no_truncation:3",
                   "box_off:3", "reweighting_seed1:all", "reweighting_seed2:all"]
    with open(tmp_path / "s" / "sensitivity.csv") as f:
        assert f.readline().startswith("# Command: `scripts/inference_sensitivity.py")
        rows = {(x["variant"], x["parameter"]): x for x in csv.DictReader(f)}
    assert math.isclose(float(rows["sd_half", "v"]["shift_sd"]), -0.2, abs_tol=1e-12)  # -0.01 / 0.05
    assert math.isclose(float(rows["sd_double", "v"]["shift_sd"]), 0.2, abs_tol=1e-12)
    assert math.isclose(float(rows["no_truncation", "v"]["shift_sd"]), 0.4, abs_tol=1e-12)
    assert float(rows["box_off", "v"]["shift_sd"]) == 0.0 and float(rows["sd_half", "b2"]["sd_ratio"]) == 1.0
    md = (tmp_path / "s" / "sensitivity.md").read_text()
    assert "(revision abc1234)" in md and "| population-SD bounds halved | `--hyper-sd-scale 0.5` | 0.9200 / 0.0500 (-0.20 SD, x1.00) |" in md
    # Re-weighting seeds 1 and 2: 0.91 and 0.92, average 0.915 against the joint 0.93; the seeds'
    # standard error 0.005 beats the stated sqrt(2) 0.001 / 2, so the combined MCSE is
    # sqrt(0.001^2 + 0.005^2).
    with open(tmp_path / "s" / "routes.csv") as f:
        f.readline()
        v = next(x for x in csv.DictReader(f) if x["parameter"] == "v")
    assert math.isclose(float(v["difference_over_combined_mcse"]), -0.015 / math.hypot(0.001, 0.005), rel_tol=1e-9)
    # The population SDs' medians: 0.05 for the joint route, 0.08 for re-weighting.
    md = (tmp_path / "s" / "routes.md").read_text()
    assert "| sd_v | 0.0500 | 0.0800 | 0.0800 |" in md and "| sd_b2 | 1.00 | 1.00 | 1.00 |" in md
    # A second run finds every run finished and runs nothing; a build of another revision runs all.
    r, ran = run(tmp_path)
    assert r.returncode == 0 and ran == []
    r, ran = run(tmp_path, revision="def5678")
    assert r.returncode == 0 and len(ran) == 10


def test_the_joint_route_over_the_seeds_of_a_seed_study(tmp_path):
    study = tmp_path / "seed_study.csv"
    lines = ["seed,parameter,mean,sd,mcse_mean"]
    for seed, v in ((1, 0.92), (2, 0.94)):
        lines += [f"{seed},v,{v},0.05,0.002"] + [f"{seed},{p},2,1,0.001" for p in ("mu_uN_per_m", "kb_J", "b2", "etam_Pa_s_um")]
    study.write_text("\n".join(lines) + "\n")
    r, _ = run(tmp_path, "--seed-study", str(study))
    assert r.returncode == 0, r.stderr
    md = (tmp_path / "s" / "routes.md").read_text()
    assert "the mean over the 2 seeds of" in md
    # Joint 0.93 ± sqrt(2) 0.002 / 2.
    assert "| v | 0.9300 ± 0.0014 |" in md
    r, _ = run(tmp_path, "--seed-study", str(tmp_path / "missing.csv"))
    assert r.returncode != 0 and "--seed-study" in r.stderr and "no such file" in r.stderr
