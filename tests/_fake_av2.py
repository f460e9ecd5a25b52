"""A small fake Argoverse 2 log for the runner's and the command line's tests.

Three sweeps from a car driving 1 m per sweep: a road (the ground, the first rows of each
sweep), a building and a car driving 1.5 m per sweep (0.5 m in the ego frame), each sweep
sampled anew; the car is annotated with a cuboid at every sweep.
"""

import shutil

import numpy as np

from mmreg.datasets import write_argoverse2_log

STAMPS = [315966265259836000 + k * 100_000_000 for k in range(3)]
SIZES = [(200, 250, 150), (180, 280, 130), (220, 230, 160)]  # road, building, car


def pose(x, y=0.0, z=0.0):
    """A 4x4 translation."""
    T = np.eye(4)
    T[:3, 3] = x, y, z
    return T


def box_surface(rng, n, low, high):
    """``n`` points on the faces of the box [low, high]."""
    low, high = np.asarray(low, float), np.asarray(high, float)
    points = rng.uniform(low, high, (n, 3))
    face = rng.integers(0, 3, n)
    points[np.arange(n), face] = np.where(rng.integers(0, 2, n), high[face], low[face])
    return points


def sweeps(seed=2):
    """The three sweeps by timestamp."""
    rng = np.random.default_rng(seed)
    out = {}
    for k, (n_road, n_building, n_car) in enumerate(SIZES):
        road = np.c_[rng.uniform(-20, 20, (n_road, 2)), np.zeros(n_road)]
        building = box_surface(rng, n_building, [-6, -8, 0.5], [-2, -4, 4]) - [k, 0, 0]
        car = box_surface(rng, n_car, [-2, -0.8, -0.5], [2, 0.8, 0.5]) + [8 + 0.5 * k, 3, 1]
        out[STAMPS[k]] = np.vstack([road, building, car])
    return out


def write_log(folder, *, annotations=True, map_=True, seed=2, annotated=STAMPS):
    """The log in ``folder``; without its annotations or its map on request."""
    cuboids = [
        dict(
            timestamp_ns=t,
            track_uuid="car-1",
            category="REGULAR_VEHICLE",
            size=(4.4, 1.8, 1.5),
            pose=pose(8.0 + 0.5 * k, 3, 1.0),
        )
        for k, t in enumerate(STAMPS)
        if t in annotated
    ]
    ego = {t: pose(1.0 * k) for k, t in enumerate(STAMPS)}
    log = write_argoverse2_log(folder, sweeps(seed), ego, cuboids)
    if not annotations:
        (log / "annotations.feather").unlink()
    if not map_:
        shutil.rmtree(log / "map")
    return log
