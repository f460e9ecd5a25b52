"""row_medians gives np.median's floats, row by row."""

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from mmreg._array.geometry import row_medians


@pytest.mark.parametrize("width", range(1, 11))
def test_every_binary_row_is_sorted(width):
    # The 0-1 principle: a compare-exchange network that sorts every row of zeros and
    # ones sorts every row.
    rows = np.array(list(itertools.product([0.0, 1.0], repeat=width)))
    np.testing.assert_array_equal(row_medians(rows), np.median(rows, axis=1))


@settings(max_examples=200, deadline=None)
@given(
    arrays(
        np.float64,
        st.tuples(st.integers(0, 30), st.integers(1, 20)),
        elements=st.floats(-1e6, 1e6, allow_nan=False) | st.sampled_from([0.0, -0.0, 1.0]),
    )
)
def test_row_medians_are_numpys(values):
    # Ties, signed zeros and widths past the network's (numpy's median then) included.
    np.testing.assert_array_equal(row_medians(values), np.median(values, axis=1))
