"""The look shared by trbc's figures (imported by the plot_*.py scripts beside it)."""
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def apply(legend_fontsize=8.0, **extra):
    """Small print for single-column figures, no top or right spines; `extra` adds rcParams."""
    plt.rcParams.update({
        "font.size": 9,
        "axes.titlesize": 10,
        "axes.labelsize": 9,
        "legend.fontsize": legend_fontsize,
        "xtick.labelsize": 8,
        "ytick.labelsize": 8,
        "axes.spines.top": False,
        "axes.spines.right": False,
        **extra,
    })
