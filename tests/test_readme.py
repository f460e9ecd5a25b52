"""Every Python block of the README runs as written; the quick start finds the objects."""

import re
from pathlib import Path

import numpy as np
import pytest

README = Path(__file__).resolve().parents[1] / "README.md"
BLOCKS = re.findall(r"```python\n(.*?)```", README.read_text(), re.S)


def test_the_readme_has_python_blocks():
    assert len(BLOCKS) >= 3


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_block_runs_as_written(index, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # a block that writes files writes them here
    exec(compile(BLOCKS[index], f"README.md block {index}", "exec"), {})


def test_quick_start_recovers_the_objects():
    namespace = {}
    exec(BLOCKS[0], namespace)
    est, scene = namespace["est"], namespace["scene"]
    assert est.n_clusters_ == scene.labels.max() + 1
    assert np.all(np.linalg.det(est.rotations_) > 0.999)
