#!/usr/bin/python3
"""Plot the learning curve of the flow networks (docs/FLOW_NETWORKS.md) from the training.json of
`trbc flow train --learning-curve N1,N2,... --folds K`.

Three panels against the number of finest-level cases: the cross-validated angle RMSE (deg), the
TTF RMSE (%) and the regime misclassified far from the boundary (%), each with its goal (the
training's "goals") and a line of slope -1/2 through the last point, the rate at which the
error of a fixed model falls with the data. The campaign's own uncertainty (RMS of the rows'
standard errors) is drawn where it is recorded: no network can fit the data better than that.

Usage:
  scripts/plot_flow_learning_curve.py TRAINING_JSON [TRAINING_JSON ...] [--label L ...] --out PNG

Several trainings (e.g. level 3 alone and levels 2 and 3) are drawn side by side, labelled by
--label (default: the folder of each file).
"""
import argparse
import json
import sys
from pathlib import Path

import numpy as np
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import plot_style  # noqa: E402

PANELS = [("inclination_rmse_deg", "campaign_inclination_se_rms_deg", "inclination_rmse_deg", 1.0, "angle RMSE (deg)"),
          ("ttf_relative_rmse", "campaign_ttf_relative_se_rms", "ttf_relative_rmse", 100.0, "TTF RMSE (%)"),
          ("far_misclassified", None, "far_misclassified_fraction", 100.0, "misclassified far from the boundary (%)")]


def points(training):
    """(cases, pooled accuracy) of the learning curve, then the full cross-validation."""
    pts = [(p["cases"], p["pooled"]) for p in training.get("learning_curve", [])]
    cv = training.get("cross_validation")
    if cv and (not pts or cv["pooled"]["cases"] > pts[-1][0]):
        pts.append((cv["pooled"]["cases"], cv["pooled"]))
    return pts


def value(acc, key):
    if key == "far_misclassified":
        return acc["far_misclassified"] / acc["far_cases"] if acc.get("far_cases") else np.nan
    v = acc.get(key)
    return np.nan if v is None else v


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("training", nargs="+")
    ap.add_argument("--label", action="append")
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    if a.label and len(a.label) != len(a.training):
        ap.error(f"--label given {len(a.label)} times for {len(a.training)} trainings")
    runs = []
    for k, f in enumerate(a.training):
        try:
            t = json.loads(Path(f).read_text())
        except (OSError, ValueError) as e:
            print(f"plot_flow_learning_curve: error: cannot read {f}: {e}", file=sys.stderr)
            return 2
        try:
            pts = points(t)
            for _, acc in pts:
                for key, noise_key, _, _, _ in PANELS:
                    value(acc, key), noise_key and value(acc, noise_key)
        except (KeyError, TypeError, AttributeError) as e:
            print(f"plot_flow_learning_curve: error: {f} is not the training.json of `trbc flow train` (missing {e})",
                  file=sys.stderr)
            return 2
        if not pts:
            print(f"plot_flow_learning_curve: error: {f} has no learning curve or cross-validation", file=sys.stderr)
            return 2
        runs.append((a.label[k] if a.label else Path(f).resolve().parent.name, t, pts))

    plot_style.apply()
    fig, axes = plt.subplots(1, 3, figsize=(10.5, 3.2))
    for (key, noise_key, goal_key, scale, ylabel), ax in zip(PANELS, axes):
        for (label, t, pts), marker in zip(runs, "osD^v"):
            n = np.array([p[0] for p in pts], float)
            y = scale * np.array([value(p[1], key) for p in pts])
            line, = ax.loglog(n, y, marker=marker, ms=4, label=label)
            if np.isfinite(y[-1]):
                ref = np.array([n[0], 1e5])
                ax.loglog(ref, y[-1] * np.sqrt(n[-1] / ref), ls=":", lw=0.8, color=line.get_color())
            if noise_key:
                noise = scale * np.array([value(p[1], noise_key) for p in pts])
                ax.loglog(n, noise, ls="--", lw=0.8, color=line.get_color(), alpha=0.7)
        goal = runs[0][1].get("goals", {}).get(goal_key)
        if goal is not None:
            ax.axhline(scale * goal, color="k", lw=0.9)
            ax.text(1.0, scale * goal, " goal", transform=ax.get_yaxis_transform(), va="center", fontsize=7)
        ax.set_xlim(20, 3e4)
        ax.set_xlabel("finest-level cases")
        ax.set_ylabel(ylabel)
    axes[0].legend(frameon=False, fontsize=7)
    fig.suptitle("Flow networks, cross-validated: solid measured, dotted slope -1/2, dashed the campaign's own uncertainty",
                 fontsize=8)
    fig.tight_layout()
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(a.out, dpi=150)
    print(a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
