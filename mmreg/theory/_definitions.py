"""Definitions 1 and 2 of Jin et al. (ICRA 2024) as checks on arrays.

Theorem 1 says that Algorithm 1, started from a ``(tau, alpha, m0)``-good clustering
(Definition 2) of a scene that satisfies Definition 1, returns a partition containing
every ground-truth object. These functions check both hypotheses on concrete data and
say which condition fails and by how much.
"""

from numbers import Integral, Real

import numpy as np
from scipy.spatial import cKDTree
from sklearn.utils import check_array
from sklearn.utils._param_validation import Interval, StrOptions, validate_params

from mmreg._array.connectivity import min_gap_between, tau_components
from mmreg._array.geometry import residuals
from mmreg._validation import check_labels, compact_labels, split_correspondences
from mmreg.theory._reports import Condition, GoodClusteringReport, GroundTruthReport

__all__ = ["is_good_clustering", "is_tau_connected", "satisfies_ground_truth"]

# Rounding allowance of the noise bound, relative to the size of the coordinates.
_NOISE_RTOL = 1e-9
# Tolerance on R^T R = I for a rotation given as data.
_ROTATION_ATOL = 1e-6


def _fmt(values, limit=8):
    """A short list for messages: the first ``limit`` values, then how many more."""
    values = [v.item() if hasattr(v, "item") else v for v in values]
    values = [round(v, 6) if isinstance(v, float) else v for v in values]
    more = f" and {len(values) - limit} more" if len(values) > limit else ""
    return f"{values[:limit]}{more}"


def _distinct_pairs(first, second, n_second):
    """Distinct rows of ``[first, second]`` (non-negative ints, ``second < n_second``)."""
    keys = np.unique(first.astype(np.int64) * n_second + second)
    return np.column_stack([keys // n_second, keys % n_second])


def _group_max(values, groups, n_groups):
    """Largest value in each group ``0..n_groups-1`` (0 for an empty group)."""
    out = np.zeros(n_groups)
    order = np.argsort(groups, kind="stable")
    groups, values = groups[order], values[order]
    starts = np.flatnonzero(np.r_[True, groups[1:] != groups[:-1]]) if len(groups) else []
    if len(starts):
        out[groups[starts]] = np.maximum.reduceat(values, starts)
    return out


def _pieces_per_group(points, tau, groups, n_groups):
    """Number of tau-connected pieces of each group ``0..n_groups-1`` (0 if empty)."""
    keep = groups >= 0
    n_pieces, comp = tau_components(points[keep], tau, groups[keep])
    distinct = _distinct_pairs(groups[keep], comp, max(n_pieces, 1))
    return np.bincount(distinct[:, 0], minlength=n_groups)


def _correspondences(X):
    X = check_array(X, dtype=np.float64, input_name="X")
    return split_correspondences(X)


@validate_params(
    {"points": ["array-like"], "tau": [Interval(Real, 0, None, closed="neither")]},
    prefer_skip_nested_validation=True,
)
def is_tau_connected(points, tau):
    """Whether a point set is ``tau``-connected (Section IV of the paper).

    A set is ``tau``-connected if any two of its points are joined by a chain of its
    points with consecutive gaps ``||p - q|| <= tau``. A set of correspondences is
    ``tau``-connected when its a-points are.

    Parameters
    ----------
    points : array-like of shape (n, d)
        The points, e.g. the a-points ``X[:, :3]`` of some correspondences.
    tau : float
        Largest gap, ``> 0``.

    Returns
    -------
    connected : bool
        True for a connected set; also for zero or one point.

    See Also
    --------
    satisfies_ground_truth : Definition 1, which needs every object ``tau``-connected.

    Notes
    -----
    ``O(n log n)`` whatever ``tau``: a grid of cells of side ``tau / sqrt(d)`` stands for
    the points, and only neighbouring cells that no witness pair already joins are
    compared point by point. About 0.1 s for 100,000 points.

    Examples
    --------
    >>> from mmreg.theory import is_tau_connected
    >>> points = [[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]
    >>> is_tau_connected(points, tau=1.0), is_tau_connected(points, tau=0.9)
    (True, False)
    """
    points = check_array(points, dtype=np.float64, ensure_min_samples=0, input_name="points")
    if len(points) <= 1:
        return True
    n_components, _ = tau_components(points, tau)
    return n_components == 1


def _transforms(transforms, n_dims):
    """``(rotations, translations)`` from a pair or an object with those attributes."""
    if hasattr(transforms, "rotations") and hasattr(transforms, "translations"):
        rotations, translations = transforms.rotations, transforms.translations
    else:
        try:
            rotations, translations = transforms
        except (TypeError, ValueError):
            raise TypeError(
                "transforms must be a pair (rotations, translations) of arrays of shapes "
                "(M, d, d) and (M, d), or an object with attributes rotations and "
                f"translations (e.g. a make_scene Bunch); got {type(transforms).__name__}."
            ) from None
    rotations = np.asarray(rotations, dtype=float)
    translations = np.asarray(translations, dtype=float)
    n = len(rotations) if rotations.ndim else 0
    if rotations.shape != (n, n_dims, n_dims) or translations.shape != (n, n_dims):
        raise ValueError(
            f"transforms must hold rotations of shape (M, {n_dims}, {n_dims}) and "
            f"translations of shape (M, {n_dims}) for {n_dims}-D points; got shapes "
            f"{rotations.shape} and {translations.shape}."
        )
    if n == 0:
        raise ValueError("transforms must hold at least one motion (M >= 1).")
    if not (np.all(np.isfinite(rotations)) and np.all(np.isfinite(translations))):
        raise ValueError("transforms contain NaN or infinity.")
    return rotations, translations


@validate_params(
    {
        "X": ["array-like"],
        "labels": ["array-like"],
        "transforms": "no_validation",
        "tau": [Interval(Real, 0, None, closed="neither")],
        "sigma": [Interval(Real, 0, None, closed="left")],
        "bound": [Interval(Real, 0, None, closed="left"), None],
    },
    prefer_skip_nested_validation=True,
)
def satisfies_ground_truth(X, labels, transforms, tau, sigma, *, bound=None):
    """Check Definition 1 (ground truth) of the paper on a labelled scene.

    The correspondences ``S`` are partitioned into objects ``G_1..G_M`` (``labels``
    ``0..M-1``) and outliers (negative labels) with motions ``g_j(a) = R_j a + t_j``, and
    for a distance ``tau`` and noise bound ``sigma``:

    1. **noise**: ``||b - R_j a - t_j||_inf <= sigma`` on every ``(a, b)`` in ``G_j``;
    2. **connected**: every ``G_j`` is ``tau``-connected;
    3. **separation**: a-points of different objects are more than ``tau`` apart;
    4. **bounded**: ``||a_i|| <= B`` for all ``i``;
    5. **outliers**: every outlier's a-point is more than ``tau`` from every object's.

    Besides these, ``partition`` checks that no object is empty and ``rigid`` that every
    ``R_j`` is a proper rotation.

    Parameters
    ----------
    X : array-like of shape (n, 2 * d)
        Stacked correspondences ``[a | b]``.
    labels : array-like of shape (n,)
        Object of each correspondence in ``0..M-1``; negative for outliers.
    transforms : (rotations, translations) or object with these attributes
        Arrays of shapes ``(M, d, d)`` and ``(M, d)``; the Bunch of
        :func:`~mmreg.datasets.make_scene` works as is.
    tau : float
        Distance threshold, ``> 0``.
    sigma : float
        Noise bound, ``>= 0``. Definition 1 draws the noise uniformly from
        ``[-sigma, sigma]^d``; only its support can be checked on data, so the check is
        the bound (up to a relative rounding allowance of ``1e-9`` of the coordinates).
    bound : float, default=None
        ``B``. None reports ``B = max ||a_i||`` and the condition holds.

    Returns
    -------
    report : GroundTruthReport
        Truthy iff every condition holds; ``str(report)`` says which fail and why, and
        its attributes hold the measured noise, pieces, separation, outlier gap and ``B``.

    Raises
    ------
    ValueError
        If ``labels`` index a motion that ``transforms`` does not have, or the shapes do
        not match.

    See Also
    --------
    is_good_clustering : Definition 2, the condition on the initial clusters.

    Notes
    -----
    ``O(n log n)``: connectivity on a grid (see :func:`is_tau_connected`), the
    separation from one KD-tree per object queried with nearby points only, the outliers
    from one KD-tree query. About 0.2 s for 100,000 correspondences.

    Examples
    --------
    >>> from mmreg.datasets import make_scene
    >>> from mmreg.theory import satisfies_ground_truth
    >>> scene = make_scene(n_objects=2, n_points=2000, noise=0.01, noise_type="uniform",
    ...                    random_state=0)
    >>> report = satisfies_ground_truth(scene.X, scene.labels, scene, tau=0.5, sigma=0.01)
    >>> bool(report)
    True
    >>> [c.name for c in satisfies_ground_truth(
    ...     scene.X, scene.labels, scene, tau=0.5, sigma=0.005).failures]
    ['noise']
    """
    a, b = _correspondences(X)
    n, d = a.shape
    labels = check_labels(labels, n)
    rotations, translations = _transforms(transforms, d)
    n_objects = len(rotations)
    if labels.max(initial=-1) >= n_objects:
        raise ValueError(
            f"labels go up to {labels.max()} but transforms hold only {n_objects} motions; "
            "label j must index the motion of object j."
        )
    labels = np.where(labels < 0, -1, labels)
    inlier = labels >= 0
    sizes = np.bincount(labels[inlier], minlength=n_objects)
    conditions = []

    empty = np.flatnonzero(sizes == 0)
    conditions.append(
        Condition(
            "partition",
            not len(empty),
            f"{n} correspondences: {int(inlier.sum())} in {n_objects} objects, "
            f"{int((~inlier).sum())} outliers"
            + (f"; objects {_fmt(empty)} are empty" if len(empty) else ""),
        )
    )

    gram = np.swapaxes(rotations, 1, 2) @ rotations
    orthogonality = np.max(np.abs(gram - np.eye(d)), axis=(1, 2))
    det = np.linalg.det(rotations)
    improper = np.flatnonzero((orthogonality > _ROTATION_ATOL) | (det <= 0))
    conditions.append(
        Condition(
            "rigid",
            not len(improper),
            f"motions {_fmt(improper)} are not proper rotations "
            f"(max |R^T R - I| = {_fmt(orthogonality[improper])}, det = {_fmt(det[improper])})"
            if len(improper)
            else f"{n_objects} proper rigid motions",
        )
    )

    worst = np.abs(residuals(a, b, rotations, translations, labels)).max(axis=1, initial=0.0)
    noise = _group_max(worst[inlier], labels[inlier], n_objects)
    scale = max(1.0, float(np.abs(a).max(initial=0.0)), float(np.abs(b).max(initial=0.0)))
    noisy = np.flatnonzero(noise > sigma + _NOISE_RTOL * scale)
    conditions.append(
        Condition(
            "noise",
            not len(noisy),
            f"objects {_fmt(noisy)} have |b - R a - t|_inf up to {_fmt(noise[noisy])} "
            f"> sigma = {sigma:.6g}"
            if len(noisy)
            else f"max |b - R a - t|_inf = {noise.max():.6g} <= sigma = {sigma:.6g}",
        )
    )

    pieces = _pieces_per_group(a, tau, labels, n_objects)
    split = np.flatnonzero(pieces > 1)
    conditions.append(
        Condition(
            "connected",
            not len(split),
            f"objects {_fmt(split)} fall into {_fmt(pieces[split])} tau-connected pieces"
            if len(split)
            else f"every object is tau-connected (tau = {tau:.6g})",
        )
    )

    separation, closest = min_gap_between(a, labels)
    conditions.append(
        Condition(
            "separation",
            separation > tau,
            f"objects {closest[0]} and {closest[1]} are {separation:.6g} apart"
            f"{' > ' if separation > tau else ' <= '}tau = {tau:.6g}"
            if closest is not None
            else "fewer than two objects",
        )
    )

    radius = float(np.sqrt(np.einsum("ij,ij->i", a, a)).max(initial=0.0))
    conditions.append(
        Condition(
            "bounded",
            bound is None or radius <= bound,
            f"max ||a_i|| = B = {radius:.6g}"
            + ("" if bound is None else (" <= " if radius <= bound else " > ") + f"{bound:.6g}"),
        )
    )

    outlier_gap = np.inf
    n_close = 0
    if (~inlier).any() and inlier.any():
        outlier_gap, _ = min_gap_between(a, np.where(inlier, 0, 1))
        if outlier_gap <= tau:
            dist, _ = cKDTree(a[inlier]).query(a[~inlier], k=1, distance_upper_bound=2 * tau)
            n_close = int(np.sum(dist <= tau))
    conditions.append(
        Condition(
            "outliers",
            n_close == 0,
            f"{n_close} of {int((~inlier).sum())} outliers are within tau = {tau:.6g} of an "
            f"object (closest {outlier_gap:.6g})"
            if n_close
            else (
                f"all {int((~inlier).sum())} outliers are {outlier_gap:.6g} > tau from every object"
                if (~inlier).any()
                else "no outliers"
            ),
        )
    )
    return GroundTruthReport(
        title=f"Definition 1 (tau={tau:.6g}, sigma={sigma:.6g})",
        conditions=tuple(conditions),
        n_objects=n_objects,
        noise=noise,
        pieces=pieces,
        separation=separation,
        outlier_gap=outlier_gap,
        bound=radius,
    )


@validate_params(
    {
        "init_labels": ["array-like"],
        "true_labels": ["array-like"],
        "X": ["array-like"],
        "tau": [Interval(Real, 0, None, closed="neither")],
        "alpha": [Interval(Real, 1, None, closed="left")],
        "m0": [Interval(Integral, 1, None, closed="left")],
        "outliers": [StrOptions({"exempt", "strict"})],
    },
    prefer_skip_nested_validation=True,
)
def is_good_clustering(init_labels, true_labels, X, tau, alpha, m0, *, outliers="exempt"):
    """Check Definition 2: is an initial clustering ``(tau, alpha, m0)``-good?

    The initial clusters ``H_1..H_K`` must partition the correspondences, with ``K >= M``
    and:

    1. **connected**: every ``H_k`` is ``tau``-connected;
    2. **size**: ``|H_k| >= m0``;
    3. **identifying**: for every object ``G``, the largest cluster ``H*`` meeting ``G``
       is more than ``alpha`` times larger than every other cluster meeting ``G``.

    ``pure`` is reported as well: every cluster lies in one object or holds only
    outliers. Under Definition 1 it follows from condition 1 (a ``tau``-connected set
    cannot reach across a gap wider than ``tau``), which is the first step of the proof
    of Theorem 1; a failure says the ground truth itself is not ``tau``-separated.

    Parameters
    ----------
    init_labels : array-like of shape (n,)
        Initial cluster of each correspondence; negative for none.
    true_labels : array-like of shape (n,)
        Ground-truth object of each correspondence; negative for outliers.
    X : array-like of shape (n, 2 * d)
        Stacked correspondences ``[a | b]``; only the a-points are used.
    tau : float
        Distance threshold, ``> 0``.
    alpha : float
        ``>= 1``. The definition asks for some ``alpha > 1``; since sizes are integers,
        ``alpha=1`` checks exactly that (``|H*|`` strictly larger than the rest).
    m0 : int
        Smallest allowed cluster size, ``>= 1``.
    outliers : {"exempt", "strict"}, default="exempt"
        How outliers (``true_labels < 0``) are treated.

        - ``"exempt"``: outliers may be in no cluster (``init_labels < 0``), and clusters
          made only of outliers are exempt from conditions 1 and 2. The proof never uses
          them: Definition 1 keeps outliers farther than ``tau`` from every object, so
          the distance gate of eq. (7) keeps such clusters and the objects apart.
        - ``"strict"``: the letter of the definition: every correspondence is in a
          cluster and every cluster, outliers' too, meets conditions 1 and 2.

        Either way, a cluster that holds outliers and object points is not ``pure`` (and
        not ``tau``-connected under Definition 1).

    Returns
    -------
    report : GoodClusteringReport
        Truthy iff every condition holds. ``report.max_alpha`` is the supremum of the
        ``alpha`` for which the identifying condition holds, ``report.max_m0`` the
        largest ``m0`` for which the size condition holds.

    See Also
    --------
    satisfies_ground_truth : Definition 1, the setting of this definition.

    Examples
    --------
    >>> import numpy as np
    >>> from mmreg.theory import is_good_clustering
    >>> a = np.column_stack([np.arange(12.0), np.zeros(12), np.zeros(12)])
    >>> X = np.hstack([a, a])                        # one object: a line of 12 points
    >>> truth = np.zeros(12, dtype=int)
    >>> init = np.repeat([0, 1], [8, 4])             # two tau-connected pieces, 8 and 4
    >>> report = is_good_clustering(init, truth, X, tau=1.5, alpha=1.5, m0=4)
    >>> bool(report), float(report.max_alpha)
    (True, 2.0)
    >>> [c.name for c in is_good_clustering(init, truth, X, tau=1.5, alpha=3, m0=5).failures]
    ['size', 'identifying']
    """
    a, _ = _correspondences(X)
    n = len(a)
    truth = check_labels(true_labels, n, name="true_labels")
    truth, n_objects = compact_labels(truth)
    init = check_labels(init_labels, n, name="init_labels")
    init, n_clusters = compact_labels(init)
    assigned = init >= 0
    sizes = np.bincount(init[assigned], minlength=n_clusters)
    conditions = []

    unassigned = ~assigned if outliers == "strict" else ~assigned & (truth >= 0)
    n_unassigned = int(unassigned.sum())
    conditions.append(
        Condition(
            "partition",
            n_unassigned == 0,
            (
                f"{n_unassigned} correspondences"
                + (" of objects" if outliers == "exempt" else "")
                + " are in no cluster"
            )
            if n_unassigned
            else f"{n_clusters} clusters cover the "
            + ("correspondences" if outliers == "strict" else "objects"),
        )
    )
    conditions.append(
        Condition(
            "count",
            n_clusters >= n_objects,
            f"K = {n_clusters} {'>=' if n_clusters >= n_objects else '<'} M = {n_objects}",
        )
    )

    # Which clusters meet an object, and which (cluster, object-or-outlier) pairs occur.
    # Outliers count as the kind n_objects here, and back to -1 after.
    kinds = _distinct_pairs(
        init[assigned], np.where(truth < 0, n_objects, truth)[assigned], n_objects + 1
    )
    kinds[kinds[:, 1] == n_objects, 1] = -1
    meets_object = np.zeros(n_clusters, dtype=bool)
    meets_object[kinds[kinds[:, 1] >= 0, 0]] = True
    subject = np.ones(n_clusters, dtype=bool) if outliers == "strict" else meets_object

    pieces = _pieces_per_group(a, tau, init, n_clusters)
    split = np.flatnonzero(subject & (pieces > 1))
    conditions.append(
        Condition(
            "connected",
            not len(split),
            f"clusters {_fmt(split)} fall into {_fmt(pieces[split])} tau-connected pieces"
            if len(split)
            else f"every cluster{'' if outliers == 'strict' else ' meeting an object'} is "
            f"tau-connected (tau = {tau:.6g})",
        )
    )

    max_m0 = int(sizes[subject].min()) if subject.any() else 0
    small = np.flatnonzero(subject & (sizes < m0))
    conditions.append(
        Condition(
            "size",
            not len(small),
            f"clusters {_fmt(small)} have {_fmt(sizes[small])} < m0 = {m0} correspondences"
            if len(small)
            else f"every cluster has >= {max_m0} >= m0 = {m0} correspondences",
        )
    )

    n_kinds = np.bincount(kinds[:, 0], minlength=n_clusters)
    mixed = np.flatnonzero(n_kinds > 1)
    conditions.append(
        Condition(
            "pure",
            not len(mixed),
            f"clusters {_fmt(mixed)} mix {_fmt(n_kinds[mixed])} objects (or outliers)"
            if len(mixed)
            else "every cluster lies in one object or holds only outliers",
        )
    )

    # For each object, |H*| / (second largest |H| among the clusters meeting it).
    meet = kinds[kinds[:, 1] >= 0]
    meet_size = sizes[meet[:, 0]]
    order = np.lexsort((-meet_size, meet[:, 1]))
    objects, meet_size = meet[order, 1], meet_size[order]
    first = np.searchsorted(objects, np.arange(n_objects))
    count = np.bincount(objects, minlength=n_objects)
    ratios = np.full(n_objects, np.nan)
    top = meet_size[np.minimum(first, len(meet_size) - 1)] if len(meet_size) else np.zeros(0)
    has_one = count >= 1
    ratios[has_one] = np.inf
    has_two = count >= 2
    ratios[has_two] = top[has_two] / meet_size[first[has_two] + 1]
    max_alpha = float(np.nanmin(ratios)) if has_one.any() else np.nan
    weak = np.flatnonzero(~(ratios > alpha))
    conditions.append(
        Condition(
            "identifying",
            not len(weak),
            f"objects {_fmt(weak)} have |H*| / next largest = {_fmt(ratios[weak])} "
            f"<= alpha = {alpha:.6g}"
            if len(weak)
            else f"min over objects of |H*| / next largest = {max_alpha:.6g} > alpha = {alpha:.6g}",
        )
    )
    return GoodClusteringReport(
        title=f"Definition 2 (tau={tau:.6g}, alpha={alpha:.6g}, m0={m0})",
        conditions=tuple(conditions),
        n_clusters=n_clusters,
        n_objects=n_objects,
        sizes=sizes,
        pieces=pieces,
        ratios=ratios,
        max_alpha=max_alpha,
        max_m0=max_m0,
    )
