"""ESC registers: addresses, AL states and status codes, FMMU and sync-manager structs.

Addresses follow ETG.1000.4 §6 (Tables 31–68, "ESC register map") and the ESC datasheets
(Beckhoff ET1100/ET1200 Section II). Multi-byte registers are little endian.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum, IntFlag

from lolacli.errors import UsageError, WireError
from lolacli.wire._codes import enum_or_int, need
from lolacli.wire.al import AL_ERROR_INDICATOR as AL_ERROR_INDICATOR
from lolacli.wire.al import AL_STATE_MASK as AL_STATE_MASK
from lolacli.wire.al import AlState as AlState
from lolacli.wire.al import al_error as al_error
from lolacli.wire.al import al_state as al_state
from lolacli.wire.al import al_state_name as al_state_name
from lolacli.wire.al import al_status_text as al_status_text

FMMU_BYTES = 16
SYNC_MANAGER_BYTES = 8
FMMU_COUNT_MAX = 16
SYNC_MANAGER_COUNT_MAX = 16


class Register(IntEnum):
    """ESC register addresses (ETG.1000.4 §6; ET1100 datasheet Section II, Table 2)."""

    TYPE = 0x0000
    REVISION = 0x0001
    BUILD = 0x0002
    FMMU_COUNT = 0x0004
    SM_COUNT = 0x0005
    RAM_SIZE = 0x0006
    PORT_DESCRIPTOR = 0x0007
    ESC_FEATURES = 0x0008
    STATION_ADDRESS = 0x0010
    STATION_ALIAS = 0x0012
    WRITE_ENABLE = 0x0020
    WRITE_PROTECTION = 0x0021
    ESC_WRITE_ENABLE = 0x0030
    ESC_WRITE_PROTECTION = 0x0031
    ESC_RESET_ECAT = 0x0040
    ESC_RESET_PDI = 0x0041
    DL_CONTROL = 0x0100
    PHYSICAL_READ_WRITE_OFFSET = 0x0108
    DL_STATUS = 0x0110
    AL_CONTROL = 0x0120
    AL_STATUS = 0x0130
    AL_STATUS_CODE = 0x0134
    RUN_LED_OVERRIDE = 0x0138
    ERR_LED_OVERRIDE = 0x0139
    PDI_CONTROL = 0x0140
    ESC_CONFIGURATION = 0x0141
    PDI_CONFIGURATION = 0x0150
    SYNC_LATCH_CONFIGURATION = 0x0151
    EXTENDED_PDI_CONFIGURATION = 0x0152
    ECAT_EVENT_MASK = 0x0200
    PDI_EVENT_MASK = 0x0204
    ECAT_EVENT_REQUEST = 0x0210
    AL_EVENT_REQUEST = 0x0220
    RX_ERROR_COUNTER = 0x0300  # 4 ports × (invalid frame u8, RX error u8)
    FORWARDED_RX_ERROR_COUNTER = 0x0308
    PROCESSING_UNIT_ERROR_COUNTER = 0x030C
    PDI_ERROR_COUNTER = 0x030D
    LOST_LINK_COUNTER = 0x0310
    WATCHDOG_DIVIDER = 0x0400
    WD_TIME_PDI = 0x0410
    WD_TIME_PD = 0x0420
    WD_STATUS_PD = 0x0440
    WD_COUNTER_PD = 0x0442
    WD_COUNTER_PDI = 0x0443
    SII_CONFIG = 0x0500
    SII_PDI_ACCESS = 0x0501
    SII_CONTROL_STATUS = 0x0502
    SII_ADDRESS = 0x0504
    SII_DATA = 0x0508
    MII_CONTROL_STATUS = 0x0510
    MII_PHY_ADDRESS = 0x0512
    MII_PHY_REGISTER = 0x0513
    MII_PHY_DATA = 0x0514
    FMMU = 0x0600
    SM = 0x0800
    DC_RECEIVE_TIME_PORT0 = 0x0900
    DC_RECEIVE_TIME_PORT1 = 0x0904
    DC_RECEIVE_TIME_PORT2 = 0x0908
    DC_RECEIVE_TIME_PORT3 = 0x090C
    DC_SYSTEM_TIME = 0x0910
    DC_RECEIVE_TIME_PU = 0x0918
    DC_SYSTEM_TIME_OFFSET = 0x0920
    DC_SYSTEM_TIME_DELAY = 0x0928
    DC_SYSTEM_TIME_DIFFERENCE = 0x092C
    DC_SPEED_COUNTER_START = 0x0930
    DC_SPEED_COUNTER_DIFF = 0x0932
    DC_FILTER_DEPTH_SYSTEM_TIME = 0x0934
    DC_FILTER_DEPTH_SPEED_COUNTER = 0x0935
    DC_CYCLIC_UNIT_CONTROL = 0x0980
    DC_ACTIVATION = 0x0981
    DC_SYNC_IMPULSE_LENGTH = 0x0982
    DC_ACTIVATION_STATUS = 0x0984
    DC_SYNC0_STATUS = 0x098E
    DC_SYNC1_STATUS = 0x098F
    DC_START_TIME_CYCLIC = 0x0990
    DC_NEXT_SYNC1_PULSE = 0x0998
    DC_SYNC0_CYCLE = 0x09A0
    DC_SYNC1_CYCLE = 0x09A4
    DC_LATCH0_CONTROL = 0x09A8
    DC_LATCH1_CONTROL = 0x09A9
    DC_LATCH0_STATUS = 0x09AE
    DC_LATCH1_STATUS = 0x09AF
    ESC_SPECIFIC = 0x0E00
    DIGITAL_IO_OUTPUT = 0x0F00
    GENERAL_PURPOSE_OUTPUT = 0x0F10
    GENERAL_PURPOSE_INPUT = 0x0F18
    USER_RAM = 0x0F80
    PROCESS_RAM = 0x1000


def fmmu_address(n: int) -> int:
    """Address of FMMU ``n`` (0x0600 + 16 n)."""
    return Register.FMMU + FMMU_BYTES * n


def sync_manager_address(n: int) -> int:
    """Address of sync manager ``n`` (0x0800 + 8 n)."""
    return Register.SM + SYNC_MANAGER_BYTES * n


class AlStatusCode(IntEnum):
    """AL status codes a slave raises and masters act on (ETG.1000.6 Table 11); every code
    has its text in :func:`al_status_text`."""

    NO_ERROR = 0x0000
    UNSPECIFIED_ERROR = 0x0001
    INVALID_REQUESTED_STATE_CHANGE = 0x0011
    UNKNOWN_REQUESTED_STATE = 0x0012
    BOOTSTRAP_NOT_SUPPORTED = 0x0013
    INVALID_MAILBOX_CONFIGURATION_BOOT = 0x0015
    INVALID_MAILBOX_CONFIGURATION_PREOP = 0x0016
    INVALID_SYNC_MANAGER_CONFIGURATION = 0x0017
    NO_VALID_INPUTS = 0x0018
    NO_VALID_OUTPUTS = 0x0019
    SYNCHRONIZATION_ERROR = 0x001A
    SYNC_MANAGER_WATCHDOG = 0x001B
    INVALID_SYNC_MANAGER_TYPES = 0x001C
    INVALID_OUTPUT_CONFIGURATION = 0x001D
    INVALID_INPUT_CONFIGURATION = 0x001E
    INVALID_WATCHDOG_CONFIGURATION = 0x001F
    INVALID_INPUT_MAPPING = 0x0024
    INVALID_OUTPUT_MAPPING = 0x0025
    INVALID_DC_SYNC_CONFIGURATION = 0x0030
    DC_SYNC0_CYCLE_TIME = 0x0036


# --- FMMU and sync manager ----------------------------------------------------------------

#: FMMU register block: logical start u32, length u16, logical start bit u8, logical stop
#: bit u8, physical start u16, physical start bit u8, type u8, activate u8, 3 reserved
_FMMU = struct.Struct("<IHBBHBBB3s")
#: Sync-manager register block: physical start u16, length u16, control u8, status u8,
#: activate u8, PDI control u8 (the emulated ESC unpacks its registers with it directly)
SYNC_MANAGER_LAYOUT = struct.Struct("<HHBBBB")
_SM = SYNC_MANAGER_LAYOUT


class FmmuType(IntFlag):
    """FMMU type register bits (ETG.1000.4 Table 57): read = inputs, write = outputs."""

    READ = 0x01
    WRITE = 0x02


@dataclass(frozen=True, slots=True)
class Fmmu:
    """One FMMU (16 bytes at 0x0600 + 16 n; ETG.1000.4 Table 57)."""

    logical_start: int
    length_bytes: int
    logical_start_bit: int = 0
    logical_stop_bit: int = 7
    physical_start: int = 0
    physical_start_bit: int = 0
    type: int = 0
    activate: int = 0
    reserved: bytes = bytes(3)

    @property
    def enabled(self) -> bool:
        return bool(self.activate & 1)


def decode_fmmu(buf: bytes | memoryview, offset: int = 0) -> Fmmu:
    need(buf, offset, FMMU_BYTES, "FMMU")
    return Fmmu(*_FMMU.unpack_from(buf, offset))


def encode_fmmu(f: Fmmu) -> bytes:
    if len(f.reserved) != 3:
        raise WireError("FMMU reserved field must be 3 bytes")
    return _FMMU.pack(
        f.logical_start & 0xFFFFFFFF,
        f.length_bytes & 0xFFFF,
        f.logical_start_bit & 0xFF,
        f.logical_stop_bit & 0xFF,
        f.physical_start & 0xFFFF,
        f.physical_start_bit & 0xFF,
        f.type & 0xFF,
        f.activate & 0xFF,
        f.reserved,
    )


#: Sync-manager bits (ETG.1000.4 Table 59): control byte mode (bits 0–1) and direction
#: (bits 2–3), watchdog trigger; status byte mailbox full; activate; PDI control.
SM_CONTROL_MODE_MASK = 0x03
SM_MODE_BUFFERED = 0x00
SM_MODE_MAILBOX = 0x02
SM_CONTROL_DIRECTION_MASK = 0x0C
SM_DIRECTION_READ = 0x00  # ECAT reads, PDI writes (inputs, mailbox in)
SM_DIRECTION_WRITE = 0x04  # ECAT writes, PDI reads (outputs, mailbox out)
SM_CONTROL_WATCHDOG = 0x40
SM_STATUS_MAILBOX_FULL = 0x08
SM_ACTIVATE_ENABLE = 0x01
SM_CONTROL_PDI_EVENT = 0x20  # bit 5: the PDI gets an event on each access
#: the usual control bytes (what configurators write and SII gives): mailbox out (written
#: by the master), mailbox in (read by it), outputs (buffered, written, watchdog), inputs
SM_CONTROL_MAILBOX_OUT = SM_MODE_MAILBOX | SM_DIRECTION_WRITE | SM_CONTROL_PDI_EVENT
SM_CONTROL_MAILBOX_IN = SM_MODE_MAILBOX | SM_DIRECTION_READ | SM_CONTROL_PDI_EVENT
SM_CONTROL_OUTPUTS = SM_DIRECTION_WRITE | SM_CONTROL_PDI_EVENT | SM_CONTROL_WATCHDOG
SM_CONTROL_INPUTS = SM_MODE_BUFFERED | SM_DIRECTION_READ | SM_CONTROL_PDI_EVENT
SM_PDI_DEACTIVATE = 0x01


@dataclass(frozen=True, slots=True)
class SyncManager:
    """One sync manager channel (8 bytes at 0x0800 + 8 n; ETG.1000.4 Table 59).

    ``control``: mode bits 0–1 (0 buffered, 2 mailbox), direction bits 2–3 (0 read by
    the master, 1 written by it). ``status`` is read-only on the ESC. ``activate`` bit 0
    enables the channel; ``pdi_control`` bit 0 lets the PDI deactivate it.
    """

    physical_start: int
    length_bytes: int
    control: int = 0
    status: int = 0
    activate: int = 0
    pdi_control: int = 0

    @property
    def enabled(self) -> bool:
        return bool(self.activate & SM_ACTIVATE_ENABLE)

    @property
    def mailbox(self) -> bool:
        return (self.control & SM_CONTROL_MODE_MASK) == SM_MODE_MAILBOX

    @property
    def master_writes(self) -> bool:
        return (self.control & SM_CONTROL_DIRECTION_MASK) == SM_DIRECTION_WRITE


def decode_sync_manager(buf: bytes | memoryview, offset: int = 0) -> SyncManager:
    need(buf, offset, SYNC_MANAGER_BYTES, "sync manager")
    return SyncManager(*_SM.unpack_from(buf, offset))


def encode_sync_manager(sm: SyncManager) -> bytes:
    return _SM.pack(
        sm.physical_start & 0xFFFF,
        sm.length_bytes & 0xFFFF,
        sm.control & 0xFF,
        sm.status & 0xFF,
        sm.activate & 0xFF,
        sm.pdi_control & 0xFF,
    )


def decode_fmmus(buf: bytes | memoryview) -> tuple[Fmmu, ...]:
    """All whole FMMUs in a block read from 0x0600."""
    return tuple(decode_fmmu(buf, i) for i in range(0, len(buf) - FMMU_BYTES + 1, FMMU_BYTES))


def decode_sync_managers(buf: bytes | memoryview) -> tuple[SyncManager, ...]:
    """All whole sync managers in a block read from 0x0800."""
    step = SYNC_MANAGER_BYTES
    return tuple(decode_sync_manager(buf, i) for i in range(0, len(buf) - step + 1, step))


# --- distributed clocks -------------------------------------------------------------------

_U32 = struct.Struct("<I")


def decode_system_time_difference(buf: bytes | memoryview, offset: int = 0) -> int:
    """Register 0x092C as signed nanoseconds.

    Sign and magnitude (ET1100 datasheet, "System Time Difference"): bits 0–30 are the
    magnitude, bit 31 set means the local copy of the system time is smaller than the
    received system time; the result is then negative (local − received).
    """
    need(buf, offset, 4, "system time difference")
    raw: int = _U32.unpack_from(buf, offset)[0]
    magnitude = raw & 0x7FFFFFFF
    return -magnitude if raw & 0x80000000 else magnitude


def encode_system_time_difference(difference_ns: int) -> bytes:
    magnitude = abs(difference_ns)
    if magnitude > 0x7FFFFFFF:
        raise WireError(f"system time difference {difference_ns} ns out of range")
    return _U32.pack(magnitude | (0x80000000 if difference_ns < 0 else 0))


# --- SII EEPROM interface -----------------------------------------------------------------


class SiiConfig(IntFlag):
    """SII EEPROM configuration, register 0x0500 (ET1100 datasheet; ETG.1000.4 Table 47)."""

    PDI_OFFERED = 0x01  # bit 0: EEPROM control is offered to the PDI
    FORCE_ECAT = 0x02  # bit 1: take it back for EtherCAT (resets 0x0501 bit 0)


class SiiCommand(IntEnum):
    """SII control/status bits 8–10: the command (ET1100 datasheet, register 0x0502)."""

    IDLE = 0
    READ = 1
    WRITE = 2
    RELOAD = 4


#: The command field of 0x0502 (bits 8–10, :class:`SiiCommand` shifted left by 8).
SII_COMMAND_SHIFT = 8
SII_COMMAND_MASK = 0x0700


class SiiStatus(IntFlag):
    """SII control/status bits at 0x0502 but the command field (ETG.1000.4 Table 47)."""

    WRITE_ENABLE = 0x0001
    EMULATION = 0x0020
    READ_8_BYTES = 0x0040  # a read returns 8 bytes at 0x0508 (else 4)
    TWO_ADDRESS_BYTES = 0x0080
    CHECKSUM_ERROR = 0x0800  # ESC configuration area checksum
    DEVICE_INFO_ERROR = 0x1000
    COMMAND_ERROR = 0x2000  # missing EEPROM acknowledge or invalid command
    WRITE_ERROR = 0x4000
    BUSY = 0x8000


@dataclass(frozen=True, slots=True)
class SiiControlStatus:
    """SII EEPROM control/status word at 0x0502 (ETG.1000.4 Table 47)."""

    write_enable: bool = False
    read_8_bytes: bool = False
    two_address_bytes: bool = False
    emulation: bool = False
    command: int = SiiCommand.IDLE
    checksum_error: bool = False
    device_info_error: bool = False
    command_error: bool = False
    write_error: bool = False
    busy: bool = False
    reserved: int = 0

    @property
    def read_bytes(self) -> int:
        """How many bytes one read returns at 0x0508 (4 or 8)."""
        return 8 if self.read_8_bytes else 4


_SII_FLAGS = tuple((str(flag.name).lower(), int(flag)) for flag in SiiStatus)
_SII_RESERVED_MASK = 0x001E


def decode_sii_control_status(word: int) -> SiiControlStatus:
    flags = {name: bool(word & mask) for name, mask in _SII_FLAGS}
    command = enum_or_int(SiiCommand, (word & SII_COMMAND_MASK) >> SII_COMMAND_SHIFT)
    return SiiControlStatus(command=command, reserved=word & _SII_RESERVED_MASK, **flags)


def encode_sii_control_status(s: SiiControlStatus) -> int:
    word = ((s.command << SII_COMMAND_SHIFT) & SII_COMMAND_MASK) | (s.reserved & _SII_RESERVED_MASK)
    for name, mask in _SII_FLAGS:
        if getattr(s, name):
            word |= mask
    return word


# --- names and sizes: the register vocabulary of `bus reg` ----------------------------------

#: ESC address space: 64 KiB of registers and process RAM (ETG.1000.4 §6)
ESC_ADDRESS_SPACE = 0x10000

#: bytes of each named register (a block: all its fields, e.g. the 4 ports of 0x0300)
REGISTER_BYTES: dict[Register, int] = {
    Register.TYPE: 1, Register.REVISION: 1, Register.BUILD: 2, Register.FMMU_COUNT: 1,
    Register.SM_COUNT: 1, Register.RAM_SIZE: 1, Register.PORT_DESCRIPTOR: 1,
    Register.ESC_FEATURES: 2, Register.STATION_ADDRESS: 2, Register.STATION_ALIAS: 2,
    Register.WRITE_ENABLE: 1, Register.WRITE_PROTECTION: 1, Register.ESC_WRITE_ENABLE: 1,
    Register.ESC_WRITE_PROTECTION: 1, Register.ESC_RESET_ECAT: 1, Register.ESC_RESET_PDI: 1,
    Register.DL_CONTROL: 4, Register.PHYSICAL_READ_WRITE_OFFSET: 2, Register.DL_STATUS: 2,
    Register.AL_CONTROL: 2, Register.AL_STATUS: 2, Register.AL_STATUS_CODE: 2,
    Register.RUN_LED_OVERRIDE: 1, Register.ERR_LED_OVERRIDE: 1, Register.PDI_CONTROL: 1,
    Register.ESC_CONFIGURATION: 1, Register.PDI_CONFIGURATION: 1,
    Register.SYNC_LATCH_CONFIGURATION: 1, Register.EXTENDED_PDI_CONFIGURATION: 2,
    Register.ECAT_EVENT_MASK: 2, Register.PDI_EVENT_MASK: 4, Register.ECAT_EVENT_REQUEST: 2,
    Register.AL_EVENT_REQUEST: 4, Register.RX_ERROR_COUNTER: 8,
    Register.FORWARDED_RX_ERROR_COUNTER: 4, Register.PROCESSING_UNIT_ERROR_COUNTER: 1,
    Register.PDI_ERROR_COUNTER: 1, Register.LOST_LINK_COUNTER: 4, Register.WATCHDOG_DIVIDER: 2,
    Register.WD_TIME_PDI: 2, Register.WD_TIME_PD: 2, Register.WD_STATUS_PD: 2,
    Register.WD_COUNTER_PD: 1, Register.WD_COUNTER_PDI: 1, Register.SII_CONFIG: 1,
    Register.SII_PDI_ACCESS: 1, Register.SII_CONTROL_STATUS: 2, Register.SII_ADDRESS: 4,
    Register.SII_DATA: 8, Register.MII_CONTROL_STATUS: 2, Register.MII_PHY_ADDRESS: 1,
    Register.MII_PHY_REGISTER: 1, Register.MII_PHY_DATA: 2, Register.FMMU: FMMU_BYTES,
    Register.SM: SYNC_MANAGER_BYTES, Register.DC_RECEIVE_TIME_PORT0: 4,
    Register.DC_RECEIVE_TIME_PORT1: 4, Register.DC_RECEIVE_TIME_PORT2: 4,
    Register.DC_RECEIVE_TIME_PORT3: 4, Register.DC_SYSTEM_TIME: 8,
    Register.DC_RECEIVE_TIME_PU: 8, Register.DC_SYSTEM_TIME_OFFSET: 8,
    Register.DC_SYSTEM_TIME_DELAY: 4, Register.DC_SYSTEM_TIME_DIFFERENCE: 4,
    Register.DC_SPEED_COUNTER_START: 2, Register.DC_SPEED_COUNTER_DIFF: 2,
    Register.DC_FILTER_DEPTH_SYSTEM_TIME: 1, Register.DC_FILTER_DEPTH_SPEED_COUNTER: 1,
    Register.DC_CYCLIC_UNIT_CONTROL: 1, Register.DC_ACTIVATION: 1,
    Register.DC_SYNC_IMPULSE_LENGTH: 2, Register.DC_ACTIVATION_STATUS: 1,
    Register.DC_SYNC0_STATUS: 1, Register.DC_SYNC1_STATUS: 1, Register.DC_START_TIME_CYCLIC: 8,
    Register.DC_NEXT_SYNC1_PULSE: 8, Register.DC_SYNC0_CYCLE: 4, Register.DC_SYNC1_CYCLE: 4,
    Register.DC_LATCH0_CONTROL: 1, Register.DC_LATCH1_CONTROL: 1, Register.DC_LATCH0_STATUS: 1,
    Register.DC_LATCH1_STATUS: 1, Register.ESC_SPECIFIC: 16, Register.DIGITAL_IO_OUTPUT: 4,
    Register.GENERAL_PURPOSE_OUTPUT: 8, Register.GENERAL_PURPOSE_INPUT: 8,
    Register.USER_RAM: 128, Register.PROCESS_RAM: 8,
}  # fmt: skip

#: register blocks a master configures and must not change under running process data
#: (SAFEOP, OP): station address, AL control, watchdogs, FMMUs, sync managers, DC SYNC
CONFIGURATION_BLOCKS: tuple[tuple[int, int, str], ...] = (
    (Register.STATION_ADDRESS, 4, "station address"),
    (Register.DL_CONTROL, 4, "DL control"),
    (Register.AL_CONTROL, 2, "AL control"),
    (Register.WATCHDOG_DIVIDER, 0x22, "watchdog"),
    (Register.FMMU, FMMU_BYTES * FMMU_COUNT_MAX, "FMMU configuration"),
    (Register.SM, SYNC_MANAGER_BYTES * SYNC_MANAGER_COUNT_MAX, "sync manager configuration"),
    (Register.DC_SYSTEM_TIME_OFFSET, 12, "DC system time offset and delay"),
    (Register.DC_CYCLIC_UNIT_CONTROL, 0x28, "DC SYNC configuration"),
)


@dataclass(frozen=True, slots=True)
class RegisterSpan:
    """``length`` bytes of the ESC from ``address``; ``name`` when it starts a named one."""

    address: int
    length: int
    name: str | None = None


def register_name(address: int) -> str | None:
    """``al_status`` for 0x0130, ``sm2`` for 0x0810, ``fmmu1`` for 0x0610; else None."""
    if Register.FMMU <= address < Register.FMMU + FMMU_BYTES * FMMU_COUNT_MAX:
        n, rest = divmod(address - Register.FMMU, FMMU_BYTES)
        return f"fmmu{n}" if rest == 0 else None
    if Register.SM <= address < Register.SM + SYNC_MANAGER_BYTES * SYNC_MANAGER_COUNT_MAX:
        n, rest = divmod(address - Register.SM, SYNC_MANAGER_BYTES)
        return f"sm{n}" if rest == 0 else None
    try:
        return str(Register(address).name).lower()
    except ValueError:
        return None


def register_names() -> tuple[str, ...]:
    """Every name :func:`parse_register` takes (``fmmuN``, ``smN`` for N = 0..15)."""
    return tuple(str(r.name).lower() for r in Register) + ("fmmuN", "smN")


def _named(text: str) -> tuple[int, int] | None:
    low = text.strip().lower().replace("-", "_")
    for prefix, base, step, count in (
        ("fmmu", Register.FMMU, FMMU_BYTES, FMMU_COUNT_MAX),
        ("sm", Register.SM, SYNC_MANAGER_BYTES, SYNC_MANAGER_COUNT_MAX),
    ):
        tail = low[len(prefix) :]
        if low.startswith(prefix) and tail.isdigit() and int(tail) < count:
            return base + step * int(tail), step
    try:
        reg = Register[low.upper()]
    except KeyError:
        return None
    return int(reg), REGISTER_BYTES.get(reg, 1)


def parse_register(text: str, *, max_length: int = 1486) -> RegisterSpan:
    """``ADDR[:LEN]``: ADDR a number (``0x130``, ``304``) or a register name (``al_status``,
    ``sm2``), LEN bytes (default: the named register's size, else 1). UsageError when it is
    neither, or the span leaves the 64 KiB ESC address space or one datagram
    (a usage error: it is what the user typed)."""
    head, sep, tail = text.strip().partition(":")
    if not head:
        raise UsageError(f"register {text!r}: give an address or a name (like al_status)")
    named = _named(head)
    if named is not None:
        address, length = named
    else:
        try:
            address = int(head, 0)
        except ValueError:
            raise UsageError(
                f"register {head!r} is neither a number nor a register name "
                "(like al_status, dl_status, rx_error_counter, sm2)"
            ) from None
        length = REGISTER_BYTES.get(Register(address), 1) if address in _ADDRESSES else 1
    if sep:
        try:
            length = int(tail, 0)
        except ValueError:
            raise UsageError(f"register length {tail!r} is not a number") from None
    if not 0 <= address < ESC_ADDRESS_SPACE:
        raise UsageError(
            f"register 0x{address:X} is outside the ESC's address space 0x0000-0xFFFF"
        )
    if not 1 <= length <= max_length:
        raise UsageError(f"register length {length}: expected 1 to {max_length} bytes")
    if address + length > ESC_ADDRESS_SPACE:
        raise UsageError(
            f"register 0x{address:04X}:{length} runs past the ESC's address space "
            "(ends at 0xFFFF)"
        )
    return RegisterSpan(address, length, register_name(address))


_ADDRESSES = frozenset(int(r) for r in Register)


def configuration_block(address: int, length: int) -> str | None:
    """The name of the first :data:`CONFIGURATION_BLOCKS` block the span touches."""
    for start, size, name in CONFIGURATION_BLOCKS:
        if address < start + size and start < address + length:
            return name
    return None
