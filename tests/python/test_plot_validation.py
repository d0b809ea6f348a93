"""scripts/plot_validation.py takes its experimental points from the output's experimental_data.json
(what `trbc validate` compared with): every figure of a shipped set differs from the same figure
drawn from an empty list of sets."""
import json
import shutil
import subprocess
import sys
from pathlib import Path

import trbc

REPO = Path(__file__).resolve().parents[2]
SCRIPT = REPO / "scripts" / "plot_validation.py"
SHIPPED = REPO / "results" / "validation" / "theta_new_level3"
FIGURES = ["angle_vs_shear_rate.png", "ttf_vs_shear_rate.png", "critical_stress_vs_eta.png", "tube_velocity_vs_pg.png",
           "tube_length_vs_velocity.png"]


def plot(out_dir, figures):
    return subprocess.run([sys.executable, str(SCRIPT), str(out_dir), "--out", str(figures)], capture_output=True, text=True,
                          cwd=REPO)


def test_figures_take_the_points_of_experimental_data_json(tmp_path):
    d = tmp_path / "run"
    d.mkdir()
    for f in ("shear.csv", "threshold.csv", "tube.csv", "validation.json"):
        shutil.copy(SHIPPED / f, d / f)
    (d / "experimental_data.json").write_text("[]")
    r = plot(d, tmp_path / "bare")
    assert r.returncode == 0, r.stderr
    sets = trbc.validation_data(REPO / "data" / "experiments" / "validation")
    (d / "experimental_data.json").write_text(json.dumps([{**s, "x": s["x"].tolist(),
                                                             "y": [[None if v != v else v for v in row] for row in s["y"].tolist()]}
                                                            for s in sets]))
    r = plot(d, tmp_path / "figs")
    assert r.returncode == 0, r.stderr
    assert "experimental points not drawn" not in r.stderr
    for f in FIGURES:
        drawn, bare = (tmp_path / "figs" / f).read_bytes(), (tmp_path / "bare" / f).read_bytes()
        assert drawn != bare, f"{f}: the experimental points are missing"


def test_intermittent_cases_without_an_angle_are_drawn(tmp_path):
    """The angle figure marks the intermittent cases that have no angle, as it marks the tumbling
    ones: removing those rows changes the figure."""
    lines = (SHIPPED / "shear.csv").read_text().splitlines(keepends=True)
    header = next(l for l in lines if not l.startswith("#")).strip().split(",")
    col = {name: k for k, name in enumerate(header)}

    def intermittent_without_angle(line):
        cells = line.strip().split(",")
        return (len(cells) == len(header) and cells[col["sweep"]] == "angle" and cells[col["regime"]] == "intermittent"
                and cells[col["inclination_deg"]] == "")

    assert any(intermittent_without_angle(l) for l in lines)
    figures = {}
    for name, keep in (("all", lines), ("without", [l for l in lines if not intermittent_without_angle(l)])):
        d = tmp_path / name
        d.mkdir()
        (d / "shear.csv").write_text("".join(keep))
        for f in ("validation.json", "experimental_data.json"):
            shutil.copy(SHIPPED / f, d / f)
        r = plot(d, tmp_path / f"{name}_figs")
        assert r.returncode == 0, r.stderr
        figures[name] = (tmp_path / f"{name}_figs" / "angle_vs_shear_rate.png").read_bytes()
    assert figures["all"] != figures["without"]
