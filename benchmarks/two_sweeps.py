"""Two sweeps: SweepRegistration on the real Argoverse 2 pairs of ../shared/realdata.

    python benchmarks/two_sweeps.py --data /work/shared/realdata

Refinement of ZeroFlow's flow on ``icpflow_av2_demo`` (with and without the ICP), and two
raw sweeps alone on ``icpflow_av2_demo`` and ``av2_api_7fab2350``; ground removed, tau=5.
Scenes that are absent are skipped. Writes benchmarks/results/two_sweeps.md.
"""

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from mmreg import MultiModelRegistration, SweepRegistration
from mmreg.metrics import objects_found, three_way_epe

MIN_OBJECT_POINTS = 100


def _row(scene, mode, flow, labels, seconds):
    true = scene.labels
    error = np.linalg.norm(flow - scene.flow, axis=1)
    objects = [k for k in np.unique(true[true >= 1]) if (true == k).sum() >= MIN_OBJECT_POINTS]
    share = objects_found(true, labels, objects=objects, min_iou=0.5) if objects else 0.0
    n_found = round(share * len(objects))
    moving = np.isin(true, objects)
    dynamic = true >= 1
    three = three_way_epe(scene.flow, flow, foreground=dynamic, dynamic=dynamic)
    return {
        "scene": scene.name,
        "mode": mode,
        "found": f"{n_found} of {len(objects)}",
        "EPE moving (m)": float(error[moving].mean()) if moving.any() else float("nan"),
        "EPE static (m)": float(error[true == 0].mean()),
        "three-way EPE": three,
        "seconds": seconds,
    }


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--data", default="../shared/realdata")
    parser.add_argument("--out", default=str(Path(__file__).parent / "results" / "two_sweeps.md"))
    args = parser.parse_args(argv)
    sys.path.insert(0, args.data)
    from load import list_scenes, load_scene

    warnings.simplefilter("ignore")
    rows = []
    available = list_scenes(args.data)
    for name in ("icpflow_av2_demo", "av2_api_7fab2350"):
        if name not in available:
            print(f"skipping {name}: absent")
            continue
        scene = load_scene(name, root=args.data, drop_ground=True)
        a, sweep = scene.a, scene.pc2
        zeroflow = scene.extras.get("est_flow_zeroflow")
        if zeroflow is not None:
            X = np.hstack([a, a + zeroflow])
            rows.append(_row(scene, "ZeroFlow alone", zeroflow, np.zeros(len(a), int), 0.0))
            start = time.perf_counter()
            em = MultiModelRegistration(variant="sweep", tau=5.0, random_state=0).fit(X)
            rows.append(
                _row(scene, "ZeroFlow + EM", em.flow_, em.labels_, time.perf_counter() - start)
            )
            for refine in ("moving", "all"):
                est = SweepRegistration(refine=refine, random_state=0)
                start = time.perf_counter()
                est.fit(X, sweep=sweep)
                seconds = time.perf_counter() - start
                rows.append(
                    _row(
                        scene,
                        f"ZeroFlow + sweep 2 (refine={refine})",
                        est.flow_,
                        est.labels_,
                        seconds,
                    )
                )
        est = SweepRegistration(random_state=0)
        start = time.perf_counter()
        est.fit(a, sweep=sweep)
        rows.append(
            _row(scene, "two raw sweeps", est.flow_, est.labels_, time.perf_counter() - start)
        )
        print(rows[-1])
    lines = [
        "# Two sweeps (benchmarks/two_sweeps.py)",
        "",
        "Argoverse 2, ground removed, tau=5, objects with >= 100 points (found: best IoU >= 0.5).",
        "Three-way EPE with foreground = dynamic = the moving objects' points (no categories).",
        "Times: one run each on a shared 2-core machine (noisy); they include the EM.",
        "",
        "| scene | mode | found | EPE moving (m) | EPE static (m) | three-way (FD / FS / BS) | s |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        t = r["three-way EPE"]
        three = " / ".join(
            f"{t.get(k, float('nan')):.3f}"
            for k in ("foreground_dynamic", "foreground_static", "background_static")
        )
        lines.append(
            f"| {r['scene']} | {r['mode']} | {r['found']} | {r['EPE moving (m)']:.3f} | "
            f"{r['EPE static (m)']:.4f} | {three} | {r['seconds']:.1f} |"
        )
    Path(args.out).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
