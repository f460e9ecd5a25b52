"""Speed of the default initialiser, ``EuclideanClustering()`` (100 clusters).

``python benchmarks/init_speed.py [--realdata PATH] [--repeats 3] [--skip-1m]``

Prints one Markdown table: for each scene, the median wall-clock time of
``EuclideanClustering().fit(X)`` over ``--repeats`` calls, and the floor: one
``cKDTree`` build plus one ``k=8`` query on the same a-points (median of as many),
which any k-NN-based clustering pays, so one sees how close to it the call is. Scenes:

``22k``         ``make_scene(random_state=0)``: the paper's scale, 7 objects.
``100k far``    1,000 small objects of 100 rows each, 6 m apart: the k-NN graph falls
                apart into the objects and the single linkage between them must be found.
``1M``          ``make_scene(n_points=1_000_000, random_state=0)``.
``AV2 sweep``   with ``--realdata PATH`` (the folder holding ``load.py``), if it exists:
                the Argoverse 2 sweep ``av2_api_7fab2350`` without its ground points.
                Read from there for the measurement only; nothing of it is stored.

Times are wall-clock seconds; the header gives the load average when the run started,
since other processes on the machine slow every row alike.
"""

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from mmreg.datasets import make_scene
from mmreg.init import EuclideanClustering


def scenes(realdata, skip_1m):
    yield "22k", make_scene(random_state=0).X
    yield (
        "100k far",
        make_scene(n_objects=1000, n_points=100_000, separation=6.0, random_state=0).X,
    )
    if not skip_1m:
        yield "1M", make_scene(n_points=1_000_000, random_state=0).X
    if realdata is not None:
        if not (Path(realdata) / "load.py").exists():
            print(f"(no load.py in {realdata}: AV2 sweep skipped)", file=sys.stderr)
            return
        sys.path.insert(0, str(realdata))
        from load import load_scene

        scene = load_scene("av2_api_7fab2350", drop_ground=True)
        yield "AV2 sweep", np.hstack([scene.a, scene.b])


def median_seconds(call, repeats):
    seconds = []
    for _ in range(repeats):
        start = time.perf_counter()
        call()
        seconds.append(time.perf_counter() - start)
    return float(np.median(seconds))


def floor(points):
    tree = cKDTree(points)
    tree.query(points, k=8)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--realdata", type=Path, default=None)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--skip-1m", action="store_true", help="leave out the 1M scene")
    args = parser.parse_args(argv)
    print(f"load average at start: {os.getloadavg()[0]:.2f} ({os.cpu_count()} CPUs)\n")
    print("| scene | rows | clusters | radius | fit (s) | floor (s) | fit / floor |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for name, X in scenes(args.realdata, args.skip_1m):
        points = np.ascontiguousarray(X[:, : X.shape[1] // 2])
        init = EuclideanClustering()
        fit = median_seconds(lambda X=X, init=init: init.fit(X), args.repeats)
        base = median_seconds(lambda points=points: floor(points), args.repeats)
        print(
            f"| {name} | {len(X):,} | {init.n_clusters_} | {init.radius_:.4g} | "
            f"{fit:.3f} | {base:.3f} | {fit / base:.1f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
