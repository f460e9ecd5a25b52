"""Small movers: walkers and cyclists among standing people and bins, in raw sweeps.

    python benchmarks/small_movers.py --min-island-size 30 12

``SweepRegistration(random_state=0)`` with its defaults (but ``min_island_size``, when
given) on ray-cast streets (``mmreg.datasets.make_lidar_sweeps``: 2 moving cars, 4 parked
ones, poles, buildings, the road in, 1 cm range noise) with 4 walkers (1.0-1.8 m/s), 2
cyclists (3-7 m/s) and 5 standing things (people standing, bins: the static world), for
every combination of

- the sensor: 32 beams, 1084 azimuths (a nuScenes HDL-32E sweep) and 64 beams, 2048
  azimuths (a KITTI HDL-64E one);
- the interval and the ego car's speed: 0.1 s at 10 m/s (a 10 Hz sensor) and 0.5 s at
  7 m/s (nuScenes' 2 Hz keyframes);
- seeds 0-5 (``--seeds``).

Each ``--min-island-size`` value (several compare settings on the same scenes, fitted
one after the other in one process; none: the estimator's default) writes a table.
Columns: walkers found / those seen, cyclists found / those seen (found: a cluster flagged
``moving_`` covers the object with IoU >= 0.5; seen: 10 points or more in the first
sweep), cars found (cars of 50 points or more, as ``frame_rate.py`` counts them), static
clusters called moving (clusters flagged moving whose points are mostly label 0), of
those the ones whose points are mostly standing things, and the fit's median time (s, a
shared 2-core machine). Writes benchmarks/results/small_movers.md (``--out``).
"""

import argparse
import itertools
import time
import warnings
from pathlib import Path

import numpy as np

from mmreg import SweepRegistration
from mmreg.datasets import make_lidar_sweeps

SENSORS = ((32, 1084), (64, 2048))  # beams, azimuths
STEPS = ((0.1, 10.0), (0.5, 7.0))  # interval (s), ego speed (m/s)
STREET = {"n_moving": 2, "n_walkers": 4, "n_cyclists": 2, "n_standing": 5}
MIN_POINTS = 10  # a walker or cyclist seen with fewer is not counted
MIN_CAR_POINTS = 50


def _best_iou(object_mask, labels, clusters):
    best = 0.0
    for c in clusters:
        cluster = labels == c
        best = max(best, (cluster & object_mask).sum() / (cluster | object_mask).sum())
    return best


def _score(scene, est):
    """Found and seen per kind, static clusters called moving, of them standing things."""
    moving = np.flatnonzero(est.moving_)
    counts = {kind: [0, 0] for kind in ("walker", "cyclist", "car")}
    for k, kind in enumerate(scene.kinds):
        mask = scene.labels == k
        if k == 0 or mask.sum() < (MIN_CAR_POINTS if kind == "car" else MIN_POINTS):
            continue
        counts[kind][1] += 1
        counts[kind][0] += _best_iou(mask, est.labels_, moving) >= 0.5
    static = scene.labels == 0
    static_moving = [c for c in moving if static[est.labels_ == c].mean() > 0.5]
    standing = sum(scene.standing[est.labels_ == c].mean() > 0.5 for c in static_moving)
    return counts, len(static_moving), int(standing)


def _rows(seeds, settings):
    """One row per sensor and step for every setting, the settings fitted on the same scenes."""
    tables = {setting: [] for setting in settings}
    for (beams, azimuths), (interval, speed) in itertools.product(SENSORS, STEPS):
        totals = {
            setting: {"found": {}, "static": 0, "standing": 0, "s": []} for setting in settings
        }
        for seed in seeds:
            scene = make_lidar_sweeps(
                **STREET,
                interval=interval,
                ego_speed=speed,
                n_beams=beams,
                n_azimuths=azimuths,
                random_state=seed,
            )
            for setting in settings:
                options = {} if setting is None else {"min_island_size": setting}
                start = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    est = SweepRegistration(random_state=0, **options).fit(
                        scene.a, sweep=scene.sweep
                    )
                total = totals[setting]
                total["s"].append(time.perf_counter() - start)
                counts, static_moving, standing = _score(scene, est)
                for kind, (found, seen) in counts.items():
                    old = total["found"].get(kind, (0, 0))
                    total["found"][kind] = (old[0] + found, old[1] + seen)
                total["static"] += static_moving
                total["standing"] += standing
        for setting in settings:
            total = totals[setting]
            row = {"beams": beams, "interval (s)": interval, "ego speed (m/s)": speed}
            for kind in ("walker", "cyclist", "car"):
                found, seen = total["found"][kind]
                row[f"{kind}s found"] = f"{found} / {seen}"
            row["static called moving"] = total["static"]
            row["of them standing things"] = total["standing"]
            row["s (median)"] = f"{np.median(total['s']):.1f}"
            tables[setting].append(row)
            print(f"min_island_size={setting}:", row, flush=True)
    return tables


def _table(rows):
    header = list(rows[0])
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return lines + ["| " + " | ".join(str(row[h]) for h in header) + " |" for row in rows]


def main(argv=None):
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seeds", type=int, default=6)
    parser.add_argument(
        "--min-island-size",
        type=int,
        nargs="+",
        default=[None],
        help="SweepRegistration's min_island_size; several values: one table each",
    )
    parser.add_argument("--out", default=str(Path(__file__).parent / "results" / "small_movers.md"))
    args = parser.parse_args(argv)
    tables = _rows(range(args.seeds), args.min_island_size)
    options = " ".join(str(m) for m in args.min_island_size if m is not None)
    command = "python benchmarks/small_movers.py" + (
        f" --min-island-size {options}" if options else ""
    )
    lines = [
        "# Small movers (benchmarks/small_movers.py)",
        "",
        f"`{command}`: `SweepRegistration(random_state=0)` on `make_lidar_sweeps(n_moving=2, "
        "n_walkers=4, n_cyclists=2, n_standing=5)` streets, seeds "
        f"0-{args.seeds - 1} per row (sums over the seeds). Found: a cluster flagged moving "
        f"covers the object with IoU >= 0.5; walkers and cyclists of {MIN_POINTS} points or "
        f"more in the first sweep are counted, cars of {MIN_CAR_POINTS} or more. Static "
        "called moving: clusters flagged moving whose points are mostly the static world's; "
        "of them standing things: those whose points are mostly a standing person's or a "
        "bin's. 32 beams: 1084 azimuths; 64 beams: 2048.",
    ]
    for setting, rows in tables.items():
        title = "the default" if setting is None else f"`min_island_size={setting}`"
        lines += ["", f"## {title}", ""] + _table(rows)
    Path(args.out).write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
