"""The robust default against the paper's Algorithm 1, time and accuracy in one run.

``python benchmarks/robust.py [--seeds N] [--quick]`` prints one Markdown table and
writes ``benchmarks/results/robust.csv`` (one row per scene, method and initialisation).
Scenes, each with the failure it shows:

``exp2``            Table I, Exp. 2 at the paper's scale (7 real meshes 3 m across, noise 0.03).
``exp2+10%``        the same with 10 % of the b-points moved 0.5-1.5 m (wrong matches).
``kmeans+10%``      that scene from 100 equal-size k-means clusters.
``voxels+10%``      that scene from 1 m voxels.
``flying_things``   :func:`~mmreg.datasets.make_flying_things` (SAM-like and Euclidean init).
``street``          :func:`~mmreg.datasets.make_street` (SAM-like and Euclidean init).

Columns: IoU with the gross errors as a ground-truth outlier class (-1), the paper's IoU
against instance labels where the scene has them, the share of moving objects found
(best IoU >= 0.5), clusters reported against motions, the share of gross errors
labelled -1 and of good correspondences labelled -1, and the time of ``fit`` with the
initialisation. The paper's tau: 1.5 m on Table I scenes, 5 m on flow scenes.
"""

import argparse
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
from sklearn.cluster import KMeans

from mmreg import MultiModelRegistration
from mmreg.datasets import (
    add_wrong_correspondences,
    make_flying_things,
    make_scene,
    make_street,
)
from mmreg.init import EuclideanClustering, PrecomputedMasks
from mmreg.metrics import iou_score, objects_found

HERE = Path(__file__).resolve().parent


def voxels(points, size):
    _, labels = np.unique(np.floor(points / size).astype(int), axis=0, return_inverse=True)
    return labels.ravel()


def scenes(seed, quick):
    """(name, X, labels with -1 for gross errors, instance labels or None, moving, inits)."""
    table = make_scene(noise=0.03, object_size=3.0, shapes="meshes", random_state=seed)
    moving = np.arange(1, 7)
    yield "exp2", table.X, table.labels, None, moving, {"euclidean": "euclidean"}, 1.5
    X, y = add_wrong_correspondences(
        table.X, table.labels, 0.1, random_state=np.random.default_rng(seed)
    )
    yield "exp2+10%", X, y, None, moving, {"euclidean": "euclidean"}, 1.5
    if not quick:
        kmeans = KMeans(100, n_init=1, random_state=seed).fit_predict(X[:, :3])
        yield "kmeans+10%", X, y, None, moving, {"kmeans": kmeans}, 1.5
        yield "voxels+10%", X, y, None, moving, {"voxels": voxels(X[:, :3], 1.0)}, 1.5
    for name, make in (("flying_things", make_flying_things), ("street", make_street)):
        scene = make(random_state=seed)
        y = np.where(scene.outlier_mask, -1, scene.labels)
        inits = {
            "sam": PrecomputedMasks(scene.masks, scene.pixels),
            "euclidean": EuclideanClustering(n_clusters=100),
        }
        moving = np.unique(scene.labels[scene.labels > 0])
        yield name, scene.X, y, scene.instance_labels, moving, inits, 5.0


def run(n_seeds, quick):
    rows = []
    for seed in range(n_seeds):
        for name, X, y, instances, moving, inits, tau in scenes(seed, quick):
            wrong = y < 0
            for init_name, init in inits.items():
                for variant in ("robust", "paper"):
                    est = MultiModelRegistration(
                        tau=tau, init=init, variant=variant, random_state=0
                    )
                    start = time.perf_counter()
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        est.fit(X)
                    seconds = time.perf_counter() - start
                    labels = est.labels_
                    rows.append(
                        {
                            "scene": name,
                            "seed": seed,
                            "init": init_name,
                            "variant": variant,
                            "iou_outliers": iou_score(y, labels),
                            "paper_iou": np.nan
                            if instances is None
                            else iou_score(instances, labels),
                            "moving_found": objects_found(y, labels, objects=moving),
                            "clusters": est.n_clusters_,
                            "motions": len(np.unique(y[y >= 0])),
                            "wrong_rejected": np.mean(labels[wrong] < 0) if wrong.any() else np.nan,
                            "good_rejected": np.mean(labels[~wrong] < 0),
                            "seconds": seconds,
                        }
                    )
    return pd.DataFrame(rows)


def main(argv=None):
    parser = argparse.ArgumentParser(
        description=__doc__.splitlines()[0], formatter_class=argparse.ArgumentDefaultsHelpFormatter
    )
    parser.add_argument("--seeds", type=int, default=10, help="scenes of each kind")
    parser.add_argument("--quick", action="store_true", help="2 seeds, no k-means or voxel scenes")
    parser.add_argument("--out", type=Path, default=HERE / "results", help="folder for robust.csv")
    args = parser.parse_args(argv)
    results = run(2 if args.quick else args.seeds, args.quick)
    args.out.mkdir(parents=True, exist_ok=True)
    results.to_csv(args.out / "robust.csv", index=False)
    summary = results.groupby(["scene", "init", "variant"], sort=False).agg(
        iou_outliers=("iou_outliers", "mean"),
        paper_iou=("paper_iou", "mean"),
        moving_found=("moving_found", "mean"),
        clusters=("clusters", "mean"),
        motions=("motions", "mean"),
        wrong_rejected=("wrong_rejected", "mean"),
        good_rejected=("good_rejected", "mean"),
        seconds=("seconds", "median"),
    )
    print(f"{results['seed'].nunique()} seeds; means (time: median)\n")
    print(summary.reset_index().to_markdown(index=False, floatfmt=".3g"))
    robust = summary.xs("robust", level="variant")["seconds"]
    paper = summary.xs("paper", level="variant")["seconds"]
    print("\ntime ratio robust / paper:\n" + (robust / paper).to_string(float_format="%.2f"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
