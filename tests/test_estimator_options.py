"""n_jobs, verbose and the ScaleWarning for a tau larger than the whole scene."""

import re
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from scipy.spatial import cKDTree
from sklearn.base import BaseEstimator, ClusterMixin
from sklearn.cluster import KMeans

import mmreg._array.flow
import mmreg.em._gate
import mmreg.em._robust
from mmreg import MultiModelRegistration
from mmreg._array.neighbors import query_workers
from mmreg.datasets import make_flying_things, make_scene, make_street
from mmreg.estimators import ScaleWarning

sys.path.insert(0, str(Path(__file__).resolve().parent))
from conftest import split_init  # noqa: E402


@pytest.fixture(scope="module")
def scene():
    return make_scene(n_objects=3, n_points=600, noise=0.01, outlier_fraction=0.05, random_state=0)


# --------------------------------------------------------------------------- n_jobs
def test_query_workers_has_scikit_learns_meaning(monkeypatch):
    monkeypatch.setattr(mmreg._array.neighbors, "cpu_count", lambda: 8)
    assert [query_workers(n) for n in (None, 1, 3, -1, -2, -8, -20)] == [1, 1, 3, 8, 7, 1, 1]
    with pytest.raises(ValueError, match="n_jobs=0"):
        query_workers(0)


class _SpyTree(cKDTree):
    """A k-d tree that records the ``workers`` of every query."""

    seen = []

    def query(self, *args, **kwargs):
        _SpyTree.seen.append(kwargs.get("workers", 1))
        return super().query(*args, **kwargs)


@pytest.mark.parametrize("variant", ["robust", "paper", "sweep"])
def test_n_jobs_reaches_the_tree_queries_and_changes_nothing(scene, variant, monkeypatch):
    init = KMeans(20, n_init=1, random_state=0).fit_predict(scene.a)
    one = MultiModelRegistration(init=init, variant=variant, random_state=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        one.fit(scene.X)
        for module in (mmreg._array.neighbors, mmreg.em._robust):
            monkeypatch.setattr(module, "cKDTree", _SpyTree)
        _SpyTree.seen = []
        two = MultiModelRegistration(init=init, variant=variant, random_state=0, n_jobs=2)
        two.fit(scene.X)
    assert _SpyTree.seen and set(_SpyTree.seen) == {2}
    assert_array_equal(one.labels_, two.labels_)
    assert_array_equal(one.rotations_, two.rotations_)
    _SpyTree.seen = []
    assert_array_equal(two.predict(scene.X), one.predict(scene.X))
    two.score(scene.X)
    assert set(_SpyTree.seen) <= {2}


class _Recorder(ClusterMixin, BaseEstimator):
    """A clusterer that records the n_jobs it was fitted with."""

    fitted_with = []

    def __init__(self, n_jobs=None):
        self.n_jobs = n_jobs

    def fit(self, X, y=None):
        _Recorder.fitted_with.append(self.n_jobs)
        self.labels_ = KMeans(6, n_init=1, random_state=0).fit_predict(X)
        return self


def test_n_jobs_reaches_an_initialiser_that_has_none_of_its_own(scene):
    _Recorder.fitted_with = []
    MultiModelRegistration(init=_Recorder(), n_jobs=3).fit(scene.X)
    MultiModelRegistration(init=_Recorder(n_jobs=1), n_jobs=3).fit(scene.X)
    MultiModelRegistration(init=_Recorder()).fit(scene.X)
    assert _Recorder.fitted_with == [3, 1, None]


def test_n_jobs_zero_is_a_clear_error(scene):
    with pytest.raises(ValueError, match="n_jobs=0"):
        MultiModelRegistration(init=split_init(scene.labels), n_jobs=0).fit(scene.X)


# --------------------------------------------------------------------------- verbose
LINE = re.compile(r"^iteration \d+, clusters \d+, .*dropped \d+, outliers \d+, .*changed \d+$")


@pytest.mark.parametrize("variant", ["robust", "paper", "sweep"])
def test_verbose_prints_one_line_per_iteration(scene, variant, capsys):
    init = split_init(scene.labels, pieces=3)
    MultiModelRegistration(init=init, variant=variant, random_state=0).fit(scene.X)
    assert capsys.readouterr().out == ""
    est = MultiModelRegistration(init=init, variant=variant, random_state=0, verbose=1)
    est.fit(scene.X)
    lines = capsys.readouterr().out.splitlines()
    if variant != "paper":  # the robust loops end with what the result holds
        assert lines.pop() == f"result: clusters {est.n_clusters_}"
    assert len(lines) == est.n_iter_ >= 1
    assert all(LINE.match(line) for line in lines), lines
    assert [int(line.split(",")[0].split()[1]) for line in lines] == list(range(1, est.n_iter_ + 1))
    # The last iteration settled everything: nothing changed.
    assert lines[-1].endswith("changed 0")


# --------------------------------------------------------------------------- ScaleWarning
def diagonal(points):
    return float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))


@pytest.mark.parametrize("variant", ["robust", "paper"])
def test_tau_far_larger_than_the_scene_warns(variant):
    # Two objects that move alike, 4 m apart: a tau 3 times the scene's diagonal joins them.
    rng = np.random.default_rng(0)
    a = np.vstack([rng.uniform(0, 1, (100, 3)), rng.uniform(5, 6, (100, 3))])
    X = np.hstack([a, a + [0.5, 0.0, 0.0]])
    init = np.repeat([0, 1, 2, 3], 50)
    tau = 3 * diagonal(a)
    with pytest.warns(ScaleWarning, match="diagonal of the a-points' bounding box"):
        merged = MultiModelRegistration(tau=tau, init=init, variant=variant).fit(X)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ScaleWarning)
        apart = MultiModelRegistration(tau=diagonal(a) / 3, init=init, variant=variant).fit(X)
        MultiModelRegistration(tau=None, init=init, variant=variant).fit(X)
    first = np.arange(len(X)) < 100
    # No cluster spans both objects, unless tau spans the scene.
    assert not set(apart.labels_[first]) & set(apart.labels_[~first])
    if variant == "robust":  # what the warning is about: the objects merge
        assert merged.n_clusters_ == 1


@pytest.mark.parametrize("factor", [0.5, 2.0])
def test_scale_warning_about_the_diagonal_fires_only_above_it(factor):
    scene = make_scene(n_objects=3, n_points=900, random_state=1)
    est = MultiModelRegistration(tau=factor * diagonal(scene.a))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        est._warn_if_tau_off_scale(scene.a)
    messages = [str(w.message) for w in caught if issubclass(w.category, ScaleWarning)]
    assert len(messages) == (factor > 1)


@pytest.mark.parametrize(
    ("make", "tau"),
    [
        (lambda seed: make_scene(object_size=3.0, random_state=seed), 1.5),  # Table I
        (lambda seed: make_scene(n_points=3000, random_state=seed), 1.5),  # 1 m objects
        (lambda seed: make_flying_things(random_state=seed), 5.0),  # Fig. 2
        (lambda seed: make_street(random_state=seed), 5.0),
    ],
    ids=["table1", "small_objects", "flying_things", "street"],
)
def test_the_papers_settings_do_not_warn(make, tau):
    scene = make(0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ScaleWarning)
        MultiModelRegistration(tau=tau)._warn_if_tau_off_scale(scene.a)
    # Not even close: the gate is a small part of the scene.
    assert tau < diagonal(scene.a) / 4
