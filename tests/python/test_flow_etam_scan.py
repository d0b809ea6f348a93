"""scripts/flow_etam_scan.py on the shipped flow networks: the η_m at which each shear set fits,
with the rest of a posterior's mean cell held. Its rows follow the networks: at the η_m it calls
best for an angle set, the networks' mean bias over that set lies within their CV error, and at
the posterior's own η_m (here far from it) the angle sets do not fit."""
import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import trbc

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "flow_etam_scan.py"


def posterior(tmp_path, etam):
    rng = np.random.default_rng(3)
    d = tmp_path / "theta_new"
    d.mkdir()
    with open(d / "samples.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["v", "mu_uN_per_m", "kb_J", "b2", "etam_over_mu_s", "etam_Pa_s_um", "log_likelihood", "log_prior"])
        for _ in range(50):
            mu = 4.65 + 0.01 * rng.standard_normal()
            w.writerow([0.93, mu, 2.26e-19, 2.0, etam / mu, etam, 0.0, 0.0])
    return d


def run(*args):
    return subprocess.run([sys.executable, str(SCRIPT), *map(str, args)], capture_output=True, text=True)


def test_each_angle_set_fits_where_the_networks_bias_vanishes(tmp_path):
    post = posterior(tmp_path, etam=1.5)
    r = run("--posterior", post, "--surrogate", ROOT / "data" / "surrogates" / "flow", "--out", tmp_path / "out")
    assert r.returncode == 0, r.stderr
    header = open(tmp_path / "out" / "etam_scan.csv").readline()
    assert trbc.__revision__ and f"trbc {trbc.__version__} ({trbc.__revision__}) | command: " in header, header
    rows = list(csv.DictReader(l for l in open(tmp_path / "out" / "etam_scan.csv") if not l.startswith("#")))
    assert "etam_scan.md" in {p.name for p in (tmp_path / "out").iterdir()}
    angles = [x for x in rows if x["set"].startswith("inclination_deg")]
    assert len(angles) == 4 and any(x["set"].startswith("critical stress") for x in rows)
    cv = json.loads((ROOT / "data" / "surrogates" / "flow" / "training.json").read_text())["cross_validation"]["pooled"]
    f = trbc.FlowSurrogate(ROOT / "data" / "surrogates" / "flow")
    data = {s["eta_out_mPa_s"]: s for s in trbc.validation_data() if s["observable"] == "inclination_deg"}
    for x in angles:
        eta = float(x["set"].split(" at ")[1].split(" mPa s")[0])
        best = float(x["etam_best_Pa_s_um"])
        assert float(x["etam_lo_Pa_s_um"]) <= best <= float(x["etam_hi_Pa_s_um"])
        s = data[eta]
        keep = np.isfinite(s["y"]).any(axis=1)
        p = f.predict(eta_out_mPa_s=eta, shear_rate_per_s=s["x"][keep], v=0.93, mu_uN_per_m=4.65, kb_J=2.26e-19, b2=2.0,
                      etam_Pa_s_um=best)
        tt = p["p_tank_treading"] > 0.5
        bias = np.mean(p["inclination_deg"][tt] - np.nanmean(s["y"][keep], axis=1)[tt])
        # 1.05: the test's cell holds mu at 4.65, the script at the synthetic posterior's mean.
        assert abs(bias) <= cv["inclination_rmse_deg"] * 1.05, (eta, best, bias)
        # This posterior's η_m, 1.5 Pa s µm, lies outside every angle set's interval.
        assert float(x["etam_hi_Pa_s_um"]) < 1.5, x


def test_bad_arguments_are_named(tmp_path):
    r = run("--posterior", tmp_path, "--out", tmp_path / "out")
    assert r.returncode != 0 and "no samples.csv" in r.stderr
    good = posterior(tmp_path, 0.7)
    r = run("--posterior", good, "--grid", "5", "--out", tmp_path / "out")
    assert r.returncode != 0 and "--grid 5 is outside [20, 100000]" in r.stderr
    phase1 = tmp_path / "phase1"
    phase1.mkdir()
    (phase1 / "samples.csv").write_text("v,mu_uN_per_m,log_likelihood,log_prior\n0.93,4.6,0,0\n")
    r = run("--posterior", phase1, "--out", tmp_path / "out")
    assert r.returncode != 0 and "no column kb_J, b2, etam_Pa_s_um" in r.stderr, r.stderr
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "samples.csv").write_text((good / "samples.csv").read_text().replace("0.93,", "0.3,"))
    r = run("--posterior", outside, "--out", tmp_path / "out")
    assert r.returncode != 0 and "lies outside it" in r.stderr, r.stderr


def test_calibrated_cell_is_the_statistics_means_where_the_inference_has_them(tmp_path):
    """trbc.calibrated_cell, the cell of every --posterior: the sample means of a bare samples.csv,
    the Rao-Blackwellised means of the inference's posterior_stats.csv beside it otherwise."""
    bare = trbc.calibrated_cell(posterior(tmp_path, etam=0.7))
    samples = trbc.Posterior(tmp_path / "theta_new" / "samples.csv")
    assert bare["estimator"] == "sample means"
    assert bare["mu_uN_per_m"] == pytest.approx(samples["mu_uN_per_m"].mean(), rel=1e-12)
    assert bare["FvK"] == pytest.approx(bare["mu_uN_per_m"] * 1e-6 * (3.2776457e-6) ** 2 / bare["kb_J"], rel=1e-4)

    inf = tmp_path / "inf"
    (inf / "phase3").mkdir(parents=True)
    (tmp_path / "theta_new").rename(inf / "phase3" / "theta_new")
    means = {"v": 0.929, "mu_uN_per_m": 4.66, "kb_J": 2.26e-19, "b2": 2.001, "etam_Pa_s_um": 0.699}
    with open(inf / "posterior_stats.csv", "w") as f:
        f.write("# a provenance line\nposterior,parameter,mean,sd\n")
        f.write("evans_fung_1972,v,0.5,0.1\n")
        for k, m in means.items():
            f.write(f"theta_new,{k},{m!r},1\n")
    cell = trbc.calibrated_cell(inf / "phase3" / "theta_new")
    assert cell["estimator"].startswith("Rao-Blackwellised")
    for k, m in means.items():
        assert cell[k] == m, (k, cell[k])
