"""PNG figures of a capture analysis (matplotlib, Agg backend, imported on call)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lolacli.capture.analyze import CaptureReport
from lolacli.errors import UsageError


@dataclass(frozen=True, slots=True)
class PlotSeries:
    """The arrays the figures are drawn from, exactly as handed to matplotlib (the engines'
    differential test compares them). Empty arrays: nothing to plot."""

    #: cycle periods of the cyclic stream (µs), in capture order: the histogram
    cycle_period_us: np.ndarray
    #: round trips (µs) in the order their returns were captured: y of "over time"
    round_trip_us: np.ndarray
    #: x of "over time": seconds since the first return, or the pair's number when the
    #: report kept no return timestamps
    round_trip_x: np.ndarray
    round_trip_x_label: str
    #: the CDF: round trips sorted (µs), and the fraction of pairs at or below each
    cdf_round_trip_us: np.ndarray
    cdf_fraction: np.ndarray


def plot_series(report: CaptureReport) -> PlotSeries:
    """The plotted arrays of a report analysed with ``keep_series`` (pure: no matplotlib)."""
    empty = np.zeros(0, np.int64)
    periods = report.cycle_period_ns if report.cycle_period_ns is not None else empty
    rt_ns = report.round_trip_ns if report.round_trip_ns is not None else empty
    rt = rt_ns / 1000.0
    at = report.round_trip_at_ns
    if at is not None and at.size == rt.size:
        x = (at - at[0]) / 1e9 if at.size else np.zeros(0)
        label = "time since the first return (s)"
    else:
        x, label = np.arange(rt.size, dtype=np.float64), "pair"
    s = np.sort(rt)
    return PlotSeries(
        cycle_period_us=periods / 1000.0,
        round_trip_us=rt,
        round_trip_x=x,
        round_trip_x_label=label,
        cdf_round_trip_us=s,
        cdf_fraction=np.arange(1, s.size + 1) / s.size if s.size else np.zeros(0),
    )


def write_plots(report: CaptureReport, folder: str | Path) -> list[Path]:
    """Cycle-period histogram, round trip over time and round-trip CDF; returns the paths
    written (a plot with nothing to show is skipped). Statistics the report marks unusable
    (quantised or backward timestamps) say so in their titles."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:  # a core dependency; a broken install still gets one line
        raise UsageError(f"--plot needs matplotlib ({exc}): pip install matplotlib") from None

    out = plot_folder(folder)
    stem = Path(report.path).stem
    written: list[Path] = []
    series = plot_series(report)
    periods = series.cycle_period_us
    unusable = set(report.unusable_stats)
    rt_note = "\nunusable: quantised or backward timestamps" if (
        "round_trip_us" in unusable) else ""
    if periods.size:
        fig, ax = plt.subplots(figsize=(7, 4))
        ax.hist(periods, bins=min(200, max(10, periods.size // 20)))
        ax.set_xlabel("cycle period (µs)")
        ax.set_ylabel("cycles")
        note = ("\nunusable: quantised or backward timestamps"
                if "cycle_period_us" in unusable else "")
        ax.set_title(f"{stem}: cycle period ({report.cyclic_stream} stream){note}", fontsize=10)
        written.append(_save(fig, out / f"{stem}-cycle-period.png"))
    if series.round_trip_us.size:
        fig, ax = plt.subplots(figsize=(7, 4))
        ax.plot(series.round_trip_x, series.round_trip_us, ".", markersize=2)
        ax.set_xlabel(series.round_trip_x_label)
        ax.set_ylabel("round trip (µs)")
        ax.set_title(f"{stem}: round trip over time{rt_note}", fontsize=10)
        written.append(_save(fig, out / f"{stem}-round-trip.png"))
        fig, ax = plt.subplots(figsize=(7, 4))
        ax.plot(series.cdf_round_trip_us, series.cdf_fraction)
        ax.set_xlabel("round trip (µs)")
        ax.set_ylabel("fraction of pairs")
        ax.set_title(f"{stem}: round-trip CDF{rt_note}", fontsize=10)
        ax.grid(True, alpha=0.3)
        written.append(_save(fig, out / f"{stem}-round-trip-cdf.png"))
    return written


def plot_folder(folder: str | Path) -> Path:
    """``folder``, created if missing (not its parent: a mistyped path is not made into
    folders); :class:`UsageError` (exit 2) when it is a file, names a PNG, its parent is
    missing or it cannot be created. Call it before the analysis so a bad folder fails
    first."""
    out = Path(folder)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--plot {out}: is a file, not a folder")
    if not out.exists() and out.suffix.lower() == ".png":
        raise UsageError(f"--plot takes a folder (the PNGs are written into it), not a "
                         f"file name: {out}")
    parent = out.parent
    if not out.exists() and not parent.is_dir():
        why = "is a file" if parent.exists() else "does not exist"
        raise UsageError(f"--plot {out}: cannot create the folder: {parent} {why}")
    try:
        out.mkdir(exist_ok=True)
    except OSError as exc:
        raise UsageError(f"--plot {out}: cannot create the folder: {exc.strerror or exc}") from None
    return out


def _save(fig: object, path: Path) -> Path:
    import matplotlib.pyplot as plt

    try:
        fig.tight_layout()  # type: ignore[attr-defined]
        fig.savefig(path, dpi=100)  # type: ignore[attr-defined]
    except OSError as exc:
        raise UsageError(f"--plot: cannot write {path}: {exc.strerror or exc}") from None
    finally:
        plt.close(fig)  # type: ignore[arg-type]
    return path
