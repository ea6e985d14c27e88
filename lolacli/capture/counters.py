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
from pathlib import Path
from typing import Any

from lolacli.capture.reader import CaptureReader
from lolacli.eni.model import Eni
from lolacli.errors import WireError
from lolacli.wire.commands import Command
from lolacli.wire.error_counters import (
    ERROR_COUNTERS_BYTES,
    ErrorCounters,
    PortRise,
    SuspectLink,
    decode_error_counters,
    frame_path,
    locate,
    rises,
)
from lolacli.wire.frame import decode_frame
from lolacli.wire.registers import Register

#: a datagram header's ADO 0x0300 and length 20 (the M flag may follow), as bytes
_MARK = int(Register.RX_ERROR_COUNTER).to_bytes(2, "little") + bytes([ERROR_COUNTERS_BYTES])


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


def error_counter_reads(
    path: str | Path, *, eni: Eni | None = None, should_stop: Callable[[], bool] | None = None
) -> CounterReads | None:
    """The error counter reads of the capture at ``path`` (module docstring); ``None``
    when it has none answered."""
    if not _mentions(Path(path), _MARK):
        return None  # the common case, at the speed of reading the file
    requests: dict[tuple[int, int], int] = {}  # (frame index, datagram) -> address
    seen: dict[tuple[str, int], list[ErrorCounters]] = {}
    reads = 0
    for n, frame in enumerate(CaptureReader(path)):
        if should_stop is not None and n % 4096 == 0 and should_stop():
            break
        if _MARK not in frame.data:
            continue
        try:
            datagrams = decode_frame(frame.data).datagrams
        except WireError:
            continue
        for i, d in enumerate(datagrams):
            if (d.cmd not in (Command.APRD, Command.FPRD) or d.ado != Register.RX_ERROR_COUNTER
                    or len(d.data) != ERROR_COUNTERS_BYTES):  # fmt: skip
                continue
            key = (d.index, i)
            if d.wkc == 0:
                requests[key] = d.adp  # the request: APRD's address before the slaves add to it
                continue
            address = requests.pop(key, None)
            if d.wkc != 1 or address is None:
                continue
            kind = "aprd" if d.cmd == Command.APRD else "fprd"
            seen.setdefault((kind, address), []).append(decode_error_counters(d.data))
            reads += 1
    if not seen:
        return None
    positions, source = _positions(seen, eni)
    first = {positions[k]: v[0] for k, v in seen.items() if k in positions}
    last = {positions[k]: v[-1] for k, v in seen.items() if k in positions}
    ports = tuple(r for p in sorted(last) for r in rises(p, first[p], last[p]))
    n = max(last)
    suspect = locate(ports, frame_path(list(range(n))))
    return CounterReads(reads, first, last, ports, suspect, source)


def _positions(
    seen: dict[tuple[str, int], list[ErrorCounters]], eni: Eni | None
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


def _mentions(path: Path, mark: bytes, chunk_bytes: int = 1 << 20) -> bool:
    """Whether the file's bytes contain ``mark`` anywhere (a quick test before decoding
    every frame)."""
    tail = b""
    with path.open("rb") as f:
        while block := f.read(chunk_bytes):
            if mark in tail + block[: len(mark)] or mark in block:
                return True
            tail = block[-len(mark) + 1 :]
    return False
