"""The CiA 402 tables the bus tests check a drive against, written from the standard
(CiA 402-2 / IEC 61800-7-201): the statusword bit patterns of the power states (Table 30)
and the state machine's transitions with the controlword commands that make them
(Figure 4, Table 4)."""

from __future__ import annotations

#: state -> statusword pattern, bit 15 first, x: either
STATUS_PATTERNS = {
    "Not ready to switch on": "xxxx xxxx x0xx 0000",
    "Switch on disabled": "xxxx xxxx x1xx 0000",
    "Ready to switch on": "xxxx xxxx x01x 0001",
    "Switched on": "xxxx xxxx x01x 0011",
    "Operation enabled": "xxxx xxxx x01x 0111",
    "Quick stop active": "xxxx xxxx x00x 0111",
    "Fault reaction active": "xxxx xxxx x0xx 1111",
    "Fault": "xxxx xxxx x0xx 1000",
}

#: controlword commands (Table 4), the bits a master sends for each
SHUTDOWN, SWITCH_ON, ENABLE_OPERATION = 0x0006, 0x0007, 0x000F
DISABLE_VOLTAGE, QUICK_STOP, DISABLE_OPERATION, FAULT_RESET = 0x0000, 0x0002, 0x0007, 0x0080

#: (transition, from, controlword, to) for every commanded transition of Figure 4
#: (3+4: switch on and enable operation in one; 16 needs a quick stop option code 5-8)
TRANSITIONS = [
    ("2", "Switch on disabled", SHUTDOWN, "Ready to switch on"),
    ("3", "Ready to switch on", SWITCH_ON, "Switched on"),
    ("3+4", "Ready to switch on", ENABLE_OPERATION, "Operation enabled"),
    ("4", "Switched on", ENABLE_OPERATION, "Operation enabled"),
    ("5", "Operation enabled", DISABLE_OPERATION, "Switched on"),
    ("6", "Switched on", SHUTDOWN, "Ready to switch on"),
    ("7", "Ready to switch on", DISABLE_VOLTAGE, "Switch on disabled"),
    ("7q", "Ready to switch on", QUICK_STOP, "Switch on disabled"),
    ("8", "Operation enabled", SHUTDOWN, "Ready to switch on"),
    ("9", "Operation enabled", DISABLE_VOLTAGE, "Switch on disabled"),
    ("10", "Switched on", DISABLE_VOLTAGE, "Switch on disabled"),
    ("10q", "Switched on", QUICK_STOP, "Switch on disabled"),
    ("11", "Operation enabled", QUICK_STOP, "Quick stop active"),
    ("12", "Quick stop active", DISABLE_VOLTAGE, "Switch on disabled"),
    ("16", "Quick stop active", ENABLE_OPERATION, "Operation enabled"),
]

#: how to reach each state from switch on disabled (controlwords in order)
PATH = {
    "Switch on disabled": [],
    "Ready to switch on": [SHUTDOWN],
    "Switched on": [SHUTDOWN, SWITCH_ON],
    "Operation enabled": [SHUTDOWN, SWITCH_ON, ENABLE_OPERATION],
    "Quick stop active": [SHUTDOWN, SWITCH_ON, ENABLE_OPERATION, QUICK_STOP],
}


def pattern(text: str) -> tuple[int, int]:
    """(mask, value) of a pattern such as ``xxxx xxxx x01x 0001``."""
    bits = text.replace(" ", "")
    mask = int("".join("0" if c == "x" else "1" for c in bits), 2)
    value = int("".join("1" if c == "1" else "0" for c in bits), 2)
    return mask, value


def states_of(statusword: int) -> list[str]:
    """Every state whose pattern the statusword matches (one, for a drive that keeps
    the standard)."""
    return [
        name
        for name, text in STATUS_PATTERNS.items()
        if statusword & pattern(text)[0] == pattern(text)[1]
    ]
