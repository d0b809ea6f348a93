#!/usr/bin/env python3
"""The membrane viscosity each shear-flow data set asks for, through the flow networks.

A one-parameter scan: v, mu, kb and b2 are held at the calibrated cell of a theta_new posterior
(trbc.calibrated_cell, the cell of every `--posterior`), and eta_m
runs over the networks' box on a log grid. Per set (docs/FLOW_NETWORKS.md, "One membrane
viscosity?"):
- inclination angle at one viscosity, or the TTF: the data are averaged over the donors at each
  shear rate, and network - data (degrees; relative for the TTF) is averaged over the rates at
  which the network's cell tank-treads. eta_m fits where that mean bias is within the networks'
  cross-validated RMSE (training.json) and the cell tank-treads at half of the rates or more
  (where it tumbles, the threshold sets speak). The best fitting eta_m has the least RMS misfit.
  The slope with the rate and the donors' spread are not fitted;
- critical stress at each viscosity: the best eta_m puts the classifier's critical stress nearest
  the data's mean in log; eta_m fits where it lies within the data's [min, max].
Every eta_m is also given as eta_m / mu (s), the ratio the bench's relaxation time constrains.

Writes OUT/etam_scan.csv and OUT/etam_scan.md. Reads the networks' files, the posterior's
samples and the shipped validation data through the trbc package; computes no physics itself.
"""
import argparse
import csv
import json
import sys
import warnings
from pathlib import Path

import numpy as np

import trbc

HELD = ("v", "mu_uN_per_m", "kb_J", "b2")
GRID = (0.01, 10.0)  # Pa s um, cut to the networks' box


def fail(message):
    sys.exit(f"flow_etam_scan: {message}")


def grid_predictions(f, cell, n, sets):
    """eta_m on a log grid over GRID, kept where every rate of every set is inside the box, and the
    networks' predictions on it per set (rows eta_m, columns the set's rates, with a value or not)."""
    g = np.exp(np.linspace(np.log(GRID[0]), np.log(GRID[1]), n))
    inside, predictions = np.ones(len(g), dtype=bool), []
    for s in sets:
        E, R = np.meshgrid(g, s["x"], indexing="ij")
        p = f.predict(eta_out_mPa_s=s["eta_out_mPa_s"], shear_rate_per_s=R, etam_Pa_s_um=E, **cell)
        inside &= ~p["outside_box"].any(axis=1)
        predictions.append(p)
    if not inside.any():
        fail("no eta_m of the grid puts every case inside the networks' box: the held cell ("
             + ", ".join(f"{k} {cell[k]:.4g}" for k in HELD) + ") lies outside it")
    return g[inside], [{k: v[inside] for k, v in p.items()} for p in predictions]


def bias_scan(p, s, relative, tolerance):
    """Per eta_m of one angle or TTF set, from the predictions p at its rates: whether it fits, the
    RMS misfit and the mean bias over the tank-treading rates, and the share of the rates that
    tank-tread."""
    keep = np.isfinite(s["y"]).any(axis=1)
    rates, data = s["x"][keep], np.nanmean(s["y"][keep], axis=1)
    p = {k: v[:, keep] for k, v in p.items()}
    key = "ttf_4pi_f_over_rate" if relative else "inclination_deg"
    resid = p[key] / data - 1 if relative else p[key] - data
    tt = p["p_tank_treading"] > 0.5
    share = tt.mean(axis=1)
    masked = np.where(tt, resid, np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an eta_m at which no rate tank-treads: NaN
        bias = np.nanmean(masked, axis=1)
        rms = np.sqrt(np.nanmean(masked ** 2, axis=1))
    fits = (share >= 0.5) & (np.abs(bias) <= tolerance)
    return fits, rms, bias, share, len(rates)


def scan_rows(f, cell, etam, predictions, k_mean, accuracy, data):
    """One row per set of data; predictions: those of grid_predictions, in the order of the angle
    and TTF sets in data."""
    rows, by_set = [], iter(predictions)

    def interval(fits):
        return (etam[fits].min(), etam[fits].max()) if fits.any() else (np.nan, np.nan)

    for s in data:
        obs = s["observable"]
        if obs in ("inclination_deg", "ttf_4pi_f_over_rate"):
            relative = obs == "ttf_4pi_f_over_rate"
            tol = accuracy["ttf_relative_rmse"] if relative else accuracy["inclination_rmse_deg"]
            fits, rms, bias, share, n = bias_scan(next(by_set), s, relative, tol)
            best = int(np.nanargmin(np.where(fits, rms, np.nan))) if fits.any() else None
            unit = "" if relative else " deg"
            lo, hi = interval(fits)
            at_mean = (f"bias {bias[k_mean]:+.3g}{unit}, RMS {rms[k_mean]:.3g}{unit}, tank-treading at {share[k_mean]:.0%} of the rates"
                       if k_mean is not None else "outside the grid")
            rows.append({"set": f"{obs} at {s['eta_out_mPa_s']:g} mPa s ({s['source']})", "points": n,
                         "etam_best_Pa_s_um": etam[best] if best is not None else np.nan, "etam_lo_Pa_s_um": lo, "etam_hi_Pa_s_um": hi,
                         "misfit_at_best": (f"bias {bias[best]:+.3g}{unit}, RMS {rms[best]:.3g}{unit}, tank-treading at {share[best]:.0%} "
                                            "of the rates") if best is not None else "",
                         "at_posterior_mean_etam": at_mean})
        elif obs == "critical_stress_Pa":
            for eta in np.unique(s["x"]):
                tau = s["y"][s["x"] == eta, 0]
                tau = tau[np.isfinite(tau)]
                if tau.size == 0:
                    continue
                cs = f.critical_stress_Pa(eta_out_mPa_s=float(eta), etam_Pa_s_um=etam, **cell)
                ok = np.isfinite(cs)
                name = f"critical stress at {eta:g} mPa s ({s['source']})"
                if not ok.any():
                    rows.append({"set": name, "points": tau.size, "etam_best_Pa_s_um": np.nan, "etam_lo_Pa_s_um": np.nan,
                                 "etam_hi_Pa_s_um": np.nan, "misfit_at_best": "the probability does not cross 1/2 in the stress range",
                                 "at_posterior_mean_etam": ""})
                    continue
                fits = ok & (cs >= tau.min()) & (cs <= tau.max())
                best = int(np.nanargmin(np.where(ok, np.abs(np.log(cs / tau.mean())), np.nan)))
                lo, hi = interval(fits)
                rows.append({"set": name, "points": tau.size, "etam_best_Pa_s_um": etam[best], "etam_lo_Pa_s_um": lo,
                             "etam_hi_Pa_s_um": hi,
                             "misfit_at_best": f"{cs[best]:.3g} Pa against {tau.min():.3g}-{tau.max():.3g} Pa",
                             "at_posterior_mean_etam": f"{cs[k_mean]:.3g} Pa" if k_mean is not None else "outside the grid"})
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--posterior", required=True, help="a theta_new posterior directory (samples.csv of `trbc infer`)")
    ap.add_argument("--surrogate", default=None, help="flow networks (default: the shipped ones)")
    ap.add_argument("--grid", type=int, default=400, help="eta_m grid points over [0.01, 10] Pa s um, [20, 100000]")
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    if not 20 <= a.grid <= 100000:
        fail(f"--grid {a.grid} is outside [20, 100000]")
    samples = Path(a.posterior) / "samples.csv"
    if not samples.is_file():
        fail(f"--posterior {a.posterior}: no samples.csv there")
    post = trbc.Posterior(samples)
    missing = [k for k in HELD + ("etam_Pa_s_um",) if k not in post.names]
    if missing:
        fail(f"--posterior {a.posterior}: samples.csv has no column {', '.join(missing)} (a theta_new posterior has all of "
             f"{', '.join(HELD + ('etam_Pa_s_um',))})")
    calibrated = trbc.calibrated_cell(a.posterior)
    cell = {k: calibrated[k] for k in HELD}
    model = Path(a.surrogate) if a.surrogate else trbc.data_dir("surrogates", "flow")
    f = trbc.FlowSurrogate(model)
    training = json.loads((model / "training.json").read_text())
    cv = training.get("cross_validation")
    accuracy, accuracy_name = ((cv["pooled"], f"{cv['folds']}-fold CV") if cv else (training["test"], "held-out test"))

    data = trbc.validation_data()
    etam, predictions = grid_predictions(f, cell, a.grid, [s for s in data if s["observable"] in ("inclination_deg", "ttf_4pi_f_over_rate")])
    mean_etam = calibrated["etam_Pa_s_um"]
    k_mean = int(np.argmin(np.abs(np.log(etam / mean_etam)))) if etam.min() <= mean_etam <= etam.max() else None
    rows = scan_rows(f, cell, etam, predictions, k_mean, accuracy, data)

    mu = cell["mu_uN_per_m"]
    for r in rows:
        for end in ("best", "lo", "hi"):
            r[f"etam_over_mu_{end}_s"] = r[f"etam_{end}_Pa_s_um"] / mu
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    command = " ".join([Path(sys.argv[0]).name] + sys.argv[1:])
    revision = training.get("revision", "?")
    with open(out / "etam_scan.csv", "w", newline="") as fh:
        fh.write(f"# trbc {trbc.__version__} ({trbc.__revision__}) | command: {command} | networks: {model} (revision {revision})\n")
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)

    def fmt(x):
        return "–" if not np.isfinite(x) else f"{x:.3g}"

    q = {k: np.quantile(post[k], [0.05, 0.95]) for k in ("etam_Pa_s_um",) + (("etam_over_mu_s",) if "etam_over_mu_s" in post.names else ())}
    ratio = (f"; its eta_m / mu 5-95 % {q['etam_over_mu_s'][0]:.3g}-{q['etam_over_mu_s'][1]:.3g} s" if "etam_over_mu_s" in q else "")
    lines = [
        "# The membrane viscosity each shear set asks for, through the flow networks", "",
        f"Command: `{command}`; networks {model} (revision {revision}; {accuracy_name}: angle {accuracy['inclination_rmse_deg']:.2f} deg, "
        f"TTF {100 * accuracy['ttf_relative_rmse']:.1f} %); trbc {trbc.__version__} ({trbc.__revision__}).", "",
        f"Held at the calibrated cell ({calibrated['estimator']}): " + ", ".join(f"{k} {cell[k]:.4g}" for k in HELD)
        + f". The posterior's eta_m: mean {mean_etam:.3g}, 5-95 % {q['etam_Pa_s_um'][0]:.3g}-{q['etam_Pa_s_um'][1]:.3g} Pa s um{ratio}. "
        f"eta_m grid: {len(etam)} points, {etam.min():.3g}-{etam.max():.3g} Pa s um (the networks' box at every case).", "",
        "| set | points | best eta_m (Pa s um) | eta_m that fits (Pa s um) | eta_m / mu that fits (s) | misfit at best | "
        "at the posterior's mean eta_m |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        fitting = np.isfinite(r["etam_lo_Pa_s_um"])
        span = f"{fmt(r['etam_lo_Pa_s_um'])}-{fmt(r['etam_hi_Pa_s_um'])}" if fitting else "none"
        span_ratio = f"{fmt(r['etam_over_mu_lo_s'])}-{fmt(r['etam_over_mu_hi_s'])}" if fitting else "none"
        lines.append(f"| {r['set']} | {r['points']} | {fmt(r['etam_best_Pa_s_um'])} | {span} | {span_ratio} | {r['misfit_at_best']} | "
                     f"{r['at_posterior_mean_etam']} |")
    (out / "etam_scan.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
