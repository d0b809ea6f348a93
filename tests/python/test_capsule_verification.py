"""scripts/capsule_verification.py on a stand-in for `trbc flow capsule`: a failed case (a non-zero
exit, or an output that is no record) makes the run exit non-zero without a record of it, the
finished cases still make the table, and a second run runs only the missing cases."""
import json
import os
import stat
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[2] / "scripts" / "capsule_verification.py"

# D12 = Ca (5/8)(3 + 1) for every case; with FAIL set, Ca 0.6 exits 1 and Ca 0.3 at level 4
# prints no JSON. Each run appends its Ca and level to runs.log beside the fake.
FAKE = r'''
import json, os, sys
a = sys.argv[1:]
val = lambda k: a[a.index(k) + 1]
ca, level = float(val("--ca")), int(val("--level"))
open(os.path.join(os.path.dirname(os.path.abspath(__file__)), "runs.log"), "a").write(f"{ca:g} {level}\n")
if os.environ.get("FAIL") and ca == 0.6:
    sys.exit("the step size fell below its floor")
if os.environ.get("FAIL") and ca == 0.3 and level == 4:
    print("Segmentation fault")
    sys.exit(0)
print(json.dumps({"observables": {"taylor_D12": 2.5 * ca, "inclination_deg": 30.0, "membrane_frequency_over_rate": 0.5,
                                  "steady_state_reached": True, "area_change": 0.0},
                  "diagnostics": {"steps": 100, "wall_s": 1.0}, "series": [1, 2],
                  "provenance": {"vertices": 10 * 4 ** level + 2, "version": "0.1.0", "revision": "abc1234"}}))
'''


def fake_trbc(tmp_path):
    path = tmp_path / "fake_trbc"
    path.write_text(f"#!{sys.executable}\n{FAKE}")
    path.chmod(path.stat().st_mode | stat.S_IEXEC)
    return path


def run(tmp_path, out, fail):
    env = {k: v for k, v in os.environ.items() if k != "FAIL"}
    if fail:
        env["FAIL"] = "1"
    return subprocess.run([sys.executable, str(SCRIPT), "--trbc", str(fake_trbc(tmp_path)), "--out", str(out), "--jobs", "2"],
                          capture_output=True, text=True, env=env)


def test_failed_cases_exit_non_zero_and_run_again_alone(tmp_path):
    out = tmp_path / "capsule"
    p = run(tmp_path, out, fail=True)
    assert p.returncode == 1, p.stderr
    failed = [ln for ln in p.stdout.splitlines() if ": failed" in ln]
    # Ca 0.6 at levels 3 and 4 (exit 1), Ca 0.3 at level 4 (no JSON)
    assert len(failed) == 3, p.stdout
    assert any("not a JSON record" in ln for ln in failed)
    assert any("step size fell below its floor" in ln for ln in failed)
    assert "3 case(s) failed" in p.stderr
    records = sorted(os.listdir(out / "cases"))
    assert not any("tmp" in r for r in records)
    table = (out / "capsule_table.md").read_text()
    assert "| 0.6 | - | - |" in table  # the failed cases' rows stay empty
    assert "(revision abc1234)" in table
    record = json.loads((out / "cases" / records[0]).read_text())
    assert "series" not in record["result"]
    ran = (tmp_path / "runs.log").read_text().splitlines()
    # A second run, the cause gone, runs the three failed cases only and completes the table.
    p = run(tmp_path, out, fail=False)
    assert p.returncode == 0, p.stderr
    again = (tmp_path / "runs.log").read_text().splitlines()[len(ran):]
    assert sorted(again) == ["0.3 4", "0.6 3", "0.6 4"]
    assert "| 0.6 | 1.5000 | 1.5000 |" in (out / "capsule_table.md").read_text()
