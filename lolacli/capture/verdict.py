"""Findings: what a capture says about the bus, each with its frame numbers (pure).

Definitions in docs/architecture.md, "Lost, late, in flight": an outgoing frame no return
matches at all is lost, unless it was sent within the capture's last ``timeout`` (in
flight at the end); a return later than the timeout is late. The timeout defaults to
10 x the median round trip, at least 1 ms. "Timestamp quality": round trips of 0
(quantised timestamps), timestamps going backwards and cut-short files are findings, and
the statistics built on them are marked unusable.

Findings are the product's one model (:mod:`lolacli.findings`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from lolacli.findings import Findings, Severity
from lolacli.text import number, plural

FAILURE = Severity.FAILURE
WARNING = Severity.WARNING
INFO = Severity.INFO
MIN_TIMEOUT_NS = 1_000_000
TIMEOUT_ROUND_TRIPS = 10


def timeout_ns(median_round_trip_ns: float | None, given_ns: int | None) -> tuple[int, str]:
    """The in-flight timeout and where it came from."""
    if given_ns is not None:
        return given_ns, "--timeout"
    scaled = None if median_round_trip_ns is None else median_round_trip_ns * TIMEOUT_ROUND_TRIPS
    if scaled is not None and scaled > MIN_TIMEOUT_NS:
        return round(scaled), "10 x the median round trip"
    return MIN_TIMEOUT_NS, "the 1 ms minimum"


@dataclass(slots=True)
class FrameFate:
    """Lost, late and in-flight outgoing frames."""

    timeout_ns: int
    timeout_source: str
    lost: Any  # outgoing frame numbers, sorted (a numpy array, or a list)
    in_flight: Any
    late: int
    late_frames: tuple[int, ...]
    lost_cyclic: int = 0


def fates(
    pending_frames: Any, pending_ts: Any, pending_cyclic: Any,
    end_ts: int, timeout: tuple[int, str], late_count: int, late_frames: tuple[int, ...],
) -> FrameFate:
    """Lost and in-flight frames among the unanswered ones: numpy arrays in and out, or
    lists (a small capture, without numpy; the same frames)."""
    t, source = timeout
    if isinstance(pending_frames, list):
        order = sorted(range(len(pending_frames)), key=pending_frames.__getitem__)
        lost: list[int] = []
        flying_frames: list[int] = []
        lost_cyclic = 0
        for i in order:
            if pending_ts[i] > end_ts - t:
                flying_frames.append(pending_frames[i])
            else:
                lost.append(pending_frames[i])
                lost_cyclic += bool(pending_cyclic[i])
        return FrameFate(t, source, lost, flying_frames, late_count, late_frames, lost_cyclic)
    import numpy as np

    in_air = pending_ts > end_ts - t
    by_frame = np.argsort(pending_frames, kind="stable")
    frames, in_air, cyc = pending_frames[by_frame], in_air[by_frame], pending_cyclic[by_frame]
    return FrameFate(t, source, frames[~in_air], frames[in_air], late_count, late_frames,
                     int(np.count_nonzero(cyc & ~in_air)))


def frame_findings(out: Findings, counts: dict[str, int], fate: FrameFate, max_lost: int,
                   direction_rule: str) -> None:
    """No EtherCAT, a bus that never answered, one-way captures, lost/late/in flight."""
    ecat, sent, back = counts["ecat_frames"], counts["outgoing_frames"], counts["returned_frames"]
    if ecat == 0:
        out.add("no-ethercat", FAILURE,
                f"no EtherCAT frame among {plural(counts['frames_total'], 'packet')}: wrong "
                "interface, or a capture filter that dropped them?")
        return
    if sent and not back:
        out.add("no-answer", FAILURE,
                f"the bus never answered: {plural(sent, 'frame')} sent, none came back (no "
                "slave connected or powered, cable, or a capture of the master's sending side "
                "only)",
                fate.lost if len(fate.lost) else fate.in_flight, sent)
    if back and not sent:
        out.add("direction-unknown", WARNING,
                f"all {plural(back, 'frame')} look returned and none echoes another: the "
                f"direction cannot be told ({direction_rule} rule); nothing is paired")
    lost = len(fate.lost)
    if lost:
        cyc = f", {fate.lost_cyclic} of them cyclic" if fate.lost_cyclic else ""
        out.add("lost", FAILURE if lost > max_lost else WARNING,
                f"{plural(lost, 'outgoing frame')} never came back{cyc} (threshold "
                f"{max_lost}; a frame can also be missing because the capture itself dropped "
                "it)",
                fate.lost, lost)
    if fate.late:
        out.add("late", WARNING,
                f"{plural(fate.late, 'frame')} came back later than the timeout "
                f"({number(fate.timeout_ns / 1000, 'µs', 2)}, {fate.timeout_source}); counted "
                "apart from lost frames", fate.late_frames, fate.late)
    if len(fate.in_flight):
        out.add("in-flight-at-end", INFO,
                f"{plural(len(fate.in_flight), 'frame')} sent within the last "
                f"{number(fate.timeout_ns / 1000, 'µs', 2)} of the capture had no answer yet "
                "(not lost)",
                fate.in_flight, len(fate.in_flight))


def timestamp_findings(
    out: Findings, rt_zero: int, rt_negative: int, rt_bad_frames: tuple[int, ...],
    pairs: int, backwards: int, backwards_frames: tuple[int, ...],
    periods_bad: int,
) -> list[str]:
    """Quantised and backward timestamps; returns the statistics they make unusable."""
    unusable: list[str] = []
    if rt_zero:
        out.add("timestamps-quantised", WARNING,
                f"{rt_zero} of {plural(pairs, 'round trip')} {'is' if rt_zero == 1 else 'are'}"
                " 0 µs: the capture's clock is coarser than a round trip; round-trip statistics"
                " are unusable", rt_bad_frames, rt_zero)
    if backwards:
        out.add("timestamps-backwards", WARNING,
                f"timestamps go backwards {plural(backwards, 'time')}; statistics that span "
                "those "
                "steps are unusable", backwards_frames, backwards)
    if rt_zero or rt_negative:
        unusable += ["round_trip_us", "round_trip_cyclic_us"]
    if periods_bad:
        unusable.append("cycle_period_us")
    return unusable
