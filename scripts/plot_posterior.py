#!/usr/bin/python3
"""Corner plots of the posteriors written by `trbc infer` (docs/BAYESIAN_INFERENCE.md).

Reads the samples.csv files of an inference directory DIR (columns: the parameters in physical
units, then log_likelihood and log_prior; one row per equally weighted sample) and writes

  <out>/corner_theta_new.png              theta_new = a new cell given all data (phase 3a), the
                                          paper's posterior figure: v, mu, kb, b2, eta_m
  <out>/corner_<data set>.png             each data set's posterior given all data (phase 3b)
  <out>/corner_<data set>_phase1.png      with --phase1: the individual (phase-1) posteriors
  <out>/corner_hyper.png                  with --hyper: the hyper-parameters (phase 2)

Diagonal: histogram of each parameter with its mean (solid) and 5 %/95 % quantiles (dashed);
below: 2-D histograms of every pair. Units as in the paper: mu in uN/m, kb in 1e-19 J,
eta_m in Pa s um; the error-model parameters (sigma, tc, z0, ...) as written.

Usage:
  scripts/plot_posterior.py DIR [--out OUTDIR] [--phase1] [--hyper] [--bins 40] [--max-samples 50000]

Only numpy and matplotlib are needed.
"""

import argparse
import csv
import sys
from pathlib import Path

import numpy as np
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

DPI = 150
# column -> (label, factor to the plotted unit)
LABELS = {
    "v": (r"$v$", 1.0),
    "mu_uN_per_m": (r"$\mu$ [$\mu$N/m]", 1.0),
    "kb_J": (r"$\kappa_b$ [$10^{-19}$ J]", 1e19),
    "b2": (r"$b_2$", 1.0),
    "etam_Pa_s_um": (r"$\eta_m$ [Pa s $\mu$m]", 1.0),
    "etam_over_mu_s": (r"$\eta_m/\mu$ [s]", 1.0),
    "FvK": ("FvK", 1.0),
    "sigma_rel": (r"$\sigma$ (rel.)", 1.0),
    "sigma0_um": (r"$\sigma_0$ [$\mu$m]", 1.0),
    "sigma1_um": (r"$\sigma_1$ [$\mu$m]", 1.0),
    "sigma_tc_rel": (r"$\sigma_{t_c}$ (rel.)", 1.0),
    "tc_s": (r"$t_c$ [s]", 1.0),
    "z0": (r"$z_0$", 1.0),
    "zinf": (r"$z_\infty$", 1.0),
    "sigma_z": (r"$\sigma_z$", 1.0),
    "mean_kb_J": (r"$\mu_{\kappa}$ [$10^{-19}$ J]", 1e19),
    "sd_kb_J": (r"$\sigma_{\kappa}$ [$10^{-19}$ J]", 1e19),
}
THETA_NEW = ["v", "mu_uN_per_m", "kb_J", "b2", "etam_Pa_s_um"]
SKIP = {"log_likelihood", "log_prior"}


def read_samples(path):
    with open(path, newline="") as f:
        reader = csv.reader((ln for ln in f if not ln.startswith("#")))
        header = next(reader)
        rows = [[float(x) for x in row] for row in reader if row]
    if not rows:
        raise ValueError(f"{path}: no samples")
    return header, np.array(rows)


def corner(path, out, title, columns=None, bins=40, max_samples=50000):
    header, x = read_samples(path)
    names = [c for c in (columns or header) if c in header and c not in SKIP]
    if len(x) > max_samples:
        x = x[np.linspace(0, len(x) - 1, max_samples).astype(int)]
    data = [x[:, header.index(c)] * LABELS.get(c, (c, 1.0))[1] for c in names]
    n = len(names)
    fig, axes = plt.subplots(n, n, figsize=(2.1 * n + 0.6, 2.1 * n + 0.6), squeeze=False)
    for i in range(n):
        for j in range(n):
            ax = axes[i][j]
            if j > i:
                ax.axis("off")
                continue
            if i == j:
                ax.hist(data[i], bins=bins, color="#2471a3", alpha=0.8, density=True)
                ax.axvline(np.mean(data[i]), color="k", lw=1)
                for q in np.quantile(data[i], [0.05, 0.95]):
                    ax.axvline(q, color="k", lw=0.8, ls="--")
                ax.set_yticks([])
            else:
                ax.hist2d(data[j], data[i], bins=bins, cmap="Blues")
            if i == n - 1:
                ax.set_xlabel(LABELS.get(names[j], (names[j], 1.0))[0])
            else:
                ax.set_xticklabels([])
            if j == 0 and i > 0:
                ax.set_ylabel(LABELS.get(names[i], (names[i], 1.0))[0])
            elif j > 0:
                ax.set_yticklabels([])
            ax.tick_params(labelsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(out, dpi=DPI)
    plt.close(fig)
    print(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dir", type=Path, help="output directory of trbc infer")
    ap.add_argument("--out", type=Path, help="figure directory (default: DIR/figures)")
    ap.add_argument("--phase1", action="store_true", help="also the phase-1 (individual) posteriors")
    ap.add_argument("--hyper", action="store_true", help="also the phase-2 hyper-parameter posterior")
    ap.add_argument("--bins", type=int, default=40)
    ap.add_argument("--max-samples", type=int, default=50000)
    a = ap.parse_args()
    out = a.out or a.dir / "figures"
    out.mkdir(parents=True, exist_ok=True)
    done = 0
    theta_new = a.dir / "phase3" / "theta_new" / "samples.csv"
    if theta_new.exists():
        corner(theta_new, out / "corner_theta_new.png", r"$\theta^{\rm new}$: a new cell given all data", THETA_NEW, a.bins, a.max_samples)
        done += 1
    for phase, suffix, what in (("phase3", "", "given all data"), ("phase1", "_phase1", "alone (phase 1)")):
        if phase == "phase1" and not a.phase1:
            continue
        base = a.dir / phase
        if not base.is_dir():
            continue
        for d in sorted(p for p in base.iterdir() if p.is_dir() and p.name != "theta_new"):
            f = d / "samples.csv"
            if f.exists():
                corner(f, out / f"corner_{d.name}{suffix}.png", f"{d.name}: {what}", None, a.bins, a.max_samples)
                done += 1
    if a.hyper and (a.dir / "phase2" / "hyper" / "samples.csv").exists():
        corner(a.dir / "phase2" / "hyper" / "samples.csv", out / "corner_hyper.png", "hyper-parameters (phase 2)", None, a.bins,
               a.max_samples)
        done += 1
    if not done:
        sys.exit(f"plot_posterior: no samples.csv found under {a.dir}")


if __name__ == "__main__":
    main()
