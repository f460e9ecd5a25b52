"""Table I of the paper: every method on PASCAL3D+-like scenes, 4 experiments.

The paper's PASCAL3D+ scenes are 7 CAD models downsampled to 22,395 points in all, each
moved by a random rigid motion. Each run here draws such a scene with
mmreg.datasets.make_scene (7 objects, 22,395 correspondences, objects --object-size
across, at least 2 m apart, motions from all of SO(3); --shapes picks the surfaces where
make_scene offers a choice). Experiments (Section V-C; the 4th is not in the paper):

  1  noiseless
  2  Gaussian noise of standard deviation 0.03 m on the b-points
  3  as 2, and 2 of the 7 objects share one motion
  4  as 2, and 10 % of the correspondences are wrong: their b-point is moved
     0.5-1.5 m in a random direction; they are the ground-truth outlier class (-1)

Methods and the paper's parameters: Euclidean clustering into 100 initial clusters
(Naive, T-Linkage, Ours, mmreg); Ours: tau = 1.5 m, m_min = 4, T = 10 (Vanilla: no gate);
T-Linkage: tau_t = 0.2 m; SRANSAC: inlier threshold 0.01 m (Exp. 1) or 0.5 m, 1000
trials; mmreg: MultiModelRegistration() with tau = 1.5 m. Measures: the paper's IoU,
per-point error, rotation and translation error (means over the runs), the share of the
7 objects found (IoU >= 0.5) and the clusters reported.

Writes to --out: table1.csv (every run), table1.md and table1.tex (the means in the
paper's layout, best in bold, the paper's numbers below ours).
"""

import inspect
import sys

import numpy as np
import pandas as pd
from _common import (
    EXACT,
    Column,
    Experiment,
    Scene,
    add_runner_arguments,
    best_mask,
    fmt,
    make_parser,
    parse_methods,
    run_with_options,
    select_columns,
    timed_labels,
    write_frame,
    write_text,
)

from mmreg.datasets import add_wrong_correspondences, make_scene
from mmreg.init import EuclideanClustering

EXPERIMENTS = {
    1: {"noise": 0.0, "same_motion": 0, "wrong_fraction": 0.0, "ransac_threshold": 0.01},
    2: {"noise": 0.03, "same_motion": 0, "wrong_fraction": 0.0, "ransac_threshold": 0.5},
    3: {"noise": 0.03, "same_motion": 1, "wrong_fraction": 0.0, "ransac_threshold": 0.5},
    4: {"noise": 0.03, "same_motion": 0, "wrong_fraction": 0.1, "ransac_threshold": 0.5},
}
TITLES = {
    1: "Exp. 1: noiseless",
    2: "Exp. 2: Gaussian noise 0.03 m",
    3: "Exp. 3: noise, 2 objects share a motion",
    4: "Exp. 4: noise, 10 % wrong correspondences",
}
# Rows of the table: measure -> (title, better, exact tolerance).
ROWS = {
    "per_point_error": ("Per-point Error [m]", "min"),
    "rotation_error": ("Rotation error [deg]", "min"),
    "translation_error": ("Translation error [m]", "min"),
    "iou": ("IoU", "max"),
    "objects_found": ("Objects found (of 7)", "max"),
    "n_clusters": ("Clusters reported (7 objects)", None),
}
PAPER_METHODS = ["Naive", "SRANSAC", "T-Linkage", "Ours (Vanilla)", "Ours"]
# Table I of the paper (means of 100 runs), by experiment and measure.
PAPER = {
    1: {
        "per_point_error": [0.0454, 9.56e-15, 0.163, 9.56e-15, 9.56e-15],
        "rotation_error": [46.8, 8.69e-7, 19.6, 8.69e-7, 8.69e-7],
        "translation_error": [0.487, 3.81e-15, 0.242, 3.81e-15, 3.81e-15],
        "iou": [0.698, 1.0, 0.723, 1.0, 1.0],
    },
    2: {
        "per_point_error": [0.0550, 0.332, 0.199, 0.0135, 0.00516],
        "rotation_error": [81.6, 74.2, 27.6, 2.42, 1.53],
        "translation_error": [0.858, 0.796, 0.287, 0.0286, 0.0165],
        "iou": [0.668, 0.450, 0.785, 0.908, 0.964],
    },
    3: {
        "per_point_error": [0.0104, 0.321, 0.215, 0.00860, 0.00776],
        "rotation_error": [75.3, 67.3, 15.9, 1.48, 1.12],
        "translation_error": [5.83, 1.33, 0.300, 0.0200, 0.0499],
        "iou": [0.755, 0.398, 0.729, 0.825, 0.970],
    },
}
N_OBJECTS = 7
N_POINTS = 22395
QUICK = {"runs": 2, "points": 1400}


def default_shapes():
    """``"meshes"`` if this make_scene can draw mesh surfaces, else its own default."""
    parameter = inspect.signature(make_scene).parameters.get("shapes")
    return "meshes" if parameter is not None else None


def table1_scene(seed, *, noise, same_motion, wrong_fraction, n_points, object_size, shapes=None):
    """Scene ``seed`` of one experiment, with its Euclidean initial clusters."""
    kwargs = {"shapes": shapes} if shapes is not None else {}
    scene = make_scene(
        N_OBJECTS,
        n_points,
        noise=noise,
        same_motion=same_motion,
        object_size=object_size,
        random_state=seed,
        **kwargs,
    )
    X, labels = add_wrong_correspondences(
        scene.X, scene.labels, wrong_fraction, random_state=np.random.default_rng([seed, 4])
    )
    init, seconds = timed_labels(EuclideanClustering(100), X)
    return Scene(
        X=X,
        truth=labels,
        transforms=(scene.rotations, scene.translations),
        with_outliers=labels,
        objects=np.arange(N_OBJECTS),
        inits={"euclidean": init},
        init_seconds={"euclidean": seconds},
    )


def columns(experiment, names):
    """The paper's methods with their parameters for ``experiment``, then mmreg and others."""
    threshold = EXPERIMENTS[experiment]["ransac_threshold"]
    em = {"min_cluster_size": 4, "max_iter": 10}
    builtin = [
        Column("Naive", "naive", {}, "euclidean"),
        Column(
            "SRANSAC", "sequential_ransac", {"residual_threshold": threshold, "max_trials": 1000}
        ),
        Column("T-Linkage", "t_linkage", {"tau_t": 0.2}, "euclidean"),
        Column("Ours (Vanilla)", "ours_vanilla", em, "euclidean"),
        Column("Ours", "ours", {"tau": 1.5, **em}, "euclidean"),
        Column("mmreg", "mmreg", {"tau": 1.5}, "euclidean"),
    ]
    family = {"tau": 1.5, "tau_t": 0.2, "residual_threshold": threshold, "max_trials": 1000, **em}
    return select_columns(builtin, names, family, {"": "euclidean"})


def experiments(
    runs=100,
    n_points=N_POINTS,
    seed=0,
    methods=None,
    object_size=3.0,
    shapes=None,
    which=(1, 2, 3, 4),
):
    """The experiments of Table I; run ``k`` of experiment ``e`` is scene ``seed + 1000 e + k``."""
    names = parse_methods(methods)
    found = []
    for number in which:
        setting = EXPERIMENTS[number]
        config = {
            "noise": setting["noise"],
            "same_motion": setting["same_motion"],
            "wrong_fraction": setting["wrong_fraction"],
            "n_points": n_points,
            "object_size": object_size,
            "shapes": shapes,
        }
        found.append(
            Experiment(
                name=f"table1-exp{number}",
                title=f"Table I, {TITLES[number]}",
                scene=table1_scene,
                config=config,
                columns=columns(number, names),
                seeds=[seed + 1000 * number + k for k in range(runs)],
            )
        )
    return found


def summarise(results):
    """Means per experiment, measure and method, laid out like Table I (long form)."""
    results = results.assign(number=results["experiment"].str.extract(r"exp(\d+)")[0].astype(int))
    means = results.groupby(["number", "method"], sort=False)[list(ROWS)].mean()
    methods = list(dict.fromkeys(results["method"]))
    rows = []
    for number in dict.fromkeys(results["number"]):
        runs = results.loc[results["number"] == number, "run"].nunique()
        for measure, (title, better) in ROWS.items():
            values = {m: means.loc[(number, m), measure] for m in methods}
            rows.append(
                {
                    "Experiment": number,
                    "runs": runs,
                    "measure": measure,
                    "Metric (mean)": title,
                    "source": "this run",
                    "better": better,
                    **values,
                }
            )
            paper = PAPER.get(number, {}).get(measure)
            if paper is not None:
                reference = dict(zip(PAPER_METHODS, paper, strict=True))
                rows.append(
                    {
                        "Experiment": number,
                        "runs": 100,
                        "measure": measure,
                        "Metric (mean)": f"{title}, paper",
                        "source": "paper",
                        "better": better,
                        **{m: reference.get(m, np.nan) for m in methods},
                    }
                )
    return pd.DataFrame(rows), methods


def _bold_cells(row, methods):
    values = pd.Series({m: row[m] for m in methods})
    target = N_OBJECTS if row["measure"] == "n_clusters" else None
    return best_mask(values, row["better"], EXACT.get(row["measure"]), target)


def to_markdown(summary, methods):
    """The means as a Markdown table: best of each row in bold, the paper's rows italic."""
    lines = [
        "| Exp. | Metric (mean) | " + " | ".join(methods) + " |",
        "|---|---|" + "---|" * len(methods),
    ]
    for _, row in summary.iterrows():
        bold = _bold_cells(row, methods)
        cells = []
        for method in methods:
            text = fmt(row[method])
            if bold[method] and text != "-":
                text = f"**{text}**"
            cells.append(text)
        label = row["Metric (mean)"]
        if row["source"] == "paper":
            label = f"*{label}*"
            cells = [f"*{c}*" if c != "-" else c for c in cells]
        lines.append(f"| {row['Experiment']} | {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def to_latex(summary, methods):
    """The means as a LaTeX tabular like the paper's (best in bold, paper's rows grey)."""
    out = [
        "\\begin{tabular}{l|l|" + "l|" * (len(methods) - 1) + "l}",
        "\\hline",
        " & Metric (mean) & " + " & ".join(methods) + " \\\\",
        "\\hline\\hline",
    ]
    previous = None
    for _, row in summary.iterrows():
        if previous is not None and row["Experiment"] != previous:
            out.append("\\hline")
        previous = row["Experiment"]
        bold = _bold_cells(row, methods)
        cells = []
        for method in methods:
            text = fmt(row[method])
            if bold[method] and text != "-":
                text = f"\\textbf{{{text}}}"
            if row["source"] == "paper":
                text = f"\\textcolor{{gray}}{{{text}}}"
            cells.append(text)
        label = row["Metric (mean)"].replace("%", "\\%")
        out.append(f"{row['Experiment']} & {label} & " + " & ".join(cells) + " \\\\")
    out += ["\\hline", "\\end{tabular}"]
    return "\n".join(out) + "\n"


def main(argv=None):
    parser = make_parser(__doc__)
    add_runner_arguments(parser, runs_default=100, runs_help="scenes per experiment (paper: 100)")
    parser.add_argument(
        "--points", type=int, default=N_POINTS, help="correspondences per scene (paper: 22,395)"
    )
    parser.add_argument(
        "--object-size",
        type=float,
        default=3.0,
        help="object extent in metres (make_scene's object_size); tau = 1.5 m stays",
    )
    parser.add_argument(
        "--shapes",
        default=default_shapes(),
        help="make_scene's shapes (e.g. 'meshes' for real mesh models), if it has the option",
    )
    parser.add_argument(
        "--experiments", default="1,2,3,4", help="comma-separated experiment numbers"
    )
    args = parser.parse_args(argv)
    runs, points = args.runs, args.points
    if args.quick:
        runs, points = min(runs, QUICK["runs"]), min(points, QUICK["points"])
    chosen = experiments(
        runs=runs,
        n_points=points,
        seed=args.seed,
        methods=args.methods,
        object_size=args.object_size,
        shapes=args.shapes,
        which=[int(e) for e in args.experiments.split(",")],
    )
    results = run_with_options(chosen, args)
    summary, methods = summarise(results)
    args.out.mkdir(parents=True, exist_ok=True)
    written = [
        write_frame(results, args.out / "table1.csv"),
        write_text(to_markdown(summary, methods), args.out / "table1.md"),
        write_text(to_latex(summary, methods), args.out / "table1.tex"),
    ]
    print(to_markdown(summary, methods))
    timing = results.groupby("method", sort=False)["runtime_s"].median()
    print("median fit time given the initial clusters [s]:")
    print(timing.to_string(float_format=lambda v: f"{v:.3f}"))
    print("wrote " + ", ".join(str(p) for p in written), file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
