"""Runtime of every method on paper-scale scenes, in one run, against the paper's statements.

Scenes at the paper's scale: Table I, Exp. 2 (GENERATED PASCAL3D+-like, 22,395
correspondences, 7 objects), and GENERATED FlyingThings3D-like (32,768) and KITTI-like
(32,768) scenes; every method with that experiment's parameters (see table1.py and
figure2.py). Each fit is timed alone, one after the other in this process (no parallel
runs, no cache), given the initial clusters; the initial clustering is timed on its own.
The paper's statements are about PASCAL3D+ (Section V-C, Python on an M1 Pro): SRANSAC
30 ms, T-Linkage about 2 s, Ours without the gate about 0.8 s, with it "a couple of
seconds".

Writes to --out: runtime.csv (every fit) and runtime.md (medians, the paper beside).
"""

import os
import platform
import sys

import figure2
import numpy as np
import pandas as pd
import table1
from _common import (
    Column,
    add_runner_arguments,
    make_parser,
    run_experiments,
    write_frame,
    write_text,
)

PAPER = {
    "Naive": "-",
    "SRANSAC": "30 ms",
    "T-Linkage": "about 2 s",
    "Ours (Vanilla)": "about 0.8 s",
    "Ours": "a couple of seconds",
    "mmreg": "- (not in the paper)",
}
FAMILIES = {
    "table1-exp2": "Table I Exp. 2 (PASCAL3D+-like)",
    "figure2-flying_things": "FlyingThings3D-like",
    "figure2-kitti": "KITTI-like",
}


def experiments(runs=3, seed=0, methods=None, quick=False):
    """Table I Exp. 2 and the two flow families, with an extra Vanilla on the flow scenes."""
    points = table1.QUICK["points"] if quick else table1.N_POINTS
    chosen = table1.experiments(
        runs=runs,
        n_points=points,
        seed=seed,
        methods=methods,
        which=(2,),
        shapes=table1.default_shapes(),
    )
    for experiment in figure2.experiments(runs=runs, seed=seed, methods=methods, quick=quick):
        vanilla = [
            Column(f"Ours (Vanilla){c.label[4:]}", "ours_vanilla", {"max_iter": 10}, c.init)
            for c in experiment.columns
            if c.method == "ours"
        ]
        experiment.columns = experiment.columns + vanilla
        chosen.append(experiment)
    return chosen


def _base(label):
    """``"T-L (SAM)"`` -> ``"T-Linkage"``: the method without its initialisation."""
    for suffix in (" (SAM)", " (Euc.)"):
        label = label.removesuffix(suffix)
    return {"SeqR": "SRANSAC", "T-L": "T-Linkage"}.get(label, label)


INIT_NAMES = {"sam": "SAM", "euclidean": "Euc."}
INIT_ROWS = {
    "sam": "SAM-like masks to labels (the init)",
    "euclidean": "Euclidean clustering (the init)",
}


def summarise(results):
    """Median fit time: a row per method, a column per scene family and initialisation."""
    rows, init_rows = {}, {}
    groups = results.groupby(["experiment", "method"], sort=False, dropna=False)
    for (experiment, label), frame in groups:
        family = FAMILIES[experiment]
        init = frame["init"].iloc[0]
        init = None if pd.isna(init) else init
        if experiment.startswith("table1"):
            targets = [family]
        elif init is None:  # needs no initial clusters: the same fit under both
            targets = [f"{family}, SAM", f"{family}, Euc."]
        else:
            targets = [f"{family}, {INIT_NAMES[init]}"]
        for target in targets:
            rows.setdefault(_base(label), {})[target] = frame["runtime_s"].median()
        if init is not None:
            seconds = frame.drop_duplicates("run")["init_s"].median()
            init_rows.setdefault(INIT_ROWS[init], {})[targets[0]] = seconds
    table = pd.DataFrame.from_dict({**rows, **init_rows}, orient="index")
    order = [FAMILIES["table1-exp2"]] + [
        f"{FAMILIES[e]}, {i}"
        for e in ("figure2-flying_things", "figure2-kitti")
        for i in ("SAM", "Euc.")
    ]
    table = table[[c for c in order if c in table.columns]]
    table.insert(0, "paper (PASCAL3D+, M1 Pro)", [PAPER.get(m, "-") for m in table.index])
    return table


def to_markdown(table, runs):
    def cell(value):
        if isinstance(value, str):
            return value
        if not np.isfinite(value):
            return "-"
        return f"{value * 1000:.0f} ms" if value < 1 else f"{value:.2f} s"

    header = ["method", *table.columns]
    lines = ["| " + " | ".join(header) + " |", "|---" * len(header) + "|"]
    for method, row in table.iterrows():
        lines.append("| " + " | ".join([method, *(cell(v) for v in row)]) + " |")
    machine = f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    return (
        f"Median wall-clock time of one fit given the initial clusters, {runs} scene(s) per "
        f"family, one fit at a time ({machine}). SAM / Euc.: initial clusters from SAM-like "
        "masks / Euclidean clustering (100 clusters); SRANSAC needs none.\n\n"
        + "\n".join(lines)
        + "\n"
    )


def main(argv=None):
    parser = make_parser(__doc__)
    add_runner_arguments(parser, runs_default=3, runs_help="scenes per family", parallel=False)
    args = parser.parse_args(argv)
    runs = 1 if args.quick else args.runs
    results = run_experiments(
        experiments(runs=runs, seed=args.seed, methods=args.methods, quick=args.quick),
        cache_dir=None,
        n_jobs=1,
        scheduler=None,
        progress=not args.no_progress,
    )
    args.out.mkdir(parents=True, exist_ok=True)
    text = to_markdown(summarise(results), runs)
    written = [
        write_frame(results, args.out / "runtime.csv"),
        write_text(text, args.out / "runtime.md"),
    ]
    print(text)
    print("wrote " + ", ".join(str(p) for p in written), file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
