"""Input checks shared by the metrics: label pairs, motion pairs and correspondences."""

import numpy as np
from sklearn.utils import check_array

from mmreg._validation import check_labels, split_correspondences

__all__ = ["check_correspondences", "check_label_pair", "check_transforms"]


def check_label_pair(labels_true, labels_pred):
    """Validate two integer label arrays of the same length; return them as ``intp``.

    Raises ``ValueError`` for arrays that are not 1-D, differ in length, are empty or
    hold NaN, and ``TypeError`` for labels that are not integers.
    """
    true = np.asarray(labels_true)
    labels_true = check_labels(true, len(true) if true.ndim else 0, name="labels_true")
    pred = np.asarray(labels_pred)
    if pred.ndim == 1 and len(pred) != len(labels_true):
        raise ValueError(
            f"labels_true and labels_pred have different lengths ({len(labels_true)} and "
            f"{len(pred)}); both need one label per correspondence."
        )
    labels_pred = check_labels(pred, len(labels_true), name="labels_pred")
    if len(labels_true) == 0:
        raise ValueError("labels_true and labels_pred are empty; there is nothing to score.")
    return labels_true, labels_pred


def check_correspondences(X, n_samples):
    """Validate stacked correspondences ``[a | b]`` with ``n_samples`` rows; return ``(a, b)``."""
    X = check_array(X, dtype=np.float64, input_name="X")
    if len(X) != n_samples:
        raise ValueError(
            f"X has {len(X)} correspondences but the labels have length {n_samples}; "
            "one label per row of X is needed."
        )
    return split_correspondences(X)


def check_transforms(transforms, labels, dim, *, name):
    """Validate a motion pair ``(rotations, translations)`` for the clusters in ``labels``.

    Parameters
    ----------
    transforms : tuple of (array-like of shape (K, d, d), array-like of shape (K, d))
    labels : ndarray of shape (n,)
        Checked labels; every non-negative label must index a motion.
    dim : int or None
        Required point dimension ``d``; None accepts any.
    name : str
        Argument name for error messages.

    Returns
    -------
    rotations : ndarray of shape (K, d, d)
    translations : ndarray of shape (K, d)
    """
    if not isinstance(transforms, (tuple, list)) or len(transforms) != 2:
        raise TypeError(
            f"{name} must be a pair (rotations, translations) of arrays of shapes "
            f"(K, d, d) and (K, d); got {type(transforms).__name__}."
        )
    rotations = np.asarray(transforms[0], dtype=float)
    translations = np.asarray(transforms[1], dtype=float)
    if rotations.ndim != 3 or rotations.shape[1] != rotations.shape[2]:
        raise ValueError(
            f"The rotations of {name} must have shape (K, d, d); got {rotations.shape}."
        )
    k, d = rotations.shape[:2]
    if translations.shape != (k, d):
        raise ValueError(
            f"The translations of {name} must have shape {(k, d)} to match its rotations "
            f"{rotations.shape}; got {translations.shape}."
        )
    if dim is not None and d != dim:
        raise ValueError(f"{name} holds {d}-D motions but the points are {dim}-D.")
    if not (np.all(np.isfinite(rotations)) and np.all(np.isfinite(translations))):
        raise ValueError(f"{name} contains NaN or infinity.")
    top = int(labels.max()) if len(labels) else -1
    if top >= k:
        raise ValueError(
            f"The labels use cluster {top} but {name} holds only {k} motions; cluster j "
            "moves by rotations[j], translations[j]."
        )
    return rotations, translations
