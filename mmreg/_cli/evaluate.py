"""``mmreg evaluate``: score a result directory against the ground truth."""

import contextlib
import json
import math
import warnings
from pathlib import Path

from mmreg._cli._common import (
    CLIError,
    check_correspondences,
    check_labels,
    load_npz,
    read_result_input,
    reading,
)

NAME = "evaluate"
HELP = "score a result directory against ground-truth labels (and motions)"
DESCRIPTION = """\
Score the result directory PRED_DIR (of "mmreg register" or "mmreg demo --out": its
labels.npy, and motions.json and its correspondences for the pose errors: its X.npy, else
the input file named in its run.json) against TRUTH, which is

  - a file of labels (.npy, .csv or .txt): the true object of every correspondence, -1
    for outliers; or
  - an .npz with an array "labels" and optionally "X" (the correspondences, else
    PRED_DIR's are used), "rotations" (K, 3, 3) and "translations" (K, 3) (the true
    motion of each object, else fitted by Horn's method on the true clusters, as the
    paper does on KITTI) and "outlier_mask" (n,) bool (marks outliers when the labels
    do not).

Prints the paper's measures (Section V-B: IoU, per-point error, rotation and translation
errors), the misclassification error and adjusted Rand index, the share of the true
objects found (a cluster of IoU >= 0.5 with it) overall and besides the largest object
(the background), the outliers found, and the numbers of clusters.
"""


def add_arguments(parser):
    parser.add_argument("pred_dir", metavar="PRED_DIR", help="a result directory")
    parser.add_argument("truth", metavar="TRUTH", help="true labels (.npy/.csv/.txt) or .npz")
    parser.add_argument("--json", action="store_true", help="print the numbers as JSON")


def _read_truth(path, n):
    import numpy as np

    from mmreg import io as mmio

    path = Path(path)
    X = rotations = translations = None
    with reading(path):
        if path.suffix.lower() == ".npz":
            with contextlib.nullcontext(load_npz(path, "ground truth")) as data:
                names = list(data.keys())
                if "labels" not in names:
                    raise CLIError(f"{path}: needs an array 'labels'; it holds {names}")
                labels = data["labels"]
                X = data["X"] if "X" in names else None
                if ("rotations" in names) != ("translations" in names):
                    raise CLIError(f"{path}: give both 'rotations' and 'translations', or neither")
                if "rotations" in names:
                    rotations, translations = data["rotations"], data["translations"]
                outliers = data["outlier_mask"] if "outlier_mask" in names else None
        else:
            labels, outliers = mmio.read_labels(path), None
    labels = check_labels(labels, n, path, "true labels")
    if outliers is not None:
        outliers = np.asarray(outliers)
        if outliers.shape != (n,):
            raise CLIError(f"{path}: 'outlier_mask' must have shape ({n},); got {outliers.shape}")
        labels = np.where(outliers.astype(bool), -1, labels)
    if X is not None:
        X = check_correspondences(X, path)
        if len(X) != n:
            raise CLIError(f"{path}: 'X' has {len(X)} rows for {n} labels")
    if rotations is not None:
        rotations = np.asarray(rotations, dtype=float)
        translations = np.asarray(translations, dtype=float)
        top = int(labels.max(initial=-1)) + 1
        if rotations.shape[1:] != (3, 3) or translations.shape[1:] != (3,):
            raise CLIError(f"{path}: 'rotations' must be (K, 3, 3) and 'translations' (K, 3)")
        if len(rotations) < top or len(translations) != len(rotations):
            raise CLIError(
                f"{path}: {len(rotations)} rotations and {len(translations)} translations "
                f"for labels up to {top - 1}"
            )
    return labels, X, rotations, translations


def _read_prediction(pred_dir):
    import numpy as np

    from mmreg import io as mmio

    pred_dir = Path(pred_dir)
    if not pred_dir.is_dir():
        raise CLIError(f"{pred_dir}: not a result directory (no such directory)")
    labels_path = pred_dir / "labels.npy"
    if not labels_path.exists():
        raise CLIError(f"{labels_path}: no such file (is {pred_dir} a result directory?)")
    with reading(labels_path):
        labels = mmio.read_labels(labels_path)
    labels = check_labels(labels, len(np.asarray(labels)), labels_path)
    motions = None
    motions_path = pred_dir / "motions.json"
    if motions_path.exists():
        with reading(motions_path):
            motions = mmio.read_motions(motions_path)
    return labels, motions


def evaluate(pred_dir, truth_path):
    """The measures as an ordered dict ``name -> value`` (NaN when not computable)."""
    import numpy as np

    from mmreg.metrics import (
        adjusted_rand_score,
        ground_truth_poses,
        iou_score,
        misclassification_error,
        objects_found,
        per_point_error,
        rotation_error,
        translation_error,
    )

    pred, motions = _read_prediction(pred_dir)
    truth, X_true, rotations, translations = _read_truth(truth_path, len(pred))
    X = X_true
    if X is None and motions is not None:  # only the pose errors need them
        X = read_result_input(pred_dir, len(pred), required=False)
    true_ids, true_sizes = np.unique(truth[truth >= 0], return_counts=True)
    # Every true object but the largest (the background; np.argmax: the first of ties).
    others = np.delete(true_ids, np.argmax(true_sizes)) if len(true_ids) else true_ids
    flagged, outlying = pred < 0, truth < 0
    hits = int(np.sum(flagged & outlying))
    result = {
        "iou": iou_score(truth, pred),
        "per_point_error": math.nan,
        "rotation_error_deg": math.nan,
        "translation_error": math.nan,
        "misclassification_error": misclassification_error(truth, pred),
        "adjusted_rand_index": float(adjusted_rand_score(truth, pred)),
        "objects_found": objects_found(truth, pred),
        "objects_found_besides_background": (
            objects_found(truth, pred, objects=others) if len(others) else math.nan
        ),
        "outliers_predicted": int(flagged.sum()),
        "outliers_true": int(outlying.sum()),
        "outlier_precision": hits / flagged.sum() if flagged.any() else math.nan,
        "outlier_recall": hits / outlying.sum() if outlying.any() else math.nan,
        "clusters_predicted": int(len(np.unique(pred[pred >= 0]))),
        "objects_true": int(len(true_ids)),
    }
    if motions is not None and X is not None and np.any(pred >= 0) and len(true_ids):
        transforms_pred = (motions["rotations"], motions["translations"])
        if rotations is None:
            rotations, translations = ground_truth_poses(X, truth)
        transforms_true = (rotations, translations)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            args = (truth, pred, transforms_true, transforms_pred)
            result["per_point_error"] = per_point_error(X, *args)
            result["rotation_error_deg"] = rotation_error(*args)
            result["translation_error"] = translation_error(*args)
    return result


_LINES = [
    ("iou", "IoU (higher is better)", ".3f"),
    ("per_point_error", "per-point error [m]", ".4f"),
    ("rotation_error_deg", "rotation error [deg]", ".3f"),
    ("translation_error", "translation error [m]", ".4f"),
    ("misclassification_error", "misclassification error", ".3f"),
    ("adjusted_rand_index", "adjusted Rand index", ".3f"),
    ("objects_found", "objects found", ".0%"),
    ("objects_found_besides_background", "objects found besides background", ".0%"),
    ("outliers_predicted", "outliers predicted", ",d"),
    ("outliers_true", "outliers true", ",d"),
    ("outlier_precision", "outlier precision", ".0%"),
    ("outlier_recall", "outlier recall", ".0%"),
    ("clusters_predicted", "clusters predicted", "d"),
    ("objects_true", "objects true", "d"),
]


def run(args):
    result = evaluate(args.pred_dir, args.truth)
    if args.json:
        clean = {
            k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in result.items()
        }
        print(json.dumps(clean, indent=2))
        return 0
    width = max(len(name) for _, name, _ in _LINES)
    for key, name, fmt in _LINES:
        value = result[key]
        text = "n/a" if isinstance(value, float) and math.isnan(value) else format(value, fmt)
        print(f"{name:<{width}}  {text}")
    return 0
