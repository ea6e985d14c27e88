"""``lolacli bus scan``: a live bus as our master sees it, and how it differs from an ENI.

What a scan reads, for every slave the broadcast read of register 0x0000 counts (its
working counter is the number of slaves on the line):

* ESC registers by auto-increment address (APRD, position ``k`` at ADP ``-(k-1)``):
  type/revision/build, FMMUs/SMs, port descriptor and features (0x0000-0x0009), station
  address and alias (0x0010), DL status (0x0110: link, loop and communication per port),
  AL status and AL status code (0x0130/0x0134), the error counters 0x0300-0x0313;
* the SII EEPROM (identity, mailbox protocols, STRINGS and GENERAL categories for the
  name), read through 0x0502-0x050F for all slaves at once (:mod:`lolacli.master.eeprom`):
  one frame writes every slave's read command, one frame reads every slave's status and
  data back.

Nothing is configured: no station address is written, no state is requested, no counter
is cleared, because a scan is a diagnosis of a bus someone else may have brought up (a
station address written under a running configuration would cut its FPxx traffic). The
only writes are the EEPROM read commands; a slave whose EEPROM its PDI holds is taken
over as every master does (0x0500) and handed back afterwards.

Some faults show only when a master asks for more than INIT: a slave that refuses OP is
in INIT like every other one after power-up. ``state`` (with an ENI) first brings the bus
up with the ENI's InitCmds as :class:`~lolacli.master.core.Master` does — this does
configure the bus — and then scans: refusals and AL status codes are then what the scan
shows. The bus is left in that state (OP decays to SAFEOP with 0x001B, the process-data
watchdog, once nobody sends cyclic frames).

With an ENI, :func:`compare_with_eni` lists every difference by position: missing, extra
or wrong slaves (vendor/product), wrong revisions, unreadable identities, where the line
ends early, states not reached. The report is ``lolacli.scan/1`` (docs/cli.md).
"""

from __future__ import annotations

import struct
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from lolacli.eni.model import Eni, Identity, Slave
from lolacli.eni.model import Master as EniMaster
from lolacli.eni.model import ProcessImage as EniProcessImage
from lolacli.errors import TransportError, UsageError
from lolacli.master import eeprom
from lolacli.master.core import Master, MasterOptions, Refusal
from lolacli.master.transport import Transport
from lolacli.text import transition_text
from lolacli.wire.commands import Command
from lolacli.wire.error_counters import ErrorCounters, decode_error_counters
from lolacli.wire.frame import Datagram
from lolacli.wire.registers import (
    AL_ERROR_INDICATOR,
    AlState,
    Register,
    al_state_name,
    al_status_text,
)
from lolacli.wire.sii import (
    SiiInfo,
    protocol_names,
)

SCHEMA = "lolacli.scan/1"
_U16 = struct.Struct("<H")

# DL status 0x0110 (ETG.1000.4 Table 32)
DL_PDI_OPERATIONAL = 0x0001
PORT_PHYSICAL = {0: "not implemented", 1: "not configured", 2: "EBUS", 3: "MII"}


@dataclass(frozen=True, slots=True)
class ScanOptions:
    timeout_ns: int = 20_000_000  # one frame's answer (generous: hosts and veth are slow)
    retries: int = 3  # lost frames are sent again this often
    read_sii: bool = True
    state: AlState | None = None  # bring the bus up to this state first (needs an ENI)


@dataclass(frozen=True, slots=True)
class Port:
    """One port of a slave as DL status 0x0110 and the port descriptor 0x0007 show it."""

    port: int
    physical: str  # "MII", "EBUS", "not implemented", "not configured"
    link: bool
    loop_closed: bool
    communication: bool

    @property
    def open(self) -> bool:
        """A frame leaves through this port and comes back (loop open, communication)."""
        return self.communication and not self.loop_closed

    def to_dict(self) -> dict[str, Any]:
        return {
            "port": self.port,
            "physical": self.physical,
            "link": self.link,
            "loop_closed": self.loop_closed,
            "communication": self.communication,
            "open": self.open,
        }


def decode_ports(dl_status: int, port_descriptor: int) -> tuple[Port, ...]:
    """The four ports of DL status (link: bit 4+p; loop closed: bit 8+2p; communication:
    bit 9+2p) and the port descriptor (2 bits per port)."""
    return tuple(
        Port(
            p,
            PORT_PHYSICAL[(port_descriptor >> (2 * p)) & 0x3],
            bool(dl_status >> (4 + p) & 1),
            bool(dl_status >> (8 + 2 * p) & 1),
            bool(dl_status >> (9 + 2 * p) & 1),
        )
        for p in range(4)
    )


@dataclass(slots=True)
class ScannedSlave:
    """One slave as the scan found it (1-based ``position`` in line order)."""

    position: int
    answered: bool = True
    station_address: int = 0
    station_alias: int = 0
    esc_type: int = 0
    esc_revision: int = 0
    esc_build: int = 0
    fmmus: int = 0
    sync_managers: int = 0
    ram_kib: int = 0
    port_descriptor: int = 0
    features: int = 0
    dl_status: int = 0
    al_status: int = 0
    al_status_code: int = 0
    counters: ErrorCounters | None = None
    eeprom_control: int = 0
    eeprom_config: int = 0
    sii: SiiInfo | None = None  # what its SII says, as far as it was read
    sii_error: str | None = None
    parent: int = 0  # position of the slave it hangs off (0: the master)

    @property
    def auto_inc_address(self) -> int:
        return (-(self.position - 1)) & 0xFFFF

    @property
    def ports(self) -> tuple[Port, ...]:
        return decode_ports(self.dl_status, self.port_descriptor)

    @property
    def al_state(self) -> str:
        return al_state_name(self.al_status)

    @property
    def al_error(self) -> bool:
        return bool(self.al_status & AL_ERROR_INDICATOR)

    @property
    def identity(self) -> Identity | None:
        """The identity its SII header gives (None: not read)."""
        if self.sii is None:
            return None
        h = self.sii.header
        return Identity(h.vendor_id, h.product_code, h.revision, h.serial)

    @property
    def name(self) -> str | None:
        return self.sii.name if self.sii is not None else None

    def label(self) -> str:
        return f"slave {self.position}" + (f" ({self.name})" if self.name else "")

    def to_dict(self) -> dict[str, Any]:
        ident = self.identity
        counters = self.counters
        protocols = self.sii.header.mailbox_protocols if self.sii is not None else 0
        return {
            "position": self.position,
            "auto_inc_address": self.auto_inc_address,
            "answered": self.answered,
            "station_address": self.station_address,
            "station_alias": self.station_alias,
            "name": self.name,
            "order": self.sii.order if self.sii is not None else None,
            "vendor_id": ident.vendor_id if ident else None,
            "product_code": ident.product_code if ident else None,
            "revision": ident.revision if ident else None,
            "serial": ident.serial if ident else None,
            "identity_source": "sii" if ident else None,
            "sii_error": self.sii_error,
            "mailbox_protocols": list(protocol_names(protocols)),
            "al_state": self.al_state,
            "al_error": self.al_error,
            "al_status_code": f"0x{self.al_status_code:04X}",
            "al_status_text": al_status_text(self.al_status_code),
            "dl_status": f"0x{self.dl_status:04X}",
            "pdi_operational": bool(self.dl_status & DL_PDI_OPERATIONAL),
            "ports": [p.to_dict() for p in self.ports],
            "parent_position": self.parent,
            "esc": {
                "type": f"0x{self.esc_type:02X}",
                "revision": self.esc_revision,
                "build": self.esc_build,
                "fmmus": self.fmmus,
                "sync_managers": self.sync_managers,
                "ram_kib": self.ram_kib,
                "features": f"0x{self.features:04X}",
            },
            "error_counters": counters.to_dict() if counters else None,
        }


@dataclass(frozen=True, slots=True)
class Difference:
    """One way the bus differs from the ENI (or from the requested state)."""

    kind: str  # missing_slave, extra_slave, wrong_slave, wrong_revision, ...
    position: int
    message: str
    expected: dict[str, Any] | None = None
    found: dict[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "position": self.position,
            "message": self.message,
            "expected": self.expected,
            "found": self.found,
        }


@dataclass(slots=True)
class ScanReport:
    iface: str
    slaves: list[ScannedSlave]
    slaves_counted: int
    eni: Eni | None = None
    state: AlState | None = None
    differences: list[Difference] = field(default_factory=list)
    findings: list[Difference] = field(default_factory=list)
    refusals: list[Refusal] = field(default_factory=list)
    frames_sent: int = 0
    frames_lost: int = 0
    duration_ns: int = 0

    @property
    def failed(self) -> bool:
        return bool(self.differences)

    def to_dict(self) -> dict[str, Any]:
        eni = self.eni
        return {
            "schema": SCHEMA,
            "iface": self.iface,
            "eni": eni.source if eni is not None else None,
            "requested_state": self.state.name if self.state is not None else None,
            "addressing": "auto-increment",
            "slaves_counted": self.slaves_counted,
            "slaves_expected": len(eni.slaves) if eni is not None else None,
            "matches_eni": (not self.differences) if eni is not None else None,
            "slaves": [s.to_dict() for s in self.slaves],
            "differences": [d.to_dict() for d in self.differences],
            "findings": [d.to_dict() for d in self.findings],
            "refusals": [r.to_dict() for r in self.refusals],
            "frames_sent": self.frames_sent,
            "frames_lost": self.frames_lost,
            "duration_ms": round(self.duration_ns / 1e6, 3),
        }


def _empty_eni() -> Eni:
    return Eni(EniMaster(), (), (), EniProcessImage(0, 0), source="")


def scan(
    transport: Transport,
    *,
    eni: Eni | None = None,
    options: ScanOptions | None = None,
    iface: str = "",
) -> ScanReport:
    """Scan the bus behind ``transport`` (see the module docstring); TransportError when
    nothing answers."""
    opts = options or ScanOptions()
    if opts.state is not None and eni is None:
        raise UsageError("bringing the bus to a state needs the ENI's InitCmds: give --eni")
    t0 = time.monotonic_ns()
    master = Master(
        eni if eni is not None and opts.state is not None else _empty_eni(),
        transport,
        options=MasterOptions(frame_timeout_ns=opts.timeout_ns, frame_retries=opts.retries),
    )
    refusals: list[Refusal] = []
    if opts.state is not None:
        _count_slaves(master, iface)  # nothing answering is exit 4, not a refusal
        refusals = list(master.bring_up(opts.state, strict=False))
    count = _count_slaves(master, iface)
    slaves = _read_registers(master, count)
    if opts.read_sii:
        read_sii(master, slaves)
    assign_parents(slaves)
    if opts.state is not None:
        master.drain()
    report = ScanReport(iface, slaves, count, eni, opts.state, refusals=refusals)
    if eni is not None:
        report.differences = compare_with_eni(slaves, eni)
    if opts.state is not None:
        report.differences += state_differences(slaves, opts.state, refusals)
    stuck = {d.position for d in report.differences if d.kind == "state_not_reached"}
    report.findings = [
        f for f in findings(slaves) if not (f.kind == "al_error" and f.position in stuck)
    ]
    report.frames_sent = master.stats.frames_sent
    report.frames_lost = master.stats.frames_lost
    report.duration_ns = time.monotonic_ns() - t0
    return report


def _count_slaves(master: Master, iface: str) -> int:
    """Slaves on the line: the working counter of a broadcast read of register 0x0000."""
    where = f" on {iface}" if iface else ""
    try:
        got = master.exchange_one(Datagram.physical(Command.BRD, 0, Register.TYPE, 1))
    except TransportError:
        raise TransportError(f"no slave answers{where} (no frame came back)") from None
    if got.wkc == 0:
        raise TransportError(f"no slave answers{where} (frames come back unprocessed)")
    return got.wkc


#: (register, length) read from every slave, in this order
_REGISTER_READS: tuple[tuple[int, int], ...] = (
    (Register.TYPE, 10),
    (Register.STATION_ADDRESS, 4),
    (Register.DL_STATUS, 2),
    (Register.AL_STATUS, 6),
    (Register.RX_ERROR_COUNTER, 20),
    (Register.SII_CONFIG, 4),
)


def _aprd(position: int, register: int, length: int) -> Datagram:
    return Datagram.physical(Command.APRD, (-(position - 1)) & 0xFFFF, register, length)


def _read_registers(master: Master, count: int) -> list[ScannedSlave]:
    reads = [_aprd(k, reg, n) for k in range(1, count + 1) for reg, n in _REGISTER_READS]
    got = master.exchange_many(reads)
    per = len(_REGISTER_READS)
    slaves = []
    for k in range(1, count + 1):
        esc, addr, dl, al, counters, sii_if = got[(k - 1) * per : k * per]
        s = ScannedSlave(k)
        if not all(d.wkc == 1 for d in (esc, addr, dl, al, counters, sii_if)):
            s.answered = False
            slaves.append(s)
            continue
        e = esc.data
        s.esc_type, s.esc_revision = e[0], e[1]
        s.esc_build = _U16.unpack_from(e, 2)[0]
        s.fmmus, s.sync_managers, s.ram_kib, s.port_descriptor = e[4], e[5], e[6], e[7]
        s.features = _U16.unpack_from(e, 8)[0]
        s.station_address, s.station_alias = struct.unpack_from("<HH", addr.data)
        s.dl_status = _U16.unpack_from(dl.data)[0]
        s.al_status = _U16.unpack_from(al.data)[0]
        s.al_status_code = _U16.unpack_from(al.data, 4)[0]
        s.counters = decode_error_counters(counters.data)
        s.eeprom_config = sii_if.data[0]
        s.eeprom_control = _U16.unpack_from(sii_if.data, 2)[0]
        slaves.append(s)
    return slaves


# ----------------------------------------------------------------------------- SII
def read_sii(master: Master, slaves: Sequence[ScannedSlave]) -> None:
    """Read every answering slave's SII at once (:mod:`lolacli.master.eeprom`, by
    position); a slave whose EEPROM does not read keeps what was read and gets
    ``sii_error``."""
    readers = [s for s in slaves if s.answered]
    addresses = [s.auto_inc_address for s in readers]
    found = eeprom.read_sii(master, addresses, auto_increment=True)
    for s, got in zip(readers, found, strict=True):
        s.sii, s.sii_error = got.info, got.error


# ------------------------------------------------------------------------- topology
def assign_parents(slaves: Sequence[ScannedSlave]) -> None:
    """The slave each one hangs off, from the number of open ports (SOEM's rule: walking
    back, an end (1 port) closes a branch, a junction (3 or 4) opens one or two more)."""
    for i, s in enumerate(slaves):
        s.parent = 0
        balance = 0
        for j in range(i - 1, -1, -1):
            ports = sum(p.open for p in slaves[j].ports)
            if ports == 1:
                balance -= 1
            elif ports == 3:
                balance += 1
            elif ports == 4:
                balance += 2
            if (balance >= 0 and ports > 1) or j == 0:
                s.parent = slaves[j].position
                break


# ---------------------------------------------------------------------- comparisons
def _expected(slave: Slave) -> dict[str, Any]:
    i = slave.identity
    return {
        "name": slave.name,
        "vendor_id": i.vendor_id,
        "product_code": i.product_code,
        "revision": i.revision,
    }


def _found(s: ScannedSlave) -> dict[str, Any]:
    i = s.identity
    return {
        "name": s.name,
        "vendor_id": i.vendor_id if i else None,
        "product_code": i.product_code if i else None,
        "revision": i.revision if i else None,
    }


def _ident_text(vendor: int, product: int, revision: int) -> str:
    return f"vendor 0x{vendor:08X} product 0x{product:08X} revision 0x{revision:08X}"


def compare_with_eni(slaves: Sequence[ScannedSlave], eni: Eni) -> list[Difference]:
    """Every difference between the scanned line and the ENI's slaves, by position."""
    out: list[Difference] = []
    for want in eni.slaves:
        k = want.position
        if k > len(slaves):
            continue
        s = slaves[k - 1]
        e = want.identity
        if not s.answered or s.identity is None:
            why = "does not answer" if not s.answered else (s.sii_error or "no SII")
            out.append(
                Difference(
                    "unverified_slave",
                    k,
                    f"slave {k}: identity not readable ({why}); ENI: {want.name}",
                    _expected(want),
                    _found(s),
                )
            )
            continue
        got = s.identity
        if (got.vendor_id, got.product_code) != (e.vendor_id, e.product_code):
            out.append(
                Difference(
                    "wrong_slave",
                    k,
                    f"slave {k}: found {s.name or '?'} "
                    f"({_ident_text(got.vendor_id, got.product_code, got.revision)}), "
                    f"ENI: {want.name} "
                    f"({_ident_text(e.vendor_id, e.product_code, e.revision)})",
                    _expected(want),
                    _found(s),
                )
            )
        elif got.revision != e.revision:
            out.append(
                Difference(
                    "wrong_revision",
                    k,
                    f"slave {k} ({want.name}): revision 0x{got.revision:08X}, "
                    f"ENI: 0x{e.revision:08X}",
                    _expected(want),
                    _found(s),
                )
            )
    expected = len(eni.slaves)
    if len(slaves) < expected:
        out += _missing(slaves, eni)
    for s in slaves[expected:]:
        out.append(
            Difference(
                "extra_slave",
                s.position,
                f"{s.label()}: not in the ENI ({expected} slaves)",
                None,
                _found(s),
            )
        )
    return out


def _missing(slaves: Sequence[ScannedSlave], eni: Eni) -> list[Difference]:
    out: list[Difference] = []
    first, last = len(slaves) + 1, len(eni.slaves)
    span = f"slave {first}" if first == last else f"slaves {first}-{last}"
    if slaves:
        end = slaves[-1]
        lost = end.counters.lost_link[1] if end.counters else 0
        port1 = end.ports[1]
        state = "closed" if port1.loop_closed else "open"
        out.append(
            Difference(
                "line_ends",
                end.position,
                f"the line ends at {end.label()}: port 1 {state}, "
                f"{'link' if port1.link else 'no link'}, lost link counter {lost}; "
                f"the ENI has {span} behind it",
                {"slaves": last},
                {"slaves": len(slaves), "port1": port1.to_dict(), "lost_link_port1": lost},
            )
        )
    for want in eni.slaves[len(slaves) :]:
        out.append(
            Difference(
                "missing_slave",
                want.position,
                f"slave {want.position} ({want.name}) of the ENI is missing",
                _expected(want),
                None,
            )
        )
    return out


def state_differences(
    slaves: Sequence[ScannedSlave], state: AlState, refusals: Sequence[Refusal]
) -> list[Difference]:
    """Slaves not in the requested state (after a bring-up), with their AL status code."""
    refused = {r.position: r for r in refusals}
    out: list[Difference] = []
    for s in slaves:
        if not s.answered or ((s.al_status & 0x0F) == state and not s.al_error):
            continue
        r = refused.get(s.position)
        why = f"; refused {transition_text(r.transition)}: {r.text}" if r is not None else ""
        out.append(
            Difference(
                "state_not_reached",
                s.position,
                f"{s.label()}: {s.al_state}, not {state.name}, AL status code "
                f"0x{s.al_status_code:04X} {al_status_text(s.al_status_code)}{why}",
                {"al_state": state.name},
                {"al_state": s.al_state, "al_status_code": f"0x{s.al_status_code:04X}"},
            )
        )
    return out


def findings(slaves: Sequence[ScannedSlave]) -> list[Difference]:
    """What is worth a look whatever the ENI says: AL errors, error counters, slaves
    that did not answer or whose SII does not read. They do not fail the scan."""
    out: list[Difference] = []
    for s in slaves:
        if not s.answered:
            out.append(Difference("not_answering", s.position, f"{s.label()}: no answer"))
            continue
        if s.al_error:
            out.append(
                Difference(
                    "al_error",
                    s.position,
                    f"{s.label()}: {s.al_state}, AL status code 0x{s.al_status_code:04X} "
                    f"{al_status_text(s.al_status_code)}",
                    None,
                    {"al_state": s.al_state, "al_status_code": f"0x{s.al_status_code:04X}"},
                )
            )
        c = s.counters
        if c is not None and any(c.lost_link):
            ports = ", ".join(f"port {p}: {n}" for p, n in enumerate(c.lost_link) if n)
            out.append(
                Difference(
                    "lost_link",
                    s.position,
                    f"{s.label()}: lost link counter {ports}",
                    None,
                    {"lost_link": list(c.lost_link)},
                )
            )
        if c is not None and c.total - sum(c.lost_link):
            out.append(
                Difference(
                    "error_counters",
                    s.position,
                    f"{s.label()}: error counters {_counter_text(c)}",
                    None,
                    c.to_dict(),
                )
            )
        if s.sii_error:
            out.append(Difference("sii_unreadable", s.position, f"{s.label()}: {s.sii_error}"))
    return out


def _counter_text(c: ErrorCounters) -> str:
    parts = []
    for name, values in (
        ("invalid frame", c.invalid_frame),
        ("RX error", c.rx_error),
        ("forwarded RX error", c.forwarded_rx_error),
    ):
        parts += [f"{name} port {p}: {n}" for p, n in enumerate(values) if n]
    if c.processing_unit_error:
        parts.append(f"processing unit: {c.processing_unit_error}")
    if c.pdi_error:
        parts.append(f"PDI: {c.pdi_error}")
    return ", ".join(parts)


def parse_state(text: str) -> AlState:
    """``init``, ``preop``, ``safeop``, ``op`` (any case) -> AlState; UsageError."""
    names = {"INIT": AlState.INIT, "PREOP": AlState.PREOP, "SAFEOP": AlState.SAFEOP}
    names["OP"] = AlState.OP
    try:
        return names[text.strip().upper().replace("-", "")]
    except KeyError:
        raise UsageError(f"--state {text!r}: expected init, preop, safeop or op") from None


__all__ = [
    "SCHEMA",
    "Difference",
    "ErrorCounters",
    "Port",
    "ScanOptions",
    "ScanReport",
    "ScannedSlave",
    "assign_parents",
    "compare_with_eni",
    "decode_error_counters",
    "decode_ports",
    "findings",
    "parse_state",
    "read_sii",
    "scan",
    "state_differences",
]
