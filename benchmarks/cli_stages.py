"""Where the time of one ``mmreg register`` run goes: imports, reading, fit, picture, files.

    python benchmarks/cli_stages.py register A.feather --sweep B.feather --out DIR -q

Runs the command in this (new) process, as ``mmreg`` would, with every stage of
``mmreg._cli.register`` timed where it is called, and prints ``{stage: seconds}`` as JSON
on the last line of stdout. Imports are counted apart ("imports": every outermost
``import`` statement or ``importlib.import_module`` call, wherever it happens), so a stage's
own seconds are its work alone, and split by package ("imports: scipy": the bodies of
scipy's modules, what they import of other packages apart). Where Python may not write
bytecode (``PYTHONDONTWRITEBYTECODE``), "imports: mmreg" includes compiling its modules.
``benchmarks/sweep_speed.py --cli`` runs it after its timed rounds.
"""

import builtins
import importlib
import json
import sys
import time

_IMPORTS = [0.0]  # seconds in outermost imports
_STACK = []  # the imports under way: [package, start, seconds of the imports inside]
# Seconds of each package's own imports (its modules' bodies, the imports they make of
# other packages apart); the rest under "other".
PACKAGES = ("numpy", "scipy", "sklearn", "pandas", "pyarrow", "matplotlib", "mmreg")
_BY_PACKAGE = dict.fromkeys(PACKAGES, 0.0)


def _package(name, args, kwargs):
    """The top-level package an ``__import__`` or ``import_module`` call imports from."""
    level = args[3] if len(args) > 3 else kwargs.get("level", 0)
    where = args[0] if args else kwargs.get("globals", kwargs.get("package"))
    if isinstance(where, dict):  # __import__'s globals: a relative import's package
        where = where.get("__package__") or where.get("__name__") if level else None
    elif not str(name).startswith("."):
        where = None
    return str(where or name).split(".")[0]


def _counted(function):
    def counted(name, *args, **kwargs):
        start = time.perf_counter()
        _STACK.append([_package(name, args, kwargs), start, 0.0])
        try:
            return function(name, *args, **kwargs)
        finally:
            package, start, inside = _STACK.pop()
            elapsed = time.perf_counter() - start
            key = package if package in _BY_PACKAGE else "other"
            _BY_PACKAGE[key] = _BY_PACKAGE.get(key, 0.0) + elapsed - inside
            if _STACK:
                _STACK[-1][2] += elapsed
            else:
                _IMPORTS[0] += elapsed

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
    for package, seconds in _BY_PACKAGE.items():
        spent[f"imports: {package}"] = seconds
    total = time.perf_counter() - start
    counted = sum(v for k, v in spent.items() if not k.startswith("imports: "))
    spent["other"] = total - counted
    spent["total (in process)"] = total
    print(json.dumps(spent))
    return code


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
