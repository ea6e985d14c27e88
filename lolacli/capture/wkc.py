"""WKC verdict (docs/architecture.md "Expected WKC"): the expected working counter of each cyclic
datagram, where it comes from, and how the observed values compare (pure).

The scanner counts, per cyclic datagram (command, address key, length) and returned WKC
value, how often it came back, with its first three and last frame. The reference is
decided afterwards, in this order:

* with an ENI: its ``<Cnt>`` where the datagram is one of its cyclic commands (same
  command, address, length); for a logical datagram laid out by the master its own way,
  the sum over the slaves it covers — coverage from the master's FMMU writes in the
  capture (else from the ENI's FMMUs), contributions from the ENI (outputs 2 + inputs 1
  per slave for LRW, 1 each for LRD/LWR); for physical reads/writes 1 per slave addressed
  (3 for read-write), broadcasts every ENI slave; otherwise the report says it cannot tell;
* without an ENI: the sum over the slaves covered by the master's FMMU writes in the
  capture, else the highest value seen (an inferred reference, named so).

A value below the reference that only occurs before the datagram first reached the
reference is the bus coming up (counted as ``bring_up``, not as a mismatch); anything else
that differs is a mismatch.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from lolacli.capture.layout import MasterLayout, Target, covered
from lolacli.text import station as station_name
from lolacli.wire.commands import (
    BROADCAST,
    READ_MULTIPLE_WRITES,
    Command,
    addressed_wkc,
    mnemonic,
    wkc_increment,
)

if TYPE_CHECKING:
    from lolacli.eni.model import Eni, Slave
    from lolacli.wire.registers import Fmmu

LOGICAL = (Command.LRD, Command.LWR, Command.LRW)
_ONE_SLAVE = frozenset({Command.APRD, Command.APWR, Command.APRW,
                        Command.FPRD, Command.FPWR, Command.FPRW})
ENI_BASES = ("eni", "eni+capture-fmmu", "eni-fmmu", "eni-addressing")
S_DC_SYSTIME = 0x0910


@dataclass(frozen=True, slots=True)
class Observed:
    """One working counter a cyclic datagram returned, and how often."""

    wkc: int
    count: int
    frames: tuple[int, ...]  # the first (up to three) frames that returned it
    last_frame: int


@dataclass(slots=True)
class DatagramVerdict:
    """One cyclic datagram: what came back, what was expected, and why."""

    cmd: int
    address: int  # logical address, or ADO << 16 | ADP (ADP 0 for auto-increment/broadcast)
    length_bytes: int
    observed: list[Observed]
    expected: int | None = None
    basis: str = ""  # eni | eni+capture-fmmu | eni-fmmu | eni-addressing | capture-fmmu | max-seen
    note: str = ""  # how the expected value was found, or why it cannot be told
    mismatches: int = 0
    bring_up: int = 0
    mismatch_frames: list[int] = field(default_factory=list)

    @property
    def returns(self) -> int:
        return sum(o.count for o in self.observed)

    @property
    def logical(self) -> bool:
        return self.cmd in LOGICAL

    def name(self) -> str:
        if self.logical:
            where = f"0x{self.address:08X}"
        else:
            ado, adp = self.address >> 16, self.address & 0xFFFF
            # (adp is kept in the key only where it is a station address)
            where = f"0x{ado:04X}" if adp == 0 else f"0x{ado:04X} of {station_name(adp)}"
        return f"{mnemonic(self.cmd)} {where} ({self.length_bytes} B)"

    def to_dict(self) -> dict[str, Any]:
        return {
            "cmd": mnemonic(self.cmd),
            "logical_address": self.address if self.logical else None,
            "adp": None if self.logical else self.address & 0xFFFF,
            "ado": None if self.logical else self.address >> 16,
            "length_bytes": self.length_bytes,
            "expected": self.expected,
            "basis": self.basis or None,
            "note": self.note,
            "returns": self.returns,
            "mismatches": self.mismatches,
            "bring_up": self.bring_up,
            "observed": [{"wkc": o.wkc, "count": o.count, "first_frames": list(o.frames),
                          "last_frame": o.last_frame} for o in self.observed],
        }

    def judge(self) -> None:
        """Count mismatches and bring-up returns against :attr:`expected`."""
        ref = self.expected
        self.mismatches = self.bring_up = 0
        self.mismatch_frames = []
        if ref is None:
            return
        reached = [o.frames[0] for o in self.observed if o.wkc >= ref]
        first_reached = min(reached) if reached else None
        for o in self.observed:
            if o.wkc == ref:
                continue
            if o.wkc < ref and first_reached is not None and o.last_frame < first_reached:
                self.bring_up += o.count
                continue
            self.mismatches += o.count
            self.mismatch_frames.extend(o.frames)
        self.mismatch_frames.sort()


@dataclass(slots=True)
class WkcVerdict:
    """The WKC verdict of every cyclic datagram, against the ENI or inferred."""

    reference: str  # "eni" | "inferred"
    datagrams: list[DatagramVerdict]

    @property
    def checked(self) -> int:
        """Returns of cyclic datagrams verified against a reference (with an ENI: one
        that came from the ENI)."""
        return sum(d.returns for d in self.datagrams if self.datagram_counts(d))

    @property
    def mismatches(self) -> int:
        return sum(d.mismatches for d in self.datagrams if self.datagram_counts(d))

    def datagram_counts(self, d: DatagramVerdict) -> bool:
        if d.expected is None:
            return False
        return d.basis in ENI_BASES if self.reference == "eni" else True

    def first_mismatches(self, limit: int = 20) -> list[dict[str, Any]]:
        rows: list[dict[str, Any]] = []
        for d in self.datagrams:
            if not self.datagram_counts(d):
                continue
            for o in d.observed:
                if o.wkc == d.expected or not set(o.frames) & set(d.mismatch_frames):
                    continue
                rows += [{"frame": f, "cmd": mnemonic(d.cmd), "address": f"0x{d.address:08X}",
                          "expected": d.expected, "received": o.wkc} for f in o.frames]
        return sorted(rows, key=lambda r: int(r["frame"]))[:limit]

    def to_dict(self) -> dict[str, Any]:
        return {
            "reference": self.reference,
            "checked_datagrams": self.checked,
            "mismatches": self.mismatches,
            "first_mismatches": self.first_mismatches(),
            "datagrams": [d.to_dict() for d in self.datagrams],
        }


def group(rows: Iterable[tuple[int, ...]]) -> list[DatagramVerdict]:
    """Datagrams from the scanner's WKC observations ``(cmd, address key, length, wkc,
    count, f1, f2, f3, last)`` (f2/f3 0 when there were fewer returns)."""
    by_key: dict[tuple[int, int, int], list[Observed]] = {}
    for cmd, akey, length, wkc, count, f1, f2, f3, last in rows:
        frames = tuple(f for f in (f1, f2, f3)[: min(count, 3)])
        by_key.setdefault((cmd, akey, length), []).append(Observed(wkc, count, frames, last))
    # in the order they first came back (ties: by command, address, length)
    order = sorted(by_key.items(), key=lambda kv: (min(o.frames[0] for o in kv[1]), kv[0]))
    return [DatagramVerdict(cmd, akey, length, sorted(obs, key=lambda o: o.wkc))
            for (cmd, akey, length), obs in order]


def verdict(rows: Iterable[tuple[int, ...]], layout: MasterLayout, eni: Eni | None) -> WkcVerdict:
    datagrams = group(rows)
    capture_fmmus = layout.fmmus()
    for d in datagrams:
        if eni is not None:
            _from_eni(d, eni, layout, capture_fmmus)
        else:
            _inferred(d, capture_fmmus)
        d.judge()
    return WkcVerdict("eni" if eni is not None else "inferred", datagrams)


# --- references ---------------------------------------------------------------------------


def _from_fmmus(d: DatagramVerdict, fmmus: dict[Target, list[Fmmu]],
                weight: Any = None) -> tuple[int, int, int]:
    """(expected, slaves with outputs covered, slaves with inputs covered)."""
    total = outs = ins = 0
    for slave, fl in fmmus.items():
        reads, writes = covered(fl, d.address, d.length_bytes)
        if weight is not None:
            reads, writes = weight(slave, reads, writes)
        total += wkc_increment(d.cmd, read=reads, write=writes)
        outs += writes
        ins += reads
    return total, outs, ins


def _coverage_note(cmd: int, outs: int, ins: int, where: str) -> str:
    parts = []
    if cmd in (Command.LRW, Command.LWR):
        parts.append(f"{outs} slaves' outputs" + (" x 2" if cmd == Command.LRW else ""))
    if cmd in (Command.LRW, Command.LRD):
        parts.append(f"{ins} slaves' inputs")
    return " + ".join(parts) + f" ({where})"


def _inferred(d: DatagramVerdict, capture_fmmus: dict[Target, list[Fmmu]]) -> None:
    if d.logical and capture_fmmus:
        total, outs, ins = _from_fmmus(d, capture_fmmus)
        if outs or ins:
            d.expected, d.basis = total, "capture-fmmu"
            d.note = _coverage_note(d.cmd, outs, ins, "the master's FMMU writes in the capture")
            return
    d.expected = max(o.wkc for o in d.observed)
    d.basis = "max-seen"
    d.note = ("inferred: the highest WKC it returned (no ENI"
              + (", no FMMU of the master covers it)" if d.logical and capture_fmmus else ")"))


def _eni_command(d: DatagramVerdict, eni: Eni) -> tuple[int, str] | None:
    """The ENI's ``<Cnt>`` of the same cyclic command, and a note. Distributing the DC
    system time (0x0910) by ARMW or FRMW is one job: a master may pick either (SOEM sends
    FRMW from the reference clock's station where the ENI has ARMW); both count the slaves
    that read or write it, so the ENI's count holds for the other command as well."""
    from lolacli.capture.scan import addr_key

    for task in eni.cyclic:
        for frame in task.frames:
            for c in frame.commands:
                if c.data_length_bytes != d.length_bytes:
                    continue
                if c.cmd != d.cmd:
                    dc = (c.cmd in READ_MULTIPLE_WRITES and d.cmd in READ_MULTIPLE_WRITES
                          and c.ado == d.address >> 16 == S_DC_SYSTIME)
                    if dc and c.expected_wkc is not None:
                        return c.expected_wkc, (f"the ENI's <Cnt> of its {mnemonic(c.cmd)} "
                                                "of the DC system time (same register)")
                    continue
                if c.logical_address is not None:
                    address = c.logical_address
                else:
                    address = ((c.ado or 0) << 16) | (c.adp or 0)
                key = addr_key(c.cmd, address & 0xFFFFFFFF)
                if key == d.address and c.expected_wkc is not None:
                    return c.expected_wkc, "the ENI's <Cnt> for this cyclic command"
    return None


def eni_slave(eni: Eni, layout: MasterLayout, slave: Target) -> Slave | None:
    """The ENI slave behind a slave of the capture: by position (from the master's station
    address writes), else by the ENI's station address."""
    pos = slave.value if slave.kind == "position" else layout.position_of(slave.value)
    if pos is not None and pos < len(eni.slaves):
        return eni.slaves[pos]
    if slave.kind == "station":
        for s in eni.slaves:
            if s.station_address == slave.value:
                return s
    return None


def _from_eni(d: DatagramVerdict, eni: Eni, layout: MasterLayout,
              capture_fmmus: dict[Target, list[Fmmu]]) -> None:
    found = _eni_command(d, eni)
    if found is not None:
        d.expected, d.note = found
        d.basis = "eni"
        return
    if d.logical:
        _eni_logical(d, eni, layout, capture_fmmus)
        return
    if d.cmd in _ONE_SLAVE:
        d.expected, d.basis = addressed_wkc(d.cmd, 1), "eni-addressing"
        d.note = "one slave addressed"
    elif d.cmd in BROADCAST:
        d.expected = addressed_wkc(d.cmd, len(eni.slaves))
        d.basis, d.note = "eni-addressing", f"every one of the ENI's {len(eni.slaves)} slaves"
    elif d.cmd == Command.NOP:
        d.expected, d.basis, d.note = 0, "eni-addressing", "no slave processes a NOP"
    else:
        d.note = "cannot tell: not one of the ENI's cyclic commands"


def _eni_logical(d: DatagramVerdict, eni: Eni, layout: MasterLayout,
                 capture_fmmus: dict[Target, list[Fmmu]]) -> None:
    if capture_fmmus:
        def weight(slave: Target, reads: bool, writes: bool) -> tuple[bool, bool]:
            s = eni_slave(eni, layout, slave)
            if s is None:
                return reads, writes
            return reads and s.inputs_bits > 0, writes and s.outputs_bits > 0

        total, outs, ins = _from_fmmus(d, capture_fmmus, weight)
        if outs or ins:
            d.expected, d.basis = total, "eni+capture-fmmu"
            d.note = _coverage_note(d.cmd, outs, ins, "the master's FMMU writes in the capture, "
                                    "slaves' data from the ENI")
            return
    eni_fmmus = {Target("position", s.position - 1): [c.fmmu for c in s.fmmus if c.fmmu.enabled]
                 for s in eni.slaves}
    total, outs, ins = _from_fmmus(d, eni_fmmus)
    if outs or ins:
        d.expected, d.basis = total, "eni-fmmu"
        d.note = _coverage_note(d.cmd, outs, ins, "the ENI's FMMUs")
        return
    d.note = ("cannot tell: the master's FMMU writes are not in the capture and the "
              "datagram lies outside the ENI's logical layout"
              if not capture_fmmus else
              "cannot tell: no FMMU (capture or ENI) covers it")


def eni_slaves_not_mapped(eni: Eni, layout: MasterLayout) -> list[Slave]:
    """ENI slaves with process data that have no active FMMU in the master's layout (only
    when the capture holds the master's FMMU writes at all)."""
    fmmus = layout.fmmus()
    if not fmmus:
        return []
    mapped = {id(s) for t in fmmus if (s := eni_slave(eni, layout, t)) is not None}
    return [s for s in eni.slaves
            if (s.inputs_bits or s.outputs_bits) and id(s) not in mapped]
