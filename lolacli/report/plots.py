"""The report's figures: what each one shows (:func:`specs`, from the series the results
expose), drawn as inline SVG for the HTML page (:mod:`lolacli.report.svg`: no import
cost, see there for the measurement) or as PNG files by matplotlib for the Markdown
report (Agg backend, imported on call)."""

from __future__ import annotations

import io
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from lolacli.report.svg import Series

if TYPE_CHECKING:
    from lolacli.report.model import Report, Source

HIST_BINS = 80
DPI = 100


@dataclass(frozen=True, slots=True)
class Spec:
    section: str
    name: str  # file stem: rt-histogram, ...
    title: str
    xlabel: str
    ylabel: str = ""
    series: list[Series] = field(default_factory=list)
    vline: float | None = None
    bars: list[tuple[str, list[float]]] | None = None  # horizontal bars per name
    names: list[str] | None = None
    hline: float | None = None
    logx: bool = False


@dataclass(frozen=True, slots=True)
class Figure:
    section: str
    name: str
    title: str
    svg: str = ""
    png: bytes = b""


def specs(report: Report) -> list[Spec]:
    """The figures of ``report``'s sections, in page order."""
    import numpy as np

    present = {s.id for s in report.sections}
    out: list[Spec] = []
    rt = [s for s in report.sources if s.round_trip_us is not None and s.round_trip_us.size]
    if "bus" in present and rt:
        edges = _edges([s.round_trip_us for s in rt])
        out.append(Spec("bus", "rt-histogram", "Round trip: histogram", "round trip (µs)",
                        "frames", [Series(s.label, edges, _counts(s, edges), "bars") for s in rt]))
        cdf = []
        for s in rt:
            v = np.sort(s.round_trip_us)  # type: ignore[arg-type]
            cdf.append(Series(s.label, v, np.arange(1, v.size + 1) / v.size))
        out.append(Spec("bus", "rt-cdf", "Round trip: CDF", "round trip (µs)",
                        "fraction at or below", cdf))
        timed = all(s.round_trip_t_s is not None for s in rt)
        out.append(Spec("bus", "rt-time", "Round trip over time",
                        "time since the first return (s)" if timed else "frame",
                        "round trip (µs)", [_over_time(s, timed) for s in rt]))
    periods = [s for s in report.sources if s.period_us is not None and s.period_us.size]
    if "bus" in present and periods:
        edges = _edges([s.period_us for s in periods])
        out.append(Spec("bus", "cycle-period", "Cycle period: histogram", "cycle period (µs)",
                        "cycles", [Series(s.label, edges, np.histogram(s.period_us, edges)[0],
                                          "bars") for s in periods if s.period_us is not None]))
    dc = [s for s in report.sources if s.dc_error_ns is not None and s.dc_error_ns.size]
    if "dc" in present and dc:
        out.append(Spec("dc", "dc-error", "DC: largest |system time difference| per read",
                        "time from the start of the cyclic run (s); before 0: start-up",
                        "|error| (ns)", [Series(s.label, s.dc_t_s, s.dc_error_ns) for s in dc],
                        vline=0.0))
    software = report.section("software")
    if software is not None:
        sections = software.data["sections_us"]
        names = list(sections)
        out.append(Spec("software", "sections", "Software: time per section of a cycle",
                        "µs per cycle", names=names, bars=[
                            ("p99", [sections[n]["p99"] for n in names]),
                            ("mean", [sections[n]["mean"] for n in names])]))
    return out + _joint_specs(report, present)


def _joint_specs(report: Report, present: set[str]) -> list[Spec]:
    """The joints' figures: a simulation's following error over time, seed 000's Fig. 9
    (joint track's error over time) and Fig. 10 (joint bode's gain and phase)."""
    import numpy as np

    from lolacli.report.joints import drawn_joints

    out: list[Spec] = []
    sim = next((s for s in report.sources if s.kind == "simulation"), None)
    if "joints" in present and sim is not None and sim.following_error:
        drawn = drawn_joints(sim.following_error, sim.doc["moves"])
        more = len(sim.following_error) - len(drawn)
        out.append(Spec("joints", "following-error", "Following error over time" + (
            f" ({len(drawn)} joints with the largest RMS; {more} more in the table)"
            if more > 0 else ""), "time since the moves began (s)",
            "set-point - actual (increments)",
            [Series(j, *sim.following_error[j]) for j in drawn]))
    track = report.joint_track
    if "tracking" in present and track is not None and all(
            "error_series" in c for c in track.doc["cases"]):
        series = []
        for c in track.doc["cases"]:
            e = c["error_series"]
            y = np.asarray(e["error_rad"], dtype=np.float64) * 1e3
            series.append(Series(c["name"], np.arange(y.size) * e["sample_s"], y))
        if any(s.y.size for s in series):
            out.append(Spec("tracking", "tracking-error",
                            f"Tracking error over time: {track.doc['joint']} (seed 000 Fig. 9)",
                            "time after settling (s)", "θd − θ (mrad)",
                            [s for s in series if s.y.size]))
    bode = report.joint_bode
    points = [p for p in bode.doc["points"] if np.isfinite(p["gain_db"])] if bode else []
    if "bandwidth" in present and bode is not None and points:
        f = np.asarray([p["freq_hz"] for p in points])
        bw = bode.doc.get("bandwidth_hz")
        mark = (f"-3 dB bandwidth {bw:.1f} Hz, dashed" if bw is not None
                else "-3 dB not reached")
        out.append(Spec("bandwidth", "bode-gain", f"Closed-loop gain, target to joint angle "
                        f"({mark}; seed 000 Fig. 10)", "frequency (Hz)", "gain (dB)",
                        [Series("gain", f, np.asarray([p["gain_db"] for p in points]))],
                        vline=bw, hline=-3.0103, logx=True))
        out.append(Spec("bandwidth", "bode-phase", "Closed-loop phase, target to joint angle",
                        "frequency (Hz)", "phase (°)",
                        [Series("phase", f, np.asarray([p["phase_deg"] for p in points]))],
                        vline=bw, logx=True))
    return out


def _edges(arrays: list[Any]) -> Any:
    """Common histogram bin edges of ``arrays``; one value: one bar in the middle."""
    import numpy as np

    lo = min(float(a.min()) for a in arrays)
    hi = max(float(a.max()) for a in arrays)
    if hi <= lo:
        lo, hi = lo - 0.5, hi + 0.5
    return np.linspace(lo, hi, HIST_BINS + 1)


def _counts(s: Source, edges: Any) -> Any:
    import numpy as np

    assert s.round_trip_us is not None
    return np.histogram(s.round_trip_us, edges)[0]


def _over_time(s: Source, timed: bool) -> Series:
    import numpy as np

    y = s.round_trip_us
    assert y is not None
    x = s.round_trip_t_s if timed else np.arange(y.size, dtype=np.float64)
    return Series(s.label, x, y)


def svg_figures(report: Report) -> list[Figure]:
    from lolacli.report.svg import chart, hbars

    out = []
    for f in specs(report):
        if f.bars is not None:
            drawn = hbars(f.title, f.xlabel, f.names or [], f.bars)
        else:
            drawn = chart(f.title, f.xlabel, f.ylabel, f.series, f.vline, hline=f.hline,
                          logx=f.logx)
        out.append(Figure(f.section, f.name, f.title, svg=drawn))
    return out


def png_figures(report: Report) -> list[Figure]:
    todo = specs(report)
    if not todo:
        return []
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = []
    for f in todo:
        fig, ax = plt.subplots(figsize=(7.2, 3.2))
        try:
            _draw(ax, f)
            ax.set_title(f.title, fontsize=10)
            ax.grid(True, alpha=0.3)
            fig.tight_layout()
            buf = io.BytesIO()
            fig.savefig(buf, format="png", dpi=DPI)
        finally:
            plt.close(fig)
        out.append(Figure(f.section, f.name, f.title, png=buf.getvalue()))
    return out


def _draw(ax: Any, f: Spec) -> None:
    from lolacli.report.svg import thin

    if f.bars is not None:
        names = f.names or []
        for (label, values), colour in zip(f.bars, ("#c8d6e5", "#2e86de"), strict=False):
            ax.barh(names, values, color=colour, label=label)
        ax.invert_yaxis()
        ax.legend(fontsize=8)
    else:
        for s in f.series:
            if s.kind == "bars":
                ax.stairs(s.y, s.x, fill=True, alpha=0.55 if len(f.series) > 1 else 1.0,
                          label=s.label)
            else:
                ax.plot(*thin(s.x, s.y), lw=0.8, label=s.label)
        if f.vline is not None:
            ax.axvline(f.vline, color="grey", lw=0.8, ls="--")
        if f.hline is not None:
            ax.axhline(f.hline, color="grey", lw=0.8, ls="--")
        if f.logx:  # round values labelled as numbers (matplotlib's minor 3×10¹ overlap)
            from matplotlib.ticker import NullFormatter

            from lolacli.report.svg import fmt_tick, log_ticks

            ax.set_xscale("log")
            xs = [float(x) for s in f.series for x in s.x]
            at = log_ticks(min(xs), max(xs))
            ax.set_xticks(at, [fmt_tick(t) for t in at])
            ax.xaxis.set_minor_formatter(NullFormatter())
        if len(f.series) > 1:
            ax.legend(fontsize=8)
        ax.set_ylabel(f.ylabel)
    ax.set_xlabel(f.xlabel)
