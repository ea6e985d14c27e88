"""Statistics helper: hand-computed values, and the pure and numpy versions agree."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lolacli.timing.stats import STAT_KEYS, percentile, summarize, summarize_array


def test_hand_computed():
    s = summarize([2, 4, 4, 4, 5, 5, 7, 9])
    assert s is not None
    assert (s.count, s.min, s.max) == (8, 2, 9)
    assert s.mean == 5
    assert s.std == 2  # population std of the textbook example
    assert s.median == 4.5
    assert s.p99 == pytest.approx(7 * 0.07 + 9 * 0.93)  # rank 6.93 between 7 and 9


def test_single_value_and_empty():
    s = summarize([124.1])
    assert s is not None and s.std == 0 and s.p99 == 124.1 and s.median == 124.1
    assert summarize([]) is None
    assert summarize_array(np.array([])) is None


def test_to_dict_scales_and_has_the_contract_keys():
    s = summarize([1000, 2000, 3000])
    assert s is not None
    d = s.to_dict(scale=1e-3)
    assert tuple(d) == STAT_KEYS
    assert d == {
        "count": 3,
        "min": 1.0,
        "mean": 2.0,
        "median": 2.0,
        "std": 0.816,
        "p99": 2.98,
        "max": 3.0,
    }


def test_percentile_bounds():
    with pytest.raises(ValueError):
        percentile([], 50)
    with pytest.raises(ValueError):
        percentile([1.0], 101)


@settings(max_examples=150, deadline=None)
@given(st.lists(st.floats(-1e9, 1e9, allow_nan=False), min_size=1, max_size=300))
def test_pure_and_numpy_agree(values):
    a, b = summarize(values), summarize_array(np.array(values))
    assert a is not None and b is not None
    assert a.count == b.count
    for key in ("min", "mean", "median", "std", "p99", "max"):
        x, y = getattr(a, key), getattr(b, key)
        assert math.isclose(x, y, rel_tol=1e-9, abs_tol=1e-6), key
