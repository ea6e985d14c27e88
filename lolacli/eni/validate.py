"""Semantic checks of an ENI (pure: model in, findings out).

Each check is a small function ``(eni) -> Iterator[Finding]``; :func:`validate_eni` runs them
all. Codes are stable strings (scripts filter on them). Severity ``error`` means the bus will
not run as configured (or a master will flag WKC errors); ``warning`` means the file is odd
but usable. Working counters follow DESIGN.md "Expected WKC": per slave addressed, read 1,
write 1, read-write 3; an LRW on a slave with only inputs counts 1, with only outputs 2.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

from lolacli.eni.model import CyclicCommand, Direction, Eni, Fmmu, Slave
from lolacli.wire.commands import BROADCAST, LOGICAL, Command, mnemonic

VALIDATE_SCHEMA = "lolacli.eni-validate/1"

FMMU_READ = 1
FMMU_WRITE = 2
FMMU_READ_WRITE = 3
DATAGRAM_HEADER_BYTES = 10


class Severity(StrEnum):
    ERROR = "error"
    WARNING = "warning"


@dataclass(frozen=True, slots=True)
class Finding:
    severity: Severity
    code: str
    message: str
    slave: int | None = None  # 1-based position, when one slave is concerned

    def as_dict(self) -> dict[str, Any]:
        return {
            "severity": self.severity.value,
            "code": self.code,
            "message": self.message,
            "slave": self.slave,
        }


def _error(code: str, message: str, slave: int | None = None) -> Finding:
    return Finding(Severity.ERROR, code, message, slave)


def _warning(code: str, message: str, slave: int | None = None) -> Finding:
    return Finding(Severity.WARNING, code, message, slave)


# --------------------------------------------------------------------------- FMMU helpers


def fmmu_valid(f: Fmmu) -> bool:
    """An FMMU we can reason about: a known type and bits within a byte."""
    return f.type in (1, 2, 3) and f.logical_start_bit < 8 and f.logical_end_bit < 8


def fmmu_bits(f: Fmmu) -> tuple[int, int]:
    """The logical bit range ``[first, last]`` an FMMU maps (ETG.1000.4 Table 56)."""
    first = f.logical_start * 8 + f.logical_start_bit
    last = (f.logical_start + f.length_bytes - 1) * 8 + f.logical_end_bit
    return first, last


def active_fmmus(s: Slave) -> list[Fmmu]:
    return [f for f in s.fmmus if f.enable and f.length_bytes > 0 and fmmu_valid(f)]


def _overlaps(a: tuple[int, int], b: tuple[int, int]) -> bool:
    return a[0] <= b[1] and b[0] <= a[1]


def _fmmu_label(f: Fmmu) -> str:
    kind = {1: "read", 2: "write", 3: "read-write"}.get(f.type, f"type {f.type}")
    return f"FMMU{f.index} ({kind} 0x{f.logical_start:08X}+{f.length_bytes})"


# --------------------------------------------------------------------------- checks


def check_station_addresses(eni: Eni) -> Iterator[Finding]:
    counts = Counter(s.station_address for s in eni.slaves)
    for s in eni.slaves:
        if s.station_address == 0:
            yield _error(
                "missing-station-address", f"slave {s.position} has station address 0", s.position
            )
        elif counts[s.station_address] > 1:
            others = [
                o.position
                for o in eni.slaves
                if o.station_address == s.station_address and o is not s
            ]
            yield _error(
                "duplicate-station-address",
                f"slave {s.position} ({s.name.strip()}) shares station address "
                f"{s.station_address} with slave(s) {others}",
                s.position,
            )


def check_chain(eni: Eni) -> Iterator[Finding]:
    stations = {s.station_address for s in eni.slaves}
    for s in eni.slaves:
        expected = -(s.position - 1) & 0xFFFF
        if s.auto_inc_address != expected:
            yield _warning(
                "auto-inc-address",
                f"slave {s.position}: AutoIncAddr {s.auto_inc_address} (0x{s.auto_inc_address:04X})"
                f" is not {expected} (0x{expected:04X}) for its chain position",
                s.position,
            )
        prev = s.previous_station_address
        if prev is not None and prev not in stations:
            yield _error(
                "unknown-previous-port",
                f"slave {s.position}: PreviousPort names unknown station {prev}",
                s.position,
            )


def check_fmmu_types(eni: Eni) -> Iterator[Finding]:
    for s in eni.slaves:
        bad = [f for f in s.fmmus if f.length_bytes and not fmmu_valid(f)]
        if bad:
            hint = (
                " (the file is an EncryptedEtherCATConfig: InitCmd data may be encrypted)"
                if eni.root == "EncryptedEtherCATConfig"
                else ""
            )
            yield _warning(
                "fmmu-undecodable",
                f"slave {s.position}: {len(bad)} FMMU register write(s) do not decode "
                f"(type {sorted({f.type for f in bad})}){hint}; not checked",
                s.position,
            )


def check_fmmu_overlaps(eni: Eni) -> Iterator[Finding]:
    """Logical bits mapped by two different slaves (any direction) collide in the frame."""
    mapped = [(s, f, fmmu_bits(f)) for s in eni.slaves for f in active_fmmus(s)]
    for i, (sa, fa, ra) in enumerate(mapped):
        for sb, fb, rb in mapped[i + 1 :]:
            if sa is sb or not _overlaps(ra, rb):
                continue
            both_write = fa.type & FMMU_WRITE and fb.type & FMMU_WRITE
            code = "fmmu-write-overlap" if both_write else "fmmu-overlap"
            yield _error(
                code,
                f"slave {sa.position} {_fmmu_label(fa)} overlaps slave {sb.position} "
                f"{_fmmu_label(fb)}",
                sb.position,
            )


MAILBOX_STATUS_REGISTER = 0x080D  # SM1 status byte, mapped by mailbox-state FMMUs


def check_fmmu_mapping(eni: Eni) -> Iterator[Finding]:
    """Each FMMU must be carried by a cyclic command of its direction and point at an SM."""
    ranges = [
        (c.cmd, r)
        for f in eni.cyclic_frames
        for c in f.commands
        if (r := _logical_range(c)) is not None
    ]
    for s in eni.slaves:
        for f in active_fmmus(s):
            bits = fmmu_bits(f)
            wanted = _carriers(f.type)
            if ranges and not any(
                cmd in wanted and r[0] <= bits[0] and bits[1] <= r[1] for cmd, r in ranges
            ):
                yield _warning(
                    "fmmu-not-in-cyclic",
                    f"slave {s.position}: {_fmmu_label(f)} is not carried by any "
                    "cyclic logical command",
                    s.position,
                )
            if s.sync_managers and not _in_sync_manager(s, f):
                yield _warning(
                    "fmmu-sm-mismatch",
                    f"slave {s.position}: {_fmmu_label(f)} maps physical "
                    f"0x{f.physical_start:04X}, inside no sync manager",
                    s.position,
                )


def _carriers(fmmu_type: int) -> set[int]:
    if fmmu_type == FMMU_READ:
        return {Command.LRD, Command.LRW}
    if fmmu_type == FMMU_WRITE:
        return {Command.LWR, Command.LRW}
    return {Command.LRW}


def _in_sync_manager(s: Slave, f: Fmmu) -> bool:
    if f.physical_start == MAILBOX_STATUS_REGISTER:
        return True
    return any(
        m.start_address <= f.physical_start < m.start_address + max(m.length_bytes, 1)
        for m in s.sync_managers
    )


def _logical_range(c: CyclicCommand) -> tuple[int, int] | None:
    if c.logical_address is None or c.data_length_bytes <= 0:
        return None
    return c.logical_address * 8, (c.logical_address + c.data_length_bytes) * 8 - 1


def check_cyclic_overlaps(eni: Eni) -> Iterator[Finding]:
    for t, task in enumerate(eni.cyclic):
        cmds = [(c, _logical_range(c)) for f in task.frames for c in f.commands]
        ranged = [(c, r) for c, r in cmds if r is not None]
        for i, (ca, ra) in enumerate(ranged):
            for cb, rb in ranged[i + 1 :]:
                if _overlaps(ra, rb):
                    yield _error(
                        "cyclic-logical-overlap",
                        f"cyclic task {t + 1}: {_cmd_label(ca)} overlaps {_cmd_label(cb)}",
                    )


def _cmd_label(c: CyclicCommand) -> str:
    if c.logical_address is not None:
        return f"{mnemonic(c.cmd)} 0x{c.logical_address:08X}+{c.data_length_bytes}"
    return f"{mnemonic(c.cmd)} {c.adp}:0x{(c.ado or 0):04X}+{c.data_length_bytes}"


def _image_window(c: CyclicCommand, direction: Direction) -> tuple[int, int] | None:
    """Image bits a command carries; loose (+header) to cover both offset conventions."""
    offs = c.input_offset_bytes if direction is Direction.INPUT else c.output_offset_bytes
    if offs is None:
        return None
    return offs * 8, (offs + DATAGRAM_HEADER_BYTES + c.data_length_bytes) * 8 - 1


def _slave_touches(s: Slave, c: CyclicCommand) -> tuple[bool, bool]:
    """(reads, writes): does the logical command move this slave's inputs / outputs?"""
    window = _logical_range(c)
    fmmus = active_fmmus(s)
    scrambled = any(f.length_bytes and not fmmu_valid(f) for f in s.fmmus)
    if fmmus and window is not None and not scrambled:
        reads = any(f.type & FMMU_READ and _overlaps(fmmu_bits(f), window) for f in fmmus)
        writes = any(f.type & FMMU_WRITE and _overlaps(fmmu_bits(f), window) for f in fmmus)
        return reads, writes
    iw, ow = _image_window(c, Direction.INPUT), _image_window(c, Direction.OUTPUT)
    reads = iw is not None and any(
        a.bit_length and _overlaps((a.bit_start, a.bit_start + a.bit_length - 1), iw)
        for a in s.inputs
    )
    writes = ow is not None and any(
        a.bit_length and _overlaps((a.bit_start, a.bit_start + a.bit_length - 1), ow)
        for a in s.outputs
    )
    return reads, writes


def expected_logical_wkc(eni: Eni, c: CyclicCommand) -> int:
    """Working counter a logical command should return, from the slaves' mappings."""
    total = 0
    for s in eni.slaves:
        reads, writes = _slave_touches(s, c)
        if c.cmd == Command.LRD:
            total += 1 if reads else 0
        elif c.cmd == Command.LWR:
            total += 1 if writes else 0
        else:
            total += (1 if reads else 0) + (2 if writes else 0)
    return total


def expected_wkc(eni: Eni, c: CyclicCommand) -> int | None:
    """The WKC a cyclic command should return, or None where it cannot be known."""
    n = len(eni.slaves)
    if c.cmd in LOGICAL:
        return expected_logical_wkc(eni, c)
    if c.cmd in BROADCAST:
        return 3 * n if c.cmd == Command.BRW else n
    if c.cmd in (Command.ARMW, Command.FRMW):
        return n
    if c.cmd == Command.NOP:
        return 0
    return 3 if c.cmd in (Command.APRW, Command.FPRW) else 1


def check_wkc(eni: Eni) -> Iterator[Finding]:
    for frame in eni.cyclic_frames:
        for c in frame.commands:
            if c.expected_wkc is None:
                continue
            if c.cmd in LOGICAL and _has_undecodable_fmmu(eni) and not _any_areas(eni):
                continue
            want = expected_wkc(eni, c)
            if want is not None and want != c.expected_wkc:
                yield _error(
                    "wkc-mismatch",
                    f"{_cmd_label(c)}: <Cnt> {c.expected_wkc}, but the slaves it addresses "
                    f"give {want}",
                )


def _has_undecodable_fmmu(eni: Eni) -> bool:
    return any(f.length_bytes and not fmmu_valid(f) for s in eni.slaves for f in s.fmmus)


def _any_areas(eni: Eni) -> bool:
    return any(s.inputs or s.outputs for s in eni.slaves)


def check_pdo_sizes(eni: Eni) -> Iterator[Finding]:
    for s in eni.slaves:
        for sm in s.sync_managers:
            bits = sum(p.bit_size for p in s.pdos if p.sync_manager == sm.index)
            if bits and (bits + 7) // 8 > sm.length_bytes:
                yield _error(
                    "pdo-overruns-sm",
                    f"slave {s.position}: PDOs assigned to SM{sm.index} need {(bits + 7) // 8}"
                    f" bytes, the sync manager is {sm.length_bytes} bytes",
                    s.position,
                )


def check_process_image(eni: Eni) -> Iterator[Finding]:
    pi = eni.process_image
    limits = {Direction.INPUT: pi.inputs_bytes * 8, Direction.OUTPUT: pi.outputs_bytes * 8}
    for v in eni.process_image.variables:
        end = v.bit_offset + v.bit_size
        if v.bit_offset < 0 or end > limits[v.direction]:
            yield _error(
                "variable-outside-image",
                f"variable {v.name!r} ({v.direction.value}, bits {v.bit_offset}..{end - 1}) "
                f"lies outside the {limits[v.direction] // 8}-byte {v.direction.value} image",
            )
    for s in eni.slaves:
        for areas, direction in ((s.inputs, Direction.INPUT), (s.outputs, Direction.OUTPUT)):
            for a in areas:
                if a.bit_start + a.bit_length > limits[direction]:
                    yield _error(
                        "process-data-outside-image",
                        f"slave {s.position}: {direction.value} bits {a.bit_start}+{a.bit_length}"
                        f" lie outside the {limits[direction] // 8}-byte image",
                        s.position,
                    )


def check_cyclic_present(eni: Eni) -> Iterator[Finding]:
    if eni.slaves and not eni.cyclic_frames:
        yield _warning("no-cyclic-frames", "the ENI has slaves but no cyclic frame")


CHECKS: tuple[Callable[[Eni], Iterator[Finding]], ...] = (
    check_station_addresses,
    check_chain,
    check_fmmu_types,
    check_fmmu_overlaps,
    check_fmmu_mapping,
    check_cyclic_overlaps,
    check_wkc,
    check_pdo_sizes,
    check_process_image,
    check_cyclic_present,
)


def validate_eni(eni: Eni) -> tuple[Finding, ...]:
    """All findings of all checks, in check order."""
    return tuple(f for check in CHECKS for f in check(eni))


def validate_report(eni: Eni, findings: tuple[Finding, ...]) -> dict[str, Any]:
    """The ``lolacli.eni-validate/1`` document."""
    errors = sum(1 for f in findings if f.severity is Severity.ERROR)
    return {
        "schema": VALIDATE_SCHEMA,
        "source": eni.source,
        "errors": errors,
        "warnings": len(findings) - errors,
        "findings": [f.as_dict() for f in findings],
    }


__all__ = [
    "CHECKS",
    "VALIDATE_SCHEMA",
    "Finding",
    "Severity",
    "expected_wkc",
    "validate_eni",
    "validate_report",
]
