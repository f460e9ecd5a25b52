"""The package layout: imports run one way, down, from the estimators to the array helpers."""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "mmreg"

# Each wing and what it may import from mmreg (besides itself): the floors beneath it.
BASE = {"mmreg._validation", "mmreg._warnings"}
BENEATH = {
    "mmreg._array": BASE,
    "mmreg.io": BASE | {"mmreg._array"},
    "mmreg.em": BASE | {"mmreg._array"},
    "mmreg.sweeps": BASE | {"mmreg._array", "mmreg.io"},
    "mmreg.tracking": BASE | {"mmreg._array", "mmreg.sweeps"},
}


def _mmreg_imports(path):
    """The mmreg modules a file imports, anywhere in it (lazy imports too)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            if node.module == "mmreg":
                found.update(f"mmreg.{alias.name}" for alias in node.names)
            elif node.module.startswith("mmreg."):
                found.add(node.module)
        elif isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name.startswith("mmreg."))
    return found


def _wing(module):
    return next((w for w in BENEATH if module == w or module.startswith(w + ".")), None)


@pytest.mark.parametrize("wing", sorted(BENEATH))
def test_a_wing_imports_only_what_lies_beneath_it(wing):
    folder = PACKAGE.joinpath(*wing.split(".")[1:])
    assert folder.is_dir()
    allowed = BENEATH[wing] | {wing}
    wrong = {
        f"{path.relative_to(PACKAGE)} -> {module}"
        for path in folder.rglob("*.py")
        for module in _mmreg_imports(path)
        if not any(module == a or module.startswith(a + ".") for a in allowed)
    }
    assert not wrong, sorted(wrong)


def test_the_helpers_beneath_never_import_the_estimators_or_the_command_line():
    above = ("mmreg.estimators", "mmreg._cli", "mmreg.runner", "mmreg.cli", "mmreg.methods")
    for path in PACKAGE.rglob("*.py"):
        module = "mmreg." + ".".join(path.relative_to(PACKAGE).with_suffix("").parts)
        if _wing(module) is None:
            continue
        for imported in _mmreg_imports(path):
            assert not imported.startswith(above), f"{module} imports {imported}"
