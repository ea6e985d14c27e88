"""JSON-ready reports over an :class:`~lolacli.eni.model.Eni` (pure: model in, dicts out).

Contracts (docs/cli.md): ``lolacli.eni/1`` (inspect), ``lolacli.eni-vars/1``.
Wire numbers follow docs/architecture.md "Definitions": frame bytes from
:func:`lolacli.wire.frame.frame_bytes_on_wire`, wire time ``8 × bytes / rate``, and the time
with overhead adds preamble+SFD (8 B) and the inter-frame gap (12 B).
"""

from __future__ import annotations

import fnmatch
from dataclasses import dataclass
from typing import Any

from lolacli.eni.model import (
    ConfiguredFmmu,
    ConfiguredSyncManager,
    CyclicCommand,
    CyclicFrame,
    Eni,
    Pdo,
    PdoEntry,
    Slave,
    Variable,
)
from lolacli.text import object_entry, station
from lolacli.wire.al import AlState
from lolacli.wire.commands import AUTO_INCREMENT, BROADCAST, CONFIGURED, mnemonic

INSPECT_SCHEMA = "lolacli.eni/1"
VARS_SCHEMA = "lolacli.eni-vars/1"

LINK_BITS_PER_S = 100_000_000
PREAMBLE_SFD_BYTES = 8
INTER_FRAME_GAP_BYTES = 12


def wire_time_ns(frame_bytes: int, link_bits_per_s: int = LINK_BITS_PER_S) -> int:
    """8 × bytes / rate, in integer nanoseconds (rounded)."""
    return (8 * frame_bytes * 1_000_000_000 + link_bits_per_s // 2) // link_bits_per_s


def _us(ns: int | None) -> float | None:
    return None if ns is None else round(ns / 1000, 2)


def _hex(value: int | None, digits: int = 4) -> str | None:
    return None if value is None else f"0x{value:0{digits}X}"


def ordered_states(states: tuple[str, ...]) -> list[str]:
    """The states a datagram is sent in, a set: each once, in the state machine's order
    (INIT, PREOP, BOOT, SAFEOP, OP; a name outside it last), whatever order the ENI lists
    them in, so the same set is written (and compared) the same way everywhere."""
    return sorted(set(states), key=lambda s: (AlState[s] if s in AlState.__members__ else 99, s))


def datagram_dict(c: CyclicCommand) -> dict[str, Any]:
    return {
        "cmd": mnemonic(c.cmd),
        "adp": c.adp,
        "ado": c.ado,
        "logical_address": c.logical_address,
        "length_bytes": c.data_length_bytes,
        "expected_wkc": c.expected_wkc,
        "input_offset_bytes": c.input_offset_bytes,
        "output_offset_bytes": c.output_offset_bytes,
        "states": ordered_states(c.states),
    }


def datagram_where(c: CyclicCommand) -> str:
    """Where a datagram reads or writes, in words: ``logical 0x00010000``, ``0x0130 at
    0x03E9 (1001)`` (configured address), ``0x0910 at position 1`` (auto-increment),
    ``0x0130 of every slave`` (broadcast)."""
    if c.logical_address is not None:
        return f"logical 0x{c.logical_address:08X}"
    adp, ado = c.adp or 0, c.ado or 0
    if c.cmd in CONFIGURED:
        return f"0x{ado:04X} at {station(adp)}"
    if c.cmd in AUTO_INCREMENT:
        return f"0x{ado:04X} at position {((-adp) & 0xFFFF) + 1}"
    if c.cmd in BROADCAST:
        return f"0x{ado:04X} of every slave"
    return f"ADP 0x{adp:04X} ADO 0x{ado:04X}"


def frame_dict(frame: CyclicFrame) -> dict[str, Any]:
    n = frame.frame_bytes
    overhead = n + PREAMBLE_SFD_BYTES + INTER_FRAME_GAP_BYTES
    return {
        "datagrams": [datagram_dict(c) for c in frame.commands],
        "frame_bytes": n,
        "wire_time_us": _us(wire_time_ns(n)),
        "wire_time_with_overhead_us": _us(wire_time_ns(overhead)),
    }


def slave_dict(s: Slave) -> dict[str, Any]:
    mailbox = s.mailbox
    return {
        "position": s.position,
        "name": s.name,
        "vendor_id": s.identity.vendor_id,
        "product_code": s.identity.product_code,
        "revision": s.identity.revision,
        "serial": s.identity.serial,
        "station_address": s.station_address,
        "auto_inc_address": s.auto_inc_address,
        "inputs_bits": s.inputs_bits,
        "outputs_bits": s.outputs_bits,
        "previous_port": s.previous_port,
        "previous_station_address": s.previous_station_address,
        "mailbox_protocols": list(mailbox.protocols) if mailbox else [],
        "coe_init_cmds": len(mailbox.coe_init_cmds) if mailbox else 0,
        "init_cmds": len(s.init_cmds),
        "dc": _dc_dict(s),
        "sync_managers": [_sync_manager_dict(m) for m in s.sync_managers],
        "fmmus": [_fmmu_dict(f) for f in s.fmmus],
        "pdos_assigned": [
            {"index": p.index, "name": p.name, "sync_manager": p.sync_manager, "bits": p.bit_size}
            for p in s.pdos
            if p.sync_manager is not None
        ],
    }


def _sync_manager_dict(m: ConfiguredSyncManager) -> dict[str, Any]:
    sm = m.sync_manager
    return {
        "index": m.index,
        "start_address": sm.physical_start,
        "length_bytes": sm.length_bytes,
        "control": sm.control,
        "enable": sm.enabled,
        "kind": m.kind,
    }


def _fmmu_dict(m: ConfiguredFmmu) -> dict[str, Any]:
    """The ``lolacli.eni-inspect`` keys: ``logical_end_bit`` is the register's stop bit,
    ``enable`` its activate bit 0."""
    f = m.fmmu
    return {
        "index": m.index,
        "logical_start": f.logical_start,
        "length_bytes": f.length_bytes,
        "logical_start_bit": f.logical_start_bit,
        "logical_end_bit": f.logical_stop_bit,
        "physical_start": f.physical_start,
        "type": f.type,
        "enable": f.enabled,
    }


def _dc_dict(s: Slave) -> dict[str, Any] | None:
    if s.dc is None:
        return None
    return {
        "reference_clock": s.dc.reference_clock,
        "cycle_time0_ns": s.dc.cycle_time0_ns,
        "cycle_time1_ns": s.dc.cycle_time1_ns,
        "shift_time_ns": s.dc.shift_time_ns,
        "assign_activate": s.dc.assign_activate,
    }


@dataclass(frozen=True, slots=True)
class VariableSource:
    """Where a process-image variable comes from: a PDO entry of an assigned PDO."""

    slave: Slave
    pdo: Pdo
    entry: PdoEntry


def variable_sources(eni: Eni) -> dict[tuple[str, str], VariableSource]:
    """The PDO entry behind each variable, by (direction, name), where the ENI gives it.

    An ENI's <ProcessImage> names a variable ``<slave>.<PDO>.<entry>`` (ETG.2100, as
    TwinCAT and the EC-Engineer write it) without its index; the entry is the one of that
    name in a PDO its slave assigns to a sync manager, of the variable's direction and bit
    size and, where the slave gives its <ProcessData> areas, inside them. A name that fits
    no entry (TwinCAT's WcState and frame-state variables) or two different ones has none.
    """
    variables = {(v.direction.value, v.name): v for v in eni.process_image.variables}
    found: dict[tuple[str, str], list[VariableSource]] = {}
    for s in eni.slaves:
        for pdo in s.pdos:
            if pdo.sync_manager is None:
                continue
            for e in pdo.entries:
                key = (pdo.direction.value, f"{s.name}.{pdo.name}.{e.name}")
                v = variables.get(key)
                if e.index and v is not None and v.bit_size == e.bit_size and _inside(v, s):
                    found.setdefault(key, []).append(VariableSource(s, pdo, e))
    return {
        key: sources[0]
        for key, sources in found.items()
        if len({(x.pdo.index, x.entry.index, x.entry.subindex) for x in sources}) == 1
    }


def _inside(v: Variable, s: Slave) -> bool:
    """Within one of the slave's <ProcessData> areas of that direction (True without any)."""
    areas = s.inputs if v.direction.value == "input" else s.outputs
    return not areas or any(
        a.bit_start <= v.bit_offset and v.bit_offset + v.bit_size <= a.bit_start + a.bit_length
        for a in areas
    )


def variable_dict(v: Variable, source: VariableSource | None = None) -> dict[str, Any]:
    """A variable's keys: name, direction, bit offset and size, data type, and its PDO
    (``pdo_index`` "0x1A00") and PDO entry (``pdo_entry`` "0x6041:00"), null where the ENI
    does not give them."""
    return {
        "name": v.name,
        "direction": v.direction.value,
        "bit_offset": v.bit_offset,
        "bit_size": v.bit_size,
        "data_type": v.data_type,
        "pdo_index": f"0x{source.pdo.index:04X}" if source else None,
        "pdo_entry": object_entry(source.entry.index, source.entry.subindex) if source else None,
    }


def inspect_report(eni: Eni) -> dict[str, Any]:
    """The ``lolacli.eni/1`` document of ``eni inspect``."""
    frames = [frame_dict(f) for f in eni.cyclic_frames]
    pi = eni.process_image
    sources = variable_sources(eni)
    return {
        "schema": INSPECT_SCHEMA,
        "source": eni.source,
        "root": eni.root,
        "cycle_time_us": _us(eni.cycle_time_ns),
        "master_cycle_time_us": _us(eni.master.cycle_time_ns),
        "master": {
            "name": eni.master.name,
            "destination_mac": eni.master.destination_mac.hex(":"),
            "source_mac": eni.master.source_mac.hex(":"),
            "ethertype": eni.master.ethertype,
            "init_cmds": len(eni.master.init_cmds),
        },
        "slave_count": len(eni.slaves),
        "slaves": [slave_dict(s) for s in eni.slaves],
        "cyclic_frames": frames,
        "frames_bytes_total": sum(f["frame_bytes"] for f in frames),
        "process_image": {
            "inputs_bytes": pi.inputs_bytes,
            "outputs_bytes": pi.outputs_bytes,
            "variable_count": len(pi.variables),
            "variables": [variable_dict(v, sources.get((v.direction.value, v.name)))
                          for v in pi.variables],
        },
    }


def filter_variables(eni: Eni, pattern: str | None) -> tuple[Variable, ...]:
    """Variables whose name matches the glob ``pattern`` (case-insensitive); all if None."""
    variables = eni.process_image.variables
    if not pattern:
        return variables
    glob = pattern.casefold()
    return tuple(v for v in variables if fnmatch.fnmatchcase(v.name.casefold(), glob))


def vars_report(eni: Eni, pattern: str | None = None) -> dict[str, Any]:
    """The ``lolacli.eni-vars/1`` document of ``eni vars``."""
    chosen = filter_variables(eni, pattern)
    sources = variable_sources(eni)
    return {
        "schema": VARS_SCHEMA,
        "source": eni.source,
        "filter": pattern,
        "count": len(chosen),
        "variables": [_vars_row(v, sources.get((v.direction.value, v.name))) for v in chosen],
    }


#: the keys of each ``eni vars`` variable, in order: the columns of ``--format csv``
VARS_FIELDS = (
    "name",
    "direction",
    "bit_offset",
    "byte_offset",
    "bit_size",
    "data_type",
    "pdo_index",
    "pdo_entry",
    "slave_station_address",
    "comment",
)


def _vars_row(v: Variable, source: VariableSource | None) -> dict[str, Any]:
    row = variable_dict(v, source) | {
        "byte_offset": v.bit_offset // 8,
        "slave_station_address": source.slave.station_address if source else None,
        "comment": v.comment,
    }
    return {key: row[key] for key in VARS_FIELDS}


__all__ = [
    "INSPECT_SCHEMA",
    "VARS_FIELDS",
    "VARS_SCHEMA",
    "VariableSource",
    "datagram_where",
    "filter_variables",
    "frame_dict",
    "inspect_report",
    "variable_sources",
    "vars_report",
    "wire_time_ns",
]
