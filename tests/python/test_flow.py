"""trbc.flow_shear and trbc.flow_tube against `trbc flow shear` and `trbc flow tube`; bad input."""
from pathlib import Path

import numpy as np
import pytest

import trbc


def test_flow_shear_gives_the_cli_numbers(run_cli, cache):
    kw = dict(eta_out_mPa_s=28.9, shear_rate_per_s=20.0, level=1, rotations=2.0)
    py = trbc.flow_shear(**kw, cache_dir=cache, threads=1)
    cli = run_cli("flow", "shear", "--eta-out", 28.9, "--shear-rate", 20.0, "--level", 1, "--rotations", 2.0,
                  "--cache", cache, "--threads", 1)
    assert py["observables"] == cli["observables"]
    assert py["analysis"] == cli["analysis"]
    assert py["diagnostics"]["steps"] == cli["diagnostics"]["steps"]
    # One record: the parameters as flow.json has them, the cell's source aside.
    assert {k: v for k, v in py["parameters"].items() if k != "cell_source"} == \
        {k: v for k, v in cli["parameters"].items() if k != "cell_source"}
    ts = py["time_series"]
    n = len(ts["t_s"])
    assert n == cli["diagnostics"]["frames"]
    assert ts["centroid_um"].shape == (n, 3)
    # frames every 0.1 / rate up to t_end = 2 x 4 pi / rate
    assert 2.0 * 4 * np.pi - 0.1 < ts["shear_strain"][-1] <= 2.0 * 4 * np.pi
    np.testing.assert_allclose(np.diff(ts["shear_strain"]), 0.1, rtol=1e-9)
    assert py["final_shape"].area == pytest.approx(135.0, rel=0.01)


@pytest.mark.parametrize("kwargs, name", [
    (dict(shear_rate_per_s=-1.0), "shear_rate_per_s"), (dict(eta_out_mPa_s=0.0), "eta_out_mPa_s"),
    (dict(level=9), "level"), (dict(v=0.5), "v"), (dict(FvK=100.0, kb_J=2e-19), "kb_J"),
    (dict(rotations=0.0), "rotations"), (dict(frame_interval=-1.0), "frame_interval"), (dict(dt=500.0), "dt"),
    (dict(tilt_deg=95.0), "tilt_deg"), (dict(tilt_deg=-1.0), "tilt_deg"),
    (dict(start="tilted"), "start"), (dict(temperature_K=500.0), "temperature_K"),
    (dict(temperature_K=293.0, thermal_step=0.0), "thermal_step"),
])
def test_flow_shear_bad_input(kwargs, name):
    args = {**dict(eta_out_mPa_s=28.9, shear_rate_per_s=20.0, level=1, rotations=1.0), **kwargs}
    with pytest.raises(ValueError, match=name):
        trbc.flow_shear(**args)


def test_flow_shear_random_start_and_fluctuations_are_seeded(run_cli, cache):
    """The ensemble start and the thermal noise give the CLI's numbers, repeat with their seed and
    differ between seeds."""
    kw = dict(eta_out_mPa_s=28.9, shear_rate_per_s=20.0, level=1, rotations=0.5, cache_dir=cache, threads=1)
    a = trbc.flow_shear(**kw, start="random", seed=4, temperature_K=293.15)
    b = trbc.flow_shear(**kw, start="random", seed=4, temperature_K=293.15)
    c = trbc.flow_shear(**kw, start="random", seed=5, temperature_K=293.15)
    np.testing.assert_array_equal(a["time_series"]["inclination_deg"], b["time_series"]["inclination_deg"])
    assert not np.array_equal(a["time_series"]["inclination_deg"], c["time_series"]["inclination_deg"])
    cli = run_cli("flow", "shear", "--eta-out", 28.9, "--shear-rate", 20.0, "--level", 1, "--rotations", 0.5,
                  "--start", "random", "--seed", 4, "--temperature", 293.15, "--cache", cache, "--threads", 1)
    assert cli["parameters"]["seed"] == 4 and cli["parameters"]["start"] == "random"
    assert cli["diagnostics"]["thermal"]["lanczos_iterations_per_step"] > 1
    assert a["diagnostics"]["steps"] == cli["diagnostics"]["steps"]


def test_flow_shear_stops_when_steady_like_the_cli(run_cli, cache):
    kw = dict(eta_out_mPa_s=28.9, shear_rate_per_s=50.0, level=1, rotations=10.0, cache_dir=cache, threads=1)
    py = trbc.flow_shear(**kw, stop_when_steady=True)
    cli = run_cli("flow", "shear", "--eta-out", 28.9, "--shear-rate", 50.0, "--level", 1, "--rotations", 10.0,
                  "--stop-when-steady", "--cache", cache, "--threads", 1)
    assert cli["diagnostics"]["stopped_when_steady"]
    assert 4.0 <= cli["diagnostics"]["rotations_run"] < 10.0
    assert py["observables"] == cli["observables"]
    assert py["time_series"]["shear_strain"][-1] < 10.0 * 4 * np.pi


TUBE = dict(radius_um=3.3, pressure_gradient_mmHg_per_mm=30.0, level=1, wall_points=12, settle_R_over_V=10.0,
            duration_R_over_V=8.0, frame_interval=0.5)


def test_flow_tube_gives_the_cli_numbers(run_cli, cache):
    py = trbc.flow_tube(**TUBE, cache_dir=cache, threads=1)
    cli = run_cli("flow", "tube", "--radius", 3.3, "--pressure-gradient", 30.0, "--level", 1, "--wall-points", 12,
                  "--settle", 10.0, "--duration", 8.0, "--frame-interval", 0.5, "--cache", cache, "--threads", 1)
    assert py["observables"] == cli["observables"]
    assert py["observables"]["velocity_cm_per_s"] > 0.0
    assert py["observables"]["velocity_over_centre_line"] < 1.0
    for key in ("steps", "rejected_steps", "wall_clearance_min_um", "t_reached_R_over_V"):
        assert py["diagnostics"][key] == cli["diagnostics"][key], key
    settling = cli["diagnostics"]["settling"]
    for key in ("settled", "t_reached_R_over_V", "final_length_um", "final_width_um"):
        assert py["settling"][key] == settling[key], key
    assert py["settling"]["steps"] == settling["steps"]
    assert py["diagnostics"]["plateau"] == cli["diagnostics"]["plateau"]
    assert {k: v for k, v in py["parameters"].items() if k != "cell_source"} == \
        {k: v for k, v in cli["parameters"].items() if k != "cell_source"}
    ts = py["time_series"]
    n = len(ts["t_s"])
    assert n == cli["diagnostics"]["frames"] == 17
    assert ts["centroid_um"].shape == (n, 3)
    np.testing.assert_allclose(np.diff(ts["t_R_over_V"]), 0.5, rtol=1e-9)
    np.testing.assert_allclose(ts["t_s"], ts["t_R_over_V"] * py["parameters"]["time_unit_R_over_V_s"], rtol=1e-12)
    assert np.all(np.diff(ts["centroid_um"][:, 0]) > 0.0)  # downstream
    assert np.all(ts["clearance_um"] > 0.0)
    assert py["final_shape"].area == pytest.approx(135.0, rel=0.01)


@pytest.mark.parametrize("kwargs, name", [
    (dict(radius_um=1.0), "radius_um"), (dict(pressure_gradient_mmHg_per_mm=0.0), "pressure_gradient_mmHg_per_mm"),
    (dict(eta_out_mPa_s=-1.0), "eta_out_mPa_s"), (dict(viscosity_ratio=2.0), "viscosity_ratio"),
    (dict(settle_R_over_V=5.0), "settle_R_over_V"), (dict(settle_relax_R_over_V=1.0, settle_etam_Pa_s_um=0.05), "settle_etam_Pa_s_um"),
    (dict(settle_etam_Pa_s_um=0.0), "settle_etam_Pa_s_um"), (dict(level=5), "level"), (dict(mu_uN_per_m=20.0), "mu_uN_per_m"),
    (dict(duration_R_over_V=0.0), "duration_R_over_V"), (dict(tube_length_um=5.0), "tube_length_um"),
])
def test_flow_tube_bad_input(kwargs, name, cache):
    with pytest.raises(ValueError, match=name):
        trbc.flow_tube(**{**TUBE, **kwargs}, cache_dir=cache)


def test_flow_tube_failure_raises_numerical_error(cache):
    with pytest.raises(trbc.NumericalError, match="settling stage"):
        trbc.flow_tube(**{**TUBE, "max_steps": 2}, cache_dir=cache)


def test_load_validation_reads_the_shipped_bands():
    d = Path(__file__).resolve().parents[2] / "results" / "validation" / "theta_new_level2_bands"
    v = trbc.load_validation(d)
    bands = v["bands"]
    n = len(bands["case"])
    assert n == len(v["summary"]["draws"]["bands"])
    with_value = bands["with_value"] > 0
    assert np.all(bands["q05"][with_value] <= bands["median"][with_value])
    assert np.all(bands["median"][with_value] <= bands["q95"][with_value])
    assert np.all(bands["q05_mcse"][with_value] >= 0)
    assert np.all(np.isnan(bands["median"][~with_value]))
    # the per-kind counts of the summary are those of the rows
    for kind, t in v["summary"]["summary"]["draws"]["kinds"].items():
        rows = [k for k in range(n) if bands["kind"][k] == kind]
        assert len(rows) == t["compared"]
        assert sum(bands["band_verdict"][k] == "overlap" for k in rows) == t["band_overlap"]
        assert sum(bands["band_verdict_within_mcse"][k] == "yes" for k in rows) == t["band_verdict_within_mcse"]
    assert len(v["draws"]["case_id"]) == v["summary"]["summary"]["draws"]["runs"]


def test_load_validation_names_a_directory_without_results(tmp_path):
    with pytest.raises(ValueError, match="no validation.json"):
        trbc.load_validation(tmp_path)


def test_validation_data_gives_the_verdicts_sets_in_trbcs_units():
    sets = trbc.validation_data()
    angles = [s for s in sets if s["observable"] == "inclination_deg"]
    assert [s["eta_out_mPa_s"] for s in angles] == [10.7, 23.9, 55.9, 104.0]
    for s in sets:
        assert s["y"].shape == (len(s["x"]), len(s["y_columns"]))
    a = angles[1]
    assert a["y"].shape[1] == 7 and np.isnan(a["y"][0, 0]) and a["y"][0, 2] == pytest.approx(12.053)
    ttf = next(s for s in sets if s["observable"] == "ttf_4pi_f_over_rate")
    assert ttf["y"][0, 0] == pytest.approx(4 * np.pi * 0.062906)  # the file holds f / rate
    hochmuth = next(s for s in sets if not s["judged"])
    assert hochmuth["x"][0] == pytest.approx(0.0035111)  # mm/s in the file, cm/s here
    with pytest.raises(ValueError, match="is not a validation data folder"):
        trbc.validation_data(Path("/nonexistent"))
