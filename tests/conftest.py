"""Shared test set-up: hypothesis profiles and small synthetic scenes."""

import os
import signal

import numpy as np
import pytest
from hypothesis import HealthCheck, settings

from mmreg.datasets import make_scene

# "ci": derandomised and short, so CI is reproducible and fast; "thorough": for local runs.
settings.register_profile(
    "ci",
    derandomize=True,
    max_examples=25,
    deadline=None,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.register_profile("dev", max_examples=50, deadline=None)
settings.register_profile(
    "thorough", max_examples=1000, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "dev"))


def terminal_sigint():
    """``preexec_fn`` of a child that must take Ctrl-C as a terminal's job does: SIGINT at
    its default, even when this test run inherited it ignored (a script's ``cmd &`` job)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def split_init(labels, pieces=3, ratio=2.0, random_state=0):
    """Over-segment every object into ``pieces`` parts, the first ``ratio`` times the next.

    A (tau, alpha, m0)-good style initial clustering for tests that need one quickly
    (the pieces are random subsets, so not tau-connected unless the object is small).
    """
    rng = np.random.default_rng(random_state)
    out = np.full(len(labels), -1)
    next_label = 0
    for obj in np.unique(labels[labels >= 0]):
        idx = rng.permutation(np.flatnonzero(labels == obj))
        weights = np.array([ratio] + [1.0] * (pieces - 1))
        cuts = np.round(np.cumsum(weights / weights.sum()) * len(idx)).astype(int)[:-1]
        for part in np.split(idx, cuts):
            out[part] = next_label
            next_label += 1
    return out


@pytest.fixture
def noiseless_scene():
    return make_scene(n_objects=4, n_points=800, random_state=0)


@pytest.fixture
def noisy_scene():
    return make_scene(n_objects=4, n_points=1200, noise=0.01, noise_type="uniform", random_state=1)


@pytest.fixture(scope="module")
def scheduler():
    """An in-process Dask cluster of one worker: jobs run one after the other."""
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0"
    ) as cluster:
        yield cluster.scheduler_address
