"""CANopen/CoE basic data types: their codes, names, and the one codec of their values.

Data type codes (CiA 301 Table 44; ETG.1000.6 Table 64 and ETG.1020 add BYTE/WORD/DWORD,
the bit-array and the bit types). Values are little endian on the wire. This module is the
one place in lolacli that turns object values into bytes and back: the SDO client, the
dictionaries read from ESI/EDS files and the value checks of ``sdo check`` use it.

Why not canopen's ``ODVariable.encode_raw``/``decode_raw``: importing it pulls in
python-can (60–100 ms here, on every EtherCAT SDO command), it truncates out-of-range
INTEGER24/40/48/56 values silently (``2**30`` as INTEGER24 encodes to ``00 00 00``), and
it drops non-ASCII bytes of strings. Here every value either fits its type exactly or is
refused with a message, and strings decode losslessly (latin-1: one character per byte).

Python values: integers for the integer and bit types, ``bool`` for BOOLEAN, ``float``
for REAL32/REAL64, ``str`` for VISIBLE_STRING/UNICODE_STRING, ``bytes`` for the octet
types (OCTET_STRING, DOMAIN, TIME_OF_DAY, TIME_DIFFERENCE). Trailing NULs of a visible
string (C devices pad with them) are not part of its value.
"""

from __future__ import annotations

import math
import struct
from enum import IntEnum

from lolacli.errors import WireError
from lolacli.text import plural

Value = int | float | bool | str | bytes


class DataType(IntEnum):
    """Data type codes (CiA 301 Table 44, ETG.1000.6 Table 64)."""

    BOOLEAN = 0x0001
    INTEGER8 = 0x0002
    INTEGER16 = 0x0003
    INTEGER32 = 0x0004
    UNSIGNED8 = 0x0005
    UNSIGNED16 = 0x0006
    UNSIGNED32 = 0x0007
    REAL32 = 0x0008
    VISIBLE_STRING = 0x0009
    OCTET_STRING = 0x000A
    UNICODE_STRING = 0x000B
    TIME_OF_DAY = 0x000C
    TIME_DIFFERENCE = 0x000D
    DOMAIN = 0x000F
    INTEGER24 = 0x0010
    REAL64 = 0x0011
    INTEGER40 = 0x0012
    INTEGER48 = 0x0013
    INTEGER56 = 0x0014
    INTEGER64 = 0x0015
    UNSIGNED24 = 0x0016
    UNSIGNED40 = 0x0018
    UNSIGNED48 = 0x0019
    UNSIGNED56 = 0x001A
    UNSIGNED64 = 0x001B
    BYTE = 0x001E
    WORD = 0x001F
    DWORD = 0x0020
    BITARR8 = 0x002D
    BITARR16 = 0x002E
    BITARR32 = 0x002F
    BIT1 = 0x0030
    BIT2 = 0x0031
    BIT3 = 0x0032
    BIT4 = 0x0033
    BIT5 = 0x0034
    BIT6 = 0x0035
    BIT7 = 0x0036
    BIT8 = 0x0037


_SIGNED: dict[int, int] = {  # type -> bytes
    DataType.INTEGER8: 1,
    DataType.INTEGER16: 2,
    DataType.INTEGER24: 3,
    DataType.INTEGER32: 4,
    DataType.INTEGER40: 5,
    DataType.INTEGER48: 6,
    DataType.INTEGER56: 7,
    DataType.INTEGER64: 8,
}
_UNSIGNED: dict[int, int] = {
    DataType.UNSIGNED8: 1,
    DataType.UNSIGNED16: 2,
    DataType.UNSIGNED24: 3,
    DataType.UNSIGNED32: 4,
    DataType.UNSIGNED40: 5,
    DataType.UNSIGNED48: 6,
    DataType.UNSIGNED56: 7,
    DataType.UNSIGNED64: 8,
    DataType.BYTE: 1,
    DataType.WORD: 2,
    DataType.DWORD: 4,
    DataType.BITARR8: 1,
    DataType.BITARR16: 2,
    DataType.BITARR32: 4,
}
#: BITn: n bits, carried in one byte when read alone by SDO.
_BITS: dict[int, int] = {DataType.BIT1 + n: n + 1 for n in range(8)}
_FLOAT: dict[int, struct.Struct] = {
    DataType.REAL32: struct.Struct("<f"),
    DataType.REAL64: struct.Struct("<d"),
}
_OCTETS_FIXED: dict[int, int] = {DataType.TIME_OF_DAY: 6, DataType.TIME_DIFFERENCE: 6}
_OCTETS = frozenset({DataType.OCTET_STRING, DataType.DOMAIN, *_OCTETS_FIXED})
_STRINGS = frozenset({DataType.VISIBLE_STRING, DataType.UNICODE_STRING})


def size_bytes(data_type: int) -> int | None:
    """Bytes of a value of this type on the wire; None for variable-length types."""
    for table in (_SIGNED, _UNSIGNED, _OCTETS_FIXED):
        if data_type in table:
            return table[data_type]
    if data_type in _FLOAT:
        return _FLOAT[data_type].size
    if data_type == DataType.BOOLEAN or data_type in _BITS:
        return 1
    return None


def bit_size(data_type: int) -> int | None:
    """Bits of a value of this type (1 for BOOLEAN, n for BITn); None if variable."""
    if data_type == DataType.BOOLEAN:
        return 1
    if data_type in _BITS:
        return _BITS[data_type]
    size = size_bytes(data_type)
    return None if size is None else 8 * size


def is_numeric(data_type: int) -> bool:
    return data_type in _SIGNED or data_type in _UNSIGNED or data_type in _BITS


def is_float(data_type: int) -> bool:
    return data_type in _FLOAT


def type_name(data_type: int) -> str:
    """``UNSIGNED32``, or ``0x0123`` for a code this table does not know."""
    try:
        return DataType(data_type).name
    except ValueError:
        return f"0x{data_type:04X}"


def int_range(data_type: int) -> tuple[int, int] | None:
    """The inclusive range of an integer or bit type; None for other types."""
    if data_type in _SIGNED:
        half = 1 << (8 * _SIGNED[data_type] - 1)
        return -half, half - 1
    if data_type in _UNSIGNED:
        return 0, (1 << (8 * _UNSIGNED[data_type])) - 1
    if data_type in _BITS:
        return 0, (1 << _BITS[data_type]) - 1
    return None


# --- encoding ------------------------------------------------------------------------------


def encode_value(data_type: int, value: Value) -> bytes:
    """The wire bytes of ``value`` as ``data_type``.

    Raises ValueError when the value does not fit the type (out of range, not a number,
    a string that is not latin-1) or the type has no codec here.
    """
    if isinstance(value, bytes | bytearray):
        size = size_bytes(data_type)
        if size is not None and len(value) != size:
            raise ValueError(
                f"{type_name(data_type)} is {plural(size, 'byte')}, not {len(value)} as given"
            )
        return bytes(value)
    if data_type == DataType.BOOLEAN:
        if value not in (0, 1):  # True/False compare equal to 1/0
            raise ValueError(f"{value!r} is not a BOOLEAN (0 or 1, true or false)")
        return b"\x01" if value else b"\x00"
    bounds = int_range(data_type)
    if bounds is not None:
        number = _as_int(value, data_type)
        low, high = bounds
        if not low <= number <= high:
            raise ValueError(f"{number} is out of range for {type_name(data_type)} ({low}..{high})")
        size = size_bytes(data_type) or 1
        return number.to_bytes(size, "little", signed=data_type in _SIGNED)
    if data_type in _FLOAT:
        return _encode_float(data_type, value)
    if data_type == DataType.VISIBLE_STRING:
        if not isinstance(value, str):
            raise ValueError(f"{value!r} is not a string")
        try:
            return value.encode("latin-1")
        except UnicodeEncodeError:
            raise ValueError(f"{value!r} has characters outside latin-1") from None
    if data_type == DataType.UNICODE_STRING:
        if not isinstance(value, str):
            raise ValueError(f"{value!r} is not a string")
        return value.encode("utf-16-le")
    if data_type in _OCTETS:
        raise ValueError(f"{type_name(data_type)} takes bytes, not {value!r}")
    raise ValueError(f"no codec for data type {type_name(data_type)}")


def _as_int(value: Value, data_type: int) -> int:
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, int):
        return value
    if isinstance(value, float) and value.is_integer():
        return int(value)
    raise ValueError(f"{value!r} is not an integer ({type_name(data_type)})")


def _encode_float(data_type: int, value: Value) -> bytes:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"{value!r} is not a number ({type_name(data_type)})")
    number = float(value)
    if data_type == DataType.REAL32 and math.isfinite(number) and abs(number) > 3.4028235e38:
        raise ValueError(f"{number} is out of range for REAL32")
    return _FLOAT[data_type].pack(number)


# --- decoding ------------------------------------------------------------------------------


def decode_value(data_type: int, raw: bytes) -> Value:
    """The value of ``raw`` as ``data_type``.

    Raises :class:`WireError` when the bytes do not fit a fixed-size type or the type has
    no codec here (the caller may show the bytes as an octet string instead).
    """
    size = size_bytes(data_type)
    if size is not None and len(raw) != size:
        raise WireError(f"{type_name(data_type)} is {plural(size, 'byte')}, not {len(raw)}")
    if data_type == DataType.BOOLEAN:
        return raw[0] != 0
    if data_type in _SIGNED:
        return int.from_bytes(raw, "little", signed=True)
    if data_type in _UNSIGNED:
        return int.from_bytes(raw, "little")
    if data_type in _BITS:
        return raw[0] & ((1 << _BITS[data_type]) - 1)
    if data_type in _FLOAT:
        value: float = _FLOAT[data_type].unpack(raw)[0]
        return value
    if data_type == DataType.VISIBLE_STRING:
        return raw.decode("latin-1").rstrip("\x00")
    if data_type == DataType.UNICODE_STRING:
        if len(raw) % 2:
            raise WireError(
                f"UNICODE_STRING of {plural(len(raw), 'byte')} (not a whole number of UTF-16 units)"
            )
        return raw.decode("utf-16-le", "replace").rstrip("\x00")
    if data_type in _OCTETS:
        return bytes(raw)
    raise WireError(f"no codec for data type {type_name(data_type)}")


# --- names and text ------------------------------------------------------------------------

#: Names a user or a device description may give a type: IEC 61131 (ESI), short forms.
_ALIASES: dict[str, DataType] = {
    "BOOL": DataType.BOOLEAN,
    "BIT": DataType.BOOLEAN,
    "SINT": DataType.INTEGER8,
    "INT": DataType.INTEGER16,
    "INT24": DataType.INTEGER24,
    "DINT": DataType.INTEGER32,
    "INT40": DataType.INTEGER40,
    "INT48": DataType.INTEGER48,
    "INT56": DataType.INTEGER56,
    "LINT": DataType.INTEGER64,
    "USINT": DataType.UNSIGNED8,
    "UINT": DataType.UNSIGNED16,
    "UINT24": DataType.UNSIGNED24,
    "UDINT": DataType.UNSIGNED32,
    "UINT40": DataType.UNSIGNED40,
    "UINT48": DataType.UNSIGNED48,
    "UINT56": DataType.UNSIGNED56,
    "ULINT": DataType.UNSIGNED64,
    "LWORD": DataType.UNSIGNED64,
    "REAL": DataType.REAL32,
    "LREAL": DataType.REAL64,
    "FLOAT": DataType.REAL32,
    "DOUBLE": DataType.REAL64,
    "STRING": DataType.VISIBLE_STRING,
    "WSTRING": DataType.UNICODE_STRING,
    "OCTETS": DataType.OCTET_STRING,
    "BYTES": DataType.OCTET_STRING,
    "BITARR": DataType.BITARR8,
    "BITARR8": DataType.BITARR8,
    "BITARR16": DataType.BITARR16,
    "BITARR32": DataType.BITARR32,
}
for _n in (8, 16, 24, 32, 40, 48, 56, 64):
    _ALIASES[f"U{_n}"] = DataType[f"UNSIGNED{_n}"]
    _ALIASES[f"I{_n}"] = DataType[f"INTEGER{_n}"]
    _ALIASES[f"S{_n}"] = DataType[f"INTEGER{_n}"]
_ALIASES["F32"] = _ALIASES["R32"] = DataType.REAL32
_ALIASES["F64"] = _ALIASES["R64"] = DataType.REAL64


def data_type_from_name(name: str) -> DataType | None:
    """A data type from its CiA name (``UNSIGNED32``), an IEC/ESI name (``UDINT``,
    ``STRING(20)``, ``ARRAY [0..5] OF BYTE``), a short form (``u32``, ``i24``, ``f32``)
    or a number (``0x0007``); None when the name is not one of these."""
    text = " ".join(name.split()).upper()
    if not text:
        return None
    if text.startswith("STRING(") or text.startswith("STRING ("):
        return DataType.VISIBLE_STRING
    if text.startswith("WSTRING("):
        return DataType.UNICODE_STRING
    if text.startswith("ARRAY") and text.endswith("OF BYTE"):
        return DataType.OCTET_STRING
    key = text.replace(" ", "_")
    if key in DataType.__members__:
        return DataType[key]
    if key in _ALIASES:
        return _ALIASES[key]
    try:
        return DataType(int(text, 0))
    except ValueError:
        return None


def parse_text(data_type: int, text: str) -> Value:
    """A value of ``data_type`` from the text a user typed (CLI argument, check file).

    Integers take decimal, ``0x``/``#x`` hex, ``0b`` binary and ``_`` separators; BOOLEAN
    also ``true``/``false``/``on``/``off``; octet types take hex bytes, spaces or colons
    allowed (``01 02 ff``). Raises ValueError with the reason.
    """
    raw = text.strip()
    if data_type == DataType.BOOLEAN:
        low = raw.lower()
        if low in ("1", "true", "on", "yes"):
            return True
        if low in ("0", "false", "off", "no"):
            return False
        raise ValueError(f"{text!r} is not a BOOLEAN (true/false, 1/0)")
    if int_range(data_type) is not None:
        return parse_int(raw, type_name(data_type))
    if data_type in _FLOAT:
        try:
            return float(raw)
        except ValueError:
            raise ValueError(f"{text!r} is not a number ({type_name(data_type)})") from None
    if data_type in _STRINGS:
        return text
    if data_type in _OCTETS:
        return parse_hex_bytes(raw)
    raise ValueError(f"no codec for data type {type_name(data_type)}")


def parse_int(text: str, what: str = "integer") -> int:
    """An integer from decimal, ``0x``/``#x`` hex, ``0o``, ``0b`` text; ValueError if not."""
    raw = text.strip()
    if raw.lower().startswith(("#x", "-#x")):
        raw = raw.replace("#x", "0x", 1).replace("#X", "0x", 1)
    try:
        return int(raw, 0)
    except ValueError:
        pass
    try:
        return int(raw, 10)  # leading zeros: "0010" is ten, as a person means it
    except ValueError:
        raise ValueError(f"{text!r} is not an integer ({what})") from None


def parse_hex_bytes(text: str) -> bytes:
    """Bytes from hex text: ``0102ff``, ``01 02 ff``, ``01:02:ff``, ``0x0102ff``."""
    raw = text.strip()
    if raw.lower().startswith("0x"):
        raw = raw[2:]
    digits = "".join(raw.replace(":", " ").replace("-", " ").split())
    try:
        return bytes.fromhex(digits)
    except ValueError:
        raise ValueError(f"{text!r} is not hex bytes (like 01 02 ff)") from None


__all__ = [
    "DataType",
    "Value",
    "bit_size",
    "data_type_from_name",
    "decode_value",
    "encode_value",
    "int_range",
    "is_float",
    "is_numeric",
    "parse_hex_bytes",
    "parse_int",
    "parse_text",
    "size_bytes",
    "type_name",
]
