"""Ablation on generated scenes: the default without each robust step in turn.

``python benchmarks/ablation_datasets.py`` fits ``MultiModelRegistration()`` (the sweep
default) and the default with each step of ``ROBUST_STEPS`` turned off (``skip_steps``) on
:mod:`mmreg.datasets` scenes, and writes ``benchmarks/results/ablation_datasets.csv`` (one
row per scene, seed and method) and ``.md`` (means over the seeds). It is the counterpart
of ``benchmarks/real.py --ablation sweep`` on data with a known truth and known errors:

``table1``  ``make_scene``: 7 objects, 8,000 correspondences, 2 cm noise, 20 % outliers,
            tau = 1.5 (Table I of the paper);
``ft3dNN``  ``make_flying_things``: 8,192 points, the default flow corruption (noise,
            boundary bleeding) with NN % gross errors, tau = 5;
``street``  ``make_street``: 8,192 points, the default corruption, tau = 5.

Columns: ``iou`` (:func:`mmreg.metrics.iou_score`, gross errors counted as outliers),
``found`` (:func:`mmreg.metrics.objects_found`), ``epe`` (m, the rigid flow ``flow_``
against the clean flow; none for ``table1``) and ``clusters``.
"""

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from mmreg import MultiModelRegistration
from mmreg.datasets import make_flying_things, make_scene, make_street
from mmreg.em._robust import ROBUST_STEPS
from mmreg.metrics import iou_score, objects_found

HERE = Path(__file__).resolve().parent


def scenes(seed):
    """(name, X, truth, clean flow or None, tau) of one seed."""
    scene = make_scene(
        n_objects=7, n_points=8000, noise=0.02, outlier_fraction=0.2, random_state=seed
    )
    yield "table1", scene.X, scene.labels, None, 1.5
    for wrong in (0.1, 0.3, 0.5):
        scene = make_flying_things(
            n_points=8192,
            corruption={"gross_error_fraction": wrong},
            sam_masks=False,
            random_state=seed,
        )
        truth = np.where(scene.outlier_mask, -1, scene.labels)
        yield f"ft3d{round(100 * wrong)}", scene.X, truth, scene.flow_clean, 5.0
    scene = make_street(n_points=8192, sam_masks=False, random_state=seed)
    truth = np.where(scene.outlier_mask, -1, scene.labels)
    yield "street", scene.X, truth, scene.flow_clean, 5.0


def run(seeds, log=print):
    rows = []
    for seed in range(seeds):
        for name, X, truth, clean, tau in scenes(seed):
            for step in (None, *ROBUST_STEPS):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    est = MultiModelRegistration(
                        tau=tau, random_state=seed, skip_steps=() if step is None else (step,)
                    ).fit(X)
                epe = np.nan
                if clean is not None:
                    epe = float(np.mean(np.linalg.norm(est.flow_ - clean, axis=1)))
                rows.append(
                    {
                        "scene": name,
                        "seed": seed,
                        "method": "sweep" if step is None else f"sweep-no-{step}",
                        "iou": iou_score(truth, est.labels_),
                        "found": objects_found(truth, est.labels_),
                        "epe": epe,
                        "clusters": est.n_clusters_,
                    }
                )
                log(", ".join(f"{key} {value}" for key, value in rows[-1].items()))
    return pd.DataFrame(rows)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--out", type=Path, default=HERE / "results")
    args = parser.parse_args(argv)
    table = run(args.seeds)
    args.out.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out / "ablation_datasets.csv", index=False)
    means = table.groupby(["scene", "method"], sort=False).mean(numeric_only=True)
    means = means.drop(columns="seed").reset_index()
    text = [
        "# Ablation on generated scenes: the sweep default without each robust step in turn",
        "",
        f"`python benchmarks/ablation_datasets.py --seeds {args.seeds}`; means over seeds "
        f"0..{args.seeds - 1}; scenes and columns: the docstring of "
        "`benchmarks/ablation_datasets.py`.",
        "",
        means.to_markdown(index=False, floatfmt=".4g"),
        "",
    ]
    (args.out / "ablation_datasets.md").write_text("\n".join(text))
    print("\n".join(text))
    return 0


if __name__ == "__main__":
    sys.exit(main())
