"""The static world without the majority rule (``variant="sweep"``).

In a crowded FlyingThings3D-like scene the background holds 10-45 % of the points and
lies in pieces at several depths (a backdrop and still objects); it is named static
because it spans the scene, and its pieces become one cluster. Scenes of objects alone
have no static world, whatever the objects' shares. A caller who knows the ego motion
names the static world with it.
"""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mmreg import MultiModelRegistration
from mmreg._array.moments import group_moments
from mmreg._validation import check_ego_motion
from mmreg.datasets import make_scene
from mmreg.datasets._flying_things import make_flying_things
from mmreg.em._static_world import widest_cluster
from mmreg.metrics import objects_found

# Small scenes: the default initial clustering asks for more clusters than they allow.
pytestmark = pytest.mark.filterwarnings("ignore:No radius tried")

CROWDED = {"n_points": 3000, "image_size": (135, 240), "corruption": False, "sam_masks": False}


def _crowded(n_objects, seed):
    # Two still objects besides the backdrop: the static world at three depths.
    return make_flying_things(n_objects, n_static=2, random_state=seed, **CROWDED)


@pytest.mark.parametrize(
    ("n_objects", "seed", "low", "high"),
    [(60, 1, 0.15, 0.25), (90, 0, 0.08, 0.15), (25, 0, 0.40, 0.48)],
    ids=["20%", "10%", "45%"],
)
def test_a_crowded_scene_names_its_background_whatever_its_share(n_objects, seed, low, high):
    scene = _crowded(n_objects, seed)
    background = scene.labels == 0
    # The share the test is about, and the pieces at several depths.
    assert low < background.mean() < high
    assert len(np.unique(scene.instance_labels[background])) >= 2
    est = MultiModelRegistration(tau=5.0, random_state=0).fit(scene.X)
    static = est.static_cluster_
    assert static >= 0
    # The whole background is the static cluster, and nothing else is.
    np.testing.assert_array_equal(est.labels_ == static, background)
    assert not est.moving_[static] and est.moving_[np.arange(est.n_clusters_) != static].all()


def test_an_object_filling_most_of_the_view_is_not_the_static_world():
    # An object near the camera holds 62 % of the points, the background 11 %: the
    # majority is an object's, and the background, which spans the scene, wins over it.
    scene = _crowded(120, 0)
    background = scene.labels == 0
    assert np.bincount(scene.labels)[1:].max() > 0.6 * len(scene.labels)
    assert background.mean() < 0.15
    est = MultiModelRegistration(tau=5.0, random_state=0).fit(scene.X)
    assert est.static_cluster_ >= 0
    np.testing.assert_array_equal(est.labels_ == est.static_cluster_, background)


def test_every_object_of_the_crowded_scene_is_still_found():
    scene = _crowded(60, 1)
    ids, counts = np.unique(scene.labels[scene.labels > 0], return_counts=True)
    est = MultiModelRegistration(tau=5.0, random_state=0).fit(scene.X)
    assert objects_found(scene.labels, est.labels_, objects=ids[counts >= 10]) == 1.0
    assert est.n_clusters_ <= len(ids) + 1


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("shapes", ["primitives", "meshes"])
@pytest.mark.parametrize("same_motion", [0, 2])
def test_objects_alone_have_no_static_world(seed, shapes, same_motion):
    # Table I's scenes: seven objects of one size, no background. None spans the scene
    # (each spreads over at most 0.36 of it), so none is named static, not even the
    # three that move alike (the paper's Exp. 3).
    scene = make_scene(
        n_points=3500,
        shapes=shapes,
        object_size=3.0 if shapes == "meshes" else 1.0,
        same_motion=same_motion,
        random_state=seed,
    )
    est = MultiModelRegistration(tau=1.5, random_state=0).fit(scene.X)
    assert est.static_cluster_ == -1
    assert est.moving_.all()


def _three_objects(seed=0):
    """Three boxes 10 m apart, none holding half of the points, with their motions."""
    rng = np.random.default_rng(seed)
    sizes = [400, 350, 250]
    centers = [[0.0, 0.0, 10.0], [10.0, 0.0, 10.0], [0.0, 10.0, 10.0]]
    a = np.vstack([c + rng.uniform(-1, 1, (n, 3)) for c, n in zip(centers, sizes, strict=True)])
    labels = np.repeat(np.arange(3), sizes)
    motions = [
        (Rotation.from_euler("z", 1.0, degrees=True).as_matrix(), np.array([0.1, 0.0, 0.0])),
        (Rotation.from_euler("x", 10.0, degrees=True).as_matrix(), np.array([0.0, 1.0, 0.0])),
        (Rotation.from_euler("y", -8.0, degrees=True).as_matrix(), np.array([1.0, 0.0, 0.5])),
    ]
    b = np.empty_like(a)
    for k, (rotation, translation) in enumerate(motions):
        b[labels == k] = a[labels == k] @ rotation.T + translation
    return np.hstack([a, b]), labels, motions


@pytest.mark.parametrize("target", [0, 2])
def test_a_given_ego_motion_names_the_cluster_that_moves_with_it(target):
    X, labels, motions = _three_objects()
    est = MultiModelRegistration(tau=2.0, random_state=0)
    assert est.fit(X).static_cluster_ == -1  # no majority, no background
    rotation, translation = motions[target]
    est.fit(X, ego_motion=(rotation, translation))
    assert est.static_cluster_ >= 0
    np.testing.assert_array_equal(est.labels_ == est.static_cluster_, labels == target)
    assert est.moving_.sum() == 2
    # The same motion as a homogeneous matrix.
    matrix = np.eye(4)
    matrix[:3, :3], matrix[:3, 3] = rotation, translation
    again = MultiModelRegistration(tau=2.0, random_state=0).fit(X, ego_motion=matrix)
    np.testing.assert_array_equal(again.labels_, est.labels_)


def test_an_ego_motion_that_no_cluster_follows_names_none():
    X, _, _ = _three_objects()
    far_off = (Rotation.from_euler("z", 30.0, degrees=True).as_matrix(), np.array([5.0, 5, 5]))
    est = MultiModelRegistration(tau=2.0, random_state=0).fit(X, ego_motion=far_off)
    assert est.static_cluster_ == -1
    assert est.moving_.all()


@pytest.mark.parametrize(
    ("ego_motion", "message"),
    [
        (np.eye(3), r"\(4, 4\) homogeneous matrix"),
        ((np.eye(3), np.zeros(2)), r"t of shape \(3,\)"),
        ((np.eye(3),), "sequence of 1"),
        ((2 * np.eye(3), np.zeros(3)), "not a rotation"),
        ((np.diag([1.0, 1.0, -1.0]), np.zeros(3)), "not a rotation"),
        ((np.full((3, 3), np.nan), np.zeros(3)), "NaN"),
    ],
)
def test_a_bad_ego_motion_is_one_clear_error(ego_motion, message):
    X, _, _ = _three_objects()
    with pytest.raises(ValueError, match=message):
        MultiModelRegistration(tau=2.0).fit(X, ego_motion=ego_motion)


def test_ego_motion_is_for_the_sweep_variant_only():
    X, _, motions = _three_objects()
    with pytest.raises(ValueError, match="variant='sweep'"):
        MultiModelRegistration(tau=2.0, variant="paper").fit(X, ego_motion=motions[0])


def test_check_ego_motion_reads_both_forms():
    rotation = Rotation.from_euler("z", 3.0, degrees=True).as_matrix()
    matrix = np.eye(4)
    matrix[:3, :3], matrix[:3, 3] = rotation, [1.0, 2.0, 3.0]
    for given in (matrix, (rotation, [1.0, 2.0, 3.0])):
        R, t = check_ego_motion(given, 3)
        np.testing.assert_array_equal(R, rotation)
        np.testing.assert_array_equal(t, [1.0, 2.0, 3.0])
    assert check_ego_motion(None, 3) is None


def test_the_widest_cluster_spans_the_scene_by_hand():
    # Cluster 0: two points 2 w apart (spread w); cluster 1: two points at the same place,
    # D above their centre (spread 0).
    w, D = 3.0, 4.0
    a = np.array([[-w, 0, 0], [w, 0, 0], [0, D, 0], [0, D, 0]], dtype=float)
    labels = np.array([0, 0, 1, 1])
    moments = group_moments(a, a, labels, 2)
    # Centre (0, D/2, 0); every point is w^2 + D^2/4 or D^2/4 away (squared).
    scene = (2 * (w**2 + D**2 / 4) + 2 * D**2 / 4) / 4
    assert w**2 / scene > 0.5**2  # spread 3 against the scene's sqrt(8.5)
    assert widest_cluster(moments) == 0
    # Farther apart, the pair makes the scene wider than twice the wide cluster.
    a[2:, 1] = 20.0
    assert w**2 < 0.5**2 * (2 * (w**2 + 100) + 2 * 100) / 4
    assert widest_cluster(group_moments(a, a, labels, 2)) == -1
    # Candidates restrict the choice.
    assert widest_cluster(moments, candidates=[1]) == -1
