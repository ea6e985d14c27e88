"""What an object entry is — its data type and its name — decided one way for ``sdo read``,
``sdo write``, ``sdo check``, ``sdo list`` and the SDO transactions of a capture
(:mod:`lolacli.capture.sdo`), and the one way its value is printed.

:meth:`TypeLookup.entry_type` is the one function. It asks its sources in this order, the
type and the name each from the first source that knows it (a source that knows only
the name leaves the type to the next):

1. ``--type T`` (or ``type:`` in a check file), for the type only: the user's word wins;
   where a source below describes the entry with another type, the note says so;
2. a dictionary given or known for the device — the ``--eds`` file of a CANopen node, the
   ``--esi`` device whose identity the slave reports, the slave's PDO entries in the ENI
   (index, subindex, name and type of each mapped object) — type source ``eds``,
   ``esi`` or ``eni``;
3. the slave's SDO Information service, where the transport has it (lolacli's own master
   on EtherCAT: one Get Entry Description per entry, kept for the session) — ``sdo-info``;
4. the CiA 301 / ETG.1000.6 communication objects (0x1000, 0x1008, 0x1018, PDO mapping
   and assignment, …) — ``cia301``;
5. for bytes read and nothing else knowing the type, a guess from them — ``guess`` — that
   the note states ("typed as UNSIGNED32 from its 4 bytes; give --type to choose"): 1, 2,
   4 or 8 bytes unsigned, printable text a VISIBLE_STRING, else an OCTET_STRING. A write
   of an unknown type is refused: the length of a value cannot be guessed.

:func:`format_value` is how every command prints a value, one rule per type:

==================================  ===============================================
type                                printed
==================================  ===============================================
BOOLEAN                             ``true`` / ``false``
INTEGER8 … INTEGER64                decimal: ``-1000``
UNSIGNED8 … UNSIGNED64, BYTE, WORD, decimal, then hex as wide as the type in brackets:
DWORD, BITARR8/16/32                ``154 (0x0000009A)`` (no object is a special case)
BIT1 … BIT8                         decimal: ``3``
REAL32, REAL64                      the shortest decimal that reads back as the same
                                    value: ``0.1``, ``1500.0``, ``nan``, ``-inf``
VISIBLE_STRING, UNICODE_STRING      double-quoted, JSON escapes: ``"LOLA IMU"``
OCTET_STRING, DOMAIN, TIME_OF_DAY,  hex bytes with spaces: ``01 02 ff``; none:
TIME_DIFFERENCE, unknown types      ``(empty)``
==================================  ===============================================
"""

from __future__ import annotations

import json
import math
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, Protocol

from lolacli.errors import WireError
from lolacli.od import OdEntry, OdObject
from lolacli.od.cia301 import standard_name, standard_object, standard_type
from lolacli.text import plural
from lolacli.wire.datatypes import (
    DataType,
    Value,
    bit_size,
    decode_value,
    int_range,
    size_bytes,
    type_name,
)

EDS, ESI, ENI, SDO_INFO, CIA301, OPTION, GUESS = (
    "eds",
    "esi",
    "eni",
    "sdo-info",
    "cia301",
    "--type",
    "guess",
)
#: every ``type_source`` of ``lolacli.sdo/1``, in lookup order after ``--type``
TYPE_SOURCES = (OPTION, EDS, ESI, ENI, SDO_INFO, CIA301, GUESS)


class Describes(Protocol):
    """A source of object descriptions: a :class:`~lolacli.od.Dictionary`
    (EDS, ESI, ENI, SDO Information read whole) or the slave's SDO Information service
    asked entry by entry. ``source`` is its ``type_source``."""

    @property
    def source(self) -> str: ...

    def object(self, index: int) -> OdObject | None: ...

    def entry(self, index: int, subindex: int) -> OdEntry | None: ...


class Cia301:
    """The CiA 301 / ETG.1000.6 communication objects as a source like the others."""

    source = CIA301

    def object(self, index: int) -> OdObject | None:
        return None  # the number of entries is the slave's: see TypeLookup.object

    def entry(self, index: int, subindex: int) -> OdEntry | None:
        kind = standard_type(index, subindex)
        if kind is None:
            return None
        return OdEntry(index, subindex, standard_name(index, subindex), kind, "", bit_size(kind))


CIA301_OBJECTS = Cia301()


@dataclass(frozen=True, slots=True)
class EntryType:
    """An entry's data type (None: not known, a write cannot be made), its name ("" if no
    source knows one), where the type came from (``type_source``; "" if nowhere), the size
    the description gives, and a note to say on stderr (a guess, a --type override)."""

    index: int
    subindex: int
    data_type: int | None
    name: str
    source: str
    bit_size: int | None = None
    note: str = ""

    @property
    def type_label(self) -> str:
        return "" if self.data_type is None else type_name(self.data_type)

    @property
    def address(self) -> str:
        return f"0x{self.index:04X}:{self.subindex:02X}"


@dataclass
class TypeLookup:
    """The sources of one slave, in the order of the module docstring."""

    dictionaries: tuple[Describes, ...] = ()
    sdo_info: Describes | None = None

    def sources(self) -> Iterator[Describes]:
        yield from self.dictionaries
        if self.sdo_info is not None:
            yield self.sdo_info
        yield CIA301_OBJECTS

    def entry_type(
        self,
        index: int,
        subindex: int,
        *,
        explicit: int | None = None,
        raw: bytes | None = None,
    ) -> EntryType:
        """The one decision of an entry's type and name (see the module docstring).
        ``explicit``: ``--type``; ``raw``: the bytes read, for the guess."""
        data_type: int | None = None
        name, source, size = "", "", None
        for where in self.sources():
            described = where.entry(index, subindex)
            if described is None:
                continue
            if not name and described.name:
                name = described.name
            if data_type is None and described.data_type is not None:
                data_type, source, size = described.data_type, where.source, described.bit_size
            if name and data_type is not None:
                break
        if explicit is not None:
            note = ""
            if data_type is not None and data_type != explicit:
                note = (
                    f"0x{index:04X}:{subindex:02X} is {type_name(data_type)} by {source}; "
                    f"taken as {type_name(explicit)} as --type says"
                )
            return EntryType(index, subindex, explicit, name, OPTION, bit_size(explicit), note)
        if data_type is None and raw is not None:
            guess = guess_type(raw)
            note = guess_note(index, subindex, guess, raw)
            return EntryType(index, subindex, guess, name, GUESS, 8 * len(raw), note)
        return EntryType(index, subindex, data_type, name, source, size)

    def object(self, index: int, count: int | None = None) -> tuple[OdObject, str] | None:
        """The first description of the whole object (for complete access) and its source;
        the CiA 301 ones take ``count`` entries after sub 0 (the slave's sub 0)."""
        for source in self.sources():
            if source is CIA301_OBJECTS:
                found = standard_object(index, count) if count is not None else None
            else:
                found = source.object(index)
            if found is not None:
                return found, source.source
        return None


def guess_type(raw: bytes) -> DataType:
    """A type for bytes of unknown type: unsigned by size, text if printable, else octets."""
    by_size = {
        1: DataType.UNSIGNED8,
        2: DataType.UNSIGNED16,
        4: DataType.UNSIGNED32,
        8: DataType.UNSIGNED64,
    }
    if len(raw) in by_size:
        return by_size[len(raw)]
    text = raw.rstrip(b"\x00")
    if text and all(0x20 <= b < 0x7F for b in text):
        return DataType.VISIBLE_STRING
    return DataType.OCTET_STRING


def guess_note(index: int, subindex: int, guess: int, raw: bytes) -> str:
    """What the guess says on stderr, once."""
    count = plural(len(raw), "byte")
    what = f"its {count}" if guess != DataType.VISIBLE_STRING else f"its {count} of text"
    return (
        f"0x{index:04X}:{subindex:02X}: no dictionary, SDO Information or CiA 301 object "
        f"describes it: typed as {type_name(guess)} from {what}; give --type to choose"
    )


# --- printing ----------------------------------------------------------------------------------

_BIT_TYPES = frozenset(DataType(DataType.BIT1 + n) for n in range(8))
_REAL32 = struct.Struct("<f")


def format_value(value: Any, data_type: int | None) -> str:
    """A value as every ``sdo`` command prints it (the table of the module docstring)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return _format_int(value, data_type)
    if isinstance(value, float):
        return format_real(value, data_type)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, bytes | bytearray):
        return bytes(value).hex(" ") if value else "(empty)"
    return str(value)


def _format_int(value: int, data_type: int | None) -> str:
    """Unsigned types (UNSIGNEDn, BYTE, WORD, DWORD, BITARRn): decimal and hex; the
    others (INTEGERn, BITn, no type known): decimal."""
    bounds = None if data_type is None or data_type in _BIT_TYPES else int_range(data_type)
    if bounds is None or bounds[0] < 0 or value < 0:
        return str(value)
    digits = 2 * (size_bytes(data_type or 0) or 1)
    return f"{value} (0x{value:0{digits}X})"


def format_real(value: float, data_type: int | None = None) -> str:
    """The shortest decimal that reads back as the same REAL32 (or REAL64) value."""
    if math.isnan(value):
        return "nan"
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    if data_type == DataType.REAL32:
        packed = _REAL32.pack(value)
        for digits in range(6, 10):
            text = f"{value:.{digits}g}"
            if _REAL32.pack(float(text)) == packed:
                return repr(float(text))
    return repr(value)


def decode(raw: bytes, typed: EntryType) -> tuple[Value, int | None, str]:
    """(value, type it was decoded as, note) of bytes read as ``typed``: bytes that do not
    fit the type are kept as octets, and the note says so."""
    note = typed.note
    if typed.data_type is None:
        return bytes(raw), None, note
    try:
        return decode_value(typed.data_type, raw), typed.data_type, note
    except WireError as exc:
        why = f"{typed.address}: {exc}; shown as octets"
        return bytes(raw), DataType.OCTET_STRING, f"{note}; {why}" if note else why


def json_value(value: Any) -> Any:
    """A value in JSON: bytes as hex text, lists of complete-access items recursively,
    NaN as null (not JSON), the rest as is."""
    if isinstance(value, bytes | bytearray):
        return bytes(value).hex()
    if isinstance(value, list):
        return [{k: json_value(v) for k, v in item.items()} for item in value]
    if isinstance(value, float) and value != value:
        return None
    return value


def describe(name: str, type_label: str, value_text: str | None = None) -> str:
    """``Device type  UNSIGNED32 = 131474 (0x00020192)``: the name (if known), the type
    (if known) and the value (if given) — the same words in read, write and check."""
    if value_text is None:
        typed = type_label
    else:
        typed = f"{type_label} = {value_text}" if type_label else value_text
    return "  ".join(part for part in (name, typed) if part)


__all__ = [
    "CIA301",
    "EDS",
    "ENI",
    "ESI",
    "GUESS",
    "OPTION",
    "SDO_INFO",
    "TYPE_SOURCES",
    "Cia301",
    "Describes",
    "EntryType",
    "TypeLookup",
    "decode",
    "describe",
    "format_real",
    "format_value",
    "guess_note",
    "guess_type",
    "json_value",
]
