"""How human output says things: one form for each kind of value, used everywhere.

Station addresses print as hex with the decimal in brackets (``0x03E9 (1001)``): hex
as in the ESC's registers and in Wireshark, decimal as in the ENI's ``<PhysAddr>``
and as ``@1001`` is typed. Counts agree with their noun (``1 slave``, ``2 slaves``).
Numbers carry their unit, separated by a space (``92.9 µs``, ``846 B``). Identity
values (vendor ID, product code, revision, serial) are 32-bit hex (``0x00010420``), object
dictionary entries index:subindex (``0x6041:00``).
"""

from __future__ import annotations


def station(address: int) -> str:
    """``0x03E9 (1001)``."""
    return f"0x{address:04X} ({address})"


def hex32(value: int) -> str:
    """``0x0000009A``: a vendor ID, product code, revision or serial number."""
    return f"0x{value:08X}"


def object_entry(index: int, subindex: int) -> str:
    """``0x6041:00``: an object dictionary entry (a PDO entry, an SDO's object)."""
    return f"0x{index:04X}:{subindex:02X}"


_STATE_LETTERS = {"I": "INIT", "P": "PREOP", "S": "SAFEOP", "O": "OP", "B": "BOOT"}


def transition_text(code: str) -> str:
    """An ENI transition in words: ``SO`` -> ``SAFEOP to OP`` (ETG.2100 names each by the
    first letters of its two states); anything else as it is."""
    if len(code) == 2 and all(c in _STATE_LETTERS for c in code):
        return f"{_STATE_LETTERS[code[0]]} to {_STATE_LETTERS[code[1]]}"
    return code


def plural(n: int, noun: str, nouns: str | None = None) -> str:
    """``1 slave``, ``0 slaves``, ``2 entries`` (with ``nouns`` given), ``3,604 frames``
    (thousands grouped, as :func:`number` groups them)."""
    return f"{n:,} {noun if n == 1 else (nouns or noun + 's')}"


def number(value: float, unit: str, digits: int = 3) -> str:
    """``92.93 µs``: up to ``digits`` decimals, trailing zeros dropped, then the unit."""
    text = f"{value:,.{digits}f}".rstrip("0").rstrip(".") if digits else f"{value:,.0f}"
    return f"{text} {unit}" if unit else text


__all__ = ["hex32", "number", "object_entry", "plural", "station", "transition_text"]
