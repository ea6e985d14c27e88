"""PNG figures of a capture analysis (matplotlib, Agg backend, imported on call)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lolacli.capture.analyze import CaptureReport
from lolacli.errors import UsageError


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
    empty = np.zeros(0, np.int64)
    periods = (report.cycle_period_ns if report.cycle_period_ns is not None else empty) / 1000.0
    rt = (report.round_trip_ns if report.round_trip_ns is not None else empty) / 1000.0
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
    if rt.size:
        fig, ax = plt.subplots(figsize=(7, 4))
        at = report.round_trip_at_ns
        x = (at - at[0]) / 1e9 if at is not None and at.size == rt.size else np.arange(rt.size)
        ax.plot(x, rt, ".", markersize=2)
        ax.set_xlabel("time (s)" if at is not None else "pair")
        ax.set_ylabel("round trip (µs)")
        ax.set_title(f"{stem}: round trip over time{rt_note}", fontsize=10)
        written.append(_save(fig, out / f"{stem}-round-trip.png"))
        fig, ax = plt.subplots(figsize=(7, 4))
        s = np.sort(rt)
        ax.plot(s, np.arange(1, s.size + 1) / s.size)
        ax.set_xlabel("round trip (µs)")
        ax.set_ylabel("fraction of pairs")
        ax.set_title(f"{stem}: round-trip CDF{rt_note}", fontsize=10)
        ax.grid(True, alpha=0.3)
        written.append(_save(fig, out / f"{stem}-round-trip-cdf.png"))
    return written


def plot_folder(folder: str | Path) -> Path:
    """``folder``, created if missing; :class:`UsageError` (exit 2) when it is a file or
    cannot be created. Call it before the analysis so a bad folder fails first."""
    out = Path(folder)
    if out.exists() and not out.is_dir():
        raise UsageError(f"--plot {out}: is a file, not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
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
