"""What the default costs against the paper variant: CPU time of both, interleaved.

``python benchmarks/cost_ratio.py [--data ../shared/realdata] [--reps 9]`` fits
``MultiModelRegistration()`` (the default) and ``MultiModelRegistration(variant="paper")``
on the same input ``--reps`` times each, alternating (default, paper, default, ...), so that
a machine whose speed drifts during the run slows both alike. It prints one Markdown table
and writes it to ``benchmarks/results/cost_ratio.md`` (``--out``).

Inputs. Generated (always): the Table I scene (:func:`mmreg.datasets.make_scene`, real
meshes, noise 0.03, ``tau=1.5``) with the default Euclidean init and with a k-means(100)
init given as labels (the scale table's row; the k-means fit is not timed), a street
(:func:`~mmreg.datasets.make_street`) and a FlyingThings3D-like scene
(:func:`~mmreg.datasets.make_flying_things`), ``tau=5``. Real (when ``--data`` holds them;
read, never copied, through ``benchmarks/real.py``'s loader and protocol, ground removed,
``tau=5``): the FlyingThings3D frames and ``ddf_loss_ft3d`` with their ground-truth flow,
and the Argoverse 2 inputs (``--av2``, slower: the paper variant takes seconds there).

Columns: ``n`` correspondences; the minimum and the median over the repetitions of each
variant's CPU time (``time.process_time``: both cores' work, the initialisation included);
``ratio`` the default's over the paper variant's, of the minima (the least disturbed runs)
and of the medians. The goal is at most 2x everywhere.
"""

import argparse
import functools
import importlib.util
import platform
import sys
import time
import warnings
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pandas as pd
from sklearn.cluster import KMeans

from mmreg import MultiModelRegistration
from mmreg.datasets import make_flying_things, make_scene, make_street

HERE = Path(__file__).resolve().parent
GOAL = 2.0
# The real inputs (benchmarks/real.py's scene/variant names), the quick ones first.
REAL_INPUTS = (
    "ddf_loss_ft3d/gt",
    "flyout_ft3d_0000710/gt",
    "flyout_ft3d_0001325/gt",
    "flyout_ft3d_0001435/gt",
    "flyout_ft3d_0003086/gt",
)
AV2_INPUTS = (
    "icpflow_av2_demo/zeroflow",
    "av2_api_7fab2350/gt",
    "av2_api_adcf7d18/gt",
)


@functools.cache
def _real_module():
    spec = importlib.util.spec_from_file_location("benchmark_real", HERE / "real.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def generated_inputs():
    """``[(name, X, tau, init)]`` of the generated scenes."""
    table = make_scene(shapes="meshes", noise=0.03, random_state=0).X
    kmeans = KMeans(100, n_init=1, random_state=0).fit_predict(table[:, :3])
    return [
        ("Table I, default init", table, 1.5, "euclidean"),
        ("Table I, k-means(100) init", table, 1.5, kmeans),
        ("street (make_street)", make_street(random_state=0).X, 5.0, "euclidean"),
        ("FlyingThings3D-like", make_flying_things(random_state=0).X, 5.0, "euclidean"),
    ]


def real_inputs(data, names):
    """``[(name, X, tau, init)]`` of the real inputs found in ``data``, and notes."""
    real = _real_module()
    loader, why = real.import_loader(data)
    if loader is None:
        return [], [f"real scenes skipped: {why}"]
    available = set(loader.list_scenes(str(data)))
    wanted = [name for name in names if name.partition("/")[0] in available]
    notes = [f"{name}: not in {data}, skipped" for name in names if name not in wanted]
    inputs = []
    for scene, variants in real.select_scenes(available, wanted)[0]:
        for case, note in real.make_cases(loader, data, scene, variants, seed=0):
            if case is None:
                notes.append(note)
            else:
                inputs.append((case.scene, np.hstack([case.a, case.b]), 5.0, "euclidean"))
    return inputs, notes


def cpu_seconds(X, tau, init, variant):
    estimator = MultiModelRegistration(tau=tau, init=init, variant=variant, random_state=0)
    start = time.process_time()
    estimator.fit(X)
    return time.process_time() - start


def measure(inputs, reps, log=print):
    rows = []
    for name, X, tau, init in inputs:
        times = {"default": [], "paper": []}
        cpu_seconds(X, tau, init, "sweep")  # warm-up: first-call costs are nobody's
        for _ in range(reps):
            for variant, key in (("sweep", "default"), ("paper", "paper")):
                times[key].append(cpu_seconds(X, tau, init, variant))
        default, paper = np.array(times["default"]), np.array(times["paper"])
        row = {
            "input": name,
            "n": len(X),
            "default min s": default.min(),
            "default median s": np.median(default),
            "paper min s": paper.min(),
            "paper median s": np.median(paper),
            "ratio of minima": default.min() / paper.min(),
            "ratio of medians": np.median(default) / np.median(paper),
        }
        row["within 2x"] = (
            "yes" if max(row["ratio of minima"], row["ratio of medians"]) <= GOAL else "no"
        )
        rows.append(row)
        log(
            f"{name}: ratio {row['ratio of minima']:.2f} (minima), "
            f"{row['ratio of medians']:.2f} (medians)"
        )
    return pd.DataFrame(rows)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=None, help="the real-data folder (load.py)")
    parser.add_argument("--av2", action="store_true", help="the Argoverse 2 inputs too")
    parser.add_argument("--reps", type=int, default=9, help="fits of each variant per input")
    parser.add_argument("--out", type=Path, default=HERE / "results" / "cost_ratio.md")
    args = parser.parse_args(argv)
    if args.reps < 1:
        parser.error("--reps must be at least 1")
    warnings.simplefilter("ignore")
    inputs, notes = generated_inputs(), []
    if args.data is not None:
        real, notes = real_inputs(args.data, REAL_INPUTS + (AV2_INPUTS if args.av2 else ()))
        inputs += real
    table = measure(inputs, args.reps)
    text = table.to_markdown(index=False, floatfmt=".3g")
    print(text)
    info = _real_module().provenance()
    lines = [
        "# The default against the paper variant: CPU time",
        "",
        "`" + " ".join(["python benchmarks/cost_ratio.py", *(argv or sys.argv[1:])]) + "`",
        "",
        f"- run {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC ({platform.machine()}, "
        f"Python {platform.python_version()}, numpy {np.__version__}); mmreg from "
        f"`{info['mmreg']}` at {info['commit']}",
        f"- {args.reps} fits of each variant per input, interleaved; protocol and columns: "
        "the docstring of `benchmarks/cost_ratio.py`",
        *[f"- note: {note}" for note in notes],
        "",
        text,
        "",
    ]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
