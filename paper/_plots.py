"""Box-plot panels shared by the figures: one box per method, one dot per scene.

Errors at or below the rounding noise of an exact answer (``EXACT``) are drawn at that
level and labelled "exact", so that no axis shows rounding noise as a difference.
"""

import textwrap

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from _common import EXACT  # noqa: E402
from matplotlib.ticker import FixedLocator, NullLocator  # noqa: E402

# Colours by method: the paper's methods in the family colours, SAM init darker.
_COLOURS = {
    "Naive": "#9e9e9e",
    "SRANSAC": "#e6862e",
    "SeqR": "#e6862e",
    "T-Linkage": "#4a90c2",
    "T-L (SAM)": "#2c6aa0",
    "T-L (Euc.)": "#8dbfe3",
    "Ours (Vanilla)": "#9fd39a",
    "Ours": "#3c9a3c",
    "Ours (SAM)": "#2d7d2d",
    "Ours (Euc.)": "#8ccc86",
    "mmreg": "#b03a8c",
    "mmreg (SAM)": "#8e2470",
    "mmreg (Euc.)": "#d98cc2",
}
_EXTRA = ["#c4a000", "#5c3566", "#204a87", "#a40000", "#4e9a06", "#ce5c00"]

# Panel title and unit of each measure, and which way is better.
PANELS = {
    "iou": ("IoU (the paper's metric)", "IoU", "higher is better"),
    "iou_outliers": ("IoU, gross errors as a true outlier class", "IoU", "higher is better"),
    "objects_found": ("Moving objects found (IoU >= 0.5)", "share of them", "higher is better"),
    "n_clusters": ("Clusters reported", "clusters (dashed: the truth)", "closer to dashed"),
    "per_point_error": ("Per-point error", "metres", "lower is better"),
    "rotation_error": ("Rotation error", "degrees", "lower is better"),
    "translation_error": ("Translation error", "metres", "lower is better"),
    "runtime_s": ("Fit time given the initial clusters", "seconds (log scale)", "lower is better"),
}


def palette(methods):
    """A colour for every method label, the same in every figure."""
    colours, extra = {}, iter(_EXTRA * 4)
    for method in methods:
        colours[method] = _COLOURS.get(method) or next(extra)
    return colours


def box_panel(ax, data, column, methods, *, title=None, ylabel=None, note=None):
    """One measure, one box per method (quartiles, median, 1.5 IQR) and a dot per run."""
    values = data[["method", column]].copy()
    exact = EXACT.get(column)
    finite = values[column].to_numpy(dtype=float)
    finite = finite[np.isfinite(finite)]
    log = False
    if exact is not None:
        values[column] = values[column].clip(lower=exact)
        if len(finite) and (finite <= exact).all():
            ax.text(
                0.5,
                0.5,
                f"every method exact\n(errors <= {exact:g}, rounding)",
                ha="center",
                va="center",
                transform=ax.transAxes,
            )
            ax.set_xticks(range(len(methods)), methods, rotation=40, ha="right")
            ax.set_yticks([])
            ax.set_title(title or column, fontsize=10)
            return ax
        positive = np.clip(finite, exact, None)
        log = len(positive) and positive.max() / positive.min() > 100
    elif column == "runtime_s":
        log = True
    colours = palette(methods)
    groups = [values.loc[values["method"] == m, column].dropna().to_numpy() for m in methods]
    positions = np.arange(len(methods))
    drawn = [i for i, g in enumerate(groups) if len(g)]
    boxes = ax.boxplot(
        [groups[i] for i in drawn],
        positions=positions[drawn],
        widths=0.6,
        showfliers=False,
        patch_artist=True,
        medianprops={"color": "black", "linewidth": 1.1},
        whiskerprops={"linewidth": 0.9},
        capprops={"linewidth": 0.9},
        boxprops={"linewidth": 0.9},
    )
    for patch, i in zip(boxes["boxes"], drawn, strict=True):
        patch.set_facecolor(colours[methods[i]])
    rng = np.random.default_rng(0)
    for i in drawn:
        jitter = rng.uniform(-0.18, 0.18, len(groups[i]))
        ax.scatter(positions[i] + jitter, groups[i], s=4, color="black", alpha=0.55, lw=0)
    ax.set_xticks(positions, methods)
    ax.set_xlim(-0.6, len(methods) - 0.4)
    if log:
        ax.set_yscale("log")
    if log and exact is not None and (finite <= exact).any():
        low, high = ax.get_ylim()
        ax.set_ylim(exact / 2, high)
        decades = np.arange(np.ceil(np.log10(exact)), np.floor(np.log10(high)) + 1)
        ticks = [exact] + [10.0**d for d in decades if 10.0**d > exact * 3]
        ax.yaxis.set_major_locator(FixedLocator(ticks))
        ax.yaxis.set_minor_locator(NullLocator())
        ax.set_yticklabels(["exact"] + [f"{t:g}" for t in ticks[1:]])
    if column in ("iou", "iou_outliers", "objects_found"):
        ax.set_ylim(-0.03, 1.03)
    if column == "n_clusters" and "n_motions" in data:
        truth = data["n_motions"].median()
        ax.axhline(truth, color="black", linestyle="--", linewidth=0.9)
        if values[column].max() > 8 * max(truth, 1):
            ax.set_yscale("symlog", linthresh=1, linscale=0.4)
            top = values[column].max()
            ticks = [t for t in (0, 1, 3, 10, 30, 100, 300, 1000, 3000) if t <= top * 1.5]
            ax.yaxis.set_major_locator(FixedLocator(ticks))
            ax.yaxis.set_minor_locator(NullLocator())
            ax.set_yticklabels([str(t) for t in ticks])
            ax.set_ylim(bottom=-0.1)
    ax.set_xlabel("")
    ax.set_ylabel(ylabel or "")
    ax.set_title(title or column, fontsize=10)
    ax.tick_params(axis="x", labelrotation=40)
    for label in ax.get_xticklabels():
        label.set_horizontalalignment("right")
    ax.grid(axis="y", alpha=0.3)
    if note:
        ax.text(0.99, 0.98, note, ha="right", va="top", fontsize=7, transform=ax.transAxes)
    return ax


def box_figure(data, columns, methods, suptitle, *, ncols=4, panel_size=(3.4, 3.2), titles=None):
    """A grid of :func:`box_panel` s; empty cells hidden; ``titles`` overrides PANELS."""
    nrows = int(np.ceil(len(columns) / ncols))
    suptitle = "\n".join(
        textwrap.fill(line, width=int(12.5 * panel_size[0] * ncols))
        for line in suptitle.splitlines()
    )
    fig, axes = plt.subplots(
        nrows,
        ncols,
        figsize=(panel_size[0] * ncols, panel_size[1] * nrows + 0.2 * (suptitle.count("\n") + 1)),
        squeeze=False,
        layout="constrained",
    )
    for ax, column in zip(axes.flat, columns, strict=False):
        title, unit, better = {**PANELS, **(titles or {})}.get(column, (column, "", ""))
        box_panel(ax, data, column, methods, title=f"{title}\n({better})", ylabel=unit)
    for ax in list(axes.flat)[len(columns) :]:
        ax.set_visible(False)
    fig.suptitle(suptitle, fontsize=10, ha="left", x=0.01)
    return fig
