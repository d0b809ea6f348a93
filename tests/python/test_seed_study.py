"""scripts/seed_study.py on a stand-in for `trbc infer` whose statistics move with the seed by a known
amount: the theta_new and phase-1 scatter tables, and the resume that runs nothing again."""
import csv
import os
import stat
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "seed_study.py"

HEADER = "posterior,parameter,mean,median,sd,q05,q95,mcse_mean,mcse_median,mcse_sd\n"

# theta_new's v: mean 0.90 + 0.01 seed, SD 0.05. Phase 1: mills_2004 b2 mean 1 + 0.1 seed, SD 0.2;
# suresh_2005 mu mean 4 (every seed), SD 0.5 + 0.1 seed. Every MCSE 0.01. Each run appends a line to
# --out's ../runs.log, so that the test counts them.
FAKE = r'''
import os, sys
a = sys.argv[1:]
if a == ["--version"]:
    sys.exit(print("0.1.0 (" + os.environ.get("FAKE_REVISION", "abc1234") + ")"))
out, seed = a[a.index("--out") + 1], int(a[a.index("--seed") + 1])
os.makedirs(os.path.join(out, "phase1"), exist_ok=True)
row = lambda post, par, m, sd: f"{post},{par},{m},{m},{sd},{m - sd},{m + sd},0.01,0.01,0.01\n"
head = "# trbc\n" + "''' + HEADER.strip() + r'''\n"
open(os.path.join(out, "posterior_stats.csv"), "w").write(head + row("theta_new", "v", 0.90 + 0.01 * seed, 0.05))
open(os.path.join(out, "phase1", "posterior_stats.csv"), "w").write(
    head + row("mills_2004", "b2", 1 + 0.1 * seed, 0.2) + row("suresh_2005", "mu_uN_per_m", 4, 0.5 + 0.1 * seed))
open(os.path.join(out, "..", "runs.log"), "a").write(f"{seed}\n")
'''


def fake_trbc(tmp_path):
    path = tmp_path / "fake_trbc"
    path.write_text(f"#!{sys.executable}\n{FAKE}")
    path.chmod(path.stat().st_mode | stat.S_IEXEC)
    return path


def run(tmp_path, out, revision="abc1234"):
    return subprocess.run([sys.executable, str(SCRIPT), "--trbc", str(fake_trbc(tmp_path)), "--out", str(out), "--seeds", "1", "2", "3"],
                          capture_output=True, text=True, check=True, env=dict(os.environ, FAKE_REVISION=revision))


def test_the_phase1_table_gives_each_data_sets_scatter_in_posterior_sd(tmp_path):
    out = tmp_path / "study"
    run(tmp_path, out)
    # means 1.1, 1.2, 1.3: SD over the seeds 0.1, over the posterior SD 0.2: 0.5; SDs 0.6, 0.7, 0.8:
    # relative scatter 0.1 / 0.7
    md = (out / "seed_study.md").read_text()
    phase1 = md[md.index("## Phase 1"):]
    rows = [ln.split(" | ") for ln in phase1.splitlines() if ln.startswith("| mills") or ln.startswith("| suresh")]
    assert [r[0] for r in rows] == ["| mills_2004", "| suresh_2005"]  # largest scatter of the mean first
    assert rows[0][1:6] == ["b2", "1.2", "0.500", "0.050", "0.2"]
    assert rows[1][1:4] == ["mu_uN_per_m", "4", "0.000"]
    assert rows[1][6].rstrip(" |") == f"{0.1 / 0.7:.3f}"
    with open(out / "seed_study_phase1.csv") as f:
        table = list(csv.DictReader(f))
    assert len(table) == 6
    assert {(r["seed"], r["data_set"], r["parameter"]) for r in table} == {
        (str(s), d, p) for s in (1, 2, 3) for d, p in (("mills_2004", "b2"), ("suresh_2005", "mu_uN_per_m"))}
    # theta_new: means 0.91-0.93, SD over seeds 0.01 = 0.2 posterior SD
    assert "| v | 0.92 | 0.200 |" in md


def test_a_second_run_runs_no_seed_again_unless_the_build_changed(tmp_path):
    out = tmp_path / "study"
    run(tmp_path, out)
    first = (out / "seed_study.md").read_text()
    run(tmp_path, out)
    assert (out / "runs.log").read_text().split() == ["1", "2", "3"]
    assert (out / "seed_study.md").read_text() == first
    run(tmp_path, out, revision="def5678")
    assert (out / "runs.log").read_text().split() == ["1", "2", "3"] * 2


def test_a_trbc_that_is_missing_or_no_trbc_stops_the_study_before_any_folder_is_made(tmp_path):
    for trbc in (tmp_path / "absent", "/bin/false"):
        r = subprocess.run([sys.executable, str(SCRIPT), "--trbc", str(trbc), "--out", str(tmp_path / "study"), "--seeds", "1"],
                           capture_output=True, text=True)
        assert r.returncode != 0 and "--trbc" in r.stderr and "Traceback" not in r.stderr, r.stderr
        assert not (tmp_path / "study").exists()
