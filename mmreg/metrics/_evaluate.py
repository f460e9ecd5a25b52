"""Run several estimators on several scenes and tabulate the measures."""

import time
from collections.abc import Mapping

import numpy as np
import pandas as pd
from sklearn.base import clone
from sklearn.metrics import adjusted_rand_score

from mmreg.metrics._clustering import iou_score, misclassification_error
from mmreg.metrics._point import per_point_error
from mmreg.metrics._pose import _pose_errors, estimated_poses, ground_truth_poses

__all__ = ["evaluate"]

COLUMNS = [
    "method",
    "scene",
    "iou",
    "per_point_error",
    "rotation_error",
    "translation_error",
    "misclassification_error",
    "ari",
    "runtime_s",
    "n_clusters",
]


def _unpack_scene(scene):
    """``(X, labels, transforms or None)`` of a Bunch/mapping or a tuple."""
    if isinstance(scene, Mapping) or hasattr(scene, "X"):
        get = scene.get if isinstance(scene, Mapping) else lambda k: getattr(scene, k, None)
        X, labels = get("X"), get("labels")
        if X is None or labels is None:
            raise ValueError("A scene given as a Bunch or dict needs the keys 'X' and 'labels'.")
        rotations, translations = get("rotations"), get("translations")
    elif isinstance(scene, (tuple, list)) and len(scene) in (2, 4):
        X, labels = scene[0], scene[1]
        rotations, translations = (scene[2], scene[3]) if len(scene) == 4 else (None, None)
    else:
        raise TypeError(
            "Each scene must be a Bunch (e.g. from make_scene) or dict with 'X' and "
            "'labels' (optionally 'rotations' and 'translations'), or a tuple "
            f"(X, labels) or (X, labels, rotations, translations); got {type(scene).__name__}."
        )
    if rotations is None or translations is None:
        return X, labels, None
    return X, labels, (rotations, translations)


def _scene_items(scenes):
    if isinstance(scenes, Mapping):
        return list(scenes.items())
    if isinstance(scenes, (list, tuple)):
        return list(enumerate(scenes))
    raise TypeError(
        "scenes must be a list of scenes or a dict name -> scene; wrap a single scene in a list."
    )


def evaluate(estimators, scenes):
    """Fit every estimator on every scene and measure the result.

    Each estimator is cloned, fitted with ``fit_predict`` on the scene's correspondences
    (the clusters found on the scene itself are scored, as in the paper) and timed. The
    motions of the clusters are the estimator's ``rotations_`` and ``translations_``, or,
    for an estimator without them (e.g. a scikit-learn clusterer), fitted by Horn's
    method on its clusters. The true motions are the scene's ``rotations`` and
    ``translations`` when given, else fitted by Horn's method on its true clusters
    (:func:`ground_truth_poses`).

    Parameters
    ----------
    estimators : dict of str -> estimator
        Method name to (unfitted) estimator; each is cloned before every fit.
    scenes : list or dict of str -> scene
        Each scene is a :class:`~sklearn.utils.Bunch` or dict with ``X`` (stacked
        correspondences ``[a | b]``) and ``labels`` (true objects, ``-1`` outliers), and
        optionally ``rotations`` and ``translations`` (as returned by
        :func:`~mmreg.datasets.make_scene`); or a tuple ``(X, labels)`` or
        ``(X, labels, rotations, translations)``. A list's scenes are named by position.

    Returns
    -------
    results : pandas.DataFrame
        One row per (method, scene), in the order given, with columns ``method``,
        ``scene``, ``iou`` (:func:`iou_score`), ``per_point_error``,
        ``rotation_error`` (degrees), ``translation_error``,
        ``misclassification_error``, ``ari`` (adjusted Rand index, with ``-1`` as one
        cluster), ``runtime_s`` (wall-clock seconds of the fit) and ``n_clusters``
        (estimated clusters, outliers not counted). For seaborn, reshape to long form
        with ``results.melt(id_vars=["method", "scene"])``.

    Examples
    --------
    >>> import numpy as np
    >>> from sklearn.cluster import KMeans
    >>> from mmreg.datasets import make_scene
    >>> from mmreg.metrics import evaluate
    >>> scenes = [make_scene(n_objects=2, n_points=100, random_state=s) for s in (0, 1)]
    >>> table = evaluate({"kmeans": KMeans(n_clusters=2, random_state=0)}, scenes)
    >>> table.shape
    (2, 10)
    >>> table.columns[:4].tolist()
    ['method', 'scene', 'iou', 'per_point_error']
    """
    if not isinstance(estimators, Mapping) or not estimators:
        raise TypeError("estimators must be a non-empty dict of name -> estimator.")
    items = _scene_items(scenes)
    rows = []
    for name, estimator in estimators.items():
        for scene_name, scene in items:
            X, labels_true, transforms_true = _unpack_scene(scene)
            if transforms_true is None:
                transforms_true = ground_truth_poses(X, labels_true)
            fitted = clone(estimator)
            start = time.perf_counter()
            labels_pred = np.asarray(fitted.fit_predict(X))
            runtime = time.perf_counter() - start
            transforms_pred = estimated_poses(fitted, X, labels_pred)
            rot_err, trans_err = _pose_errors(
                labels_true, labels_pred, transforms_true, transforms_pred
            )
            n_clusters = getattr(fitted, "n_clusters_", None)
            if n_clusters is None:
                n_clusters = len(np.unique(labels_pred[labels_pred >= 0]))
            rows.append(
                {
                    "method": name,
                    "scene": scene_name,
                    "iou": iou_score(labels_true, labels_pred),
                    "per_point_error": per_point_error(
                        X, labels_true, labels_pred, transforms_true, transforms_pred
                    ),
                    "rotation_error": rot_err,
                    "translation_error": trans_err,
                    "misclassification_error": misclassification_error(labels_true, labels_pred),
                    "ari": adjusted_rand_score(labels_true, labels_pred),
                    "runtime_s": runtime,
                    "n_clusters": int(n_clusters),
                }
            )
    return pd.DataFrame(rows, columns=COLUMNS)
