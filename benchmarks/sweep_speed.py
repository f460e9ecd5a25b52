"""Speed of two raw sweeps: SweepRegistration against the k-NN floor, beside the peers.

    python benchmarks/sweep_speed.py --data /work/shared/realdata

For every raw Argoverse 2 pair of ../shared/realdata with its second sweep
(``av2_api_7fab2350`` with the ground in and removed, ``icpflow_av2_demo``), interleaved
over ``--repeats`` rounds (medians):

- **floor**: what any method that matches the sweeps point by point pays at least: one
  scipy ``cKDTree`` of the second sweep and an 8-NN query of the first, one thread (as
  mmreg queries unless asked for more);
- **fit**: ``SweepRegistration(random_state=0).fit(a, sweep=b)``, wall clock, and its
  ratio to the floor, also in CPU seconds (steadier while other jobs share the cores);
- **peers** for the ego-motion step alone: small_gicp's GICP and KISS-ICP's registration
  (one thread, ``benchmarks/ego_motion.py``'s settings); ICP-Flow, the peer of the whole
  task, reports 8-50 s a pair (its paper; it needs a GPU build not installed here).

Then where the fit's time goes (one more fit, each stage timed where it is called), and
``mmreg register`` end to end (a new process each round: imports, reading, the fit,
the picture and the files; ``--cli``), on the pair's raw files (Argoverse 2 .feather
sweeps, which carry capture times: the fit deskews) or on .npy copies of its points
written to a temporary folder, and where its time goes (one more run through
``benchmarks/cli_stages.py``: imports, reading, the fit, the picture, the files).

Times depend on the machine and its load (the shared 2-core machine of the results file
runs other jobs): compare the ratios, and runs made side by side. Writes
benchmarks/results/sweep_speed.md.
"""

import argparse
import functools
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).parent))
from ego_motion import gicp, kiss  # noqa: E402

import mmreg.estimators._two_sweeps as two_sweeps  # noqa: E402
from mmreg import SweepRegistration  # noqa: E402
from mmreg.estimators import _multi_model_registration  # noqa: E402
from mmreg.sweeps import (  # noqa: E402
    _island_search,
    _pair,
    _sweep_state,
)

# The command line runs the mmreg imported here (PYTHONPATH), not necessarily this tree's.
ROOT = Path(two_sweeps.__file__).resolve().parents[2]
NEIGHBOURS = 8

# (label, owner, attribute, caller): the stages of a raw fit, timed where the pipeline
# (mmreg.sweeps._pair and the stages' modules) calls them; a caller counts only the
# calls from that function.
STAGES = [
    ("ground (Patchwork++)", _pair, "pair_ground", None),
    ("ego motion (ICP)", _pair, "pair_ego_motion", None),
    ("islands", _sweep_state, "voxel_islands", None),
    ("translation starts", _island_search, "translation_starts", None),
    ("island hypotheses (ICP)", _island_search, "multi_body_icp", "_island_hypotheses"),
    ("choosing island motions", _island_search, "choose_island_motions", None),
    ("slow movers", _island_search, "slow_movers", None),
    ("EM", _multi_model_registration.MultiModelRegistration, "fit", None),
    ("object ICP (refine)", _pair, "refine_clusters", None),
    ("slides rejoin", _pair, "join_slides", None),
]


def floor(a, sweep):
    """The k-NN floor: a k-d tree of the second sweep and an 8-NN query of the first."""
    cKDTree(sweep).query(a, k=NEIGHBOURS, workers=1)


def fit(a, sweep):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return SweepRegistration(random_state=0).fit(a, sweep=sweep)


def _timed(function, *args, **kwargs):
    start = time.perf_counter()
    function(*args, **kwargs)
    return time.perf_counter() - start


def _wall_and_cpu(function, *args):
    """Wall and CPU seconds of one call (the CPU's hold better on a shared machine)."""
    cpu = time.process_time()
    wall = _timed(function, *args)
    return wall, time.process_time() - cpu


@functools.cache
def _stage_clock():
    """Seconds spent in each stage, and the stages' wrappers installed (once)."""
    spent = dict.fromkeys(label for label, _, _, _ in STAGES)
    for label, owner, name, caller in STAGES:
        original = getattr(owner, name)
        is_static = isinstance(vars(owner).get(name), staticmethod)

        def timed(*args, _original=original, _label=label, _caller=caller, **kwargs):
            if _caller is not None and sys._getframe(1).f_code.co_name != _caller:
                return _original(*args, **kwargs)
            start = time.perf_counter()
            try:
                return _original(*args, **kwargs)
            finally:
                spent[_label] = (spent[_label] or 0.0) + time.perf_counter() - start

        setattr(owner, name, staticmethod(timed) if is_static else timed)
    return spent


def stages(a, sweep):
    """``{stage: seconds}`` of one fit, the rest under "other"."""
    spent = _stage_clock()
    for label in spent:
        spent[label] = None
    total = _timed(fit, a, sweep)
    result = {label: seconds for label, seconds in spent.items() if seconds is not None}
    result["other"] = total - sum(result.values())
    result["fit"] = total
    return result


def peers(a, sweep):
    """Seconds of the ego-motion peers on the pair, or NaN where one is not installed."""
    out = {}
    for name, method in (("small_gicp GICP", gicp), ("KISS-ICP", kiss)):
        try:
            out[name] = _timed(method, a, sweep)
        except ImportError:
            out[name] = float("nan")
    return out


def pairs(root):
    sys.path.insert(0, str(root))
    from load import list_scenes, load_scene

    available = list_scenes(root)
    if "av2_api_7fab2350" in available:
        whole = load_scene("av2_api_7fab2350", root=root)
        lidar = Path(root) / "av2_api_7fab2350" / "raw" / "sensors" / "lidar"
        files = sorted(lidar.glob("*.feather"))
        yield "av2_api_7fab2350, ground in", whole.a, whole.pc2, files if len(files) == 2 else None
        removed = load_scene("av2_api_7fab2350", root=root, drop_ground=True)
        yield "av2_api_7fab2350, ground removed", removed.a, removed.pc2, None
    if "icpflow_av2_demo" in available:
        demo = load_scene("icpflow_av2_demo", root=root, drop_ground=True)
        yield "icpflow_av2_demo", demo.a, demo.pc2, None


def cli_seconds(a, sweep, files, repeats):
    """Median wall seconds of ``mmreg register A --sweep B`` and of its fit (run.json),
    and ``{stage: seconds}`` of one more run (``cli_stages.py``: imports apart)."""
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        if files is None:
            files = [folder / "a.npy", folder / "b.npy"]
            np.save(files[0], a)
            np.save(files[1], sweep)
        arguments = ["register", str(files[0]), "--sweep", str(files[1])]
        arguments += ["--out", str(folder / "out"), "--overwrite", "-q"]
        env = os.environ | {"PYTHONPATH": str(ROOT)}
        total, fitted = [], []
        for _ in range(repeats):
            command = [sys.executable, "-m", "mmreg.cli", *arguments]
            total.append(_timed(subprocess.run, command, env=env, check=True))
            fitted.append(json.loads((folder / "out" / "run.json").read_text())["fit_seconds"])
        staged = [sys.executable, str(Path(__file__).parent / "cli_stages.py"), *arguments]
        lines = subprocess.run(staged, env=env, check=True, capture_output=True, text=True)
        stages = json.loads(lines.stdout.splitlines()[-1])
        return statistics.median(total), statistics.median(fitted), stages


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--data", default="../shared/realdata")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--cli", action=argparse.BooleanOptionalAction, default=True)
    parser.add_argument("--out", default=str(Path(__file__).parent / "results" / "sweep_speed.md"))
    args = parser.parse_args(argv)
    rows, stage_rows = [], []
    for name, a, sweep, files in pairs(args.data):
        times = {key: [] for key in ("floor", "fit", "floor cpu", "fit cpu")}
        times |= {"small_gicp GICP": [], "KISS-ICP": []}
        fit(a, sweep)  # warm: imports, caches
        for _ in range(args.repeats):  # interleaved: the machine's load hits all alike
            for key, function in (("floor", floor), ("fit", fit)):
                wall, cpu = _wall_and_cpu(function, a, sweep)
                times[key].append(wall)
                times[f"{key} cpu"].append(cpu)
            for peer, seconds in peers(a, sweep).items():
                times[peer].append(seconds)
        median = {key: statistics.median(values) for key, values in times.items()}
        row = {"pair": name, "n": len(a), "m": len(sweep)} | median
        if args.cli:
            row["cli"], row["cli fit"], row["cli stages"] = cli_seconds(
                a, sweep, files, args.repeats
            )
            row["cli input"] = "the .feather sweeps (deskewed)" if files else ".npy points"
        rows.append(row)
        stage_rows.append((name, stages(a, sweep)))
        print(row, flush=True)
    Path(args.out).write_text(_report(rows, stage_rows, args))
    print(Path(args.out).read_text())


def _report(rows, stage_rows, args):
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    lines = [
        "# Two raw sweeps: speed (benchmarks/sweep_speed.py)",
        "",
        f"`python benchmarks/sweep_speed.py --repeats {args.repeats}`: medians of "
        f"{args.repeats} interleaved rounds on a {os.cpu_count()}-core machine shared with "
        f"other jobs (load average {load:.1f} at the end): compare ratios, not seconds.",
        "Floor: scipy cKDTree of the second sweep + 8-NN query of the first, one thread. "
        "Peers: the ego-motion step alone (small_gicp GICP, KISS-ICP, one thread); "
        "ICP-Flow reports 8-50 s a pair for the whole task. 'CPU': the same ratio of the "
        "process's CPU seconds, which the other jobs' load disturbs less than the wall clock's.",
        "",
        "| pair | points (a / b) | floor (s) | fit (s) | fit / floor | fit / floor, CPU "
        "| small_gicp GICP (s) | KISS-ICP (s) | `mmreg register` (s) | its fit (s) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        cli = f"{r['cli']:.2f} | {r['cli fit']:.2f}" if "cli" in r else "- | -"
        lines.append(
            f"| {r['pair']} | {r['n']:,} / {r['m']:,} | {r['floor']:.3f} | {r['fit']:.2f} | "
            f"{r['fit'] / r['floor']:.1f} | {r['fit cpu'] / r['floor cpu']:.1f} | "
            f"{r['small_gicp GICP']:.3f} | {r['KISS-ICP']:.3f} "
            f"| {cli} |"
        )
    inputs = "; ".join(f"{r['pair']}: {r['cli input']}" for r in rows if "cli input" in r)
    lines += [
        "",
        "`mmreg register A --sweep B -q` end to end (a new process: imports, reading, fit, "
        "picture, files); "
        + (f"input: {inputs}." if inputs else "not measured in this run (--no-cli)."),
        *_cli_stage_table(rows),
        "",
        "Where one fit's time goes (s; one run, after the timed ones):",
        "",
        "| stage | " + " | ".join(name for name, _ in stage_rows) + " |",
        "|---|" + "---|" * len(stage_rows),
    ]
    labels = [label for label, _, _, _ in STAGES] + ["other", "fit"]
    for label in labels:
        values = [spent.get(label) for _, spent in stage_rows]
        cells = ["-" if v is None else f"{v:.3f}" for v in values]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _cli_stage_table(rows):
    """Where ``mmreg register``'s time goes: lines of a table, one column per pair."""
    staged = [r for r in rows if "cli stages" in r]
    if not staged:
        return []
    lines = [
        "",
        "Where `mmreg register`'s time goes (s; one more run, `benchmarks/cli_stages.py`: "
        "every import counted under imports, wherever it happens; the fit's stages are "
        "below):",
        "",
        "| stage | " + " | ".join(r["pair"] for r in staged) + " |",
        "|---|" + "---|" * len(staged),
    ]
    labels = list(dict.fromkeys(label for r in staged for label in r["cli stages"]))
    for label in labels:
        cells = [r["cli stages"].get(label) for r in staged]
        cells = ["-" if v is None else f"{v:.3f}" for v in cells]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return lines


if __name__ == "__main__":
    main()
