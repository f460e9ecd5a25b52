"""Where a run's tasks go: this process, or worker processes of a LocalCluster, and how many.

A LocalCluster costs seconds before its first result (its start, 3.5 s of a 5-pair run
on 2 cores, then every worker's imports), and a worker beside a job that keeps several
threads busy only takes cores from it: on 2 cores, one worker per core was slower than
one worker in 4 of 4 logs (70.5 s against 40.3 s). So by default the tasks run in this
process, without a cluster, unless several fit side by side (the cores over each task's
own threads, on the cores other processes leave free) and the work left after the
first task, timed here, outweighs the cluster's cost with a margin
(:func:`worth_a_cluster`).
"""

import math
import os
import time

__all__ = [
    "CLUSTER_START_S",
    "available_cores",
    "default_workers",
    "free_cores",
    "run_tasks",
    "task_threads",
    "worth_a_cluster",
]

#: Seconds a LocalCluster costs before it works (its start and the workers' imports),
#: counted twice over in :func:`worth_a_cluster`: a shared machine's cores are not all ours.
CLUSTER_START_S = 5.0


def available_cores():
    """The cores this process may run on (its CPU affinity where the system tells it)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # macOS, Windows
        return max(1, os.cpu_count() or 1)


def free_cores(cores=None, load=None):
    """The cores not kept busy by other processes: ``cores`` less the system's load over
    the last minute beyond this process's own one (``os.getloadavg``), rounded, at least 1.

    On a machine shared with others, two workers on 2 cores each ran at a third of the
    speed of one (a load of 3); counting the cores alone would start them.

    Examples
    --------
    >>> from mmreg.runner._workers import free_cores
    >>> free_cores(2, load=0.2), free_cores(2, load=3.6), free_cores(8, load=3.0)
    (2, 1, 6)
    """
    cores = available_cores() if cores is None else int(cores)
    if load is None:
        try:
            load = os.getloadavg()[0]
        except (AttributeError, OSError):  # Windows: no load average
            load = 0.0
    others = max(0.0, float(load) - 1.0)
    return max(1, min(cores, math.floor(cores - others + 0.5)))


def task_threads(estimator, cores=None):
    """The threads one task of ``estimator`` keeps busy: the largest ``n_jobs`` among its
    parameters and its inner estimators' (None: one; -1: every core, scikit-learn's
    rule), at most ``cores``.

    Examples
    --------
    >>> from mmreg import MultiModelRegistration, SweepRegistration
    >>> from mmreg.runner._workers import task_threads
    >>> task_threads(SweepRegistration(MultiModelRegistration()), cores=8)
    1
    >>> task_threads(SweepRegistration(MultiModelRegistration(n_jobs=-1)), cores=8)
    8
    """
    cores = available_cores() if cores is None else int(cores)
    params = {}
    if hasattr(estimator, "get_params"):
        try:
            params = estimator.get_params(deep=True)
        except Exception:  # an estimator that cannot list its parameters: one thread
            params = {}
    threads = 1
    for key, value in params.items():
        if not (key == "n_jobs" or key.endswith("__n_jobs")) or value is None:
            continue
        try:
            value = int(value)
        except (TypeError, ValueError):
            continue
        threads = max(threads, cores + 1 + value if value < 0 else value)
    return max(1, min(threads, cores))


def default_workers(n_tasks, threads=1, cores=None):
    """Worker processes for ``n_tasks`` tasks of ``threads`` threads each on ``cores``
    cores (default: :func:`free_cores`): as many as fit side by side, at most one per
    task; 0 (run the tasks in this process, no cluster) when fewer than two would.

    Examples
    --------
    >>> from mmreg.runner._workers import default_workers
    >>> default_workers(1, cores=8)  # a single log: no cluster
    0
    >>> default_workers(39, cores=2), default_workers(39, threads=2, cores=2)
    (2, 0)
    >>> default_workers(3, cores=8)
    3
    """
    cores = free_cores() if cores is None else int(cores)
    workers = min(int(n_tasks), cores // max(1, int(threads)))
    return workers if workers >= 2 else 0


def worth_a_cluster(n_left, seconds_per_task, workers, start_s=CLUSTER_START_S):
    """Whether ``workers`` worker processes would finish ``n_left`` tasks of
    ``seconds_per_task`` each sooner than this process alone, by twice the cluster's
    cost ``start_s`` (its start, the workers' imports; the margin: a shared machine's
    cores are not all free).

    Examples
    --------
    >>> from mmreg.runner._workers import worth_a_cluster
    >>> worth_a_cluster(3, 0.9, 2)  # the rest of a 4-frame log: 2.7 s in all
    False
    >>> worth_a_cluster(38, 0.9, 2)  # the rest of a 40-frame log: 34 s
    True
    """
    if workers < 2 or n_left < 2 or not math.isfinite(seconds_per_task):
        return False
    workers = min(workers, n_left)
    saved = n_left * seconds_per_task * (1.0 - 1.0 / workers)
    return saved > 2.0 * start_s


def run_tasks(tasks, here, cluster, *, scheduler=None, n_workers=None, threads=1):
    """Run ``tasks`` in this process or on a cluster; what was done, for the record.

    ``here(tasks)`` runs tasks in this process, ``cluster(tasks, scheduler, n_workers)``
    on the cluster at ``scheduler`` or on a new LocalCluster of ``n_workers`` workers
    (and returns the seconds its start took). ``scheduler`` given: there; ``n_workers``
    0: here; another number: a LocalCluster of that many; None: :func:`default_workers`
    decides, and when it would start some, the first task runs here, timed, and the rest
    go to a cluster only if :func:`worth_a_cluster`.

    Returns
    -------
    plan : dict
        ``where`` ("this process", "local cluster" or the scheduler's address),
        ``workers`` (0 here), ``start_s`` (the cluster's start, 0 here) and ``why``.
    """
    tasks = list(tasks)
    plan = {"where": "this process", "workers": 0, "start_s": 0.0, "why": ""}
    if not tasks:
        return plan | {"why": "nothing to run"}
    if scheduler is not None:
        start_s = cluster(tasks, scheduler, None)
        return plan | {
            "where": str(scheduler),
            "workers": None,
            "start_s": start_s,
            "why": "--scheduler",
        }
    if n_workers is not None:
        if n_workers == 0:
            here(tasks)
            return plan | {"why": "--n-workers 0"}
        start_s = cluster(tasks, None, n_workers)
        return plan | {
            "where": "local cluster",
            "workers": n_workers,
            "start_s": start_s,
            "why": "--n-workers",
        }
    cores = free_cores()
    workers = default_workers(len(tasks), threads, cores)
    if not workers:
        why = (
            "one task"
            if len(tasks) == 1
            else (
                f"{cores} free core{'s' if cores != 1 else ''} for tasks of "
                f"{threads} thread{'s' if threads != 1 else ''}"
            )
        )
        here(tasks)
        return plan | {"why": why}
    begin = time.perf_counter()
    here(tasks[:1])
    seconds = time.perf_counter() - begin
    rest = tasks[1:]
    workers = default_workers(len(rest), threads, cores)
    if not worth_a_cluster(len(rest), seconds, workers):
        here(rest)
        return plan | {"why": f"{len(tasks)} tasks of {seconds:.1f} s: a cluster would not pay"}
    start_s = cluster(rest, None, workers)
    return plan | {
        "where": "local cluster",
        "workers": workers,
        "start_s": start_s,
        "why": f"{len(rest)} tasks of {seconds:.1f} s left on {cores} free cores",
    }
