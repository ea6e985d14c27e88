"""The summary of a chunked series (a capture's round trips) against numpy on the
concatenated series, to the last bit however it is cut, and in the capture's µs."""

from __future__ import annotations

import numpy as np
import pytest

from lolacli.timing import stats


def _us(summary):
    """As ``capture analyze`` reports it: µs = ns / 1000, not rounded."""
    return summary.to_dict(divisor=1000.0, digits=None)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("gather_max", [1, 64, 1 << 20])
def test_summary_equals_numpy(monkeypatch, seed, gather_max):
    monkeypatch.setattr(stats, "GATHER_MAX", gather_max)
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 5000))
    kind = seed % 4
    if kind == 0:      # round trips around 60 µs with rare long outliers
        v = rng.integers(40_000, 90_000, n)
        v[rng.random(n) < 0.01] = 2_000_000_000
    elif kind == 1:    # quantised timestamps: a handful of distinct values
        v = rng.choice([0, 1_000_000, 2_000_000], n)
    elif kind == 2:    # negative values (out-of-order timestamps)
        v = rng.integers(-5_000, 5_000, n)
    else:              # wide range, int64
        v = rng.integers(0, 1 << 40, n)
    v = v.astype(np.int64)
    cuts = np.sort(rng.integers(0, n, 5))
    chunks = [c.astype(np.int32) if np.abs(c).max(initial=0) < 2**31 else c
              for c in np.split(v, cuts)]
    got = _us(stats.summarize_chunks(chunks))
    x = v.astype(np.float64) / 1000.0
    assert got["count"] == n
    assert got["min"] == x.min() and got["max"] == x.max()
    assert got["median"] == pytest.approx(np.median(x), rel=1e-12, abs=1e-9)
    assert got["p99"] == pytest.approx(np.percentile(x, 99), rel=1e-12, abs=1e-9)
    assert got["mean"] == pytest.approx(x.mean(), rel=1e-12, abs=1e-9)
    assert got["std"] == pytest.approx(x.std(), rel=1e-9, abs=1e-9)
    # chunking does not change anything
    assert _us(stats.summarize_chunks([v])) == got


def test_empty_is_none():
    assert stats.summarize_chunks([]) is None
    assert stats.summarize_chunks([np.zeros(0, np.int32)]) is None
    assert stats.summarize_array([]) is None


@pytest.mark.parametrize("seed", range(3))
def test_std_is_exact_over_the_whole_int64_range(seed):
    """Values spread over all of int64 (a damaged capture's timestamps): the std equals
    the exact rational result (statistics.pstdev) and does not depend on the chunking."""
    import statistics

    rng = np.random.default_rng(seed)
    v = rng.integers(-(2**63), 2**63 - 1, 300, dtype=np.int64, endpoint=True)
    v[:2] = -(2**63), 2**63 - 1
    exact = statistics.pstdev([int(x) for x in v]) / 1000.0
    whole = _us(stats.summarize_chunks([v]))
    assert whole["std"] == pytest.approx(exact, rel=1e-15)
    for cuts in ([1], [7, 100, 101], list(range(0, 300, 13))):
        assert _us(stats.summarize_chunks(np.split(v, cuts))) == whole


@pytest.mark.parametrize("seed", range(6))
def test_python_ints_give_the_numpy_figures_to_the_last_bit(seed):
    """A short series of Python ints (a small capture's rows) is summarised without numpy;
    every figure is the one the numpy path gives for the same values, however cut."""
    from array import array

    rng = np.random.default_rng(100 + seed)
    n = int(rng.integers(1, 3000))
    if seed % 3 == 0:
        v = rng.integers(40_000, 90_000, n)
    elif seed % 3 == 1:
        v = rng.integers(-(2**62), 2**62, n)  # offsets beyond 2^63: the limbs' range
    else:
        v = rng.choice([0, 5, 1_000_000], n)
    values = [int(x) for x in v]
    cuts = sorted(int(c) for c in rng.integers(0, n, 4))
    parts = [values[a:b] for a, b in zip([0, *cuts], [*cuts, n], strict=True)]
    expected = stats.summarize_chunks([np.asarray(p, np.int64) for p in parts])
    assert stats.summarize_chunks(parts) == expected
    assert stats.summarize_chunks([array("q", p) for p in parts]) == expected
    assert stats.summarize_array(values) == expected


def test_python_values_that_are_not_ints_still_raise():
    for bad in ([1.5, 2.0], [True, False], [1, 2.5]):
        with pytest.raises(TypeError):
            stats.summarize_array(bad)
    assert stats.summarize_array([]) is None
