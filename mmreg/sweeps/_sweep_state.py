"""One sweep and what registering it computes, each once, kept for every pair it is in.

In a LiDAR log every sweep is the second of one pair and the first of the next. What the
registration computes of a sweep alone -- its ground, k-d tree, surface normals, islands
-- depends on its points and on lengths the registration derives from ``tau``, never on
the other sweep: a :class:`SweepState` computes each on first use and keeps it, keyed by
the lengths it depends on, so that one state serves every pair with the same settings,
and the pairs give what independent fits give. The ego motion's voxel cloud is kept
too: each sweep's is laid out on a grid of its own frame, one for both pairs it is in.

The subsets a pair registers (the sweep without the ego vehicle's body, the points off
the ground) are states of their own, kept by their parent and keyed by their rows: a
subset asked for twice is computed once.
"""

import numpy as np

from mmreg._array.point_tree import PointTree
from mmreg.sweeps._ego_motion import fine_cloud
from mmreg.sweeps._ground import ground_mask, has_ground, is_z_up_sweep
from mmreg.sweeps._icp import SurfaceNormals
from mmreg.sweeps._islands import voxel_islands

__all__ = ["SweepState"]

# Neighbours of the surface normals (the point itself included), as multi_body_icp's.
_NORMAL_NEIGHBOURS = 10


class SweepState:
    """One sweep's points and, computed on first use and kept, what is made of them.

    Parameters
    ----------
    points : array-like of shape (n, 3)
        The sweep's valid returns (no NaN, no failed return at the origin), in its
        sensor's frame.
    workers : int, default=1
        Threads of the k-d tree queries of the normals (the answers are the same).

    Attributes
    ----------
    points : ndarray of shape (n, 3), float64

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.sweeps._sweep_state import SweepState
    >>> rng = np.random.default_rng(0)
    >>> state = SweepState(rng.uniform(0, 10, (500, 3)))
    >>> state.tree is state.tree, state.islands(1.0, 5) is state.islands(1.0, 5)
    (True, True)
    >>> keep = state.points[:, 0] > 5
    >>> state.subset(keep) is state.subset(keep.copy()), len(state.subset(keep).points)
    (True, 266)
    """

    def __init__(self, points, *, workers=1):
        self.points = np.asarray(points, dtype=np.float64)
        self.workers = workers
        self._memo = {}

    def __getstate__(self):
        # What it computed of its own points goes with it; the ego motion's clouds
        # (small_gicp's, which do not pickle) and the subsets' states are made again
        # where they are asked for.
        memo = {
            key: value
            for key, value in self._memo.items()
            if not (isinstance(key, tuple) and key[0] in ("ego_cloud", "subset"))
        }
        return {"points": self.points, "workers": self.workers, "_memo": memo}

    def learn(self, other):
        """Keep what ``other``, the state of the same points (a copy that went to another
        process), computed and this one did not; their normals are merged."""
        if other.points.shape != self.points.shape:
            raise ValueError("other must be the state of the same points.")
        for key, value in other._memo.items():
            if key not in self._memo:
                self._memo[key] = value
            elif key == "normals":
                self._memo[key].learn(value)

    def _cached(self, key, make):
        """``make()`` the first time ``key`` is asked for, the same object after."""
        try:
            return self._memo[key]
        except KeyError:
            value = self._memo[key] = make()
            return value

    # -------------------------------------------------------------- neighbourhoods
    @property
    def tree(self):
        """The k-d tree of the points (a :class:`~mmreg._array.point_tree.PointTree`:
        ``cKDTree``'s interface, twice its speed on nearest-point queries)."""
        return self._cached("tree", lambda: PointTree(self.points))

    @property
    def normals(self):
        """The points' :class:`~mmreg.sweeps._icp.SurfaceNormals` (10 neighbours), each
        normal computed when first asked for and kept."""
        return self._cached(
            "normals",
            lambda: SurfaceNormals(self.points, self.tree, _NORMAL_NEIGHBOURS, self.workers),
        )

    def target(self):
        """``(points, tree, normals)``: the sweep as an ICP's target."""
        return self.points, self.tree, self.normals

    def is_z_up(self):
        """Whether the points look like a LiDAR sweep with z up
        (:func:`~mmreg.sweeps._ground.is_z_up_sweep`)."""
        return self._cached("z_up", lambda: is_z_up_sweep(self.points))

    def islands(self, cell, min_size):
        """:func:`~mmreg.sweeps._islands.voxel_islands` of the points: ``(labels, K)``."""
        return self._cached(
            ("islands", float(cell), int(min_size)),
            lambda: voxel_islands(self.points, cell, min_size),
        )

    # ---------------------------------------------------------------- the ground
    def ground(self, tau):
        """Which points lie on the ground: Patchwork++ in units of ``tau``
        (:func:`~mmreg.sweeps._ground.ground_mask`)."""
        return self._cached(("ground", float(tau)), lambda: ground_mask(self.points, tau))

    def holds_ground(self, tau):
        """Whether the sweep is z-up and holds a ground (not the remnants of a removed
        one, :func:`~mmreg.sweeps._ground.has_ground`); the ground is segmented only for
        z-up sweeps."""
        return self.is_z_up() and self._cached(
            ("holds_ground", float(tau)), lambda: has_ground(self.points, self.ground(tau))
        )

    # ------------------------------------------------------------------- subsets
    def subset(self, rows):
        """The state of the points where ``rows`` (bool, one per point) is True, kept:
        the same object for the same rows."""
        rows = np.asarray(rows, dtype=bool)
        if rows.shape != (len(self.points),):
            raise ValueError(
                f"rows must have shape ({len(self.points)},), one bool per point; got {rows.shape}."
            )
        key = ("subset", np.packbits(rows).tobytes(), len(rows))

        return self._cached(key, lambda: SweepState(self.points[rows], workers=self.workers))

    # ------------------------------------------------------- the ego motion's cloud
    def ego_cloud(self, scale):
        """The ego motion's fine cloud of the points in units of ``scale``
        (:func:`~mmreg.sweeps._ego_motion.fine_cloud`): one for both pairs."""
        return self._cached(("ego_cloud", float(scale)), lambda: fine_cloud(self.points, scale))
