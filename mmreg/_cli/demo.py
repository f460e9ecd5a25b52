"""``mmreg demo``: a generated street scene, registered, and what was found."""

import io
import time

from mmreg._cli._common import Steps, check_out, format_table
from mmreg._cli.register import _seed, register

NAME = "demo"
HELP = "register a generated KITTI-like street scene and report what was found"
DESCRIPTION = """\
End-to-end demo on a generated KITTI-like street (mmreg.datasets.make_street: 7 cars, 3 of
them moving, 16,384 correspondences from a scene flow with realistic errors, 10 % gross
errors, the camera driving forward). The initial clusters are the scene's SegmentAnything-
like masks (PrecomputedMasks), which beat the default Euclidean clustering on these
scenes; the registration is MultiModelRegistration's default with the paper's
gate for street scenes, tau = 5 m (the paper's tau = 1.5 m is for objects a few metres
apart: on a street it keeps every tree and pole apart from the road).

Prints every recovered cluster (size, rotation angle and translation of its motion, its
motion relative to the background, whether it moves, the true object it overlaps most and
their IoU), the paper's IoU, the share of the moving cars found and the outliers found.
With --out DIR, also writes the result directory of "mmreg register" there (result.png,
labels.npy, motions.json, summary.csv, clusters.ply, X.npy, run.json) and truth.npz (the
true labels with -1 for gross errors, X, rotations, translations), so that
"mmreg evaluate DIR DIR/truth.npz" and "mmreg view DIR" work on it. Without --out nothing
is written.
"""


def add_arguments(parser):
    parser.add_argument(
        "--out", metavar="DIR", default=None, help="write the result directory here"
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an earlier result directory at --out (never a folder of other files)",
    )
    parser.add_argument("--seed", type=_seed, default=0, help="seed of the scene")
    parser.add_argument("--quiet", "-q", action="store_true", help="no progress bar, no report")
    parser.add_argument(
        "--verbose", "-v", action="count", default=0, help="print the EM's iterations"
    )


def _truth_names(scene):
    names = {-1: "gross errors", 0: "static world"}
    names.update({k: f"moving car {k}" for k in range(1, len(scene.rotations))})
    return names


def _best_matches(truth, labels, n_clusters):
    """Per estimated cluster: the true object it shares most points with, and their IoU."""
    import numpy as np

    matches = []
    for label in range(n_clusters):
        members = labels == label
        ids, counts = np.unique(truth[members], return_counts=True)
        best = ids[np.argmax(counts)]
        union = members.sum() + np.sum(truth == best) - counts.max()
        matches.append((int(best), counts.max() / union))
    return matches


def run(args):
    import argparse

    import numpy as np

    from mmreg.datasets import make_street
    from mmreg.init import PrecomputedMasks
    from mmreg.metrics import iou_score, objects_found

    if args.out is not None:
        check_out(args.out, overwrite=args.overwrite)  # before any work
    start = time.perf_counter()
    with Steps(5 if args.out else 4, quiet=args.quiet, verbose=args.verbose) as steps:
        with steps.step("generating the street scene"):
            scene = make_street(n_cars=7, n_moving=3, random_state=args.seed)
        truth = np.where(scene.outlier_mask, -1, scene.labels)
        init = PrecomputedMasks(scene.masks, scene.pixels)
        options = argparse.Namespace(
            tau=5.0,
            min_cluster_size=4,
            max_iter=10,
            paper=False,
            seed=0,
            verbose=args.verbose,
            out=args.out,
            overwrite=args.overwrite,
            view="street",
            init="SAM-like masks",
        )
        extra = {"demo_seed": args.seed, "scene": "make_street(n_cars=7, n_moving=3)"}
        truth_file = io.BytesIO()
        np.savez(
            truth_file,
            labels=truth,
            X=scene.X,
            rotations=scene.rotations,
            translations=scene.translations,
        )
        estimator, summary, elapsed, n_masks = register(
            scene.X,
            init,
            options,
            input_name=f"demo street (seed {args.seed})",
            steps=steps,
            extra_run=extra,
            title=(
                f"mmreg demo: generated street (seed {args.seed}), "
                f"{len(scene.X):,} correspondences -> {{found}}"
            ),
            camera=scene.camera,
            extra_files={"truth.npz": truth_file.getvalue()},
        )
    total = time.perf_counter() - start
    if args.quiet:
        return 0

    labels = estimator.labels_
    names = _truth_names(scene)
    moving_cars = np.arange(1, len(scene.rotations))
    sizes = np.bincount(truth[truth >= 0], minlength=len(scene.rotations))
    print(
        f"Street scene (seed {args.seed}): {len(scene.X):,} correspondences; "
        f"{len(moving_cars)} moving cars of {', '.join(f'{s:,}' for s in sizes[1:])} points, "
        f"{scene.outlier_mask.sum():,} gross flow errors; camera moving "
        f"{np.linalg.norm(scene.ego_motion[1]):.2f} m."
    )
    print(
        f"MultiModelRegistration (default, tau 5 m) from {n_masks} "
        f"SAM-like masks: {estimator.n_clusters_} clusters in {estimator.n_iter_} iterations, "
        f"{elapsed:.1f} s."
    )
    print()
    matches = _best_matches(truth, labels, estimator.n_clusters_)
    moving = summary["moving"].map({True: "yes", False: "no"})
    table = summary.assign(
        moving=moving.where(~summary["background"], "background"),
        best_match=[f"{names[m]} ({iou:.2f})" for m, iou in matches],
    )
    spec = [
        ("label", "cluster", ""),
        ("size", "points", ",d"),
        ("rotation_angle_deg", "rotation [deg]", ".2f"),
        ("translation_norm", "translation [m]", ".2f"),
        ("displacement_vs_background", "vs background [m]", ".2f"),
        ("moving", "moving", ""),
        ("best_match", "best match (IoU)", ""),
    ]
    print(format_table(table, spec))
    print()
    found = objects_found(truth, labels, objects=moving_cars)
    flagged = labels < 0
    true_out = truth < 0
    precision = (flagged & true_out).sum() / max(flagged.sum(), 1)
    recall = (flagged & true_out).sum() / max(true_out.sum(), 1)
    print(f"IoU (Sec. V-B; truth: motions, gross errors -1): {iou_score(truth, labels):.3f}")
    print(
        f"moving cars found:          {found:.0%} ({round(found * len(moving_cars))} of "
        f"{len(moving_cars)}, IoU >= 0.5)"
    )
    print(
        f"gross errors flagged:       {flagged.sum():,} outliers, precision {precision:.0%}, "
        f"recall {recall:.0%}"
    )
    if args.out is not None:
        print(f"written: {args.out}/ (result.png, labels.npy, motions.json, summary.csv, ...)")
        print(f"  mmreg evaluate {args.out} {args.out}/truth.npz")
    print(f"total time: {total:.1f} s")
    return 0
