#!/usr/bin/env python3
"""The membrane viscosity each shear-flow data set asks for, through the flow networks.

The other cell parameters are held at the means of a theta_new posterior, and eta_m runs over the
networks' box on a log grid. Per set (docs/FLOW_NETWORKS.md, "One membrane viscosity?"):
- inclination angle at one viscosity, or the TTF: the mean over the tank-treading data points of
  network - data (degrees; relative for the TTF). eta_m counts as fitting where that bias is
  within the networks' cross-validated RMSE (training.json) and the cell tank-treads at at least
  half of the data's shear rates (the misfit is over those; the threshold is the sets below); best is the fitting eta_m of least RMS misfit;
- critical stress at each viscosity: best is the eta_m whose critical stress is nearest the data's
  mean in log; eta_m fits where it lies within the data's [min, max] at that viscosity.

Writes OUT/etam_profile.csv and OUT/etam_profile.md. Reads the networks' files, the posterior's
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


def grid_in_box(f, cell, n):
    """eta_m on a log grid over [0.01, 10] Pa s um, kept where a mid-range query is inside the box."""
    g = np.exp(np.linspace(np.log(0.01), np.log(10.0), n))
    inside = ~f.predict(eta_out_mPa_s=30.0, shear_rate_per_s=3.0, etam_Pa_s_um=g, **cell)["outside_box"]
    return g[inside]


def bias_profile(f, cell, etam, s, relative, tolerance):
    """Per eta_m of one angle or TTF set: whether it fits, the RMS misfit and the mean bias over the
    tank-treading rates, the share of the rates that tank-tread; and the number of rates."""
    x, y = s["x"], s["y"]
    keep = np.isfinite(y).any(axis=1)
    rates, data = x[keep], np.nanmean(y[keep], axis=1)
    E, R = np.meshgrid(etam, rates, indexing="ij")
    p = f.predict(eta_out_mPa_s=s["eta_out_mPa_s"], shear_rate_per_s=R, etam_Pa_s_um=E, **cell)
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


def profile_rows(f, cell, etam, cv):
    rows = []
    mean_etam = cell["etam_Pa_s_um"]
    cell = {k: v for k, v in cell.items() if k != "etam_Pa_s_um"}
    k_mean = int(np.argmin(np.abs(np.log(etam / mean_etam))))
    for s in trbc.validation_data():
        obs = s["observable"]
        if obs in ("inclination_deg", "ttf_4pi_f_over_rate"):
            relative = obs == "ttf_4pi_f_over_rate"
            tol = cv["ttf_relative_rmse"] if relative else cv["inclination_rmse_deg"]
            fits, rms, bias, share, n = bias_profile(f, cell, etam, s, relative, tol)
            best = int(np.nanargmin(np.where(fits, rms, np.nan))) if fits.any() else None
            unit = "" if relative else " deg"
            rows.append({
                "set": f"{obs} at {s['eta_out_mPa_s']:g} mPa s ({s['source']})", "points": n,
                "etam_best_Pa_s_um": etam[best] if best is not None else np.nan,
                "etam_lo_Pa_s_um": etam[fits].min() if fits.any() else np.nan,
                "etam_hi_Pa_s_um": etam[fits].max() if fits.any() else np.nan,
                "misfit_at_best": f"RMS {rms[best]:.3g}{unit}, tank-treading at {share[best]:.0%} of the rates" if best is not None else "",
                "misfit_at_posterior_mean": f"bias {bias[k_mean]:+.3g}{unit}, RMS {rms[k_mean]:.3g}{unit}, "
                                            f"tank-treading at {share[k_mean]:.0%} of the rates",
            })
        elif obs == "critical_stress_Pa":
            for eta in np.unique(s["x"]):
                tau = s["y"][s["x"] == eta, 0]
                cs = f.critical_stress_Pa(eta_out_mPa_s=float(eta), etam_Pa_s_um=etam, **cell)
                ok = np.isfinite(cs)
                fits = ok & (cs >= tau.min()) & (cs <= tau.max())
                best = int(np.nanargmin(np.where(ok, np.abs(np.log(cs / tau.mean())), np.nan)))
                rows.append({
                    "set": f"critical stress at {eta:g} mPa s ({s['source']})", "points": len(tau),
                    "etam_best_Pa_s_um": etam[best],
                    "etam_lo_Pa_s_um": etam[fits].min() if fits.any() else np.nan,
                    "etam_hi_Pa_s_um": etam[fits].max() if fits.any() else np.nan,
                    "misfit_at_best": f"{cs[best]:.3g} Pa against {tau.min():.3g}-{tau.max():.3g} Pa",
                    "misfit_at_posterior_mean": f"{cs[k_mean]:.3g} Pa",
                })
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--posterior", required=True, help="a theta_new posterior directory (samples.csv of `trbc infer`)")
    ap.add_argument("--surrogate", default=None, help="flow networks (default: the shipped ones)")
    ap.add_argument("--grid", type=int, default=400, help="eta_m grid points over [0.01, 10] Pa s um, [20, 100000]")
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    if not 20 <= a.grid <= 100000:
        sys.exit(f"flow_etam_profile: --grid {a.grid} is outside [20, 100000]")
    samples = Path(a.posterior) / "samples.csv"
    if not samples.is_file():
        sys.exit(f"flow_etam_profile: --posterior {a.posterior}: no samples.csv there")
    post = trbc.Posterior(samples)
    mean = post.mean()
    cell = {k: mean[k] for k in ("v", "mu_uN_per_m", "kb_J", "b2", "etam_Pa_s_um")}
    f = trbc.FlowSurrogate(a.surrogate)
    model = Path(a.surrogate) if a.surrogate else trbc.data_dir("surrogates", "flow")
    training = json.loads((model / "training.json").read_text())
    cv = training["cross_validation"]["pooled"]
    etam = grid_in_box(f, {k: v for k, v in cell.items() if k != "etam_Pa_s_um"}, a.grid)
    rows = profile_rows(f, cell, etam, cv)

    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    command = " ".join([Path(sys.argv[0]).name] + sys.argv[1:])
    q05, q50, q95 = np.quantile(post["etam_Pa_s_um"], [0.05, 0.5, 0.95])
    with open(out / "etam_profile.csv", "w", newline="") as fh:
        fh.write(f"# trbc {trbc.__version__} ({trbc.__revision__}) | command: {command} | networks: {model} (revision {training.get('revision', '?')})\n")
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    fmt = lambda x: "–" if not np.isfinite(x) else f"{x:.3g}"  # noqa: E731
    lines = [
        "# The membrane viscosity each shear set asks for, through the flow networks", "",
        f"Command: `{command}`; networks {model} (revision {training.get('revision', '?')}, 5-fold CV: angle "
        f"{cv['inclination_rmse_deg']:.2f} deg, TTF {100 * cv['ttf_relative_rmse']:.1f} %); trbc {trbc.__version__} ({trbc.__revision__}).", "",
        "The rest of the cell at the posterior's means: " + ", ".join(f"{k} {v:.4g}" for k, v in cell.items() if k != "etam_Pa_s_um")
        + f". The posterior's eta_m: mean {cell['etam_Pa_s_um']:.3g}, median {q50:.3g}, 5-95 % {q05:.3g}-{q95:.3g} Pa s um. "
        f"eta_m grid: {len(etam)} points, {etam.min():.3g}-{etam.max():.3g} Pa s um (the networks' box).", "",
        "| set | points | best eta_m (Pa s um) | eta_m that fits (Pa s um) | misfit at best | at the posterior's mean eta_m |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        span = f"{fmt(r['etam_lo_Pa_s_um'])}-{fmt(r['etam_hi_Pa_s_um'])}" if np.isfinite(r["etam_lo_Pa_s_um"]) else "none"
        lines.append(f"| {r['set']} | {r['points']} | {fmt(r['etam_best_Pa_s_um'])} | {span} | {r['misfit_at_best']} | "
                     f"{r['misfit_at_posterior_mean']} |")
    (out / "etam_profile.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
