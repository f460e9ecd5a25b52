"""Two labellings side by side, the prediction's colours matched to the truth's."""

import numpy as np

from mmreg.plotting._clusters import _new_figure, plot_clusters
from mmreg.plotting._style import (
    OUTLIER_COLOR,
    VIEWS,
    _check_labels,
    _check_points,
    _color_table,
    _qualitative,
    _ranked,
)


def _use_constrained_layout(fig):
    if fig.get_layout_engine() is None:
        fig.set_layout_engine("constrained")


def _matched_colors(labels_true, labels_pred):
    """Colours of the true clusters, and of the predicted ones by their matched true cluster.

    Predicted clusters are matched one-to-one to true clusters (most shared points,
    Hungarian method); a matched cluster takes its true cluster's colour, an unmatched
    one a colour of its own.
    """
    from scipy.optimize import linear_sum_assignment

    true_ids, _ = _ranked(labels_true)
    pred_ids, _ = _ranked(labels_pred)
    true_table = _color_table(labels_true, True)
    if not len(true_ids) or not len(pred_ids):
        return true_table, _color_table(labels_pred, True)
    t_index = {label: i for i, label in enumerate(true_ids.tolist())}
    p_index = {label: i for i, label in enumerate(pred_ids.tolist())}
    both = (labels_true >= 0) & (labels_pred >= 0)
    overlap = np.zeros((len(true_ids), len(pred_ids)))
    np.add.at(
        overlap,
        (
            np.array([t_index[v] for v in labels_true[both].tolist()], dtype=np.intp),
            np.array([p_index[v] for v in labels_pred[both].tolist()], dtype=np.intp),
        ),
        1.0,
    )
    rows, cols = linear_sum_assignment(-overlap)
    pred_table = {-1: np.array(OUTLIER_COLOR)}
    matched = {}
    for r, c in zip(rows, cols, strict=True):
        if overlap[r, c] > 0:
            matched[int(pred_ids[c])] = true_table[int(true_ids[r])]
    spare = iter(_qualitative(len(true_ids) + len(pred_ids))[max(len(true_ids) - 1, 0) :])
    for label in pred_ids.tolist():
        pred_table[label] = matched[label] if label in matched else next(spare)
    return true_table, pred_table


def plot_comparison(
    a,
    labels_true,
    labels_pred,
    *,
    view="3d",
    camera=None,
    fig=None,
    titles=("ground truth", "estimate"),
    title=None,
    max_points=60_000,
):
    """Ground truth and estimated clusters side by side, a match in the same colour.

    Each estimated cluster is matched one-to-one to the true object it shares the most
    points with (Hungarian method) and drawn in that object's colour; unmatched clusters
    get colours of their own, so a split object shows as two colours on the right.

    Parameters
    ----------
    a : array-like of shape (n, 3)
        The a-points.
    labels_true, labels_pred : array-like of shape (n,)
        True and estimated clusters, ``-1`` for outliers.
    view : {"3d", "top", "bev", "camera"}, default="3d"
    camera : dict, default=None
        Intrinsics for ``view="camera"``.
    fig : matplotlib Figure, default=None
        Where to draw (empty); None: a new pyplot figure.
    titles : (str, str), default=("ground truth", "estimate")
    title : str, default=None
        Figure title.
    max_points : int or None, default=60000

    Returns
    -------
    fig : matplotlib Figure

    Examples
    --------
    >>> import matplotlib
    >>> matplotlib.use("Agg")
    >>> from matplotlib.figure import Figure
    >>> from mmreg import MultiModelRegistration
    >>> from mmreg.datasets import make_scene
    >>> from mmreg.plotting import plot_comparison
    >>> scene = make_scene(n_objects=3, n_points=600, random_state=0)
    >>> est = MultiModelRegistration(init=scene.labels).fit(scene.X)
    >>> fig = plot_comparison(scene.a, scene.labels, est.labels_, view="top", fig=Figure())
    >>> len(fig.axes)
    2
    """
    if view not in VIEWS:
        raise ValueError(f"view must be one of {VIEWS}; got {view!r}.")
    a = _check_points(a, "a")
    labels_true = _check_labels(labels_true, len(a), "labels_true")
    labels_pred = _check_labels(labels_pred, len(a), "labels_pred")
    wide = view == "camera"
    fig = _new_figure(fig, (12, 7.5) if wide else (12, 5.5))
    _use_constrained_layout(fig)
    true_table, pred_table = _matched_colors(labels_true, labels_pred)
    projection = "3d" if view == "3d" else None
    shape = (2, 1) if wide else (1, 2)
    panels = [
        (labels_true, true_table, titles[0], "object"),
        (labels_pred, pred_table, titles[1], "cluster"),
    ]
    for i, (labels, table, name, kind) in enumerate(panels):
        ax = fig.add_subplot(*shape, i + 1, projection=projection)
        plot_clusters(
            a,
            labels,
            ax=ax,
            view=view,
            camera=camera,
            colors=table,
            background=True,
            kind=kind,
            title=name,
            max_points=max_points,
        )
    if title is not None:
        fig.suptitle(title, fontsize=11)
    return fig
