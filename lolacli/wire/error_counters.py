"""The ESC error counters (0x0300-0x0313) and the link where errors enter the line.

Counters (ETG.1000.4 Table 40; ET1100 datasheet section II, 0x0300-0x0313), one byte each,
saturating at 255, cleared by a write:

* 0x0300 + 2p invalid frame counter of port p (a frame received with a bad FCS),
  0x0301 + 2p RX error counter (the PHY's symbol errors): together the port's RX errors;
* 0x0308 + p forwarded RX error counter: a frame that arrived already marked as damaged
  by an ESC upstream (it saw the error first, and marked the frame);
* 0x030C ECAT processing unit error, 0x030D PDI error;
* 0x0310 + p lost link counter.

Where errors enter: a frame damaged on a cable is counted as an RX error by the first
port that receives it after the damage; every ESC after that counts it as forwarded.
So along the frame's path (into each slave's port 0 on the way out, then back in through
the ports its branches hang off) the first port whose RX errors rise is at the bad link,
and its upstream neighbour is the other end (:func:`locate`). A bare rising lost link
counter (no RX errors) names a link that went down and up again.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from lolacli.text import plural

#: bytes read from 0x0300 for all counters
ERROR_COUNTERS_BYTES = 20
#: a counter stops at this value
COUNTER_MAX = 0xFF


@dataclass(frozen=True, slots=True)
class ErrorCounters:
    """Registers 0x0300-0x0313 (ETG.1000.4 Table 40; ET1100 datasheet)."""

    invalid_frame: tuple[int, int, int, int]  # 0x0300 + 2p
    rx_error: tuple[int, int, int, int]  # 0x0301 + 2p
    forwarded_rx_error: tuple[int, int, int, int]  # 0x0308 + p
    processing_unit_error: int  # 0x030C
    pdi_error: int  # 0x030D
    lost_link: tuple[int, int, int, int]  # 0x0310 + p

    @property
    def total(self) -> int:
        return (
            sum(self.invalid_frame)
            + sum(self.rx_error)
            + sum(self.forwarded_rx_error)
            + self.processing_unit_error
            + self.pdi_error
            + sum(self.lost_link)
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "invalid_frame": list(self.invalid_frame),
            "rx_error": list(self.rx_error),
            "forwarded_rx_error": list(self.forwarded_rx_error),
            "processing_unit_error": self.processing_unit_error,
            "pdi_error": self.pdi_error,
            "lost_link": list(self.lost_link),
        }


def decode_error_counters(raw: bytes) -> ErrorCounters:
    """The 20 bytes read from 0x0300."""
    if len(raw) < ERROR_COUNTERS_BYTES:
        raise ValueError("error counters: 20 bytes from 0x0300 expected")
    return ErrorCounters(
        (raw[0], raw[2], raw[4], raw[6]),
        (raw[1], raw[3], raw[5], raw[7]),
        (raw[8], raw[9], raw[10], raw[11]),
        raw[12],
        raw[13],
        (raw[16], raw[17], raw[18], raw[19]),
    )


def _rise(before: int, after: int) -> int:
    """How much a counter rose; one that went down was cleared meanwhile (all it shows
    now rose since)."""
    return after - before if after >= before else after


@dataclass(frozen=True, slots=True)
class PortRise:
    """How much one port's counters rose over an interval (1-based ``position``)."""

    position: int
    port: int
    invalid_frames: int
    phy_errors: int
    forwarded_rx_errors: int
    lost_links: int
    saturated: bool = False  # a counter stood at 255: the rise may be more

    @property
    def rx_errors(self) -> int:
        return self.invalid_frames + self.phy_errors

    @property
    def any(self) -> bool:
        return bool(self.rx_errors or self.forwarded_rx_errors or self.lost_links)

    def to_dict(self) -> dict[str, Any]:
        return {
            "position": self.position,
            "port": self.port,
            "rx_errors": self.rx_errors,
            "invalid_frames": self.invalid_frames,
            "phy_rx_errors": self.phy_errors,
            "forwarded_rx_errors": self.forwarded_rx_errors,
            "lost_links": self.lost_links,
            "saturated": self.saturated,
        }


def rises(position: int, before: ErrorCounters, after: ErrorCounters) -> list[PortRise]:
    """The four ports' rises of one slave."""
    out = []
    for p in range(4):
        values = (after.invalid_frame[p], after.rx_error[p], after.forwarded_rx_error[p],
                  after.lost_link[p])  # fmt: skip
        out.append(
            PortRise(
                position,
                p,
                _rise(before.invalid_frame[p], after.invalid_frame[p]),
                _rise(before.rx_error[p], after.rx_error[p]),
                _rise(before.forwarded_rx_error[p], after.forwarded_rx_error[p]),
                _rise(before.lost_link[p], after.lost_link[p]),
                COUNTER_MAX in values,
            )
        )
    return out


@dataclass(frozen=True, slots=True)
class Hop:
    """A port on the frame's path: the frame enters slave ``position`` at ``port`` over
    the cable from ``neighbour`` (0: the master)."""

    position: int
    port: int
    neighbour: int


#: the order in which an ESC passes a frame on through its ports (ETG.1000.4: 0, 3, 1, 2)
PORT_ORDER = (3, 1, 2)


def frame_path(
    parents: Sequence[int], open_ports: Sequence[Sequence[int]] | None = None
) -> list[Hop]:
    """The hops of a frame in order. ``parents[i]`` is the position slave ``i + 1`` hangs
    off (0: the master); ``open_ports[i]`` the ports other than 0 through which its
    branches leave, in the ESC's order (default: a line, port 1 for all but the last).
    A slave's children take its open ports in that order."""
    n = len(parents)
    children: dict[int, list[int]] = {}
    for i, parent in enumerate(parents):
        children.setdefault(parent, []).append(i + 1)
    path: list[Hop] = []

    def visit(position: int, neighbour: int) -> None:
        path.append(Hop(position, 0, neighbour))
        kids = children.get(position, [])
        if open_ports is not None:
            ports = [p for p in PORT_ORDER if p in open_ports[position - 1]]
        else:
            ports = [1] * len(kids)
        for port, child in zip(ports, kids, strict=False):
            visit(child, position)
            path.append(Hop(position, port, child))

    stack = children.get(0, [])
    for first in stack:  # normally one: the line's first slave
        visit(first, 0)
    return path if n else []


@dataclass(frozen=True, slots=True)
class SuspectLink:
    """The cable where errors enter: between ``upstream`` and ``downstream`` (positions;
    0 = the master), received at ``downstream``'s (or, on the way back, ``upstream``'s)
    ``port``; ``at`` is the slave whose port saw the errors first."""

    upstream: int
    downstream: int
    at: int
    port: int
    cause: str  # "rx_errors" or "lost_links"
    evidence: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        return {
            "upstream": self.upstream,
            "downstream": self.downstream,
            "at": self.at,
            "port": self.port,
            "cause": self.cause,
            "evidence": list(self.evidence),
        }


def locate(port_rises: Sequence[PortRise], path: Sequence[Hop]) -> SuspectLink | None:
    """The link where errors enter (module docstring), with the counts that show it;
    ``None`` when no RX error and no lost link counter rose."""
    by_port = {(r.position, r.port): r for r in port_rises}
    for cause in ("rx_errors", "lost_links"):
        for hop in path:
            r = by_port.get((hop.position, hop.port))
            if r is None or not getattr(r, cause):
                continue
            link = _link(hop)
            return SuspectLink(*link, hop.position, hop.port, cause,
                               _evidence(r, cause, port_rises))  # fmt: skip
    return None


def _link(hop: Hop) -> tuple[int, int]:
    """(upstream, downstream) of the cable into ``hop``."""
    if hop.port == 0:
        return hop.neighbour, hop.position
    return hop.position, hop.neighbour


def _evidence(first: PortRise, cause: str, port_rises: Sequence[PortRise]) -> tuple[str, ...]:
    where = f"slave {first.position} port {first.port}"
    if cause == "lost_links":
        lines = [f"{where}: lost link counter +{first.lost_links}, no RX errors anywhere"]
    else:
        lines = [
            f"{where}: RX errors +{first.rx_errors} (invalid frame +{first.invalid_frames}, "
            f"PHY +{first.phy_errors}), the first on the frame's path"
        ]
        forwarded = [r for r in port_rises if r.forwarded_rx_errors]
        if forwarded:
            positions = sorted({r.position for r in forwarded})
            lines.append(
                f"forwarded RX errors at {plural(len(positions), 'slave')} "
                f"({_span(positions)}): frames already damaged when they got there"
            )
        later = [r for r in port_rises if r.rx_errors and r is not first]
        if later:
            lines.append(
                "RX errors further on: "
                + ", ".join(f"slave {r.position} port {r.port} +{r.rx_errors}" for r in later)
            )
    if first.saturated:
        lines.append(f"{where}: a counter stands at 255 (saturated): the rise may be more")
    return tuple(lines)


def _span(positions: Sequence[int]) -> str:
    """``3-7, 9`` for sorted positions."""
    parts: list[str] = []
    start = prev = positions[0]
    for p in [*positions[1:], None]:
        if p is not None and p == prev + 1:
            prev = p
            continue
        parts.append(f"{start}" if start == prev else f"{start}-{prev}")
        if p is not None:
            start = prev = p
    return ", ".join(parts)
