#!/usr/bin/python3
"""Plot Sobol' sensitivity indices of the surrogate (docs/CAMPAIGN_AND_SURROGATE.md, Sobol' indices).

Reads DIR/sobol_indices.csv with columns output,input,S1,S1_ci,ST,ST_ci (one row per output and
input, as written by trbc::writeSobolCsv; *_ci are 95 % bootstrap half-widths) and writes:

  <prefix>scalar.png  grouped bars of S1 and ST with CI error bars, one panel per scalar output
                      D_um, hmin_um, hmax_um, tc_s (those present)
  <prefix>force.png   S1 and ST of D0 (transverse, D_tr) and D1 (axial, D_ax) against the bead
                      force, one curve per input with a CI band; these outputs are named
                      D0_um@F and D1_um@F with F the force in pN (e.g. D0_um@100.0)

Usage:
  scripts/plot_sobol.py DIR [--out OUTDIR] [--prefix sobol_]

--out defaults to DIR. Only numpy and matplotlib are needed. NaN indices (an output with zero
variance) leave gaps.
"""

import argparse
import csv
import math
import sys
from collections import OrderedDict
from pathlib import Path

import numpy as np
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import plot_style  # noqa: E402

DPI = 150
SCALAR_OUTPUTS = [("D_um", r"$D$"), ("hmin_um", r"$h_{\min}$"), ("hmax_um", r"$h_{\max}$"), ("tc_s", r"$t_c$")]
FORCE_OUTPUTS = [("D0_um", r"$D_0$ (transverse, $D_{tr}$)"), ("D1_um", r"$D_1$ (axial, $D_{ax}$)")]
INPUT_LABELS = {
    "v": r"$v$", "mu": r"$\mu$", "FvK": "FvK", "fvk": "FvK", "b2": r"$b_2$",
    "etam": r"$\eta_m$", "eta_m": r"$\eta_m$", "kappa_b": r"$\kappa_b$",
}
C_S1 = "#2471a3"
C_ST = "#c0392b"
INPUT_COLORS = ["#1f3b73", "#c0392b", "#27ae60", "#d35400", "#8e44ad", "#7f8c8d", "#17a589", "#b7950b"]

plot_style.apply()

COLUMNS = ["output", "input", "S1", "S1_ci", "ST", "ST_ci"]


def read_indices(path):
    """Return (inputs in file order, {output: {input: {col: float}}} in file order)."""
    with open(path, newline="") as f:
        reader = csv.DictReader((ln for ln in f if not ln.startswith("#")))
        missing = [c for c in COLUMNS if c not in (reader.fieldnames or [])]
        if missing:
            sys.exit(f"plot_sobol: {path}: missing column(s) {', '.join(missing)}; "
                     f"expected header {','.join(COLUMNS)}")
        inputs = []
        data = OrderedDict()
        for line, row in enumerate(reader, start=2):
            try:
                values = {c: float(row[c]) for c in COLUMNS[2:]}
            except (TypeError, ValueError):
                sys.exit(f"plot_sobol: {path}:{line}: non-numeric index value in {row}")
            if row["input"] not in inputs:
                inputs.append(row["input"])
            data.setdefault(row["output"], {})[row["input"]] = values
    if not data:
        sys.exit(f"plot_sobol: {path}: no rows")
    return inputs, data


def label(name):
    return INPUT_LABELS.get(name, name)


def value(data, output, inp, col):
    return data.get(output, {}).get(inp, {}).get(col, math.nan)


def plot_scalar(inputs, data, path):
    present = [(name, lab) for name, lab in SCALAR_OUTPUTS if name in data]
    if not present:
        return False
    fig, axes = plt.subplots(1, len(present), figsize=(2.6 * len(present) + 0.6, 3.0), sharey=True, squeeze=False)
    x = np.arange(len(inputs))
    w = 0.38
    for ax, (name, lab) in zip(axes[0], present):
        for k, (col, color, text) in enumerate([("S1", C_S1, r"$S_i$ (first order)"), ("ST", C_ST, r"$S_{T,i}$ (total)")]):
            y = [value(data, name, i, col) for i in inputs]
            err = [value(data, name, i, col + "_ci") for i in inputs]
            ax.bar(x + (k - 0.5) * w, y, w, yerr=err, color=color, alpha=0.85, label=text,
                   error_kw={"elinewidth": 0.8, "capsize": 2, "ecolor": "#333333"})
        ax.axhline(0, color="#999999", lw=0.6)
        ax.set_xticks(x)
        ax.set_xticklabels([label(i) for i in inputs])
        ax.set_title(lab)
        ax.set_ylim(min(-0.05, ax.get_ylim()[0]), max(1.05, ax.get_ylim()[1]))
    axes[0][0].set_ylabel("Sobol' index")
    axes[0][0].legend(loc="upper left", frameon=False)
    fig.suptitle("Sobol' indices with 95 % bootstrap intervals", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return True


def force_series(data, stem):
    """Sorted forces and output names 'stem@F' present in data."""
    series = []
    for out in data:
        base, sep, force = out.partition("@")
        if sep and base == stem:
            try:
                series.append((float(force), out))
            except ValueError:
                sys.exit(f"plot_sobol: output '{out}': force after '@' is not a number")
    series.sort()
    return series


def plot_force(inputs, data, path):
    present = [(stem, lab, force_series(data, stem)) for stem, lab in FORCE_OUTPUTS]
    present = [p for p in present if p[2]]
    if not present:
        return False
    fig, axes = plt.subplots(len(present), 2, figsize=(8.0, 2.9 * len(present)), sharex=True, sharey=True, squeeze=False)
    for r, (stem, lab, series) in enumerate(present):
        forces = np.array([f for f, _ in series])
        for c, (col, name) in enumerate([("S1", r"first-order $S_i$"), ("ST", r"total $S_{T,i}$")]):
            ax = axes[r][c]
            for k, inp in enumerate(inputs):
                color = INPUT_COLORS[k % len(INPUT_COLORS)]
                y = np.array([value(data, out, inp, col) for _, out in series])
                ci = np.array([value(data, out, inp, col + "_ci") for _, out in series])
                ax.plot(forces, y, color=color, lw=1.4, label=label(inp))
                ax.fill_between(forces, y - ci, y + ci, color=color, alpha=0.18, lw=0)
            ax.axhline(0, color="#999999", lw=0.6)
            ax.set_title(f"{lab}: {name}")
            ax.set_ylabel(col.replace("S1", r"$S_i$").replace("ST", r"$S_{T,i}$"))
            if r == len(present) - 1:
                ax.set_xlabel(r"$F_{\rm ext}$ [pN]")
    axes[0][0].legend(loc="best", frameon=False, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return True


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dir", type=Path, help="directory holding sobol_indices.csv")
    ap.add_argument("--out", type=Path, default=None, help="output directory (default: DIR)")
    ap.add_argument("--prefix", default="sobol_", help="file-name prefix of the PNGs (default sobol_)")
    args = ap.parse_args(argv)

    csv_path = args.dir / "sobol_indices.csv"
    if not csv_path.is_file():
        sys.exit(f"plot_sobol: {csv_path} not found")
    inputs, data = read_indices(csv_path)
    out = args.out if args.out is not None else args.dir
    out.mkdir(parents=True, exist_ok=True)

    written = []
    for kind, fn in [("scalar", plot_scalar), ("force", plot_force)]:
        path = out / f"{args.prefix}{kind}.png"
        if fn(inputs, data, path):
            written.append(path)
        else:
            print(f"plot_sobol: no {kind} outputs in {csv_path}; {path.name} not written", file=sys.stderr)
    if not written:
        sys.exit(f"plot_sobol: {csv_path} has none of the known outputs "
                 f"({', '.join(n for n, _ in SCALAR_OUTPUTS)}, D0_um@F, D1_um@F)")
    for p in written:
        print(p)


if __name__ == "__main__":
    main()
