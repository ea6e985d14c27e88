"""Summary statistics of a run: {count, min, mean, median, std, p99, max}.

Conventions, numpy's defaults (the same as :func:`lolacli.capture.stats.summary_us`, which
computes them exactly over chunked captures):

* ``std`` is the population standard deviation (ddof = 0);
* ``median`` and ``p99`` are linear-interpolation percentiles (numpy ``method="linear"``,
  Hyndman & Fan type 7): rank = q/100 × (n − 1), interpolated between neighbours.

:func:`summarize_array` returns ``None`` for an empty input, which the JSON contracts
render as ``null``.
"""

from __future__ import annotations

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


__all__ = ["STAT_KEYS", "Summary", "summarize_array"]
