"""``lolacli bus diag``: the error counters of every port over an interval, and the link
where errors enter the line (:mod:`lolacli.wire.error_counters`).

What it does on the bus, in order:

1. a scan (:func:`lolacli.master.scan.scan`, nothing configured): slaves, names and the
   topology (parents from the open ports);
2. with ``reset``, a broadcast write of zeros to 0x0300-0x0313 (a write clears the
   counters on an ESC);
3. every slave's counters (APRD 0x0300, 20 bytes);
4. for the interval, probe frames at ``probe_hz`` (a BRD of AL status 0x0130: each one
   passes every cable out and back, so a bad cable has frames to damage even on a bus
   nobody else drives); the ones that do not come back are counted lost;
5. the counters again. What rose, per port, and the first port on the frame's path whose
   RX errors rose name the link.

Frames lost on the way (a bad cable also damages the diagnosis's own reads) are sent
again, ``retries`` times.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from lolacli.errors import TransportError, UsageError
from lolacli.master.core import Master, MasterOptions
from lolacli.master.scan import ScannedSlave, ScanOptions, scan
from lolacli.master.transport import Transport
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
from lolacli.wire.frame import Datagram
from lolacli.wire.registers import Register

SCHEMA = "lolacli.diag/1"
#: the longest interval (a day): beyond it a typo more likely than a wish
MAX_INTERVAL_NS = 86_400 * 1_000_000_000


@dataclass(frozen=True, slots=True)
class DiagOptions:
    interval_ns: int = 10_000_000_000
    reset: bool = False
    probe_hz: float = 1000.0  # probe frames a second during the interval (0: none)
    timeout_ns: int = 20_000_000
    retries: int = 10


@dataclass(slots=True)
class DiagReport:
    iface: str
    interval_ns: int
    slaves: list[ScannedSlave]
    reset: bool
    ports: list[PortRise] = field(default_factory=list)
    suspect: SuspectLink | None = None
    probes_sent: int = 0
    probes_lost: int = 0
    other_errors: list[dict[str, int]] = field(default_factory=list)

    @property
    def errors(self) -> bool:
        return self.suspect is not None or bool(self.other_errors)

    def to_dict(self) -> dict[str, Any]:
        names = {s.position: s.name for s in self.slaves}
        return {
            "schema": SCHEMA,
            "iface": self.iface,
            "interval_s": self.interval_ns / 1e9,
            "reset": self.reset,
            "slaves": len(self.slaves),
            "names": {str(k): v for k, v in names.items()},
            "probe_frames": self.probes_sent,
            "probe_frames_lost": self.probes_lost,
            "ports": [p.to_dict() for p in self.ports],
            "other_errors": self.other_errors,
            "suspect_link": self.suspect.to_dict() if self.suspect else None,
            "errors": self.errors,
        }


def diagnose(
    transport: Transport,
    *,
    options: DiagOptions | None = None,
    iface: str = "",
    stopped: Callable[[], bool] | None = None,
) -> DiagReport:
    """Watch the counters of the bus behind ``transport`` (module docstring);
    TransportError when nothing answers. ``stopped`` ends the interval early."""
    opts = options or DiagOptions()
    if not 0 < opts.interval_ns <= MAX_INTERVAL_NS:
        raise UsageError("--interval: expected more than 0 s and at most a day")
    found = scan(
        transport,
        options=ScanOptions(timeout_ns=opts.timeout_ns, retries=opts.retries),
        iface=iface,
    )
    slaves = [s for s in found.slaves if s.answered]
    master = Master(
        _empty(), transport,
        options=MasterOptions(frame_timeout_ns=opts.timeout_ns, frame_retries=opts.retries),
    )  # fmt: skip
    if opts.reset:
        zeros = bytes(ERROR_COUNTERS_BYTES)
        master.exchange_one(Datagram.physical(Command.BWR, 0, Register.RX_ERROR_COUNTER, zeros))
    before = read_counters(master, slaves)
    t0 = transport.now_ns()
    sent, lost = _probe(master, transport, t0 + opts.interval_ns, opts.probe_hz, stopped)
    after = read_counters(master, slaves)
    report = DiagReport(iface, transport.now_ns() - t0, slaves, opts.reset,
                        probes_sent=sent, probes_lost=lost)  # fmt: skip
    for s in slaves:
        b, a = before[s.position], after[s.position]
        report.ports += [r for r in rises(s.position, b, a) if _shown(r, s)]
        pu = a.processing_unit_error - b.processing_unit_error
        pdi = a.pdi_error - b.pdi_error
        if pu > 0 or pdi > 0:
            report.other_errors.append(
                {"position": s.position, "processing_unit_errors": max(pu, 0),
                 "pdi_errors": max(pdi, 0)}  # fmt: skip
            )
    parents = [s.parent for s in slaves]
    open_ports = [[p.port for p in s.ports if p.open and p.port] for s in slaves]
    report.suspect = locate(report.ports, frame_path(parents, open_ports))
    return report


def _empty() -> Any:
    from lolacli.eni.model import Eni, ProcessImage
    from lolacli.eni.model import Master as EniMaster

    return Eni(EniMaster(), (), (), ProcessImage(0, 0), source="")


def _shown(r: PortRise, s: ScannedSlave) -> bool:
    """A port in the report: one that exists, or one whose counters rose."""
    return r.any or s.ports[r.port].physical != "not implemented"


def read_counters(master: Master, slaves: list[ScannedSlave]) -> dict[int, ErrorCounters]:
    """Every slave's counters by position (APRD 0x0300, 20 bytes)."""
    reads = [
        Datagram.physical(Command.APRD, s.auto_inc_address, Register.RX_ERROR_COUNTER,
                          ERROR_COUNTERS_BYTES)  # fmt: skip
        for s in slaves
    ]
    got = master.exchange_many(reads)
    out = {}
    for s, d in zip(slaves, got, strict=True):
        if d.wkc != 1:
            raise TransportError(f"slave {s.position} does not answer the error counter read")
        out[s.position] = decode_error_counters(d.data)
    return out


def _probe(
    master: Master,
    transport: Transport,
    until_ns: int,
    probe_hz: float,
    stopped: Callable[[], bool] | None,
) -> tuple[int, int]:
    """Probe frames until ``until_ns``: (sent, lost)."""
    sent = lost = 0
    if probe_hz <= 0:
        while transport.now_ns() < until_ns and not (stopped and stopped()):
            transport.wait_until(min(until_ns, transport.now_ns() + 100_000_000))
        return 0, 0
    period = round(1e9 / probe_hz)
    probe = Datagram.physical(Command.BRD, 0, Register.AL_STATUS, 2)
    t = transport.now_ns()
    check = time.monotonic_ns
    last_poll = check()
    while t < until_ns:
        try:
            sent += 1
            master.exchange([probe], retries=0)
        except TransportError:
            lost += 1
        t += period
        transport.wait_until(t)
        if stopped is not None and check() - last_poll > 50_000_000:
            last_poll = check()
            if stopped():
                break
    return sent, lost
