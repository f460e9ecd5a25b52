"""Time and peak memory by scene size, measured now: ``python benchmarks/scale.py``.

Also the default section of ``benchmarks/run.py``. Each row runs in a fresh Python
process (``--row NAME``), so its peak memory is its own: the process's maximum resident
size (``resource.getrusage(RUSAGE_SELF)``, data generation included), the resident size
just before the measured call, and for ``mmreg register`` the command's own peak
(``RUSAGE_CHILDREN`` of the process that waited for it). Beside each row, the floor at
that size, what any method pays there:

``knn_s``   one ``scipy.spatial.cKDTree`` build on the a-points plus one ``k = 8`` query
            of every a-point (one neighbour pass);
``pass_s``  one pass over the correspondences: the squared residual ``|R a + t - b|^2`` of
            every row under one motion (what one E-step costs per motion);
``table_s`` (Table I row) the default's own neighbour pass: the ``k = 16`` nearest
            neighbours of every a-point (``mmreg._array.neighbors.NeighbourTable``), which its
            boundary-layers step reads;

medians of as many repeats as the row's timing. The rows, with the issue's "today"
figures and goals as written there:

``table1``    Table I scene (``make_scene(noise=0.03, object_size=3.0, shapes="meshes")``,
              22,395 correspondences), k-means(100) labels given as ``init``:
              ``MultiModelRegistration()``, ``variant="sweep"``, ``variant="paper"`` and
              the default without its boundary-layers step (``skip_steps=
              ("boundary_layers",)``: no neighbour table), which shows what that step costs,
              and without its range-noise estimate as well (the steps that the goal of
              0.1 s leaves no room for).
``1m``        1M correspondences, 20 objects (``make_scene(20, 1_000_000, noise=0.03)``),
              initial clusters from 0.9 m voxels (1,000+), the default, ``"sweep"`` and
              the default fitted on one correspondence per 0.1 m voxel.
``far``       1,000 objects of 100 rows 6 m apart (``make_scene(1000, 100_000,
              separation=6.0)``), the default and ``"sweep"`` with their own init.
``far_k``     the same scene at K = 10, 100 and 1,000 objects of 100 rows each
              (``make_scene(K, 100 K, separation=6.0)``; ``--quick``: 10, 100, 300), the
              default, 3 repeats: how the time grows with the number of clusters (the
              static world's tests of pairs of clusters once grew with its square).
``euclidean`` ``EuclideanClustering()`` on those 100k rows.
``startup``   ``mmreg --version`` and ``mmreg --help`` (the floor: ``python -c pass``).
``register``  ``mmreg register`` on 2M generated correspondences (``make_scene(20,
              2_000_000, noise=0.03)`` in ``.npy``), and with ``--voxel-size 0.1``
              (peak memory: the largest command so far): wall time, the fit's share (its
              ``run.json`` ``fit_seconds``: initial clusters and EM), peak memory, and the
              size of the result directory and whether it holds a copy of the input.

Times are wall-clock seconds; the machine is shared, so the header gives the load
average at the start and every timing is a median of the stated repeats.
"""

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROWS = ("table1", "1m", "far", "far_k", "euclidean", "startup", "register")

# The goals: (work, the figure when the goal was set, the goal).
ISSUE = {
    "table1": (
        "Table I scene (22,395 correspondences), default, k-means(100) init given",
        "263-326 ms, 2 iterations (paper variant: 74 ms an iteration)",
        "<= 100 ms",
    ),
    "1m": (
        "1M correspondences, 20 objects, 0.9 m voxel init (1,000+ clusters), default",
        "15.8-17.1 s, peak 0.5 GB",
        "<= 8 s, <= 2 GB",
    ),
    "far": (
        "1,000 objects of 100 rows 6 m apart (100k rows), default",
        "28 s",
        "<= 5 s",
    ),
    "far_k": (
        "K objects of 100 rows 6 m apart (K = 10, 100, 1,000), default",
        "K = 1,000: 0.4 s at the last release, then 7-18 s (a test per pair of clusters)",
        "<= 1 s at K = 1,000",
    ),
    "euclidean": ("EuclideanClustering() on those 100k far-apart rows", "4.6-5.6 s", "<= 0.5 s"),
    "startup": ("mmreg --version, mmreg --help", "2.2-3.1 s", "<= 0.5 s"),
    "register": (
        "2M correspondences through mmreg register",
        "3 min 37 s, 1.96 GB, writes a 96 MB copy of the input",
        "<= 30 s, copy of the input only on request",
    ),
}


def _rss_mib():
    """Peak resident size of this process so far (MiB; Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _current_rss_mib():
    try:
        with open("/proc/self/statm") as handle:
            return int(handle.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except OSError:  # not Linux: the peak so far instead
        return _rss_mib()


def _median_time(call, repeats):
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = call()
        times.append(time.perf_counter() - start)
    return float(np.median(times)), result


def floors(X, repeats, table=False):
    """The k-NN pass (build + k=8 query) and one pass over the rows, median seconds;
    ``table``: also the default's k = 16 neighbour table."""
    from scipy.spatial import cKDTree

    from mmreg._array.neighbors import NeighbourTable

    a = np.ascontiguousarray(X[:, :3])
    b = np.ascontiguousarray(X[:, 3:])
    R, t = np.eye(3), np.zeros(3)
    knn, _ = _median_time(lambda: cKDTree(a).query(a, k=8), repeats)

    def one_pass():
        # einsum, not a @ R.T: OpenBLAS threads make that 3 x 3 product 10-30x slower on
        # a busy machine, which would measure the thread pool, not the pass.
        r = np.einsum("ij,kj->ik", a, R)
        r += t
        r -= b
        return np.einsum("ij,ij->i", r, r)

    one, _ = _median_time(one_pass, max(repeats, 3))
    out = {"knn_s": knn, "pass_s": one}
    if table:
        out["table_s"], _ = _median_time(lambda: NeighbourTable(a), repeats)
    return out


def _fit_row(name, X, estimator, repeats, truth=None):
    from mmreg.metrics import iou_score

    before = _current_rss_mib()
    seconds, fitted = _median_time(lambda: estimator.fit(X), repeats)
    row = {
        "method": name,
        "n": len(X),
        "seconds": seconds,
        "repeats": repeats,
        "n_iter": int(fitted.n_iter_),
        "s_per_iter": seconds / max(int(fitted.n_iter_), 1),
        "clusters": int(fitted.n_clusters_),
        "rss_before_mib": before,
        "peak_rss_mib": _rss_mib(),
    }
    if truth is not None:
        row["iou"] = float(iou_score(truth, fitted.labels_))
    return row


def _voxels(points, size):
    _, labels = np.unique(np.floor(points / size).astype(np.int64), axis=0, return_inverse=True)
    return labels.ravel()


def row_table1(quick):
    from sklearn.cluster import KMeans

    from mmreg import MultiModelRegistration
    from mmreg.datasets import make_scene

    scene = make_scene(noise=0.03, object_size=3.0, shapes="meshes", random_state=0)
    init = KMeans(100, n_init=1, random_state=0).fit_predict(scene.X[:, :3])
    repeats = 3 if quick else 7
    rows = [
        _fit_row(
            f"MultiModelRegistration({variant})",
            scene.X,
            MultiModelRegistration(init=init, random_state=0, **kwargs),
            repeats,
            scene.labels,
        )
        for variant, kwargs in (
            ("", {}),
            ('variant="sweep"', {"variant": "sweep"}),
            ('variant="paper"', {"variant": "paper"}),
            ('skip_steps=("boundary_layers",)', {"skip_steps": ("boundary_layers",)}),
            (
                'skip_steps=("boundary_layers", "range_noise")',
                {"skip_steps": ("boundary_layers", "range_noise")},
            ),
        )
    ]
    return rows, floors(scene.X, repeats, table=True)


def row_1m(quick):
    from mmreg import MultiModelRegistration
    from mmreg.datasets import make_scene

    n = 200_000 if quick else 1_000_000
    scene = make_scene(20, n, noise=0.03, random_state=0)
    init = _voxels(scene.a, 0.9)
    rows = []
    for variant, kwargs in (
        ("", {}),
        ("voxel_size=None", {"voxel_size": None}),
        ("voxel_size=0.1", {"voxel_size": 0.1}),
    ):
        row = _fit_row(
            f"MultiModelRegistration({variant})",
            scene.X,
            MultiModelRegistration(init=init, random_state=0, **kwargs),
            1,
            scene.labels,
        )
        rows.append(row | {"init_clusters": int(init.max()) + 1})
    return rows, floors(scene.X, 1)


def _far_scene(quick):
    from mmreg.datasets import make_scene

    n_objects = 200 if quick else 1000
    return make_scene(n_objects, 100 * n_objects, separation=6.0, random_state=0)


def row_far(quick):
    from mmreg import MultiModelRegistration

    scene = _far_scene(quick)
    rows = [
        _fit_row(
            f"MultiModelRegistration({variant})",
            scene.X,
            MultiModelRegistration(random_state=0, **kwargs),
            1,
            scene.labels,
        )
        for variant, kwargs in (("", {}), ("voxel_size=None", {"voxel_size": None}))
    ]
    return rows, floors(scene.X, 1)


def row_far_k(quick):
    from mmreg import MultiModelRegistration
    from mmreg.datasets import make_scene

    rows = []
    for n_objects in (10, 100, 300 if quick else 1000):
        scene = make_scene(n_objects, 100 * n_objects, separation=6.0, random_state=0)
        row = _fit_row(
            f"MultiModelRegistration(), K = {n_objects:,}",
            scene.X,
            MultiModelRegistration(random_state=0),
            3,
            scene.labels,
        )
        # Each size its own floor, in the row (run_row adds the last one's otherwise).
        rows.append(row | {"objects": n_objects} | floors(scene.X, 3))
    return rows, {}


def row_euclidean(quick):
    from mmreg.init import EuclideanClustering

    scene = _far_scene(quick)
    repeats = 3
    before = _current_rss_mib()
    seconds, fitted = _median_time(lambda: EuclideanClustering().fit(scene.X), repeats)
    row = {
        "method": "EuclideanClustering()",
        "n": len(scene.X),
        "seconds": seconds,
        "repeats": repeats,
        "clusters": int(fitted.n_clusters_),
        "rss_before_mib": before,
        "peak_rss_mib": _rss_mib(),
    }
    return [row], floors(scene.X, repeats)


def _command(*args):
    program = shutil.which("mmreg")
    return [program, *args] if program else [sys.executable, "-m", "mmreg.cli", *args]


def _run_timed(command, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        subprocess.run(command, check=True, capture_output=True)
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def row_startup(quick):
    repeats = 5 if quick else 9
    rows = [
        {
            "method": f"mmreg {option}",
            "seconds": _run_timed(_command(option), repeats),
            "repeats": repeats,
            "peak_rss_mib": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024,
        }
        for option in ("--version", "--help")
    ]
    python = _run_timed([sys.executable, "-c", "pass"], repeats)
    return rows, {"python_startup_s": python}


def row_register(quick):
    from mmreg.datasets import make_scene

    n = 200_000 if quick else 2_000_000
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "pairs.npy"
        X = make_scene(20, n, noise=0.03, random_state=0).X
        np.save(path, X)
        rows = []
        for options in ([], ["--voxel-size", "none"], ["--voxel-size", "0.1"]):
            out = Path(folder) / f"result{len(rows)}"
            start = time.perf_counter()
            done = subprocess.run(
                _command("register", str(path), "--out", str(out), "-q", *options),
                capture_output=True,
                text=True,
                check=False,
            )
            seconds = time.perf_counter() - start
            if done.returncode != 0:
                raise RuntimeError(f"mmreg register failed: {done.stderr}")
            run = json.loads((out / "run.json").read_text())
            children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
            rows.append(
                {
                    "method": " ".join(["mmreg register pairs.npy", *options]),
                    "n": n,
                    "seconds": seconds,
                    "repeats": 1,
                    "fit_s": run["fit_seconds"],
                    "outside_fit_s": seconds - run["fit_seconds"],
                    # The largest child so far: the first command's, if it was larger.
                    "peak_rss_mib": children,
                    "result_mb": sum(p.stat().st_size for p in out.iterdir()) / 1e6,
                    "input_copy": (out / "X.npy").exists(),
                    "input_mb": path.stat().st_size / 1e6,
                }
            )
            shutil.rmtree(out)
        return rows, floors(X, 1)


def run_row(name, quick):
    rows, floor = globals()[f"row_{name}"](quick)
    return [{"row": name} | row | floor for row in rows]


def _cell(value, fmt):
    if value is None or (isinstance(value, float) and np.isnan(value)):
        return ""
    return format(value, fmt)


def describe(row):
    """The "measured now" cell of one row."""
    parts = [f"{row['seconds']:.3g} s"]
    if "n_iter" in row:
        parts.append(f"{row['n_iter']} iter ({1000 * row['s_per_iter']:.0f} ms/iter)")
    if "fit_s" in row:
        parts.append(f"fit {row['fit_s']:.1f} s + {row['outside_fit_s']:.1f} s around it")
    if "peak_rss_mib" in row:
        parts.append(f"peak {row['peak_rss_mib'] / 1024:.2f} GiB")
    if "result_mb" in row:
        copy = "with" if row["input_copy"] else "no"
        parts.append(f"result {row['result_mb']:.0f} MB, {copy} copy of the input")
    if "iou" in row:
        parts.append(f"IoU {row['iou']:.3f}")
    return ", ".join(parts)


def floor_text(row):
    if "python_startup_s" in row:
        return f"python -c pass {row['python_startup_s']:.3g} s"
    text = f"k-NN {row['knn_s']:.3g} s, one pass {row['pass_s']:.3g} s"
    if not np.isnan(row.get("table_s", np.nan)):
        text += f" (the default's k=16 neighbour table: {row['table_s']:.3g} s)"
    return text


def markdown(rows):
    lines = [
        "| work | when the goal was set | goal | method | measured now | floor at this size |",
        "|---|---|---|---|---|---|",
    ]
    for row in rows:
        work, today, goal = ISSUE[row["row"]]
        lines.append(
            f"| {work} | {today} | {goal} | {row['method']} | {describe(row)} | {floor_text(row)} |"
        )
    return "\n".join(lines)


BLAS_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def run_all(names, quick, out=None, blas_threads=None):
    """Every row in its own process; prints each as it comes, returns them all."""
    rows = []
    env = dict(os.environ)
    if blas_threads is not None:
        env.update(dict.fromkeys(BLAS_VARIABLES, str(blas_threads)))
    for name in names:
        command = [sys.executable, str(Path(__file__).resolve()), "--row", name]
        command += ["--quick"] if quick else []
        start = time.perf_counter()
        done = subprocess.run(command, capture_output=True, text=True, check=False, env=env)
        if done.returncode != 0:
            print(done.stderr, file=sys.stderr)
            raise RuntimeError(f"row {name} failed")
        new = json.loads(done.stdout.strip().splitlines()[-1])
        print(f"  {name}: {time.perf_counter() - start:.0f} s", file=sys.stderr, flush=True)
        rows += new
    if out is not None:
        import pandas as pd

        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        pd.DataFrame(rows).to_csv(out / "scale.csv", index=False, float_format="%.6g")
    return rows


def _shown(argv):
    """The options of the command line, without --out (a local path)."""
    shown, skip = [], False
    for item in argv:
        if skip or item == "--out":
            skip = not skip
            continue
        shown.append(item)
    return "".join(f" {item}" for item in shown)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--rows", default=",".join(ROWS), help=f"comma-separated: {', '.join(ROWS)}"
    )
    parser.add_argument("--quick", action="store_true", help="smaller scenes, fewer repeats")
    parser.add_argument("--out", default=str(HERE / "results"), help="folder of scale.csv/.md")
    parser.add_argument(
        "--blas-threads",
        type=int,
        default=None,
        help="set OPENBLAS/OMP/MKL_NUM_THREADS for the rows (default: as the environment has it)",
    )
    parser.add_argument("--row", help=argparse.SUPPRESS)
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser.parse_args(argv)
    if args.row:
        print(json.dumps(run_row(args.row, args.quick)))
        return
    names = [name for name in args.rows.split(",") if name]
    unknown = set(names) - set(ROWS)
    if unknown:
        parser.error(f"unknown rows: {', '.join(sorted(unknown))}")
    header = (
        f"load average at start: {os.getloadavg()[0]:.2f} ({os.cpu_count()} CPUs), "
        f"python {sys.version.split()[0]}, numpy {np.__version__}, BLAS threads "
        + (str(args.blas_threads) if args.blas_threads is not None else "as the environment")
    )
    print(header, flush=True)
    start = time.perf_counter()
    rows = run_all(names, args.quick, args.out, args.blas_threads)
    table = markdown(rows)
    total = f"whole run: {time.perf_counter() - start:.0f} s"
    print("\n" + table + "\n\n" + total)
    Path(args.out, "scale.md").write_text(
        f"# Time and peak memory by scene size\n\n`python benchmarks/scale.py{_shown(argv)}`"
        f"\n\n{header}\n\n{table}\n\n{total}\n"
    )


if __name__ == "__main__":
    main()
