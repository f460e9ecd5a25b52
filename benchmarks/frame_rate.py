"""Frame rate and sensor: two raw sweeps of generated streets, any interval, any ego speed.

    python benchmarks/frame_rate.py

``SweepRegistration(random_state=0)`` with its defaults on ray-cast streets
(``mmreg.datasets.make_lidar_sweeps``: parked cars, poles, walls, the road in, 1 cm range
noise, 1024 azimuths), for every combination of

- the interval between the sweeps: 0.05 s (20 Hz), 0.1 s (10 Hz), 0.5 s (2 Hz keyframes);
- the ego car's speed: 3 m/s (the other cars then move up to 4-5 m a 2 Hz step relative
  to the world, beyond the 3 m guess of ``max_displacement="auto"``) and 10 m/s;
- the sensor: 32 beams (nuScenes-like) and 64 (KITTI HDL-64-like);
- seeds 0-3.

Columns: moving cars found (best IoU >= 0.5, cars of 50 points or more), static clusters
called moving (clusters flagged moving whose points are mostly the static world's), the
ego motion's rotation (deg) and translation (mm) errors, and the fit's time (s, a shared
2-core machine). Writes benchmarks/results/frame_rate.md.
"""

import argparse
import itertools
import time
import warnings
from pathlib import Path

import numpy as np

from mmreg import SweepRegistration
from mmreg._array.geometry import rotation_angle
from mmreg.datasets import make_lidar_sweeps
from mmreg.metrics import objects_found

INTERVALS = (0.05, 0.1, 0.5)
SPEEDS = (3.0, 10.0)
BEAMS = (32, 64)
MIN_CAR_POINTS = 50


def _row(interval, speed, beams, seeds):
    found = cars = static_moving = 0
    rotation, translation, seconds = [], [], []
    for seed in seeds:
        scene = make_lidar_sweeps(
            interval=interval, ego_speed=speed, n_beams=beams, n_azimuths=1024, random_state=seed
        )
        objects = [
            k
            for k in range(1, scene.labels.max() + 1)
            if (scene.labels == k).sum() >= MIN_CAR_POINTS
        ]
        start = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            est = SweepRegistration(random_state=0).fit(scene.a, sweep=scene.sweep)
        seconds.append(time.perf_counter() - start)
        if objects:
            share = objects_found(scene.labels, est.labels_, objects=objects, min_iou=0.5)
            found += round(share * len(objects))
            cars += len(objects)
        static = scene.labels == 0
        static_moving += sum(
            np.mean(static[est.labels_ == c]) > 0.5 for c in np.flatnonzero(est.moving_)
        )
        truth = scene.transforms[0]
        rotation.append(float(rotation_angle(est.ego_motion_[0], truth[:3, :3])))
        translation.append(1000 * np.linalg.norm(est.ego_motion_[1] - truth[:3, 3]))
    return {
        "interval (s)": interval,
        "ego speed (m/s)": speed,
        "beams": beams,
        "cars found": f"{found} of {cars}",
        "static called moving": int(static_moving),
        "rotation error (deg, max)": f"{max(rotation):.3f}",
        "translation error (mm, max)": f"{max(translation):.1f}",
        "s (median)": f"{np.median(seconds):.1f}",
    }


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--out", default=str(Path(__file__).parent / "results" / "frame_rate.md"))
    args = parser.parse_args(argv)
    rows = []
    for interval, speed, beams in itertools.product(INTERVALS, SPEEDS, BEAMS):
        rows.append(_row(interval, speed, beams, range(args.seeds)))
        print(rows[-1], flush=True)
    header = list(rows[0])
    lines = [
        "# Frame rate and sensor (benchmarks/frame_rate.py)",
        "",
        f"`python benchmarks/frame_rate.py`: `SweepRegistration(random_state=0)` with its "
        f"defaults on `make_lidar_sweeps` streets, seeds 0-{args.seeds - 1} per row (sums "
        "and the worst seed). Static called moving: clusters flagged moving whose points are "
        "mostly the static world's.",
        "",
        "| " + " | ".join(header) + " |",
        "|" + "---|" * len(header),
    ]
    lines += ["| " + " | ".join(str(row[h]) for h in header) + " |" for row in rows]
    Path(args.out).write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
