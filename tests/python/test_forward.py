"""trbc.simulate and trbc.sfs against `trbc simulate` and `trbc sfs`; bad input; Ctrl-C."""
import os
import signal
import threading
import time

import numpy as np
import pytest

import trbc

OBSERVABLES = ("D_um", "hmin_um", "hmax_um", "D0_um", "D1_um", "tc_s")


def test_simulate_gives_the_cli_numbers(run_cli, cache):
    # level 2 keeps the suite fast; the comparison at level 3 is in docs/PYTHON.md
    args = dict(v=0.9, mu_uN_per_m=5.0, FvK=300.0, b2=1.2, etam_Pa_s_um=0.5, Fext_pN=80.0)
    py = trbc.simulate(**args, level=2, cache_dir=cache, force_curve=[40.0])
    cli = run_cli("simulate", "--v", 0.9, "--mu", 5.0, "--FvK", 300.0, "--b2", 1.2, "--etam", 0.5, "--Fext", 80.0,
                  "--level", 2, "--cache", cache, "--force-curve", 40)
    assert py["status"] == cli["status"] == "ok"
    for k in OBSERVABLES:
        assert py["observables"][k] == cli["observables"][k], k
    assert py["parameters"] == cli["parameters"]
    assert py["stretching_curve"] == cli["stretching_curve"]
    assert py["diagnostics"]["equilibrium"]["iterations"] == cli["diagnostics"]["equilibrium"]["iterations"]
    # arrays and shapes
    assert isinstance(py["shapes"]["equilibrium"], trbc.Mesh)
    assert py["shapes"]["equilibrium"].n_vertices == 162
    assert py["shapes"]["equilibrium"].area == pytest.approx(135.0, rel=1e-6)
    assert py["stretching_curve_arrays"]["Fext_pN"].tolist() == [40.0]
    r = py["relaxation"]
    assert r["t_s"].shape == r["z"].shape and r["t_s"][0] == 0.0 and r["z"][0] > r["z"][-1]
    D = py["observables"]["D_um"]
    assert 2 * py["equilibrium_profile"]["r_um"].max() == pytest.approx(D, rel=0.05)


def test_simulate_kb_and_subset_of_experiments(run_cli, cache):
    py = trbc.simulate(v=0.95, kb_J=2e-19, level=2, experiments=("eq",), cache_dir=cache)
    cli = run_cli("simulate", "--v", 0.95, "--kb", 2e-19, "--level", 2, "--experiments", "eq", "--cache", cache)
    assert py["observables"] == cli["observables"]
    assert py["observables"]["D0_um"] is None and py["observables"]["tc_s"] is None
    assert "stretched" not in py["shapes"]


def test_sfs_gives_the_cli_mesh(tmp_path, run_cli, cache):
    s = trbc.sfs(0.8, level=2, cache_dir=cache)
    out = run_cli("sfs", "--v", 0.8, "--level", 2, "--cache", cache, "--out", tmp_path / "s.off")
    m = trbc.Mesh.read(str(tmp_path / "s.off"))
    np.testing.assert_allclose(s["mesh"].vertices, m.vertices, rtol=0, atol=1e-13)
    assert s["mesh"].area == pytest.approx(135.0, rel=1e-12)
    assert s["diagnostics"]["reduced_volume"] == out["sfs"]["reduced_volume"]
    assert s["diagnostics"]["converged"]


@pytest.mark.parametrize("kwargs, name", [
    (dict(v=1.2), "v"), (dict(mu_uN_per_m=-1.0), "mu_uN_per_m"), (dict(FvK=5.0), "FvK"), (dict(b2=9.0), "b2"),
    (dict(etam_Pa_s_um=3.0), "etam_Pa_s_um"), (dict(Fext_pN=500.0), "Fext_pN"), (dict(kb_J=-1e-19), "kb_J"),
    (dict(level=1), "level"), (dict(experiments=("eq", "shear")), "experiments"), (dict(FvK=200.0, kb_J=2e-19), "kb_J"),
    (dict(in_plane_axis="diagonal"), "in_plane_axis"), (dict(equilibrium_symmetry="mirror"), "equilibrium_symmetry"),
    (dict(equilibrium_kicks=0), "equilibrium_kicks"),
])
def test_simulate_bad_input_raises_value_error_naming_the_parameter(kwargs, name):
    with pytest.raises(ValueError, match=name):
        trbc.simulate(**{**dict(level=2), **kwargs})


def test_sfs_bad_input():
    with pytest.raises(ValueError, match="v"):
        trbc.sfs(1.5, level=2, cache=False)
    with pytest.raises(ValueError, match="level"):
        trbc.sfs(0.9, level=9, cache=False)


def test_ctrl_c_interrupts_a_long_call():
    # a level-5 SFS without cache takes minutes (a level-4 one can finish in 0.2 s on an idle
    # machine, before the signal); SIGINT after 0.3 s must end it with KeyboardInterrupt
    timer = threading.Timer(0.3, lambda: os.kill(os.getpid(), signal.SIGINT))
    t0 = time.monotonic()
    timer.start()
    with pytest.raises(KeyboardInterrupt):
        trbc.sfs(0.7, level=5, cache=False)
    timer.join()
    assert time.monotonic() - t0 < 3.0
