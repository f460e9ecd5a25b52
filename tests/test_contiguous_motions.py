"""Two motions that share one contiguous region, with no gap between them.

Found while timing the command line's Ctrl-C test: a 100 x 100 x 3 m slab of uniformly
spread points, 49 % standing still and 51 % moving 1 m along x. Three of the 100 initial
Euclidean clusters straddle the border; in the first iteration the merges chain through
them into one cluster with the mean motion (0.55 m, noise scale 0.15 m), and by the
second iteration every correspondence is an outlier (the paper variant keeps 14 clusters,
none empty). Real scenes rarely put two motions side by side without a gap, which is why
the shared real inputs and the generated benchmarks never met it.
"""

import numpy as np
import pytest

from mmreg import MultiModelRegistration


def _slab(n, seed=0):
    rng = np.random.default_rng(seed)
    a = rng.uniform([-50, -50, 0], [50, 50, 3], (n, 3))
    moving = ((a[:, 0] > 20) | (a[:, 1] > 20)).astype(int)
    b = a + moving[:, None] * [1.0, 0.0, 0.0] + rng.normal(0, 0.02, (n, 3))
    return np.hstack([a, b]), moving


@pytest.mark.filterwarnings("ignore")
@pytest.mark.xfail(strict=True, reason="merges chain through straddling initial clusters")
def test_two_touching_motions_keep_their_points():
    X, moving = _slab(20_000)
    est = MultiModelRegistration(tau=5.0, random_state=0).fit(X)
    # Far from any cut-off: today 100 % outliers; right is about 0 %.
    assert np.mean(est.labels_ < 0) < 0.5
    assert est.n_clusters_ >= 2
