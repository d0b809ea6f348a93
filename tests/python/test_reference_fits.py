"""trbc.evans_fung_thickness, trbc.evans_fung_radius_um and trbc.fit_hochmuth: the closed forms they
stand for, recovery of known parameters, bad input."""
import numpy as np
import pytest

import trbc

# Evans & Fung (1972) shape, docs/MEMBRANE_MODEL.md: h(r) = R0 sqrt(1 - rho^2)(c0 + c1 rho^2 + c2 rho^4), rho = r/R0
R0 = 3.91
C = (0.207161, 2.002558, -1.122762)


def evans_fung(r):
    rho2 = (np.asarray(r, dtype=float) / R0) ** 2
    return R0 * np.sqrt(1 - rho2) * (C[0] + C[1] * rho2 + C[2] * rho2 ** 2)


def hochmuth(t, tc, zinf, z0):
    """z = zinf (Lam + e)/(Lam - e), e = exp(-t/tc), Lam = (z0 + zinf)/(z0 - zinf)."""
    e = np.exp(-np.asarray(t, dtype=float) / tc)
    lam = (z0 + zinf) / (z0 - zinf)
    return zinf * (lam + e) / (lam - e)


def test_evans_fung_thickness_is_the_closed_form():
    assert trbc.evans_fung_radius_um() == R0
    r = np.array([0.0, 0.5, 1.0, 2.0, 2.8, 3.5, 3.9])
    h = trbc.evans_fung_thickness(r)
    assert isinstance(h, np.ndarray) and h.shape == r.shape and h.dtype == np.float64
    np.testing.assert_allclose(h, evans_fung(r), rtol=1e-14, atol=0)
    # the centre is R0 c0 thick; the shape is even in r and closes at r = R0
    assert h[0] == pytest.approx(R0 * C[0], rel=1e-15)
    np.testing.assert_array_equal(trbc.evans_fung_thickness(-r), h)
    np.testing.assert_array_equal(trbc.evans_fung_thickness([R0, 4.5]), [0.0, 0.0])
    # the shape of the input is kept (here 2-D, and a list of ints is converted)
    g = trbc.evans_fung_thickness(r.reshape(7, 1))
    assert g.shape == (7, 1)
    np.testing.assert_array_equal(g[:, 0], h)
    assert trbc.evans_fung_thickness([1, 2]).tolist() == trbc.evans_fung_thickness([1.0, 2.0]).tolist()


@pytest.mark.parametrize("tc, zinf, z0, t0", [(0.11, 1.11, 2.0, 0.0), (0.16, 1.07, 2.0, 0.0007), (0.18, 1.004, 1.67, 0.01)])
def test_fit_hochmuth_recovers_a_synthetic_curve(tc, zinf, z0, t0):
    # 25 samples over 0.4 s, as the Hochmuth et al. 1979 cells; the law is exact, so the fit is too
    t = t0 + np.linspace(0.0, 0.4, 25)
    z = hochmuth(t - t0, tc, zinf, z0)
    f = trbc.fit_hochmuth(t, z)
    assert f["converged"], f["message"]
    assert f["tc_s"] == pytest.approx(tc, rel=1e-8)
    assert f["zinf"] == pytest.approx(zinf, rel=1e-8)
    assert f["z0"] == z[0] and f["t0_s"] == t[0]
    assert f["rms"] < 1e-9
    assert set(f) == {"tc_s", "zinf", "z0", "t0_s", "rms", "converged", "iterations", "message"}
    # another start reaches the same minimum
    g = trbc.fit_hochmuth(t, z, tc_guess_s=0.5, zinf_guess=1.3)
    assert g["converged"] and g["tc_s"] == pytest.approx(tc, rel=1e-8) and g["zinf"] == pytest.approx(zinf, rel=1e-8)


def test_fit_hochmuth_with_noise_stays_close():
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 0.4, 25)
    z = hochmuth(t, 0.12, 1.15, 2.0) + rng.normal(0.0, 0.005, t.size)
    z[0] = 2.0  # z0 is fixed to the first sample
    f = trbc.fit_hochmuth(t, z)
    assert f["converged"], f["message"]
    assert f["tc_s"] == pytest.approx(0.12, rel=0.1)
    assert f["zinf"] == pytest.approx(1.15, abs=0.02)
    assert f["rms"] == pytest.approx(np.sqrt(np.mean((hochmuth(t, f["tc_s"], f["zinf"], 2.0) - z) ** 2)), rel=1e-6)


@pytest.mark.parametrize("t, z, what", [
    ([0.0, 0.1], [2.0, 1.5], "need at least 3"),
    ([0.0, 0.1, 0.2], [2.0, 1.5], "3 times but 2 deformation indices"),
    ([0.0, 0.2, 0.1], [2.0, 1.5, 1.3], "not strictly increasing"),
    ([0.0, 0.1, np.nan], [2.0, 1.5, 1.3], "not finite"),
    ([[0.0, 0.1, 0.2]], [2.0, 1.5, 1.3], "t_s: expected a 1-D array"),
])
def test_fit_hochmuth_bad_input_raises_value_error(t, z, what):
    with pytest.raises(ValueError, match=what):
        trbc.fit_hochmuth(t, z)


def test_fit_hochmuth_bad_start_raises_value_error():
    t, z = [0.0, 0.1, 0.2], [2.0, 1.5, 1.3]
    with pytest.raises(ValueError, match="initial tc"):
        trbc.fit_hochmuth(t, z, tc_guess_s=-1.0)
    with pytest.raises(ValueError, match="zinf_guess needs tc_guess_s"):
        trbc.fit_hochmuth(t, z, zinf_guess=1.1)
