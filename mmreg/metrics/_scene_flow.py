"""The scene-flow community's measures: EPE3D, Acc3DS/R, Outliers3D, three-way and bucketed EPE.

Pure functions of flow arrays ``(n, d)`` (metres per frame pair; ``d = 3`` for scene
flow) and of boolean point masks, as the scene-flow papers and benchmarks define them:

* :func:`end_point_error` and :func:`scene_flow_metrics`: EPE3D, Acc3DS, Acc3DR and
  Outliers3D as in the evaluation code of HPLFlowNet (Gu et al., CVPR 2019), which
  PointPWC-Net, FLOT and most papers since reuse;
* :func:`dynamic_mask`, :func:`three_way_epe` and :func:`dynamic_iou`: the Argoverse 2
  scene-flow challenge's point classes and scores (``av2.evaluation.scene_flow.eval``),
  as also used by ZeroFlow and BucketedSceneFlowEval;
* :func:`bucketed_epe`: bucket normalised EPE, the Argoverse 2 2024 scene-flow
  challenge's measure (Khatri et al., ECCV 2024; BucketedSceneFlowEval), per class and
  speed bucket, each moving bucket's error divided by its speed;
* scorers for ``GridSearchCV`` that read a fitted estimator's ``flow_``
  (:func:`make_end_point_error_scorer`, :func:`make_bucketed_epe_scorer`,
  :func:`scene_flow_scorers`).

A registration estimator's flow is the rigid flow of its clusters,
``flow_[i] = R_j a_i + t_j - a_i`` for the cluster ``j`` of correspondence ``i``.
"""

import numpy as np
from sklearn.utils import check_array

__all__ = [
    "bucketed_epe",
    "dynamic_iou",
    "dynamic_mask",
    "end_point_error",
    "make_bucketed_epe_scorer",
    "make_end_point_error_scorer",
    "scene_flow_metrics",
    "scene_flow_scorers",
    "three_way_epe",
]

#: Added to the true flow's norm in the relative error, as in HPLFlowNet's
#: ``evaluation_utils.evaluate_3d`` (Argoverse 2's ``compute_accuracy`` adds 1e-10).
RELATIVE_ERROR_EPS = 1e-4

#: Argoverse 2's ``SCENE_FLOW_DYNAMIC_THRESHOLD``: 0.05 m between sweeps 0.1 s apart,
#: i.e. 0.5 m/s.
DYNAMIC_THRESHOLD = 0.05

#: BucketedSceneFlowEval's speed buckets (``BucketedEPEEvaluator``: ``bucket_max_speed
#: = 2.0``, ``num_buckets = 51``): edges 0, 0.04, ..., 2.0 metres per frame pair (0.4 m/s
#: wide at 10 Hz) and a last bucket from 2.0 m (20 m/s) up. The first bucket holds the
#: static points.
BUCKET_EDGES = np.append(np.linspace(0.0, 2.0, 51), np.inf)


def _check_flow_pair(flow_true, flow_pred, *, names=("flow_true", "flow_pred")):
    """Validate two flow arrays of the same shape ``(n, d)``, ``n >= 1``; return them as float64."""
    flow_true = check_array(flow_true, dtype=np.float64, input_name=names[0])
    flow_pred = check_array(flow_pred, dtype=np.float64, input_name=names[1])
    if flow_true.shape != flow_pred.shape:
        raise ValueError(
            f"{names[0]} and {names[1]} have different shapes ({flow_true.shape} and "
            f"{flow_pred.shape}); both need one flow vector per point."
        )
    return flow_true, flow_pred


def _check_mask(mask, n_samples, *, name):
    """Validate a 1-D boolean (or 0/1) mask of length ``n_samples``; return it as bool."""
    arr = np.asarray(mask)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be 1-D; got an array of shape {arr.shape}.")
    if len(arr) != n_samples:
        raise ValueError(
            f"{name} has length {len(arr)} but the flows have {n_samples} points; one "
            "value per point is needed."
        )
    if arr.dtype == bool:
        return arr
    if arr.dtype.kind not in "iuf":
        raise TypeError(f"{name} must be boolean; got dtype {arr.dtype}.")
    if arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or infinity.")
    if not np.all((arr == 0) | (arr == 1)):
        raise ValueError(f"{name} must be boolean (or 0/1); got other values.")
    return arr.astype(bool)


def _check_sample_weight(sample_weight, n_samples):
    """None or non-negative finite weights of length ``n_samples`` with a positive sum."""
    if sample_weight is None:
        return None
    weight = np.asarray(sample_weight, dtype=np.float64)
    if weight.ndim != 1 or len(weight) != n_samples:
        raise ValueError(
            f"sample_weight must have shape ({n_samples},), one weight per point; got "
            f"{weight.shape}."
        )
    if not np.all(np.isfinite(weight)):
        raise ValueError("sample_weight contains NaN or infinity.")
    if np.any(weight < 0) or not weight.sum() > 0:
        raise ValueError("sample_weight must be non-negative with a positive sum.")
    return weight


def _point_errors(flow_true, flow_pred):
    """Per-point end-point error ``||flow_pred - flow_true||_2``."""
    return np.linalg.norm(flow_pred - flow_true, axis=1)


def end_point_error(flow_true, flow_pred, *, sample_weight=None):
    """Mean end-point error (EPE3D): the mean distance between true and estimated flow.

    .. math::

        \\mathrm{EPE} = \\frac{1}{n} \\sum_i \\lVert \\hat f_i - f_i \\rVert_2

    in the units of the flow (metres for point clouds), weighted by ``sample_weight``
    if given. This is ``EPE3D`` of HPLFlowNet's evaluation code (Gu et al., CVPR 2019,
    ``evaluation_utils.evaluate_3d``) and the ``EPE`` of the Argoverse 2 scene-flow
    challenge.

    Parameters
    ----------
    flow_true : array-like of shape (n_samples, d)
        Ground-truth flow of each point.
    flow_pred : array-like of shape (n_samples, d)
        Estimated flow of each point.
    sample_weight : array-like of shape (n_samples,), default=None
        Non-negative weights; None weighs every point equally.

    Returns
    -------
    epe : float
        Non-negative; 0 for a perfect estimate.

    References
    ----------
    X. Gu, Y. Wang, C. Wu, Y. J. Lee and P. Wang, "HPLFlowNet: Hierarchical Permutohedral
    Lattice FlowNet for Scene Flow Estimation on Large-scale Point Clouds", CVPR 2019.

    Examples
    --------
    >>> from mmreg.metrics import end_point_error
    >>> truth = [[1.0, 0, 0], [0, 0, 0]]
    >>> end_point_error(truth, [[1.0, 0.3, 0.4], [0, 0, 0]])   # errors 0.5 and 0
    0.25
    >>> end_point_error(truth, [[1.0, 0.3, 0.4], [0, 0, 0]], sample_weight=[1, 0])
    0.5
    """
    flow_true, flow_pred = _check_flow_pair(flow_true, flow_pred)
    weight = _check_sample_weight(sample_weight, len(flow_true))
    return float(np.average(_point_errors(flow_true, flow_pred), weights=weight))


def scene_flow_metrics(flow_true, flow_pred, *, sample_weight=None):
    """EPE3D, Acc3DS, Acc3DR and Outliers3D, as HPLFlowNet and PointPWC-Net compute them.

    With the end-point error ``e_i = ||f̂_i - f_i||_2`` (metres) and the relative error
    ``r_i = e_i / (||f_i||_2 + 1e-4)`` (divided by the *true* flow's norm):

    * ``EPE3D``: the mean of ``e_i`` (:func:`end_point_error`);
    * ``Acc3DS`` (strict accuracy): the share of points with ``e_i < 0.05`` m **or**
      ``r_i < 0.05``;
    * ``Acc3DR`` (relaxed accuracy): the share with ``e_i < 0.1`` m **or** ``r_i < 0.1``;
    * ``Outliers3D``: the share with ``e_i > 0.3`` m **or** ``r_i > 0.1``.

    The inequalities are strict, as in ``evaluation_utils.evaluate_3d`` of HPLFlowNet
    (Gu et al., CVPR 2019), copied unchanged into PointPWC-Net (Wu et al., ECCV 2020).
    The Argoverse 2 challenge's ``ACCURACY_STRICT``/``ACCURACY_RELAX`` are the same two
    accuracies with ``1e-10`` instead of ``1e-4`` in the relative error. The thresholds
    are in metres, so the measures suit flows in metres at a LiDAR's or FlyingThings3D's
    scale.

    Parameters
    ----------
    flow_true : array-like of shape (n_samples, d)
        Ground-truth flow of each point.
    flow_pred : array-like of shape (n_samples, d)
        Estimated flow of each point.
    sample_weight : array-like of shape (n_samples,), default=None
        Non-negative weights; None weighs every point equally.

    Returns
    -------
    metrics : dict
        ``"EPE3D"`` (lower is better), ``"Acc3DS"``, ``"Acc3DR"`` (in ``[0, 1]``, higher
        is better) and ``"Outliers3D"`` (in ``[0, 1]``, lower is better), as floats.

    References
    ----------
    X. Gu et al., "HPLFlowNet", CVPR 2019 (``evaluation_utils.py``, ``evaluate_3d``);
    W. Wu, Z. Y. Wang, Z. Li, W. Liu and L. Fuxin, "PointPWC-Net: Cost Volume on Point
    Clouds for (Self-)Supervised Scene Flow Estimation", ECCV 2020.

    Examples
    --------
    >>> from mmreg.metrics import scene_flow_metrics
    >>> truth = [[1.0, 0, 0], [1.0, 0, 0], [0, 0, 0], [0, 0, 0]]
    >>> estimate = [[1.04, 0, 0], [1.08, 0, 0], [0, 0.2, 0], [0, 0.5, 0]]
    >>> {k: round(v, 3) for k, v in scene_flow_metrics(truth, estimate).items()}
    {'EPE3D': 0.205, 'Acc3DS': 0.25, 'Acc3DR': 0.5, 'Outliers3D': 0.5}

    The second point is 8 cm off but 8 % of its 1 m flow: not strict, relaxed. Points
    3 and 4 have no true flow, so any error is a large relative error: both outliers.
    """
    flow_true, flow_pred = _check_flow_pair(flow_true, flow_pred)
    weight = _check_sample_weight(sample_weight, len(flow_true))
    error = _point_errors(flow_true, flow_pred)
    relative = error / (np.linalg.norm(flow_true, axis=1) + RELATIVE_ERROR_EPS)
    strict = (error < 0.05) | (relative < 0.05)
    relaxed = (error < 0.1) | (relative < 0.1)
    outlier = (error > 0.3) | (relative > 0.1)
    return {
        "EPE3D": float(np.average(error, weights=weight)),
        "Acc3DS": float(np.average(strict, weights=weight)),
        "Acc3DR": float(np.average(relaxed, weights=weight)),
        "Outliers3D": float(np.average(outlier, weights=weight)),
    }


def dynamic_mask(flow_true, flow_static=None, *, threshold=DYNAMIC_THRESHOLD):
    """Which points are *dynamic*: their flow differs from the static world's by ``threshold``.

    .. math::

        \\mathrm{dynamic}_i = \\lVert f_i - s_i \\rVert_2 \\ge \\mathrm{threshold}

    where ``s_i`` is the flow point ``i`` would have if it were static (the ego motion
    applied to it). This is Argoverse 2's rule (``av2.torch.structures.flow.Flow.
    from_sweep_pair``: ``is_dynamic = ||flow - rigid_flow|| >= 0.05``, the rigid flow
    being the ego motion ``ego1_SE3_ego0``): 0.05 m between sweeps 0.1 s apart, i.e. a
    speed of 0.5 m/s. For ego-motion-compensated frames (ZeroFlow's and
    BucketedSceneFlowEval's, where the static world has zero flow) ``s_i = 0`` and the
    rule is ``||f_i|| >= 0.05``: pass ``flow_static=None``. At another frame rate, scale
    ``threshold`` (0.5 m/s times the time between the frames).

    Parameters
    ----------
    flow_true : array-like of shape (n_samples, d)
        Ground-truth flow of each point.
    flow_static : array-like of shape (n_samples, d), default=None
        The flow of each point under the static world's motion; None means zero.
    threshold : float, default=0.05
        Metres per frame pair.

    Returns
    -------
    dynamic : ndarray of shape (n_samples,), dtype bool

    Examples
    --------
    >>> from mmreg.metrics import dynamic_mask
    >>> dynamic_mask([[0.0, 0, 0], [0.06, 0, 0], [1.0, 0, 0]])
    array([False,  True,  True])
    >>> ego = [[1.0, 0, 0]] * 3                   # the ego vehicle drives 1 m forward
    >>> dynamic_mask([[1.0, 0, 0], [1.06, 0, 0], [0.0, 0, 0]], ego)
    array([False,  True,  True])
    """
    if flow_static is None:
        flow = check_array(flow_true, dtype=np.float64, input_name="flow_true")
        flow_static = np.zeros_like(flow)
    else:
        flow, flow_static = _check_flow_pair(
            flow_true, flow_static, names=("flow_true", "flow_static")
        )
    if not (np.isfinite(threshold) and threshold > 0):
        raise ValueError(f"threshold must be a positive number of metres; got {threshold!r}.")
    return _point_errors(flow_static, flow) >= threshold


def three_way_epe(flow_true, flow_pred, *, foreground, dynamic):
    """The Argoverse 2 scene-flow challenge's three-way EPE.

    The mean end-point error (:func:`end_point_error`) on each of three classes of
    points, and their unweighted mean, so that the few points of moving objects weigh as
    much as the many of the static world:

    * ``foreground_dynamic``: ``foreground & dynamic``;
    * ``foreground_static``: ``foreground & ~dynamic``;
    * ``background_static``: ``~foreground & ~dynamic`` (background points marked
      dynamic, which Argoverse 2's labels never have, are in no class);
    * ``three_way_mean``: ``(foreground_dynamic + foreground_static +
      background_static) / 3``.

    Argoverse 2 (``av2.evaluation.scene_flow.eval``): *foreground* points lie in the
    cuboid (grown by 0.2 m in length and width) of an annotated object of any of its 30
    categories (vehicles, pedestrians, cyclists, but also bollards, cones and signs:
    ``FOREGROUND_BACKGROUND_BREAKDOWN``); the rest is *background*. *Dynamic* follows the
    speed rule of :func:`dynamic_mask` (0.5 m/s relative to the static world). The
    challenge scores non-ground points within 50 m (in x and y) of the ego vehicle,
    averaging each class over all points of all frames before the three-way mean; pass
    the points to score (e.g. ``flow_true[keep]``) and the masks to match. ZeroFlow and
    BucketedSceneFlowEval's ``ThreeWayEPEEvaluator`` use the same classes, with the
    speed ``||f_i||`` of ego-compensated flow.

    Parameters
    ----------
    flow_true : array-like of shape (n_samples, d)
        Ground-truth flow of each point.
    flow_pred : array-like of shape (n_samples, d)
        Estimated flow of each point.
    foreground : array-like of shape (n_samples,), dtype bool
        Whether each point belongs to an annotated object.
    dynamic : array-like of shape (n_samples,), dtype bool
        Whether each point moves (:func:`dynamic_mask` of the true flow).

    Returns
    -------
    epe : dict
        ``"foreground_dynamic"``, ``"foreground_static"``, ``"background_static"`` and
        ``"three_way_mean"`` (metres). A class with no point has NaN, and then so has
        the mean, as in Argoverse 2's ``results_to_dict``.

    References
    ----------
    Argoverse 2 scene flow challenge, ``av2-api``: ``src/av2/evaluation/scene_flow/``
    (``eval.py``: ``compute_metrics``, ``results_to_dict``, "EPE 3-Way Average";
    ``constants.py``). K. Vedder et al., "ZeroFlow: Scalable Scene Flow via
    Distillation", ICLR 2024.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.metrics import three_way_epe
    >>> truth = np.array([[1.0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]])
    >>> estimate = np.array([[0.8, 0, 0], [0.1, 0, 0], [0, 0, 0], [0, 0.3, 0]])
    >>> epe = three_way_epe(truth, estimate, foreground=[True, True, False, False],
    ...                     dynamic=[True, False, False, False])
    >>> list(epe)
    ['foreground_dynamic', 'foreground_static', 'background_static', 'three_way_mean']
    >>> [round(v, 3) for v in epe.values()]
    [0.2, 0.1, 0.15, 0.15]
    """
    flow_true, flow_pred = _check_flow_pair(flow_true, flow_pred)
    n = len(flow_true)
    foreground = _check_mask(foreground, n, name="foreground")
    dynamic = _check_mask(dynamic, n, name="dynamic")
    error = _point_errors(flow_true, flow_pred)
    classes = {
        "foreground_dynamic": foreground & dynamic,
        "foreground_static": foreground & ~dynamic,
        "background_static": ~foreground & ~dynamic,
    }
    result = {
        name: float(error[mask].mean()) if mask.any() else float("nan")
        for name, mask in classes.items()
    }
    result["three_way_mean"] = float(sum(result.values()) / 3)
    return result


def _check_bucket_edges(bucket_edges):
    """Strictly increasing edges from 0, at least one moving bucket; as float64."""
    if bucket_edges is None:
        return BUCKET_EDGES
    edges = np.asarray(bucket_edges, dtype=np.float64)
    if edges.ndim != 1 or len(edges) < 3:
        raise ValueError(
            "bucket_edges must be 1-D with at least 3 edges (a static bucket and a moving "
            f"one); got shape {edges.shape}."
        )
    if np.isnan(edges).any() or edges[0] != 0 or not np.all(np.diff(edges) > 0):
        raise ValueError(
            f"bucket_edges must start at 0 and increase strictly; got {edges.tolist()}."
        )
    return edges


def bucketed_epe(flow_true, flow_pred, *, classes=None, bucket_edges=None):
    """Bucket normalised EPE: the Argoverse 2 2024 scene-flow challenge's measure.

    Points are split by class and by the speed of their true flow, ``s_i = ||f_i||``,
    into buckets ``[e_k, e_{k+1})`` (default :data:`BUCKET_EDGES`: 0, 0.04, ..., 2.0 m
    per frame pair, then 2.0 m and up; 0.4 m/s wide at 10 Hz). For a class:

    * ``static_epe``: the mean end-point error of its points in the first bucket (speed
      below 0.04 m, i.e. 0.4 m/s);
    * ``dynamic_normalized_epe``: over its other (moving) buckets that hold points, the
      mean of ``mean EPE / mean speed`` of each bucket (a ratio of the bucket's means,
      not a mean of per-point ratios). 1 means an error as large as the motion itself:
      a method that predicts zero flow scores 1 on every moving bucket.

    ``mean_static_epe`` and ``mean_dynamic_normalized_epe`` average these over the
    classes that have a value (a class with no point in a bucket range is left out, as
    ``np.nanmean`` does); the challenge ranks by ``mean_dynamic_normalized_epe``. This is
    BucketedSceneFlowEval's ``BucketedEPEEvaluator`` (``BucketResultMatrix``:
    ``get_normalized_error_matrix``, ``get_overall_class_errors``,
    ``get_mean_average_values``) on one frame, or on several frames passed stacked
    (it pools each class's bucket over all points, as the evaluator weighs frames by
    their counts). The challenge's classes are the meta-classes ``BACKGROUND``,
    ``CAR``, ``OTHER_VEHICLES``, ``PEDESTRIAN`` and ``WHEELED_VRU`` of Argoverse 2's
    annotation categories, scored on non-ground points within 35 m (in x and y) of the
    ego vehicle, in ego-motion-compensated frames (the static world has zero flow):
    pass those points, their flows and their classes.

    Parameters
    ----------
    flow_true : array-like of shape (n_samples, d)
        Ground-truth flow of each point, in metres per frame pair, with the ego motion
        removed (a static point has zero flow).
    flow_pred : array-like of shape (n_samples, d)
        Estimated flow of each point, in the same frame.
    classes : array-like of shape (n_samples,), default=None
        The class of each point (integers or names); None puts every point in one
        class, ``"all"``.
    bucket_edges : array-like of shape (n_buckets + 1,), default=None
        Speed-bucket edges in metres per frame pair, from 0, strictly increasing; the
        last may be ``inf``. None: :data:`BUCKET_EDGES`. Points at or above the last
        edge are in no bucket. At another frame rate than 10 Hz, scale the edges.

    Returns
    -------
    scores : dict
        ``"mean_static_epe"`` (metres) and ``"mean_dynamic_normalized_epe"`` (no unit),
        floats, lower is better, NaN when no class has a value; ``"per_class"``: ``{class:
        {"static_epe": float, "dynamic_normalized_epe": float}}``, NaN where the class
        has no static point, or no moving one.

    References
    ----------
    I. Khatri, K. Vedder, N. Peri, D. Ramanan and J. Hays, "I Can't Believe It's Not
    Scene Flow!", ECCV 2024 (arXiv:2403.04739); its evaluation code,
    BucketedSceneFlowEval (``bucketed_scene_flow_eval/eval/bucketed_epe.py``,
    ``datasets/argoverse2/av2_metacategories.py``), the Argoverse 2 2024 scene-flow
    challenge's scorer.

    Examples
    --------
    >>> from mmreg.metrics import bucketed_epe
    >>> truth = [[0.0, 0, 0], [0.0, 0, 0], [1.0, 0, 0], [0.1, 0, 0]]
    >>> estimate = [[0.02, 0, 0], [0.0, 0, 0], [0.5, 0, 0], [0.1, 0.01, 0]]
    >>> scores = bucketed_epe(truth, estimate, classes=["BACKGROUND", "BACKGROUND", "CAR",
    ...                                                 "PEDESTRIAN"])
    >>> {k: round(v, 3) for k, v in scores["per_class"]["CAR"].items()}
    {'static_epe': nan, 'dynamic_normalized_epe': 0.5}
    >>> round(scores["mean_static_epe"], 3), round(scores["mean_dynamic_normalized_epe"], 3)
    (0.01, 0.3)

    The car's 1 m motion is half wrong (0.5); the pedestrian's 0.1 m is 10 % wrong
    (0.1): their mean is 0.3. The background, static, has only a static EPE (0.01).
    """
    flow_true, flow_pred = _check_flow_pair(flow_true, flow_pred)
    n = len(flow_true)
    edges = _check_bucket_edges(bucket_edges)
    if classes is None:
        names, index = ["all"], np.zeros(n, dtype=np.intp)
    else:
        classes = np.asarray(classes)
        if classes.shape != (n,):
            raise ValueError(
                f"classes must have shape ({n},), one class per point; got {classes.shape}."
            )
        unique, index = np.unique(classes, return_inverse=True)
        names = unique.tolist()
    speed = np.linalg.norm(flow_true, axis=1)
    error = _point_errors(flow_true, flow_pred)
    n_buckets = len(edges) - 1
    bucket = np.searchsorted(edges, speed, side="right") - 1  # [e_k, e_{k+1})
    scored = bucket < n_buckets
    cell = index[scored] * n_buckets + bucket[scored]
    size = len(names) * n_buckets
    counts = np.bincount(cell, minlength=size).reshape(len(names), n_buckets)
    errors = np.bincount(cell, weights=error[scored], minlength=size)
    speeds = np.bincount(cell, weights=speed[scored], minlength=size)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_error = errors.reshape(counts.shape) / counts  # NaN where empty
        mean_speed = speeds.reshape(counts.shape) / counts
        normalized = mean_error[:, 1:] / mean_speed[:, 1:]  # moving buckets: speed > 0
    static = mean_error[:, 0]
    moving = np.full(len(names), np.nan)
    filled = counts[:, 1:].any(axis=1)
    moving[filled] = np.nanmean(normalized[filled], axis=1)
    per_class = {
        name: {"static_epe": float(s), "dynamic_normalized_epe": float(m)}
        for name, s, m in zip(names, static, moving, strict=True)
    }

    def mean(values):
        values = values[~np.isnan(values)]
        return float(values.mean()) if len(values) else float("nan")

    return {
        "mean_static_epe": mean(static),
        "mean_dynamic_normalized_epe": mean(moving),
        "per_class": per_class,
    }


def dynamic_iou(dynamic_true, dynamic_pred):
    """Intersection over union of the dynamic and the static points (motion segmentation).

    .. math::

        \\mathrm{IoU}_{\\mathrm{dyn}} = \\frac{TP}{TP + FP + FN}, \\qquad
        \\mathrm{IoU}_{\\mathrm{stat}} = \\frac{TN}{TN + FN + FP}

    with the dynamic points as positives. ``IoU_dyn`` is Argoverse 2's "Dynamic IoU"
    (``av2.evaluation.scene_flow.eval.results_to_dict``), for the challenge's optional
    dynamic segmentation; ``mean`` is the mean IoU of the two classes, as in semantic
    segmentation.

    Parameters
    ----------
    dynamic_true : array-like of shape (n_samples,), dtype bool
        Whether each point truly moves (e.g. :func:`dynamic_mask` of the true flow).
    dynamic_pred : array-like of shape (n_samples,), dtype bool
        Whether it is estimated to move.

    Returns
    -------
    iou : dict
        ``"dynamic"``, ``"static"`` and ``"mean"``, in ``[0, 1]``. A class absent from
        both arrays has NaN, and ``mean`` is then the other class's IoU.

    Examples
    --------
    >>> from mmreg.metrics import dynamic_iou
    >>> iou = dynamic_iou([1, 1, 0, 0, 0], [1, 0, 1, 0, 0])
    >>> {k: round(v, 3) for k, v in iou.items()}
    {'dynamic': 0.333, 'static': 0.5, 'mean': 0.417}
    """
    truth = np.asarray(dynamic_true)
    truth = _check_mask(truth, len(truth) if truth.ndim else -1, name="dynamic_true")
    pred = _check_mask(dynamic_pred, len(truth), name="dynamic_pred")
    if not len(truth):
        raise ValueError("dynamic_true and dynamic_pred are empty; there is nothing to score.")
    result = {}
    for name, positive_true, positive_pred in (
        ("dynamic", truth, pred),
        ("static", ~truth, ~pred),
    ):
        union = np.count_nonzero(positive_true | positive_pred)
        inter = np.count_nonzero(positive_true & positive_pred)
        result[name] = float(inter / union) if union else float("nan")
    defined = [v for v in result.values() if not np.isnan(v)]
    result["mean"] = float(np.mean(defined))
    return result


class _FlowScorer:
    """``sign * metric(y, estimator.flow_)`` for the rows the estimator was fitted on."""

    def __init__(self, name, metric, sign):
        self._name = name
        self._metric = metric
        self._sign = sign

    def __call__(self, estimator, X, y):
        if y is None:
            raise ValueError(
                f"The {self._name} scorer needs the ground-truth flow as y, an array of shape "
                "(n_samples, d); pass it to fit of the search or to cross_validate."
            )
        flow = getattr(estimator, "flow_", None)
        if flow is None:
            raise ValueError(
                f"The {self._name} scorer needs a fitted estimator with a flow_ attribute "
                f"(the rigid flow of its clusters); {type(estimator).__name__} has none."
            )
        if len(flow) != len(X):
            raise ValueError(
                f"The estimator was fitted on {len(flow)} correspondences but {len(X)} are "
                "scored; a flow scorer scores the rows the estimator was fitted on, so use "
                "cv=[(rows, rows)] (one whole scene per split)."
            )
        return self._sign * self._metric(y, flow)

    def __repr__(self):
        return f"<scene-flow scorer {self._name}>"


def _metric_of(key):
    def metric(flow_true, flow_pred):
        return scene_flow_metrics(flow_true, flow_pred)[key]

    return metric


def make_end_point_error_scorer():
    """Scorer of minus the end-point error (:func:`end_point_error`) of ``estimator.flow_``.

    The estimator's ``flow_`` is the rigid flow of its clusters on the correspondences it
    was fitted on, so a split must score the rows it fits (``cv=[(rows, rows)]``), and
    ``y`` is the true flow of those rows, shape ``(n_samples, d)``.

    Returns
    -------
    scorer : callable
        ``scorer(estimator, X, y)``, greater (closer to 0) is better.

    Examples
    --------
    >>> import numpy as np
    >>> from sklearn.model_selection import GridSearchCV
    >>> from mmreg import MultiModelRegistration
    >>> from mmreg.datasets import make_scene
    >>> from mmreg.metrics import make_end_point_error_scorer
    >>> scene = make_scene(n_objects=2, n_points=200, random_state=0)
    >>> flow = scene.b - scene.a                       # the true flow
    >>> rows = np.arange(200)
    >>> search = GridSearchCV(
    ...     MultiModelRegistration(init=np.arange(200) % 8, variant="paper"),
    ...     {"max_iter": [0, 10]}, scoring=make_end_point_error_scorer(), cv=[(rows, rows)],
    ... ).fit(scene.X, flow)
    >>> search.best_params_, round(-float(search.best_score_), 6)
    ({'max_iter': 10}, 0.0)
    """
    return _FlowScorer("end_point_error", end_point_error, -1.0)


def make_bucketed_epe_scorer(*, bucket_edges=None):
    """Scorer of minus the mean dynamic normalised EPE (:func:`bucketed_epe`) of ``flow_``.

    One class (the scorer sees no point classes): the dynamic normalised EPE of the
    moving buckets of every point, the challenge's ranking measure for a dataset without
    classes. ``y`` is the true flow, ego-motion compensated (a static point has zero
    flow), and each split scores the rows it fits, as for
    :func:`make_end_point_error_scorer`. A scene without a moving point scores NaN.

    Parameters
    ----------
    bucket_edges : array-like, default=None
        As for :func:`bucketed_epe`.

    Returns
    -------
    scorer : callable
        ``scorer(estimator, X, y)``, greater (closer to 0) is better.

    Examples
    --------
    >>> from mmreg import MultiModelRegistration
    >>> from mmreg.datasets import make_scene
    >>> from mmreg.metrics import make_bucketed_epe_scorer
    >>> scene = make_scene(n_objects=2, n_points=200, random_state=0)
    >>> estimator = MultiModelRegistration(random_state=0).fit(scene.X)
    >>> round(-make_bucketed_epe_scorer()(estimator, scene.X, scene.b - scene.a), 6)
    0.0
    """
    edges = _check_bucket_edges(bucket_edges)

    def metric(flow_true, flow_pred):
        return bucketed_epe(flow_true, flow_pred, bucket_edges=edges)["mean_dynamic_normalized_epe"]

    return _FlowScorer("bucketed_epe", metric, -1.0)


def scene_flow_scorers():
    """The measures of :func:`scene_flow_metrics` as a dict of scorers of ``estimator.flow_``.

    For multi-metric ``scoring=`` of ``GridSearchCV`` (pass ``refit=`` one of the keys);
    ``y`` is the true flow and each split scores the rows it fits, as for
    :func:`make_end_point_error_scorer`.

    Returns
    -------
    scorers : dict
        ``"neg_EPE3D"``, ``"Acc3DS"``, ``"Acc3DR"`` and ``"neg_Outliers3D"``; greater is
        better for each.
    """
    return {
        "neg_EPE3D": _FlowScorer("EPE3D", _metric_of("EPE3D"), -1.0),
        "Acc3DS": _FlowScorer("Acc3DS", _metric_of("Acc3DS"), 1.0),
        "Acc3DR": _FlowScorer("Acc3DR", _metric_of("Acc3DR"), 1.0),
        "neg_Outliers3D": _FlowScorer("Outliers3D", _metric_of("Outliers3D"), -1.0),
    }
