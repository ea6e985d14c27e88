"""The one statistics summary of the product: ``{count, min, mean, median, std, p99, max}``.

Every figure that summarises a series (round trips and cycle periods of a capture, the
round trips, sections and wake-ups of ``bus simulate``, the real-time master's periods)
is a :class:`Summary` made by :func:`summarize_array` (one series) or
:func:`summarize_chunks` (a series kept in chunks) from integers (nanoseconds, counts).
Conventions, numpy's defaults:

* ``std`` is the population standard deviation (ddof = 0);
* ``median`` and ``p99`` are linear-interpolation percentiles (numpy ``method="linear"``,
  Hyndman & Fan type 7): rank = q/100 × (n − 1), interpolated between neighbours.

The results are exact, and the same however the series is cut into chunks: a 2 GB
capture holds millions of round trips, kept as a list of chunks; concatenating them (and
sorting a copy for the median) would double or triple the memory. Up to GATHER_MAX
values are gathered into one array and counted by value (when their span is at most
the larger of 65,536 and their number) or partitioned. Beyond, the order
statistics are found by histogram refinement over the chunks: a histogram of up to
65,536 integer bins over the current window locates the bin that holds the wanted rank,
the window shrinks to that bin, and once it holds few values they are gathered and
partitioned. Mean and std come from exact integer sums.

A short series of Python ints (lists or ``array.array``, up to :data:`PLAIN_MAX`
values: a small capture's round trips) is summarised without numpy, by the same exact
sums and ranks, so that a short command need not import it (~100 ms): the figures are
the same to the last bit.

:func:`summarize_array` returns ``None`` for an empty series, which the JSON contracts render
as ``null``; :meth:`Summary.to_dict` gives the contract's keys in the contract's unit.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

    _Chunk = npt.NDArray[np.integer[Any]]

STAT_KEYS = ("count", "min", "mean", "median", "std", "p99", "max")

BINS = 1 << 16
GATHER_MAX = 1 << 20
#: series of Python ints up to this long are summarised without numpy
PLAIN_MAX = 1 << 18


@dataclass(frozen=True, slots=True)
class Summary:
    """The summary of a series, in the series' own unit (e.g. ns)."""

    count: int
    min: float
    mean: float
    median: float
    std: float
    p99: float
    max: float

    def to_dict(
        self, scale: float = 1.0, digits: int | None = 3, divisor: float = 1.0
    ) -> dict[str, float | int]:
        """Keys of :data:`STAT_KEYS`; every value but ``count`` is ``value * scale /
        divisor``, rounded to ``digits`` (None: not rounded).

        Two contracts use it: ``bus simulate`` and the real-time master report µs as
        ``round(ns * 1e-3, 3)`` (``scale=1e-3``); ``capture analyze`` reports them
        unrounded as ``ns / 1000`` (``divisor=1000.0, digits=None``), to the last bit."""
        out: dict[str, float | int] = {"count": self.count}
        for key in STAT_KEYS[1:]:
            v = getattr(self, key) * scale / divisor
            out[key] = round(v, digits) if digits is not None else v
        return out

    def jitter(self, scale: float = 1.0, divisor: float = 1.0) -> dict[str, float]:
        """Jitter of a cycle period: its std and the largest deviation from the median
        (``max |x - median|``), in the unit of :meth:`to_dict` (unrounded; each value is
        converted before the difference is taken)."""
        lo, med, hi = (v * scale / divisor for v in (self.min, self.median, self.max))
        return {"std": self.std * scale / divisor,
                "max_deviation": max(abs(lo - med), abs(hi - med))}


def summarize_array(values: npt.ArrayLike) -> Summary | None:
    """The summary of a series of integers (a list, an array); ``None`` when empty.

    Raises :class:`TypeError` for values that are not integers."""
    return summarize_chunks([values])  # type: ignore[list-item]


def summarize_chunks(chunks: Iterable[_Chunk]) -> Summary | None:
    """The summary of the series made of ``chunks`` (integer arrays, or lists) one after
    the other; the same, to the last bit, however the series is cut. ``None`` when
    empty."""
    chunks = list(chunks)
    plain = _plain(chunks)
    if plain is not None:
        return _summary(plain)
    import numpy as np

    parts = [c for c in (np.asarray(c) for c in chunks) if c.size]
    for c in parts:
        if not np.issubdtype(c.dtype, np.integer):
            raise TypeError(f"summarize: integers expected, not {c.dtype}")
    n = sum(int(c.size) for c in parts)
    if n == 0:
        return None
    gathered = None
    if n <= GATHER_MAX:
        # small enough to gather: one array (not thousands of drained chunks), and one
        # partition finds every wanted rank at once
        gathered = np.concatenate(parts, dtype=np.int64)
        parts = [gathered]
    lo = min(int(c.min()) for c in parts)
    hi = max(int(c.max()) for c in parts)
    wanted = _ranks(n)
    memo: dict[int, int] = {}
    if gathered is not None and hi - lo < max(BINS, n):
        # few distinct values possible (round trips, periods): count them, exactly; the
        # counts give the sums too
        counts = np.bincount(gathered - lo, minlength=hi - lo + 1)
        s1, s2 = _counted_moments(counts)
        cum = np.cumsum(counts)
        at = np.searchsorted(cum, wanted, side="right")
        memo = {k: lo + int(i) for k, i in zip(wanted, at, strict=True)}
    else:
        s1, s2 = _moments(parts, lo, hi)
        if gathered is not None:  # (a copy of the chunks: partitioned in place)
            gathered.partition(wanted)
            memo = {k: int(gathered[k]) for k in wanted}
    histograms: dict[tuple[int, int], npt.NDArray[np.int64]] = {}

    def rank(k: int) -> int:
        if k not in memo:
            memo[k] = order_statistic(parts, k, lo, hi, histograms)
        return memo[k]

    return _made(n, lo, hi, s1, s2, rank)


def _ranks(n: int) -> list[int]:
    """The 0-based ranks the median and the p99 of ``n`` values interpolate between."""
    p_lo = int(math.floor((n - 1) * 0.99))
    return sorted({(n - 1) // 2, n // 2, p_lo, min(p_lo + 1, n - 1)})


def _made(n: int, lo: int, hi: int, s1: int, s2: int, rank: Any) -> Summary:
    """The summary from the count, the extremes, the exact sums of the offsets from
    ``lo`` and of their squares, and ``rank(k)``: the value of 0-based rank k."""
    pos = (n - 1) * 0.99
    p_lo = int(math.floor(pos))
    p_hi = min(p_lo + 1, n - 1)
    r_lo, r_hi = float(rank(p_lo)), float(rank(p_hi))
    return Summary(
        count=n,
        min=float(lo),
        mean=(lo * n + s1) / n,
        median=(float(rank((n - 1) // 2)) + float(rank(n // 2))) / 2.0,
        std=math.sqrt((s2 * n - s1 * s1) / (n * n)),
        p99=r_lo + (r_hi - r_lo) * (pos - p_lo),
        max=float(hi),
    )


def _plain(chunks: list[Any]) -> list[int] | None:
    """The values of ``chunks`` as one list when every chunk is a list of ints or an
    integer ``array.array`` and there are at most :data:`PLAIN_MAX` of them, else None
    (numpy summarises them; it also says why values that are not integers are not)."""
    if not all(isinstance(c, list | array) for c in chunks):
        return None
    if sum(len(c) for c in chunks) > PLAIN_MAX:
        return None
    values: list[int] = []
    for c in chunks:
        if isinstance(c, array):
            if c.typecode not in "bBhHiIlLqQ":
                return None
            values += c.tolist()
        elif all(type(v) is int for v in c):
            values += c
        else:
            return None
    return values


def _summary(values: list[int]) -> Summary | None:
    """:func:`summarize_chunks` of Python ints, without numpy (the same figures)."""
    n = len(values)
    if n == 0:
        return None
    lo, hi = min(values), max(values)
    total = sum(values)
    s1 = total - lo * n
    s2 = sum(v * v for v in values) - 2 * lo * total + lo * lo * n
    ordered = sorted(values)
    return _made(n, lo, hi, s1, s2, ordered.__getitem__)


def _window_counts(chunks: Sequence[_Chunk], lo: int, hi: int, bins: int) -> npt.NDArray[np.int64]:
    import numpy as np

    span = hi - lo + 1
    counts = np.zeros(bins, np.int64)
    for c in chunks:
        v = c[(c >= lo) & (c <= hi)].astype(np.int64)
        if v.size:
            counts += np.bincount(((v - lo) * bins) // span, minlength=bins)
    return counts


def _gather(chunks: Sequence[_Chunk], lo: int, hi: int) -> npt.NDArray[np.int64]:
    import numpy as np

    parts = [c[(c >= lo) & (c <= hi)].astype(np.int64) for c in chunks]
    return np.concatenate(parts) if parts else np.zeros(0, np.int64)


def order_statistic(
    chunks: Sequence[_Chunk], rank: int, lo: int, hi: int,
    cache: dict[tuple[int, int], npt.NDArray[np.int64]] | None = None,
) -> int:
    """The value of 0-based ``rank`` in the sorted union of ``chunks`` (all within
    ``[lo, hi]``). ``cache`` shares window histograms between ranks."""
    import numpy as np

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


def _counted_moments(counts: npt.NDArray[np.int64]) -> tuple[int, int]:
    """:func:`_moments` from the count of each offset (``counts[v]``: how many values
    are ``lo + v``). Exact in int64: there are at most :data:`GATHER_MAX` (2^20) values
    and offsets (below ``max(BINS, n)``), so each sum stays below 2^60."""
    import numpy as np

    offsets = np.arange(counts.size, dtype=np.int64)
    weighted = counts * offsets
    return int(weighted.sum()), int(np.dot(weighted, offsets))


def _moments(chunks: Sequence[_Chunk], lo: int, hi: int) -> tuple[int, int]:
    """Exact sums of the offsets from ``lo`` and of their squares, so that mean and std do
    not depend on how the series is chunked (nor overflow int64). When the offsets are
    small (``hi - lo`` below 2^31: round trips, cycle periods), slices short enough that
    their sum of squares stays below 2^63 are summed in int64; else each offset (below
    2^64) is split into three 22-bit limbs whose products sum in uint64 without
    overflow. Both are exact: the same integers."""
    import numpy as np

    span = hi - lo
    if span < 1 << 31:
        step = max(1, ((1 << 63) - 1) // max(span * span, 1))
        s1 = s2 = 0
        for c in chunks:
            for i in range(0, c.size, step):
                off = c[i : i + step].astype(np.int64) - np.int64(lo)
                s1 += int(off.sum())
                s2 += int(np.dot(off, off))
        return s1, s2
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


__all__ = ["STAT_KEYS", "Summary", "order_statistic", "summarize_array", "summarize_chunks"]
