"""A track's claim keeps the pieces its evidence is on.

A motion along a parked car's side slides the side onto itself: the ego motion and the
track's motion explain it alike, so it can join a cyclist's claim beside it (a generated
64-beam log had a cyclist's track carry 573 points of a parked car for five frames). Its
island of the claim holds almost none of the evidence (points only the track's motion
explains), and it is left out; a car whose rings are islands of their own keeps them all.
"""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from mmreg.tracking._log import _on_evidence

_CELL = 0.25


def _blob(rng, centre, n, size):
    return rng.uniform(-0.5, 0.5, (n, 3)) * size + centre


def test_a_side_that_only_slides_is_left_out():
    rng = np.random.default_rng(0)
    cyclist = _blob(rng, [10.0, -6.0, 0.0], 400, [1.8, 0.5, 1.6])
    parked = _blob(rng, [10.0, -7.2, 0.0], 600, [4.0, 0.3, 1.5])  # 0.8 m from the cyclist
    points = np.vstack([cyclist, parked])
    rows = np.arange(len(points))
    # A third of the cyclist; one noisy point of the parked car (a share 0.0017 of it;
    # the claim's is 0.135, the cut a tenth of that).
    shown = np.r_[np.arange(0, 400, 3), [400]]
    still = np.arange(len(points)) >= 400  # the ego motion explains the parked car
    kept = _on_evidence(points, rows, shown, still, _CELL)
    assert kept.tolist() == list(range(400))
    # The same piece, hidden from the next sweep (nothing explains it): the track's.
    kept = _on_evidence(points, rows, shown, np.zeros(len(points), bool), _CELL)
    assert kept.tolist() == rows.tolist()


def test_a_car_whose_rings_are_islands_keeps_them_all():
    # A far car: three rings 0.7 m apart (each its own island); each ring's rear end,
    # which its motion uncovers, is its evidence.
    x = np.linspace(0.0, 4.5, 40)
    rings = [np.c_[x + 30.0, np.full(40, 2.0), np.full(40, z)] for z in (-1.0, -0.3, 0.4)]
    points = np.vstack(rings)
    shown = np.concatenate([np.arange(k * 40, k * 40 + 6) for k in range(3)])
    # Their sides slide along themselves: the ego motion explains all but the rear ends.
    still = np.ones(len(points), dtype=bool)
    still[shown] = False
    kept = _on_evidence(points, np.arange(len(points)), shown, still, _CELL)
    assert len(kept) == len(points)


@given(seed=st.integers(0, 2**16))
def test_the_pieces_kept_do_not_depend_on_the_rows_order(seed):
    rng = np.random.default_rng(seed)
    mover = _blob(rng, [0.0, 0.0, 0.0], 300, [0.6, 0.6, 0.6])  # one island
    slab = _blob(rng, [0.0, 3.0, 0.0], 600, [3.0, 0.2, 1.0])
    points = np.vstack([mover, slab])
    rows = np.arange(len(points))
    # Evidence on every voxel of the mover; one point of the slab (a share 0.0017, the
    # cut 0.1 x 301/900 = 0.033).
    shown = np.r_[np.arange(300), 300 + rng.integers(600)]
    still = np.arange(len(points)) >= 300
    kept = _on_evidence(points, rows, shown, still, _CELL)
    order = rng.permutation(len(rows))
    again = _on_evidence(points, rows[order], shown, still[order], _CELL)
    assert sorted(again.tolist()) == kept.tolist()
    assert kept.tolist() == list(range(300))
