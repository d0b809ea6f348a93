"""trbc.infer / load_inference / predict against `trbc infer` and `trbc predict`; the phase-1 and
hierarchical log-posteriors against the values trbc's sampler stored; an emcee cross-check."""
import numpy as np
import pytest

import trbc

SEED = 5
N = 1000


@pytest.fixture(scope="module")
def inference(tmp_path_factory):
    out = tmp_path_factory.mktemp("infer-py")
    return trbc.infer(out, phase="all", samples=N, seed=SEED, threads=1)


@pytest.fixture(scope="module")
def cli_phase1(tmp_path_factory, run_cli):
    out = tmp_path_factory.mktemp("infer-cli")
    run_cli("infer", "--phase", 1, "--samples", N, "--seed", SEED, "--threads", 1, "--quiet", "--out", out, json_out=False)
    return trbc.load_inference(out)


def test_infer_gives_the_cli_samples(inference, cli_phase1):
    names = [d.name for d in trbc.load_data_sets()]
    assert sorted(inference["phase1"]) == sorted(cli_phase1["phase1"]) == sorted(names)
    for name in names:
        a, b = inference["phase1"][name], cli_phase1["phase1"][name]
        assert a.names == b.names
        np.testing.assert_array_equal(a.samples, b.samples)
        np.testing.assert_array_equal(a.log_likelihood, b.log_likelihood)
    assert set(inference["phase3"]) == {"theta_new", *names}
    t = inference["phase3"]["theta_new"]
    assert t.names[:5] == ["v", "mu_uN_per_m", "kb_J", "b2", "etam_over_mu_s"] or "v" in t.names
    assert len(t) == N and 0.65 <= t["v"].min() and t["v"].max() <= 1.0


def test_phase1_log_posterior_reproduces_the_sampler_values(inference):
    for name in ("evans_fung_1972", "mills_2004", "hochmuth_1979_cell1"):
        post = inference["phase1"][name]
        f = trbc.phase1_log_posterior(name)
        assert f.names == post.names
        np.testing.assert_allclose(f.log_likelihood(post.samples), post.log_likelihood, rtol=1e-12, atol=1e-9)
        lp = f(post.samples)
        assert np.all(np.isfinite(lp))
        assert f(post.samples[0]) == pytest.approx(lp[0], rel=1e-14)
        outside = post.samples[0].copy()
        outside[0] = 2.0  # v outside its prior box
        assert f(outside) == -np.inf


def test_hierarchical_log_posterior_reproduces_the_sampler_values(inference):
    f = trbc.hierarchical_log_posterior({k: v.samples for k, v in inference["phase1"].items()})
    hyper = inference["phase2"]["hyper"]
    assert f.names == hyper.names
    np.testing.assert_allclose(f.log_likelihood(hyper.samples), hyper.log_likelihood, rtol=1e-9, atol=1e-9)
    assert np.all(np.isfinite(f(hyper.samples)))


def test_predict_gives_the_cli_bands(inference, run_cli, tmp_path):
    post = inference["phase1"]["mills_2004"]
    p = trbc.predict(post, grid=20)
    assert p["x_name"] == "Fext_pN" and set(p["bands"]) == {"D0_um", "D1_um"}
    run_cli("predict", "--posterior", post.file.parent, "--grid", 20, "--quiet", "--out", tmp_path, json_out=False)
    files = list(tmp_path.glob("predict_*_stretching.csv"))
    assert len(files) == 1
    table = np.genfromtxt(files[0], delimiter=",", names=True, dtype=None, encoding=None)
    d1 = table[table[table.dtype.names[0]] == "D1_um"] if table.dtype.names[0] == "observable" else None
    band = p["bands"]["D1_um"]
    if d1 is not None:
        np.testing.assert_allclose(band["q50"], d1["q50"], rtol=1e-8)
    else:  # one row per force with a column per observable and level
        np.testing.assert_allclose(band["q50"], table["D1_um_q50"], rtol=1e-8)
    assert all(c["inside"] in (True, False) for c in p["coverage"]) and len(p["coverage"]) > 0


def test_bad_input_raises_value_error_naming_it(tmp_path):
    with pytest.raises(ValueError, match="data_set"):
        trbc.phase1_log_posterior("nobody_2024")
    f = trbc.phase1_log_posterior("evans_fung_1972")
    with pytest.raises(ValueError, match="theta"):
        f(np.zeros(5))
    with pytest.raises(ValueError, match="samples"):
        trbc.infer(tmp_path, phase=1, samples=1, data_sets=["evans_fung_1972"])
    with pytest.raises(ValueError, match="data_sets"):
        trbc.infer(tmp_path, phase="all", samples=100, data_sets=["evans_fung_1972"])


def test_emcee_agrees_with_trbc_sampler(tmp_path):
    """One phase-1 posterior (mills_2004: v, mu, kb, b2, sigma0, sigma1) sampled by emcee and by
    trbc's TMCMC/BASIS; means agree within 4 Monte Carlo standard errors, standard deviations within 15 %."""
    emcee = pytest.importorskip("emcee")
    name = "mills_2004"
    f = trbc.phase1_log_posterior(name)
    ours = trbc.infer(tmp_path, phase=1, samples=8000, seed=11, data_sets=[name])["phase1"][name]

    nwalkers, nsteps, burn = 32, 2500, 1000
    rng = np.random.default_rng(12)
    start = ours.samples[rng.choice(len(ours), nwalkers, replace=False)]
    sampler = emcee.EnsembleSampler(nwalkers, f.dimension, f, vectorize=True)
    np.random.seed(13)  # emcee's moves draw from numpy's global generator
    sampler.run_mcmc(start, nsteps, progress=False)
    chain = sampler.get_chain(discard=burn, flat=True)
    tau = np.max(sampler.get_autocorr_time(discard=burn, quiet=True))
    ess_emcee = chain.shape[0] / tau
    # BASIS repeats a sample when its move is rejected: count distinct samples, halved for correlation.
    ess_ours = len(np.unique(ours.samples, axis=0)) / 2.0

    for k, pname in enumerate(f.names):
        a, b = chain[:, k], ours.samples[:, k]
        sd = 0.5 * (a.std() + b.std())
        se = sd * np.sqrt(1.0 / ess_emcee + 1.0 / ess_ours)
        assert abs(a.mean() - b.mean()) < 4.0 * se, (pname, a.mean(), b.mean(), se)
        assert a.std() == pytest.approx(b.std(), rel=0.15), pname
