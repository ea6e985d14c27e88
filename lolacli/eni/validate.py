"""Semantic checks of an ENI (pure: model in, findings out).

Each check is a small function ``(eni) -> Iterator[Finding]``; :func:`validate_eni` runs them
all. Codes are stable strings (scripts filter on them). Severity ``error`` means the bus will
not run as configured (or a master will flag WKC errors); ``warning`` means the file is odd
but usable. Working counters follow docs/architecture.md, "Expected WKC": per slave
addressed, read 1, write 1, read-write 3; an LRW on a slave with only inputs counts 1,
with only outputs 2.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from typing import Any

from lolacli.eni.limits import (
    ADDRESS16,
    AREA_BITS,
    BIT_LEN,
    CCS,
    COMMAND,
    CYCLE_NS,
    DATA_LENGTH,
    ETHERNET_PAYLOAD_BYTES,
    I32,
    IMAGE_BIT,
    IMAGE_BYTES,
    LOGICAL_BIT,
    MILLISECONDS,
    RETRIES,
    SM_INDEX,
    U8,
    U16,
    U32,
    WKC,
    WORD32,
    Width,
)
from lolacli.eni.model import (
    ConfiguredFmmu,
    CyclicCommand,
    CyclicFrame,
    Direction,
    Eni,
    InitCmd,
    Mailbox,
    Slave,
)
from lolacli.findings import Finding, Severity
from lolacli.text import plural, station
from lolacli.wire.commands import LOGICAL, Command, addressed_wkc, mnemonic, wkc_increment
from lolacli.wire.frame import DATAGRAM_HEADER_BYTES, ECAT_HEADER_BYTES, WKC_BYTES
from lolacli.wire.registers import Fmmu, FmmuType

VALIDATE_SCHEMA = "lolacli.eni-validate/2"



def _error(code: str, message: str, slave: int | None = None) -> Finding:
    return Finding(code, Severity.FAILURE, message, slave=slave)


def _warning(code: str, message: str, slave: int | None = None) -> Finding:
    return Finding(code, Severity.WARNING, message, slave=slave)


# --------------------------------------------------------------------------- FMMU helpers


def fmmu_valid(f: Fmmu) -> bool:
    """An FMMU we can reason about: a known type and bits within a byte."""
    return f.type in (1, 2, 3) and f.logical_start_bit < 8 and f.logical_stop_bit < 8


def fmmu_bits(f: Fmmu) -> tuple[int, int]:
    """The logical bit range ``[first, last]`` an FMMU maps (ETG.1000.4 Table 56)."""
    first = f.logical_start * 8 + f.logical_start_bit
    last = (f.logical_start + f.length_bytes - 1) * 8 + f.logical_stop_bit
    return first, last


def _undecodable(f: Fmmu) -> bool:
    return bool(f.length_bytes) and not fmmu_valid(f)


def active_fmmus(s: Slave) -> list[ConfiguredFmmu]:
    return [c for c in s.fmmus if c.fmmu.enabled and c.fmmu.length_bytes > 0 and fmmu_valid(c.fmmu)]


def _overlaps(a: tuple[int, int], b: tuple[int, int]) -> bool:
    return a[0] <= b[1] and b[0] <= a[1]


def _fmmu_label(c: ConfiguredFmmu) -> str:
    f = c.fmmu
    kind = {1: "read", 2: "write", 3: "read-write"}.get(f.type, f"type {f.type}")
    return f"FMMU{c.index} ({kind} 0x{f.logical_start:08X}+{f.length_bytes})"


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
                f"{station(s.station_address)} with {'slave' if len(others) == 1 else 'slaves'} "
                f"{', '.join(map(str, others))}",
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
                f"slave {s.position}: PreviousPort names unknown station {station(prev)}",
                s.position,
            )


def check_fmmu_types(eni: Eni) -> Iterator[Finding]:
    for s in eni.slaves:
        bad = [c.fmmu for c in s.fmmus if _undecodable(c.fmmu)]
        if bad:
            hint = (
                " (the file is an EncryptedEtherCATConfig: InitCmd data may be encrypted)"
                if eni.root == "EncryptedEtherCATConfig"
                else ""
            )
            yield _warning(
                "fmmu-undecodable",
                f"slave {s.position}: {plural(len(bad), 'FMMU register write')} not decoded "
                f"(type {', '.join(str(t) for t in sorted({f.type for f in bad}))}){hint}; "
                "not checked",
                s.position,
            )


def check_fmmu_overlaps(eni: Eni) -> Iterator[Finding]:
    """Logical bits mapped by two different slaves (any direction) collide in the frame."""
    mapped = [(s, c, fmmu_bits(c.fmmu)) for s in eni.slaves for c in active_fmmus(s)]
    for i, (sa, fa, ra) in enumerate(mapped):
        for sb, fb, rb in mapped[i + 1 :]:
            if sa is sb or not _overlaps(ra, rb):
                continue
            both_write = fa.fmmu.type & FmmuType.WRITE and fb.fmmu.type & FmmuType.WRITE
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
        for c in active_fmmus(s):
            f = c.fmmu
            bits = fmmu_bits(f)
            wanted = _carriers(f.type)
            if ranges and not any(
                cmd in wanted and r[0] <= bits[0] and bits[1] <= r[1] for cmd, r in ranges
            ):
                yield _warning(
                    "fmmu-not-in-cyclic",
                    f"slave {s.position}: {_fmmu_label(c)} is not carried by any "
                    "cyclic logical command",
                    s.position,
                )
            if s.sync_managers and not _in_sync_manager(s, f):
                yield _warning(
                    "fmmu-sm-mismatch",
                    f"slave {s.position}: {_fmmu_label(c)} maps physical "
                    f"0x{f.physical_start:04X}, inside no sync manager",
                    s.position,
                )


def _carriers(fmmu_type: int) -> set[int]:
    if fmmu_type == FmmuType.READ:
        return {Command.LRD, Command.LRW}
    if fmmu_type == FmmuType.WRITE:
        return {Command.LWR, Command.LRW}
    return {Command.LRW}


def _in_sync_manager(s: Slave, f: Fmmu) -> bool:
    if f.physical_start == MAILBOX_STATUS_REGISTER:
        return True
    return any(
        m.physical_start <= f.physical_start < m.physical_start + max(m.length_bytes, 1)
        for m in (c.sync_manager for c in s.sync_managers)
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
    fmmus = [c.fmmu for c in active_fmmus(s)]
    scrambled = any(_undecodable(c.fmmu) for c in s.fmmus)
    if fmmus and window is not None and not scrambled:
        reads = any(f.type & FmmuType.READ and _overlaps(fmmu_bits(f), window) for f in fmmus)
        writes = any(f.type & FmmuType.WRITE and _overlaps(fmmu_bits(f), window) for f in fmmus)
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
    return sum(wkc_increment(c.cmd, read=r, write=w)
               for r, w in (_slave_touches(s, c) for s in eni.slaves))


def expected_wkc(eni: Eni, c: CyclicCommand) -> int | None:
    """The WKC a cyclic command should return, or None where it cannot be known."""
    if c.cmd in LOGICAL:
        return expected_logical_wkc(eni, c)
    return addressed_wkc(c.cmd, len(eni.slaves))


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
    return any(_undecodable(c.fmmu) for s in eni.slaves for c in s.fmmus)


def _any_areas(eni: Eni) -> bool:
    return any(s.inputs or s.outputs for s in eni.slaves)


def check_pdo_sizes(eni: Eni) -> Iterator[Finding]:
    for s in eni.slaves:
        for sm in s.sync_managers:
            bits = sum(p.bit_size for p in s.pdos if p.sync_manager == sm.index)
            length_bytes = sm.sync_manager.length_bytes
            if bits and (bits + 7) // 8 > length_bytes:
                yield _error(
                    "pdo-overruns-sm",
                    f"slave {s.position}: PDOs assigned to SM{sm.index} need {(bits + 7) // 8}"
                    f" bytes, the sync manager is {length_bytes} bytes",
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
                f"variable \"{v.name}\" ({v.direction.value}, bits {v.bit_offset}..{end - 1}) "
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


# --------------------------------------------------------------------------- field widths

# The widths are lolacli.eni.limits': the parser refuses a file with a value outside them
# (exit 3, naming the line), so these findings come from models built in code or read back
# from the cache, never from a file just parsed.

RANGE_CODE = "value-out-of-range"

_Field = tuple[str, int | None, Width]


def _range_findings(
    where: str, fields: Iterable[_Field], slave: int | None = None
) -> Iterator[Finding]:
    for label, value, width in fields:
        if value is not None and not width.holds(value):
            yield _error(RANGE_CODE, f"{where}: {label} {value} is outside {width}", slave)


def _init_cmd_fields(n: int, c: InitCmd) -> Iterator[_Field]:
    at = f"InitCmd {n} ({c.comment})" if c.comment else f"InitCmd {n}"
    yield f"{at} <Cmd>", c.cmd, COMMAND
    if c.logical_address is None:
        yield f"{at} <Adp>", c.adp, ADDRESS16
        yield f"{at} <Ado>", c.ado, ADDRESS16
    yield f"{at} <Addr>", c.logical_address, WORD32
    yield f"{at} data length", len(c.data), DATA_LENGTH
    yield f"{at} <Cnt>", c.expected_wkc, WKC
    yield f"{at} <Retries>", c.retries, RETRIES
    yield f"{at} <Timeout>", c.timeout_ms, MILLISECONDS
    yield f"{at} <Validate><Timeout>", c.validate_timeout_ms, MILLISECONDS
    for name, data in (("<Validate><Data>", c.validate_data), ("<DataMask>", c.validate_mask)):
        if data is not None:
            yield f"{at} {name} length", len(data), DATA_LENGTH


def _init_cmds_fields(cmds: Iterable[InitCmd]) -> Iterator[_Field]:
    for n, c in enumerate(cmds, 1):
        yield from _init_cmd_fields(n, c)


def _identity_fields(s: Slave) -> Iterator[_Field]:
    yield "<Info><PhysAddr>", s.station_address, ADDRESS16
    yield "<Info><AutoIncAddr>", s.auto_inc_address, ADDRESS16
    yield "<Info><VendorId>", s.identity.vendor_id, WORD32
    yield "<Info><ProductCode>", s.identity.product_code, WORD32
    yield "<Info><RevisionNo>", s.identity.revision, WORD32
    yield "<Info><SerialNo>", s.identity.serial, WORD32
    yield "<PreviousPort><PhysAddr>", s.previous_station_address, ADDRESS16


def _mailbox_fields(m: Mailbox | None) -> Iterator[_Field]:
    if m is None:
        return
    yield "<Mailbox><Send><Start>", m.out_start, U16
    yield "<Mailbox><Send><Length>", m.out_length_bytes, U16
    yield "<Mailbox><Recv><Start>", m.in_start, U16
    yield "<Mailbox><Recv><Length>", m.in_length_bytes, U16
    yield "<Mailbox><Recv><PollTime>", m.poll_time_ms, MILLISECONDS
    yield "<Mailbox><Recv><StatusBitAddr>", m.status_bit_address, LOGICAL_BIT
    for n, c in enumerate(m.coe_init_cmds, 1):
        at = f"CoE InitCmd {n} ({c.comment})" if c.comment else f"CoE InitCmd {n}"
        yield f"{at} <Index>", c.index, U16
        yield f"{at} <SubIndex>", c.subindex, U8
        yield f"{at} <Ccs>", c.ccs, CCS
        yield f"{at} <Timeout>", c.timeout_ms, MILLISECONDS


def _sm_fmmu_fields(s: Slave) -> Iterator[_Field]:
    for c in s.sync_managers:
        sm = c.sync_manager
        yield f"SM{c.index} index", c.index, SM_INDEX
        yield f"SM{c.index} start address", sm.physical_start, U16
        yield f"SM{c.index} length", sm.length_bytes, U16
        yield f"SM{c.index} control byte", sm.control, U8
    for cf in s.fmmus:
        f = cf.fmmu
        yield f"FMMU{cf.index} logical start", f.logical_start, U32
        yield f"FMMU{cf.index} length", f.length_bytes, U16
        yield f"FMMU{cf.index} physical start", f.physical_start, U16


def _pdo_fields(s: Slave) -> Iterator[_Field]:
    for p in s.pdos:
        index = f"0x{p.index:04X}" if p.index >= 0 else str(p.index)
        at = f"{'RxPdo' if p.direction is Direction.OUTPUT else 'TxPdo'} {index}"
        yield f"{at} <Index>", p.index, U16
        yield f"{at} Sm", p.sync_manager, SM_INDEX
        for n, e in enumerate(p.entries, 1):
            entry = f"{at} Entry {n} ({e.name})" if e.name else f"{at} Entry {n}"
            yield f"{entry} <Index>", e.index, U16
            yield f"{entry} <SubIndex>", e.subindex, U8
            yield f"{entry} <BitLen>", e.bit_size, BIT_LEN


def _dc_fields(s: Slave) -> Iterator[_Field]:
    for kind, areas in (("Send", s.outputs), ("Recv", s.inputs)):
        for a in areas:
            yield f"<ProcessData><{kind}><BitStart>", a.bit_start, LOGICAL_BIT
            yield f"<ProcessData><{kind}><BitLength>", a.bit_length, AREA_BITS
    if s.dc is None:
        return
    yield "<DC><CycleTime0>", s.dc.cycle_time0_ns, U32
    yield "<DC><CycleTime1>", s.dc.cycle_time1_ns, U32
    yield "<DC><ShiftTime>", s.dc.shift_time_ns, I32
    yield "<DC><AssignActivate>", s.dc.assign_activate, U16


def _slave_fields(s: Slave) -> Iterator[_Field]:
    yield from _identity_fields(s)
    yield from _mailbox_fields(s.mailbox)
    yield from _sm_fmmu_fields(s)
    yield from _pdo_fields(s)
    yield from _dc_fields(s)
    yield from _init_cmds_fields(s.init_cmds)


def _cyclic_command_fields(c: CyclicCommand) -> Iterator[_Field]:
    yield "<Cmd>", c.cmd, COMMAND
    yield "<Adp>", c.adp, ADDRESS16
    yield "<Ado>", c.ado, ADDRESS16
    yield "<Addr>", c.logical_address, WORD32
    yield "<DataLength>", c.data_length_bytes, DATA_LENGTH
    yield "<Cnt>", c.expected_wkc, WKC
    yield "<InputOffs>", c.input_offset_bytes, IMAGE_BYTES
    yield "<OutputOffs>", c.output_offset_bytes, IMAGE_BYTES


FRAME_PAYLOAD = Width(0, ETHERNET_PAYLOAD_BYTES, "an Ethernet frame carries 1500 bytes")


def _payload_bytes(frame: CyclicFrame) -> int:
    """EtherCAT header and datagrams: what the frame's Ethernet payload must hold (a
    negative length is a finding of its own)."""
    return ECAT_HEADER_BYTES + sum(
        DATAGRAM_HEADER_BYTES + max(c.data_length_bytes, 0) + WKC_BYTES for c in frame.commands
    )


def _cyclic_findings(eni: Eni) -> Iterator[Finding]:
    for t, task in enumerate(eni.cyclic, 1):
        yield from _range_findings(
            f"cyclic task {t}", [("<CycleTime> (ns)", task.cycle_time_ns, CYCLE_NS)]
        )
        for fn, frame in enumerate(task.frames, 1):
            # CycleTimeFactor (Elmo Application Studio) is no bus field; its exports write 0.
            where = f"cyclic task {t} frame {fn}"
            yield from _range_findings(
                where, [("Ethernet payload (bytes)", _payload_bytes(frame), FRAME_PAYLOAD)]
            )
            for cn, c in enumerate(frame.commands, 1):
                yield from _range_findings(
                    f"{where} Cmd {cn} ({mnemonic(c.cmd)})", _cyclic_command_fields(c)
                )


def _image_fields(eni: Eni) -> Iterator[_Field]:
    pi = eni.process_image
    yield "<Inputs><ByteSize>", pi.inputs_bytes, IMAGE_BYTES
    yield "<Outputs><ByteSize>", pi.outputs_bytes, IMAGE_BYTES
    for v in pi.variables:
        yield f"variable {v.name!r} <BitOffs>", v.bit_offset, IMAGE_BIT
        yield f"variable {v.name!r} <BitSize>", v.bit_size, IMAGE_BIT


def check_field_ranges(eni: Eni) -> Iterator[Finding]:
    """Numbers outside the width their register, datagram field or CoE object gives them."""
    master = eni.master
    yield from _range_findings(
        "master",
        [
            ("<CycleTime> (ns)", master.cycle_time_ns, CYCLE_NS),
            *_init_cmds_fields(master.init_cmds),
        ],
    )
    for s in eni.slaves:
        where = (
            f"slave {s.position} ({s.name.strip()})" if s.name.strip() else f"slave {s.position}"
        )
        yield from _range_findings(where, _slave_fields(s), s.position)
    yield from _cyclic_findings(eni)
    yield from _range_findings("process image", _image_fields(eni))


def within_limits(eni: Eni) -> bool:
    """True when every number of ``eni`` holds the limits the parser enforces (no
    :func:`check_field_ranges` finding): a model that did not come from the parser (built
    in code, read from the cache) and may be handed to the emulator or master."""
    return next(check_field_ranges(eni), None) is None


def check_slaves_present(eni: Eni) -> Iterator[Finding]:
    """An ENI configures a bus: with no ``<Slave>`` there is nothing to bring up, emulate or
    check a capture against."""
    if not eni.slaves:
        yield _error("no-slaves", "the ENI has no <Slave>: there is no bus to configure")


def check_cyclic_present(eni: Eni) -> Iterator[Finding]:
    if eni.slaves and not eni.cyclic_frames:
        yield _warning("no-cyclic-frames", "the ENI has slaves but no cyclic frame")


CHECKS: tuple[Callable[[Eni], Iterator[Finding]], ...] = (
    check_slaves_present,
    check_station_addresses,
    check_chain,
    check_fmmu_types,
    check_fmmu_overlaps,
    check_fmmu_mapping,
    check_cyclic_overlaps,
    check_wkc,
    check_pdo_sizes,
    check_process_image,
    check_field_ranges,
    check_cyclic_present,
)


def validate_eni(eni: Eni) -> tuple[Finding, ...]:
    """All findings of all checks, in check order."""
    return tuple(f for check in CHECKS for f in check(eni))


def validate_report(eni: Eni, findings: tuple[Finding, ...]) -> dict[str, Any]:
    """The ``lolacli.eni-validate/2`` document: the findings as every verdict gives them
    (:class:`lolacli.findings.Finding`; /1 had ``code`` for ``kind`` and ``error`` for
    ``failure``: ``code`` stays as an alias)."""
    errors = sum(1 for f in findings if f.severity is Severity.FAILURE)
    return {
        "schema": VALIDATE_SCHEMA,
        "source": eni.source,
        "errors": errors,
        "warnings": len(findings) - errors,
        "verdict": "fail" if errors else "pass",
        "findings": [{**f.to_dict(), "code": f.kind} for f in findings],
    }


__all__ = [
    "CHECKS",
    "RANGE_CODE",
    "VALIDATE_SCHEMA",
    "Width",
    "check_field_ranges",
    "expected_wkc",
    "validate_eni",
    "validate_report",
    "within_limits",
]
