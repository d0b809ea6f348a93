"""trbc from Python in a few steps: the surrogate and the direct forward model against the Mills
(2004) optical-tweezers stretching data, and the phase-1 posterior of that data set as a corner plot.

    make python                                   # once: builds and installs the package in .venv
    .venv/bin/python examples/quickstart.py       # writes out/quickstart/stretching.png, corner.png

Options: --out DIR, --level L (direct forward model, default 3), --samples N (TMCMC, default 5000).
"""
import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import trbc


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="out/quickstart")
    ap.add_argument("--level", type=int, default=3)
    ap.add_argument("--samples", type=int, default=5000)
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)

    # 1. The data: trbc ships the seven data sets of the paper.
    mills = next(d for d in trbc.load_data_sets() if d.name == "mills_2004")
    print(f"{mills.name}: {len(mills.force_pN)} forces up to {mills.force_pN.max():.0f} pN")

    # 2. The phase-1 posterior of this data set with trbc's own sampler (TMCMC/BASIS on the surrogate).
    inf = trbc.infer(out / "infer", phase=1, data_sets=[mills.name], samples=a.samples, seed=1)
    post = inf["phase1"][mills.name]
    print(post)
    mean = post.mean()
    print("posterior means: " + ", ".join(f"{k} = {v:.4g}" for k, v in mean.items()))

    # 3. A stretching curve for the posterior-mean cell: the surrogate on a fine force grid and the
    #    direct forward model (membrane mechanics on a level-L mesh) on a few forces.
    cell = dict(v=mean["v"], mu_uN_per_m=mean["mu_uN_per_m"], kb_J=mean["kb_J"], b2=mean["b2"])
    fvk = cell["mu_uN_per_m"] * 10.742958658 / (cell["kb_J"] * 1e18)
    forces = np.linspace(0.0, 200.0, 101)
    x = {"v": cell["v"], "mu_uN_per_m": cell["mu_uN_per_m"], "FvK": fvk, "b2": cell["b2"], "etam_Pa_s_um": 0.7,
         "Fext_pN": forces}
    y = trbc.Surrogate().evaluate(x)
    direct = trbc.simulate(**cell, Fext_pN=200.0, force_curve=[50.0, 100.0, 150.0], level=a.level,
                           experiments=("eq", "stretch"))
    curve = direct["stretching_curve_arrays"]
    f_direct = np.append(curve["Fext_pN"], 200.0)
    d0_direct = np.append(curve["D0_um"], direct["observables"]["D0_um"])
    d1_direct = np.append(curve["D1_um"], direct["observables"]["D1_um"])
    print(f"direct forward model, level {a.level}: D1(200 pN) = {direct['observables']['D1_um']:.3f} um "
          f"({direct['diagnostics']['total']['wall_s']:.1f} s)")

    fig, ax = plt.subplots(figsize=(5.5, 4))
    ax.plot(forces, y["D1_um"], "C0-", label="D1 (axial), surrogate")
    ax.plot(forces, y["D0_um"], "C1-", label="D0 (transverse), surrogate")
    ax.plot(f_direct, d1_direct, "C0s", mfc="none", label=f"direct model, level {a.level}")
    ax.plot(f_direct, d0_direct, "C1s", mfc="none")
    ax.plot(mills.force_pN, mills.D1_um, "ko", ms=4, label="Mills et al. 2004")
    ax.plot(mills.force_pN, mills.D0_um, "k^", ms=4)
    ax.set_xlabel("bead force F (pN)")
    ax.set_ylabel("diameter (um)")
    ax.set_title("Posterior-mean cell against the stretching data")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "stretching.png", dpi=120)

    # 4. Corner plot of the posterior (matplotlib only).
    names = post.names
    d = len(names)
    fig, axes = plt.subplots(d, d, figsize=(1.7 * d, 1.7 * d))
    for i in range(d):
        for j in range(d):
            axij = axes[i, j]
            if j > i:
                axij.axis("off")
                continue
            if i == j:
                axij.hist(post.samples[:, i], bins=40, color="C0", histtype="stepfilled", alpha=0.7)
            else:
                axij.hist2d(post.samples[:, j], post.samples[:, i], bins=40, cmap="Blues")
            if i == d - 1:
                axij.set_xlabel(names[j], fontsize=7)
            else:
                axij.set_xticklabels([])
            if j == 0 and i > 0:
                axij.set_ylabel(names[i], fontsize=7)
            else:
                axij.set_yticklabels([])
            axij.tick_params(labelsize=6)
    fig.suptitle(f"phase-1 posterior, {mills.name} ({len(post)} samples)")
    fig.tight_layout()
    fig.savefig(out / "corner.png", dpi=110)
    print(f"wrote {out / 'stretching.png'} and {out / 'corner.png'}")


if __name__ == "__main__":
    main()
