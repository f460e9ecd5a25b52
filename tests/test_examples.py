"""Every script of examples/ runs as a user runs it, short, quick and without a warning."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
SCRIPTS = sorted(p.name for p in EXAMPLES.glob("*.py"))
# What each prints when it works (arguments, text expected in stdout).
EXPECTED = {
    "quick_start.py": (["picture.png"], ["clusters in", "IoU", "written: picture.png"]),
    "grid_search.py": ([], ["initial clusters", "best: {'init__n_clusters': 50, 'tau': 0.25}"]),
    "sam_masks.py": ([], ["SAM-like masks", "Euclidean, 100 clusters", "objects found"]),
    "kitti_pipeline.py": (["out"], ["vs the static world", "moving cars found", "written:"]),
}


def test_every_example_is_listed_and_short():
    assert set(SCRIPTS) == set(EXPECTED)
    for name in SCRIPTS:
        assert len((EXAMPLES / name).read_text().splitlines()) <= 60, name


@pytest.mark.parametrize("name", SCRIPTS)
def test_example_runs(name, tmp_path):
    args, expected = EXPECTED[name]
    result = subprocess.run(
        [sys.executable, str(EXAMPLES / name), *args],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "MPLBACKEND": "Agg"},
    )
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""  # no warning the reader did not ask for
    for text in expected:
        assert text in result.stdout, (text, result.stdout)
    written = {p.name for p in tmp_path.rglob("*") if p.is_file()}
    if name == "quick_start.py":
        assert written == {"picture.png"}
    elif name == "kitti_pipeline.py":
        assert written == {"labels.npy", "motions.json", "street.png"}
        assert np.load(tmp_path / "out" / "labels.npy").ndim == 1
    else:
        assert written == set()  # the others write nothing
