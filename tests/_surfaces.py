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
