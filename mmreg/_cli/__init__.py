"""The ``mmreg`` command line: one module per subcommand, plus plugins.

A subcommand is a module (or any object) with ``NAME``, ``HELP``, ``DESCRIPTION``,
``add_arguments(parser)`` and ``run(args) -> int``. Installed packages add subcommands
through the entry-point group ``"mmreg.commands"`` (:data:`ENTRY_POINT_GROUP`), e.g. in
their ``pyproject.toml``::

    [project.entry-points."mmreg.commands"]
    my-command = "my_package.cli_module"

Every error the user can fix (a missing file, a wrong shape, NaN) is one line on stderr,
``mmreg: error: FILE: problem``, with exit code 2; ``--debug`` shows the traceback.

Ctrl-C ends a run with exit code 130 and ``mmreg: interrupted``, after removing what the
run had begun to write. When ``mmreg`` runs as a program (the console scripts,
``python -m mmreg.cli``), it then leaves with :func:`os._exit`: finalising the interpreter
while C++ worker threads (scipy's k-d tree queries with ``workers``) still run crashes it.

Heavy modules (Open3D, matplotlib, pandas, the estimators) are imported by the
subcommands when they run, not to build the parser, so ``mmreg --help`` and
``mmreg --version`` start quickly.
"""

import argparse
import contextlib
import os
import signal
import sys
import warnings
from importlib.metadata import entry_points
from pathlib import Path

from mmreg import _interrupt
from mmreg._cli import dataset, demo, evaluate, register, view
from mmreg._cli._common import STRAY_WARNINGS, CLIError, one_line, remove_partial, show_warning

__all__ = ["BUILTIN_COMMANDS", "ENTRY_POINT_GROUP", "build_parser", "main"]

ENTRY_POINT_GROUP = "mmreg.commands"
BUILTIN_COMMANDS = (demo, register, evaluate, view, dataset)
# Exit codes: bad input or usage, and a failure of mmreg itself.
EXIT_USAGE, EXIT_FAILURE, EXIT_INTERRUPTED = 2, 1, 130


class _Formatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    """Every option with its default (unless None: its help says), descriptions as written."""

    def _get_help_string(self, action):
        if action.default is None:
            return action.help
        return super()._get_help_string(action)


def _plugins():
    commands = []
    for entry in entry_points(group=ENTRY_POINT_GROUP):
        try:
            command = entry.load()
            for attribute in ("add_arguments", "run"):
                if not callable(getattr(command, attribute, None)):
                    raise TypeError(f"it has no {attribute}()")
        except Exception as error:  # a broken plugin must not break the built-ins
            print(
                f"mmreg: warning: plugin {entry.name!r} ({entry.value}) not loaded: "
                f"{one_line(error)}",
                file=sys.stderr,
            )
            continue
        commands.append((entry.name, command))
    return commands


def build_parser():
    """The argument parser of ``mmreg`` with every subcommand."""
    from mmreg import __version__

    parser = argparse.ArgumentParser(
        prog="mmreg",
        description="Multi-model 3D registration: find every rigidly moving object in point\n"
        "correspondences between two point clouds (Jin et al., ICRA 2024).",
        epilog="Run 'mmreg COMMAND --help' for the options of a command.",
        formatter_class=_Formatter,
    )
    parser.add_argument("--version", action="version", version=f"mmreg {__version__}")
    parser.add_argument(
        "--debug", action="store_true", help="show the Python traceback of an error"
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    commands = [(command.NAME, command) for command in BUILTIN_COMMANDS]
    builtin = {name for name, _ in commands}
    commands += [(name, c) for name, c in _plugins() if name not in builtin]
    for name, command in commands:
        sub = subparsers.add_parser(
            name,
            help=getattr(command, "HELP", None),
            description=getattr(command, "DESCRIPTION", None),
            epilog=getattr(command, "EPILOG", None),
            formatter_class=_Formatter,
        )
        command.add_arguments(sub)
        sub.set_defaults(_run=command.run)
    return parser


def _is_the_program():
    """Whether this process is ``mmreg`` itself (not Python calling :func:`main`)."""
    module = sys.modules.get("__main__")
    spec = getattr(module, "__spec__", None)
    if spec is not None and spec.name in ("mmreg.cli", "mmreg._demo", "mmreg._cli"):
        return True
    name = Path(getattr(module, "__file__", None) or "").name.lower()
    return name.removesuffix(".exe").removesuffix("-script.py") in ("mmreg", "mmreg-demo")


def _flush():
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):  # a closed pipe or stream
            stream.flush()


def _interrupted():
    """Clean up after Ctrl-C; return 130, or leave the process at once when it is mmreg."""
    with contextlib.suppress(ValueError):  # ValueError: not the main thread
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C: no half cleanup
    remove_partial()
    with contextlib.suppress(OSError, ValueError):
        print("mmreg: interrupted", file=sys.stderr)
    _flush()
    if _is_the_program():
        # Worker threads of a k-d tree query may still run: finalising the interpreter
        # under them crashes it (a segfault instead of exit code 130).
        os._exit(EXIT_INTERRUPTED)
    return EXIT_INTERRUPTED


def main(argv=None):
    """Run ``mmreg`` with ``argv`` (default: ``sys.argv[1:]``); returns the exit code.

    When this process is the ``mmreg`` program, Ctrl-C ends it with exit code 130 at once
    (:func:`os._exit`, after cleaning up and flushing stdout and stderr).
    """
    args = None
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        with warnings.catch_warnings(), _interrupt.installed():
            if not args.debug:  # one line per warning; none of numpy's stray notes
                for category in STRAY_WARNINGS:
                    warnings.simplefilter("ignore", category)
                warnings.showwarning = show_warning
            code = int(args._run(args) or 0)
            _interrupt.check()  # a Ctrl-C whose KeyboardInterrupt something swallowed
            return code
    except CLIError as error:
        if args is not None and args.debug:
            raise
        remove_partial()
        print(f"mmreg: error: {one_line(error)}", file=sys.stderr)
        return EXIT_USAGE
    except BrokenPipeError:  # e.g. "mmreg demo | head": stop quietly
        remove_partial()
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_FAILURE
    except KeyboardInterrupt:
        return _interrupted()
    except Exception as error:
        if args is not None and args.debug:
            raise
        remove_partial()
        command = args.command if args is not None else "COMMAND"
        print(
            f"mmreg: error: {type(error).__name__}: {one_line(error)} (run 'mmreg --debug "
            f"{command} ...' for the traceback)",
            file=sys.stderr,
        )
        return EXIT_FAILURE
