"""Distances in units of the sweep's spacing (mmreg.sweeps._explained)."""

import warnings

import numpy as np
from scipy.spatial import cKDTree

from mmreg.sweeps._explained import spacing_ratio


def test_a_sweep_that_repeats_a_point_gives_infinite_ratios_without_a_warning():
    sweep = np.array([[0.0, 0, 0], [0.0, 0, 0], [5.0, 0, 0], [5.0, 1.0, 0]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ratio, nearest, _ = spacing_ratio(
            np.array([[0.0, 0, 10.0], [5.0, 0.5, 0]]), cKDTree(sweep), sweep
        )
    assert np.isinf(ratio[0]) and nearest[0] in (0, 1)
    assert ratio[1] == 0.5
