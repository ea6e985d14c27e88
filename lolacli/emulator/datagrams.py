"""The chain's general path: where each datagram sits in the frame (:class:`Slot`), found
fast for the usual untagged command frame (:func:`slots`) and by the full decoder for the
rest (:func:`parse`), and the datagrams run through the slaves one after the other
(:func:`run_slots`)."""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from lolacli.emulator.esc import (
    Esc,
    PortTimes,
    broadcast_of_registers,
    broadcast_read,
    broadcast_write,
)
from lolacli.emulator.registers import FMMU, PROCESS_RAM, SM, SYNC_MANAGER_BYTES
from lolacli.errors import WireError
from lolacli.wire.commands import LOGICAL, Command
from lolacli.wire.frame import (
    DATAGRAM_HEADER_BYTES,
    ECAT_HEADER_BYTES,
    ECAT_TYPE_COMMANDS,
    WKC_BYTES,
    decode_ethernet_header,
    decode_frame,
)

if TYPE_CHECKING:
    from lolacli.emulator.core import ChainCore

_HEAD = struct.Struct("<BBHHH")  # cmd, index, adp, ado, length word
_U16 = struct.Struct("<H")
_READS_ONLY = frozenset({Command.APRD, Command.FPRD, Command.BRD})
_APRD, _FPRD, _BRD, _BWR = int(Command.APRD), int(Command.FPRD), int(Command.BRD), int(Command.BWR)
_APWR, _FPWR = int(Command.APWR), int(Command.FPWR)
_AUTO_INCREMENT_SINGLE = frozenset({Command.APRD, Command.APWR, Command.APRW})
_CONFIGURED_SINGLE = frozenset({Command.FPRD, Command.FPWR, Command.FPRW})


@dataclass(slots=True)
class Slot:
    """A datagram's place in the frame."""

    header: int  # offset of the datagram header in the frame
    cmd: int
    length: int
    adp: int  # as the next slave sees it
    ado: int


# FMMU and SM registers: where a device cycle's data go
_SM_AND_FMMU = (FMMU, SM + 16 * SYNC_MANAGER_BYTES)


def touches_process_data(slots: list[Slot]) -> bool:
    """Whether a frame may see or change what a held device cycle reads and writes: the
    SM buffers in process RAM (logical datagrams, physical ones from 0x1000) and the
    FMMU/SM registers. Register reads and other register writes may go first, as they
    would on a slave whose application is late (AL control requests wait for the
    firmware anyway)."""
    lo, hi = _SM_AND_FMMU
    for slot in slots:
        cmd = slot.cmd
        if cmd in LOGICAL or slot.ado + slot.length > PROCESS_RAM:
            return True
        if cmd not in _READS_ONLY and slot.ado < hi and lo < slot.ado + slot.length:
            return True
    return False


def slots(frame: bytes) -> list[Slot] | None:
    """The datagrams of an untagged EtherCAT command frame; ``None`` for anything else
    (the full decoder then tells a tagged frame from a malformed one). Accepts what
    :func:`lolacli.wire.frame.decode_frame` accepts for such frames."""
    n = len(frame)
    if n < 16 or frame[12] != 0x88 or frame[13] != 0xA4:
        return None
    word = frame[14] | frame[15] << 8
    end = 16 + (word & 0x7FF)
    if word >> 12 != ECAT_TYPE_COMMANDS or end > n:
        return None
    out = []
    pos = 16
    unpack = _HEAD.unpack_from
    while True:
        if pos + DATAGRAM_HEADER_BYTES > end:
            return None
        cmd, _index, adp, ado, lenw = unpack(frame, pos)
        length = lenw & 0x7FF
        out.append(Slot(pos, cmd, length, adp, ado))
        pos += DATAGRAM_HEADER_BYTES + length + WKC_BYTES
        if pos > end:
            return None
        if not lenw & 0x8000:
            return out


def parse(frame: bytes) -> list[Slot] | None:
    """The datagrams of any frame by the full decoder: ``[]`` for another EtherCAT type,
    ``None`` for a malformed frame."""
    try:
        decoded = decode_frame(frame)
        _header, _etype, pos = decode_ethernet_header(frame)
    except WireError:
        return None
    if decoded.ecat_type != ECAT_TYPE_COMMANDS:
        return []
    out = []
    pos += ECAT_HEADER_BYTES
    for d in decoded.datagrams:
        out.append(Slot(pos, d.cmd, len(d.data), d.adp, d.ado))
        pos += DATAGRAM_HEADER_BYTES + len(d.data) + WKC_BYTES
    return out


def run_slots(
    buf: bytearray,
    found: list[Slot],
    processing: list[Esc],
    offsets: list[PortTimes],
    core: ChainCore | None,
    station_position: Callable[[int], int],
    t_ns: int,
) -> bool:
    """Run the datagrams through the slaves ``processing`` (reached ``offsets`` after the
    frame's start); ADP and WKC fields updated in ``buf``. True when a datagram was logical.

    Datagram by datagram, each through the slaves it reaches, which is the order the
    frame passes them in for every slave (slave-major) as long as slaves meet only
    through the frame's bytes; a single-slave datagram goes straight to its slave.
    With the C core, the ESC state it holds of the slaves a datagram reaches comes
    back to their Esc objects first (one slave for APxx/FPxx, all for the rest)."""
    view = memoryview(buf)
    reached = len(processing)
    released = core.released if core is not None else None
    logical = False
    for slot in found:
        cmd, ado = slot.cmd, slot.ado
        start = slot.header + DATAGRAM_HEADER_BYTES
        data = view[start : start + slot.length]
        added = 0
        if cmd in _AUTO_INCREMENT_SINGLE:
            position = (-slot.adp) & 0xFFFF
            if position < reached:
                if released is not None and position not in released:
                    core.release((position,))  # type: ignore[union-attr]
                if cmd == _APRD:
                    esc = processing[position]
                    t = t_ns + offsets[position].port0_ns
                    added = esc.read_addressed(cmd, 0, ado, data, t)
                else:
                    added = _one(processing[position], offsets[position], cmd, 0, ado, data, t_ns)
            slot.adp = (slot.adp + reached) & 0xFFFF  # every slave incremented it
        elif cmd in _CONFIGURED_SINGLE:
            position = station_position(slot.adp)
            if position < reached:
                if released is not None and position not in released:
                    core.release((position,))  # type: ignore[union-attr]
                if cmd == _FPRD:
                    esc = processing[position]
                    t = t_ns + offsets[position].port0_ns
                    added = esc.read_addressed(cmd, slot.adp, ado, data, t)
                else:
                    added = _one(
                        processing[position], offsets[position], cmd, slot.adp, ado, data, t_ns
                    )
        else:
            held = core is not None and broadcast_of_registers(cmd, ado, slot.length)
            if core is not None and not held:
                core.release()  # broadcast, logical, xRMW: every slave takes part
            if (
                cmd == _BRD
                and (got := broadcast_read(processing, offsets, ado, data, t_ns)) is not None
            ):
                added = got
                slot.adp = (slot.adp + reached) & 0xFFFF
            elif (
                cmd == _BWR
                and (got := broadcast_write(processing, offsets, ado, data, t_ns)) is not None
            ):
                added = got
                slot.adp = (slot.adp + reached) & 0xFFFF
            else:
                logical = logical or cmd in LOGICAL
                adp = slot.adp
                for esc, port in zip(processing, offsets, strict=False):
                    esc.frame_t_ns = t_ns
                    esc.port_offsets = port
                    adp, wkc = esc.process(cmd, adp, ado, data, t_ns + port.port0_ns)
                    added += wkc
                slot.adp = adp
            if held:  # registers only: the core keeps the slaves, with their new time
                core.note_times(reached)  # type: ignore[union-attr]
        data.release()
        _U16.pack_into(buf, slot.header + 2, slot.adp)
        if added:
            at = start + slot.length
            _U16.pack_into(buf, at, (_U16.unpack_from(buf, at)[0] + added) & 0xFFFF)
    view.release()
    return logical


def _one(
    esc: Esc, port: PortTimes, cmd: int, adp: int, ado: int, data: memoryview, t_ns: int
) -> int:
    esc.frame_t_ns = t_ns
    esc.port_offsets = port
    if cmd == _APWR or cmd == _FPWR:  # registers stored straight, no dispatch
        return esc.write_addressed(cmd, adp, ado, data, t_ns + port.port0_ns)
    return esc.process(cmd, adp, ado, data, t_ns + port.port0_ns)[1]
