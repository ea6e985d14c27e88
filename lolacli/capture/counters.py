"""The error counters a capture shows, and the link where errors enter the line.

What a capture can show of a bad cable: the frames it damaged are lost to the master (its
NIC drops their bad FCS), so they are lost frames — but a lost frame does not say where
on the line it was hit. The ESCs' error counters do: where a master reads them (``bus
diag``, ``bus scan``, TwinCAT's and other masters' diagnosis), the captured answers of
APRD/FPRD reads of 0x0300 (20 bytes) carry every slave's counters over time. The first
and the last read of each slave give the rise, and
:func:`lolacli.wire.error_counters.locate` the link, as ``bus diag`` names it.

A capture does not show the ports, so the line is taken as a line (port 0 out, port 1
back) in position order; positions come from the APRD's address in the request, or for
FPRD from the ENI's station addresses (without an ENI: stations in ascending order).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from lolacli.wire.commands import Command

if TYPE_CHECKING:
    from lolacli.eni.model import Eni
    from lolacli.wire.error_counters import ErrorCounters, Hop, PortRise, SuspectLink

# lolacli.wire.error_counters (~3 ms of dataclasses) is imported by the first answered
# read: most captures have none.


@dataclass(frozen=True, slots=True)
class CounterReads:
    """The counters a capture carries and what they say."""

    reads: int
    first: dict[int, ErrorCounters]  # by position
    last: dict[int, ErrorCounters]
    ports: tuple[PortRise, ...]
    suspect: SuspectLink | None
    positions_from: str  # "aprd", "eni", "station order"

    def to_dict(self) -> dict[str, Any]:
        return {
            "reads": self.reads,
            "slaves": len(self.last),
            "topology": "line (assumed: a capture does not show the ports)",
            "positions_from": self.positions_from,
            "ports": [p.to_dict() for p in self.ports if p.any],
            "suspect_link": self.suspect.to_dict() if self.suspect else None,
        }


class CounterTracker:
    """The error counter reads of one scan (module docstring), fed in file order with the
    datagrams the scanner flags (:func:`lolacli.capture.scan._counter_read`): no second
    pass over the file. A datagram with WKC 0 is a request (APRD's address before the
    slaves add to it); the next one with its (index, place in the frame) and WKC 1 is its
    answer. Bounded: a pending request per (index, place), the first and the last
    answer's 20 bytes per address."""

    def __init__(self) -> None:
        self.reads = 0
        self._requests: dict[tuple[int, int], int] = {}  # (index, datagram) -> address
        self._first: dict[tuple[str, int], bytes] = {}
        self._last: dict[tuple[str, int], bytes] = {}

    def feed(self, cmd: int, adp: int, index: int, place: int, wkc: int,
             data: Callable[[], bytes]) -> None:
        """One flagged datagram; ``data()`` gives its 20 bytes (read only for answers)."""
        key = (index, place)
        if wkc == 0:
            self._requests[key] = adp
            return
        address = self._requests.pop(key, None)
        if wkc != 1 or address is None:
            return
        from lolacli.wire.error_counters import ERROR_COUNTERS_BYTES

        at = ("aprd" if cmd == Command.APRD else "fprd", address)
        raw = data()
        if len(raw) != ERROR_COUNTERS_BYTES:
            return  # a mapped file that shrank under the scan (that pass is read again)
        self._first.setdefault(at, raw)
        self._last[at] = raw
        self.reads += 1

    def result(self, eni: Eni | None = None) -> CounterReads | None:
        """What the reads say; ``None`` when the capture has no answered read."""
        if not self._last:
            return None
        from lolacli.wire.error_counters import decode_error_counters, locate, rises

        positions, source = _positions(list(self._last), eni)
        first = {positions[k]: decode_error_counters(v) for k, v in self._first.items()
                 if k in positions}
        last = {positions[k]: decode_error_counters(v) for k, v in self._last.items()
                if k in positions}
        if not last:
            return None  # FPRDs of stations the ENI does not have: no position
        ports = tuple(r for p in sorted(last) for r in rises(p, first[p], last[p]))
        suspect = locate(ports, line_path(max(last)))
        return CounterReads(self.reads, first, last, ports, suspect, source)


def _positions(
    seen: list[tuple[str, int]], eni: Eni | None
) -> tuple[dict[tuple[str, int], int], str]:
    """1-based positions of the addresses read."""
    aprd = {k: ((-k[1]) & 0xFFFF) + 1 for k in seen if k[0] == "aprd"}
    stations = sorted(k[1] for k in seen if k[0] == "fprd")
    if not stations:
        return aprd, "aprd"
    if eni is not None:
        by_station = {s.station_address: p for p, s in enumerate(eni.slaves, start=1)}
        fprd = {("fprd", s): by_station[s] for s in stations if s in by_station}
        return {**aprd, **fprd}, "eni"
    return {**aprd, **{("fprd", s): i for i, s in enumerate(stations, start=1)}}, \
        "station order"


def line_path(n: int) -> list[Hop]:
    """The hops of a frame through a line of ``n`` slaves: what
    :func:`lolacli.wire.error_counters.frame_path` gives for ``list(range(n))``, without
    its recursion (a damaged capture may read the counters of position 40,000)."""
    from lolacli.wire.error_counters import Hop

    out = [Hop(p, 0, p - 1) for p in range(1, n + 1)]
    return out + [Hop(p, 1, p + 1) for p in range(n - 1, 0, -1)]
