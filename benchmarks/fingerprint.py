"""Fingerprints of fitted estimators, to show that a restructure changes no result.

``python benchmarks/fingerprint.py --out before.json`` fits :class:`MultiModelRegistration`
(variants ``sweep``, ``robust`` and ``paper``, and the default with each robust step
turned off by ``skip_steps``) on a fixed set of inputs and writes, per fit, a SHA-256 of
every fitted attribute (``labels_``, ``rotations_``, ``translations_``, ``sigmas_``,
``weights_``, ``flow_``, ``history_``, ``static_cluster_``, ``moving_``, ...), bit for bit.
``--compare before.json`` then prints every fit whose fingerprint differs, attribute by
attribute, and exits 1 if any does.

The inputs: :mod:`mmreg.datasets` scenes (``make_scene`` as Table I, with noise and
outliers; ``make_flying_things`` with 10 % and 50 % gross errors; ``make_street``), a few
seeds each, and, when ``--data`` holds them, the shared real scenes (ground removed):
every scene's ground-truth flow, ZeroFlow's flow of ``icpflow_av2_demo`` and the noisy
Argoverse 2 flow of ``benchmarks/real.py``. ``--quick`` keeps one seed.
"""

import argparse
import hashlib
import importlib.util
import json
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from mmreg import MultiModelRegistration
from mmreg.datasets import make_flying_things, make_scene, make_street
from mmreg.em._robust import ROBUST_STEPS

HERE = Path(__file__).resolve().parent
DEFAULT_DATA = Path(os.environ.get("MMREG_REALDATA", HERE.parent.parent / "shared" / "realdata"))


def digest(value):
    """SHA-256 of a fitted attribute, bit for bit (arrays by dtype, shape and bytes)."""
    h = hashlib.sha256()
    if isinstance(value, np.ndarray):
        h.update(f"{value.dtype}{value.shape}".encode())
        h.update(np.ascontiguousarray(value).tobytes())
    elif isinstance(value, (list, tuple)):
        h.update(type(value).__name__.encode())
        for item in value:
            h.update(digest(item).encode())
    elif isinstance(value, dict):
        for key in sorted(value):
            h.update(f"{key}={digest(value[key])}".encode())
    elif isinstance(value, (float, np.floating)):
        h.update(np.float64(value).tobytes())
    else:
        h.update(repr(value).encode())
    return h.hexdigest()[:16]


def fitted_attributes(est):
    """Every attribute ``fit`` set (a trailing underscore), and the cluster labels of
    fitted rows when they differ from ``labels_``."""
    found = {
        key: value
        for key, value in vars(est).items()
        if key.endswith("_") and not key.startswith("_") and key != "n_features_in_"
    }
    for key in ("_cluster_labels", "_cluster_points"):
        if key in vars(est):
            found[key] = vars(est)[key]
    return found


def synthetic_cases(seeds):
    """(name, X, tau) of the generated scenes."""
    for seed in seeds:
        scene = make_scene(
            n_objects=7, n_points=6000, noise=0.01, outlier_fraction=0.1, random_state=seed
        )
        yield f"table1/seed{seed}", scene.X, 1.5
        for wrong in (0.1, 0.5):
            scene = make_flying_things(
                n_points=8192,
                corruption={"gross_error_fraction": wrong},
                sam_masks=False,
                random_state=seed,
            )
            yield f"flying_things/wrong{wrong:.0%}/seed{seed}", scene.X, 5.0
        scene = make_street(n_points=8192, sam_masks=False, random_state=seed)
        yield f"street/seed{seed}", scene.X, 5.0


def real_cases(data):
    """(name, X, tau) of the shared real scenes, as ``benchmarks/real.py`` makes them."""
    spec = importlib.util.spec_from_file_location("realdata_load", Path(data) / "load.py")
    loader = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(loader)
    for name in loader.list_scenes(str(data)):
        scene = loader.load_scene(name, root=str(data), drop_ground=True)
        a, flow = scene.a, scene.flow
        yield f"{name}/gt", np.hstack([a, a + flow]), 5.0
        if "est_flow_zeroflow" in scene.extras:
            zero = np.asarray(scene.extras["est_flow_zeroflow"], dtype=float)
            yield f"{name}/zeroflow", np.hstack([a, a + zero]), 5.0
        if name.startswith("av2_api") and scene.labels is not None:
            rng = np.random.default_rng(0)
            noisy = np.where((scene.labels >= 1)[:, None], 0.9 * flow, flow)
            noisy = noisy + rng.normal(scale=0.02, size=noisy.shape)
            yield f"{name}/noisy", np.hstack([a, a + noisy]), 5.0


def settings(name, n):
    """The estimator settings fitted on one input."""
    out = [{"variant": "sweep"}, {"variant": "robust"}]
    if n <= 10_000:
        out.append({"variant": "paper"})
    ablate = name.startswith(("table1/seed0", "flying_things/wrong50%/seed0", "street/seed0"))
    ablate |= name in ("icpflow_av2_demo/zeroflow", "av2_api_7fab2350/noisy")
    if ablate:
        for step in ROBUST_STEPS:
            out.append({"variant": "sweep", "skip_steps": (step,)})
        out.append({"variant": "robust", "skip_steps": ("boundary_layers", "outliers")})
        out.append({"variant": "sweep", "skip_steps": tuple(ROBUST_STEPS)})
    return out


def run(data, seeds, log=print):
    cases = list(synthetic_cases(seeds))
    if data is not None and Path(data, "load.py").exists():
        cases += list(real_cases(data))
    prints = {}
    for name, X, tau in cases:
        for params in settings(name, len(X)):
            key = f"{name} " + ",".join(f"{k}={v}" for k, v in params.items())
            start = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                est = MultiModelRegistration(tau=tau, random_state=0, **params).fit(X)
            attributes = fitted_attributes(est)
            prints[key] = {k: digest(v) for k, v in sorted(attributes.items())}
            prints[key]["all"] = digest(prints[key])
            log(f"{key}: {prints[key]['all']} ({time.perf_counter() - start:.1f} s)")
    return prints


def compare(before, after):
    """Keys whose fingerprints differ, with the attributes that do."""
    differ = {}
    for key in sorted(set(before) | set(after)):
        old, new = before.get(key), after.get(key)
        if old is None or new is None:
            differ[key] = ["missing before" if old is None else "missing after"]
        elif old["all"] != new["all"]:
            differ[key] = sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))
    return differ


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=str(DEFAULT_DATA))
    parser.add_argument("--no-real", action="store_true", help="generated scenes only")
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--out", help="write the fingerprints to this JSON file")
    parser.add_argument("--compare", help="a JSON file of fingerprints to compare with")
    args = parser.parse_args(argv)
    data = None if args.no_real else args.data
    prints = run(data, range(1 if args.quick else args.seeds))
    if args.out:
        Path(args.out).write_text(json.dumps(prints, indent=1, sort_keys=True))
    if args.compare:
        differ = compare(json.loads(Path(args.compare).read_text()), prints)
        for key, attributes in differ.items():
            print(f"DIFFERS {key}: {', '.join(attributes)}")
        print(f"{len(prints) - len(differ)} of {len(prints)} fits identical")
        return 1 if differ else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
