"""Fig. 2 of the paper: box plots on FlyingThings3D-like and KITTI-like scenes.

Without --data the scenes are GENERATED, not the real data sets:
mmreg.datasets.make_flying_things (about 10 objects 2-4 m across, FlyingThings3D's
camera, 32,768 correspondences) and mmreg.datasets.make_street (a KITTI-like street,
parked and moving cars, 32,768 correspondences as in the paper), both with the errors of a
learned network (noise growing with depth, bleeding across object boundaries, 10 % gross
errors) and SAM-like masks. --data PATH reads real frames instead, through
mmreg.datasets.load_flying_things / load_kitti_scene_flow (frames 0, 1, ...; 32,768
points each, as in the paper); those give the ground-truth flow, so the network's errors
are simulated on it (corrupt_scene_flow) and the SAM masks from the object map
(simulate_sam_masks): the paper used CamliRAFT's flow and SegmentAnything. With --data,
give one data set per run (--datasets kitti or flying_things).

Methods and the paper's parameters (Section V-D/E): Naive (Euclidean init), SeqR
(SRANSAC, residual threshold 0.2 m, 1000 trials), T-Linkage (tau_t = 1 m) and Ours
(Algorithm 1, tau = 5 m, m_min = 4, T = 10), each from SAM-like masks or Euclidean
clustering (100 clusters); mmreg (MultiModelRegistration(tau=5.0)) from both.

Panels: the paper's IoU (ground truth: instances; KITTI: each car and the background),
per-point, rotation and translation error (ground-truth poses by Horn's method on the
clean flow); and the IoU with the gross flow errors as a ground-truth outlier class, the
share of moving objects found (IoU >= 0.5), the clusters reported against the true
number of motions, and the fit time.

Writes to --out: figure2.csv (every run), figure2_<dataset>.png/.pdf, figure2.md (medians).
"""

import sys

from _common import (
    DATASETS,
    Column,
    Experiment,
    add_formats_argument,
    add_runner_arguments,
    flow_scene,
    fmt,
    make_parser,
    parse_methods,
    run_with_options,
    save_figure,
    select_columns,
    write_frame,
    write_text,
)
from _plots import box_figure

TAU, TAU_T, RANSAC_THRESHOLD = 5.0, 1.0, 0.2
PANEL_COLUMNS = [
    "iou",
    "iou_outliers",
    "objects_found",
    "n_clusters",
    "per_point_error",
    "rotation_error",
    "translation_error",
    "runtime_s",
]
# Generated scenes: correspondences and the image size (None: the data set's own).
SIZES = {"flying_things": (32768, None), "kitti": (32768, None)}
QUICK_SIZES = {"flying_things": (2048, (135, 240)), "kitti": (2048, (94, 310))}
QUICK_RUNS = 1
REAL_POINTS = 32768


def columns(names):
    """The paper's eight boxes (six methods and mmreg from both inits) and any others."""
    em = {"min_cluster_size": 4, "max_iter": 10}
    builtin = [
        Column("Naive", "naive", {}, "euclidean"),
        Column(
            "SeqR",
            "sequential_ransac",
            {"residual_threshold": RANSAC_THRESHOLD, "max_trials": 1000},
        ),
        Column("T-L (SAM)", "t_linkage", {"tau_t": TAU_T}, "sam"),
        Column("T-L (Euc.)", "t_linkage", {"tau_t": TAU_T}, "euclidean"),
        Column("Ours (SAM)", "ours", {"tau": TAU, **em}, "sam"),
        Column("Ours (Euc.)", "ours", {"tau": TAU, **em}, "euclidean"),
        Column("mmreg (SAM)", "mmreg", {"tau": TAU}, "sam"),
        Column("mmreg (Euc.)", "mmreg", {"tau": TAU}, "euclidean"),
    ]
    family = {
        "tau": TAU,
        "tau_t": TAU_T,
        "residual_threshold": RANSAC_THRESHOLD,
        "max_trials": 1000,
        **em,
    }
    return select_columns(builtin, names, family, {" (SAM)": "sam", " (Euc.)": "euclidean"})


def experiments(runs=20, seed=0, methods=None, data=None, quick=False, datasets=tuple(DATASETS)):
    """One experiment per data set; scene ``k`` is ``seed + k`` (or the k-th real scene)."""
    names = parse_methods(methods)
    found = []
    for dataset in datasets:
        n_points, image_size = (QUICK_SIZES if quick else SIZES)[dataset]
        config = {"dataset": dataset, "data": None if data is None else str(data)}
        if data is None:
            config.update(n_points=n_points, image_size=image_size)
        else:  # the paper's number of points, sampled from the frame
            config.update(n_points=REAL_POINTS)
        kind = DATASETS[dataset][0]
        if data is not None:
            kind = f"{kind.removesuffix('-like')}, real frames"
        found.append(
            Experiment(
                name=f"figure2-{dataset}",
                title=f"Fig. 2, {kind}",
                scene=flow_scene,
                config=config,
                columns=columns(names),
                seeds=[seed + k for k in range(runs)] if data is None else list(range(runs)),
            )
        )
    return found


def suptitle(dataset, results, real):
    runs = results["run"].nunique()
    points = int(results["n_points"].median())
    if real:
        source = (
            f"REAL {DATASETS[dataset][0].removesuffix('-like')} frames (--data), ground-truth "
            "flow with simulated network errors and SAM-like masks from the object map"
        )
    elif dataset == "flying_things":
        source = (
            "GENERATED FlyingThings3D-like scenes (mmreg.datasets.make_flying_things), "
            "not the real data set"
        )
    else:
        source = (
            "GENERATED KITTI-like street scenes (mmreg.datasets.make_street), not the real data set"
        )
    size = f", {points:,} correspondences each" if points else ""
    return (
        f"Fig. 2 ({'a' if dataset == 'flying_things' else 'b'}) reproduced: {source}; "
        f"{runs} scenes{size}, scene-flow errors incl. 10 % gross errors.\n"
        f"Ours = Algorithm 1 (tau = {TAU:g} m, m_min = 4, T = 10); mmreg = the default "
        f"(tau = {TAU:g} m); T-L: tau_t = {TAU_T:g} m; SeqR: threshold {RANSAC_THRESHOLD:g} m, "
        "1000 trials. SAM = SAM-like masks, Euc. = Euclidean clustering (100 clusters).\n"
        "Boxes: quartiles and median, whiskers 1.5 IQR; dots: one per scene."
    )


def medians_markdown(results):
    """Median of every measure per data set and method, as Markdown."""
    lines = []
    for _, frame in results.groupby("experiment", sort=False):
        methods = list(dict.fromkeys(frame["method"]))
        medians = frame.groupby("method", sort=False)[PANEL_COLUMNS].median()
        lines.append(
            f"**{frame['title'].iloc[0]}** ({frame['run'].nunique()} scenes; medians; "
            f"true motions: median {frame['n_motions'].median():g})\n"
        )
        lines.append("| measure | " + " | ".join(methods) + " |")
        lines.append("|---|" + "---|" * len(methods))
        for column in PANEL_COLUMNS:
            cells = [fmt(medians.loc[m, column]) for m in methods]
            lines.append(f"| {column} | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)


def draw(results, out, real=False, formats="png,pdf"):
    """One figure per data set, PNG and PDF; returns the paths."""
    paths = []
    for experiment, frame in results.groupby("experiment", sort=False):
        dataset = experiment.removeprefix("figure2-")
        methods = list(dict.fromkeys(frame["method"]))
        fig = box_figure(frame, PANEL_COLUMNS, methods, suptitle(dataset, frame, real))
        paths += save_figure(fig, out / f"figure2_{dataset}", formats=formats)
    return paths


def main(argv=None):
    parser = make_parser(__doc__)
    add_runner_arguments(
        parser, runs_default=20, runs_help="scenes per data set (paper: the whole set)"
    )
    parser.add_argument(
        "--data",
        default=None,
        help="folder of the real data set (read by mmreg.datasets.load_flying_things / "
        "load_kitti_scene_flow); without it the scenes are generated",
    )
    parser.add_argument(
        "--datasets",
        default=",".join(DATASETS),
        help=f"comma-separated, of: {', '.join(DATASETS)}",
    )
    add_formats_argument(parser)
    args = parser.parse_args(argv)
    runs = min(args.runs, QUICK_RUNS) if args.quick else args.runs
    chosen = experiments(
        runs=runs,
        seed=args.seed,
        methods=args.methods,
        data=args.data,
        quick=args.quick,
        datasets=[d.strip() for d in args.datasets.split(",")],
    )
    results = run_with_options(chosen, args)
    args.out.mkdir(parents=True, exist_ok=True)
    table = medians_markdown(results)
    written = [
        write_frame(results, args.out / "figure2.csv"),
        write_text(table, args.out / "figure2.md"),
        *draw(results, args.out, real=args.data is not None, formats=args.formats),
    ]
    print(table)
    print("wrote " + ", ".join(str(p) for p in written), file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
