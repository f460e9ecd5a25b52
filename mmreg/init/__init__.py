"""Initial clusterings for the EM: the partition Theorem 1 starts from.

Every initialiser is a scikit-learn clusterer and transformer on the stacked
correspondences ``X = [a | b]``: ``fit`` sets ``labels_`` (``-1``: no initial cluster),
``transform`` returns the sparse one-hot membership matrix. Pass one as ``init`` to
:class:`~mmreg.MultiModelRegistration`; its parameters can then be searched as
``init__<name>``.
"""

from mmreg.init._base import BaseInitializer
from mmreg.init._dbscan import DBSCANClustering
from mmreg.init._describe import describe_partition
from mmreg.init._euclidean import EuclideanClustering, euclidean_clustering
from mmreg.init._masks import load_masks, masks_to_labels
from mmreg.init._precomputed import PrecomputedLabels, PrecomputedMasks
from mmreg.init._resolve import initial_labels

__all__ = [
    "BaseInitializer",
    "DBSCANClustering",
    "EuclideanClustering",
    "PrecomputedLabels",
    "PrecomputedMasks",
    "describe_partition",
    "euclidean_clustering",
    "initial_labels",
    "load_masks",
    "masks_to_labels",
]
