"""Warnings of the estimators, initialisers and measures name the caller's line."""

import warnings

import numpy as np
import pytest
from sklearn.exceptions import ConvergenceWarning, UndefinedMetricWarning

from mmreg import MultiModelRegistration, SweepRegistration
from mmreg.datasets import make_scene
from mmreg.estimators import ScaleWarning
from mmreg.init import DBSCANClustering, EuclideanClustering
from mmreg.init._dbscan import AllOutliersWarning
from mmreg.metrics import per_point_error, rotation_error

SCENE = make_scene(n_objects=3, n_points=300, random_state=0)
IDENTITY = (np.eye(3)[None], np.zeros((1, 3)))
THREE = (np.stack([np.eye(3)] * 3), np.zeros((3, 3)))


def _fits():
    X = SCENE.X
    init = np.arange(300) % 40
    return [
        (
            ConvergenceWarning,
            lambda: MultiModelRegistration(variant="paper", max_iter=1, init=init).fit(X),
        ),
        (ScaleWarning, lambda: MultiModelRegistration(tau=1e-5).fit(X)),
        (ScaleWarning, lambda: MultiModelRegistration(tau=1e6).fit(X)),
        # Nested: SweepRegistration fits a MultiModelRegistration inside its own fit.
        (
            ScaleWarning,
            lambda: SweepRegistration(MultiModelRegistration(tau=1e6)).fit(X, sweep=SCENE.b),
        ),
        (AllOutliersWarning, lambda: DBSCANClustering(eps=1e-9).fit(X)),
        (UserWarning, lambda: EuclideanClustering(n_clusters=1000).fit(X)),
        (
            UndefinedMetricWarning,
            lambda: rotation_error(np.full(300, -1), SCENE.labels, IDENTITY, THREE),
        ),
        (
            UndefinedMetricWarning,
            lambda: per_point_error(X, np.full(300, -1), SCENE.labels, IDENTITY, THREE),
        ),
    ]


@pytest.mark.parametrize("case", range(len(_fits())))
def test_warning_names_this_file(case):
    category, call = _fits()[case]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        call()
    ours = [w for w in caught if issubclass(w.category, category)]
    assert ours, [str(w.message) for w in caught]
    for w in ours:
        assert w.filename == __file__, (w.filename, str(w.message))
