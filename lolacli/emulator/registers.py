"""ESC register addresses and codes the emulator uses (ETG.1000.4 §6, ET1100 datasheet §2).

AL states and AL status codes come from :mod:`lolacli.wire.registers`.
"""

from __future__ import annotations

from enum import IntFlag

from lolacli.wire.registers import AL_ERROR_INDICATOR, AL_STATE_MASK, AlState

# --- ESC information (ETG.1000.4 Table 31) --------------------------------------------
TYPE = 0x0000
REVISION = 0x0001
BUILD = 0x0002
FMMUS_SUPPORTED = 0x0004
SYNC_MANAGERS_SUPPORTED = 0x0005
RAM_SIZE_KIB = 0x0006
PORT_DESCRIPTOR = 0x0007
FEATURES = 0x0008

# --- station address, data link layer --------------------------------------------------
STATION_ADDRESS = 0x0010
STATION_ALIAS = 0x0012
DL_CONTROL = 0x0100
DL_CONTROL_ALIAS_ENABLE_BYTE = 0x0103  # bit 0: station alias used for configured addressing
DL_STATUS = 0x0110

# --- application layer (ETG.1000.6 §5.3) -----------------------------------------------
AL_CONTROL = 0x0120
AL_STATUS = 0x0130
AL_STATUS_CODE = 0x0134
PDI_CONTROL = 0x0140

# --- error counters (ETG.1000.4 Table 45..48) -------------------------------------------
RX_ERROR_COUNTER = 0x0300  # 2 bytes per port: invalid frame, RX error
FORWARDED_RX_ERROR = 0x0308
PROCESSING_UNIT_ERROR = 0x030C
PDI_ERROR = 0x030D
LOST_LINK_COUNTER = 0x0310
ERROR_COUNTERS_END = 0x0314

# --- watchdogs -------------------------------------------------------------------------
WATCHDOG_DIVIDER = 0x0400
WATCHDOG_TIME_PDI = 0x0410
WATCHDOG_TIME_PROCESS_DATA = 0x0420
WATCHDOG_STATUS_PROCESS_DATA = 0x0440  # bit 0: 1 = OK, 0 = expired
WATCHDOG_COUNTER_PROCESS_DATA = 0x0442

# --- SII EEPROM interface (ETG.1000.4 Table 49..52) --------------------------------------
EEPROM_CONFIG = 0x0500
EEPROM_PDI_ACCESS = 0x0501
EEPROM_CONTROL = 0x0502
EEPROM_ADDRESS = 0x0504
EEPROM_DATA = 0x0508
EEPROM_END = 0x0510

EEPROM_STATUS_READ_8_BYTES = 0x0040
EEPROM_STATUS_BUSY = 0x8000
EEPROM_COMMAND_MASK = 0x0700
EEPROM_COMMAND_READ = 0x0100
EEPROM_COMMAND_WRITE = 0x0200
EEPROM_COMMAND_RELOAD = 0x0300
EEPROM_ERROR_COMMAND = 0x2000

# --- FMMU and sync managers (ETG.1000.4 Tables 56 and 58) -------------------------------
FMMU_BASE = 0x0600
FMMU_BYTES = 16
SYNC_MANAGER_BASE = 0x0800
SYNC_MANAGER_BYTES = 8

SM_CONTROL_MODE_MASK = 0x03
SM_MODE_BUFFERED = 0x00
SM_MODE_MAILBOX = 0x02
SM_CONTROL_DIRECTION_MASK = 0x0C
SM_DIRECTION_READ = 0x00  # ECAT reads, PDI writes (inputs, mailbox in)
SM_DIRECTION_WRITE = 0x04  # ECAT writes, PDI reads (outputs, mailbox out)
SM_CONTROL_WATCHDOG = 0x40
SM_STATUS_MAILBOX_FULL = 0x08
SM_ACTIVATE_ENABLE = 0x01
SM_PDI_DEACTIVATE = 0x01

FMMU_TYPE_READ = 0x01
FMMU_TYPE_WRITE = 0x02

# --- distributed clocks (ETG.1000.4 Table 60, ET1100 §2.45) ------------------------------
DC_RECEIVE_TIME_PORT0 = 0x0900  # 4 bytes per port; a write latches all ports
DC_SYSTEM_TIME = 0x0910  # 8 bytes
DC_RECEIVE_TIME_PROCESSING_UNIT = 0x0918  # 8 bytes
DC_SYSTEM_TIME_OFFSET = 0x0920  # 8 bytes
DC_SYSTEM_TIME_DELAY = 0x0928  # 4 bytes
DC_SYSTEM_TIME_DIFFERENCE = 0x092C  # 4 bytes, bit 31 sign: 1 = local copy smaller
DC_SPEED_COUNTER_START = 0x0930
DC_SPEED_COUNTER_DIFF = 0x0932
DC_FILTER_DEPTH = 0x0934
DC_CYCLIC_UNIT_CONTROL = 0x0980
DC_ACTIVATION = 0x0981
DC_SYNC0_START_TIME = 0x0990
DC_SYNC0_CYCLE_TIME = 0x09A0
DC_SYNC1_CYCLE_TIME = 0x09A4
DC_END = 0x09A8

PROCESS_RAM = 0x1000
MEMORY_BYTES = 0x10000


class EscFeature(IntFlag):
    """ESC features supported, register 0x0008 (ETG.1000.4 Table 31)."""

    FMMU_BYTE_ORIENTED = 0x0001
    DISTRIBUTED_CLOCKS = 0x0004
    DC_64_BIT = 0x0008
    LOW_JITTER_EBUS = 0x0010
    ENHANCED_LINK_DETECTION_EBUS = 0x0020
    ENHANCED_LINK_DETECTION_MII = 0x0040
    SEPARATE_FCS_ERRORS = 0x0080


__all__ = ["AL_ERROR_INDICATOR", "AL_STATE_MASK", "AlState", "EscFeature"]
