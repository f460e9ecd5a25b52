"""``mmreg evaluate``: score a result directory against the ground truth."""

import argparse
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
    reading,
    warn,
)
from mmreg._cli._results import open_results

NAME = "evaluate"
HELP = "score a result (directory, 'mmreg run' folder or job) against the ground truth"
DESCRIPTION = """\
Score RESULT against the ground truth. RESULT is

  - a result directory of "mmreg register" or "mmreg demo --out": its labels.npy, its
    motions.json and its correspondences (X.npy, else the input files named in its
    run.json) for the errors;
  - an "mmreg run" folder: every job (a table, one row per job) or the one named by
    --job;
  - one job's file of a run, RUN/jobs/<job>.npz (its labels, motions and flow);
  - an "mmreg run" folder of a log, or of a folder of logs (a table, one row per log, or
    the log named by --job), scored against the log itself (runs with --pairs too, every
    pair at once: the moving rows are those of the clusters found moving, and the pose
    error is that of each pair's static-world motion): the moving-object IoU of
    LiDAR-MOS where the log has labels (labels/<frame>.label beside its frames, in
    SemanticKITTI's uint32 or a nuScenes conversion's uint8; unlabelled points and the
    ego body are left out), the tracking scores where the labels carry instance ids,
    and where the log has poses the relative pose error of every consecutive frame pair
    (mean and max, metres and degrees) of the poses found. TRUTH does not apply.

TRUTH is

  - a file of labels (.npy, .csv or .txt): the true object of every correspondence, -1
    for outliers; or
  - an .npz with an array "labels" and optionally "X" (the true correspondences),
    "rotations" (K, 3, 3) and "translations" (K, 3) (the true motion of each object),
    "flow" (n, 3) (the true scene flow of every a-point) and "outlier_mask" (n,) bool
    (marks outliers when the labels do not);
  - left out: RESULT/truth.npz (written by "mmreg demo --out"), or for the jobs of a run
    the truth their dataset holds (Argoverse 2's labels and flow; negative labels are
    unknown points, not scored).

Prints the paper's measures (Section V-B: IoU, per-point error, rotation and translation
errors), the misclassification error and adjusted Rand index, the share of the true
objects found (a cluster of IoU >= 0.5 with it) overall and besides the largest object
(the background), the outliers found and the numbers of clusters; with a true flow also
the end-point error EPE3D and the bucketed EPE (mmreg.metrics.bucketed_epe, one class,
both flows relative to the true static world's motion).

The labels alone answer the IoU, objects found and outliers: no input file is read for
them. The errors need true motions: TRUTH's "rotations" and "translations", else fitted
by Horn's method on the true clusters of TRUTH's "X" or "flow", else of RESULT's input
correspondences (as the paper does on KITTI). A result of two raw sweeps (--sweep, or
'mmreg run --pairs sweeps') has no input correspondences: its b-points are its own flow,
so with labels alone its errors are not measured (n/a, with a warning) rather than
measured against itself. A moved or changed input file is named in a warning, and the
measures that need it are n/a.
"""


class _IntermixedParser(argparse.ArgumentParser):
    """Options may come between RESULT and TRUTH (``RUN --job J TRUTH``).

    argparse fills every positional at the first run of positionals it meets, so an
    optional TRUTH after an option was left over; an intermixed parse takes the options
    out first (Python 3.13 parses this case itself).
    """

    _mixing = False

    def parse_known_args(self, args=None, namespace=None):
        if self._mixing:  # parse_known_intermixed_args calls this one, twice
            return super().parse_known_args(args, namespace)
        self._mixing = True
        try:
            return self.parse_known_intermixed_args(args, namespace)
        finally:
            self._mixing = False


def add_arguments(parser):
    # This subcommand's parser alone reads options between its positionals.
    parser.__class__ = type("EvaluateParser", (_IntermixedParser, type(parser)), {})
    parser.add_argument(
        "pred_dir",
        metavar="RESULT",
        help="a result directory, an 'mmreg run' folder or one of its jobs/<job>.npz",
    )
    parser.add_argument(
        "truth",
        metavar="TRUTH",
        nargs="?",
        default=None,
        help="true labels (.npy/.csv/.txt) or .npz (default: RESULT/truth.npz of 'mmreg demo', "
        "or the truth of each job's dataset)",
    )
    parser.add_argument(
        "--job", metavar="NAME", default=None, help="score only this job of an 'mmreg run' folder"
    )
    parser.add_argument("--json", action="store_true", help="print the numbers as JSON")


def _read_truth(path, n):
    import numpy as np

    from mmreg import io as mmio

    path = Path(path)
    X = rotations = translations = flow = None
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
                flow = data["flow"] if "flow" in names else None
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
    if flow is not None:
        flow = np.asarray(flow)
        if flow.shape != (n, 3) or flow.dtype.kind not in "iuf" or not np.isfinite(flow).all():
            raise CLIError(f"{path}: 'flow' must be ({n}, 3) finite numbers; got {flow.shape}")
        flow = flow.astype(float)
    return labels, X, rotations, translations, flow


def _truth_of(result, truth_path):
    """The truth to score ``result`` against: ``{labels, X, rotations, translations, flow,
    unknown}`` (``unknown``: negative labels are unknown points, not scored)."""
    import numpy as np

    n = len(result.labels)
    if truth_path is None and result.path.is_dir() and (result.path / "truth.npz").exists():
        truth_path = result.path / "truth.npz"  # mmreg demo --out keeps its truth
    if truth_path is not None:
        labels, X, rotations, translations, flow = _read_truth(truth_path, n)
        return {
            "labels": labels,
            "X": X,
            "rotations": rotations,
            "translations": translations,
            "flow": flow,
            "unknown": False,
        }
    data = result.job_data()
    if data is None:
        raise CLIError(
            f"{result.path}: give TRUTH, the true labels (and motions or flow) to score it against"
        )
    if data.get("labels_true") is None and data.get("flow_true") is None:
        raise CLIError(f"{result.name}: its dataset holds no truth; give TRUTH")
    labels = data.get("labels_true")
    labels = (
        np.zeros(n, dtype=np.intp)
        if labels is None
        else check_labels(result.rows(np.asarray(labels)), n, result.path, "true labels")
    )
    flow = data.get("flow_true")
    return {
        "labels": labels,
        "X": None,
        "rotations": None,
        "translations": None,
        "flow": None if flow is None else result.rows(np.asarray(flow, dtype=float)),
        "unknown": True,
    }


def _points(result, needed):
    """The result's points, or None with a warning naming the input file at fault (a
    moved or changed input, outside the result)."""
    if not needed:
        return None
    if not result.external:  # the result's own X.npy: damage to it is an error
        return result.points(required=False)
    try:
        return result.points(required=False)
    except CLIError as error:
        warn(f"{error}; pose and per-point errors not measured")
        return None


def _predicted_flow(result, X):
    """The result's flow: a job's own, else b - a of derived points, else its motions'."""
    import numpy as np

    from mmreg._array.flow import rigid_flow

    if result.flow is not None:
        flow = result.flow
    elif result.derived and X.shape[1] == 6:
        flow = X[:, 3:] - X[:, :3]
    else:
        flow = rigid_flow(X[:, :3], result.labels, result.rotations, result.translations)
    return np.nan_to_num(flow, nan=0.0)  # no cluster at all: not moving


def _flow_measures(result, X, truth, keep):
    """EPE3D and the bucketed EPE of the result's flow against the true flow."""
    import numpy as np

    from mmreg.metrics import bucketed_epe, ground_truth_poses, scene_flow_metrics

    flow_true = truth["flow"][keep]
    flow_pred = _predicted_flow(result, X)[keep]
    a = X[keep, :3]
    scores = {"epe3d": scene_flow_metrics(flow_true, flow_pred)["EPE3D"]}
    labels = truth["labels"][keep]
    ids, sizes = np.unique(labels[labels >= 0], return_counts=True)
    if len(ids):
        # Bucketed EPE is defined in ego-motion-compensated frames: both flows are taken
        # relative to the true motion of the static world (the largest true object).
        static = labels == ids[np.argmax(sizes)]
        pairs = np.hstack([a[static], a[static] + flow_true[static]])
        (rotation,), (translation,) = ground_truth_poses(pairs, np.zeros(len(pairs), int))
        ego = a @ rotation.T + translation - a
        flow_true, flow_pred = flow_true - ego, flow_pred - ego
    bucketed = bucketed_epe(flow_true, flow_pred)
    scores["bucketed_static_epe"] = bucketed["mean_static_epe"]
    scores["bucketed_dynamic_normalized_epe"] = bucketed["mean_dynamic_normalized_epe"]
    return scores


def _pose_truth(result, truth, X):
    """The true motions and the points for the pose errors, or None with the reason."""
    import numpy as np

    from mmreg.metrics import ground_truth_poses

    labels = truth["labels"]
    if truth["rotations"] is not None:
        points = truth["X"] if truth["X"] is not None else X
        return (truth["rotations"], truth["translations"]), points, None
    if truth["X"] is not None:
        return ground_truth_poses(truth["X"], labels), truth["X"], None
    if X is None:
        return None, None, "RESULT's points could not be read"
    if truth["flow"] is not None:
        pairs = np.hstack([X[:, :3], X[:, :3] + truth["flow"]])
        return ground_truth_poses(pairs, labels), pairs, None
    if X.shape[1] == 6 and not result.derived:
        # The paper's way (KITTI): the true objects' motions fitted on the input's
        # correspondences, which are data, not the result.
        return ground_truth_poses(X, labels), X, None
    return (
        None,
        None,
        (
            "TRUTH holds labels only and RESULT's b-points are its own flow (two raw sweeps); "
            "give TRUTH 'rotations' and 'translations', 'X' or 'flow' to measure them"
        ),
    )


def evaluate(result, truth):
    """The measures of one :class:`~mmreg._cli._results.Result` against ``truth`` (see
    :func:`_truth_of`), as an ordered dict ``name -> value`` (NaN when not measured)."""
    import numpy as np

    from mmreg.metrics import (
        adjusted_rand_score,
        iou_score,
        misclassification_error,
        objects_found,
        per_point_error,
        rotation_error,
        translation_error,
    )

    pred_all = result.labels
    truth_all = truth["labels"]
    keep = truth_all >= 0 if truth["unknown"] else np.ones(len(pred_all), bool)
    pred, labels = pred_all[keep], truth_all[keep]
    true_ids, true_sizes = np.unique(labels[labels >= 0], return_counts=True)
    # Every true object but the largest (the background; np.argmax: the first of ties).
    others = np.delete(true_ids, np.argmax(true_sizes)) if len(true_ids) else true_ids
    # The ego vehicle's own body (labelled -1) is no predicted outlier: counted apart.
    body = np.zeros(len(pred_all), bool) if result.ego_body is None else result.ego_body
    flagged, outlying = (pred < 0) & ~body[keep], labels < 0
    hits = int(np.sum(flagged & outlying))
    scores = {
        "iou": iou_score(labels, pred) if len(labels) else math.nan,
        "per_point_error": math.nan,
        "rotation_error_deg": math.nan,
        "translation_error": math.nan,
        "misclassification_error": misclassification_error(labels, pred),
        "adjusted_rand_index": float(adjusted_rand_score(labels, pred)),
        "objects_found": objects_found(labels, pred) if len(true_ids) else math.nan,
        "objects_found_besides_background": (
            objects_found(labels, pred, objects=others) if len(others) else math.nan
        ),
        "outliers_predicted": int(flagged.sum()),
        "outliers_true": int(outlying.sum()),
        "outlier_precision": hits / flagged.sum() if flagged.any() else math.nan,
        "outlier_recall": hits / outlying.sum() if outlying.any() else math.nan,
        "clusters_predicted": int(len(np.unique(pred_all[pred_all >= 0]))),
        "objects_true": int(len(true_ids)),
    }
    if body.any():
        scores["ego_body"] = int(body[keep].sum())
    has_motions = result.rotations is not None
    X = _points(result, needed=has_motions or truth["flow"] is not None)
    if truth["flow"] is not None and X is not None:
        scores.update(_flow_measures(result, X, truth, keep))
    if not (has_motions and np.any(pred >= 0) and len(true_ids)):
        return scores
    transforms_true, points, reason = _pose_truth(result, truth, X)
    if reason is not None:
        if X is not None:
            warn(f"{result.name}: pose and per-point errors not measured: {reason}")
        return scores
    transforms_pred = (result.rotations, result.translations)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        args = (labels, pred, transforms_true, transforms_pred)
        scores["rotation_error_deg"] = rotation_error(*args)
        scores["translation_error"] = translation_error(*args)
        if points is not None:
            points = points[keep]
            if points.shape[1] == 3:  # per_point_error reads the a-points only
                points = np.hstack([points, points])
            scores["per_point_error"] = per_point_error(points, *args)
    return scores


_LINES = [
    ("iou", "IoU (higher is better)", ".3f"),
    ("per_point_error", "per-point error [m]", ".4f"),
    ("rotation_error_deg", "rotation error [deg]", ".3f"),
    ("translation_error", "translation error [m]", ".4f"),
    ("epe3d", "end-point error EPE3D [m]", ".4f"),
    ("bucketed_static_epe", "bucketed EPE: static [m]", ".4f"),
    ("bucketed_dynamic_normalized_epe", "bucketed EPE: dynamic normalised", ".3f"),
    ("misclassification_error", "misclassification error", ".3f"),
    ("adjusted_rand_index", "adjusted Rand index", ".3f"),
    ("objects_found", "objects found", ".0%"),
    ("objects_found_besides_background", "objects found besides background", ".0%"),
    ("outliers_predicted", "outliers predicted", ",d"),
    ("outliers_true", "outliers true", ",d"),
    ("ego_body", "on the ego body", ",d"),
    ("outlier_precision", "outlier precision", ".0%"),
    ("outlier_recall", "outlier recall", ".0%"),
    ("clusters_predicted", "clusters predicted", "d"),
    ("objects_true", "objects true", "d"),
]
# The columns of the table of several jobs.
_TABLE = [
    ("job", "job", ""),
    ("iou", "IoU", ".3f"),
    ("objects_found_besides_background", "moving found", ".0%"),
    ("rotation_error_deg", "rot [deg]", ".3f"),
    ("translation_error", "trans [m]", ".4f"),
    ("epe3d", "EPE3D [m]", ".4f"),
    ("bucketed_dynamic_normalized_epe", "dyn. norm. EPE", ".3f"),
    ("clusters_predicted", "clusters", "d"),
]


def _text(value, fmt):
    if isinstance(value, float) and math.isnan(value):
        return "n/a"
    return format(value, fmt)


def run(args):
    import pandas as pd

    from mmreg._cli._sequence_results import (
        evaluate_logs,
        evaluate_pair_logs,
        is_log_result,
        pair_log_run,
    )

    if is_log_result(args.pred_dir):
        return evaluate_logs(args)
    logs = pair_log_run(args.pred_dir) if args.truth is None else None
    if logs:  # --pairs on LiDAR logs: every pair at once, against the logs themselves
        return evaluate_pair_logs(args, logs)
    results = open_results(args.pred_dir, job=args.job, every_job=args.truth is None)
    rows = []
    for result in results:
        row = evaluate(result, _truth_of(result, args.truth))
        rows.append({"job": result.name} | row if len(results) > 1 else row)
    if args.json:
        clean = [
            {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in row.items()}
            for row in rows
        ]
        print(json.dumps(clean if len(results) > 1 else clean[0], indent=2))
        return 0
    if len(results) > 1:
        frame = pd.DataFrame(rows)
        spec = [(key, name, fmt) for key, name, fmt in _TABLE if key in frame]
        frame = frame.astype(object).where(frame.notna(), math.nan)
        cells = [[name for _, name, _ in spec]]
        cells += [[_text(row[key], fmt) for key, _, fmt in spec] for _, row in frame.iterrows()]
        widths = [max(len(r[i]) for r in cells) for i in range(len(spec))]
        for number, cell in enumerate(cells):
            print("  ".join(c.rjust(w) for c, w in zip(cell, widths, strict=True)))
            if number == 0:
                print("  ".join("-" * w for w in widths))
        return 0
    width = max(len(name) for _, name, _ in _LINES)
    for key, name, fmt in _LINES:
        if key in rows[0]:
            print(f"{name:<{width}}  {_text(rows[0][key], fmt)}")
    return 0
