"""ESC register addresses and codes the emulator uses (ETG.1000.4 §6, ET1100 datasheet §2).

Addresses are :mod:`lolacli.wire.registers`'s ``Register`` values under the same names, as
plain ints: a module constant costs a third of an ``IntEnum`` member in the ESC's hot path
(``benchmarks/register_constants.py``). Sync-manager bits, AL states and masks are wire's,
re-exported; only range ends and what wire has no use for are defined here.
"""

from __future__ import annotations

from enum import IntFlag

from lolacli.wire.registers import (
    AL_ERROR_INDICATOR,
    AL_STATE_MASK,
    FMMU_BYTES,
    SM_ACTIVATE_ENABLE,
    SM_CONTROL_DIRECTION_MASK,
    SM_CONTROL_MODE_MASK,
    SM_CONTROL_WATCHDOG,
    SM_DIRECTION_READ,
    SM_DIRECTION_WRITE,
    SM_MODE_BUFFERED,
    SM_MODE_MAILBOX,
    SM_PDI_DEACTIVATE,
    SM_STATUS_MAILBOX_FULL,
    SYNC_MANAGER_BYTES,
    AlState,
)
from lolacli.wire.registers import Register as _R

# --- ESC information (ETG.1000.4 Table 31) --------------------------------------------
TYPE = int(_R.TYPE)
REVISION = int(_R.REVISION)
BUILD = int(_R.BUILD)
FMMU_COUNT = int(_R.FMMU_COUNT)
SM_COUNT = int(_R.SM_COUNT)
RAM_SIZE = int(_R.RAM_SIZE)
PORT_DESCRIPTOR = int(_R.PORT_DESCRIPTOR)
ESC_FEATURES = int(_R.ESC_FEATURES)

# --- station address, data link layer --------------------------------------------------
STATION_ADDRESS = int(_R.STATION_ADDRESS)
STATION_ALIAS = int(_R.STATION_ALIAS)
DL_CONTROL = int(_R.DL_CONTROL)
DL_CONTROL_ALIAS_ENABLE_BYTE = 0x0103  # bit 0: station alias used for configured addressing
DL_STATUS = int(_R.DL_STATUS)

# --- application layer (ETG.1000.6 §5.3) -----------------------------------------------
AL_CONTROL = int(_R.AL_CONTROL)
AL_STATUS = int(_R.AL_STATUS)
AL_STATUS_CODE = int(_R.AL_STATUS_CODE)
PDI_CONTROL = int(_R.PDI_CONTROL)

# --- error counters (ETG.1000.4 Table 45..48) -------------------------------------------
RX_ERROR_COUNTER = int(_R.RX_ERROR_COUNTER)  # 2 bytes per port: invalid frame, RX error
FORWARDED_RX_ERROR_COUNTER = int(_R.FORWARDED_RX_ERROR_COUNTER)
PROCESSING_UNIT_ERROR_COUNTER = int(_R.PROCESSING_UNIT_ERROR_COUNTER)
PDI_ERROR_COUNTER = int(_R.PDI_ERROR_COUNTER)
LOST_LINK_COUNTER = int(_R.LOST_LINK_COUNTER)
ERROR_COUNTERS_END = 0x0314

# --- watchdogs -------------------------------------------------------------------------
WATCHDOG_DIVIDER = int(_R.WATCHDOG_DIVIDER)
WD_TIME_PDI = int(_R.WD_TIME_PDI)
WD_TIME_PD = int(_R.WD_TIME_PD)
WD_STATUS_PD = int(_R.WD_STATUS_PD)  # bit 0: 1 = OK, 0 = expired
WD_COUNTER_PD = int(_R.WD_COUNTER_PD)

# --- SII EEPROM interface (ETG.1000.4 Table 49..52) --------------------------------------
SII_CONFIG = int(_R.SII_CONFIG)
SII_PDI_ACCESS = int(_R.SII_PDI_ACCESS)
SII_CONTROL_STATUS = int(_R.SII_CONTROL_STATUS)
SII_ADDRESS = int(_R.SII_ADDRESS)
SII_DATA = int(_R.SII_DATA)
SII_END = int(_R.MII_CONTROL_STATUS)  # the SII interface ends where MII begins

# --- FMMU and sync managers (ETG.1000.4 Tables 56 and 58) -------------------------------
FMMU = int(_R.FMMU)
SM = int(_R.SM)

# --- distributed clocks (ETG.1000.4 Table 60, ET1100 §2.45) ------------------------------
DC_RECEIVE_TIME_PORT0 = int(_R.DC_RECEIVE_TIME_PORT0)  # 4 bytes per port; a write latches all ports
DC_SYSTEM_TIME = int(_R.DC_SYSTEM_TIME)  # 8 bytes
DC_RECEIVE_TIME_PU = int(_R.DC_RECEIVE_TIME_PU)  # 8 bytes
DC_SYSTEM_TIME_OFFSET = int(_R.DC_SYSTEM_TIME_OFFSET)  # 8 bytes
DC_SYSTEM_TIME_DELAY = int(_R.DC_SYSTEM_TIME_DELAY)  # 4 bytes
# 4 bytes, bit 31 sign: 1 = local copy smaller
DC_SYSTEM_TIME_DIFFERENCE = int(_R.DC_SYSTEM_TIME_DIFFERENCE)
DC_SPEED_COUNTER_START = int(_R.DC_SPEED_COUNTER_START)
DC_SPEED_COUNTER_DIFF = int(_R.DC_SPEED_COUNTER_DIFF)
DC_FILTER_DEPTH_SYSTEM_TIME = int(_R.DC_FILTER_DEPTH_SYSTEM_TIME)
DC_CYCLIC_UNIT_CONTROL = int(_R.DC_CYCLIC_UNIT_CONTROL)
DC_ACTIVATION = int(_R.DC_ACTIVATION)
DC_START_TIME_CYCLIC = int(_R.DC_START_TIME_CYCLIC)
DC_SYNC0_CYCLE = int(_R.DC_SYNC0_CYCLE)
DC_SYNC1_CYCLE = int(_R.DC_SYNC1_CYCLE)
DC_END = int(_R.DC_LATCH0_CONTROL)  # the DC registers the emulator serves end here

PROCESS_RAM = int(_R.PROCESS_RAM)
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


__all__ = [
    "AL_ERROR_INDICATOR",
    "AL_STATE_MASK",
    "FMMU_BYTES",
    "SM_ACTIVATE_ENABLE",
    "SM_CONTROL_DIRECTION_MASK",
    "SM_CONTROL_MODE_MASK",
    "SM_CONTROL_WATCHDOG",
    "SM_DIRECTION_READ",
    "SM_DIRECTION_WRITE",
    "SM_MODE_BUFFERED",
    "SM_MODE_MAILBOX",
    "SM_PDI_DEACTIVATE",
    "SM_STATUS_MAILBOX_FULL",
    "SYNC_MANAGER_BYTES",
    "AlState",
    "EscFeature",
]
