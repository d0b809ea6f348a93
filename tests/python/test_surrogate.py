"""trbc.Surrogate against `trbc surrogate eval`; dict input; gradients; bad input."""
import numpy as np
import pytest

import trbc

LO = np.array([0.65, 1.0, 10.0, 0.0, 0.1, 0.0])
HI = np.array([1.0, 10.0, 1000.0, 4.0, 1.0, 200.0])


def box_points(n, seed=1):
    rng = np.random.default_rng(seed)
    return LO + (HI - LO) * rng.uniform(0.02, 0.98, size=(n, 6))


def test_evaluate_gives_the_cli_numbers(tmp_path, run_cli):
    x = box_points(64)
    np.savetxt(tmp_path / "in.csv", x, delimiter=",", header=",".join(trbc.INPUT_NAMES), comments="", fmt="%.17g")
    run_cli("surrogate", "eval", "--in", tmp_path / "in.csv", "--out", tmp_path / "out.csv", json_out=False)
    table = np.genfromtxt(tmp_path / "out.csv", delimiter=",", names=True, skip_header=1)  # after the provenance line
    y = trbc.Surrogate().evaluate(x)
    assert list(y) == list(trbc.OUTPUT_NAMES)
    for name in trbc.OUTPUT_NAMES:
        # the CLI writes 10 significant digits
        np.testing.assert_allclose(y[name], table[name], rtol=1e-9)


def test_dict_input_kb_and_single_precision():
    s = trbc.Surrogate()
    x = box_points(10, seed=2)
    ref = s.evaluate_array(x)
    d = {name: x[:, k] for k, name in enumerate(trbc.INPUT_NAMES)}
    np.testing.assert_array_equal(s.evaluate(d)["D0_um"], ref[:, 3])
    kb = x[:, 1] * 10.742958658 / (x[:, 2] * 1e18)
    d2 = {k: v for k, v in d.items() if k != "FvK"} | {"kb_J": kb}
    np.testing.assert_allclose(s.evaluate(d2)["tc_s"], ref[:, 5], rtol=1e-12)
    single = trbc.Surrogate(precision="single").evaluate_array(x)
    np.testing.assert_allclose(single, ref, rtol=1e-4)
    assert trbc.Surrogate.outside_training_box(np.vstack([x[0], [1.2, 4, 250, 1.5, 0.7, 100]])).tolist() == [False, True]


def test_gradient_matches_finite_differences():
    s = trbc.Surrogate()
    x = box_points(20, seed=3)
    J = s.gradient(x)
    assert J.shape == (20, 6, 6)
    for j in range(6):
        h = 1e-6 * (HI[j] - LO[j])  # small enough for the steep hmin ramp near v = 1
        xp, xm = x.copy(), x.copy()
        xp[:, j] += h
        xm[:, j] -= h
        fd = (s.evaluate_array(xp) - s.evaluate_array(xm)) / (2 * h)
        scale = np.abs(fd).max(axis=0) + 1e-12
        assert np.all(np.abs(J[:, :, j] - fd) <= 1e-5 * scale), j
    w = np.random.default_rng(4).normal(size=(20, 6))
    np.testing.assert_allclose(s.gradient(x, weights=w), np.einsum("ki,kij->kj", w, J), rtol=1e-10, atol=1e-14)


def test_bad_input_raises_value_error_naming_it():
    s = trbc.Surrogate()
    with pytest.raises(ValueError, match="x"):
        s.evaluate(np.zeros((5, 4)))
    with pytest.raises(ValueError, match="Fext_pN"):
        s.evaluate({"v": [0.9], "mu_uN_per_m": [4], "FvK": [200], "b2": [1], "etam_Pa_s_um": [0.5]})
    with pytest.raises(ValueError, match="precision"):
        trbc.Surrogate(precision="half")
    with pytest.raises(ValueError, match="missing"):
        trbc.Surrogate(model_dir="/nonexistent")
    with pytest.raises(ValueError, match="weights"):
        s.gradient(box_points(3), weights=np.zeros((2, 6)))
