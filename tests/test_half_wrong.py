"""Half of the correspondences wrong (Table I, Exp. 2 scene: 7 meshes 3 m across, noise
3 cm, each wrong b-point moved 0.5-1.5 m): the robust variant finds the 7 objects; the
sweep variant's proposals add an eighth cluster of one object's wrong matches."""

import numpy as np
import pytest
from sklearn.metrics import adjusted_rand_score

from mmreg import MultiModelRegistration
from mmreg.datasets import add_wrong_correspondences, make_scene


@pytest.fixture(scope="module")
def half_wrong():
    scene = make_scene(noise=0.03, object_size=3.0, shapes="meshes", random_state=3)
    return add_wrong_correspondences(scene.X, scene.labels, 0.5, random_state=3)


def _objects_found(labels, truth):
    """Adjusted Rand index on the good correspondences, and the number of clusters."""
    good = truth >= 0
    return adjusted_rand_score(truth[good], labels[good]), int(labels.max()) + 1


@pytest.mark.parametrize(
    "params", [{"variant": "robust"}, {"skip_steps": ("proposals",)}], ids=["robust", "sweep"]
)
def test_seven_objects_without_the_sweep_proposals(half_wrong, params):
    X, truth = half_wrong
    est = MultiModelRegistration(tau=1.5, random_state=0, **params).fit(X)
    assert _objects_found(est.labels_, truth) == (1.0, 7)
    assert np.mean(est.labels_[truth < 0] < 0) > 0.95


@pytest.mark.xfail(
    strict=True,
    reason="the sweep variant's proposals (noise scale searched up to 10 % of the motion, "
    "from the identity when there is no static world) make one object's wrong matches a "
    "cluster of their own",
)
def test_seven_objects_with_the_sweep_proposals(half_wrong):
    X, truth = half_wrong
    est = MultiModelRegistration(tau=1.5, random_state=0).fit(X)
    assert _objects_found(est.labels_, truth)[1] == 7
