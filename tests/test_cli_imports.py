"""The command line imports what a command needs, when it needs it, and nothing else."""

import json
import subprocess
import sys

import numpy as np
import pytest
from _fake_av2 import STAMPS, sweeps, write_log

# Packages no help text needs; the parser is built from mmreg's own small modules.
HEAVY = {"numpy", "scipy", "sklearn", "pandas", "matplotlib", "PIL", "pyarrow", "open3d"}
HEAVY |= {"seaborn", "tqdm", "dask", "rosbags", "small_gicp", "pypatchworkpp"}

# Run the command line in a new interpreter; print the top-level packages it imported.
_CHILD = """
import json, sys
import mmreg
before = set(sys.modules)
from mmreg.cli import main
try:
    code = main(json.loads(sys.argv[1]))
except SystemExit as exit:
    code = exit.code
new = sorted({m.split(".")[0] for m in set(sys.modules) - before})
print(json.dumps({"code": code, "new": new}))
"""


def _imported(*args):
    """The top-level packages ``mmreg ARGS`` imports beyond ``import mmreg``."""
    result = subprocess.run(
        [sys.executable, "-c", _CHILD, json.dumps([str(a) for a in args])],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert result.returncode == 0, result.stderr
    found = json.loads(result.stdout.splitlines()[-1])
    assert found["code"] == 0, result.stderr
    return set(found["new"])


def test_import_mmreg_is_light():
    code = "import sys, mmreg; print(' '.join(sorted(m.split('.')[0] for m in sys.modules)))"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert not set(result.stdout.split()) & HEAVY


@pytest.mark.parametrize("args", [["--help"], ["--version"], ["register", "--help"]])
def test_help_and_version_import_nothing_heavy(args):
    new = _imported(*args)
    assert "mmreg" in new  # the command line itself was imported
    assert not new & HEAVY, sorted(new & HEAVY)


def test_two_sweeps_import_neither_open3d_nor_seaborn_nor_a_progress_bar(tmp_path):
    """Two raw sweeps of points: the fit and the picture, but no Open3D, no seaborn, no
    tqdm (stderr is not a terminal), no dask. (scikit-learn imports pandas, and pandas 3
    pyarrow, whatever mmreg does.)"""
    first, second = (sweeps()[stamp] for stamp in STAMPS[:2])
    np.save(tmp_path / "a.npy", first)
    np.save(tmp_path / "b.npy", second)
    new = _imported(
        "register", tmp_path / "a.npy", "--sweep", tmp_path / "b.npy", "--out", tmp_path / "r"
    )
    assert {"sklearn", "matplotlib"} <= new  # the fit and the picture ran
    assert (tmp_path / "r" / "result.png").exists()
    unneeded = {"open3d", "seaborn", "tqdm", "dask", "rosbags"}
    assert not new & unneeded, sorted(new & unneeded)


def test_feather_sweeps_need_no_more(tmp_path):
    lidar = write_log(tmp_path / "log") / "sensors" / "lidar"
    first, second = (lidar / f"{stamp}.feather" for stamp in STAMPS[:2])
    new = _imported("register", first, "--sweep", second, "--out", tmp_path / "r", "-q")
    assert "pyarrow" in new
    unneeded = {"open3d", "seaborn", "tqdm", "dask", "rosbags"}
    assert not new & unneeded, sorted(new & unneeded)
