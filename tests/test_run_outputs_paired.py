"""Correspondences whose a-rows are one point repeated: one clear ValueError, no crash."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from mmreg import MultiModelRegistration
from mmreg._validation import NotCorrespondencesError, check_paired
from mmreg.cli import main

finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)


@given(
    point=st.tuples(finite, finite, finite),
    n=st.integers(3, 60),
    seed=st.integers(0, 2**16),
)
def test_one_a_point_sent_to_many_places_is_a_clear_value_error(point, n, seed):
    a = np.tile(np.asarray(point, dtype=float), (n, 1))
    # b-rows far apart from each other (beyond any gate), so the rows cannot be a motion.
    b = a + np.random.default_rng(seed).uniform(-1.0, 1.0, (n, 3)) * 100.0 + [200.0, 0, 0]
    with pytest.raises(NotCorrespondencesError, match=f"{n} of its {n} rows share one a-point"):
        check_paired(a, b, tau=1.5)


def test_the_estimator_and_the_command_line_say_it(tmp_path, capsys):
    rng = np.random.default_rng(0)
    X = np.hstack([np.ones((40, 3)), rng.uniform(-50, 50, (40, 3))])
    with pytest.raises(ValueError, match="share one a-point"):
        MultiModelRegistration(tau=1.5).fit(X)
    np.save(tmp_path / "pairs.npy", X)
    assert main(["register", str(tmp_path / "pairs.npy"), "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert "pairs.npy: X does not look like correspondences: 40 of its 40 rows" in err
    assert "Traceback" not in err
