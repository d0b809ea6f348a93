"""scripts/plot_forward.py and scripts/plot_predict.py take the experimental data as trbc reads them for
the calibration (trbc.load_data_sets), so a data directory laid out by a datasets.json works as the
shipped one does."""
import csv
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import trbc

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / "data" / "experiments"
SHIPPED = {"evans_fung_1972": ("equilibrium", "equilibrium/evans_fung_1972.csv"),
           "mills_2004": ("stretching", "stretching/mills_2004/mills_2004.csv"),
           "suresh_2005": ("stretching", "stretching/suresh_2005/suresh_2005.csv"),
           **{f"hochmuth_1979_cell{i}": ("relaxation", f"relaxation/hochmuth_1979/{i}.csv") for i in range(1, 5)}}


def manifest_dir(tmp_path, names):
    """The named shipped sets under other file names, listed in a datasets.json."""
    d = tmp_path / "mine"
    d.mkdir()
    entries = []
    for k, name in enumerate(names):
        experiment, rel = SHIPPED[name]
        shutil.copy(DATA / rel, d / f"set{k}.csv")
        entries.append({"name": name, "experiment": experiment, "file": f"set{k}.csv"})
    (d / "datasets.json").write_text(json.dumps(entries))
    return d


def shipped_sds():
    with open(DATA / "equilibrium" / "evans_fung_1972.csv") as f:
        rows = {r["quantity"]: float(r["sd_um"]) for r in csv.DictReader(ln for ln in f if not ln.startswith("#"))}
    return [rows["D"], rows["hmin"], rows["hmax"]]


def test_the_equilibrium_set_carries_its_standard_deviations():
    ef = next(d for d in trbc.load_data_sets() if d.name == "evans_fung_1972")
    assert np.array_equal(ef.shape_sd_um, shipped_sds())
    other = next(d for d in trbc.load_data_sets() if d.name == "mills_2004")
    assert np.isnan(other.shape_sd_um).all()


def plot_forward(data, out):
    return subprocess.run([sys.executable, str(REPO / "scripts" / "plot_forward.py"), str(REPO / "docs" / "figures" / "reference_L4"),
                           "--data", str(data), "--out", str(out), "--prefix", "t_"], capture_output=True, text=True)


def test_plot_forward_draws_the_sets_of_a_manifest_directory(tmp_path):
    r = plot_forward(manifest_dir(tmp_path, list(SHIPPED)), tmp_path / "figs")
    assert r.returncode == 0, r.stderr
    assert "data set" not in r.stderr, r.stderr  # every set found
    assert [ln.split(":")[0] for ln in r.stdout.splitlines() if ln.startswith("Hochmuth et al. 1979")] == [
        f"Hochmuth et al. 1979, cell {i}" for i in range(1, 5)]
    # the equilibrium table's measured column: the file's means and SDs
    sd = shipped_sds()
    assert f"evans_fung_1972: D 7.82 ± {sd[0]:.3g} um, hmin 0.81 ± {sd[1]:.3g} um, hmax 2.58 ± {sd[2]:.3g} um" in r.stdout
    assert sorted(p.name for p in (tmp_path / "figs").iterdir()) == ["t_equilibrium.png", "t_relaxation.png", "t_stretching.png"]
    # A directory without relaxation data: the figure is still drawn, and a note says so.
    shutil.rmtree(tmp_path / "mine")
    r = plot_forward(manifest_dir(tmp_path, ["evans_fung_1972", "mills_2004"]), tmp_path / "figs2")
    assert r.returncode == 0, r.stderr
    assert "no relaxation data set" in r.stderr and "no stretching data set" not in r.stderr
    # A path the filesystem refuses: drawn without the data, not a traceback.
    r = plot_forward(tmp_path / ("x" * 300), tmp_path / "figs3")
    assert r.returncode == 0 and "experimental data will be missing" in r.stderr, r.stderr


def test_an_equilibrium_set_without_standard_deviations_prints_its_means_alone(tmp_path):
    d = manifest_dir(tmp_path, ["evans_fung_1972"])
    (d / "set0.csv").write_text("quantity,mean_um\nD,7.82\nhmin,0.81\nhmax,2.58\n")
    r = plot_forward(d, tmp_path / "figs")
    assert r.returncode == 0, r.stderr
    assert "evans_fung_1972: D 7.82 um, hmin 0.81 um, hmax 2.58 um" in r.stdout, r.stdout


def test_plot_predict_marks_the_equilibrium_mean_and_sd_of_any_data_directory(tmp_path):
    sys.path.insert(0, str(REPO / "scripts"))
    try:
        import plot_predict
    finally:
        sys.path.pop(0)
    marks = plot_predict.equilibrium_mean_sd(str(manifest_dir(tmp_path, ["mills_2004", "evans_fung_1972"])))
    ef = next(d for d in trbc.load_data_sets() if d.name == "evans_fung_1972")
    assert marks == {k: (m, s) for k, m, s in zip(("D_um", "hmin_um", "hmax_um"), ef.shape, shipped_sds())}
    assert plot_predict.equilibrium_mean_sd(str(tmp_path / "nowhere")) == {}
    assert plot_predict.equilibrium_mean_sd(str(tmp_path / ("x" * 300))) == {}
