"""Exact statistics of long integer series kept as a list of chunks (pure numpy).

A 2 GB capture holds millions of round trips and cycle periods. Concatenating them (and
sorting a copy for the median) would double or triple the memory; instead the order
statistics are found by histogram refinement over the chunks: a histogram of up to 65,536
integer bins over the current window locates the bin that holds the wanted rank, the
window shrinks to that bin, and once it holds few values they are gathered and
partitioned. Every result is exact (integers in, the same numbers as sorting).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

BINS = 1 << 16
GATHER_MAX = 1 << 20


def _window_counts(chunks: Sequence[np.ndarray], lo: int, hi: int, bins: int) -> np.ndarray:
    span = hi - lo + 1
    counts = np.zeros(bins, np.int64)
    for c in chunks:
        v = c[(c >= lo) & (c <= hi)].astype(np.int64)
        if v.size:
            counts += np.bincount(((v - lo) * bins) // span, minlength=bins)
    return counts


def _gather(chunks: Sequence[np.ndarray], lo: int, hi: int) -> np.ndarray:
    parts = [c[(c >= lo) & (c <= hi)].astype(np.int64) for c in chunks]
    return np.concatenate(parts) if parts else np.zeros(0, np.int64)


def order_statistic(
    chunks: Sequence[np.ndarray], rank: int, lo: int, hi: int,
    cache: dict[tuple[int, int], np.ndarray] | None = None,
) -> int:
    """The value of 0-based ``rank`` in the sorted union of ``chunks`` (all within
    ``[lo, hi]``). ``cache`` shares window histograms between ranks."""
    cache = {} if cache is None else cache
    below = 0  # values smaller than the window
    population = sum(int(c.size) for c in chunks)
    while True:
        span = hi - lo + 1
        if span == 1:
            return lo
        if population <= GATHER_MAX:
            v = _gather(chunks, lo, hi)
            k = rank - below
            v.partition(k)
            return int(v[k])
        bins = min(span, BINS)
        counts = cache.get((lo, hi))
        if counts is None:
            counts = cache[(lo, hi)] = _window_counts(chunks, lo, hi, bins)
        cum = np.cumsum(counts)
        b = int(np.searchsorted(cum, rank - below, side="right"))
        before = int(cum[b - 1]) if b > 0 else 0
        below += before
        population = int(counts[b])
        lo, hi = lo + -(-b * span // bins), lo + -(-(b + 1) * span // bins) - 1


def _moments(chunks: Sequence[np.ndarray], lo: int) -> tuple[int, int]:
    """Exact sums of the offsets from ``lo`` and of their squares, so that mean and std do
    not depend on how the series is chunked (nor overflow int64): each offset (below
    2^64) is split into three 22-bit limbs whose products sum in uint64 without overflow."""
    m22 = np.uint64((1 << 22) - 1)
    base = np.uint64(lo % (1 << 64))
    s1 = s2 = 0
    for c in chunks:
        for i in range(0, c.size, 1 << 16):
            d = c[i : i + (1 << 16)].astype(np.int64).astype(np.uint64) - base
            x0, x1, x2 = d & m22, (d >> np.uint64(22)) & m22, d >> np.uint64(44)
            t = [int(v) for v in (x0.sum(), x1.sum(), x2.sum())]
            s1 += t[0] + (t[1] << 22) + (t[2] << 44)
            p = [int(np.dot(a, b)) for a, b in
                 ((x0, x0), (x0, x1), (x1, x1), (x0, x2), (x1, x2), (x2, x2))]
            s2 += (p[0] + (p[1] << 23) + ((p[2] + 2 * p[3]) << 44) + (p[4] << 67)
                   + (p[5] << 88))
    return s1, s2


def summary_us(chunks: Sequence[np.ndarray]) -> dict[str, float | int] | None:
    """``{count, min, mean, median, std, p99, max}`` in µs of integer-ns chunks.

    Population std; median and p99 interpolate linearly between order statistics, as
    numpy's default percentile does.
    """
    chunks = [c for c in chunks if c.size]
    n = sum(int(c.size) for c in chunks)
    if n == 0:
        return None
    lo = min(int(c.min()) for c in chunks)
    hi = max(int(c.max()) for c in chunks)
    s1, s2 = _moments(chunks, lo)
    mean = (lo * n + s1) / n
    std = math.sqrt((s2 * n - s1 * s1) / (n * n))
    pos = (n - 1) * 0.99
    p_lo = int(math.floor(pos))
    p_hi = min(p_lo + 1, n - 1)
    wanted = sorted({(n - 1) // 2, n // 2, p_lo, p_hi})
    memo: dict[int, int] = {}
    if n <= GATHER_MAX:
        # small enough to gather: one partition finds every wanted rank at once
        v = np.concatenate([c.astype(np.int64) for c in chunks])
        v.partition(wanted)
        memo = {k: int(v[k]) for k in wanted}
    histograms: dict[tuple[int, int], np.ndarray] = {}

    def rank(k: int) -> float:
        if k not in memo:
            memo[k] = order_statistic(chunks, k, lo, hi, histograms)
        return float(memo[k])

    p99 = rank(p_lo) + (rank(p_hi) - rank(p_lo)) * (pos - p_lo)
    return {
        "count": n,
        "min": lo / 1000.0,
        "mean": mean / 1000.0,
        "median": (rank((n - 1) // 2) + rank(n // 2)) / 2.0 / 1000.0,
        "std": std / 1000.0,
        "p99": p99 / 1000.0,
        "max": hi / 1000.0,
    }
