"""Where the time of one ``mmreg register`` run goes: imports, reading, fit, picture, files.

    python benchmarks/cli_stages.py register A.feather --sweep B.feather --out DIR -q

Runs the command in this (new) process, as ``mmreg`` would, with every stage of
``mmreg._cli.register`` timed where it is called, and prints ``{stage: seconds}`` as JSON
on the last line of stdout. Imports are counted apart ("imports": every outermost
``import`` statement or ``importlib.import_module`` call, wherever it happens), so a stage's
own seconds are its work alone. ``benchmarks/sweep_speed.py --cli`` runs it after its timed
rounds.
"""

import builtins
import importlib
import json
import sys
import time

_IMPORTS = [0.0]  # seconds in outermost imports
_DEPTH = [0]


def _counted(function):
    def counted(*args, **kwargs):
        if _DEPTH[0]:
            return function(*args, **kwargs)
        _DEPTH[0] += 1
        start = time.perf_counter()
        try:
            return function(*args, **kwargs)
        finally:
            _IMPORTS[0] += time.perf_counter() - start
            _DEPTH[0] -= 1

    return counted


builtins.__import__ = _counted(builtins.__import__)
importlib.import_module = _counted(importlib.import_module)

# (label, attribute of mmreg._cli.register or mmreg._cli._common)
STAGES = [
    ("reading INPUT", "read_input"),
    ("reading --sweep", "read_sweep"),
    ("capture times", "read_capture_times"),
    ("fit", "_fit"),
    ("residuals to --sweep", "sweep_residuals"),
    ("summary", "summarize"),
    ("picture: drawing", "result_figure"),
    ("picture: PNG", "render_png"),
    ("input digests (run.json)", "input_record"),
    ("writing the files", "write_result_dir"),
]


def main(argv):
    spent = {"imports": 0.0}
    start = time.perf_counter()
    import mmreg._cli as cli  # noqa: PLC0415 (timed: the command line's own imports)
    from mmreg._cli import register

    for label, name in STAGES:
        original = getattr(register, name)

        def timed(*args, _original=original, _label=label, **kwargs):
            begin, imports = time.perf_counter(), _IMPORTS[0]
            try:
                return _original(*args, **kwargs)
            finally:
                own = time.perf_counter() - begin - (_IMPORTS[0] - imports)
                spent[_label] = spent.get(_label, 0.0) + own

        setattr(register, name, timed)
    code = cli.main(argv)
    spent["imports"] = _IMPORTS[0]
    total = time.perf_counter() - start
    spent["other"] = total - sum(spent.values())
    spent["total (in process)"] = total
    print(json.dumps(spent))
    return code


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
