"""The ``mmreg`` command line: one module per subcommand, plus plugins.

A subcommand is a module (or any object) with ``NAME``, ``HELP``, ``DESCRIPTION``,
``add_arguments(parser)`` and ``run(args) -> int``. Installed packages add subcommands
through the entry-point group ``"mmreg.commands"`` (:data:`ENTRY_POINT_GROUP`), e.g. in
their ``pyproject.toml``::

    [project.entry-points."mmreg.commands"]
    my-command = "my_package.cli_module"

Every error the user can fix (a missing file, a wrong shape, NaN) is one line on stderr,
``mmreg: error: FILE: problem``, with exit code 2; ``--debug`` shows the traceback.
"""

import argparse
import os
import sys
from importlib.metadata import entry_points

from mmreg._cli import demo, evaluate, register, view
from mmreg._cli._common import CLIError, one_line

__all__ = ["BUILTIN_COMMANDS", "ENTRY_POINT_GROUP", "build_parser", "main"]

ENTRY_POINT_GROUP = "mmreg.commands"
BUILTIN_COMMANDS = (demo, register, evaluate, view)
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


def main(argv=None):
    """Run ``mmreg`` with ``argv`` (default: ``sys.argv[1:]``); returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except CLIError as error:
        if args.debug:
            raise
        print(f"mmreg: error: {one_line(error)}", file=sys.stderr)
        return EXIT_USAGE
    except BrokenPipeError:  # e.g. "mmreg demo | head": stop quietly
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_FAILURE
    except KeyboardInterrupt:
        print("mmreg: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as error:
        if args.debug:
            raise
        print(
            f"mmreg: error: {type(error).__name__}: {one_line(error)} (run 'mmreg --debug "
            f"{args.command} ...' for the traceback)",
            file=sys.stderr,
        )
        return EXIT_FAILURE
