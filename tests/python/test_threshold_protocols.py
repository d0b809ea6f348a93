"""scripts/threshold_protocols.py on a stand-in for `trbc flow shear` whose cell tank-treads from a
known shear stress: the in-plane table, the fluctuating rows run stress by stress (--descend), the
resume, and the tables."""
import csv
import os
import shlex
import stat
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "threshold_protocols.py"

# Tank-treads from 0.1 Pa from the in-plane start, from 0.06 Pa when fluctuating (seed 3 only at
# 0.06-0.1 Pa, so the fraction there is 1/3); writes OUT/flow.json as `flow shear` does.
FAKE = r'''
import json, os, sys
a = sys.argv[1:]
val = lambda k: a[a.index(k) + 1]
stress = float(val("--eta-out")) * 1e-3 * float(val("--shear-rate"))
thermal = "--temperature" in a
seed = int(val("--seed")) if "--seed" in a else 0
tt = stress >= 0.1 or (thermal and stress >= 0.06 and (seed == 3 or stress >= 0.09))
out = val("--out")
os.makedirs(out, exist_ok=True)
with open(os.path.join(out, "flow.json"), "w") as f:
    cell = {k: float(val("--" + o)) for k, o in (("v", "v"), ("mu_uN_per_m", "mu"), ("kb_J", "kb"), ("b2", "b2"), ("etam_Pa_s_um", "etam"))}
    rec = {"status": "ok", "observables": {"regime": "tank-treading" if tt else "tumbling"}, "parameters": {"cell": cell},
           "diagnostics": {"thermal": {"step_times_rate": 0.05}} if thermal else {}}
    if os.environ.get("FAKE_REVISION"):
        rec["provenance"] = {"revision": os.environ["FAKE_REVISION"]}
    json.dump(rec, f)
with open(os.environ["FAKE_LOG"], "a") as f:
    f.write(os.path.basename(out) + "\n")
'''


def run(tmp_path, *args, revision=""):
    fake = tmp_path / "trbc"
    fake.write_text(f"#!/bin/sh\nexec {shlex.quote(sys.executable)} {shlex.quote(str(tmp_path / 'fake.py'))} \"$@\"\n")
    (tmp_path / "fake.py").write_text(FAKE)
    fake.chmod(fake.stat().st_mode | stat.S_IEXEC)
    r = subprocess.run([sys.executable, str(SCRIPT), "--trbc", str(fake), "--out", str(tmp_path / "scan"), "--cells", "reference",
                        "--viscosities", "30", "--fluctuating", "3", "--jobs", "2", *args],
                       capture_output=True, text=True, env=dict(os.environ, FAKE_LOG=str(tmp_path / "ran.log"), FAKE_REVISION=revision))
    assert r.returncode == 0, r.stderr
    log = tmp_path / "ran.log"
    ran = log.read_text().split() if log.exists() else []
    log.unlink(missing_ok=True)
    return ran, r.stdout


def test_fluctuating_rows_descend_from_the_in_plane_threshold(tmp_path):
    # Stresses at 30 mPa s: 0.03, 0.0458, 0.0701, 0.107, 0.164, 0.25 Pa.
    ran, _ = run(tmp_path, "--protocols", "in-plane")
    assert len(ran) == 6
    ran, table = run(tmp_path, "--protocols", "fluctuating", "--descend")
    # From 0.107 (the in-plane start's first tank-treading stress) down: 0.107 (3/3), 0.0701 (1/3),
    # 0.0458 (0/3), where the row stops; 0.164, 0.25 and 0.03 are not run.
    assert sorted(ran) == sorted(f"reference_eta30_tau{s}_T{k}" for s in ("0.1071", "0.07006", "0.04584") for k in (1, 2, 3))
    assert "| reference | 30 | in-plane | 0.03: 0/1, 0.0458: 0/1, 0.0701: 0/1, 0.107: 1/1, 0.164: 1/1, 0.25: 1/1 | [0.0701, 0.107] |" in table
    row = next(line for line in table.splitlines() if "| fluctuating |" in line)
    assert "0.0458: 0/3, 0.0701: 1/3, 0.107: 3/3 | 0.0" in row and "in [0.0701, 0.107]" in row
    with open(tmp_path / "scan" / "cases.csv") as f:
        status = {r["id"]: r["status"] for r in csv.DictReader(f)}
    assert status["reference_eta30_tau0.25_T1"] == "not run" and status["reference_eta30_tau0.07006_T2"] == "ok"
    head = (tmp_path / "scan" / "threshold_table.md").read_text().splitlines()[0]
    assert head.startswith("Command: `scripts/threshold_protocols.py --trbc") and "(revision not recorded)" in head
    assert "Cells: reference: v 0.95, mu 4.99, kb 2.1e-19, b2 1.84, etam 0.42." in head
    # A second run keeps every finished case and runs nothing.
    ran, _ = run(tmp_path, "--protocols", "fluctuating", "--descend")
    assert ran == []


def test_a_fresh_scan_runs_the_in_plane_cases_before_it_descends(tmp_path):
    ran, _ = run(tmp_path, "--protocols", "in-plane,fluctuating", "--descend")
    assert sorted(ran[:6]) == sorted(f"reference_eta30_tau{s}_inplane" for s in ("0.03", "0.04584", "0.07006", "0.1071", "0.1636", "0.25"))
    assert sorted(ran[6:]) == sorted(f"reference_eta30_tau{s}_T{k}" for s in ("0.1071", "0.07006", "0.04584") for k in (1, 2, 3))
    r = subprocess.run([sys.executable, str(SCRIPT), "--out", str(tmp_path / "x"), "--descend"], capture_output=True, text=True)
    assert r.returncode != 0 and "--fluctuating N >= 1" in r.stderr


def test_a_kept_case_of_another_cell_runs_again(tmp_path):
    ran, _ = run(tmp_path, "--protocols", "in-plane")
    assert len(ran) == 6
    rec = tmp_path / "scan" / "cases" / "reference_eta30_tau0.25_inplane" / "flow.json"
    rec.write_text('{"status": "ok", "observables": {"regime": "tank-treading"}, '
                   '"parameters": {"cell": {"v": 0.95, "mu_uN_per_m": 4.5, "kb_J": 2.1e-19, "b2": 1.84, "etam_Pa_s_um": 0.42}}}')
    ran, _ = run(tmp_path, "--protocols", "in-plane")
    assert ran == ["reference_eta30_tau0.25_inplane"]
    # The re-run record holds the scan's own cell (mu 4.99) and is kept.
    ran, _ = run(tmp_path, "--protocols", "in-plane")
    assert ran == []
    # A record that names no cell (a failure recorded without one) runs again.
    rec.write_text('{"status": "failed", "observables": {"regime": null}}')
    ran, _ = run(tmp_path, "--protocols", "in-plane")
    assert ran == ["reference_eta30_tau0.25_inplane"]


def test_the_table_names_the_revisions_of_the_records_it_counts(tmp_path):
    run(tmp_path, "--protocols", "in-plane,fluctuating", "--descend", revision="abc1234")
    # A record of another cell and build where --descend runs nothing (0.25 Pa, fluctuating): not
    # counted, so not named.
    stale = tmp_path / "scan" / "cases" / "reference_eta30_tau0.25_T1"
    stale.mkdir(parents=True)
    (stale / "flow.json").write_text('{"status": "ok", "observables": {"regime": "tank-treading"}, "provenance": {"revision": "0ld0000"}, '
                                     '"parameters": {"cell": {"v": 0.95, "mu_uN_per_m": 4.5, "kb_J": 2.1e-19, "b2": 1.84, "etam_Pa_s_um": 0.42}}}')
    ran, table = run(tmp_path, "--protocols", "in-plane,fluctuating", "--descend", revision="abc1234")
    assert ran == []
    head = (tmp_path / "scan" / "threshold_table.md").read_text().splitlines()[0]
    assert "(revision abc1234)" in head, head
    assert "0.25: 1/1 |" in table and "0.25: 1/" not in next(line for line in table.splitlines() if "| fluctuating |" in line)


def test_the_theta_new_cell_needs_a_posterior(tmp_path):
    r = subprocess.run([sys.executable, str(SCRIPT), "--out", str(tmp_path / "x"), "--cells", "theta_new", "--dry-run"],
                       capture_output=True, text=True)
    assert r.returncode != 0 and "--cells theta_new needs --posterior" in r.stderr
