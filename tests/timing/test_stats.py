"""Statistics helper: hand-computed values, and agreement with the capture's exact
chunked statistics (:func:`lolacli.capture.stats.summary_us`, an independent implementation)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from lolacli.capture.stats import summary_us
from lolacli.timing.stats import STAT_KEYS, summarize_array


def test_hand_computed():
    s = summarize_array([2, 4, 4, 4, 5, 5, 7, 9])
    assert s is not None
    assert (s.count, s.min, s.max) == (8, 2, 9)
    assert s.mean == 5
    assert s.std == 2  # population std of the textbook example
    assert s.median == 4.5
    assert math.isclose(s.p99, 7 * 0.07 + 9 * 0.93)  # rank 6.93 between 7 and 9


def test_single_value_and_empty():
    s = summarize_array([124.1])
    assert s is not None and s.std == 0 and s.p99 == 124.1 and s.median == 124.1
    assert summarize_array(np.array([])) is None


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


@settings(max_examples=150, deadline=None)
@given(st.lists(st.integers(0, 10**10), min_size=1, max_size=300))
def test_agrees_with_the_capture_statistics(values):
    a = summarize_array(np.array(values))
    b = summary_us([np.array(values, np.int64)])
    assert a is not None and b is not None
    assert tuple(b) == STAT_KEYS and a.count == b["count"]
    for key in STAT_KEYS[1:]:
        x, y = getattr(a, key) / 1000.0, float(b[key])
        assert math.isclose(x, y, rel_tol=1e-9, abs_tol=1e-6), key
