"""scikit-learn's own estimator checks on every estimator of the package."""

import numpy as np
import pytest
from sklearn.cluster import KMeans
from sklearn.utils.estimator_checks import parametrize_with_checks

from mmreg import (
    MultiModelRegistration,
    NaiveRegistration,
    SequentialRANSAC,
    SweepRegistration,
    TLinkage,
)
from mmreg.init import (
    DBSCANClustering,
    EuclideanClustering,
    PrecomputedLabels,
    PrecomputedMasks,
)

# X holds stacked correspondences [a | b], so it must have an even number of columns.
# These checks feed data with 3 or 5 columns and cannot apply; every other check must pass.
ODD_COLUMNS = "the check uses X with an odd number of columns, which are not [a | b] pairs"
ODD_COLUMN_CHECKS = (
    "check_dict_unchanged",
    "check_dont_overwrite_parameters",
    "check_estimators_dtypes",
    "check_estimators_nan_inf",
    "check_estimators_pickle",
    "check_f_contiguous_array_estimator",
    "check_fit2d_predict1d",
    "check_fit_score_takes_y",
    "check_methods_sample_order_invariance",
    "check_methods_subset_invariance",
    "check_pipeline_consistency",
    # Transformers only (the initialisers):
    "check_transformer_data_not_an_array",
    "check_transformer_general",
)
BLOBS_ARE_NOT_MOTIONS = (
    "check_clustering reads 50 Gaussian blobs in 2 columns as 1-D correspondences b = a + t; "
    "they are no rigid motions, and this estimator groups by motion (the EM from the default "
    "100-cluster init merges the blobs, which share one translation; RANSAC uses the motion only)"
)
# Precomputed labels and pixels belong to one X: these checks fit on X of other lengths.
FIXED_ROWS = "the labels (or pixels) are given for 30 rows; the check fits on another number"
FIXED_ROW_CHECKS = (
    "check_clustering",
    "check_dtype_object",
    "check_estimators_fit_returns_self",
    "check_estimators_overwrite_params",
    "check_fit2d_1sample",
    "check_fit_check_is_fitted",
    "check_fit_idempotent",
    "check_n_features_in",
    "check_n_features_in_after_fitting",
    "check_positive_only_tag_during_fit",
    "check_readonly_memmap_input",
)


# These checks fit random rows, whose a- and b-halves are two unrelated point clouds:
# MultiModelRegistration refuses them (mmreg._validation.check_paired).
RANDOM_ROWS = "random rows are not correspondences, and are refused"
RANDOM_ROW_CHECKS = (
    "check_estimators_overwrite_params",
    "check_estimators_fit_returns_self",
    "check_readonly_memmap_input",
)
# Without tau only the scene's radius and spacing bound the refusal: more checks' rows.
RANDOM_ROW_CHECKS_WITHOUT_TAU = (
    "check_fit_idempotent",
    "check_fit_check_is_fitted",
    "check_n_features_in",
)


def expected_failed_checks(estimator):
    failures = dict.fromkeys(ODD_COLUMN_CHECKS, ODD_COLUMNS)
    default_em = isinstance(estimator, MultiModelRegistration) and estimator.init == "euclidean"
    # SweepRegistration without a sweep is its default estimator, the EM from 100 clusters.
    default_em |= isinstance(estimator, SweepRegistration)
    if default_em or isinstance(estimator, SequentialRANSAC):
        failures["check_clustering"] = BLOBS_ARE_NOT_MOTIONS
    if isinstance(estimator, MultiModelRegistration):
        failures.update(dict.fromkeys(RANDOM_ROW_CHECKS, RANDOM_ROWS))
        if estimator.tau is None:
            failures.update(dict.fromkeys(RANDOM_ROW_CHECKS_WITHOUT_TAU, RANDOM_ROWS))
    if isinstance(estimator, (PrecomputedLabels, PrecomputedMasks)):
        failures.update(dict.fromkeys(FIXED_ROW_CHECKS, FIXED_ROWS))
    return failures


ROWS = np.arange(30)


# The checks fit on a few dozen points, where the estimators rightly warn about their
# defaults (100 initial clusters, tau=1.5 or 5 against points a metre apart) and about
# inputs in which nothing survives; those warnings are the checks' data, not the API.
@pytest.mark.filterwarnings("ignore:No radius tried gives n_clusters:UserWarning")
@pytest.mark.filterwarnings("ignore::mmreg.estimators.ScaleWarning")
@pytest.mark.filterwarnings("ignore:No cluster survived:mmreg.estimators.DegenerateInputWarning")
@pytest.mark.filterwarnings("ignore:DBSCAN found no cluster:mmreg.init._dbscan.AllOutliersWarning")
@parametrize_with_checks(
    [
        MultiModelRegistration(),
        SweepRegistration(),
        MultiModelRegistration(tau=None, init=KMeans(n_clusters=3, n_init=1), random_state=0),
        NaiveRegistration(),
        NaiveRegistration(init=KMeans(n_clusters=3, n_init=1), random_state=0),
        SequentialRANSAC(random_state=0),
        TLinkage(),
        TLinkage(init=KMeans(n_clusters=3, n_init=1), n_hypotheses=20, random_state=0),
        EuclideanClustering(n_clusters=3, min_cluster_size=1),
        EuclideanClustering(radius=0.5),
        DBSCANClustering(eps=0.5, backend="sklearn"),
        PrecomputedLabels(ROWS % 3),
        PrecomputedMasks(ROWS.reshape(5, 6) % 4, np.column_stack([ROWS % 6, ROWS // 6])),
    ],
    expected_failed_checks=expected_failed_checks,
)
def test_sklearn_compatible(estimator, check):
    check(estimator)
