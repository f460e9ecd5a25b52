"""``mmreg-demo``: the same as ``mmreg demo`` (kept for the README's set-up line)."""

import sys

from mmreg._cli import main as _main


def main(argv=None):
    """Run ``mmreg demo`` with ``argv`` (default: ``sys.argv[1:]``)."""
    return _main(["demo", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    raise SystemExit(main())
