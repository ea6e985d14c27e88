"""The SDO client seam and typed reads/writes over it.

:class:`SdoClient` is the one protocol every transport implements (python-can's ``BusABC``
is the model): bytes up and down by index/subindex, optional complete access, the slave's
own object dictionary where it has the SDO Information service. Backends raise
:class:`~lolacli.errors.SdoAbortError` for an abort (exit 1) and
:class:`~lolacli.errors.TransportError` when the slave does not answer (exit 4).

:func:`read` and :func:`write` add the value types: a type given by the caller, else the
object dictionary (EDS, ESI or SDO Information), else the CiA 301 communication objects,
else (reads only) a guess from the length that says it is one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

from lolacli.errors import SdoAbortError, UsageError
from lolacli.sdo.dictionary import (
    Dictionary,
    OdObject,
    standard_name,
    standard_object,
    standard_type,
)
from lolacli.wire.datatypes import (
    DataType,
    Value,
    decode_value,
    encode_value,
    parse_hex_bytes,
    parse_text,
    type_name,
)


class SdoClient(Protocol):
    """One slave's SDO server, reached over some transport."""

    #: How the slave is reached, for messages ("node 5 on udp_multicast 239.74.163.2").
    description: str

    def upload(self, index: int, subindex: int, *, complete_access: bool = False) -> bytes:
        """The object's bytes (SDO upload)."""
        ...

    def download(
        self, index: int, subindex: int, data: bytes, *, complete_access: bool = False
    ) -> None:
        """Write the object's bytes (SDO download)."""
        ...

    def dictionary(self) -> Dictionary | None:
        """The slave's object dictionary by the SDO Information service; None where the
        protocol or the slave has none."""
        ...

    def close(self) -> None: ...


def abort_error(index: int, subindex: int, code: int) -> SdoAbortError:
    """The error for an abort, with the code's CiA 301 text (``wire.sdo.abort_text``)."""
    from lolacli.wire.sdo import abort_text

    return SdoAbortError(index, subindex, code, abort_text(code))


# --- typing ------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class TypeChoice:
    data_type: int | None
    source: str  # option, eds, esi, sdo_info, standard, length, none
    name: str = ""


def choose_type(
    index: int, subindex: int, explicit: int | None, dictionary: Dictionary | None
) -> TypeChoice:
    """Where the type of an entry comes from: ``--type``, the dictionary, the standard
    communication objects; ``data_type`` None when none of them knows."""
    entry = None if dictionary is None else dictionary.entry(index, subindex)
    name = entry.name if entry is not None and entry.name else standard_name(index, subindex)
    if explicit is not None:
        return TypeChoice(explicit, "option", name)
    if entry is not None and entry.data_type is not None and dictionary is not None:
        return TypeChoice(entry.data_type, dictionary.source, name)
    standard = standard_type(index, subindex)
    if standard is not None:
        return TypeChoice(standard, "standard", name)
    return TypeChoice(None, "none", name)


def guess_type(raw: bytes) -> DataType:
    """A type for bytes of unknown type: unsigned by size, text if printable, else octets."""
    by_size = {1: DataType.UNSIGNED8, 2: DataType.UNSIGNED16, 4: DataType.UNSIGNED32}
    if len(raw) in by_size:
        return by_size[len(raw)]
    if len(raw) == 8:
        return DataType.UNSIGNED64
    text = raw.rstrip(b"\x00")
    if text and all(0x20 <= b < 0x7F for b in text):
        return DataType.VISIBLE_STRING
    return DataType.OCTET_STRING


# --- results -----------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SdoValue:
    """An entry's value as read (or as written): the contract ``lolacli.sdo/1``."""

    slave: str
    index: int
    subindex: int
    raw: bytes
    value: Any  # Value, or a list of {subindex, value} for complete access
    data_type: str
    type_source: str
    name: str = ""
    complete_access: bool = False
    note: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "schema": "lolacli.sdo/1",
            "slave": self.slave,
            "index": self.index,
            "subindex": self.subindex,
            "object": f"0x{self.index:04X}:{self.subindex:02X}",
            "name": self.name or None,
            "value": json_value(self.value),
            "raw_hex": self.raw.hex(),
            "data_type": self.data_type,
            "type_source": self.type_source,
            "complete_access": self.complete_access,
        }


def json_value(value: Any) -> Any:
    """Bytes as hex text; lists of complete-access items recursively; the rest as is."""
    if isinstance(value, bytes | bytearray):
        return bytes(value).hex()
    if isinstance(value, list):
        return [{k: json_value(v) for k, v in item.items()} for item in value]
    if isinstance(value, float) and value != value:  # NaN is not JSON
        return None
    return value


def display_value(value: Any) -> str:
    """A value as a person reads it: hex beside integers, spaced hex bytes, quoted text."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value) if value < 0 else f"{value} (0x{value:X})"
    if isinstance(value, bytes | bytearray):
        return bytes(value).hex(" ") if value else "(empty)"
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, list):
        return ", ".join(f"{item['subindex']}: {display_value(item['value'])}" for item in value)
    return str(value)


def decode(raw: bytes, choice: TypeChoice) -> tuple[Value, str, str, str]:
    """(value, type name, type source, note) of bytes read."""
    if choice.data_type is not None:
        try:
            return (
                decode_value(choice.data_type, raw),
                type_name(choice.data_type),
                choice.source,
                "",
            )
        except Exception as exc:  # WireError: bytes that do not fit the type
            note = f"{exc}; shown as octets"
            return bytes(raw), type_name(DataType.OCTET_STRING), choice.source, note
    guess = guess_type(raw)
    note = "type guessed from the length: give --type or an --eds/--esi"
    return decode_value(guess, raw), type_name(guess), "length", note


# --- operations --------------------------------------------------------------------------------


def read(
    client: SdoClient,
    index: int,
    subindex: int,
    *,
    slave: str = "",
    data_type: int | None = None,
    dictionary: Dictionary | None = None,
    complete_access: bool = False,
) -> SdoValue:
    """Upload an entry (or, with ``complete_access``, the whole object from ``subindex``
    0 or 1) and decode it."""
    raw = client.upload(index, subindex, complete_access=complete_access)
    if complete_access:
        obj = None if dictionary is None else dictionary.object(index)
        source = "none" if dictionary is None else dictionary.source
        if obj is None and raw:
            count = raw[0] if subindex == 0 else 0
            obj, source = standard_object(index, count), "standard"
        return _complete_value(slave, index, subindex, raw, obj, source)
    choice = choose_type(index, subindex, data_type, dictionary)
    value, name, source, note = decode(raw, choice)
    return SdoValue(slave, index, subindex, raw, value, name, source, choice.name, False, note)


def write(
    client: SdoClient,
    index: int,
    subindex: int,
    value: Value,
    *,
    slave: str = "",
    data_type: int | None = None,
    dictionary: Dictionary | None = None,
    complete_access: bool = False,
) -> SdoValue:
    """Encode ``value`` (text is parsed by the type) and download it.

    The type comes as for :func:`read`; a write with no known type is a UsageError (the
    length of a value cannot be guessed). Complete access writes take raw bytes (hex).
    """
    if complete_access:
        raw = parse_hex_bytes(value) if isinstance(value, str) else _need_bytes(value)
        client.download(index, subindex, raw, complete_access=True)
        kind = type_name(DataType.OCTET_STRING)
        return SdoValue(slave, index, subindex, raw, raw, kind, "option", "", True)
    choice = choose_type(index, subindex, data_type, dictionary)
    if choice.data_type is None:
        # a slave that describes itself (SDO Information) can say; optional for clients
        ask = getattr(client, "entry_type", None)
        found = ask(index, subindex) if ask is not None else None
        if found is not None and type_name(found) != f"0x{found:04X}":
            choice = TypeChoice(found, "sdo_info", choice.name)
    if choice.data_type is None:
        raise UsageError(
            f"the data type of 0x{index:04X}:{subindex:02X} is not known: give --type "
            "(or the object dictionary with --eds/--esi)"
        )
    raw = encode_text(choice.data_type, value)
    client.download(index, subindex, raw)
    typed = decode_value(choice.data_type, raw)
    return SdoValue(
        slave, index, subindex, raw, typed, type_name(choice.data_type), choice.source, choice.name
    )


def encode_text(data_type: int, value: Value) -> bytes:
    """Bytes of a value given as text or as a Python value; UsageError if it does not fit."""
    try:
        parsed = parse_text(data_type, value) if isinstance(value, str) else value
        return encode_value(data_type, parsed)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def _need_bytes(value: Value) -> bytes:
    if isinstance(value, bytes | bytearray):
        return bytes(value)
    raise UsageError("a complete-access write takes the object's bytes in hex (01 02 …)")


def _complete_value(
    slave: str, index: int, subindex: int, raw: bytes, obj: OdObject | None, source: str
) -> SdoValue:
    """Complete access: sub 0 (8 bits, padded to 16 when the transfer starts at sub 0),
    then each entry by its size (ETG.1000.6 §5.6.2.1.2). Entries of a size that is not a
    whole number of bytes, or an unknown object, leave the bytes as they are."""
    octets = type_name(DataType.OCTET_STRING)
    if obj is None or any(
        e.data_type is None or e.bit_size is None or e.bit_size % 8 for e in obj.entries[1:]
    ):
        note = "" if obj is not None else "object not in a dictionary: shown as octets"
        return SdoValue(slave, index, subindex, raw, raw, octets, "none", "", True, note)
    items: list[dict[str, Any]] = []
    pos = 0
    count = len(obj.entries) - 1
    if subindex == 0 and raw:
        count = raw[0]
        items.append({"subindex": 0, "value": raw[0]})
        pos = 2
    for entry in obj.entries[1:]:
        if entry.subindex > count or entry.data_type is None or entry.bit_size is None:
            continue
        size = entry.bit_size // 8
        chunk = raw[pos : pos + size]
        if len(chunk) < size:
            break
        try:
            value: Any = decode_value(entry.data_type, chunk)
        except Exception:
            value = bytes(chunk)
        items.append({"subindex": entry.subindex, "value": value})
        pos += size
    return SdoValue(slave, index, subindex, raw, items, obj.object_code, source, obj.name, True)


__all__ = [
    "SdoClient",
    "SdoValue",
    "TypeChoice",
    "abort_error",
    "choose_type",
    "decode",
    "display_value",
    "encode_text",
    "guess_type",
    "json_value",
    "read",
    "write",
]
