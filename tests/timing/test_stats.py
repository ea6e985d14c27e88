"""The one statistics summary: hand-computed values, numpy as the oracle, and the two JSON
forms (``bus simulate``'s rounded µs, ``capture analyze``'s unrounded ns / 1000)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lolacli.timing.stats import STAT_KEYS, summarize_array, summarize_chunks


def test_hand_computed():
    s = summarize_array([2, 4, 4, 4, 5, 5, 7, 9])
    assert s is not None
    assert (s.count, s.min, s.max) == (8, 2, 9)
    assert s.mean == 5
    assert s.std == 2  # population std of the textbook example
    assert s.median == 4.5
    assert math.isclose(s.p99, 7 * 0.07 + 9 * 0.93)  # rank 6.93 between 7 and 9


def test_single_value_and_empty():
    s = summarize_array([124])
    assert s is not None and s.std == 0 and s.p99 == 124 and s.median == 124
    assert summarize_array(np.array([], np.int64)) is None
    assert summarize_array([]) is None


def test_only_integers():
    with pytest.raises(TypeError):
        summarize_array([1.5, 2.0])


def test_to_dict_scales_and_has_the_contract_keys():
    s = summarize_array([1000, 2000, 3000])
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
    exact = s.to_dict(divisor=1000.0, digits=None)
    assert math.isclose(exact["std"], math.sqrt(2 / 3), rel_tol=1e-15)
    assert exact["p99"] == 2.98


def test_jitter_is_std_and_the_largest_deviation_from_the_median():
    s = summarize_array([500_000, 499_000, 500_000, 503_500])
    assert s is not None
    j = s.jitter(divisor=1000.0)
    assert j == {"std": s.std / 1000.0, "max_deviation": 3.5}


@settings(max_examples=150, deadline=None)
@given(st.lists(st.integers(0, 10**10), min_size=1, max_size=300), st.data())
def test_agrees_with_numpy_however_cut(values, data):
    v = np.array(values, np.int64)
    s = summarize_array(v)
    assert s is not None and s.count == v.size
    x = v.astype(np.float64)
    expected = {"min": x.min(), "mean": x.mean(), "median": np.median(x), "std": x.std(),
                "p99": np.percentile(x, 99), "max": x.max()}
    for key, value in expected.items():
        assert math.isclose(getattr(s, key), value, rel_tol=1e-9, abs_tol=1e-6), key
    cuts = sorted(data.draw(st.lists(st.integers(0, v.size), max_size=5)))
    assert summarize_chunks(np.split(v, cuts)) == s
