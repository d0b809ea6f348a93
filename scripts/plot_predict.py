#!/usr/bin/python3
"""Figures of `trbc predict` (docs/BAYESIAN_INFERENCE.md, prediction): per posterior the predictive bands with the data.

Usage: scripts/plot_predict.py OUT [--data-dir EXPERIMENTS_DIR]

Reads OUT/predict_<posterior>_<experiment>.csv (+ _density.csv for equilibrium) and OUT/coverage.csv
and writes OUT/predict_<posterior>_<experiment>.png:
  stretching   D0 and D1 against Fext: 50/90/99 % bands, median, mean, the data points
  equilibrium  predictive densities of D, hmin, hmax with the data's mean +- SD (read by trbc's
               Python package, trbc.load_data_sets; without it the marks are left out)
  relaxation   z(t) bands with the Hochmuth cell's points
Data points outside their 90 % band are drawn as red crosses.
"""
import argparse
import csv
import glob
import os
import re
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

BANDS = [("q005", "q995", 0.15, "99 %"), ("q05", "q95", 0.3, "90 %"), ("q25", "q75", 0.5, "50 %")]


def _number(text):
    """A CSV number; "n/a" (a band without a data point) and an empty cell are NaN."""
    return float("nan") if text in ("", "n/a") else float(text)


def read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader((ln for ln in f if not ln.startswith("#"))))
    if not rows:
        return {}
    return {k: [_number(r[k]) if k not in ("observable", "posterior", "experiment") else r[k] for r in rows] for k in rows[0]}


def coverage(out_dir):
    path = os.path.join(out_dir, "coverage.csv")
    points = {}
    if os.path.exists(path):
        with open(path, newline="") as f:
            for r in csv.DictReader((ln for ln in f if not ln.startswith("#"))):
                points.setdefault(r["posterior"], []).append(r)
    return points


def equilibrium_mean_sd(data_dir):
    """{"D_um": (mean, SD), ...} of the data directory's equilibrium set, as trbc reads it (the
    shipped layout or a datasets.json); {} with a note when trbc or the set is not there, or the
    file gives no SD."""
    out = {}
    try:
        import trbc
        for d in trbc.load_data_sets(data_dir):
            if d.experiment == "equilibrium":
                for name, mean, sd in zip(("D_um", "hmin_um", "hmax_um"), d.shape, d.shape_sd_um):
                    if sd == sd:  # not NaN
                        out[name] = (float(mean), float(sd))
                break
    except (ImportError, AttributeError, ValueError) as exc:
        # no trbc (or one without the data sets), bad data, or a path the filesystem refuses: the
        # figures are drawn without the marks
        print(f"plot_predict: note: no equilibrium data marks ({exc})", file=sys.stderr)
        return {}
    return out


def draw_data(ax, pts, observable):
    for p in pts:
        if p["observable"] != observable:
            continue
        inside = p["inside_90"] == "1"
        ax.plot(float(p["x"]), float(p["y"]), "ko" if inside else "rx", ms=4 if inside else 7, zorder=5)


def draw_bands(ax, table, xname, obs, color):
    x = table[xname]
    for lo, hi, alpha, label in BANDS:
        ax.fill_between(x, table[f"{obs}_{lo}"], table[f"{obs}_{hi}"], color=color, alpha=alpha, lw=0, label=label)
    ax.plot(x, table[f"{obs}_q50"], color=color, lw=1.5, label="median")
    ax.plot(x, table[f"{obs}_mean"], "--", color="k", lw=1, label="mean (no noise)")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", help="output directory of trbc predict")
    default_data = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "data", "experiments")
    ap.add_argument("--data-dir", default=os.environ.get("TRBC_EXPERIMENT_DATA", default_data))
    a = ap.parse_args()
    cov = coverage(a.out)
    sds = equilibrium_mean_sd(a.data_dir)
    files = sorted(glob.glob(os.path.join(a.out, "predict_*_*.csv")))
    made = []
    for path in files:
        m = re.match(r"predict_(.+)_(stretching|relaxation|equilibrium)\.csv$", os.path.basename(path))
        if not m:
            continue
        label, exp = m.group(1), m.group(2)
        pts = cov.get(label, [])
        table = read_csv(path)
        if exp == "stretching":
            fig, ax = plt.subplots(figsize=(6, 4.5))
            for obs, color, name in (("D1_um", "tab:blue", "$D_1$ (axial)"), ("D0_um", "tab:orange", "$D_0$ (transverse)")):
                draw_bands(ax, table, "Fext_pN", obs, color)
                draw_data(ax, pts, obs)
                ax.text(table["Fext_pN"][-1], table[f"{obs}_q50"][-1], " " + name, va="center", fontsize=8)
            ax.set_xlabel("$F_{ext}$ (pN)")
            ax.set_ylabel("diameter (µm)")
            handles, labels = ax.get_legend_handles_labels()
            ax.legend(handles[:5], labels[:5], fontsize=8, loc="upper left")
        elif exp == "relaxation":
            fig, ax = plt.subplots(figsize=(6, 4.5))
            draw_bands(ax, table, "t_s", "z", "tab:green")
            draw_data(ax, pts, "z")
            ax.set_xlabel("$t$ (s)")
            ax.set_ylabel("$z = L/W$")
            ax.legend(fontsize=8)
        else:
            dens_path = path[:-4] + "_density.csv"
            dens = read_csv(dens_path) if os.path.exists(dens_path) else {}
            fig, axes = plt.subplots(1, 3, figsize=(11, 3.5))
            for ax, obs, name in zip(axes, ("D_um", "hmin_um", "hmax_um"), ("$D$", "$h_{min}$", "$h_{max}$")):
                if dens:
                    ax.plot(dens[obs], dens[obs + "_density"], color="tab:purple", label="predictive density")
                if obs in sds:
                    mu, sd = sds[obs]
                    ax.axvline(mu, color="k", label="Evans & Fung mean")
                    ax.axvspan(mu - sd, mu + sd, color="k", alpha=0.15, label="± SD")
                i = table["observable"].index(obs) if obs in table.get("observable", []) else None
                if i is not None:
                    ax.axvline(table["pred_q05"][i], color="tab:purple", ls=":", label="90 % band")
                    ax.axvline(table["pred_q95"][i], color="tab:purple", ls=":")
                ax.set_xlabel(name + " (µm)")
                ax.set_yticks([])
            axes[0].legend(fontsize=7)
        fig.suptitle(f"{label} ({exp})", fontsize=10)
        fig.tight_layout()
        png = path[:-4] + ".png"
        fig.savefig(png, dpi=130)
        plt.close(fig)
        made.append(png)
    if not made:
        print(f"plot_predict: no predict_*.csv in {a.out}", file=sys.stderr)
        return 1
    for p in made:
        print(p)
    return 0


if __name__ == "__main__":
    sys.exit(main())
