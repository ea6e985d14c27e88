"""What ``lolacli bus timing`` computes, from what it was given: the frame and the line of
slaves to time (an ENI, a capture's analysis, or the numbers themselves), the measured
round trip (given, or a capture's), the estimate of :func:`~lolacli.timing.model.estimate`
and its document (``bus timing --format json``). Pure: the caller reads the ENI and
analyses the capture (:attr:`TimingRequest.reads_eni`, :attr:`TimingRequest.reads_capture`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum
from typing import TYPE_CHECKING, Any

from lolacli.errors import InputError, UsageError
from lolacli.text import number as _number

if TYPE_CHECKING:
    from lolacli.eni.model import Eni


class Statistic(StrEnum):
    """The statistic of a capture's round trips taken as the measured total."""

    min = "min"
    median = "median"


@dataclass(frozen=True, slots=True)
class Line:
    """The frame and the line of slaves to time, and where each number came from."""

    frame_bytes: int
    frame_bytes_from: str
    slaves: int
    slaves_from: str
    cycle_ns: int | None
    source: str


@dataclass(frozen=True, slots=True)
class BusTiming:
    """The document of ``bus timing`` and the budget's verdict (None: no budget)."""

    doc: dict[str, Any]
    within_budget: bool | None


@dataclass(frozen=True, slots=True)
class TimingRequest:
    """``bus timing``'s inputs as given (``eni`` and ``capture`` as paths, ``measured`` as
    text such as ``124.1us``); UsageError when they contradict each other."""

    eni: str | None = None
    frame_bytes: int | None = None
    slaves: int | None = None
    link_mbit: float = 100.0
    cable_m: float = 1.0
    per_slave_ns: int | None = None
    host_latency_us: float = 0.0
    measured: str | None = None
    capture: str | None = None
    statistic: Statistic = Statistic.min
    budget_us: float | None = None

    def __post_init__(self) -> None:
        if self.eni is not None and (self.frame_bytes is not None or self.slaves is not None):
            raise UsageError("--eni and --frame-bytes/--slaves contradict each other; give one")
        if self.capture is None and (self.frame_bytes is None) != (self.slaves is None):
            raise UsageError("--frame-bytes and --slaves go together (or come from --capture)")
        if self.measured is not None and self.capture is not None:
            raise UsageError("--measured and --capture contradict each other; give one")

    @property
    def reads_eni(self) -> bool:
        """The frame and line come from an ENI: ``eni``, else the embedded LOLA chain."""
        return self.eni is not None or (self.capture is None and self.frame_bytes is None)

    @property
    def reads_capture(self) -> bool:
        return self.capture is not None

    def run(
        self,
        read_eni: Callable[[], Eni] | None = None,
        report: dict[str, Any] | None = None,
        warn: Callable[[str], None] = lambda _: None,
    ) -> BusTiming:
        """The timing, given the reader of the ENI (called when :attr:`reads_eni`, after
        the options are checked) and the capture's analysis (``CaptureReport.to_dict()``,
        when :attr:`reads_capture`); ``warn`` is told what the numbers cannot show (more
        than one cyclic frame, an implausible calibration)."""
        from lolacli.timing.model import estimate, parse_duration_ns

        measured_ns, measured_from = None, None
        if self.measured is not None:
            measured_ns, measured_from = parse_duration_ns(self.measured), "--measured"
        elif self.capture is not None:
            assert report is not None
            measured_ns, measured_from = capture_round_trip_ns(
                report, self.statistic, self.capture
            )
        line = self._line(read_eni, report, warn)
        budget_ns = (scaled("--budget-us", self.budget_us, 1000) if self.budget_us is not None
                     else line.cycle_ns)
        try:
            result = estimate(
                line.frame_bytes,
                line.slaves,
                link_bit_s=scaled("--link-mbit", self.link_mbit, 1_000_000),
                cable_m_per_segment=self.cable_m,
                per_slave_delay_ns=self.per_slave_ns,
                measured_total_ns=measured_ns,
                budget_ns=budget_ns,
                host_latency_ns=scaled("--host-latency-us", self.host_latency_us, 1000),
            )
        except UsageError as e:
            if self.capture is None or measured_ns is None:
                raise
            # the capture's own numbers do not fit a round trip (a veth has no wire time)
            raise InputError(f"{e}; from {measured_from}", path=self.capture) from None
        caution = calibration_warning(result)
        if caution:
            warn(caution)
        doc = result.to_dict() | {
            "source": line.source,
            "measured_from": measured_from,
            "sources": {"frame_bytes": line.frame_bytes_from, "slaves": line.slaves_from,
                        "measured": measured_from},
            "calibration_warning": caution,
        }
        return BusTiming(doc, result.within_budget)

    def _line(
        self,
        read_eni: Callable[[], Eni] | None,
        report: dict[str, Any] | None,
        warn: Callable[[str], None],
    ) -> Line:
        if self.reads_eni:
            assert read_eni is not None
            source = self.eni if self.eni is not None else "embedded LOLA chain"
            return line_from_eni(read_eni(), source, warn)
        if self.capture is None:
            assert self.frame_bytes is not None and self.slaves is not None
            return Line(self.frame_bytes, "--frame-bytes", self.slaves, "--slaves", None,
                        "options")
        assert report is not None
        return line_from_report(report, self.frame_bytes, self.slaves, self.capture)


def line_from_eni(model: Eni, source: str, warn: Callable[[str], None]) -> Line:
    """The ENI's first cyclic frame and its slaves; ``source`` names the ENI."""
    frames = model.cyclic_frames
    if not frames:
        raise InputError("the ENI has no cyclic frame to time", path=model.source)
    if len(frames) > 1:
        warn(f"{model.source}: {len(frames)} cyclic frames; timing the first one")
    return Line(frames[0].frame_bytes, f"{source}: first cyclic frame", len(model.slaves),
                f"{source}: slaves", model.cycle_time_ns, source)


def line_from_report(
    report: dict[str, Any], frame_bytes: int | None, slaves: int | None, capture: str
) -> Line:
    """The capture's longest cyclic frame and its slave count (a BRD's working counter),
    where ``frame_bytes`` or ``slaves`` do not say otherwise."""
    seen = report["bus_seen"]
    if frame_bytes is None:
        if seen["cyclic_frame_bytes"] is None:
            raise UsageError(f"{capture}: no cyclic frame to time; give --frame-bytes or --eni")
        frame_bytes = seen["cyclic_frame_bytes"]
        bytes_from = f"capture: its longest cyclic frame ({report['cyclic_stream']} stream)"
    else:
        bytes_from = "--frame-bytes"
    if slaves is None:
        if seen["slaves"] is None:
            raise UsageError(f"{capture}: no BRD/BWR came back to count the slaves; give "
                             "--slaves or --eni")
        slaves, slaves_from = seen["slaves"], f"capture: {seen['slaves_from']}"
    else:
        slaves_from = "--slaves"
    return Line(frame_bytes, bytes_from, slaves, slaves_from, None, "capture")


def capture_round_trip_ns(
    report: dict[str, Any], statistic: Statistic, path: str
) -> tuple[int, str]:
    """The chosen statistic of the capture's cyclic round trips (else of all pairs), ns,
    and where it came from."""
    for key, what in (("round_trip_cyclic_us", "cyclic round trips"),
                      ("round_trip_us", "round trips of all pairs")):
        stats = report.get(key)
        if not stats:
            continue
        if key in report["unusable_stats"] or float(stats[statistic.value]) <= 0:
            zero = [f for f in report["findings"] if f["kind"] == "timestamps-quantised"]
            why = zero[0]["message"] if zero else "they are not positive"
            raise InputError(f"round trips of 0 µs cannot measure one: {why}", path=path)
        value = round(float(stats[statistic.value]) * 1000)
        label = "minimum" if statistic is Statistic.min else "median"
        return value, f"capture: {label} of {stats['count']} {what}"
    raise InputError("no outgoing/returned frame pairs to measure a round trip", path=path)


def scaled(option: str, value: float, scale: int) -> int:
    """round(value × scale); a usage error when that is not a finite number (typer lets
    'inf' and '1e999' through its range checks)."""
    if not math.isfinite(value * scale):
        raise UsageError(f"{option} {value:g}: out of range")
    return round(value * scale)


def calibration_warning(result: Any) -> str | None:
    """What to say when the calibrated per-slave delay lies outside what ESCs do."""
    if result.calibration_plausible is not False:
        return None
    lo, hi = (v / 1000 for v in result.to_dict()["esc_delay_range_ns"])
    delay = _number(result.calibrated_per_slave_delay_ns, "ns", 0)
    return (f"the calibrated per-slave delay ({delay}) is "
            f"outside what ESCs do ({lo:g}-{hi:g} µs): the measured round trip holds more than "
            "the slaves (the master's stack and NIC, a switch; see --host-latency-us), or the "
            "slave count is off")
