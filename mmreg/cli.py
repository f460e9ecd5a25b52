"""The ``mmreg`` command: ``mmreg demo``, ``register``, ``evaluate``, ``view`` and ``run``.

``mmreg --help`` lists the subcommands, ``mmreg COMMAND --help`` their options; this
module is also runnable as ``python -m mmreg.cli``. The subcommands live in
:mod:`mmreg._cli`, one module each.
"""

from mmreg._cli import build_parser, main

__all__ = ["build_parser", "main"]

if __name__ == "__main__":
    raise SystemExit(main())
