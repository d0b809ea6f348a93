#!/usr/bin/python3
"""Plot the output of ``trbc validate`` against the flow-validation experiments.

Reads the CSV files written by ``trbc validate`` into DIR (see
docs/VALIDATION.md, sections 3 and 4) and overlays the simulated observables
on the experimental data of data/experiments/validation:

  angle_vs_shear_rate.png      mean inclination angle (error bar = swinging
                               amplitude) vs shear rate, one panel per outer
                               viscosity; Fischer & Korzeniewski 2015 donors
  ttf_vs_shear_rate.png        4 pi f / shear rate vs shear rate;
                               Fischer (donors 1-2, 28.9 mPa s)
  critical_stress_vs_eta.png   TT/TB threshold stress interval per eta
                               (threshold.csv) plus every threshold-sweep case
                               coloured by regime; Fischer 2013, Abkarian 2007
  tube_velocity_vs_pg.png      cell velocity vs pressure gradient;
                               Tomaiuolo 2009 (6.6 µm tube)
  tube_length_vs_velocity.png  cell length vs velocity; Tomaiuolo 2009
                               (6.6 um) and Hochmuth 1970 (6.7 um, mm/s -> cm/s)

Inputs in DIR (each optional; a missing or empty file only skips its figures):
  shear.csv, threshold.csv, tube.csv, validation.json ("cell", "level").
Rows with status != "ok" and rows with empty observables are ignored.

Usage:
  scripts/plot_validation.py DIR [--data EXPDIR] [--out FIGDIR]

Defaults: --data <repo>/data/experiments/validation, --out DIR/figures.
The path of every figure written is printed on stdout; notes go to stderr.
Exit status: 0 on success (also when there is nothing to plot), 2 when DIR
does not exist, an argument is invalid or FIGDIR cannot be written.
Only numpy and matplotlib are needed.
"""

import argparse
import csv
import json
import math
import re
import sys
from pathlib import Path

import numpy as np
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
DEFAULT_DATA = REPO / "data" / "experiments" / "validation"

DPI = 150
C_SIM = "#1f3b73"          # simulation (dark blue)
C_EXP = "0.45"             # experimental points (grey)
C_EXP2 = "black"           # second experimental set
REGIME_STYLE = {           # regime -> (colour, marker, label)
    "tumbling": ("#c0392b", "x", "tumbling"),
    "tank-treading": ("#2471a3", "o", "tank-treading"),
    "intermittent": ("#d68910", "D", "intermittent"),
    "empty": ("#7f8c8d", ".", "unclassified"),
}
PANEL_COLOURS = ["#1f3b73", "#c0392b", "#27ae60", "#8e44ad", "#d35400", "#17a589"]

plt.rcParams.update({
    "font.size": 9,
    "axes.titlesize": 10,
    "axes.labelsize": 9,
    "legend.fontsize": 7.5,
    "xtick.labelsize": 8,
    "ytick.labelsize": 8,
    "axes.spines.top": False,
    "axes.spines.right": False,
})


def note(msg):
    print(f"plot_validation: {msg}", file=sys.stderr)


# --------------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------------

def read_rows(path):
    """List of dicts (keys and values stripped) of a CSV file with header; [] if absent/unreadable."""
    path = Path(path)
    if not path.is_file():
        return []
    try:
        with open(path, newline="") as fh:
            reader = csv.DictReader(fh)
            rows = []
            for r in reader:
                rows.append({(k or "").strip(): (v or "").strip() if isinstance(v, str) else ""
                             for k, v in r.items()})
            return rows
    except (OSError, csv.Error, UnicodeDecodeError) as e:
        note(f"cannot read {path}: {e}")
        return []


def fnum(s):
    """Float of a CSV field, or None if empty / not a finite number."""
    if s is None:
        return None
    s = str(s).strip()
    if not s:
        return None
    try:
        x = float(s)
    except ValueError:
        return None
    return x if math.isfinite(x) else None


def ok_rows(rows):
    """Rows whose status is 'ok' (rows without a status column are kept)."""
    return [r for r in rows if r.get("status", "ok").strip().lower() in ("ok", "")]


def read_exp_columns(path, columns):
    """Numeric columns of an experimental file as arrays (NaN for blanks); None if absent."""
    rows = read_rows(path)
    if not rows:
        note(f"experimental file missing or empty: {path}")
        return None
    out = {}
    for c in columns:
        out[c] = np.array([fnum(r.get(c)) if fnum(r.get(c)) is not None else np.nan for r in rows])
    return out


def read_json(path):
    path = Path(path)
    if not path.is_file():
        return None
    try:
        with open(path) as fh:
            return json.load(fh)
    except (OSError, ValueError) as e:
        note(f"cannot read {path}: {e}")
        return None


# --------------------------------------------------------------------------------------------
# subtitle from validation.json
# --------------------------------------------------------------------------------------------

_CELL_LABELS = [  # (candidate keys, label, unit, formatter)
    (("v", "reduced_volume"), "v", "", "{:.3f}"),
    (("mu_uN_per_m", "mu"), "mu", " uN/m", "{:.3g}"),
    (("kb_J", "kb", "kappa_b"), "kb", " J", "{:.3g}"),
    (("b2",), "b2", "", "{:.3g}"),
    (("etam_Pa_s_um", "eta_m", "etam"), "eta_m", " Pa s µm", "{:.3g}"),
    (("eta_in_mPa_s", "eta_i_mPa_s", "eta_i"), "eta_i", " mPa s", "{:.3g}"),
]


def subtitle(meta):
    if not isinstance(meta, dict):
        return None
    parts = []
    cell = meta.get("cell")
    if isinstance(cell, dict) and isinstance(cell.get("parameters"), dict):
        cell = cell["parameters"]  # a posterior cell: {"source": ..., "parameters": {...}}
    if isinstance(cell, dict):
        used = set()
        for keys, lab, unit, fmt in _CELL_LABELS:
            for k in keys:
                val = cell.get(k)
                if isinstance(val, (int, float)) and not isinstance(val, bool):
                    parts.append(f"{lab}={fmt.format(val)}{unit}")
                    used.update(keys)
                    break
        if not parts:  # unknown key names: show the first few numeric entries as they are
            for k, val in cell.items():
                if isinstance(val, (int, float)) and not isinstance(val, bool):
                    parts.append(f"{k}={val:.3g}")
                if len(parts) >= 6:
                    break
    text = ("cell: " + ", ".join(parts)) if parts else ""
    level = meta.get("level")
    if level is not None and level != "":
        text = f"{text}; level {level}" if text else f"level {level}"
    return text or None


def finish(fig, path, sub, written):
    if sub:
        fig.text(0.5, 0.005, sub, ha="center", va="bottom", fontsize=7, color="0.3")
        fig.tight_layout(rect=(0, 0.035, 1, 1))
    else:
        fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)  # created only when a figure exists
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    written.append(path)
    print(path)


def positive(xs):
    return [x for x in xs if x is not None and x > 0]


def use_log(values, ratio=20.0):
    """Log axis if the positive values span more than `ratio` (and no non-positive value)."""
    v = [x for x in values if x is not None and math.isfinite(x)]
    if not v or min(v) <= 0:
        return False
    return max(v) / min(v) > ratio


# --------------------------------------------------------------------------------------------
# shear flow figures
# --------------------------------------------------------------------------------------------

def eta_key(x):
    """Canonical text of a viscosity, to match '10.7' with 10.7, '104' with 104.0."""
    return f"{float(x):.6g}"


def find_angle_files(data):
    """{eta_key: path} of the Fisher2015 inclination-angle files."""
    d = Path(data) / "shear_flow" / "inclination_angle"
    out = {}
    if d.is_dir():
        for p in sorted(d.glob("Fisher2015_eta_*_mPa_s.csv")):
            m = re.match(r"Fisher2015_eta_([0-9.]+)_mPa_s\.csv$", p.name)
            if m:
                try:
                    out[eta_key(m.group(1))] = p
                except ValueError:
                    pass
    return out


def plot_angle(shear, data, figdir, sub, written):
    rows = [r for r in ok_rows(shear) if r.get("sweep", "").strip().lower() == "angle"]
    by_eta = {}
    for r in rows:
        eta = fnum(r.get("eta_out_mPa_s"))
        g = fnum(r.get("shear_rate_per_s"))
        if eta is None or g is None or g <= 0:
            continue
        by_eta.setdefault(eta_key(eta), (eta, []))[1].append(r)
    if not by_eta:
        note("no usable angle-sweep rows in shear.csv: skipping angle_vs_shear_rate.png")
        return
    files = find_angle_files(data)
    etas = sorted(by_eta.values(), key=lambda t: t[0])
    n = len(etas)
    ncol = min(n, 2)
    nrow = int(math.ceil(n / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.4 * ncol, 3.5 * nrow), squeeze=False)
    for ax in axes.flat[n:]:
        ax.set_visible(False)

    for k, ((eta, rs), ax) in enumerate(zip(etas, axes.flat)):
        col = PANEL_COLOURS[k % len(PANEL_COLOURS)]
        xs_all = []
        # experiment
        path = files.get(eta_key(eta))
        if path is not None:
            cols = [f"angle{i}" for i in range(1, 8)]
            tab = read_exp_columns(path, ["shear_rate"] + cols)
            if tab is not None:
                first = True
                for c in cols:
                    m = np.isfinite(tab["shear_rate"]) & np.isfinite(tab[c])
                    if m.any():
                        ax.plot(tab["shear_rate"][m], tab[c][m], ls="none", marker="o", ms=3.2,
                                mfc="none", mec=C_EXP, mew=0.8,
                                label=("Fischer & Korzeniewski 2015 (donors)" if first else None))
                        first = False
                        xs_all += list(tab["shear_rate"][m])
        else:
            note(f"no Fisher2015 angle file for eta = {eta:g} mPa s")
        # simulation: tank-treading (or unclassified) rows with an angle
        tt = []
        tb = []
        other = []
        for r in rs:
            g = fnum(r["shear_rate_per_s"])
            reg = r.get("regime", "").strip().lower()
            th = fnum(r.get("inclination_deg"))
            if reg == "tumbling":
                tb.append(g)
            elif th is None:
                continue
            elif reg in ("tank-treading", "", "empty"):
                tt.append((g, th, fnum(r.get("swing_amplitude_deg"))))
            else:  # intermittent with an angle: show separately
                other.append((g, th, fnum(r.get("swing_amplitude_deg"))))
        if tt:
            tt.sort()
            g = np.array([t[0] for t in tt])
            th = np.array([t[1] for t in tt])
            err = np.array([abs(t[2]) if t[2] is not None else 0.0 for t in tt])
            ax.errorbar(g, th, yerr=err, color=col, marker="s", ms=4, lw=1.3, capsize=2.5,
                        elinewidth=0.9, label="simulation (error bar: swing amplitude)", zorder=5)
            xs_all += list(g)
        if other:
            g = np.array([t[0] for t in other])
            th = np.array([t[1] for t in other])
            err = np.array([abs(t[2]) if t[2] is not None else 0.0 for t in other])
            st = REGIME_STYLE["intermittent"]
            ax.errorbar(g, th, yerr=err, color=st[0], marker=st[1], ms=4, ls="none", capsize=2.5,
                        elinewidth=0.9, label="simulation, intermittent", zorder=5)
            xs_all += list(g)
        if tb:
            ax.plot(tb, np.zeros(len(tb)), ls="none", marker="x", ms=7, mew=1.6,
                    color=REGIME_STYLE["tumbling"][0], label="simulation: tumbling (no angle)",
                    zorder=6, clip_on=False)
            xs_all += tb
        if xs_all and min(xs_all) > 0:  # shear rates span decades (VALIDATION.md 3.2)
            ax.set_xscale("log")
        ax.axhline(0, color="0.8", lw=0.6, zorder=0)
        ax.set_xlabel(r"shear rate $\dot\gamma$ [1/s]")
        ax.set_ylabel("inclination angle [deg]")
        ax.set_title(rf"$\eta_o$ = {eta:g} mPa s")
        lo, hi = ax.get_ylim()
        ax.set_ylim(min(lo, -2.0), max(hi, 5.0))
        ax.legend(loc="best", frameon=False)
    finish(fig, Path(figdir) / "angle_vs_shear_rate.png", sub, written)


def plot_ttf(shear, data, figdir, sub, written):
    rows = [r for r in ok_rows(shear) if r.get("sweep", "").strip().lower() == "ttf"]
    pts = []
    tumbling = []
    etas = set()
    for r in rows:
        g = fnum(r.get("shear_rate_per_s"))
        f = fnum(r.get("ttf_4pi_f_over_shear_rate"))
        if g is None or g <= 0:
            continue
        if fnum(r.get("eta_out_mPa_s")) is not None:
            etas.add(fnum(r.get("eta_out_mPa_s")))
        if f is None:
            if r.get("regime", "").strip().lower() == "tumbling":
                tumbling.append(g)
            continue
        pts.append((g, f))
    if not pts and not tumbling:
        note("no usable ttf-sweep rows in shear.csv: skipping ttf_vs_shear_rate.png")
        return
    fig, ax = plt.subplots(figsize=(5.0, 3.7))
    xs = []
    tab = read_exp_columns(Path(data) / "shear_flow" / "ttf" / "data_donors12.csv",
                           ["shear_rate", "TTF"])
    if tab is not None:
        m = np.isfinite(tab["shear_rate"]) & np.isfinite(tab["TTF"])
        ax.plot(tab["shear_rate"][m], 4 * np.pi * tab["TTF"][m], ls="none", marker="o", ms=3,
                mfc="none", mec=C_EXP, mew=0.7,
                label=r"Fischer, donors 1-2 ($\eta_o$ = 28.9 mPa s)")
        xs += list(tab["shear_rate"][m])
    if pts:
        pts.sort()
        g = np.array([p[0] for p in pts])
        f = np.array([p[1] for p in pts])
        eta_txt = ", ".join(f"{e:g}" for e in sorted(etas))
        lab = "simulation" + (rf" ($\eta_o$ = {eta_txt} mPa s)" if eta_txt else "")
        ax.plot(g, f, color=C_SIM, marker="s", ms=4.5, lw=1.4, label=lab, zorder=5)
        xs += list(g)
    if tumbling:
        ax.plot(tumbling, np.zeros(len(tumbling)), ls="none", marker="x", ms=7, mew=1.6,
                color=REGIME_STYLE["tumbling"][0], label="simulation: tumbling (no TTF)",
                clip_on=False, zorder=6)
        xs += tumbling
    if xs and min(xs) > 0:
        ax.set_xscale("log")
    ax.set_ylim(bottom=0)
    ax.set_xlabel(r"shear rate $\dot\gamma$ [1/s]")
    ax.set_ylabel(r"$4\pi f/\dot\gamma$")
    ax.set_title("Tank-treading frequency")
    ax.legend(loc="best", frameon=False)
    finish(fig, Path(figdir) / "ttf_vs_shear_rate.png", sub, written)


def plot_threshold(shear, threshold, data, figdir, sub, written):
    # bracket per eta
    brackets = []
    for r in threshold:
        eta = fnum(r.get("eta_out_mPa_s"))
        if eta is None or eta <= 0:
            continue
        lo = fnum(r.get("tau_lo_Pa"))
        hi = fnum(r.get("tau_hi_Pa"))
        # fall back to the shear-rate bounds when the stresses are absent
        if lo is None and fnum(r.get("gamma_lo_per_s")) is not None:
            lo = eta * 1e-3 * fnum(r.get("gamma_lo_per_s"))
        if hi is None and fnum(r.get("gamma_hi_per_s")) is not None:
            hi = eta * 1e-3 * fnum(r.get("gamma_hi_per_s"))
        if lo is not None and lo <= 0:
            lo = None
        if hi is not None and hi <= 0:
            hi = None
        if lo is None and hi is None:
            continue
        brackets.append((eta, lo, hi))
    # sweep cases
    cases = {}
    for r in ok_rows(shear):
        if r.get("sweep", "").strip().lower() != "threshold":
            continue
        eta = fnum(r.get("eta_out_mPa_s"))
        tau = fnum(r.get("shear_stress_Pa"))
        if tau is None and eta is not None and fnum(r.get("shear_rate_per_s")) is not None:
            tau = eta * 1e-3 * fnum(r.get("shear_rate_per_s"))
        reg = r.get("regime", "").strip().lower() or "empty"
        if eta is None or tau is None or tau <= 0 or eta <= 0:
            continue
        cases.setdefault(reg if reg in REGIME_STYLE else "empty", []).append((eta, tau))
    if not brackets and not cases:
        note("no usable rows in threshold.csv or threshold-sweep rows in shear.csv: "
             "skipping critical_stress_vs_eta.png")
        return

    fig, ax = plt.subplots(figsize=(7.6, 4.0))
    d = Path(data) / "shear_flow" / "tt_tb_critical_stress"
    for name, lab, mk, col in (("Fischer2013.csv", "Fischer & Korzeniewski 2013", "o", C_EXP),
                               ("Abkarian2007.csv", "Abkarian et al. 2007", "^", C_EXP2)):
        tab = read_exp_columns(d / name, ["eta", "tau"])
        if tab is None:
            continue
        m = np.isfinite(tab["eta"]) & np.isfinite(tab["tau"]) & (tab["tau"] > 0)
        ax.plot(tab["eta"][m], tab["tau"][m], ls="none", marker=mk, ms=5.5, mfc="none",
                mec=col, mew=1.1, label=lab, zorder=4)

    # sweep, lightly
    for reg in ("tank-treading", "tumbling", "intermittent", "empty"):
        if reg not in cases:
            continue
        col, mk, lab = REGIME_STYLE[reg]
        e = np.array([c[0] for c in cases[reg]])
        t = np.array([c[1] for c in cases[reg]])
        ax.plot(e, t, ls="none", marker=mk, ms=4, color=col, alpha=0.45,
                mfc=("none" if mk in "oD" else col), label=f"simulated case: {lab}", zorder=2)

    # brackets
    first_iv = first_one = True
    for eta, lo, hi in sorted(brackets):
        if lo is not None and hi is not None:
            a, b = min(lo, hi), max(lo, hi)
            mid = math.sqrt(a * b)
            ax.errorbar([eta], [mid], yerr=[[mid - a], [b - mid]], color=C_SIM, marker="s",
                        ms=5, capsize=4, elinewidth=2.0, lw=0, zorder=6,
                        label=(r"simulation: $[\eta_o\dot\gamma_{lo}, \eta_o\dot\gamma_{hi}]$"
                               if first_iv else None))
            first_iv = False
        else:
            # one-sided: lo only -> threshold above lo (arrow up); hi only -> below hi (arrow down)
            val = lo if lo is not None else hi
            mk = r"$\uparrow$" if lo is not None else r"$\downarrow$"
            ax.plot([eta], [val], ls="none", marker="_", ms=10, mew=2.0, color=C_SIM, zorder=6)
            tip = val * (1.8 if lo is not None else 1 / 1.8)
            ax.annotate("", xy=(eta, tip), xytext=(eta, val),
                        arrowprops=dict(arrowstyle="->", color=C_SIM, lw=1.6), zorder=6)
            ax.plot([eta], [tip], ls="none", marker="none")  # keep the arrow inside the limits
            ax.plot([], [], ls="none", marker=mk, color=C_SIM, ms=8,
                    label=("simulation: one bound only (arrow towards threshold)"
                           if first_one else None))
            first_one = False
    ax.set_yscale("log")
    all_eta = [b[0] for b in brackets] + [c[0] for v in cases.values() for c in v]
    if use_log(all_eta + [10.7, 104.0], ratio=8.0):
        ax.set_xscale("log")
    ax.set_xlabel(r"outer viscosity $\eta_o$ [mPa s]")
    ax.set_ylabel(r"critical shear stress $\eta_o\dot\gamma$ [Pa]")
    ax.set_title("Tumbling / tank-treading threshold")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    finish(fig, Path(figdir) / "critical_stress_vs_eta.png", sub, written)


# --------------------------------------------------------------------------------------------
# microtube figures
# --------------------------------------------------------------------------------------------

def is_true(s):
    return str(s).strip().lower() in ("true", "1", "yes", "y")


def tube_points(tube, xcol, ycol):
    """(x, y, plateau) of ok rows with both observables."""
    out = []
    for r in ok_rows(tube):
        x = fnum(r.get(xcol))
        y = fnum(r.get(ycol))
        if x is None or y is None:
            continue
        pl = r.get("plateau", "true")
        out.append((x, y, is_true(pl) if pl.strip() else True))
    out.sort()
    return out


def radii_label(tube):
    rs = sorted({fnum(r.get("radius_um")) for r in ok_rows(tube)
                 if fnum(r.get("radius_um")) is not None})
    if not rs:
        return "simulation"
    return "simulation (R = " + ", ".join(f"{x:g}" for x in rs) + " µm)"


def draw_tube_sim(ax, pts, tube, xcol_label=None):
    x = np.array([p[0] for p in pts])
    y = np.array([p[1] for p in pts])
    pl = np.array([p[2] for p in pts], dtype=bool)
    ax.plot(x, y, color=C_SIM, lw=1.3, marker="s", ms=4.5, markevery=list(pl), zorder=4,
            label=radii_label(tube))
    if (~pl).any():
        ax.plot(x[~pl], y[~pl], ls="none", marker="s", ms=5, mfc="white", mec=C_SIM, mew=1.2,
                zorder=5, label="simulation, no plateau reached (open)")


def plot_tube_v_pg(tube, data, figdir, sub, written):
    pts = tube_points(tube, "pg_mmHg_per_mm", "velocity_cm_per_s")
    if not pts:
        note("no usable rows in tube.csv: skipping tube_velocity_vs_pg.png")
        return
    fig, ax = plt.subplots(figsize=(5.0, 3.7))
    tab = read_exp_columns(Path(data) / "microtube" / "Tomaiuolo2009_pg_v_6.6um.csv", ["pg", "v"])
    if tab is not None:
        m = np.isfinite(tab["pg"]) & np.isfinite(tab["v"])
        ax.plot(tab["pg"][m], tab["v"][m], ls="none", marker="o", ms=3.5, mfc="none", mec=C_EXP,
                mew=0.9, label="Tomaiuolo et al. 2009 (6.6 µm tube)")
    draw_tube_sim(ax, pts, tube)
    ax.set_xlim(left=0)
    ax.set_ylim(bottom=0)
    ax.set_xlabel(r"pressure gradient $\Delta P/L$ [mmHg/mm]")
    ax.set_ylabel("cell velocity [cm/s]")
    ax.set_title("Microtube: velocity vs pressure gradient")
    ax.legend(loc="best", frameon=False)
    finish(fig, Path(figdir) / "tube_velocity_vs_pg.png", sub, written)


def plot_tube_l_v(tube, data, figdir, sub, written):
    pts = tube_points(tube, "velocity_cm_per_s", "length_um")
    if not pts:
        note("no usable rows in tube.csv (length, velocity): skipping tube_length_vs_velocity.png")
        return
    fig, ax = plt.subplots(figsize=(5.0, 3.7))
    xs = [p[0] for p in pts]
    d = Path(data) / "microtube"
    tab = read_exp_columns(d / "Tomaiuolo2009_v_l_6.6um.csv", ["v", "l", "l_high", "l_low"])
    if tab is not None:
        m = np.isfinite(tab["v"]) & np.isfinite(tab["l"])
        lo = np.where(np.isfinite(tab["l_low"]), tab["l"] - tab["l_low"], 0.0)[m]
        hi = np.where(np.isfinite(tab["l_high"]), tab["l_high"] - tab["l"], 0.0)[m]
        ax.errorbar(tab["v"][m], tab["l"][m], yerr=[np.abs(lo), np.abs(hi)], ls="none",
                    marker="o", ms=4, mfc="none", mec=C_EXP, ecolor=C_EXP, mew=1.0, capsize=2.5,
                    elinewidth=0.8, label="Tomaiuolo et al. 2009 (6.6 µm tube)")
        xs += list(tab["v"][m])
    tab = read_exp_columns(d / "Hochmut1970_v_l_6.7um.csv", ["v", "l"])
    if tab is not None:
        m = np.isfinite(tab["v"]) & np.isfinite(tab["l"])
        v_cm = tab["v"][m] * 0.1  # mm/s -> cm/s (data/README.md 2.2)
        ax.plot(v_cm, tab["l"][m], ls="none", marker="^", ms=4, mfc="none", mec=C_EXP2, mew=0.9,
                label="Hochmuth et al. 1970 (6.7 µm tube)")
        xs += list(v_cm)
    draw_tube_sim(ax, pts, tube)
    if use_log(xs, ratio=30.0):
        ax.set_xscale("log")
    else:
        ax.set_xlim(left=0)
    ax.set_xlabel("cell velocity [cm/s]")
    ax.set_ylabel(r"cell length $l$ [$\mu$m]")
    ax.set_title("Microtube: cell length vs velocity")
    ax.legend(loc="best", frameon=False)
    finish(fig, Path(figdir) / "tube_length_vs_velocity.png", sub, written)


# --------------------------------------------------------------------------------------------

def main(argv=None):
    ap = argparse.ArgumentParser(
        description="Plot `trbc validate` outputs (shear.csv, threshold.csv, tube.csv) against "
                    "the flow-validation experiments (docs/VALIDATION.md sections 3-4).")
    ap.add_argument("dir", metavar="DIR", help="output directory of `trbc validate`")
    ap.add_argument("--data", metavar="EXPDIR", default=str(DEFAULT_DATA),
                    help="experimental validation data (default: %(default)s)")
    ap.add_argument("--out", metavar="FIGDIR", default=None,
                    help="where to write the PNG figures (default: DIR/figures)")
    args = ap.parse_args(argv)

    d = Path(args.dir)
    if not d.is_dir():
        note(f"error: validate output directory does not exist: {d}")
        return 2
    data = Path(args.data)
    if not data.is_dir():
        note(f"warning: experimental data directory not found: {data} "
             "(figures are drawn without experimental points)")
    figdir = Path(args.out) if args.out else d / "figures"

    shear = read_rows(d / "shear.csv")
    threshold = read_rows(d / "threshold.csv")
    tube = read_rows(d / "tube.csv")
    for name, rows in (("shear.csv", shear), ("threshold.csv", threshold), ("tube.csv", tube)):
        if not rows:
            note(f"{name}: missing or no data rows in {d}")
    if not shear and not threshold and not tube:
        note("nothing to plot")
        return 0
    sub = subtitle(read_json(d / "validation.json"))

    written = []
    for fn, fargs in ((plot_angle, (shear, data, figdir, sub, written)),
                      (plot_ttf, (shear, data, figdir, sub, written)),
                      (plot_threshold, (shear, threshold, data, figdir, sub, written)),
                      (plot_tube_v_pg, (tube, data, figdir, sub, written)),
                      (plot_tube_l_v, (tube, data, figdir, sub, written))):
        try:
            fn(*fargs)
        except OSError as e:  # e.g. FIGDIR cannot be created or written
            plt.close("all")
            note(f"error: cannot write figure to {figdir}: {e}")
            return 2
        except Exception as e:  # one broken figure must not prevent the others
            plt.close("all")
            note(f"error while drawing {fn.__name__}: {type(e).__name__}: {e}")
    if not written:
        note("nothing to plot")
    return 0


if __name__ == "__main__":
    sys.exit(main())
