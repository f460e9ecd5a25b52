"""Multi-model registration on real scene flow: Argoverse 2 sweeps and FlyingThings3D frames.

``python benchmarks/real.py --data ../shared/realdata`` runs every method on every scene
found there, prints one Markdown table and writes ``benchmarks/results/real.csv`` (one row
per scene, method and seed) and ``real.md`` (the table and what its columns mean).
``--ablation`` instead runs the default with each robust step turned off in turn
(``ROBUST_STEPS``, ``skip_steps``) and writes ``real_ablation.csv`` and ``.md``;
``--ablation sweep`` does the same for ``variant="sweep"`` (``real_ablation_sweep.*``).
With ``--scenes`` it runs in minutes rather than the better part of an hour.

The data folder is read, never copied: its ``load.py`` is imported at run time and gives
``list_scenes(root)`` and ``load_scene(name, root=..., drop_ground=True)`` (see its
README.md and SOURCES.md). Scenes that are absent are skipped with a note.

Protocol. Ground points are removed (``drop_ground=True``); points labelled -1 (unknown
motion) are kept in the input but left out of every score. Each scene gives one or more
inputs ``b = a + flow_in``:

``icpflow_av2_demo/zeroflow``  ZeroFlow's estimated flow (a real network's errors);
``<scene>/gt``                 the ground-truth flow;
``av2_api_*/noisy``            the ground-truth flow with every moving object's flow scaled
                               by 0.9 (a bias like ZeroFlow's) plus 2 cm Gaussian noise per
                               axis on every point (seeded by the seed).

Methods, each with its defaults and tau = 5 m (the paper's street and FlyingThings3D
setting) where it takes a tau: ``mmreg`` (``MultiModelRegistration()``, whose default is
``variant="sweep"``), ``sweep`` and ``robust`` (those variants: ``robust`` is the earlier
default, one noise scale shared by all clusters), ``paper``
(``variant="paper"``), ``voxel`` (the default fitted on one correspondence per 0.3 m
voxel, ``voxel_size=0.3``; ``voxel0.2`` another side) and the baselines of
:mod:`mmreg.methods` (``naive``,
``sequential_ransac``, ``t_linkage``); any name of ``available_methods()`` works. The
initialisation is each method's default (Euclidean clustering, 100 clusters). A baseline
whose fit takes longer than ``--max-seconds`` is skipped on the remaining scenes.

Columns (scored points: ground-truth label >= 0):

``n``                 correspondences (ground removed); ``time_s``: ``fit``, init included
                      (the default Euclidean init is computed once per input and shared
                      by the methods that use it, its time, ``init_s``, added to each);
``clusters``          clusters reported (``n_clusters_``);
``moving_found``      moving objects (label >= 1 with >= 50 points) recovered by a cluster
                      with IoU >= 0.5 (:func:`mmreg.metrics.objects_found`), as found/total;
``static_in_largest`` share of the static world (label 0) in its single largest cluster;
``static_moving``     clusters that are mostly static world (> 50 % label 0) yet reported
                      moving, and ``static_moving_share`` the share of the static world in
                      them. Static cluster and moving flags: the estimator's
                      ``static_cluster_`` and ``moving_`` if it has them, else the largest
                      cluster is static and a cluster moves when its motion carries its
                      points more than 3 cm, on average, away from the static motion's
                      (``moving_from``: which one was used);
``iou``               the paper's IoU (:func:`mmreg.metrics.iou_score`);
``epe_in``/``epe``    EPE3D (m) of the input flow ``b - a`` / of the rigid flow ``flow_``
                      against the ground-truth flow; ``acc3ds``, ``acc3dr``, ``outliers3d``:
                      HPLFlowNet's measures of the rigid flow
                      (:func:`mmreg.metrics.scene_flow_metrics`);
``3way_in``/``3way``  Argoverse 2's three-way EPE (:func:`mmreg.metrics.three_way_epe`) on
                      its evaluation region (|x|, |y| <= 50 m), where the scene has
                      foreground (in a cuboid of any AV2 category) and dynamic (0.5 m/s
                      relative to the static world) information; the three classes are in
                      the CSV (``fd``, ``fs``, ``bs``);
``dyn_iou``           IoU of the dynamic class (Argoverse 2's "Dynamic IoU") with the
                      rigid flow's points marked dynamic by the same speed rule relative
                      to the static cluster's motion (every point, when the estimator
                      says there is no static cluster: ``static_cluster_ == -1``);
``epe_obj_in``/``epe_obj``  EPE of the input / rigid flow on each moving object, the mean
                      over objects in the table, each object's in the CSV (``label:epe``);
``labelled_-1``       share of all correspondences the method labels -1 (outliers);
``static_cluster``    the static cluster used (-1: none), ``warnings`` those fit raised.
"""

import argparse
import importlib.util
import os
import platform
import subprocess
import sys
import time
import warnings
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pandas as pd

import mmreg
from mmreg.init._resolve import initial_labels
from mmreg.methods import available_methods, make_method
from mmreg.metrics import (
    dynamic_iou,
    dynamic_mask,
    iou_score,
    objects_found,
    scene_flow_metrics,
    three_way_epe,
)

HERE = Path(__file__).resolve().parent
DEFAULT_DATA = Path(os.environ.get("MMREG_REALDATA", HERE.parent.parent / "shared" / "realdata"))

TAU = 5.0  # metres: the paper's street and FlyingThings3D setting
MIN_OBJECT_POINTS = 50  # a moving object counts when it has this many points
MOVING_DISTANCE = 0.03  # metres: the fallback rule for a moving cluster
AV2_EVAL_RANGE = 50.0  # metres: Argoverse 2 scores points with |x|, |y| <= 50
NOISE_STD = 0.02  # metres per axis
NOISE_SCALE = 0.9  # moving objects' flow is scaled by this in the noisy variant

DEFAULT_METHODS = ("mmreg", "robust", "paper", "naive", "sequential_ransac", "t_linkage")
# The side of the voxels of the ``voxel`` method (the default fitted on one
# correspondence per voxel), in metres.
VOXEL_SIZE = 0.3
BASELINES = ("naive", "sequential_ransac", "t_linkage")

# The inputs made from each scene; scenes not listed give their ground-truth flow only.
VARIANTS = {
    "icpflow_av2_demo": ("zeroflow", "gt"),
    "av2_api_7fab2350": ("gt", "noisy"),
    "av2_api_adcf7d18": ("gt", "noisy"),
}
SCENE_ORDER = (
    "icpflow_av2_demo",
    "av2_api_7fab2350",
    "av2_api_adcf7d18",
    "flyout_ft3d_0000710",
    "flyout_ft3d_0001325",
    "flyout_ft3d_0001435",
    "flyout_ft3d_0003086",
    "ddf_loss_ft3d",
)


@dataclass
class Case:
    """One input of the benchmark: a scene, a flow given to the methods and the truth."""

    scene: str
    a: np.ndarray
    b: np.ndarray
    flow_true: np.ndarray
    labels: np.ndarray
    moving: np.ndarray
    foreground: np.ndarray | None = None
    dynamic: np.ndarray | None = None
    region: np.ndarray | None = None


# --- data ----------------------------------------------------------------------------


def import_loader(data):
    """The ``load`` module of the data folder, or None (with the reason) if there is none."""
    path = Path(data) / "load.py"
    if not path.is_file():
        return None, f"no load.py in {data}"
    spec = importlib.util.spec_from_file_location(f"_realdata_load_{abs(hash(path))}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module, ""


def _static_flow(scene):
    """The flow every point would have with the static world's motion (label 0)."""
    if scene.transforms is None or not len(scene.transforms):
        return np.zeros_like(scene.a)
    T = np.asarray(scene.transforms[0], dtype=float)
    return scene.a @ T[:3, :3].T + T[:3, 3] - scene.a


def _foreground(scene):
    """Points in an annotated object's cuboid, or None where the scene does not say."""
    extras = scene.extras
    if "category" in extras:  # av2-api CATEGORY_TO_INDEX: 0 = NONE
        return np.asarray(extras["category"]) > 0
    if "classes" in extras:  # ZeroFlow's CATEGORY_MAP: -1 = background
        return np.asarray(extras["classes"]) >= 0
    return None


def make_cases(loader, data, name, variants, seed):
    """The benchmark inputs of one scene; a list of (Case or None, note)."""
    scene = loader.load_scene(name, root=str(data), drop_ground=True)
    if scene.labels is None:
        return [(None, f"{name}: no labels, skipped")]
    a = np.asarray(scene.a, dtype=float)
    flow_true = np.asarray(scene.flow, dtype=float)
    labels = np.asarray(scene.labels, dtype=np.intp)
    ids, counts = np.unique(labels[labels >= 1], return_counts=True)
    moving = ids[counts >= MIN_OBJECT_POINTS]
    foreground = _foreground(scene)
    dynamic = region = None
    if foreground is not None:
        if "dynamic" in scene.extras:
            dynamic = np.asarray(scene.extras["dynamic"], dtype=bool)
        else:
            dynamic = dynamic_mask(flow_true, _static_flow(scene))
        region = np.all(np.abs(a[:, :2]) <= AV2_EVAL_RANGE, axis=1)
    out = []
    for variant in variants:
        if variant == "gt":
            flow_in = flow_true
        elif variant == "zeroflow":
            if "est_flow_zeroflow" not in scene.extras:
                out.append((None, f"{name}/zeroflow: no est_flow_zeroflow, skipped"))
                continue
            flow_in = np.asarray(scene.extras["est_flow_zeroflow"], dtype=float)
        elif variant == "noisy":
            rng = np.random.default_rng(seed)
            flow_in = np.where((labels >= 1)[:, None], NOISE_SCALE * flow_true, flow_true)
            flow_in = flow_in + rng.normal(scale=NOISE_STD, size=flow_in.shape)
        else:
            raise ValueError(f"unknown variant {variant!r}")
        out.append(
            (
                Case(
                    scene=f"{name}/{variant}",
                    a=a,
                    b=a + flow_in,
                    flow_true=flow_true,
                    labels=labels,
                    moving=moving,
                    foreground=foreground,
                    dynamic=dynamic,
                    region=region,
                ),
                "",
            )
        )
    return out


def select_scenes(available, wanted):
    """``[(scene, variants)]`` for the scenes asked for (``name`` or ``name/variant``)."""
    order = [s for s in SCENE_ORDER if s in available] + sorted(
        s for s in available if s not in SCENE_ORDER
    )
    notes = []
    if wanted is None:
        return [(s, VARIANTS.get(s, ("gt",))) for s in order], notes
    chosen = {}
    for item in wanted:
        name, _, variant = item.partition("/")
        if name not in available:
            notes.append(f"{name}: not in the data folder, skipped")
            continue
        variants = VARIANTS.get(name, ("gt",))
        if variant and variant not in variants:
            notes.append(f"{item}: unknown variant (known: {', '.join(variants)}), skipped")
            continue
        chosen.setdefault(name, [])
        for v in [variant] if variant else variants:
            if v not in chosen[name]:
                chosen[name].append(v)
    return [(s, tuple(chosen[s])) for s in order if s in chosen], notes


# --- methods -------------------------------------------------------------------------


def robust_steps():
    """The robust steps that ``skip_steps`` can turn off, or None with the reason."""
    from mmreg import MultiModelRegistration

    try:
        from mmreg.em import _robust as _robust_em
    except ImportError as exc:  # pragma: no cover - the module exists today
        return None, f"mmreg.em._robust cannot be imported ({exc})"
    steps = getattr(_robust_em, "ROBUST_STEPS", None)
    if steps is None:
        return None, "mmreg.em._robust has no ROBUST_STEPS"
    if "skip_steps" not in MultiModelRegistration().get_params():
        return None, "MultiModelRegistration has no skip_steps parameter"
    return tuple(steps), ""


def estimator_variants():
    """The ``variant`` values MultiModelRegistration accepts."""
    from mmreg import MultiModelRegistration

    for constraint in MultiModelRegistration._parameter_constraints.get("variant", []):
        options = getattr(constraint, "options", None)
        if options:
            return set(options)
    return {"robust", "paper"}


def default_methods():
    """The default methods that this version of mmreg offers (variants only if they exist)."""
    variants = estimator_variants()
    return [m for m in DEFAULT_METHODS if m not in ("sweep", "robust") or m in variants]


def _base_and_step(name):
    """``("mmreg", step)`` for ``"mmreg-no-<step>"``, ``("sweep", step)`` likewise, or None."""
    for base in ("mmreg", "sweep"):
        if name.startswith(f"{base}-no-"):
            return base, name.removeprefix(f"{base}-no-")
    return None


def _voxel_size(name):
    """The voxel side of ``"voxel"`` (0.3) or ``"voxel<size>"`` (e.g. ``"voxel0.2"``),
    None for any other name."""
    if not name.startswith("voxel"):
        return None
    try:
        return float(name.removeprefix("voxel") or VOXEL_SIZE)
    except ValueError:
        return None


def build_method(name, seed):
    """A new estimator of the benchmark's method ``name``."""
    from mmreg import MultiModelRegistration

    ablated = _base_and_step(name)
    skip = {} if ablated is None else {"skip_steps": (ablated[1],)}
    base = name if ablated is None else ablated[0]
    if base == "mmreg":
        return MultiModelRegistration(tau=TAU, random_state=seed, **skip)
    if base in ("sweep", "robust", "paper"):
        return MultiModelRegistration(variant=base, tau=TAU, random_state=seed, **skip)
    size = _voxel_size(base)
    if size is not None:
        return MultiModelRegistration(tau=TAU, voxel_size=size, random_state=seed, **skip)
    return make_method(name, tau=TAU, random_state=seed, strict=False)


def check_methods(names):
    extra = {"paper"} | ({"sweep", "robust"} & estimator_variants())
    known = set(available_methods()) | extra
    unknown = [m for m in names if m not in known and _voxel_size(m) is None]
    if unknown:
        raise SystemExit(
            f"real.py: error: unknown method(s) {', '.join(unknown)}; available: "
            f"{', '.join([*sorted(extra), *available_methods()])}"
        )


class SharedInit:
    """The default initial clusters of one input, computed once for every method using them.

    A method whose ``init`` is the ``"euclidean"`` shortcut gets the labels that its own
    ``fit`` would compute (through the same :func:`~mmreg.init._resolve.initial_labels`
    call, with the same seed), so its result is unchanged; the time of that computation
    is added to the method's fit time. Any other ``init`` is left to the method.
    """

    def __init__(self, X, seed):
        self.X, self.seed = X, seed
        self.labels, self.seconds = None, 0.0

    def give(self, est):
        params = est.get_params(deep=False)
        # A voxel fit clusters its own sample, not every row.
        if params.get("init") != "euclidean" or params.get("voxel_size") is not None:
            return 0.0
        if self.labels is None:
            start = time.perf_counter()
            self.labels = initial_labels("euclidean", self.X, random_state=self.seed)
            self.seconds = time.perf_counter() - start
        est.set_params(init=self.labels)
        return self.seconds


# --- scores --------------------------------------------------------------------------


def static_and_moving(est, a):
    """Static cluster, moving flag of every cluster, and where they come from."""
    labels = est.labels_
    n_clusters = int(est.n_clusters_)
    static = getattr(est, "static_cluster_", None)
    moving = getattr(est, "moving_", None)
    if static is not None and moving is not None:
        return int(static), np.asarray(moving, dtype=bool), "estimator"
    if n_clusters == 0:
        return -1, np.zeros(0, dtype=bool), "fallback"
    sizes = np.bincount(labels[labels >= 0], minlength=n_clusters)
    static = int(np.argmax(sizes))
    rotations, translations = est.rotations_, est.translations_
    moving = np.zeros(n_clusters, dtype=bool)
    for j in range(n_clusters):
        points = a[labels == j]
        if j == static or not len(points):
            continue
        gap = points @ (rotations[j] - rotations[static]).T + (
            translations[j] - translations[static]
        )
        moving[j] = np.linalg.norm(gap, axis=1).mean() > MOVING_DISTANCE
    return static, moving, "fallback"


def _object_epes(flow_true, flow, labels, objects):
    errors = np.linalg.norm(flow - flow_true, axis=1)
    return {int(k): float(errors[labels == k].mean()) for k in objects}


def _format_objects(epes):
    return ";".join(f"{k}:{v:.3f}" for k, v in epes.items())


def score(case, method, est, seconds, caught):
    """One row of the table."""
    truth = case.labels
    scored = truth >= 0
    pred = np.asarray(est.labels_)
    flow = np.asarray(est.flow_, dtype=float)
    flow_in = case.b - case.a
    t, p = truth[scored], pred[scored]

    static, moving, moving_from = static_and_moving(est, case.a)
    static_points = t == 0
    in_cluster = p[static_points]
    in_cluster = in_cluster[in_cluster >= 0]
    largest = np.bincount(in_cluster).max() if len(in_cluster) else 0
    static_moving, static_moving_points = 0, 0
    for j in np.flatnonzero(moving):
        members = p == j
        n_static = np.count_nonzero(members & static_points)
        if n_static > 0.5 * np.count_nonzero(members):
            static_moving += 1
            static_moving_points += n_static

    row = {
        "scene": case.scene,
        "method": method,
        "n": len(case.a),
        "time_s": seconds,
        "clusters": int(est.n_clusters_),
        "moving_found": np.nan,
        "moving_total": len(case.moving),
        "static_in_largest": largest / max(np.count_nonzero(static_points), 1),
        "static_moving": static_moving,
        "static_moving_share": static_moving_points / max(np.count_nonzero(static_points), 1),
        "moving_from": moving_from,
        "static_cluster": static,
        "iou": iou_score(t, p),
    }
    if len(case.moving):
        row["moving_found"] = round(
            objects_found(t, p, objects=case.moving, min_iou=0.5) * len(case.moving)
        )
    finite = np.all(np.isfinite(flow), axis=1) & scored
    measures_in = scene_flow_metrics(case.flow_true[scored], flow_in[scored])
    row["epe_in"] = measures_in["EPE3D"]
    if finite.any():
        measures = scene_flow_metrics(case.flow_true[finite], flow[finite])
    else:
        measures = dict.fromkeys(("EPE3D", "Acc3DS", "Acc3DR", "Outliers3D"), np.nan)
    row.update(
        epe=measures["EPE3D"],
        acc3ds=measures["Acc3DS"],
        acc3dr=measures["Acc3DR"],
        outliers3d=measures["Outliers3D"],
        unscored_flow=int(np.count_nonzero(scored & ~finite)),
    )
    for key in ("3way_in", "3way", "fd_in", "fs_in", "bs_in", "fd", "fs", "bs", "dyn_iou"):
        row[key] = np.nan
    if case.foreground is not None:
        keep = scored & case.region
        for suffix, estimate, rows in (("_in", flow_in, keep), ("", flow, keep & finite)):
            if not rows.any():
                continue
            three = three_way_epe(
                case.flow_true[rows],
                estimate[rows],
                foreground=case.foreground[rows],
                dynamic=case.dynamic[rows],
            )
            row["3way" + suffix] = three["three_way_mean"]
            row["fd" + suffix] = three["foreground_dynamic"]
            row["fs" + suffix] = three["foreground_static"]
            row["bs" + suffix] = three["background_static"]
        rows = keep & finite
        if rows.any():
            if static >= 0:
                a_rows = case.a[rows]
                moved = a_rows @ est.rotations_[static].T + est.translations_[static]
                predicted = dynamic_mask(flow[rows], moved - a_rows)
            else:  # no static world: the estimator says every cluster moves
                predicted = np.ones(np.count_nonzero(rows), dtype=bool)
            row["dyn_iou"] = dynamic_iou(case.dynamic[rows], predicted)["dynamic"]
    objects_in = _object_epes(case.flow_true, flow_in, truth, case.moving)
    objects = _object_epes(case.flow_true, flow, truth, case.moving)
    row["epe_obj_in"] = np.mean(list(objects_in.values())) if objects_in else np.nan
    row["epe_obj"] = np.nanmean(list(objects.values())) if objects else np.nan
    row["epe_objects_in"] = _format_objects(objects_in)
    row["epe_objects"] = _format_objects(objects)
    row["labelled_-1"] = float(np.mean(pred < 0))
    row["warnings"] = ";".join(sorted({w.category.__name__ for w in caught}))
    return row


# --- the run -------------------------------------------------------------------------


def run(data, scenes=None, methods=None, seeds=1, max_seconds=60.0, log=print, repeats=1):
    """Run the benchmark; return the table (one row per scene, method, seed) and notes.

    Each method is fitted ``repeats`` times on each input, a fresh estimator each time;
    ``time_s`` is the median (the first fit in a process also pays one-time costs, and
    the machine's speed drifts), the scores are the last fit's (every method is seeded).
    """
    methods = default_methods() if methods is None else methods
    loader, why = import_loader(data)
    if loader is None:
        return pd.DataFrame(), [f"no data: {why}"]
    available = set(loader.list_scenes(str(data)))
    plan, notes = select_scenes(available, scenes)
    too_slow = {}
    rows = []
    for seed in range(seeds):
        for name, variants in plan:
            for case, note in make_cases(loader, data, name, variants, seed):
                if case is None:
                    notes.append(note)
                    continue
                X = np.hstack([case.a, case.b])
                shared = SharedInit(X, seed)
                for method in methods:
                    if method in too_slow:
                        continue
                    times = []
                    for _ in range(repeats):
                        est = build_method(method, seed)
                        with warnings.catch_warnings(record=True) as caught:
                            warnings.simplefilter("always")
                            init_seconds = shared.give(est)
                            start = time.perf_counter()
                            est.fit(X)
                            times.append(init_seconds + time.perf_counter() - start)
                    seconds = float(np.median(times))
                    row = score(case, method, est, seconds, caught)
                    row["init_s"] = init_seconds
                    row["seed"] = seed
                    rows.append(row)
                    log(
                        f"{case.scene:32s} {method:18s} seed {seed}: {seconds:6.1f} s, "
                        f"{row['clusters']} clusters, IoU {row['iou']:.3f}, "
                        f"EPE {row['epe']:.3f} m",
                    )
                    if method in BASELINES and seconds > max_seconds:
                        too_slow[method] = (
                            f"{method}: {seconds:.0f} s on {case.scene} (> {max_seconds:g} s), "
                            "skipped on the remaining scenes"
                        )
    notes.extend(too_slow.values())
    table = pd.DataFrame(rows)
    if len(table):
        first = ["scene", "method", "seed"]
        table = table[first + [c for c in table.columns if c not in first]]
    return table, notes


SUMMARY = {
    "n": "n",
    "time_s": "time s",
    "clusters": "clusters",
    "found": "moving found",
    "static_in_largest": "static in largest",
    "static_moving": "static clusters moving",
    "iou": "IoU",
    "epe_in": "EPE in",
    "epe": "EPE",
    "3way_in": "3-way in",
    "3way": "3-way",
    "dyn_iou": "dyn IoU",
    "epe_obj_in": "EPE obj in",
    "epe_obj": "EPE obj",
    "outliers3d": "Outliers3D",
    "labelled_-1": "labelled -1",
}


def summarise(table):
    """Means over seeds (median time), one row per scene and method, for the Markdown table."""
    grouped = table.groupby(["scene", "method"], sort=False)
    numeric = [c for c in SUMMARY if c not in ("found", "time_s") and c in table]
    out = grouped[numeric].mean()
    out["time_s"] = grouped["time_s"].median()
    found = grouped["moving_found"].mean()
    total = grouped["moving_total"].first()
    out["found"] = ["-" if t == 0 else f"{f:.3g}/{t}" for f, t in zip(found, total, strict=True)]
    out["n"] = out["n"].round().astype(int)
    out["static_moving"] = out["static_moving"].round(2)
    out = out[[c for c in SUMMARY if c in out]].rename(columns=SUMMARY).reset_index()
    return out


def machine_speed(repeats=3):
    """Seconds of a fixed yardstick, the fastest of ``repeats``: a k-d tree built on
    100,000 uniform points and queried for every point's 8 nearest neighbours. The
    machine's speed drifts by tens of percent over a day; this says how fast it ran."""
    from scipy.spatial import cKDTree

    points = np.random.default_rng(0).uniform(size=(100_000, 3))
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        cKDTree(points).query(points, k=8)
        best = min(best, time.perf_counter() - start)
    return best


def provenance():
    """Where mmreg was imported from, its git commit and uncommitted changes under mmreg/."""
    source = Path(mmreg.__file__).resolve().parent.parent
    info = {"mmreg": str(source)}
    try:
        commit = subprocess.run(
            ["git", "-C", str(source), "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(source), "status", "--porcelain", "--", "mmreg"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.split("\n")
        dirty = [line[3:] for line in dirty if line.strip()]
        info["commit"] = commit + (f" + uncommitted changes to {', '.join(dirty)}" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        info["commit"] = "unknown (not a git checkout)"
    return info


def write_markdown(path, title, table, summary, notes, seeds, argv, repeats=1, speed=None):
    info = provenance()
    lines = [
        f"# {title}",
        "",
        "`" + " ".join(["python benchmarks/real.py", *argv]) + "`",
        "",
        f"- run {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC on {os.cpu_count()} cores "
        f"({platform.machine()}, Python {platform.python_version()}, numpy {np.__version__}); "
        f"mmreg from `{info['mmreg']}` at {info['commit']}",
        f"- {seeds} seed(s): means over seeds, median time; "
        + (f"each time the median of {repeats} fits" if repeats > 1 else "one fit per time"),
        "- protocol and columns: the docstring of `benchmarks/real.py`; every column of "
        "every run is in the CSV",
    ]
    if speed is not None:
        lines.append(
            "- the machine's speed (`machine_speed()`: a k-d tree's 8-NN pass over 100,000 "
            f"points) {speed[0]:.3f} s before the run, {speed[1]:.3f} s after"
        )
    lines += [f"- note: {n}" for n in notes]
    none = table[table["static_cluster"] < 0].groupby("method", sort=False)["scene"].count()
    if len(none):
        runs = table["method"].value_counts()
        lines.append(
            "- no static cluster (`static_cluster_ == -1`: every cluster then counts as moving "
            "and every point as dynamic) from "
            + ", ".join(f"{m} on {k} of {runs[m]} inputs" for m, k in none.items())
        )
    lines += [
        "- static cluster and moving flags from: "
        + ", ".join(sorted(set(table["moving_from"])))
        + " (fallback: the largest cluster is static, a cluster moves when its motion carries "
        "its points > 3 cm from the static motion's)",
        "- Outliers3D (HPLFlowNet) divides the error by |true flow| + 1e-4 m, so where the "
        "static world barely moves (ego-compensated `icpflow_av2_demo`, the stopped ego "
        "vehicle of `av2_api_adcf7d18`) a few millimetres make a point an outlier; EPE and "
        "Acc3DS/Acc3DR (CSV) are the telling ones there",
    ]
    lines += ["", summary.to_markdown(index=False, floatfmt=".3g"), ""]
    Path(path).write_text("\n".join(lines))


def main(argv=None):
    parser = argparse.ArgumentParser(
        description=__doc__.splitlines()[0], formatter_class=argparse.ArgumentDefaultsHelpFormatter
    )
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder with load.py")
    parser.add_argument(
        "--scenes",
        type=lambda s: [x for x in s.split(",") if x],
        default=None,
        help="comma-separated scene names or name/variant (default: every scene found)",
    )
    parser.add_argument(
        "--methods",
        type=lambda s: [x for x in s.split(",") if x],
        default=None,
        help="comma-separated: mmreg, sweep, robust, paper, or any name of "
        "mmreg.methods.available_methods() (default: mmreg, robust, paper and the baselines)",
    )
    parser.add_argument("--seeds", type=int, default=1, help="seeds 0..N-1 (noise and methods)")
    parser.add_argument(
        "--repeats", type=int, default=1, help="fits timed per input and method (median)"
    )
    parser.add_argument("--out", type=Path, default=HERE / "results", help="folder for results")
    parser.add_argument(
        "--max-seconds",
        type=float,
        default=60.0,
        help="a baseline slower than this on a scene is skipped on the remaining scenes",
    )
    parser.add_argument(
        "--ablation",
        nargs="?",
        const="robust",
        default=None,
        choices=("robust", "sweep"),
        help="run the default (or variant='sweep') with each robust step turned off in turn "
        "(real_ablation.*, real_ablation_sweep.*)",
    )
    args = parser.parse_args(argv)
    argv = sys.argv[1:] if argv is None else list(argv)

    if args.ablation:
        steps, why = robust_steps()
        if steps is None:
            print(f"Ablation skipped: {why} (the estimator does not offer skip_steps yet).")
            return 0
        if args.ablation not in estimator_variants():
            print(f"Ablation skipped: MultiModelRegistration has no variant={args.ablation!r}.")
            return 0
        base = "mmreg" if args.ablation == "robust" else args.ablation
        methods = [base, *(f"{base}-no-{step}" for step in steps)]
        stem = "real_ablation" if args.ablation == "robust" else f"real_ablation_{args.ablation}"
        title = f"Ablation on real scene flow: {base} without each robust step in turn"
    else:
        methods = default_methods() if args.methods is None else args.methods
        check_methods(methods)
        stem, title = "real", "Multi-model registration on real scene flow"

    if args.repeats < 1:
        parser.error(f"--repeats must be at least 1, got {args.repeats}")
    before = machine_speed()
    table, notes = run(
        args.data, args.scenes, methods, args.seeds, args.max_seconds, repeats=args.repeats
    )
    speed = (before, machine_speed())
    for note in notes:
        print(f"note: {note}")
    if table.empty:
        print("Nothing was run; no results written.")
        return 0
    summary = summarise(table)
    print()
    print(summary.to_markdown(index=False, floatfmt=".3g"))
    args.out.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out / f"{stem}.csv", index=False)
    write_markdown(
        args.out / f"{stem}.md",
        title,
        table,
        summary,
        notes,
        args.seeds,
        argv,
        args.repeats,
        speed,
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
