"""benchmarks/scale.py: its floors and how a row is written, on a small scene."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from mmreg.datasets import make_scene

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def scale():
    path = ROOT / "benchmarks/scale.py"
    spec = importlib.util.spec_from_file_location("_scale_under_test", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def X():
    return make_scene(n_objects=3, n_points=600, random_state=0).X


def test_floors_time_the_neighbour_table_only_when_asked(scale, X):
    plain = scale.floors(X, 1)
    assert set(plain) == {"knn_s", "pass_s"}
    with_table = scale.floors(X, 1, table=True)
    assert set(with_table) == {"knn_s", "pass_s", "table_s"}
    assert all(np.isfinite(v) and v > 0 for v in with_table.values())


def test_floor_text_names_the_table_where_it_was_timed(scale):
    row = {"knn_s": 0.0437, "pass_s": 0.0008}
    assert scale.floor_text(row) == "k-NN 0.0437 s, one pass 0.0008 s"
    # Rows read back from the CSV carry NaN where another row timed the table.
    assert "table" not in scale.floor_text(row | {"table_s": float("nan")})
    assert scale.floor_text(row | {"table_s": 0.068}).endswith(
        "(the default's k=16 neighbour table: 0.068 s)"
    )


def test_every_row_of_the_table_has_the_issue_words(scale):
    rows = [
        {
            "row": "table1",
            "method": "MultiModelRegistration()",
            "seconds": 0.2,
            "n_iter": 2,
            "s_per_iter": 0.1,
            "iou": 1.0,
            "knn_s": 0.04,
            "pass_s": 0.001,
            "table_s": 0.06,
        }
    ]
    line = scale.markdown(rows).splitlines()[-1]
    assert line.startswith("| Table I scene (22,395 correspondences)")
    assert "| <= 100 ms |" in line
    assert "0.2 s, 2 iter (100 ms/iter), IoU 1.000" in line
    assert "neighbour table: 0.06 s" in line
