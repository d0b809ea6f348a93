#!/usr/bin/python3
"""Plot the output of ``trbc validate`` against the flow-validation experiments.

Reads the CSV files written by ``trbc validate`` into DIR (see
docs/VALIDATE.md) and overlays the simulated observables
on the experimental sets that the verdicts compared with, in trbc's units:
DIR/experimental_data.json of `trbc validate` (for a DIR without it, the same
list from trbc's Python package, trbc.validation_data, where it imports):

  angle_vs_shear_rate.png      mean inclination angle (error bar = swinging
                               amplitude) vs shear rate, one panel per outer
                               viscosity, tumbling (x) and intermittent
                               (diamond) cases without an angle on the axis;
                               Fischer & Korzeniewski 2015 donors
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
  shear.csv, threshold.csv, tube.csv, validation.json ("cell", "level"), and
  bands.csv of `trbc validate --draws N`: where present, every figure also shows
  the 5-95 % band over the posterior draws of each case (a wide pale bar) with
  its median (open marker), beside the configured cell's points.
Rows with status != "ok" and rows with empty observables are ignored.

Usage:
  scripts/plot_validation.py DIR [--data EXPDIR] [--out FIGDIR]
  scripts/plot_validation.py --series LABEL DIR [DIR ...] [--series LABEL DIR [DIR ...] ...]
                             --out FIGDIR [--data EXPDIR]

The first form (used by `trbc validate`) plots one result directory; the figure
footer shows the cell and level of DIR/validation.json.

The second form overlays several labelled result sets ("series", e.g. two cells)
on the same figures. Each --series groups the directories of one cell (e.g. its
angle, ttf, threshold and tube runs): their shear.csv, threshold.csv and
tube.csv rows are concatenated per file. Every series has its own colour, marker
and line style in all figures and its label in the legend (one legend per figure,
below the axes); a series without data for a figure is left out of it. In the
shear-flow figures the series are shifted by a few points horizontally so that
their points and error bars do not hide each other (the threshold brackets of the
series stand side by side; the sweep cases keep the regime colour and take the
series' marker shape; tumbling and intermittent markers without an angle get one row
per series, on the axis). In the tube figures nothing is shifted; earlier series get
bigger markers. The footer names the series drawn and their level (from the CSV rows' "level" column, else
validation.json "level"/"tube_level"). --out is required in this form; a DIR
positional cannot be combined with it (a DIR after a --series group belongs to it).

Defaults: --data <repo>/data/experiments/validation, --out DIR/figures.
The path of every figure written is printed on stdout; notes go to stderr.
Exit status: 0 on success (also when there is nothing to plot), 2 when DIR
(or a series directory) does not exist, an argument is invalid or FIGDIR
cannot be written.
Needs numpy and matplotlib; without experimental_data.json and without trbc's
package the figures are drawn without the experimental points, and a note says so.
"""

import argparse
import csv
import itertools
import json
import math
import sys
from pathlib import Path

import numpy as np
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import plot_style  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from matplotlib.transforms import offset_copy  # noqa: E402

try:
    import trbc  # noqa: E402
    trbc.validation_data  # noqa: B018
except (ImportError, AttributeError) as _exc:  # experimental_data.json is enough
    trbc = None
    _TRBC_MISSING = str(_exc)

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
# --series mode: (colour, marker, line style) of the i-th series; the colours avoid the regime
# colours, the line styles keep coinciding curves apart
SERIES_STYLES = [("#1f3b73", "s", "-"), ("#1e8449", "D", "--"), ("#7d3c98", "v", "-."),
                 ("#a04000", "P", ":"), ("#117a8b", "X", (0, (5, 1, 1, 1, 1, 1))),
                 ("#7b241c", "h", (0, (8, 2)))]
SERIES_SPREAD_PT = 4.5     # horizontal distance (points) between neighbouring series
BAND_OFFSET_PT = 6.0       # horizontal distance (points) of a posterior band from its case
SRC = "\x00dir"            # key added to the rows in --series mode: their directory

plot_style.apply(legend_fontsize=7.5)


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
            reader = csv.DictReader((ln for ln in fh if not ln.startswith("#")))
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


def experimental_sets(dirs, data):
    """The experimental sets: the first experimental_data.json of `dirs`, else trbc.validation_data
    of the data folder; [] with a note when neither can be read."""
    for d in dirs:
        recorded = read_json(Path(d) / "experimental_data.json")
        if isinstance(recorded, list):
            for e in recorded:
                e["x"] = np.asarray(e["x"], dtype=float)
                e["y"] = np.asarray(e["y"], dtype=float).reshape(len(e["x"]), len(e["y_columns"]))  # null -> NaN
            return recorded
    if trbc is None:
        note(f"experimental points not drawn: no experimental_data.json in {', '.join(map(str, dirs))} and trbc's "
             f"Python package does not import ({_TRBC_MISSING})")
        return []
    try:
        return trbc.validation_data(data)
    except (ValueError, RuntimeError) as e:
        note(f"experimental points not drawn: {e}")
        return []


def sets_of(run, observable):
    """The sets of one observable, each with its finite rows: (set, x, y) with y of shape (n, k)."""
    out = []
    for d in run.sets:
        if d["observable"] != observable:
            continue
        x, y = np.asarray(d["x"]), np.asarray(d["y"])
        m = np.isfinite(x)
        out.append((d, x[m], y[m]))
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




# --------------------------------------------------------------------------------------------
# result sets ("series") and per-figure bookkeeping
# --------------------------------------------------------------------------------------------

class Series:
    """The rows of one result set (one cell) and how it is drawn.

    label None is the single-DIR form: the original labels and colours are used."""

    def __init__(self, label, dirs, index=0, count=1):
        self.label = label
        self.dirs = [Path(d) for d in dirs]
        self.index = index
        self.count = count
        self.colour, self.marker, self.ls = SERIES_STYLES[index % len(SERIES_STYLES)]
        self.shear, self.threshold, self.tube, self.bands = [], [], [], []
        self.meta = {}  # str(dir) -> validation.json (dict or None)

    def load(self):
        """Concatenate the CSV rows of all directories (each row tagged with its directory)."""
        seen = {}
        for d in self.dirs:
            found = []
            for attr, name in (("shear", "shear.csv"), ("threshold", "threshold.csv"),
                               ("tube", "tube.csv"), ("bands", "bands.csv")):
                rows = read_rows(d / name)
                for r in rows:
                    r[SRC] = str(d)
                    cid = r.get("case_id", "")
                    if cid:
                        other = seen.setdefault((name, cid), str(d))
                        if other != str(d):
                            note(f"warning: series '{self.label}': case {cid} is in both {other} "
                                 f"and {d} ({name}); both are drawn")
                getattr(self, attr).extend(rows)
                if rows:
                    found.append(f"{name} ({len(rows)} rows)")
            self.meta[str(d)] = read_json(d / "validation.json")
            note(f"series '{self.label}': {d}: " + (", ".join(found) if found else "no data rows"))


def level_text(x):
    v = fnum(x)
    if v is None:
        return str(x).strip() or None
    return f"{v:g}"


class Run:
    """What every figure needs: the series, the experimental data and where to write."""

    def __init__(self, series, data, figdir, sub=None):
        self.series = series
        self.multi = any(s.label is not None for s in series)
        self.data = data
        self.sets = experimental_sets([d for s in series for d in s.dirs], data)
        self.figdir = Path(figdir)
        self.sub = sub          # footer of the single-DIR form
        self.written = []


class FigCtx:
    """Per-figure bookkeeping (used by the --series form): legend order, side-by-side
    positions and the levels drawn."""

    def __init__(self, run):
        self.run = run
        self.used = {}          # series index -> set of level texts of the rows drawn
        self.order = {}         # legend label -> (group, rank)
        self.extra = []         # (group, rank, handle, label) legend proxies
        self.slot = {}          # series index -> (position, number) among the series drawn
        self.rows = {}          # axes -> number of marker rows stacked so far

    def present(self, series):
        """The series drawn in this figure: their side-by-side positions."""
        idx = sorted({s.index for s in series})
        self.slot = {i: (k, len(idx)) for k, i in enumerate(idx)}

    def shift(self, ax, s, spread=SERIES_SPREAD_PT):
        """Transform that draws series s a few points left/right of the other series drawn."""
        k, n = self.slot.get(s.index, (0, 1))
        dx = (k - (n - 1) / 2.0) * spread
        if not self.run.multi or n <= 1 or dx == 0:
            return ax.transData
        return offset_copy(ax.transData, fig=ax.figure, x=dx, units="points")

    def stack(self, ax, s, step=6.5):
        """Transform that puts the markers of series s in their own row below those of the
        series stacked before it in this axes (called once per series and axes)."""
        k = self.rows.get(ax, 0)
        self.rows[ax] = k + 1
        if not self.run.multi or k == 0:
            return ax.transData
        return offset_copy(ax.transData, fig=ax.figure, y=-step * k, units="points")

    def label(self, s, legacy, suffix="", rank=0):
        """Legend label: the original one for the single-DIR form, else LABEL+suffix."""
        if s.label is None:
            return legacy
        text = s.label + suffix
        self.order[text] = (1 + s.index, rank)
        return text

    def use(self, s, rows, tube=False):
        """Record that rows of series s are drawn (for the footer's level)."""
        lv = self.used.setdefault(s.index, set())
        for r in rows:
            t = level_text(r.get("level", ""))
            if t is None:
                meta = s.meta.get(r.get(SRC, ""))
                if isinstance(meta, dict):
                    val = meta.get("tube_level") if tube else None
                    val = val if val not in (None, "") else meta.get("level")
                    t = level_text(val) if val not in (None, "") else None
            if t is not None:
                lv.add(t)

    def subtitle(self):
        drawn = [s for s in self.run.series if s.index in self.used]
        if not drawn:
            return None
        levels = set().union(*(self.used[s.index] for s in drawn))
        if len(levels) <= 1:
            text = " vs ".join(s.label for s in drawn)
            return f"{text}; level {next(iter(levels))}" if levels else text
        parts = []
        for s in drawn:
            lv = sorted(self.used[s.index], key=lambda t: (fnum(t) is None, fnum(t) or 0, t))
            if len(lv) == 1:
                parts.append(f"{s.label} (level {lv[0]})")
            elif lv:
                parts.append(f"{s.label} (levels {', '.join(lv)})")
            else:
                parts.append(s.label)
        return " vs ".join(parts)


def anchor(ax, run, x, y):
    """--series form: artists drawn with a shifted transform do not count for the axis limits;
    an invisible copy in data coordinates does."""
    if run.multi and len(x):
        ax.plot(x, y, ls="none", marker="none")


def tkw(run, tr):
    """transform= keyword for the --series form (nothing for the single-DIR form)."""
    return {"transform": tr} if run.multi else {}


def band_points(s, kind, observable, xcol, eta=None):
    """(x, median, q05, q95, q05 MC error, q95 MC error) of the bands.csv rows of series s with a
    band (--draws); the errors are None in tables without them."""
    out = []
    for r in s.bands:
        if r.get("kind") != kind or r.get("observable") != observable:
            continue
        if eta is not None and eta_key(fnum(r.get("eta_out_mPa_s")) or 0.0) != eta_key(eta):
            continue
        x, m, lo, hi = (fnum(r.get(c)) for c in (xcol, "median", "q05", "q95"))
        if None not in (x, m, lo, hi):
            out.append((x, m, lo, hi, fnum(r.get("q05_mcse")), fnum(r.get("q95_mcse"))))
    return sorted(out)


def draw_bands(ax, run, s, ctx, pts, colour, what="draws"):
    """The 5-95 % band of each case over the posterior draws (pale bar), its median, and the
    Monte Carlo error of the band's ends (thin whiskers) where bands.csv has it."""
    if not pts:
        return
    x = np.array([p[0] for p in pts])
    m = np.array([p[1] for p in pts])
    lo = np.array([p[2] for p in pts])
    hi = np.array([p[3] for p in pts])
    # a few points right of the case's own marker, so that neither hides the other
    tr = offset_copy(ctx.shift(ax, s), fig=ax.figure, x=BAND_OFFSET_PT, units="points")
    ax.errorbar(x, m, yerr=[m - lo, hi - m], ls="none", marker=s.marker, ms=5, mfc="white",
                mec=colour, ecolor=colour, elinewidth=5, alpha=0.35, capsize=0, zorder=3,
                label=ctx.label(s, f"posterior {what}: median, 5-95 % band",
                                f": posterior {what}, median and 5-95 % band", 3),
                transform=tr)
    ax.plot(np.r_[x, x], np.r_[lo, hi], ls="none", marker="none")  # the band inside the limits
    ends = [(p[0], end, err) for p in pts if len(p) > 5 for end, err in ((p[2], p[4]), (p[3], p[5]))
            if err is not None and err > 0]
    if ends:
        ex, ey, ee = (np.array(c) for c in zip(*ends))
        ax.errorbar(ex, ey, yerr=ee, ls="none", marker="none", ecolor=colour, elinewidth=0.8, capsize=2,
                    alpha=0.8, zorder=3, transform=tr,
                    label=ctx.label(s, f"Monte Carlo error of the band's ends ({what})",
                                    ": MC error of the band's ends", 4))


def legend_below(fig, ctx, sub):
    """--series form: one legend for the whole figure below the axes (one column per source
    where it fits), the footer under it; the figure grows by the legend's height."""
    hs, ls, keys = [], [], []
    for ax in fig.axes:
        if not ax.get_visible():
            continue
        for h, lab in zip(*ax.get_legend_handles_labels()):
            if lab and lab not in ls:
                hs.append(h)
                ls.append(lab)
                keys.append(ctx.order.get(lab, (0, 0)))
    for group, rank, h, lab in ctx.extra:
        hs.append(h)
        ls.append(lab)
        keys.append((group, rank))
    idx = sorted(range(len(ls)), key=lambda i: (keys[i], i))
    groups = {}
    for i in idx:
        groups.setdefault(keys[i][0], []).append(i)
    w, h0 = fig.get_size_inches()
    foot = 0.035 * h0 if sub else 0.0  # inches, as the single-DIR form
    if not ls:
        if sub:
            fig.text(0.5, 0.005, sub, ha="center", va="bottom", fontsize=7, color="0.3")
        fig.tight_layout(rect=(0, foot / h0, 1, 1))
        return
    renderer = fig.canvas.get_renderer()

    glist = list(groups.values())  # the groups in legend order

    def columns(ncol):
        """The groups, in order and each kept whole, split into ncol columns of fewest rows."""
        best = None
        for cuts in itertools.combinations(range(1, len(glist)), ncol - 1):
            bounds = (0,) + cuts + (len(glist),)
            cols = [sum(glist[i:j], []) for i, j in zip(bounds, bounds[1:])]
            rows = max(len(c) for c in cols)
            if best is None or rows < best[0]:
                best = (rows, cols)
        return best[1]

    def make(cols):  # column-major, short columns padded with blank entries
        nrow = max(len(c) for c in cols)
        H, L = [], []
        for c in cols:
            H += [hs[i] for i in c] + [Line2D([], [], ls="none", marker="none")] * (nrow - len(c))
            L += [ls[i] for i in c] + [""] * (nrow - len(c))
        return fig.legend(H, L, loc="lower center", ncol=len(cols), frameon=False,
                          columnspacing=1.4, handletextpad=0.5, borderaxespad=0.2)

    leg = None
    for ncol in range(len(glist), 0, -1):
        if leg is not None:
            leg.remove()
        leg = make(columns(ncol))
        if leg.get_window_extent(renderer).width <= 0.98 * fig.bbox.width:
            break
    lh = leg.get_window_extent(renderer).height / fig.dpi
    H = h0 + lh + 0.05
    fig.set_size_inches(w, H)
    leg.set_bbox_to_anchor((0.5, (foot + 0.02) / H), transform=fig.transFigure)
    if sub:
        fig.text(0.5, 0.005 * h0 / H, sub, ha="center", va="bottom", fontsize=7, color="0.3")
    fig.tight_layout(rect=(0, (foot + lh + 0.06) / H, 1, 1))


def finish(fig, name, ctx):
    run = ctx.run
    path = run.figdir / name
    if run.multi:
        legend_below(fig, ctx, ctx.subtitle())
    elif run.sub:
        fig.text(0.5, 0.005, run.sub, ha="center", va="bottom", fontsize=7, color="0.3")
        fig.tight_layout(rect=(0, 0.035, 1, 1))
    else:
        fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)  # created only when a figure exists
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    run.written.append(path)
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


def plot_angle(run):
    ctx = FigCtx(run)
    by_eta = {}  # eta_key -> (eta, {series index: rows})
    for s in run.series:
        for r in ok_rows(s.shear):
            if r.get("sweep", "").strip().lower() != "angle":
                continue
            eta = fnum(r.get("eta_out_mPa_s"))
            g = fnum(r.get("shear_rate_per_s"))
            if eta is None or g is None or g <= 0:
                continue
            by_eta.setdefault(eta_key(eta), (eta, {}))[1].setdefault(s.index, []).append(r)
    if not by_eta:
        note("no usable angle-sweep rows in shear.csv: skipping angle_vs_shear_rate.png")
        return
    ctx.present([s for s in run.series if any(s.index in per for _, per in by_eta.values())])
    angle_sets = sets_of(run, "inclination_deg")
    etas = sorted(by_eta.values(), key=lambda t: t[0])
    n = len(etas)
    ncol = min(n, 2)
    nrow = int(math.ceil(n / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.4 * ncol, 3.5 * nrow), squeeze=False)
    for ax in axes.flat[n:]:
        ax.set_visible(False)

    for k, ((eta, per), ax) in enumerate(zip(etas, axes.flat)):
        xs_all = []
        # experiment
        here = [(d, x, y) for d, x, y in angle_sets if eta_key(d["eta_out_mPa_s"]) == eta_key(eta)]
        for d, x, y in here:
            first = True
            for c in range(y.shape[1]):  # one column per donor
                m = np.isfinite(y[:, c])
                if m.any():
                    ax.plot(x[m], y[m, c], ls="none", marker="o", ms=3.2, mfc="none", mec=C_EXP, mew=0.8,
                            label=(f"{d['source']} (donors)" if first else None))
                    first = False
                    xs_all += list(x[m])
        if not here and run.sets:
            note(f"no experimental angles at eta = {eta:g} mPa s")
        for s in run.series:
            rs = per.get(s.index)
            if not rs:
                continue
            ctx.use(s, rs)
            col = s.colour if run.multi else PANEL_COLOURS[k % len(PANEL_COLOURS)]
            tr = ctx.shift(ax, s)
            # simulation: tank-treading (or unclassified) rows with an angle
            tt = []
            tb = []
            im = []  # intermittent without an angle: drawn on the axis, as the tumbling ones
            other = []
            for r in rs:
                g = fnum(r["shear_rate_per_s"])
                reg = r.get("regime", "").strip().lower()
                th = fnum(r.get("inclination_deg"))
                if reg == "tumbling":
                    tb.append(g)
                elif th is None:
                    if reg == "intermittent":
                        im.append(g)
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
                ax.errorbar(g, th, yerr=err, color=col, marker=s.marker, ms=4, lw=1.3,
                            capsize=2.5, elinewidth=0.9, ls=s.ls,
                            label=ctx.label(s, "simulation (error bar: swing amplitude)",
                                            " (error bar: swing amplitude)", 0),
                            zorder=5, **tkw(run, tr))
                anchor(ax, run, np.r_[g, g], np.r_[th - err, th + err])
                xs_all += list(g)
            if other:
                g = np.array([t[0] for t in other])
                th = np.array([t[1] for t in other])
                err = np.array([abs(t[2]) if t[2] is not None else 0.0 for t in other])
                st = REGIME_STYLE["intermittent"]
                ax.errorbar(g, th, yerr=err, color=st[0], marker=(s.marker if run.multi else st[1]),
                            ms=4, ls="none", capsize=2.5, elinewidth=0.9,
                            label=ctx.label(s, "simulation, intermittent", ": intermittent", 1),
                            zorder=5, **tkw(run, tr))
                anchor(ax, run, np.r_[g, g], np.r_[th - err, th + err])
                xs_all += list(g)
            row = ctx.stack(ax, s) if tb or im else None
            if tb:
                ax.plot(tb, np.zeros(len(tb)), ls="none", marker="x", ms=7, mew=1.6,
                        color=(s.colour if run.multi else REGIME_STYLE["tumbling"][0]),
                        label=ctx.label(s, "simulation: tumbling (no angle)",
                                        ": tumbling (no angle)", 2),
                        zorder=6, clip_on=False, **tkw(run, row))
                anchor(ax, run, tb, np.zeros(len(tb)))
                xs_all += tb
            if im:
                st = REGIME_STYLE["intermittent"]
                ax.plot(im, np.zeros(len(im)), ls="none", marker=st[1], ms=5, mfc="none", mew=1.4,
                        color=(s.colour if run.multi else st[0]),
                        label=ctx.label(s, "simulation: intermittent (no angle)",
                                        ": intermittent (no angle)", 3),
                        zorder=6, clip_on=False, **tkw(run, row))
                anchor(ax, run, im, np.zeros(len(im)))
                xs_all += im
        for s in run.series:
            pts = band_points(s, "angle", "inclination [deg]", "shear_rate_per_s", eta)
            draw_bands(ax, run, s, ctx, pts, s.colour if run.multi else PANEL_COLOURS[k % len(PANEL_COLOURS)])
            xs_all += [p[0] for p in pts]
        if xs_all and min(xs_all) > 0:  # shear rates span decades (docs/FLOW.md, shear)
            ax.set_xscale("log")
        ax.axhline(0, color="0.8", lw=0.6, zorder=0)
        ax.set_xlabel(r"shear rate $\dot\gamma$ [1/s]")
        ax.set_ylabel("inclination angle [deg]")
        ax.set_title(rf"$\eta_o$ = {eta:g} mPa s")
        lo, hi = ax.get_ylim()
        ax.set_ylim(min(lo, -2.0), max(hi, 5.0))
        if not run.multi:
            ax.legend(loc="best", frameon=False)
    finish(fig, "angle_vs_shear_rate.png", ctx)


def plot_ttf(run):
    ctx = FigCtx(run)
    per = []  # (series, points, tumbling rates, etas, rows used)
    for s in run.series:
        rows = [r for r in ok_rows(s.shear) if r.get("sweep", "").strip().lower() == "ttf"]
        pts = []
        tumbling = []
        etas = set()
        used = []
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
                    used.append(r)
                continue
            pts.append((g, f))
            used.append(r)
        if pts or tumbling:
            per.append((s, pts, tumbling, etas, used))
    if not per:
        note("no usable ttf-sweep rows in shear.csv: skipping ttf_vs_shear_rate.png")
        return
    ctx.present([p[0] for p in per])
    fig, ax = plt.subplots(figsize=(5.0, 3.7))
    xs = []
    for d, x, y in sets_of(run, "ttf_4pi_f_over_rate"):  # already 4 pi f / rate
        m = np.isfinite(y[:, 0])
        eta = d["eta_out_mPa_s"]
        ax.plot(x[m], y[m, 0], ls="none", marker="o", ms=3, mfc="none", mec=C_EXP, mew=0.7,
                label=d["source"] + (rf" ($\eta_o$ = {eta:g} mPa s)" if eta is not None else ""))
        xs += list(x[m])
    for s, pts, tumbling, etas, used in per:
        ctx.use(s, used)
        if pts:
            pts.sort()
            g = np.array([p[0] for p in pts])
            f = np.array([p[1] for p in pts])
            eta_txt = ", ".join(f"{e:g}" for e in sorted(etas))
            eta_lab = rf" ($\eta_o$ = {eta_txt} mPa s)" if eta_txt else ""
            ax.plot(g, f, color=(s.colour if run.multi else C_SIM), marker=s.marker, ms=4.5,
                    lw=1.4, ls=s.ls, label=ctx.label(s, "simulation" + eta_lab, eta_lab, 0),
                    zorder=5, **tkw(run, ctx.shift(ax, s)))
            anchor(ax, run, g, f)
            xs += list(g)
        if tumbling:
            ax.plot(tumbling, np.zeros(len(tumbling)), ls="none", marker="x", ms=7, mew=1.6,
                    color=(s.colour if run.multi else REGIME_STYLE["tumbling"][0]),
                    label=ctx.label(s, "simulation: tumbling (no TTF)", ": tumbling (no TTF)", 2),
                    clip_on=False, zorder=6, **tkw(run, ctx.stack(ax, s)))
            anchor(ax, run, tumbling, np.zeros(len(tumbling)))
            xs += tumbling
    for s in run.series:
        pts = band_points(s, "ttf", "4 pi f / rate", "shear_rate_per_s")
        draw_bands(ax, run, s, ctx, pts, s.colour if run.multi else C_SIM)
        xs += [p[0] for p in pts]
    if xs and min(xs) > 0:
        ax.set_xscale("log")
    ax.set_ylim(bottom=0)
    ax.set_xlabel(r"shear rate $\dot\gamma$ [1/s]")
    ax.set_ylabel(r"$4\pi f/\dot\gamma$")
    ax.set_title("Tank-treading frequency")
    if not run.multi:
        ax.legend(loc="best", frameon=False)
    finish(fig, "ttf_vs_shear_rate.png", ctx)


def threshold_data(s):
    """(brackets [(eta, lo, hi)], cases {regime: [(eta, tau)]}, rows used) of series s."""
    brackets = []
    used = []
    for r in s.threshold:
        eta = fnum(r.get("eta_out_mPa_s"))
        if eta is None or eta <= 0:
            continue
        lo = fnum(r.get("tau_lo_Pa"))
        hi = fnum(r.get("tau_hi_Pa"))
        if lo is not None and lo <= 0:
            lo = None
        if hi is not None and hi <= 0:
            hi = None
        if lo is None and hi is None:
            continue
        brackets.append((eta, lo, hi))
        used.append(r)
    # sweep cases
    cases = {}
    for r in ok_rows(s.shear):
        if r.get("sweep", "").strip().lower() != "threshold":
            continue
        eta = fnum(r.get("eta_out_mPa_s"))
        tau = fnum(r.get("shear_stress_Pa"))
        reg = r.get("regime", "").strip().lower() or "empty"
        if eta is None or tau is None or tau <= 0 or eta <= 0:
            continue
        cases.setdefault(reg if reg in REGIME_STYLE else "empty", []).append((eta, tau))
        used.append(r)
    return brackets, cases, used


def plot_threshold(run):
    ctx = FigCtx(run)
    per = []
    for s in run.series:
        brackets, cases, used = threshold_data(s)
        if brackets or cases:
            per.append((s, brackets, cases, used))
    if not per:
        note("no usable rows in threshold.csv or threshold-sweep rows in shear.csv: "
             "skipping critical_stress_vs_eta.png")
        return

    ctx.present([p[0] for p in per])
    fig, ax = plt.subplots(figsize=(7.6, 4.0))
    for (d, x, y), (mk, col) in zip(sets_of(run, "critical_stress_Pa"), itertools.cycle((("o", C_EXP), ("^", C_EXP2)))):
        m = np.isfinite(y[:, 0]) & (y[:, 0] > 0)
        ax.plot(x[m], y[m, 0], ls="none", marker=mk, ms=5.5, mfc="none", mec=col, mew=1.1, label=d["source"], zorder=4)

    # sweep, lightly (--series: regime colour, series marker, shifted with the series' bracket)
    spread = 9.0
    regimes_drawn = []
    for s, brackets, cases, used in per:
        ctx.use(s, used)
        for reg in ("tank-treading", "tumbling", "intermittent", "empty"):
            if reg not in cases:
                continue
            col, mk, lab = REGIME_STYLE[reg]
            e = np.array([c[0] for c in cases[reg]])
            t = np.array([c[1] for c in cases[reg]])
            if run.multi:
                ax.plot(e, t, ls="none", marker=s.marker, ms=4.2, color=col, alpha=0.6,
                        mfc="none", mew=1.0, zorder=2, transform=ctx.shift(ax, s, spread))
                anchor(ax, run, e, t)
                if reg not in regimes_drawn:
                    regimes_drawn.append(reg)
            else:
                ax.plot(e, t, ls="none", marker=mk, ms=4, color=col, alpha=0.45,
                        mfc=("none" if mk in "oD" else col), label=f"simulated case: {lab}",
                        zorder=2)
        if run.multi and cases:
            ctx.extra.append((1 + s.index, 2,
                              Line2D([], [], ls="none", marker=s.marker, ms=4.2, mfc="none",
                                     mec="0.35", mew=1.0),
                              f"{s.label}: sweep cases"))
    for reg in regimes_drawn:
        col, mk, lab = REGIME_STYLE[reg]
        ctx.extra.append((1000, 0, Patch(facecolor=col, alpha=0.6, edgecolor="none"),
                          f"case regime: {lab}"))

    # brackets
    for s, brackets, cases, used in per:
        col = s.colour if run.multi else C_SIM
        tr = ctx.shift(ax, s, spread)
        first_iv = first_one = True
        for eta, lo, hi in sorted(brackets):
            if lo is not None and hi is not None:
                a, b = min(lo, hi), max(lo, hi)
                mid = math.sqrt(a * b)
                ax.errorbar([eta], [mid], yerr=[[mid - a], [b - mid]], color=col, marker=s.marker,
                            ms=5, capsize=4, elinewidth=2.0, lw=0, zorder=6,
                            label=(ctx.label(s, r"simulation: $[\eta_o\dot\gamma_{lo}, "
                                               r"\eta_o\dot\gamma_{hi}]$",
                                             r": $[\eta_o\dot\gamma_{lo}, \eta_o\dot\gamma_{hi}]$",
                                             0)
                                   if first_iv else None), **tkw(run, tr))
                anchor(ax, run, [eta, eta], [a, b])
                first_iv = False
            else:
                # one-sided: lo only -> threshold above lo (arrow up); hi only -> below hi (down)
                val = lo if lo is not None else hi
                mk = r"$\uparrow$" if lo is not None else r"$\downarrow$"
                ax.plot([eta], [val], ls="none", marker="_", ms=10, mew=2.0, color=col, zorder=6,
                        **tkw(run, tr))
                anchor(ax, run, [eta], [val])
                tip = val * (1.8 if lo is not None else 1 / 1.8)
                if run.multi:
                    ax.annotate("", xy=(eta, tip), xytext=(eta, val), xycoords=tr, textcoords=tr,
                                arrowprops=dict(arrowstyle="->", color=col, lw=1.6), zorder=6)
                else:
                    ax.annotate("", xy=(eta, tip), xytext=(eta, val),
                                arrowprops=dict(arrowstyle="->", color=col, lw=1.6), zorder=6)
                ax.plot([eta], [tip], ls="none", marker="none")  # keep the arrow inside the limits
                ax.plot([], [], ls="none", marker=mk, color=col, ms=8,
                        label=(ctx.label(s, "simulation: one bound only (arrow towards threshold)",
                                         ": one bound only (arrow towards threshold)", 1)
                               if first_one else None))
                first_one = False
    for s in run.series:
        draw_bands(ax, run, s, ctx, band_points(s, "threshold", "critical stress [Pa]", "eta_out_mPa_s"),
                   s.colour if run.multi else C_SIM, "draws, sqrt(tau_lo tau_hi)")
    ax.set_yscale("log")
    all_eta = ([b[0] for p in per for b in p[1]]
               + [c[0] for p in per for v in p[2].values() for c in v])
    if use_log(all_eta + [10.7, 104.0], ratio=8.0):
        ax.set_xscale("log")
    ax.set_xlabel(r"outer viscosity $\eta_o$ [mPa s]")
    ax.set_ylabel(r"critical shear stress $\eta_o\dot\gamma$ [Pa]")
    ax.set_title("Tumbling / tank-treading threshold")
    if not run.multi:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    finish(fig, "critical_stress_vs_eta.png", ctx)


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


def radii_text(tube):
    rs = sorted({fnum(r.get("radius_um")) for r in ok_rows(tube)
                 if fnum(r.get("radius_um")) is not None})
    return " (R = " + ", ".join(f"{x:g}" for x in rs) + " µm)" if rs else ""


def radii_label(tube):
    return "simulation" + radii_text(tube)


def draw_tube_sim(ax, pts, s, ctx):
    run = ctx.run
    col = s.colour if run.multi else C_SIM
    # --series: no shift (the pressure gradients are the same, the velocities almost so);
    # earlier series get bigger markers, so that the later ones drawn on top leave them visible
    tr = ctx.shift(ax, s, spread=0.0)
    k, n = ctx.slot.get(s.index, (0, 1))
    ms = 4.5 + (1.6 * (n - 1 - k) / (n - 1) if run.multi and n > 1 else 0.0)
    x = np.array([p[0] for p in pts])
    y = np.array([p[1] for p in pts])
    pl = np.array([p[2] for p in pts], dtype=bool)
    ax.plot(x, y, color=col, lw=1.3, ls=s.ls, marker=s.marker, ms=ms, markevery=list(pl), zorder=4,
            label=ctx.label(s, radii_label(s.tube), radii_text(s.tube), 0), **tkw(run, tr))
    anchor(ax, run, x, y)
    if (~pl).any():
        ax.plot(x[~pl], y[~pl], ls="none", marker=s.marker, ms=ms + 0.5, mfc="white", mec=col,
                mew=1.2, zorder=5, label=ctx.label(s, "simulation, no plateau reached (open)",
                                          ", no plateau reached (open)", 1), **tkw(run, tr))


def plot_tube_v_pg(run):
    ctx = FigCtx(run)
    per = [(s, tube_points(s.tube, "pg_mmHg_per_mm", "velocity_cm_per_s")) for s in run.series]
    per = [(s, pts) for s, pts in per if pts]
    if not per:
        note("no usable rows in tube.csv: skipping tube_velocity_vs_pg.png")
        return
    ctx.present([p[0] for p in per])
    fig, ax = plt.subplots(figsize=(5.0, 3.7))
    for d, x, y in sets_of(run, "velocity_cm_per_s"):
        m = np.isfinite(y[:, 0])
        ax.plot(x[m], y[m, 0], ls="none", marker="o", ms=3.5, mfc="none", mec=C_EXP, mew=0.9, label=d["source"])
    for s, pts in per:
        ctx.use(s, [r for r in ok_rows(s.tube) if fnum(r.get("pg_mmHg_per_mm")) is not None
                    and fnum(r.get("velocity_cm_per_s")) is not None], tube=True)
        draw_tube_sim(ax, pts, s, ctx)
    for s in run.series:
        draw_bands(ax, run, s, ctx, band_points(s, "tube", "velocity [cm/s]", "pg_mmHg_per_mm"),
                   s.colour if run.multi else C_SIM)
    ax.set_xlim(left=0)
    ax.set_ylim(bottom=0)
    ax.set_xlabel(r"pressure gradient $\Delta P/L$ [mmHg/mm]")
    ax.set_ylabel("cell velocity [cm/s]")
    ax.set_title("Microtube: velocity vs pressure gradient")
    if not run.multi:
        ax.legend(loc="best", frameon=False)
    finish(fig, "tube_velocity_vs_pg.png", ctx)


def plot_tube_l_v(run):
    ctx = FigCtx(run)
    per = [(s, tube_points(s.tube, "velocity_cm_per_s", "length_um")) for s in run.series]
    per = [(s, pts) for s, pts in per if pts]
    if not per:
        note("no usable rows in tube.csv (length, velocity): skipping tube_length_vs_velocity.png")
        return
    ctx.present([p[0] for p in per])
    fig, ax = plt.subplots(figsize=(5.0, 3.7))
    xs = [p[0] for s, pts in per for p in pts]
    for d, x, y in sets_of(run, "length_um"):  # velocities already in cm/s
        m = np.isfinite(y[:, 0])
        if d["y_columns"][1:] == ["l_high", "l_low"]:  # the judged band: value with its high and low ends
            lo = np.where(np.isfinite(y[:, 2]), y[:, 0] - y[:, 2], 0.0)[m]
            hi = np.where(np.isfinite(y[:, 1]), y[:, 1] - y[:, 0], 0.0)[m]
            ax.errorbar(x[m], y[m, 0], yerr=[np.abs(lo), np.abs(hi)], ls="none", marker="o", ms=4, mfc="none", mec=C_EXP,
                        ecolor=C_EXP, mew=1.0, capsize=2.5, elinewidth=0.8, label=d["source"])
        else:
            ax.plot(x[m], y[m, 0], ls="none", marker="^", ms=4, mfc="none", mec=C_EXP2, mew=0.9, label=d["source"])
        xs += list(x[m])
    for s, pts in per:
        ctx.use(s, [r for r in ok_rows(s.tube) if fnum(r.get("velocity_cm_per_s")) is not None
                    and fnum(r.get("length_um")) is not None], tube=True)
        draw_tube_sim(ax, pts, s, ctx)
    for s in run.series:  # at the median velocity of the case's draws
        velocity = {r.get("case"): fnum(r.get("median")) for r in s.bands
                    if r.get("observable") == "velocity [cm/s]"}
        pts = [(velocity[r.get("case")], fnum(r.get("median")), fnum(r.get("q05")), fnum(r.get("q95")),
                fnum(r.get("q05_mcse")), fnum(r.get("q95_mcse")))
               for r in s.bands if r.get("observable") == "length [um]"
               and velocity.get(r.get("case")) is not None and fnum(r.get("median")) is not None]
        draw_bands(ax, run, s, ctx, sorted(pts), s.colour if run.multi else C_SIM)
        xs += [p[0] for p in pts]
    if use_log(xs, ratio=30.0):
        ax.set_xscale("log")
    else:
        ax.set_xlim(left=0)
    ax.set_xlabel("cell velocity [cm/s]")
    ax.set_ylabel(r"cell length $l$ [$\mu$m]")
    ax.set_title("Microtube: cell length vs velocity")
    if not run.multi:
        ax.legend(loc="best", frameon=False)
    finish(fig, "tube_length_vs_velocity.png", ctx)


# --------------------------------------------------------------------------------------------

USAGE = ("%(prog)s DIR [--data EXPDIR] [--out FIGDIR]\n"
         "       %(prog)s --series LABEL DIR [DIR ...] [--series LABEL DIR [DIR ...] ...] "
         "--out FIGDIR [--data EXPDIR]")


def parse_args(argv):
    ap = argparse.ArgumentParser(
        usage=USAGE,
        description="Plot `trbc validate` outputs (shear.csv, threshold.csv, tube.csv) against "
                    "the flow-validation experiments (docs/VALIDATE.md); with "
                    "--series, several labelled result sets on the same figures.")
    ap.add_argument("dir", metavar="DIR", nargs="?", default=None,
                    help="output directory of `trbc validate` (single-directory form)")
    ap.add_argument("--series", metavar=("LABEL", "DIR"), nargs="+", action="append", default=None,
                    help="a labelled result set: LABEL, then one or more `trbc validate` output "
                         "directories whose rows are concatenated (e.g. the angle, ttf, threshold "
                         "and tube runs of one cell); repeat for each set; replaces DIR")
    ap.add_argument("--data", metavar="EXPDIR", default=str(DEFAULT_DATA),
                    help="experimental validation data (default: %(default)s)")
    ap.add_argument("--out", metavar="FIGDIR", default=None,
                    help="where to write the PNG figures (default: DIR/figures; required with "
                         "--series)")
    args = ap.parse_args(argv)
    if args.series is not None:
        if args.dir is not None:
            ap.error(f"DIR ({args.dir}) cannot be combined with --series: give every directory "
                     "inside a --series LABEL DIR... group")
        labels = set()
        for grp in args.series:
            if len(grp) < 2:
                ap.error(f"--series {grp[0]!r}: a LABEL and at least one DIR are needed")
            if not grp[0].strip():
                ap.error("--series: the LABEL must not be empty")
            if grp[0] in labels:
                ap.error(f"--series: label {grp[0]!r} is given twice")
            labels.add(grp[0])
        if args.out is None:
            ap.error("--out FIGDIR is required with --series")
    elif args.dir is None:
        ap.error("a DIR or at least one --series LABEL DIR [DIR ...] is required")
    return args


def main(argv=None):
    args = parse_args(argv)
    data = Path(args.data)

    if args.series is None:  # single-directory form (called by `trbc validate`)
        d = Path(args.dir)
        if not d.is_dir():
            note(f"error: validate output directory does not exist: {d}")
            return 2
        if not data.is_dir():
            note(f"warning: experimental data directory not found: {data} "
                 "(figures are drawn without experimental points)")
        figdir = Path(args.out) if args.out else d / "figures"

        shear = read_rows(d / "shear.csv")
        threshold = read_rows(d / "threshold.csv")
        tube = read_rows(d / "tube.csv")
        for name, rows in (("shear.csv", shear), ("threshold.csv", threshold),
                           ("tube.csv", tube)):
            if not rows:
                note(f"{name}: missing or no data rows in {d}")
        if not shear and not threshold and not tube:
            note("nothing to plot")
            return 0
        s = Series(None, [d])
        s.shear, s.threshold, s.tube = shear, threshold, tube
        s.bands = read_rows(d / "bands.csv")
        run = Run([s], data, figdir, sub=subtitle(read_json(d / "validation.json")))
    else:  # --series form
        missing = [d for grp in args.series for d in grp[1:] if not Path(d).is_dir()]
        for d in missing:
            note(f"error: validate output directory does not exist: {d}")
        if missing:
            return 2
        if not data.is_dir():
            note(f"warning: experimental data directory not found: {data} "
                 "(figures are drawn without experimental points)")
        for grp in args.series:
            if Path(grp[0]).is_dir():
                note(f"warning: series label {grp[0]!r} is also a directory; it is used as the "
                     "label (--series LABEL DIR [DIR ...])")
        series = [Series(grp[0], grp[1:], index=i, count=len(args.series))
                  for i, grp in enumerate(args.series)]
        for s in series:
            s.load()
        if not any(s.shear or s.threshold or s.tube for s in series):
            note("nothing to plot")
            return 0
        run = Run(series, data, Path(args.out))

    for fn in (plot_angle, plot_ttf, plot_threshold, plot_tube_v_pg, plot_tube_l_v):
        try:
            fn(run)
        except OSError as e:  # e.g. FIGDIR cannot be created or written
            plt.close("all")
            note(f"error: cannot write figure to {run.figdir}: {e}")
            return 2
        except Exception as e:  # one broken figure must not prevent the others
            plt.close("all")
            note(f"error while drawing {fn.__name__}: {type(e).__name__}: {e}")
    if not run.written:
        note("nothing to plot")
    return 0


if __name__ == "__main__":
    sys.exit(main())
