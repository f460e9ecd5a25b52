"""Ablation: IoU against the initial clustering and the rate of wrong correspondences.

Scenes: GENERATED FlyingThings3D-like scenes (mmreg.datasets.make_flying_things, 32,768
correspondences, scene-flow noise and boundary bleeding) with 0, 10, 20 or 30 % gross
flow errors (the b-point off by 0.5-1.5 m; half of them in coherent image blobs), the
ground-truth outlier class. Scene k is the same geometry at every rate.

Initial clusterings (about 100 clusters each, where the data allow): Euclidean
clustering (100 clusters), SAM-like masks (mmreg.datasets.simulate_sam_masks), k-means
(100 clusters on the a-points) and a voxel grid (--voxel m cubes). Methods with the
parameters of the paper's FlyingThings3D experiment: Naive, T-Linkage (tau_t = 1 m), Ours
(Algorithm 1, tau = 5 m) and mmreg (tau = 5 m) from every initial clustering; SRANSAC
(threshold 0.2 m, 1000 trials) needs none and is drawn in every panel.

Measures: the IoU with the gross errors as a ground-truth outlier class (top) and the
share of moving objects found (bottom), mean and 95 % bootstrap interval over the scenes.

Writes to --out: ablation.csv (every run), ablation.md (means), ablation.png/.pdf.
"""

import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import seaborn as sns  # noqa: E402
from _common import (  # noqa: E402
    Column,
    Experiment,
    add_formats_argument,
    add_runner_arguments,
    flow_scene,
    make_parser,
    parse_methods,
    run_with_options,
    save_figure,
    select_columns,
    write_frame,
    write_text,
)
from _plots import palette  # noqa: E402
from sklearn.cluster import KMeans  # noqa: E402

RATES = (0.0, 0.1, 0.2, 0.3)
INITS = {
    "euclidean": "Euclidean",
    "sam": "SAM-like",
    "kmeans": "k-means",
    "voxels": "voxels",
}
TAU, TAU_T, RANSAC_THRESHOLD = 5.0, 1.0, 0.2
QUICK = {"n_points": 2048, "image_size": (135, 240), "runs": 1, "rates": (0.0, 0.3)}


def ablation_scene(seed, *, rate, voxel, n_points=None, image_size=None):
    """A FlyingThings3D-like scene with ``rate`` gross errors and four initial clusterings."""
    scene = flow_scene(
        seed,
        dataset="flying_things",
        n_points=n_points,
        image_size=image_size,
        corruption={"gross_error_fraction": rate},
    )
    a = scene.X[:, :3]
    kmeans = KMeans(n_clusters=min(100, len(a)), n_init=1, random_state=seed).fit_predict(a)
    _, voxels = np.unique(np.floor(a / voxel).astype(int), axis=0, return_inverse=True)
    scene.inits["kmeans"], scene.inits["voxels"] = kmeans, voxels.ravel()
    scene.extra.clear()  # the Bunch is not needed and is large to send back
    return scene


def columns(names, inits):
    """Every method from every initial clustering; SRANSAC once."""
    em = {"min_cluster_size": 4, "max_iter": 10}
    builtin = [Column("SRANSAC", "sequential_ransac", {"residual_threshold": RANSAC_THRESHOLD})]
    for init in inits:
        kind = INITS[init]
        builtin += [
            Column(f"Naive / {kind}", "naive", {}, init),
            Column(f"T-Linkage / {kind}", "t_linkage", {"tau_t": TAU_T}, init),
            Column(f"Ours / {kind}", "ours", {"tau": TAU, **em}, init),
            Column(f"mmreg / {kind}", "mmreg", {"tau": TAU}, init),
        ]
    family = {"tau": TAU, "tau_t": TAU_T, "residual_threshold": RANSAC_THRESHOLD, **em}
    return select_columns(builtin, names, family, {f" / {INITS[i]}": i for i in inits})


def experiments(
    runs=10, seed=0, methods=None, rates=RATES, inits=tuple(INITS), voxel=4.0, quick=False
):
    """One experiment per rate of wrong correspondences; scene k is ``seed + k``."""
    names = parse_methods(methods)
    config = {"voxel": voxel}
    if quick:
        config.update(n_points=QUICK["n_points"], image_size=QUICK["image_size"])
    return [
        Experiment(
            name=f"ablation-wrong{round(100 * rate)}",
            title=f"Ablation, {100 * rate:.0f} % wrong correspondences",
            scene=ablation_scene,
            config={**config, "rate": rate},
            columns=columns(names, inits),
            seeds=[seed + k for k in range(runs)],
        )
        for rate in rates
    ]


def tidy(results):
    """Method, init and rate of every run as columns of their own."""
    split = results["method"].str.split(" / ", n=1, expand=True, regex=False)
    results = results.assign(
        family=split[0],
        init=split[1] if split.shape[1] > 1 else None,
        wrong_percent=results["experiment"].str.extract(r"wrong(\d+)")[0].astype(int),
    )
    return results


def draw(results, inits):
    """IoU and objects found against the rate, one panel per initial clustering."""
    data = tidy(results)
    families = list(dict.fromkeys(data["family"]))
    colours = palette(families)
    fig, axes = plt.subplots(
        2,
        len(inits),
        figsize=(3.6 * len(inits), 7.2),
        sharey="row",
        squeeze=False,
        layout="constrained",
    )
    for col, init in enumerate(inits):
        shown = data[(data["init"] == INITS[init]) | data["init"].isna()]
        for row, (measure, label) in enumerate(
            (
                ("iou_outliers", "IoU, gross errors as outlier class"),
                ("objects_found", "moving objects found (share)"),
            )
        ):
            ax = axes[row, col]
            sns.lineplot(
                data=shown,
                x="wrong_percent",
                y=measure,
                hue="family",
                hue_order=families,
                palette=colours,
                style="family",
                markers=True,
                dashes=False,
                errorbar=("ci", 95),
                n_boot=500,
                seed=0,
                ax=ax,
                legend=(row == 0 and col == 0),
            )
            ax.set_ylim(-0.03, 1.03)
            ax.set_xticks(sorted(data["wrong_percent"].unique()))
            ax.set_xlabel("wrong correspondences [%]")
            ax.set_ylabel(label if col == 0 else "")
            ax.grid(alpha=0.3)
            if row == 0:
                ax.set_title(f"initial clusters: {INITS[init]}", fontsize=10)
    legend = axes[0, 0].get_legend()
    if legend is not None:
        handles, labels = axes[0, 0].get_legend_handles_labels()
        legend.remove()
        fig.legend(handles, labels, loc="outside lower center", ncol=len(labels), frameon=False)
    runs = data["run"].nunique()
    fig.suptitle(
        f"Ablation on GENERATED FlyingThings3D-like scenes (make_flying_things, "
        f"{int(data['n_points'].median()):,} correspondences): {runs} scenes per rate; "
        "mean and 95 % bootstrap interval.\nOurs = Algorithm 1 (tau = 5 m), T-Linkage "
        "tau_t = 1 m, SRANSAC 0.2 m (no initial clusters: the same line in every panel).",
        fontsize=10,
        x=0.01,
        ha="left",
    )
    return fig


def means_markdown(results):
    """Mean IoU (gross errors as outliers) per method and rate, as Markdown."""
    data = tidy(results)
    table = data.pivot_table(
        index="method",
        columns="wrong_percent",
        values="iou_outliers",
        aggfunc="mean",
        sort=False,
    )
    table.columns = [f"{c} % wrong" for c in table.columns]
    runs = data["run"].nunique()
    return (
        f"Mean IoU with the gross errors as outlier class, {runs} scenes per rate\n\n"
        + table.to_markdown(floatfmt=".3f")
        + "\n"
    )


def main(argv=None):
    parser = make_parser(__doc__)
    add_runner_arguments(parser, runs_default=10, runs_help="scenes per rate")
    parser.add_argument(
        "--rates",
        default=",".join(f"{r:g}" for r in RATES),
        help="comma-separated fractions of wrong correspondences",
    )
    parser.add_argument(
        "--inits", default=",".join(INITS), help=f"comma-separated, of: {', '.join(INITS)}"
    )
    parser.add_argument("--voxel", type=float, default=4.0, help="voxel edge in metres")
    add_formats_argument(parser)
    args = parser.parse_args(argv)
    rates = [float(r) for r in args.rates.split(",")]
    inits = [i.strip() for i in args.inits.split(",")]
    runs = args.runs
    if args.quick:
        runs, rates = min(runs, QUICK["runs"]), [r for r in rates if r in QUICK["rates"]] or rates
    chosen = experiments(
        runs=runs,
        seed=args.seed,
        methods=args.methods,
        rates=rates,
        inits=inits,
        voxel=args.voxel,
        quick=args.quick,
    )
    results = run_with_options(chosen, args)
    args.out.mkdir(parents=True, exist_ok=True)
    table = means_markdown(results)
    written = [
        write_frame(results, args.out / "ablation.csv"),
        write_text(table, args.out / "ablation.md"),
        *save_figure(draw(results, inits), args.out / "ablation", formats=args.formats),
    ]
    print(table)
    print("wrote " + ", ".join(str(p) for p in written), file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
