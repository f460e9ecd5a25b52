"""Moving islands that tear a part of them off: their motion explains it worse than the
ego motion does (a pole that a walker's motion takes along)."""

import numpy as np

from mmreg.sweeps._explained import EXPLAINED_SPACINGS, spacing_ratio
from mmreg.sweeps._islands import voxel_islands

__all__ = ["torn_islands"]

# A moving island is refused when the ego motion explains at least this share of a part
# of it and its own motion this share of the part's points fewer (a pole that a walker's
# motion takes along: 0.85 and 0.83-0.86 fewer; a sparse walker's rings, of fewer points
# than the parts asked for, 1.0 and 0.17-0.5 fewer).
_TORN_EXPLAINED = 0.5
_TORN_LOSS = 0.2


def torn_islands(a, islands, n_islands, moving, motions, at_rest, target, cell, min_size):
    """Moving islands that hold a part their motion explains clearly worse than the ego
    motion does.

    A part is an island of voxels of side ``cell`` of at least ``min_size`` points
    within a moving island; ``at_rest``: ``a`` moved by the ego motion. A point is
    explained within 2 of the second sweep's sampling spacings of a point of it (the
    slow movers' rule). Torn: the ego motion
    explains at least half of a part's points, and the island's motion a fifth of the
    part's points fewer. A point-to-plane cost, which chose the motion, cannot see it:
    a thin pole moved half a metre keeps points near some plane.
    """
    rows = np.flatnonzero((islands >= 0) & moving[np.maximum(islands, 0)])
    torn = np.zeros(n_islands, dtype=bool)
    parts, n_parts = voxel_islands(a[rows], cell, 1)
    if n_parts < 2:
        return torn
    owner = islands[rows]
    sweep, tree, normals = target
    rotations, translations = motions
    own = np.einsum("nij,nj->ni", rotations[owner], a[rows]) + translations[owner]
    sizes = np.bincount(parts, minlength=n_parts)
    shares = [
        np.bincount(
            parts,
            weights=spacing_ratio(moved, tree, sweep, normals)[0] <= EXPLAINED_SPACINGS,
            minlength=n_parts,
        )
        / np.maximum(sizes, 1)
        for moved in (at_rest[rows], own)
    ]
    worse = (
        (sizes >= min_size) & (shares[0] >= _TORN_EXPLAINED) & (shares[1] < shares[0] - _TORN_LOSS)
    )
    part_owner = np.zeros(n_parts, dtype=np.intp)
    part_owner[parts] = owner
    torn[part_owner[worse]] = True
    return torn
