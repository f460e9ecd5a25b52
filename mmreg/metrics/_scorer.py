"""Scorers for ``GridSearchCV`` and ``cross_validate``: ``scorer(estimator, X, y) -> float``.

``y`` holds the ground-truth labels of the correspondences ``X`` (``-1`` for outliers).
Every scorer labels ``X`` with the fitted estimator's ``predict``; a pose scorer also
needs the true motions, which it fits by Horn's method on the true clusters of ``X``
(how the paper obtains ground truth on FlyingThings3D and KITTI), unless they are given.

A registration estimator finds the objects of one scene, so a cross-validation split
should hold a whole scene, scored on the same correspondences it was fitted on:

>>> import numpy as np
>>> from sklearn.model_selection import GridSearchCV
>>> from mmreg import MultiModelRegistration
>>> from mmreg.datasets import make_scene
>>> from mmreg.metrics import make_iou_scorer
>>> scene = make_scene(n_objects=2, n_points=200, random_state=0)
>>> init = np.arange(200) % 8                       # any initial over-segmentation
>>> everything = np.arange(200)
>>> search = GridSearchCV(
...     MultiModelRegistration(init=init, variant="paper"), {"max_iter": [0, 10]},
...     scoring=make_iou_scorer(), cv=[(everything, everything)],
... ).fit(scene.X, scene.labels)
>>> search.best_params_, float(search.best_score_)
({'max_iter': 10}, 1.0)

Several scenes stacked into one ``X`` (with labels in ``y``) are scored one per split
with ``cv=[(rows_of_scene, rows_of_scene) for each scene]``.
"""

import numpy as np
from sklearn.metrics import adjusted_rand_score, make_scorer

from mmreg.metrics._checks import check_transforms
from mmreg.metrics._clustering import iou_score, misclassification_error
from mmreg.metrics._point import per_point_error
from mmreg.metrics._pose import (
    _pose_errors,
    estimated_poses,
    ground_truth_poses,
)

__all__ = [
    "make_iou_scorer",
    "make_misclassification_scorer",
    "make_per_point_error_scorer",
    "make_rotation_error_scorer",
    "make_translation_error_scorer",
    "registration_scorers",
]


def _rotation(X, labels_true, labels_pred, transforms_true, transforms_pred):
    return _pose_errors(labels_true, labels_pred, transforms_true, transforms_pred)[0]


def _translation(X, labels_true, labels_pred, transforms_true, transforms_pred):
    return _pose_errors(labels_true, labels_pred, transforms_true, transforms_pred)[1]


class _PoseErrorScorer:
    """``-error(X, y, estimator.predict(X), true motions, fitted motions)``."""

    def __init__(self, name, metric, transforms_true):
        self._name = name
        self._metric = metric
        self._transforms_true = transforms_true

    def __call__(self, estimator, X, y):
        if y is None:
            raise ValueError(
                f"The {self._name} scorer needs the ground-truth labels as y; pass y to "
                "fit of the search or to cross_validate."
            )
        labels_pred = estimator.predict(X)
        transforms_pred = estimated_poses(estimator, X, labels_pred)
        transforms_true = self._transforms_true
        if transforms_true is None:
            transforms_true = ground_truth_poses(X, y)
        # Lower errors are better: scorers are maximised, as for "neg_mean_squared_error".
        return -self._metric(X, y, labels_pred, transforms_true, transforms_pred)

    def __repr__(self):
        return f"make_{self._name}_scorer()"


def _check_fixed_transforms(transforms_true):
    if transforms_true is None:
        return None
    # Labels are only known at scoring time; an empty array checks shapes alone.
    return check_transforms(
        transforms_true, np.empty(0, dtype=np.intp), None, name="transforms_true"
    )


def make_iou_scorer():
    """Scorer of the mean IoU (:func:`iou_score`) of ``estimator.predict(X)`` against ``y``.

    Returns
    -------
    scorer : callable
        ``scorer(estimator, X, y)``, greater is better.

    Examples
    --------
    >>> from sklearn.cluster import KMeans
    >>> from mmreg.metrics import make_iou_scorer
    >>> X = [[0.0], [0.1], [5.0], [5.1]]
    >>> kmeans = KMeans(n_clusters=2, n_init=1, random_state=0).fit(X)
    >>> make_iou_scorer()(kmeans, X, [0, 0, 1, 1])
    1.0
    """
    return make_scorer(iou_score)


def make_misclassification_scorer():
    """Scorer of ``-misclassification_error`` (:func:`misclassification_error`).

    Returns
    -------
    scorer : callable
        ``scorer(estimator, X, y)``, greater (closer to 0) is better.
    """
    return make_scorer(misclassification_error, greater_is_better=False)


def make_per_point_error_scorer(transforms_true=None):
    """Scorer of ``-per_point_error`` (:func:`per_point_error`) of a fitted estimator.

    Parameters
    ----------
    transforms_true : tuple of (array-like of shape (K, d, d), \\
            array-like of shape (K, d)), default=None
        Fixed true motions ``(rotations, translations)`` used for every split, e.g. a
        synthetic scene's; ``y`` must then number the objects like them. None fits them
        by Horn's method on the true clusters ``y`` of the scored ``X``
        (:func:`ground_truth_poses`).

    Returns
    -------
    scorer : callable
        ``scorer(estimator, X, y)`` returning minus the error, so greater is better.
        The estimated motions are the estimator's ``rotations_`` and ``translations_``,
        or fitted by Horn's method on its clusters if it has none.
    """
    return _PoseErrorScorer(
        "per_point_error", per_point_error, _check_fixed_transforms(transforms_true)
    )


def make_rotation_error_scorer(transforms_true=None):
    """Scorer of ``-rotation_error`` (:func:`rotation_error`, degrees) of a fitted estimator.

    Parameters
    ----------
    transforms_true : tuple of (array-like of shape (K, d, d), \\
            array-like of shape (K, d)), default=None
        Fixed true motions ``(rotations, translations)`` used for every split, e.g. a
        synthetic scene's; ``y`` must then number the objects like them. None fits them
        by Horn's method on the true clusters ``y`` of the scored ``X``
        (:func:`ground_truth_poses`).

    Returns
    -------
    scorer : callable
        ``scorer(estimator, X, y)`` returning minus the error, so greater is better.
        The estimated motions are the estimator's ``rotations_`` and ``translations_``,
        or fitted by Horn's method on its clusters if it has none.
    """
    return _PoseErrorScorer("rotation_error", _rotation, _check_fixed_transforms(transforms_true))


def make_translation_error_scorer(transforms_true=None):
    """Scorer of ``-translation_error`` (:func:`translation_error`) of a fitted estimator.

    Parameters
    ----------
    transforms_true : tuple of (array-like of shape (K, d, d), \\
            array-like of shape (K, d)), default=None
        Fixed true motions ``(rotations, translations)`` used for every split, e.g. a
        synthetic scene's; ``y`` must then number the objects like them. None fits them
        by Horn's method on the true clusters ``y`` of the scored ``X``
        (:func:`ground_truth_poses`).

    Returns
    -------
    scorer : callable
        ``scorer(estimator, X, y)`` returning minus the error, so greater is better.
        The estimated motions are the estimator's ``rotations_`` and ``translations_``,
        or fitted by Horn's method on its clusters if it has none.
    """
    return _PoseErrorScorer(
        "translation_error", _translation, _check_fixed_transforms(transforms_true)
    )


def registration_scorers(transforms_true=None):
    """All the measures as a dict of scorers, for multi-metric ``scoring=``.

    Parameters
    ----------
    transforms_true : tuple of (ndarray, ndarray), default=None
        Fixed true motions for the pose scorers; see :func:`make_rotation_error_scorer`.

    Returns
    -------
    scorers : dict
        ``"iou"``, ``"neg_per_point_error"``, ``"neg_rotation_error"``,
        ``"neg_translation_error"``, ``"neg_misclassification_error"`` and
        ``"adjusted_rand"``; greater is better for each. With ``GridSearchCV`` pass
        ``refit="iou"`` (or another key) to choose the best parameters.
    """
    return {
        "iou": make_iou_scorer(),
        "neg_per_point_error": make_per_point_error_scorer(transforms_true),
        "neg_rotation_error": make_rotation_error_scorer(transforms_true),
        "neg_translation_error": make_translation_error_scorer(transforms_true),
        "neg_misclassification_error": make_misclassification_scorer(),
        "adjusted_rand": make_scorer(adjusted_rand_score),
    }
