"""Scene flow from fitted clusters: every point moved by the rigid motion of its object."""

import numpy as np

from mmreg._array.geometry import apply_motions
from mmreg._array.neighbors import lookup_tree

__all__ = ["rigid_flow"]


def rigid_flow(a, labels, rotations, translations, *, workers=1):
    """The rigid scene flow ``R_j a_i + t_j - a_i`` of every point.

    A point of cluster ``j`` moves with its cluster's motion. A point labelled ``-1``
    (an outlier: its correspondence was wrong, not the point) moves with the cluster
    of its nearest clustered point, the object it lies on; with no cluster at all its
    flow is NaN.

    Parameters
    ----------
    a : ndarray of shape (n, d)
        The points.
    labels : ndarray of shape (n,)
        Cluster of each point, ``-1`` for outliers.
    rotations : ndarray of shape (K, d, d)
    translations : ndarray of shape (K, d)
    workers : int, default=1
        Threads of the nearest-neighbour query for the outliers (``-1``: every core).

    Returns
    -------
    flow : ndarray of shape (n, d)

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg._array.flow import rigid_flow
    >>> a = np.array([[0.0, 0, 0], [1, 0, 0], [1.1, 0, 0], [9, 0, 0]])
    >>> labels = np.array([0, 1, -1, 1])
    >>> rotations = np.stack([np.eye(3)] * 2)
    >>> translations = np.array([[0.0, 0, 0], [0, 2, 0]])
    >>> rigid_flow(a, labels, rotations, translations)[:, 1]
    array([0., 2., 2., 2.])
    """
    a = np.asarray(a, dtype=float)
    labels = np.asarray(labels)
    outliers = np.flatnonzero(labels < 0)
    clustered = np.flatnonzero(labels >= 0)
    if len(outliers) and not len(clustered):
        return np.full(a.shape, np.nan)
    labels = labels.copy()
    if len(outliers):
        _, nearest = lookup_tree(a[clustered]).query(a[outliers], workers=workers)
        labels[outliers] = labels[clustered[nearest]]
    return apply_motions(a, rotations, translations, labels) - a
