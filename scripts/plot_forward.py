#!/usr/bin/python3
"""Plot the output of ``trbc simulate ... --save-shapes DIR`` against experiment.

Reads DIR/simulate.json (required) and the optional CSV files written next to it
(equilibrium_profile.csv, stretching_curve.csv, relaxation.csv) and writes three
figures (see docs/MEMBRANE_MODEL.md and docs/FORWARD_MODEL.md):

  <prefix>equilibrium.png  aligned cross-section vs the Evans-Fung (1972) shape,
                           simulated D, hmin, hmax vs measured mean +- sd
  <prefix>stretching.png   D0 (transverse), D1 (axial) vs Fext against
                           Mills et al. 2004 and Suresh et al. 2005
  <prefix>relaxation.png   z = L/W after release with its Hochmuth fit, and the
                           four Hochmuth et al. 1979 cells (each fitted with
                           trbc.fit_hochmuth), as z(t) and in the linearised (log) form

Usage:
  scripts/plot_forward.py DIR [--data EXPDIR] [--out OUTDIR] [--prefix forward_]

Defaults: --data <repo>/data/experiments, --out <repo>/docs/figures
(both resolved from this script's location, so they work from any directory).
Needs numpy, matplotlib and trbc's Python module, which gives the Evans-Fung shape and the
Hochmuth fit: the package installed by `make python`, or, from a build tree,
PYTHONPATH=src/python:build/python after `cmake --build build --target trbc_python`
(scripts/showcase_forward.sh sets it).
"""

import argparse
import csv
import json
import math
import sys
from itertools import cycle
from pathlib import Path

import numpy as np
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import plot_style  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

# trbc gives the Evans-Fung shape and the Hochmuth fit; an import that finds only the extension
# module (PYTHONPATH=build/python alone) or an older build lacks them.
try:
    import trbc  # noqa: E402
    trbc.fit_hochmuth, trbc.evans_fung_thickness, trbc.load_data_sets  # noqa: B018
except (ImportError, AttributeError) as exc:
    sys.exit(f"plot_forward: error: cannot use trbc ({exc}); install it with `make python`, or build "
             f"`cmake --build build --target trbc_python` and set PYTHONPATH=src/python:build/python")

REPO = Path(__file__).resolve().parent.parent
DEFAULT_DATA = (REPO / "data" / "experiments").resolve()
DEFAULT_OUT = REPO / "docs" / "figures"

DPI = 150
C_SIM = "#1f3b73"      # simulation (dark blue)
C_D1 = "#c0392b"       # axial diameter
C_D0 = "#2471a3"       # transverse diameter
C_CELLS = ["#d35400", "#27ae60", "#8e44ad", "#7f8c8d"]  # Hochmuth cells 1-4, then again
# The figures' names of the shipped data sets; another set is named as its datasets.json does.
LABELS = {"evans_fung_1972": "Evans–Fung 1972", "mills_2004": "Mills et al. 2004", "suresh_2005": "Suresh et al. 2005",
          **{f"hochmuth_1979_cell{i}": f"Hochmuth et al. 1979, cell {i}" for i in range(1, 5)}}

plot_style.apply(**{"savefig.dpi": DPI})


# --------------------------------------------------------------------------- I/O
def note(msg):
    print(f"plot_forward: {msg}", file=sys.stderr)


def die(msg):
    print(f"plot_forward: error: {msg}", file=sys.stderr)
    sys.exit(1)


def read_csv(path):
    """Read a headed numeric CSV into {column: float array}; None if absent/unusable."""
    path = Path(path)
    if not path.is_file():
        return None
    try:
        with open(path, newline="") as fh:
            rows = [r for r in csv.reader((ln for ln in fh if not ln.startswith("#"))) if r and any(c.strip() for c in r)]
    except OSError as exc:
        note(f"cannot read {path}: {exc}")
        return None
    if len(rows) < 2:
        note(f"{path} has no data rows")
        return None
    header = [h.strip() for h in rows[0]]
    cols = {h: [] for h in header}
    for r in rows[1:]:
        for i, h in enumerate(header):
            s = r[i].strip() if i < len(r) else ""
            try:
                cols[h].append(float(s) if s else math.nan)
            except ValueError:
                cols[h].append(math.nan)
    return {h: np.asarray(v, dtype=float) for h, v in cols.items()}


def need_cols(tab, cols, path):
    missing = [c for c in cols if c not in tab]
    if missing:
        note(f"{path}: missing column(s) {', '.join(missing)}; skipped")
        return False
    return True


def num(d, key):
    """Float value of d[key], or None if absent/null/non-finite."""
    if not isinstance(d, dict):
        return None
    v = d.get(key)
    try:
        v = float(v)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def fmt(x, nd=4):
    return "n/a" if x is None else f"{x:.{nd}g}"


def param_caption(sim):
    p = sim.get("parameters") or {}
    parts = [f"v = {fmt(num(p, 'v'))}",
             rf"$\mu$ = {fmt(num(p, 'mu_uN_per_m'))} µN/m"]
    if num(p, "FvK") is not None or num(p, "kb_J") is None:
        parts.append(f"FvK = {fmt(num(p, 'FvK'))}")
    else:
        parts.append(rf"$\kappa_b$ = {fmt(num(p, 'kb_J'))} J")
    parts += [rf"$b_2$ = {fmt(num(p, 'b2'))}",
              rf"$\eta_m$ = {fmt(num(p, 'etam_Pa_s_um'))} Pa·s·µm"]
    foot = provenance_footer(sim)
    return f"simulation{f' ({foot})' if foot else ''}:  " + ",   ".join(parts)


def provenance_footer(sim):
    pv = sim.get("provenance") or {}
    bits = []
    if pv.get("version") is not None:
        bits.append(f"trbc {pv['version']}")
    if pv.get("level") is not None:
        bits.append(f"level {pv['level']}")
    return ", ".join(bits)


def finish(fig, sim, path, rect_top=1.0, layout=True):
    fig.suptitle(param_caption(sim), fontsize=9, y=0.985)
    if layout:
        fig.tight_layout(rect=(0, 0.02, 1, rect_top))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=DPI, bbox_inches="tight", pad_inches=0.08)
    plt.close(fig)
    print(path)


# ----------------------------------------------------------------- Hochmuth law
def hochmuth(tau, tc, zinf, z0):
    """z(tau) = zinf (Lam + e)/(Lam - e), e = exp(-tau/tc), Lam = (z0+zinf)/(z0-zinf)."""
    e = np.exp(-np.asarray(tau, dtype=float) / tc)
    lam = (z0 + zinf) / (z0 - zinf)
    return zinf * (lam + e) / (lam - e)


def hochmuth_log(z, zinf, z0):
    """ln[(z-zinf)/(z+zinf) * (z0+zinf)/(z0-zinf)]; NaN where the argument is <= 0."""
    z = np.asarray(z, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        arg = (z - zinf) / (z + zinf) * (z0 + zinf) / (z0 - zinf)
        out = np.full_like(z, np.nan)
        ok = np.isfinite(arg) & (arg > 0)
        out[ok] = np.log(arg[ok])
    return out


def fit_hochmuth(t, z, what):
    """trbc.fit_hochmuth on the finite samples of (t, z) in time order: (tc, zinf) by least squares,
    z0 = z at the first sample, time measured from it. Returns dict(tc, zinf, z0, t0, rms), or None
    (with a note naming `what`) when the data are unusable or the fit does not converge."""
    t = np.asarray(t, float)
    z = np.asarray(z, float)
    ok = np.isfinite(t) & np.isfinite(z)
    o = np.argsort(t[ok])
    try:
        f = trbc.fit_hochmuth(t[ok][o], z[ok][o])
    except ValueError as exc:
        note(f"{what}: Hochmuth fit not possible: {exc}")
        return None
    if not f["converged"]:
        note(f"{what}: Hochmuth fit did not converge: {f['message']}")
        return None
    return {"tc": f["tc_s"], "zinf": f["zinf"], "z0": f["z0"], "t0": f["t0_s"], "rms": f["rms"]}


# ---------------------------------------------------------------- figure 1
def thickness_extrema(r, h):
    """hmax, r*, and hmin = min of h over r <= r* (docs/FORWARD_MODEL.md, equilibrium)."""
    k = int(np.nanargmax(h))
    rs = r[k]
    inner = r <= rs
    j = int(np.nanargmin(np.where(inner, h, np.inf)))
    return h[k], rs, h[j], r[j]


def plot_equilibrium(sim, d, sets, out):
    prof_path = d / "equilibrium_profile.csv"
    prof = read_csv(prof_path)
    if prof is None:
        note(f"{prof_path} not found; equilibrium figure skipped")
        return None
    if not need_cols(prof, ["r_um", "zlow_um", "zhigh_um"], prof_path):
        return None
    r, zl, zh = prof["r_um"], prof["zlow_um"], prof["zhigh_um"]
    ok = np.isfinite(r) & np.isfinite(zl) & np.isfinite(zh)
    r, zl, zh = r[ok], zl[ok], zh[ok]
    if r.size < 2:
        note(f"{prof_path}: fewer than two valid rows; equilibrium figure skipped")
        return None
    o = np.argsort(r)
    r, zl, zh = r[o], zl[o], zh[o]
    h = zh - zl

    obs = sim.get("observables") or {}
    hmax_p, rstar, hmin_p, rmin = thickness_extrema(r, h)
    sim_vals = {
        "D": num(obs, "D_um"),
        "hmin": num(obs, "hmin_um"),
        "hmax": num(obs, "hmax_um"),
    }
    from_profile = []
    for key, val in (("D", 2 * r.max()), ("hmin", hmin_p), ("hmax", hmax_p)):
        if sim_vals[key] is None:
            sim_vals[key] = float(val)
            from_profile.append(key)
    if from_profile:
        note("observable(s) " + ", ".join(from_profile) +
             " not in simulate.json; taken from the profile")

    # Evans-Fung analytic shape (trbc's, as the biconcave mesh of `trbc mesh icosphere --biconcave`)
    ef_r0 = trbc.evans_fung_radius_um()
    rho = np.linspace(0.0, 1.0, 801)
    hef = trbc.evans_fung_thickness(ef_r0 * rho)
    ref_ef = np.concatenate([-ef_r0 * rho[::-1], ef_r0 * rho])
    hef_full = np.concatenate([hef[::-1], hef])

    # closed outline of the simulated section (right half, then mirrored)
    xs = np.concatenate([r, r[::-1], -r, -r[::-1]])
    zs = np.concatenate([zh, zl[::-1], zl, zh[::-1]])

    fig = plt.figure(figsize=(9.0, 3.6))
    ax = fig.add_axes((0.08, 0.15, 0.60, 0.70))
    side = fig.add_axes((0.70, 0.15, 0.29, 0.70))
    side.axis("off")

    ax.fill(xs, zs, color=C_SIM, alpha=0.10, lw=0, zorder=1)
    ax.plot(np.concatenate([-r[::-1], r]), np.concatenate([zh[::-1], zh]),
            color=C_SIM, lw=1.8, zorder=3, label="simulation\n(aligned, section y = 0)")
    ax.plot(np.concatenate([-r[::-1], r]), np.concatenate([zl[::-1], zl]),
            color=C_SIM, lw=1.8, zorder=3)
    # close the rim with a short segment so the outline reads as one curve
    for sgn in (1, -1):
        ax.plot([sgn * r[-1]] * 2, [zl[-1], zh[-1]], color=C_SIM, lw=1.8, zorder=3)
    ax.plot(ref_ef, hef_full / 2, color="k", ls="--", lw=1.1, zorder=4,
            label="Evans & Fung (1972)\nanalytic shape")
    ax.plot(ref_ef, -hef_full / 2, color="k", ls="--", lw=1.1, zorder=4)
    ax.axhline(0, color="0.85", lw=0.6, zorder=0)
    ax.axvline(0, color="0.85", lw=0.6, zorder=0)

    # dimension marks on the simulated profile (right half)
    arrow = dict(arrowstyle="<->", color="0.35", lw=0.8, shrinkA=0, shrinkB=0)
    kmin = int(np.argmin(np.abs(r - rmin)))
    kmax = int(np.argmin(np.abs(r - rstar)))
    zmid = 0.5 * (zl[kmin] + zh[kmin])
    ax.annotate("", xy=(r[kmin], zl[kmin]), xytext=(r[kmin], zh[kmin]), arrowprops=arrow, zorder=5)
    ax.text(r[kmin] + 0.1, zmid, r"$h_{\min}$", fontsize=8, color="0.25", ha="left", va="center")
    ax.annotate("", xy=(r[kmax], zl[kmax]), xytext=(r[kmax], zh[kmax]), arrowprops=arrow, zorder=5)
    ax.text(r[kmax] - 0.1, 0.5 * (zl[kmax] + zh[kmax]), r"$h_{\max}$", fontsize=8, color="0.25",
            ha="right", va="center")
    ymin = min(np.nanmin(zl), -hef.max() / 2)
    ymax = max(np.nanmax(zh), hef.max() / 2)
    yD = ymin - 0.3
    ax.annotate("", xy=(-r[-1], yD), xytext=(r[-1], yD), arrowprops=arrow, zorder=5)
    ax.text(0, yD - 0.07, r"$D$", fontsize=8, color="0.25", ha="center", va="top")

    # table: simulated vs measured
    meas = {}  # quantity: (mean, SD or NaN)
    eq = [s for s in sets if s.experiment == "equilibrium"]
    if not eq:
        note("no equilibrium data set; measured values not shown")
    else:
        for key, m, sd in zip(("D", "hmin", "hmax"), eq[0].shape, eq[0].shape_sd_um):
            meas[key] = (float(m), float(sd))
        print(f"{eq[0].name}: " + ", ".join(f"{k} {m:.3g}" + (f" ± {sd:.3g}" if np.isfinite(sd) else "") + " um"
                                             for k, (m, sd) in meas.items()))
    names = {"D": "D    ", "hmin": "h_min", "hmax": "h_max"}
    lines = [f"(µm)     sim.   {LABELS.get(eq[0].name, eq[0].name) if eq else 'measured'}",
             "                 mean ± sd"]
    for key in ("D", "hmin", "hmax"):
        s = sim_vals[key]
        star = "*" if key in from_profile else " "
        if key in meas:
            m, sd = meas[key]
            lines.append(f"{names[key]}  {s:6.3f}{star} {m:5.2f}" + (f" ± {sd:.2f}" if np.isfinite(sd) else ""))
        else:
            lines.append(f"{names[key]}  {s:6.3f}{star}")
    devs = [f"{names[k].strip()} {(sim_vals[k] - meas[k][0]) / meas[k][1]:+.1f}"
            for k in ("D", "hmin", "hmax") if k in meas and meas[k][1] > 0]
    if devs:
        lines += ["", "sim − mean, in sd:", "  " + ",  ".join(devs)]
    if from_profile:
        lines.append("* from the saved profile")

    xmax = max(r.max(), ef_r0) + 0.3
    ax.set_xlim(-xmax, xmax)
    ax.set_ylim(yD - 0.45, ymax + 0.3)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("r  (µm; half-line y = 0, x = r ≥ 0, mirrored to −r)")
    ax.set_ylabel("z  (µm, symmetry axis)")
    ax.set_title("Equilibrium shape: cross-section through the symmetry axis", loc="left")

    # align the side panel (legend + table) with the aspect-shrunk main axes
    ax.apply_aspect()
    pos = ax.get_position()
    side.set_position((pos.x1 + 0.03, pos.y0, 0.97 - pos.x1 - 0.03, pos.height))
    h, l = ax.get_legend_handles_labels()
    side.legend(h, l, loc="upper left", frameon=False, bbox_to_anchor=(0.0, 1.0),
                borderaxespad=0.0, handlelength=2.2)
    side.text(0.0, 0.0, "\n".join(lines), transform=side.transAxes, ha="left", va="bottom",
              family="monospace", fontsize=7.5,
              bbox=dict(boxstyle="round,pad=0.5", fc="white", ec="0.75", lw=0.6))
    path = out / f"{PREFIX}equilibrium.png"
    finish(fig, sim, path, layout=False)
    return path


# ---------------------------------------------------------------- figure 2
def plot_stretching(sim, d, sets, out):
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    anything = False

    curve_path = d / "stretching_curve.csv"
    curve = read_csv(curve_path)
    if curve is None:
        note(f"{curve_path} not found; simulated stretching curve not drawn")
    elif need_cols(curve, ["Fext_pN", "D0_um", "D1_um"], curve_path):
        o = np.argsort(curve["Fext_pN"])
        F = curve["Fext_pN"][o]
        for key, col in (("D1_um", C_D1), ("D0_um", C_D0)):
            y = curve[key][o]
            m = np.isfinite(F) & np.isfinite(y)
            ax.plot(F[m], y[m], color=col, lw=1.6, marker="o", ms=2.5, zorder=3)
            anything = anything or bool(m.any())

    p = sim.get("parameters") or {}
    obs = sim.get("observables") or {}
    Fs = num(p, "Fext_pN")
    single = False
    if Fs is not None:
        for key, col in (("D1_um", C_D1), ("D0_um", C_D0)):
            y = num(obs, key)
            if y is not None:
                ax.plot([Fs], [y], marker="*", ms=12, color=col, mec="k", mew=0.6,
                        ls="none", zorder=5)
                single = anything = True
    if not single:
        note("no single-force stretching result (Fext_pN, D0_um, D1_um) in simulate.json")

    sources = []
    stretching = [s for s in sets if s.experiment == "stretching"]
    if not stretching:
        note("no stretching data set; the data are not drawn")
    for k, ds in enumerate(stretching):
        label, mk, filled = LABELS.get(ds.name, ds.name), "osD^v"[k % 5], k % 2 == 0
        for diameter, col in ((ds.D1_um, C_D1), (ds.D0_um, C_D0)):
            ax.plot(ds.force_pN, diameter, ls="none", marker=mk, ms=5,
                    mfc=col if filled else "white", mec=col, mew=1.1, alpha=0.9, zorder=4)
        sources.append((label, mk, filled))
        anything = True

    if not anything:
        plt.close(fig)
        note("nothing to plot for stretching; figure skipped")
        return None

    # two-part legend: colour = diameter, symbol = source
    h_q = [Line2D([], [], color=C_D1, lw=3, label=r"$D_1$  axial (along the pull)"),
           Line2D([], [], color=C_D0, lw=3, label=r"$D_0$  transverse")]
    h_s = []
    if curve is not None:
        h_s.append(Line2D([], [], color="0.3", lw=1.6, marker="o", ms=2.5, label="simulation"))
    if single:
        h_s.append(Line2D([], [], color="0.6", marker="*", ms=11, mec="k", mew=0.6, ls="none",
                          label=f"simulation, F = {Fs:.4g} pN"))
    for label, mk, filled in sources:
        h_s.append(Line2D([], [], ls="none", marker=mk, ms=5, mfc="0.3" if filled else "white",
                          mec="0.3", mew=1.1, label=label))
    leg1 = ax.legend(handles=h_q, loc="upper left", frameon=False)
    ax.add_artist(leg1)
    ax.legend(handles=h_s, loc="center right", frameon=False)

    ax.set_xlim(left=-5)
    ax.set_xlabel(r"$F_\mathrm{ext}$  (pN, force of one bead)")
    ax.set_ylabel("diameter  (µm)")
    ax.set_title("Optical-tweezers stretching", loc="left")
    ax.grid(alpha=0.25, lw=0.5)
    path = out / f"{PREFIX}stretching.png"
    finish(fig, sim, path)
    return path


# ---------------------------------------------------------------- figure 3
def plot_relaxation(sim, d, sets, out):
    rel_path = d / "relaxation.csv"
    rel = read_csv(rel_path)
    sim_ok = rel is not None and need_cols(rel, ["t_s", "z"], rel_path)
    if rel is None:
        note(f"{rel_path} not found; simulated relaxation not drawn")
    t_sim = z_sim = None
    sfit = None
    if sim_ok:
        m = np.isfinite(rel["t_s"]) & np.isfinite(rel["z"])
        o = np.argsort(rel["t_s"][m])
        t_sim, z_sim = rel["t_s"][m][o], rel["z"][m][o]
        if t_sim.size == 0:
            sim_ok = False
    if sim_ok:
        rf = sim.get("relaxation_fit") or {}
        fit = {k: num(rf, key) for k, key in (("tc", "tc_s"), ("zinf", "zinf"), ("z0", "z0"), ("t0", "t0_s"))}
        if all(v is not None for v in fit.values()) and fit["tc"] > 0 and fit["z0"] != fit["zinf"]:
            sfit = fit
        else:
            # The fit is trbc simulate's (its samples, its start t0_s); none is made here.
            note("relaxation_fit incomplete in simulate.json (tc_s, zinf, z0, t0_s); the simulated z(t) is drawn "
                 "without its fit")

    cells = []
    relaxation = [s for s in sets if s.experiment == "relaxation"]
    if not relaxation:
        note("no relaxation data set; the data are not drawn")
    for ds in relaxation:
        name = LABELS.get(ds.name, ds.name)
        f = fit_hochmuth(ds.t_s, ds.aspect, ds.file)
        if f is not None:
            print(f"{name}: tc = {f['tc']:.4f} s, zinf = {f['zinf']:.4f}, "
                  f"z0 = {f['z0']:.4f}, rms = {f['rms']:.3g}")
        cells.append((name, ds.t_s, ds.aspect, f))

    if not sim_ok and not cells:
        note("nothing to plot for relaxation; figure skipped")
        return None

    fig, (axz, axl) = plt.subplots(1, 2, figsize=(10.5, 4.75))
    tmax = 0.0

    # --- left: z(t)
    if sim_ok:
        axz.plot(t_sim, z_sim, ls="none", marker="o", ms=2.6, mfc="none", mec=C_SIM, mew=0.7,
                 label="simulation", zorder=4)
        tmax = max(tmax, t_sim.max())
        if sfit is not None:
            tt = np.linspace(t_sim[0], t_sim.max(), 400)
            axz.plot(tt, hochmuth(tt - sfit["t0"], sfit["tc"], sfit["zinf"], sfit["z0"]),
                     color=C_SIM, lw=1.4, zorder=5,
                     label=rf"Hochmuth fit: $t_c$ = {sfit['tc']:.3g} s, $z_\infty$ = {sfit['zinf']:.3g}")
    for (name, t, z, f), col in zip(cells, cycle(C_CELLS)):
        axz.plot(t, z, ls="none", marker="^", ms=4, color=col, alpha=0.85, zorder=3, label=name)
        if f is not None:
            tt = np.linspace(f["t0"], np.nanmax(t), 200)
            axz.plot(tt, hochmuth(tt - f["t0"], f["tc"], f["zinf"], f["z0"]),
                     color=col, lw=0.8, ls="--", alpha=0.8, zorder=2)
        tmax = max(tmax, np.nanmax(t))
    if any(c[3] is not None for c in cells):
        axz.plot([], [], color="0.45", lw=0.8, ls="--", label="Hochmuth law fitted to each cell")
    axz.axhline(1.0, color="0.8", lw=0.6, zorder=0)
    axz.set_xlabel("t  (s, since release)")
    axz.set_ylabel("z = L / W")
    axz.set_title("Relaxation after release", loc="left")
    axz.set_xlim(-0.01 * tmax, 1.02 * tmax)
    axz.legend(frameon=False, loc="upper right")

    # --- right: linearised form
    ylo = 0.0
    if sim_ok and sfit is not None:
        y = hochmuth_log(z_sim, sfit["zinf"], sfit["z0"])
        n_clip = int(np.sum(~np.isfinite(y)))
        lab = "simulation" + (f" ({n_clip} pt{'s' if n_clip > 1 else ''} clipped)" if n_clip else "")
        axl.plot(t_sim, y, ls="none", marker="o", ms=2.6, mfc="none", mec=C_SIM, mew=0.7,
                 label=lab, zorder=4)
        tt = np.array([t_sim[0], t_sim.max()])
        yl = -(tt - sfit["t0"]) / sfit["tc"]
        axl.plot(tt, yl, color=C_SIM, lw=1.4, zorder=5,
                 label=rf"simulation fit: slope $-1/t_c$, $t_c$ = {sfit['tc']:.3g} s")
        if np.isfinite(y).any():
            ylo = min(ylo, np.nanmin(y), yl.min())
    elif sim_ok:
        note("no Hochmuth fit for the simulation; its log form not drawn")
    tc_exp = []
    for (name, t, z, f), col in zip(cells, cycle(C_CELLS)):
        if f is None:
            continue
        y = hochmuth_log(z, f["zinf"], f["z0"])
        n_clip = int(np.sum(~np.isfinite(y)))
        extra = f", {n_clip} clipped" if n_clip else ""
        axl.plot(t, y, ls="none", marker="^", ms=4, color=col, alpha=0.85, zorder=3,
                 label=rf"{name.removeprefix('Hochmuth et al. 1979, ')}: $t_c$ = {f['tc']:.3f} s  ($z_\infty$ = {f['zinf']:.2f}{extra})")
        tt = np.array([f["t0"], np.nanmax(t)])
        axl.plot(tt, -(tt - f["t0"]) / f["tc"], color=col, lw=0.8, ls="--", alpha=0.8, zorder=2)
        tc_exp.append(f["tc"])
        if np.isfinite(y).any():
            ylo = min(ylo, np.nanmin(y))
    if tc_exp:
        axl.plot([], [], ls="none",
                 label=(rf"cells: mean $t_c$ = {np.mean(tc_exp):.3f} ± "
                        f"{np.std(tc_exp, ddof=1) if len(tc_exp) > 1 else 0:.3f} s (sd)"))
    ylo = max(ylo, -12.0)
    axl.set_ylim(ylo - 0.3, 0.4)
    axl.set_xlim(-0.01 * tmax, 1.02 * tmax)
    axl.axhline(0, color="0.8", lw=0.6, zorder=0)
    axl.set_xlabel("t  (s, since release)")
    axl.set_ylabel(r"$\ln\,[\,(z-z_\infty)(z_0+z_\infty)\,/\,(z+z_\infty)(z_0-z_\infty)\,]$")
    axl.set_title(r"Linearised Hochmuth law (slope $-1/t_c$)", loc="left")
    axl.legend(frameon=False, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2,
               fontsize=7.5, columnspacing=1.2, handletextpad=0.4)
    path = out / f"{PREFIX}relaxation.png"
    finish(fig, sim, path)
    return path


# ---------------------------------------------------------------- main
PREFIX = "forward_"


def main(argv=None):
    global PREFIX
    ap = argparse.ArgumentParser(
        description="Plot the output of `trbc simulate --save-shapes DIR` against experiment.")
    ap.add_argument("dir", help="directory written by trbc simulate --save-shapes")
    ap.add_argument("--data", default=str(DEFAULT_DATA),
                    help="experiments data folder (default: %(default)s)")
    ap.add_argument("--out", default=str(DEFAULT_OUT),
                    help="output folder for the PNG files (default: %(default)s)")
    ap.add_argument("--prefix", default="forward_", help="file-name prefix (default: %(default)s)")
    a = ap.parse_args(argv)
    PREFIX = a.prefix

    d = Path(a.dir)
    sj = d / "simulate.json"
    if not d.is_dir():
        die(f"{d} is not a directory")
    if not sj.is_file():
        die(f"{sj} not found (run `trbc simulate ... --save-shapes {d}` first)")
    try:
        with open(sj) as fh:
            sim = json.load(fh)
    except (OSError, json.JSONDecodeError) as exc:
        die(f"cannot parse {sj}: {exc}")
    if not isinstance(sim, dict):
        die(f"{sj}: top level is not a JSON object")

    # The data sets as trbc reads them for the calibration (the shipped layout or a datasets.json).
    try:
        sets = trbc.load_data_sets(a.data)
    except ValueError as exc:  # bad input, or a path the filesystem refuses: drawn without the data
        note(f"--data {a.data}: {exc}; experimental data will be missing")
        sets = []
    out = Path(a.out)

    written = []
    for fn in (plot_equilibrium, plot_stretching, plot_relaxation):
        p = fn(sim, d, sets, out)
        if p is not None:
            written.append(p)
    if not written:
        note("no figure written")
    return 0


if __name__ == "__main__":
    sys.exit(main())
