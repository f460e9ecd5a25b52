"""The paper's measures (Section V-B) as functions, scikit-learn scorers and tables.

Functions of label arrays (``-1`` marks outliers) and motions ``(rotations,
translations)`` of shapes ``(K, d, d)`` and ``(K, d)``:

* :func:`iou_score` (higher is better), :func:`per_point_error`, :func:`rotation_error`
  and :func:`translation_error` (lower is better), exactly as the paper defines them;
* :func:`objects_found`: the share of (moving) objects some cluster recovers, which
  the paper's IoU hides (one cluster holding a whole street scores high on it);
* :func:`misclassification_error` (Hungarian matching) and
  :func:`~sklearn.metrics.adjusted_rand_score`, the usual clustering view;
* :func:`ground_truth_poses`: true motions by Horn's method on the true clusters;
* scorers for ``GridSearchCV`` and ``cross_validate``, and :func:`evaluate`, which
  tabulates several methods on several scenes as a :class:`pandas.DataFrame`.

Functions of scene flow ``(n, d)`` (the estimators' ``flow_``), as the scene-flow
community defines them:

* :func:`end_point_error` and :func:`scene_flow_metrics` (EPE3D, Acc3DS, Acc3DR,
  Outliers3D of HPLFlowNet and PointPWC-Net);
* :func:`dynamic_mask`, :func:`three_way_epe` and :func:`dynamic_iou` (Argoverse 2's
  scene-flow challenge); :func:`bucketed_epe` (bucket normalised EPE, its 2024
  measure); :func:`make_end_point_error_scorer`,
  :func:`make_bucketed_epe_scorer` and :func:`scene_flow_scorers` score ``flow_``
  against the true flow as ``y``.

Functions of a whole LiDAR log, lists of per-frame arrays (one value per point):

* :func:`moving_iou`: LiDAR-MOS's moving-object IoU, counts summed over the frames;
* :func:`tracking_scores`: per true object the share of its frames a track finds it in,
  ID switches and fragmentations (CLEAR-MOT's), and false moving tracks per frame;
* :func:`relative_pose_errors`: an estimated trajectory of sensor poses against the true
  one, the motion of every consecutive frame pair (translation and rotation errors).
"""

from sklearn.metrics import adjusted_rand_score

from mmreg.metrics._clustering import iou_score, misclassification_error
from mmreg.metrics._evaluate import evaluate
from mmreg.metrics._objects import objects_found
from mmreg.metrics._point import chamfer_distance, per_point_error
from mmreg.metrics._pose import ground_truth_poses, rotation_error, translation_error
from mmreg.metrics._scene_flow import (
    bucketed_epe,
    dynamic_iou,
    dynamic_mask,
    end_point_error,
    make_bucketed_epe_scorer,
    make_end_point_error_scorer,
    scene_flow_metrics,
    scene_flow_scorers,
    three_way_epe,
)
from mmreg.metrics._scorer import (
    make_iou_scorer,
    make_misclassification_scorer,
    make_per_point_error_scorer,
    make_rotation_error_scorer,
    make_translation_error_scorer,
    registration_scorers,
)
from mmreg.metrics._sequences import TrackingScores, moving_iou, tracking_scores
from mmreg.metrics._trajectory import relative_pose_errors

__all__ = [
    "TrackingScores",
    "adjusted_rand_score",
    "bucketed_epe",
    "chamfer_distance",
    "dynamic_iou",
    "dynamic_mask",
    "end_point_error",
    "evaluate",
    "ground_truth_poses",
    "iou_score",
    "make_bucketed_epe_scorer",
    "make_end_point_error_scorer",
    "make_iou_scorer",
    "make_misclassification_scorer",
    "make_per_point_error_scorer",
    "make_rotation_error_scorer",
    "make_translation_error_scorer",
    "misclassification_error",
    "moving_iou",
    "objects_found",
    "per_point_error",
    "registration_scorers",
    "relative_pose_errors",
    "rotation_error",
    "scene_flow_metrics",
    "scene_flow_scorers",
    "three_way_epe",
    "tracking_scores",
    "translation_error",
]
