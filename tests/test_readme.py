"""The README's quick start runs as written and finds the scene's objects."""

import re
from pathlib import Path

import numpy as np

README = Path(__file__).resolve().parents[1] / "README.md"


def test_quick_start_runs_and_recovers_the_objects():
    code = re.search(r"```python\n(.*?)```", README.read_text(), re.S).group(1)
    namespace = {}
    exec(code, namespace)
    est, scene = namespace["est"], namespace["scene"]
    assert est.n_clusters_ == scene.labels.max() + 1
    assert np.all(np.linalg.det(est.rotations_) > 0.999)
