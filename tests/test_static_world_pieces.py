"""A background in pieces that no single one spans (``variant="sweep"``).

A FlyingThings3D-like camera view: the backdrop is met at two depths, its two pieces
farther apart than tau, neither spanning half of the scene alone; six objects in front,
each with its own motion; the flow is a network's (noise that grows with range, and the
nearer piece's flow off by a few centimetres as a whole). The static world is the union
of the pieces that move with the backdrop, named and reported as one cluster.
"""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mmreg import MultiModelRegistration
from mmreg._array.moments import group_moments
from mmreg.em._static_world import SPANS_THE_SCENE, spanning_union, widest_cluster
from mmreg.metrics import objects_found

pytestmark = pytest.mark.filterwarnings("ignore:No radius tried")

TAU = 5.0
# The camera's motion, the static world's in its frame.
CAMERA = (Rotation.from_euler("xyz", [1.0, 5.0, 0.5], degrees=True).as_matrix(), [0.3, 0.1, -1.0])


def _wall(rng, n, x, y, z):
    return np.column_stack([rng.uniform(*x, n), rng.uniform(*y, n), rng.uniform(*z, n)])


def _spread(points):
    return np.sqrt(((points - points.mean(axis=0)) ** 2).sum(axis=1).mean())


def _scene(seed=0, bias=0.025, slow=None):
    """a, b, labels (0: the background's two pieces, 1-6: objects) and the far piece's
    and near piece's rows. ``bias``: how far the network shifts the near piece's flow as
    a whole; ``slow``: the translation of object 1 relative to the static world, if it
    is to move slowly (otherwise every object moves by a metre or so)."""
    rng = np.random.default_rng(seed)
    far = _wall(rng, 1000, (-14.0, -5.0), (-4.0, 4.0), (29.0, 31.0))
    near = _wall(rng, 300, (8.0, 13.0), (-3.0, 1.0), (21.5, 22.5))
    centres = [[-9, -2, 12], [-4, 3, 15], [0, -3, 11], [4, 2, 17], [8, -3, 13], [11, 3, 16]]
    boxes = [c + rng.uniform(-1.0, 1.0, (400, 3)) for c in centres]
    a = np.vstack([far, near, *boxes])
    labels = np.repeat(np.arange(7), [len(far) + len(near)] + [len(box) for box in boxes])
    rotation, translation = CAMERA
    b = a @ rotation.T + translation
    for k, centre in enumerate(centres, start=1):
        own = Rotation.from_euler("xyz", rng.uniform(-8, 8, 3), degrees=True).as_matrix()
        shift = rng.uniform(0.6, 1.4, 3) * rng.choice([-1, 1], 3)
        if k == 1 and slow is not None:
            own, shift = np.eye(3), np.asarray(slow, dtype=float)
        rows = labels == k
        # The object turns about its own centre, then the camera moves.
        moved = (a[rows] - centre) @ own.T + centre + shift
        b[rows] = moved @ rotation.T + translation
    # A network's flow: errors that grow with range, and a coherent offset on a patch.
    ranges = np.linalg.norm(a, axis=1)
    b += rng.normal(size=a.shape) * (0.002 + 0.00001 * ranges**2)[:, None]
    near_rows = np.arange(len(far), len(far) + len(near))
    b[near_rows] += bias * np.array([0.6, 0.0, 0.8])
    return a, b, labels, np.arange(len(far)), near_rows


def test_the_scene_has_the_pieces_the_test_is_about():
    a, _, labels, far, near = _scene()
    scene = _spread(a)
    # Neither piece spans half of the scene alone; together they do, with room.
    assert _spread(a[far]) < 0.4 * scene and _spread(a[near]) < 0.2 * scene
    assert _spread(a[labels == 0]) > 0.6 * scene
    gaps = np.linalg.norm(a[far][:, None, :] - a[near][None, :, :], axis=2)
    assert gaps.min() > 1.5 * TAU


def test_a_background_in_pieces_is_named_and_whole():
    a, b, labels, _, _ = _scene()
    est = MultiModelRegistration(tau=TAU, random_state=0).fit(np.hstack([a, b]))
    static = est.static_cluster_
    assert static >= 0
    np.testing.assert_array_equal(est.labels_ == static, labels == 0)
    assert not est.moving_[static]
    assert objects_found(labels, est.labels_, objects=np.arange(1, 7)) == 1.0
    assert est.n_clusters_ <= 1.1 * 7


def test_an_object_moving_slowly_is_not_swallowed():
    # 0.4 m relative to the static world: eight times min_motion, far beyond the noise.
    a, b, labels, _, _ = _scene(slow=[0.0, 0.0, 0.4])
    est = MultiModelRegistration(tau=TAU, random_state=0).fit(np.hstack([a, b]))
    static = est.static_cluster_
    np.testing.assert_array_equal(est.labels_ == static, labels == 0)
    slow_object = np.bincount(est.labels_[labels == 1]).argmax()
    assert slow_object != static and est.moving_[slow_object]


def test_spanning_union_by_hand():
    # The union's spread and ranges computed from the points, against the rule's.
    a, _, labels, far, near = _scene()
    pieces = labels.copy()
    pieces[near] = 7
    moments = group_moments(a, a, pieces, 8)
    members = np.eye(8, dtype=bool)
    members[0, 7] = members[7, 0] = True
    assert widest_cluster(moments) == -1
    union = a[labels == 0]
    assert _spread(union) ** 2 >= SPANS_THE_SCENE**2 * _spread(a) ** 2
    rms_range = np.sqrt((np.linalg.norm(union, axis=1) ** 2).mean())
    assert all(
        rms_range > np.sqrt((np.linalg.norm(a[pieces == k], axis=1) ** 2).mean())
        for k in range(1, 7)
    )
    assert spanning_union(moments, members) in (0, 7)
    # Without the shared motion no union spans: the pieces stay unnamed.
    assert spanning_union(moments, np.eye(8, dtype=bool)) == -1


def test_objects_that_move_alike_around_the_origin_are_not_a_background():
    # Two far-apart objects with one motion span the scene, but the origin sits among
    # the objects (Table I's layout, a LiDAR's): no view, nothing is behind anything.
    rng = np.random.default_rng(1)
    centres = np.array([[-8.0, 0, 0], [8.0, 0, 0], [0, 0, 0.0], [0, 4.0, 0], [0, -4.0, 0]])
    a = np.vstack([c + rng.uniform(-1, 1, (200, 3)) for c in centres])
    labels = np.repeat(np.arange(5), 200)
    moments = group_moments(a, a, labels, 5)
    members = np.eye(5, dtype=bool)
    members[0, 1] = members[1, 0] = True
    assert widest_cluster(moments) == -1
    assert spanning_union(moments, members) == -1
    # Seen by a camera 20 m away instead, the pair behind the others is the background.
    seen = a + [0.0, 0.0, 20.0]
    seen[labels < 2, 2] += 6.0
    assert spanning_union(group_moments(seen, seen, labels, 5), members) in (0, 1)
