"""How human output says things: one form for each kind of value, used everywhere.

Station addresses print as hex with the decimal in brackets (``0x03E9 (1001)``): hex
as in the ESC's registers and in Wireshark, decimal as in the ENI's ``<PhysAddr>``
and as ``@1001`` is typed. Counts agree with their noun (``1 slave``, ``2 slaves``).
Numbers carry their unit, separated by a space (``92.9 µs``, ``846 B``).
"""

from __future__ import annotations


def station(address: int) -> str:
    """``0x03E9 (1001)``."""
    return f"0x{address:04X} ({address})"


def plural(n: int, noun: str, nouns: str | None = None) -> str:
    """``1 slave``, ``0 slaves``, ``2 entries`` (with ``nouns`` given)."""
    return f"{n} {noun if n == 1 else (nouns or noun + 's')}"


def number(value: float, unit: str, digits: int = 3) -> str:
    """``92.93 µs``: up to ``digits`` decimals, trailing zeros dropped, then the unit."""
    text = f"{value:,.{digits}f}".rstrip("0").rstrip(".") if digits else f"{value:,.0f}"
    return f"{text} {unit}" if unit else text


__all__ = ["number", "plural", "station"]
