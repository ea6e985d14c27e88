"""Summary statistics used across lolacli: {count, min, mean, median, std, p99, max} (pure).

Conventions, the same as numpy's defaults so the two implementations agree:

* ``std`` is the population standard deviation (ddof = 0);
* ``median`` and ``p99`` are linear-interpolation percentiles (numpy ``method="linear"``,
  Hyndman & Fan type 7): rank = q/100 × (n − 1), interpolated between neighbours.

:func:`summarize` is pure Python for sequences (small inputs, no numpy import);
:func:`summarize_array` does the same with numpy for large arrays. Both return ``None``
for an empty input, which the JSON contracts render as ``null``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

STAT_KEYS = ("count", "min", "mean", "median", "std", "p99", "max")


@dataclass(frozen=True, slots=True)
class Summary:
    count: int
    min: float
    mean: float
    median: float
    std: float
    p99: float
    max: float

    def to_dict(self, scale: float = 1.0, digits: int | None = 3) -> dict[str, float | int]:
        """Keys of :data:`STAT_KEYS`; values multiplied by ``scale`` (e.g. 1e-3 for ns → µs)."""
        out: dict[str, float | int] = {"count": self.count}
        for key, value in asdict(self).items():
            if key != "count":
                v = value * scale
                out[key] = round(v, digits) if digits is not None else v
        return out


def percentile(sorted_values: Sequence[float], q: float) -> float:
    """Linear-interpolation percentile of already sorted values (numpy's default)."""
    if not sorted_values:
        raise ValueError("percentile of no values")
    if not 0 <= q <= 100:
        raise ValueError(f"percentile {q} outside 0..100")
    rank = q / 100 * (len(sorted_values) - 1)
    lo = math.floor(rank)
    hi = min(lo + 1, len(sorted_values) - 1)
    frac = rank - lo
    return sorted_values[lo] + (sorted_values[hi] - sorted_values[lo]) * frac


def summarize(values: Sequence[float]) -> Summary | None:
    """Statistics of a sequence of numbers (pure Python); ``None`` when it is empty."""
    if len(values) == 0:
        return None
    data = sorted(float(v) for v in values)
    n = len(data)
    mean = math.fsum(data) / n
    variance = math.fsum((v - mean) ** 2 for v in data) / n
    return Summary(
        count=n,
        min=data[0],
        mean=mean,
        median=percentile(data, 50),
        std=math.sqrt(variance),
        p99=percentile(data, 99),
        max=data[-1],
    )


def summarize_array(values: Any) -> Summary | None:
    """The same statistics with numpy (for large arrays); ``None`` when empty."""
    import numpy as np

    arr = np.asarray(values, dtype=np.float64).ravel()
    if arr.size == 0:
        return None
    p50, p99 = np.percentile(arr, [50, 99])
    return Summary(
        count=int(arr.size),
        min=float(arr.min()),
        mean=float(arr.mean()),
        median=float(p50),
        std=float(arr.std()),
        p99=float(p99),
        max=float(arr.max()),
    )


__all__ = ["STAT_KEYS", "Summary", "percentile", "summarize", "summarize_array"]
