"""Every experiment of the paper in one go: Table I, Fig. 1, Fig. 2, ablation, runtime.

Runs, in this order, with the options below handed on:

  table1           table1.py, then figure_boxplots.py (Table I as box plots)
  figure2          figure2.py (Fig. 2 on generated FlyingThings3D-/KITTI-like scenes)
  figure1          figure1.py (Fig. 1, a street seen from the camera)
  ablation         ablation.py (IoU against the init and the rate of wrong matches)
  runtime          runtime.py (every method on paper-scale scenes, one fit at a time)

Every run (experiment, method, scene) is cached as one small JSON file under --cache, so
an interrupted run resumes where it stopped; a progress bar per experiment shows how far
it is. --quick runs everything on tiny scenes in seconds (what the tests run).

Examples:
  python paper/run_all.py --n-jobs 2 --out paper/figures --cache paper/out/cache
  python paper/run_all.py --quick --out /tmp/quick
  python paper/run_all.py --scheduler tcp://10.0.0.5:8786 --methods ours,mmreg,my_method
"""

import sys
import time
from pathlib import Path

import ablation
import figure1
import figure2
import figure_boxplots
import runtime
import table1
from _common import DEFAULT_OUT, add_formats_argument, make_parser, parse_methods

STEPS = ("table1", "figure2", "figure1", "ablation", "runtime")


def _runner_argv(args, runs):
    argv = ["--out", str(args.out), "--seed", str(args.seed), "--methods", args.methods]
    argv += ["--runs", str(runs)]
    if args.quick:
        argv.append("--quick")
    if args.no_progress:
        argv.append("--no-progress")
    return argv


def _parallel_argv(args):
    argv = ["--n-jobs", str(args.n_jobs)]
    if args.scheduler:
        argv += ["--scheduler", args.scheduler]
    if args.no_cache:
        argv.append("--no-cache")
    elif args.cache is not None:
        argv += ["--cache", str(args.cache)]
    return argv


def main(argv=None):
    parser = make_parser(__doc__)
    parser.add_argument(
        "--only", default=",".join(STEPS), help=f"comma-separated steps, of: {', '.join(STEPS)}"
    )
    parser.add_argument("--quick", action="store_true", help="tiny scenes, seconds (tests)")
    parser.add_argument(
        "--n-jobs", type=int, default=1, help="parallel joblib processes (-1: all cores)"
    )
    parser.add_argument(
        "--scheduler",
        default=None,
        help="address of a Dask scheduler to run the scenes on (its workers' PYTHONPATH must "
        "hold this folder)",
    )
    parser.add_argument(
        "--methods",
        default="all",
        help="comma-separated registry names (built-ins, registered or entry points of the "
        "group 'mmreg.methods'), or 'all'",
    )
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="folder for every output")
    parser.add_argument(
        "--cache", type=Path, default=None, help="per-run cache folder; default: OUT/cache"
    )
    parser.add_argument("--no-cache", action="store_true", help="recompute every run")
    parser.add_argument("--seed", type=int, default=0, help="base seed of every scene family")
    parser.add_argument(
        "--table1-runs", type=int, default=100, help="scenes per Table I experiment (paper: 100)"
    )
    parser.add_argument("--figure2-runs", type=int, default=20, help="scenes per Fig. 2 data set")
    parser.add_argument("--ablation-runs", type=int, default=10, help="scenes per ablation rate")
    parser.add_argument("--runtime-runs", type=int, default=3, help="scenes per runtime family")
    parser.add_argument(
        "--data",
        default=None,
        help="folder of a real data set for Fig. 2 (see figure2.py --help); default: generated",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    add_formats_argument(parser)
    args = parser.parse_args(argv)
    parse_methods(args.methods)  # fail early on an unknown name
    steps = [step.strip() for step in args.only.split(",") if step.strip()]
    unknown = sorted(set(steps) - set(STEPS))
    if unknown:
        parser.error(f"unknown step(s) {', '.join(unknown)}; choose from {', '.join(STEPS)}")
    args.out.mkdir(parents=True, exist_ok=True)
    timings = {}
    formats = ["--formats", args.formats]
    for step in steps:
        start = time.perf_counter()
        print(f"== {step}", file=sys.stderr, flush=True)
        if step == "table1":
            table1.main(_runner_argv(args, args.table1_runs) + _parallel_argv(args))
            figure_boxplots.main(["--out", str(args.out), "--formats", args.formats])
        elif step == "figure2":
            extra = ["--data", args.data] if args.data else []
            figure2.main(
                _runner_argv(args, args.figure2_runs) + _parallel_argv(args) + extra + formats
            )
        elif step == "figure1":
            quick = ["--quick"] if args.quick else []
            figure1.main(["--out", str(args.out), "--seed", str(4 + args.seed), *formats, *quick])
        elif step == "ablation":
            ablation.main(_runner_argv(args, args.ablation_runs) + _parallel_argv(args) + formats)
        elif step == "runtime":
            runtime.main(_runner_argv(args, args.runtime_runs))
        timings[step] = time.perf_counter() - start
    summary = ", ".join(f"{step} {seconds:.0f} s" for step, seconds in timings.items())
    print(f"done: {summary}; outputs in {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
