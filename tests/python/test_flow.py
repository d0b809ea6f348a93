"""trbc.flow_shear against `trbc flow shear`; bad input."""
import numpy as np
import pytest

import trbc


def test_flow_shear_gives_the_cli_numbers(run_cli, cache):
    kw = dict(eta_out_mPa_s=28.9, shear_rate_per_s=20.0, level=1, rotations=2.0)
    py = trbc.flow_shear(**kw, cache_dir=cache, threads=1)
    cli = run_cli("flow", "shear", "--eta-out", 28.9, "--shear-rate", 20.0, "--level", 1, "--rotations", 2.0,
                  "--cache", cache, "--threads", 1)
    assert py["observables"] == cli["observables"]
    assert py["diagnostics"]["steps"] == cli["diagnostics"]["steps"]
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
])
def test_flow_shear_bad_input(kwargs, name):
    args = {**dict(eta_out_mPa_s=28.9, shear_rate_per_s=20.0, level=1, rotations=1.0), **kwargs}
    with pytest.raises(ValueError, match=name):
        trbc.flow_shear(**args)
