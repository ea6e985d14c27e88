"""Registers and process RAM: what a master's write stores and what it sets off, and the
state every part of the ESC shares (memory, configuration, application, firmware side)."""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Protocol

from lolacli.emulator import registers as r
from lolacli.emulator.esc.counters import COUNTER_CLEAR_GROUPS, EscCounters
from lolacli.emulator.registers import AlState
from lolacli.emulator.sii import SiiLayout

_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
PLAN_FREE_REGISTERS = 0x0F00  # digital outputs and user RAM: no frame plan depends on them


class EscApplication(Protocol):
    """What sits behind the PDI: a device with mailbox server and process data."""

    def mailbox_request(self, request: bytes, read_bytes: int) -> list[bytes]:
        """A complete mailbox written by the master (the whole buffer of the write
        mailbox) -> mailbox messages to send back in the read mailbox of ``read_bytes``."""
        ...

    def mailbox_posted(self, message: bytes) -> bytes:
        """A message the firmware posts unasked (an emergency), as it numbers it."""
        ...

    def process_data_bytes(self) -> tuple[int, int]:
        """(outputs, inputs) sizes the current PDO mapping needs, in bytes."""
        ...

    def state_changed(self, state: AlState) -> None: ...

    def cycle(self, outputs: bytes, t_ns: int) -> bytes:
        """Outputs from the master -> inputs for the master (one process-data cycle)."""
        ...


@dataclass(frozen=True, slots=True)
class EscConfig:
    """Identity of the ESC silicon (registers 0x0000–0x000F)."""

    esc_type: int = 0x11  # ET1100-like
    revision: int = 0x02
    build: int = 0x0003
    fmmus: int = 8
    sync_managers: int = 8
    ram_kib: int = 8
    port_descriptor: int = 0x0F  # ports 0 and 1: MII; 2 and 3 not implemented
    features: int = int(r.EscFeature.DISTRIBUTED_CLOCKS | r.EscFeature.DC_64_BIT)
    eeprom_8_byte_reads: bool = True
    pdi_control: int = 0x0005  # SPI
    watchdog_divider: int = 0x09C2  # 100 µs at 25 MHz
    watchdog_time_process_data: int = 1000  # 100 ms


class EscMemory:
    """64 KiB of registers and process RAM, and what the ESC's parts share."""

    config: EscConfig
    sii: bytearray
    layout: SiiLayout
    app: EscApplication | None
    mem: bytearray
    _view: memoryview
    counters: EscCounters
    now_ns: int  # when the datagram being processed reached this slave
    last_port: bool
    # bumped whenever addressing or mapping may have changed (register writes, AL
    # states, topology): the chain's frame plans are valid for one value. A chain
    # shares one cell between its slaves.
    epoch: list[int]
    # bumped when a station address, alias or alias enable may have changed: the
    # chain's map of configured addresses is valid for one value (shared like epoch)
    addressing: list[int]
    # bumped when the SII image or its layout is replaced (power-on with another image,
    # an EEPROM reload): the C core's line of SII images and mailbox sync managers is
    # valid for one value (shared like epoch)
    sii_version: list[int]
    # The slave's firmware side (the PDI): AL control requests and mailbox writes are
    # taken by the ESC at once (the frame is answered) and handled by the firmware
    # afterwards, as on hardware. ``None``: handled at once; a list (a chain's): work
    # queued there as (function, arguments), run by the chain after the answer.
    pdi: list[tuple[Callable[..., object], tuple[Any, ...]]] | None

    def set_topology(self, *, last: bool) -> None:
        """DL status 0x0110: port 0 link+communication, port 1 too unless last in line."""
        self.last_port = last
        self.epoch[0] += 1
        status = 0x0001 | 0x0010 | 0x0200  # PDI operational, link port 0, comm port 0
        status |= 0x0400 if last else (0x0020 | 0x0800)  # port 1 closed loop, or open+comm
        status |= 0x1000 | 0x4000  # ports 2 and 3: loop closed
        _U16.pack_into(self.mem, r.DL_STATUS, status)

    @property
    def station_address(self) -> int:
        return int(_U16.unpack_from(self.mem, r.STATION_ADDRESS)[0])

    @property
    def station_alias(self) -> int:
        return int(_U16.unpack_from(self.mem, r.STATION_ALIAS)[0])

    def u16(self, address: int) -> int:
        return int(_U16.unpack_from(self.mem, address)[0])

    def u32(self, address: int) -> int:
        return int(_U32.unpack_from(self.mem, address)[0])

    @property
    def alias_enabled(self) -> bool:
        return bool(self.mem[r.DL_CONTROL_ALIAS_ENABLE_BYTE] & 0x01)

    def addressed_configured(self, adp: int) -> bool:
        if adp == self.mem[r.STATION_ADDRESS] | self.mem[r.STATION_ADDRESS + 1] << 8:
            return True
        return self.alias_enabled and adp == self.station_alias

    def hand_to_firmware(self, work: Callable[..., None], *args: Any) -> None:
        """Hand ``work`` to the slave's firmware: at once, or queued in ``pdi``."""
        if self.pdi is None:
            work(*args)
        else:
            self.pdi.append((work, args))

    def continue_in_firmware(self, work: Callable[..., None], *args: Any) -> None:
        """The rest of the piece of firmware work now running, as a piece of its own that
        comes before any other pending work (a frame may come between the two): at once
        where there is no queue."""
        if self.pdi is None:
            work(*args)
        else:
            self.pdi.insert(0, (work, args))

    def _store(self, start: int, data: bytes) -> None:
        """``data`` into memory from ``start``, as far as the memory goes (a master may
        place an SM buffer across its end; the memory never grows)."""
        end = min(start + len(data), r.MEMORY_BYTES)
        if start < end:
            self.mem[start:end] = data[: end - start]


def overlaps(a0: int, a1: int, b0: int, b1: int) -> bool:
    return a0 < b1 and b0 < a1


def _readonly_mask() -> bytearray:
    """1 where the master cannot write a register byte (ETG.1000.4 register tables)."""
    mask = bytearray(r.PROCESS_RAM)
    ranges = [
        (0x0000, 0x0010),
        (r.STATION_ALIAS, r.STATION_ALIAS + 2),
        (r.DL_STATUS, r.DL_STATUS + 2),
        (r.AL_STATUS, r.AL_STATUS + 6),
        (r.PDI_CONTROL, r.PDI_CONTROL + 2),
        (r.SII_PDI_ACCESS, r.SII_PDI_ACCESS + 1),
        (r.WD_STATUS_PD, r.WD_STATUS_PD + 2),
        (r.DC_RECEIVE_TIME_PORT0, r.DC_SYSTEM_TIME),
        (r.DC_SYSTEM_TIME, r.DC_SYSTEM_TIME + 8),
        (r.DC_RECEIVE_TIME_PU, r.DC_SYSTEM_TIME_OFFSET),
        (r.DC_SYSTEM_TIME_DIFFERENCE, r.DC_SYSTEM_TIME_DIFFERENCE + 4),
    ]
    for lo, hi in ranges:
        mask[lo:hi] = b"\x01" * (hi - lo)
    for sm in range(16):
        base = r.SM + r.SYNC_MANAGER_BYTES * sm
        mask[base + 5] = 1  # status
        mask[base + 7] = 1  # PDI control
    return mask


_READONLY = _readonly_mask()
_SM_REGISTERS_END = r.SM + 16 * r.SYNC_MANAGER_BYTES


@dataclass(frozen=True, slots=True)
class RegisterWrite:
    """What a master's write to ``[start, end)`` does beyond storing bytes: worked out once
    per address range (:func:`register_write`), the same for every ESC."""

    segments: tuple[tuple[int, int], ...]  # writable runs (read-only bytes keep their value)
    clear_groups: tuple[tuple[int, int], ...]
    configuration: bool  # FMMU or SM registers: decoded configuration stale
    watchdog: bool
    addressing: bool  # station address or alias enable
    eeprom: bool
    latch: bool
    system_time: bool
    sync_managers: bool
    al_control: bool

    effects: bool  # any of the above
    #: the bytes from ``start`` to the end of the last writable run, and the read-only
    #: ones among them as a little-endian bit mask (0: none)
    span: int = 0
    keep: int = 0

    @property
    def system_time_only(self) -> bool:
        """Whether the write's one effect is the DC time control loop's step (a master's
        BWR of the system time to every slave)."""
        others = (self.configuration, self.watchdog, self.addressing, self.eeprom, self.latch,
                  self.sync_managers, self.al_control, self.clear_groups)  # fmt: skip
        return self.system_time and not any(others)

    @property
    def memory_only(self) -> bool:
        """Whether the write leaves the ESC's clock, watchdog and decoded FMMU/SM
        configuration alone: it changes memory, and what the firmware does with it (an AL
        control request, an EEPROM command, the mailbox) runs as firmware work."""
        return not (self.configuration or self.watchdog or self.latch or self.system_time)

    def store(self, mem: bytearray, start: int, payload: bytes) -> None:
        """``payload`` into ``mem`` at ``start``, the read-only bytes keeping their value:
        in one step, masked where read-only bytes lie between writable ones (a BWR of 16
        sync managers has 32 runs: 4.7 µs a slave run by run, 0.5 µs masked)."""
        if not self.keep:
            mem[start : start + self.span] = payload[: self.span]
        else:
            self.store_bits(mem, start, self.writable_bits(payload))

    def writable_bits(self, payload: bytes) -> int:
        """``payload`` as a little-endian integer with its read-only bytes cleared (once
        for a write that many slaves take, see :meth:`store_bits`)."""
        return int.from_bytes(payload[: self.span], "little") & ~self.keep

    def store_bits(self, mem: bytearray, start: int, bits: int) -> None:
        """:meth:`store` of a payload given as :meth:`writable_bits`."""
        end = start + self.span
        old = int.from_bytes(mem[start:end], "little") & self.keep
        mem[start:end] = (old | bits).to_bytes(self.span, "little")


# what a master's write to a register byte does, for the C core's register path
# (_ccore.c, lolacli_core_registers): kept, FMMU/SM configuration or watchdog times (both
# worked out again, Esc.configuration_written), sync manager registers, the DC
# receive-time latch or system time (the kernel tells them apart by address), the EEPROM
# command, the AL control request, the station address and alias enable, an error counter
# group cleared (COUNTER_CLEAR_GROUPS)
REGISTER_READONLY, REGISTER_CONFIGURATION, REGISTER_SYNC_MANAGER = 1, 2, 4
REGISTER_DC, REGISTER_EEPROM, REGISTER_AL_CONTROL, REGISTER_ADDRESSING = 8, 16, 32, 64
REGISTER_CLEAR = 128

#: the registers whose write does more than store bytes: each of RegisterWrite's flags,
#: its ranges, and the class register_classes gives their bytes
_EFFECTS: tuple[tuple[str, tuple[tuple[int, int], ...], int], ...] = (
    ("configuration", ((r.FMMU, _SM_REGISTERS_END),), REGISTER_CONFIGURATION),
    ("watchdog", ((r.WATCHDOG_DIVIDER, r.WD_TIME_PD + 2),), REGISTER_CONFIGURATION),
    ("addressing", ((r.STATION_ADDRESS, r.STATION_ADDRESS + 2),
                    (r.DL_CONTROL_ALIAS_ENABLE_BYTE, r.DL_CONTROL_ALIAS_ENABLE_BYTE + 1)),
     REGISTER_ADDRESSING),
    ("eeprom", ((r.SII_CONTROL_STATUS, r.SII_CONTROL_STATUS + 2),), REGISTER_EEPROM),
    ("latch", ((r.DC_RECEIVE_TIME_PORT0, r.DC_RECEIVE_TIME_PORT0 + 4),), REGISTER_DC),
    ("system_time", ((r.DC_SYSTEM_TIME, r.DC_SYSTEM_TIME + 8),), REGISTER_DC),
    ("sync_managers", ((r.SM, r.SM + 16 * 8),), REGISTER_SYNC_MANAGER),
    ("al_control", ((r.AL_CONTROL, r.AL_CONTROL + 1),), REGISTER_AL_CONTROL),
)


@lru_cache(maxsize=4096)
def register_write(start: int, end: int) -> RegisterWrite:
    segments: list[tuple[int, int]] = []
    run: int | None = None
    for a in range(start, min(end, r.PROCESS_RAM)):
        if _READONLY[a]:
            if run is not None:
                segments.append((run, a))
                run = None
        elif run is None:
            run = a
    if run is not None:
        segments.append((run, min(end, r.PROCESS_RAM)))
    if end > r.PROCESS_RAM:
        if segments and segments[-1][1] == r.PROCESS_RAM:
            segments[-1] = (segments[-1][0], end)
        else:
            segments.append((r.PROCESS_RAM, end))

    def hit(lo: int, hi: int) -> bool:
        return overlaps(start, end, lo, hi)

    clear_groups = tuple(g for g in COUNTER_CLEAR_GROUPS if hit(*g))
    flags = {name: any(hit(lo, hi) for lo, hi in ranges) for name, ranges, _ in _EFFECTS}
    span = segments[-1][1] - start if segments else 0
    keep = 0
    for a in range(start, start + span):
        if a < r.PROCESS_RAM and _READONLY[a]:
            keep |= 0xFF << (8 * (a - start))
    return RegisterWrite(
        tuple(segments), clear_groups, **flags,
        effects=bool(clear_groups) or any(flags.values()), span=span, keep=keep,
    )


@lru_cache(maxsize=1)
def register_classes() -> bytes:
    """One class per register byte (0x0000-0x0FFF), from :func:`register_write` of that
    byte alone: a write's effects are those of its bytes together."""
    out = bytearray(REGISTER_READONLY if ro else 0 for ro in _READONLY)
    for _, ranges, cls in _EFFECTS:
        for lo, hi in ranges:
            for a in range(max(lo, 0), min(hi, r.PROCESS_RAM)):
                out[a] |= cls
    for lo, hi in COUNTER_CLEAR_GROUPS:
        for a in range(max(lo, 0), min(hi, r.PROCESS_RAM)):
            out[a] |= REGISTER_CLEAR
    return bytes(out)
