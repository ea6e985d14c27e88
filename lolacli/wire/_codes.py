"""Helpers shared by the codecs: codes that survive unknown values, bounds checks."""

from __future__ import annotations

from enum import IntEnum
from typing import TypeVar

from lolacli.errors import WireError

E = TypeVar("E", bound=IntEnum)


def enum_or_int(enum: type[E], value: int) -> E | int:
    """``enum(value)`` where the value is known, else the plain int (it survives decoding)."""
    try:
        return enum(value)
    except ValueError:
        return value


def need(buf: bytes | memoryview, offset: int, size: int, what: str) -> None:
    """Raise :class:`WireError` unless ``size`` bytes from ``offset`` are in ``buf``."""
    if offset < 0 or offset + size > len(buf):
        raise WireError(f"{what} truncated ({len(buf) - offset} of {size} bytes)", offset=offset)
