"""The small statistics of ``tollcli.stats`` against their definitions."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from tollcli.stats import median

finite = st.floats(allow_nan=False, allow_infinity=False, width=64, min_value=-1e300, max_value=1e300)


@settings(max_examples=300, deadline=None)
@given(arrays(np.float64, st.integers(1, 60), elements=finite | st.sampled_from([0.0, 1.0, -2.5])))
def test_the_median_is_numpys(a):
    """Property: the one-partition median is ``np.median``'s number — odd and even lengths, repeated values, values
    spanning six hundred decades."""
    assert median(a) == np.median(a)


def test_the_median_of_known_arrays():
    assert median(np.array([3.0])) == 3.0
    assert median(np.array([4.0, 1.0])) == 2.5
    assert median(np.array([5.0, 1.0, 3.0, 3.0])) == 3.0
    assert median(np.array([9.0, -1.0, 2.0, 7.0, 2.0])) == 2.0
