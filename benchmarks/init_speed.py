"""Speed of the default initialiser, ``EuclideanClustering()`` (100 clusters).

``python benchmarks/init_speed.py [--realdata PATH] [--repeats 5] [--skip-1m]
[--baseline DIR]``

Prints one Markdown table: for each scene, the median wall-clock time of the clustering
over ``--repeats`` calls, and the floor: one ``cKDTree`` build plus one ``k=8`` query on
the same a-points (median of as many), which any k-NN-based clustering pays, so one sees
how close to it the call is. Rows marked ``plain`` time ``EuclideanClustering().fit(X)``;
rows marked ``default`` time the initial clusters of ``MultiModelRegistration()`` as it
makes them: ``EuclideanClustering(max_radius=tau)`` with ``tau = 1.5`` reading the
estimator's neighbour table (listed beforehand, not timed). Scenes:

``22k``          ``make_scene(random_state=0)``: the paper's scale, 7 objects.
``Table I``      ``make_scene(noise=0.03, object_size=3.0, shapes="meshes")``, 22,395 rows.
``street``       ``make_street(random_state=0)``, 16,384 rows.
``FlyingThings`` ``make_flying_things(random_state=0)``, 32,768 rows.
``100k far``     1,000 small objects of 100 rows each, 6 m apart: the k-NN graph falls
                 apart into the objects and the single linkage between them must be found.
``1M``           ``make_scene(n_points=1_000_000, random_state=0)``.
``AV2 sweep``    with ``--realdata PATH`` (the folder holding ``load.py``), if it exists:
                 the Argoverse 2 sweep ``av2_api_7fab2350`` without its ground points, whole
                 (``plain``) and as the 25,000-voxel sample the default fits (``default``).
                 Read from there for the measurement only; nothing of it is stored.

``--baseline DIR``: a checkout of an earlier commit (``git worktree add DIR <commit>``);
its ``mmreg/init/_euclidean.py`` is loaded next to this one (its imports resolve to this
checkout's ``mmreg``) and timed on the same rows, alternating call by call so that the
load of the machine falls on both alike; the table adds its time, the ratio, and whether
the labels are identical.

Times are wall-clock seconds; the header gives the load average when the run started,
since other processes on the machine slow every row alike.
"""

import argparse
import importlib.util
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

import mmreg.init._euclidean as current
from mmreg._array.neighbors import NeighbourTable
from mmreg._array.voxels import voxel_sample
from mmreg.datasets import make_flying_things, make_scene, make_street

TAU = 1.5  # MultiModelRegistration's default gate, the default init's max_radius


def scenes(realdata, skip_1m):
    """Name, how the clustering is called ("plain" or "default"), and the a-points."""
    yield "22k", "plain", make_scene(random_state=0).a
    table1 = make_scene(noise=0.03, object_size=3.0, shapes="meshes", random_state=0).a
    yield "Table I", "plain", table1
    yield "Table I", "default", table1
    yield "street", "default", make_street(random_state=0).a
    yield "FlyingThings", "default", make_flying_things(random_state=0).a
    far = make_scene(n_objects=1000, n_points=100_000, separation=6.0, random_state=0).a
    yield "100k far", "plain", far
    if not skip_1m:
        yield "1M", "plain", make_scene(n_points=1_000_000, random_state=0).a
    if realdata is not None:
        if not (Path(realdata) / "load.py").exists():
            print(f"(no load.py in {realdata}: AV2 sweep skipped)", file=sys.stderr)
            return
        sys.path.insert(0, str(realdata))
        from load import load_scene

        a = load_scene("av2_api_7fab2350", drop_ground=True).a
        yield "AV2 sweep", "plain", a
        _, rows = voxel_sample(a, 25_000)
        yield "AV2 sweep, 25k voxels", "default", a[rows]


def load_baseline(folder):
    path = Path(folder) / "mmreg" / "init" / "_euclidean.py"
    spec = importlib.util.spec_from_file_location("_baseline_euclidean", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def timed(function, *args, **kwargs):
    start = time.perf_counter()
    result = function(*args, **kwargs)
    return time.perf_counter() - start, result


def floor(points):
    tree = cKDTree(points)
    tree.query(points, k=8)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--realdata", type=Path, default=None)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--skip-1m", action="store_true", help="leave out the 1M scene")
    parser.add_argument("--baseline", type=Path, default=None, help="checkout to compare with")
    args = parser.parse_args(argv)
    modules = {"now": current}
    if args.baseline is not None:
        modules["baseline"] = load_baseline(args.baseline)
    print(f"load average at start: {os.getloadavg()[0]:.2f} ({os.cpu_count()} CPUs)\n")
    header = "| scene | init | rows | clusters | radius | fit (s) | floor (s) | fit / floor |"
    rule = "|---|---|---:|---:|---:|---:|---:|---:|"
    if args.baseline is not None:
        header += " baseline (s) | baseline / fit | same labels |"
        rule += "---:|---:|---|"
    print(header)
    print(rule)
    warnings.simplefilter("ignore", UserWarning)
    for name, how, points in scenes(args.realdata, args.skip_1m):
        points = np.ascontiguousarray(points, dtype=float)
        kwargs = {}
        if how == "default":
            kwargs = {"max_radius": TAU, "neighbours": NeighbourTable(points)}
        seconds = {tag: [] for tag in modules}
        labels = {}
        if len(points) <= 200_000:
            # One call each, untimed: the first calls of a run pay for imports and caches.
            for module in modules.values():
                module.euclidean_clustering(points, **kwargs)
        for _ in range(args.repeats):
            for tag, module in modules.items():
                spent, labels[tag] = timed(module.euclidean_clustering, points, **kwargs)
                seconds[tag].append(spent)
        base = float(np.median([timed(floor, points)[0] for _ in range(args.repeats)]))
        fit = float(np.median(seconds["now"]))
        found, radius = labels["now"]
        line = (
            f"| {name} | {how} | {len(points):,} | {found.max() + 1} | {radius:.4g} | "
            f"{fit:.3f} | {base:.3f} | {fit / base:.1f} |"
        )
        if args.baseline is not None:
            before = float(np.median(seconds["baseline"]))
            same = np.array_equal(found, labels["baseline"][0]) and radius == labels["baseline"][1]
            line += f" {before:.3f} | {before / fit:.2f} | {'yes' if same else 'NO'} |"
        print(line, flush=True)


if __name__ == "__main__":
    main()
