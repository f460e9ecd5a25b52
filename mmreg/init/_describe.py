"""Inspect an initial partition: cluster sizes and tau-connectivity (Definition 2)."""

import numpy as np
import pandas as pd
from sklearn.utils.validation import check_array

from mmreg._array.connectivity import cluster_components
from mmreg._validation import check_labels, split_correspondences

__all__ = ["describe_partition"]


def describe_partition(labels, X, tau=None):
    """One row per cluster: its size and, given ``tau``, whether it is tau-connected.

    Definition 2 of the paper asks of a good initial clustering that every cluster be
    ``tau``-connected (any two of its a-points joined by a chain of its own a-points with
    gaps of at most ``tau``) and that each object have one cluster much larger than the
    others meeting it; this table shows both.

    Parameters
    ----------
    labels : array-like of shape (n_samples,)
        Integer cluster of each correspondence; negative for none.
    X : array-like of shape (n_samples, 2 * d)
        Stacked correspondences ``[a | b]``; connectivity is measured on the a-points.
    tau : float or None, default=None
        Largest gap allowed within a cluster. None leaves out the connectivity columns.

    Returns
    -------
    table : pandas.DataFrame
        Sorted by decreasing size, with columns ``cluster`` (the label), ``size``,
        ``fraction`` (of all correspondences) and, with ``tau``, ``n_pieces`` (number of
        ``tau``-connected pieces) and ``tau_connected`` (``n_pieces == 1``).
        ``table.attrs`` holds ``n_clusters``, ``n_unassigned`` (rows with a negative
        label) and ``tau``.

    Notes
    -----
    The pieces come from a grid of cells of diameter ``tau``
    (:func:`mmreg.theory.tau_components`), never from the list of all pairs closer than
    ``tau``, so a large ``tau`` on a dense cloud costs no more than a small one.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.init import describe_partition
    >>> a = np.array([[0.0, 0, 0], [0.5, 0, 0], [5, 0, 0], [9, 0, 0], [9.4, 0, 0]])
    >>> X = np.hstack([a, a])
    >>> table = describe_partition([0, 0, 0, 1, -1], X, tau=1.0)
    >>> table[["cluster", "size", "n_pieces", "tau_connected"]]
       cluster  size  n_pieces  tau_connected
    0        0     3         2          False
    1        1     1         1           True
    >>> table.attrs["n_unassigned"]
    1
    """
    X = check_array(X, dtype=np.float64)
    points = split_correspondences(X)[0]
    labels = check_labels(labels, len(points), name="labels")
    clustered = labels >= 0
    clusters, sizes = np.unique(labels[clustered], return_counts=True)
    table = pd.DataFrame(
        {"cluster": clusters, "size": sizes, "fraction": sizes / max(len(labels), 1)}
    )
    if tau is not None:
        if not tau > 0:
            raise ValueError(f"tau must be positive; got {tau}.")
        pieces = cluster_components(points, labels, tau)[clusters]
        table["n_pieces"] = pieces
        table["tau_connected"] = pieces == 1
    table = table.sort_values(["size", "cluster"], ascending=[False, True], kind="stable")
    table = table.reset_index(drop=True)
    table.attrs.update(
        n_clusters=len(clusters), n_unassigned=int(np.count_nonzero(~clustered)), tau=tau
    )
    return table
