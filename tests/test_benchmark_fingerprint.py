"""benchmarks/fingerprint.py and benchmarks/ablation_datasets.py: fingerprints that tell
any bit apart, and an ablation run on a small generated scene."""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from mmreg import MultiModelRegistration
from mmreg.datasets import make_scene
from mmreg.em._robust import ROBUST_STEPS

ROOT = Path(__file__).resolve().parent.parent


def _benchmark(name):
    spec = importlib.util.spec_from_file_location(
        f"benchmark_{name}", ROOT / f"benchmarks/{name}.py"
    )
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(f"benchmark_{name}", module)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def fingerprint():
    return _benchmark("fingerprint")


def test_a_digest_tells_apart_one_bit_a_dtype_and_a_shape(fingerprint):
    x = np.linspace(0.0, 1.0, 6)
    nudged = x.copy()
    nudged[3] = np.nextafter(nudged[3], 2.0)
    digests = {
        fingerprint.digest(v)
        for v in (x, nudged, x.astype(np.float32), x.reshape(2, 3), list(x), 0.5)
    }
    assert len(digests) == 6
    assert fingerprint.digest(x.copy()) == fingerprint.digest(x)
    assert fingerprint.digest({"b": 1, "a": 2}) == fingerprint.digest({"a": 2, "b": 1})


def test_compare_names_the_attributes_that_differ_and_the_fits_missing(fingerprint):
    X = make_scene(n_objects=2, n_points=1200, separation=3.0, random_state=0).X
    first, again = (
        {
            key: fingerprint.digest(value)
            for key, value in fingerprint.fitted_attributes(
                MultiModelRegistration(tau=1.5, random_state=0).fit(X)
            ).items()
        }
        for _ in range(2)
    )
    assert first == again and "labels_" in first and "rotations_" in first
    other = dict(first, labels_="0" * 16, all="1" * 16)
    first["all"] = fingerprint.digest(first)
    differ = fingerprint.compare({"fit": first, "gone": first}, {"fit": other, "new": first})
    assert differ == {
        "fit": ["all", "labels_"],
        "gone": ["missing after"],
        "new": ["missing before"],
    }


def test_the_ablation_fits_the_default_without_each_step(tmp_path, monkeypatch):
    ablation = _benchmark("ablation_datasets")
    scene = make_scene(n_objects=2, n_points=300, separation=3.0, random_state=1)

    def small(seed):
        yield "small", scene.X, scene.labels, None, 1.5

    monkeypatch.setattr(ablation, "scenes", small)
    assert ablation.main(["--seeds", "1", "--out", str(tmp_path)]) == 0
    text = (tmp_path / "ablation_datasets.md").read_text()
    for step in ROBUST_STEPS:
        assert f"| sweep-no-{step} " in text
    table = np.genfromtxt(tmp_path / "ablation_datasets.csv", delimiter=",", names=True, dtype=None)
    assert len(table) == 1 + len(ROBUST_STEPS)
