"""Timing and memory benchmarks of mmreg: ``python benchmarks/run.py [--quick]``.

Five sections, each printed as a Markdown table and written as a CSV under
``benchmarks/results/`` (or ``--out``); ``--sections`` picks them, by default ``scale``
alone (a few minutes; ``--sections all`` runs every one):

``scale``
    Every row of the scale table (the issue's figure, its goal, the time and peak
    memory measured now, and the floor at each size: one k-d tree k = 8 k-NN pass with
    its build, and one pass over the data), each row in a fresh process; see
    ``benchmarks/scale.py`` (``scale.csv`` and ``scale.md``).

``paper``
    Paper scale (Section V-A): 22,395 correspondences on 7 objects, Gaussian noise 0.03,
    Euclidean initial clustering with 100 clusters, T = 10. Every method of the package
    on the same data and the same initial clusters; the median of several runs, and the
    IoU against the true objects.
``yardstick``
    The EM (:func:`mmreg.estimators.multi_model_em`) against the plain loop of
    ``benchmarks/straightforward_em.py`` on the same input, in the same run: the speed-up
    ratio of the medians, and whether the two give the same labels.
``scaling_n`` and ``scaling_k``
    The EM from 10k to 1M correspondences (Euclidean initial clusters), and from 100 to
    10,000 initial clusters at 100k correspondences (voxel-grid initial clusters, which
    over-segment every object into about as many compact pieces as asked), with and
    without the gate. Each configuration runs in a fresh process: median time, the peak
    of the memory numpy allocates during one EM run (``tracemalloc``) and the peak
    resident size of the whole process. The exponent of time against ``n`` is fitted by
    least squares on the log-log points.

Times are wall-clock seconds on an otherwise idle machine if possible: the header lists
the load average when the run started.
"""

import argparse
import csv
import json
import os
import platform
import resource
import subprocess
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np
import scipy

import mmreg
from mmreg.datasets import make_scene
from mmreg.em._paper import default_sigma_floor
from mmreg.estimators import MultiModelRegistration, multi_model_em
from mmreg.metrics import iou_score

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from straightforward_em import straightforward_em  # noqa: E402

PAPER_POINTS = 22395
PAPER_OBJECTS = 7
NOISE = 0.03
TAU = 1.5
MAX_ITER = 10


# --- initial clusterings --------------------------------------------------------------------


def euclidean_init(X, n_clusters, random_state=0):
    """Euclidean clustering of the a-points into about ``n_clusters`` clusters."""
    try:
        from mmreg.init import EuclideanClustering
    except ImportError:  # an older mmreg: bisect the radius of connected components
        return _bisected_components(X[:, : X.shape[1] // 2], n_clusters)
    return EuclideanClustering(n_clusters=n_clusters).fit(X).labels_


def _bisected_components(points, n_clusters):
    from mmreg._array.neighbors import connected_labels

    low, high = 1e-6, float(np.ptp(points, axis=0).max()) or 1.0
    for _ in range(40):
        mid = np.sqrt(low * high)
        if connected_labels(points, mid)[0] > n_clusters:
            low = mid
        else:
            high = mid
    return connected_labels(points, high)[1]


def voxel_init(X, n_clusters):
    """Cubic cells of the a-points, of the size that occupies about ``n_clusters`` cells."""
    points = X[:, : X.shape[1] // 2]
    low = points.min(axis=0)

    def cells(size):
        keys = np.floor((points - low) / size).astype(np.int64)
        shape = keys.max(axis=0) + 1
        if np.prod(shape.astype(float)) >= 2.0**62:
            return np.unique(keys, axis=0, return_inverse=True)[1].ravel()
        # One integer per cell (row-major over the occupied box), then its rank.
        return np.unique(np.ravel_multi_index(keys.T, shape), return_inverse=True)[1]

    small, large = 1e-6, float(np.ptp(points, axis=0).max()) or 1.0
    for _ in range(40):
        mid = np.sqrt(small * large)
        if cells(mid).max() + 1 > n_clusters:
            small = mid
        else:
            large = mid
    return cells(large)


# --- timing helpers -------------------------------------------------------------------------


def timed(function, repeats):
    """Median and minimum wall time of ``repeats`` calls, and the last result."""
    times = []
    result = None
    for _ in range(repeats):
        start = time.perf_counter()
        result = function()
        times.append(time.perf_counter() - start)
    return float(np.median(times)), float(np.min(times)), result


def machine():
    info = {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "mmreg": mmreg.__version__,
        "cpus": os.cpu_count(),
        "processor": platform.processor() or platform.machine(),
    }
    if hasattr(os, "getloadavg"):
        info["load_average"] = " ".join(f"{x:.2f}" for x in os.getloadavg())
    return info


# --- sections -------------------------------------------------------------------------------


def paper_scene():
    scene = make_scene(n_objects=PAPER_OBJECTS, n_points=PAPER_POINTS, noise=NOISE, random_state=0)
    init = euclidean_init(scene.X, 100)
    return scene, init


def paper_methods(scene, init, quick):
    """Every estimator of the package on the paper-scale scene: (name, factory) pairs."""
    methods = [
        (
            "Algorithm 1, gate tau=1.5 (variant='paper')",
            lambda: MultiModelRegistration(init=init, variant="paper"),
        ),
        (
            "Algorithm 1, no gate (variant='paper', tau=None)",
            lambda: MultiModelRegistration(tau=None, init=init, variant="paper"),
        ),
        (
            "Algorithm 1 with its Euclidean init (variant='paper')",
            lambda: MultiModelRegistration(variant="paper"),
        ),
        ("Robust default, gate tau=1.5", lambda: MultiModelRegistration(init=init)),
        ("Robust default with its Euclidean init", MultiModelRegistration),
    ]
    try:
        from mmreg.baselines import NaiveRegistration, SequentialRANSAC, TLinkage
    except ImportError:
        return methods
    methods += [
        ("Naive (NaiveRegistration)", lambda: NaiveRegistration(init=init)),
        ("Sequential RANSAC (SequentialRANSAC)", lambda: SequentialRANSAC(random_state=0)),
        ("T-Linkage (TLinkage)", lambda: TLinkage(init=init, random_state=0)),
    ]
    return methods


def run_paper(scene, init, quick):
    median, best, _ = timed(lambda: euclidean_init(scene.X, 100), 3 if quick else 7)
    rows = [
        {
            "method": "Euclidean init, 100 clusters (EuclideanClustering)",
            "median_s": median,
            "min_s": best,
            "iou": iou_score(scene.labels, init),
            "n_clusters": int(init.max()) + 1,
        }
    ]
    for name, factory in paper_methods(scene, init, quick):
        estimator = factory()
        first = time.perf_counter()
        estimator.fit(scene.X)
        once = time.perf_counter() - first
        repeats = (3 if quick else 7) if once < 1.0 else (1 if quick else 3)
        median, best, fitted = timed(lambda f=factory: f().fit(scene.X), repeats)
        rows.append(
            {
                "method": name,
                "median_s": median,
                "min_s": best,
                "iou": iou_score(scene.labels, fitted.labels_),
                "n_clusters": int(fitted.n_clusters_),
            }
        )
    return rows


def run_yardstick(scene, init, quick):
    rows = []
    floor = default_sigma_floor(scene.b)
    for tau in (TAU, None):

        def fast(tau=tau):
            return multi_model_em(scene.a, scene.b, init, tau=tau, max_iter=MAX_ITER)

        def plain(tau=tau):
            return straightforward_em(
                scene.a, scene.b, init, tau=tau, max_iter=MAX_ITER, sigma_floor=floor
            )

        fast_median, fast_min, result = timed(fast, 5 if quick else 15)
        plain_median, plain_min, plain_labels = timed(plain, 1 if quick else 3)
        rows.append(
            {
                "gate": "tau=1.5" if tau else "none",
                "fast_median_s": fast_median,
                "fast_min_s": fast_min,
                "plain_median_s": plain_median,
                "speedup": plain_median / fast_median,
                "same_labels": bool(np.array_equal(result.labels, plain_labels)),
                "n_iter": result.n_iter,
            }
        )
    return rows


def worker(config):
    """One scaling configuration, in this (fresh) process; returns a dict."""
    n, k, init_kind = config["n"], config["k"], config["init"]
    scene = make_scene(n_objects=PAPER_OBJECTS, n_points=n, noise=NOISE, random_state=0)
    start = time.perf_counter()
    init = euclidean_init(scene.X, k) if init_kind == "euclidean" else voxel_init(scene.X, k)
    init_s = time.perf_counter() - start
    out = dict(config, init_s=init_s, init_clusters=int(init.max()) + 1)
    for tau, tag in ((TAU, "gate"), (None, "nogate")):

        def run(tau=tau):
            return multi_model_em(scene.a, scene.b, init, tau=tau, max_iter=MAX_ITER)

        median, best, result = timed(run, config["repeats"])
        tracemalloc.start()
        run()
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        out.update(
            {
                f"{tag}_median_s": median,
                f"{tag}_min_s": best,
                f"{tag}_peak_mib": peak / 2**20,
                f"{tag}_n_iter": result.n_iter,
                f"{tag}_clusters": int(result.labels.max()) + 1,
                f"{tag}_iou": iou_score(scene.labels, result.labels),
            }
        )
    out["max_rss_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return out


def run_scaling(configs):
    rows = []
    for config in configs:
        done = subprocess.run(
            [sys.executable, __file__, "--worker", json.dumps(config)],
            capture_output=True,
            text=True,
            check=False,
        )
        if done.returncode != 0:
            print(done.stderr, file=sys.stderr)
            raise RuntimeError(f"benchmark worker failed on {config}")
        row = json.loads(done.stdout.strip().splitlines()[-1])
        print(
            f"  n={row['n']:>9,} K={row['k']:>6,}: gate {row['gate_median_s']:.3f} s, "
            f"no gate {row['nogate_median_s']:.3f} s, peak {row['gate_peak_mib']:.0f} MiB",
            flush=True,
        )
        rows.append(row)
    return rows


def exponent(rows, key):
    """Least-squares slope of log(time) against log(n)."""
    n = np.log([row["n"] for row in rows])
    t = np.log([row[key] for row in rows])
    return float(np.polyfit(n, t, 1)[0])


# --- output ---------------------------------------------------------------------------------


def markdown(rows, columns):
    def cell(value):
        if isinstance(value, bool):
            return "yes" if value else "no"
        if isinstance(value, float):
            return f"{value:.3g}" if abs(value) < 1000 else f"{value:,.0f}"
        if isinstance(value, int):
            return f"{value:,}"
        return str(value)

    lines = ["| " + " | ".join(title for title, _ in columns) + " |"]
    lines.append("|" + "|".join("---" for _ in columns) + "|")
    for row in rows:
        lines.append("| " + " | ".join(cell(row[key]) for _, key in columns) + " |")
    return "\n".join(lines)


def write_csv(path, rows):
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats, smaller scales")
    parser.add_argument("--out", default=str(HERE / "results"), help="directory for the CSVs")
    parser.add_argument(
        "--sections",
        default="scale",
        help="comma-separated subset of: scale, paper, yardstick, scaling_n, scaling_k; or all",
    )
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        print(json.dumps(worker(json.loads(args.worker))))
        return
    sections = set(args.sections.split(","))
    if "all" in sections:
        sections = {"scale", "paper", "yardstick", "scaling_n", "scaling_k"}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    info = machine()
    print("Machine: " + ", ".join(f"{key} {value}" for key, value in info.items()))
    if sections - {"scale"}:  # the machine of the older sections' CSVs
        write_csv(out / "machine.csv", [info])

    if "scale" in sections:
        import scale

        scale.main(["--out", str(out)] + ["--quick"] * args.quick)

    if sections & {"paper", "yardstick"}:
        scene, init = paper_scene()
    if "paper" in sections:
        print("\n## Paper scale: 22,395 correspondences, 7 objects, 100 initial clusters\n")
        rows = run_paper(scene, init, args.quick)
        write_csv(out / "paper.csv", rows)
        print(
            markdown(
                rows,
                [
                    ("method", "method"),
                    ("median time (s)", "median_s"),
                    ("IoU", "iou"),
                    ("clusters", "n_clusters"),
                ],
            )
        )
    if "yardstick" in sections:
        print("\n## EM against the straightforward loop (same input, same run)\n")
        rows = run_yardstick(scene, init, args.quick)
        write_csv(out / "yardstick.csv", rows)
        print(
            markdown(
                rows,
                [
                    ("gate", "gate"),
                    ("EM median (s)", "fast_median_s"),
                    ("plain loop median (s)", "plain_median_s"),
                    ("speed-up", "speedup"),
                    ("same labels", "same_labels"),
                    ("iterations", "n_iter"),
                ],
            )
        )
    scaling_columns = [
        ("n", "n"),
        ("initial clusters", "init_clusters"),
        ("init (s)", "init_s"),
        ("EM, gate (s)", "gate_median_s"),
        ("EM, no gate (s)", "nogate_median_s"),
        ("iterations", "gate_n_iter"),
        ("peak numpy memory (MiB)", "gate_peak_mib"),
        ("process max RSS (MiB)", "max_rss_mib"),
    ]
    if "scaling_n" in sections:
        print("\n## Scaling in n (Euclidean initial clusters)\n")
        sizes = [10_000, 30_000, 100_000] if args.quick else [10_000, 30_000, 100_000, 300_000]
        sizes += [1_000_000]
        configs = [
            {"n": n, "k": 100, "init": "euclidean", "repeats": 3 if n <= 100_000 else 1}
            for n in sizes
        ]
        configs.append({"n": 1_000_000, "k": 1000, "init": "euclidean", "repeats": 1})
        rows = run_scaling(configs)
        write_csv(out / "scaling_n.csv", rows)
        print(markdown(rows, scaling_columns) + "\n")
        by_n = [row for row in rows if row["k"] == 100]
        large = [row for row in by_n if row["n"] >= 100_000]
        for label, subset in (("all n", by_n), ("n >= 100,000", large)):
            gate, no_gate = exponent(subset, "gate_median_s"), exponent(subset, "nogate_median_s")
            print(
                f"Fitted exponent of time vs n (K = 100, {label}): "
                f"gate {gate:.2f}, no gate {no_gate:.2f}"
            )
    if "scaling_k" in sections:
        print("\n## Scaling in the number of initial clusters (100,000 correspondences)\n")
        ks = [100, 1000, 10_000] if args.quick else [100, 300, 1000, 3000, 10_000]
        configs = [{"n": 100_000, "k": k, "init": "voxel", "repeats": 3} for k in ks]
        rows = run_scaling(configs)
        write_csv(out / "scaling_k.csv", rows)
        print(markdown(rows, scaling_columns))
        k = np.log([row["init_clusters"] for row in rows])
        t = np.log([row["gate_median_s"] for row in rows])
        print(f"\nFitted exponent of time vs initial clusters (gate): {np.polyfit(k, t, 1)[0]:.2f}")
    print(f"\nCSVs written to {out}")


if __name__ == "__main__":
    main()
