"""Initial clusters given in advance: image masks (e.g. SegmentAnything) or plain labels."""

import numpy as np
from sklearn.base import _fit_context
from sklearn.utils._param_validation import StrOptions

from mmreg._validation import check_labels, compact_labels
from mmreg.init._masks import OVERLAP_RULES, UNCOVERED_RULES, masks_to_labels
from mmreg.init._partition import PartitionInitializer

__all__ = ["PrecomputedLabels", "PrecomputedMasks"]


class _FixedPartition(PartitionInitializer):
    """A partition of the fitted correspondences themselves, which new rows cannot join."""

    def _assign(self, points):
        if len(points) != len(self.labels_):
            raise ValueError(
                f"{type(self).__name__} labels the {len(self.labels_)} correspondences it was "
                f"fitted on, one per row in order; got {len(points)} rows."
            )
        return self.labels_


class PrecomputedMasks(_FixedPartition):
    """Initial clusters from image masks, such as SegmentAnything's (SAM), via pixels.

    Each correspondence ``(a_i, b_i)`` belongs to the mask that covers the pixel
    ``pixels[i]`` of its a-point in the image the masks were computed on.

    Parameters
    ----------
    masks : list of ndarray, list of dict, or ndarray
        A list of ``H x W`` boolean masks; SAM's automatic-mask-generator output (a list
        of dicts with a boolean ``"segmentation"``; ``"area"`` and ``"predicted_iou"`` are
        not used); an ``(n_masks, H, W)`` boolean array; or an ``H x W`` integer label
        image, negative where no mask is. See :func:`load_masks` for files.
    pixels : array-like of shape (n_samples, 2)
        Integer pixel ``(column, row)`` of each a-point, in the order of the rows of ``X``.
    overlap : {"smallest", "largest", "first"}, default="smallest"
        Which mask a pixel covered by several belongs to: the one of fewest pixels (SAM
        nests parts in wholes; the part wins, so the partition is the finest), of most
        pixels, or the first in ``masks``. Ties go to the earlier mask.
    uncovered : {"unassigned", "nearest"}, default="unassigned"
        Correspondences whose pixel no mask covers get ``-1`` (no initial cluster: the
        EM offers them to every cluster within ``tau``), or the mask of the nearest
        covered pixel.

    Attributes
    ----------
    labels_ : ndarray of shape (n_samples,)
        Cluster of each correspondence in ``0..n_clusters_-1``; ``-1`` for none.
    n_clusters_ : int
        Number of masks that cover at least one correspondence.
    mask_ids_ : ndarray of shape (n_clusters_,)
        The mask of each cluster: its index in ``masks``, or its value in the label image.
    n_features_in_ : int
        Number of columns of ``X`` (``2 * d``).

    See Also
    --------
    PrecomputedLabels : Initial clusters given as labels.
    load_masks : Read masks saved as ``.npy`` or ``.npz``.

    Notes
    -----
    The masks are parameters: nothing is checked until ``fit``, and cloning (e.g. in
    :class:`~sklearn.model_selection.GridSearchCV`) copies them. ``transform(X)`` accepts
    only the fitted rows (the pixels belong to them) and returns the sparse one-hot
    membership matrix ``(n_samples, n_clusters_)``.

    References
    ----------
    A. Kirillov et al., "Segment Anything", ICCV 2023.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.init import PrecomputedMasks
    >>> whole = np.ones((4, 4), dtype=bool)
    >>> part = np.zeros((4, 4), dtype=bool)
    >>> part[:2, :2] = True
    >>> pixels = np.array([[0, 0], [1, 1], [3, 3], [2, 3]])   # (column, row)
    >>> X = np.random.default_rng(0).normal(size=(4, 6))
    >>> init = PrecomputedMasks([whole, part], pixels).fit(X)
    >>> init.labels_, init.mask_ids_
    (array([1, 1, 0, 0]), array([0, 1]))
    """

    _parameter_constraints: dict = {
        "masks": ["array-like"],
        "pixels": ["array-like"],
        "overlap": [StrOptions(set(OVERLAP_RULES))],
        "uncovered": [StrOptions(set(UNCOVERED_RULES))],
    }

    def __init__(self, masks, pixels, *, overlap="smallest", uncovered="unassigned"):
        self.masks = masks
        self.pixels = pixels
        self.overlap = overlap
        self.uncovered = uncovered

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, X, y=None):
        """Label each correspondence of ``X`` with the mask at its pixel.

        Parameters
        ----------
        X : array-like of shape (n_samples, 2 * d)
            Stacked correspondences ``[a | b]``, one per row of ``pixels``.
        y : Ignored
            Not used, present for API consistency.

        Returns
        -------
        self : PrecomputedMasks
            The fitted initialiser.
        """
        points = self._validate_points(X, reset=True)
        if len(self.pixels) != len(points):
            raise ValueError(
                f"pixels has {len(self.pixels)} rows but X has {len(points)} "
                "correspondences; one pixel per correspondence is needed."
            )
        mask_labels = masks_to_labels(
            self.masks, self.pixels, overlap=self.overlap, uncovered=self.uncovered
        )
        self.labels_, self.n_clusters_ = compact_labels(mask_labels)
        self.mask_ids_ = np.unique(mask_labels[mask_labels >= 0])
        return self


class PrecomputedLabels(_FixedPartition):
    """Initial clusters given as one label per correspondence.

    Parameters
    ----------
    labels : array-like of shape (n_samples,)
        Integer cluster of each correspondence, in the order of the rows of ``X``;
        negative for none.

    Attributes
    ----------
    labels_ : ndarray of shape (n_samples,)
        The labels renumbered ``0..n_clusters_-1`` in increasing order; ``-1`` for none.
    n_clusters_ : int
        Number of distinct non-negative labels.
    n_features_in_ : int
        Number of columns of ``X`` (``2 * d``).

    See Also
    --------
    PrecomputedMasks : Initial clusters from image masks.

    Notes
    -----
    An array passed as ``init`` to :class:`~mmreg.MultiModelRegistration` does the same;
    this class makes the labels an estimator, so that they can sit in a pipeline or be
    compared with other initialisers in a parameter search. ``transform(X)`` accepts only
    the fitted rows and returns the sparse one-hot membership matrix.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.init import PrecomputedLabels
    >>> X = np.random.default_rng(0).normal(size=(5, 6))
    >>> PrecomputedLabels([7, 7, 3, -1, 3]).fit_predict(X)
    array([ 1,  1,  0, -1,  0])
    """

    _parameter_constraints: dict = {"labels": ["array-like"]}

    def __init__(self, labels):
        self.labels = labels

    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, X, y=None):
        """Check the labels against ``X``.

        Parameters
        ----------
        X : array-like of shape (n_samples, 2 * d)
            Stacked correspondences ``[a | b]``, one per label.
        y : Ignored
            Not used, present for API consistency.

        Returns
        -------
        self : PrecomputedLabels
            The fitted initialiser.
        """
        points = self._validate_points(X, reset=True)
        labels = check_labels(self.labels, len(points), name="labels")
        self.labels_, self.n_clusters_ = compact_labels(labels)
        return self
