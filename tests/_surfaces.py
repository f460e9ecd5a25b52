"""Point sets on box surfaces, for the tests' generated sweeps."""

import numpy as np


def area_weighted_box(center, size, n, rng):
    """``n`` points uniform on the surface of an axis-aligned box (area-weighted faces)."""
    size = np.asarray(size)
    areas = np.array([size[1] * size[2], size[0] * size[2], size[0] * size[1]]).repeat(2)
    face = rng.choice(6, n, p=areas / areas.sum())
    points = rng.uniform(-0.5, 0.5, (n, 3))
    points[np.arange(n), face // 2] = np.where(face % 2, 0.5, -0.5)
    return points * size + center


def grid(low, high, step=0.1):
    """Points every ``step`` in the box ``[low, high]`` (a plane where one side is 0)."""
    axes = [np.arange(lo, hi + 1e-9, step) for lo, hi in zip(low, high, strict=True)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
