"""AL (application layer) states and the texts of AL status codes: the state bits of AL
control/status (0x0120/0x0130) and what the code at 0x0134 means, ETG.1000.6 Tables 9
and 11.

Re-exported by :mod:`lolacli.wire.registers` (their home for every user); a module of its
own so that reading them (``capture analyze`` names the AL states a capture shows) does not
build the register map, FMMU, sync-manager and SII types (~6 ms of start-up).
"""

from __future__ import annotations

from enum import IntEnum

from lolacli.wire._codes import enum_or_int


class AlState(IntEnum):
    """Application-layer state in AL control/status bits 0–3 (ETG.1000.6 Table 9)."""

    INIT = 1
    PREOP = 2
    BOOT = 3
    SAFEOP = 4
    OP = 8


#: AL status bit 4: the slave refused the requested change (error indicator);
#: in AL control the same bit acknowledges the error.
AL_ERROR_INDICATOR = 0x10
AL_STATE_MASK = 0x0F


def al_state(status: int) -> AlState | int:
    """The state bits of an AL status/control word; unknown values stay ints."""
    return enum_or_int(AlState, status & AL_STATE_MASK)


def al_error(status: int) -> bool:
    return bool(status & AL_ERROR_INDICATOR)


def al_state_name(status: int) -> str:
    """``OP``, ``SAFEOP+ERR``, ``0x7`` …"""
    state = al_state(status)
    name = state.name if isinstance(state, AlState) else f"0x{state:X}"
    return name + ("+ERR" if al_error(status) else "")


_AL_STATUS_TEXT: dict[int, str] = {
    0x0000: "No error",
    0x0001: "Unspecified error",
    0x0002: "No memory",
    0x0003: "Invalid device setup",
    0x0006: "SII/EEPROM information does not match firmware",
    0x0007: "Firmware update not successful",
    0x000E: "License error",
    0x0011: "Invalid requested state change",
    0x0012: "Unknown requested state",
    0x0013: "Bootstrap not supported",
    0x0014: "No valid firmware",
    0x0015: "Invalid mailbox configuration (BOOT)",
    0x0016: "Invalid mailbox configuration (PREOP)",
    0x0017: "Invalid sync manager configuration",
    0x0018: "No valid inputs available",
    0x0019: "No valid outputs",
    0x001A: "Synchronization error",
    0x001B: "Sync manager watchdog",
    0x001C: "Invalid sync manager types",
    0x001D: "Invalid output configuration",
    0x001E: "Invalid input configuration",
    0x001F: "Invalid watchdog configuration",
    0x0020: "Slave needs cold start",
    0x0021: "Slave needs INIT",
    0x0022: "Slave needs PREOP",
    0x0023: "Slave needs SAFEOP",
    0x0024: "Invalid input mapping",
    0x0025: "Invalid output mapping",
    0x0026: "Inconsistent settings",
    0x0027: "Free-run not supported",
    0x0028: "Synchronization not supported",
    0x0029: "Free-run needs 3-buffer mode",
    0x002A: "Background watchdog",
    0x002B: "No valid inputs and outputs",
    0x002C: "Fatal sync error",
    0x002D: "No sync error",
    0x002E: "Cycle time too small",
    0x0030: "Invalid DC SYNC configuration",
    0x0031: "Invalid DC latch configuration",
    0x0032: "PLL error",
    0x0033: "DC sync IO error",
    0x0034: "DC sync timeout error",
    0x0035: "DC invalid sync cycle time",
    0x0036: "DC SYNC0 cycle time",
    0x0037: "DC SYNC1 cycle time",
    0x0041: "Mailbox AoE error",
    0x0042: "Mailbox EoE error",
    0x0043: "Mailbox CoE error",
    0x0044: "Mailbox FoE error",
    0x0045: "Mailbox SoE error",
    0x004F: "Mailbox VoE error",
    0x0050: "EEPROM no access",
    0x0051: "EEPROM error",
    0x0052: "External hardware not ready",
    0x0060: "Slave restarted locally",
    0x0061: "Device identification value updated",
    0x0070: "Detected module ident list does not match",
    0x0080: "Supply voltage too low",
    0x0081: "Supply voltage too high",
    0x0082: "Temperature too low",
    0x0083: "Temperature too high",
    0x00F0: "Application controller available",
}


def al_status_text(code: int) -> str:
    """Text of an AL status code; vendor codes (0x8000+) and unknown ones say so."""
    if code in _AL_STATUS_TEXT:
        return _AL_STATUS_TEXT[code]
    if code >= 0x8000:
        return f"Vendor specific code 0x{code:04X}"
    return f"Unknown AL status code 0x{code:04X}"

