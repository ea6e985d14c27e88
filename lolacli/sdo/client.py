"""The SDO client seam and typed reads/writes over it.

:class:`SdoClient` is the one protocol every transport implements (python-can's ``BusABC``
is the model): bytes up and down by index/subindex, optional complete access, the slave's
own object dictionary where it has the SDO Information service. Backends raise
:class:`~lolacli.errors.SdoAbortError` for an abort (exit 1) and
:class:`~lolacli.errors.TransportError` when the slave does not answer (exit 4).

:func:`read` and :func:`write` add the value types and names, decided by
:meth:`lolacli.od.lookup.TypeLookup.entry_type` (the one lookup of every ``sdo``
command: ``--type``, the device's dictionary, SDO Information, CiA 301, a stated guess).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

from lolacli.errors import SdoAbortError, UsageError
from lolacli.od import Dictionary
from lolacli.od.lookup import (
    Describes,
    EntryType,
    TypeLookup,
    decode,
    format_value,
    json_value,
)
from lolacli.wire.datatypes import (
    DataType,
    Value,
    decode_value,
    encode_value,
    parse_hex_bytes,
    parse_text,
    size_bytes,
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

    def sdo_info(self) -> Describes | None:
        """The SDO Information service asked entry by entry (for types and names); None
        where the transport has none."""
        ...

    def close(self) -> None: ...


def abort_error(index: int, subindex: int, code: int) -> SdoAbortError:
    """The error for an abort, with the code's CiA 301 text (``wire.sdo.abort_text``)."""
    from lolacli.wire.sdo import abort_text

    return SdoAbortError(index, subindex, code, abort_text(code))


# --- results -----------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SdoValue:
    """An entry's value as read (or as written): the contract ``lolacli.sdo/1``.

    ``data_type`` is the type's name (``UNSIGNED32``; the object code, ``RECORD``, for
    complete access), ``type_code`` its number, ``type_source`` one of
    :data:`lolacli.od.lookup.TYPE_SOURCES`; ``note`` is for stderr (a guess, an
    override, bytes that do not fit the type)."""

    slave: str
    index: int
    subindex: int
    raw: bytes
    value: Any  # Value, or a list of {subindex, name, data_type, value} for complete access
    data_type: str
    type_source: str
    name: str = ""
    complete_access: bool = False
    note: str = ""
    type_code: int | None = None

    @property
    def text(self) -> str:
        """The value as every command prints it (:func:`format_value`)."""
        return format_value(self.value, self.type_code)

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


def lookup_for(client: SdoClient, dictionary: Dictionary | None = None) -> TypeLookup:
    """The sources of a client's slave: ``dictionary`` (EDS, ESI) if given, then its SDO
    Information where the transport has it."""
    ask = getattr(client, "sdo_info", None)
    return TypeLookup((dictionary,) if dictionary is not None else (), ask() if ask else None)


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
    lookup: TypeLookup | None = None,
) -> SdoValue:
    """Upload an entry (or, with ``complete_access``, the whole object from ``subindex``
    0 or 1) and decode it. The type and name: ``lookup`` (a session's target has one),
    else :func:`lookup_for` the client and ``dictionary``; ``data_type`` is ``--type``."""
    lookup = lookup or lookup_for(client, dictionary)
    raw = client.upload(index, subindex, complete_access=complete_access)
    if complete_access:
        return complete_value(slave, index, subindex, raw, lookup)
    typed = lookup.entry_type(index, subindex, explicit=data_type, raw=raw)
    value, code, note = decode(raw, typed)
    label = type_name(code) if code is not None else "?"
    return SdoValue(
        slave, index, subindex, raw, value, label, typed.source, typed.name, False, note, code
    )


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
    lookup: TypeLookup | None = None,
) -> SdoValue:
    """Encode ``value`` (text is parsed by the type) and download it.

    The type comes as for :func:`read`; a write with no known type is a UsageError (the
    length of a value cannot be guessed). Complete access writes take the object's bytes
    (hex), and the result reads them back as :func:`read` would.
    """
    lookup = lookup or lookup_for(client, dictionary)
    if complete_access:
        raw = parse_hex_bytes(value) if isinstance(value, str) else _need_bytes(value)
        client.download(index, subindex, raw, complete_access=True)
        return complete_value(slave, index, subindex, raw, lookup)
    typed = lookup.entry_type(index, subindex, explicit=data_type)
    code = typed.data_type
    if code is None:
        raise UsageError(
            f"the data type of {typed.address} is not known: give --type (no --eds/--esi "
            "dictionary, SDO Information or CiA 301 object describes it)"
        )
    raw = encode_text(code, value)
    client.download(index, subindex, raw)
    return SdoValue(
        slave,
        index,
        subindex,
        raw,
        decode_value(code, raw),
        type_name(code),
        typed.source,
        typed.name,
        False,
        typed.note,
        code,
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


def complete_value(
    slave: str, index: int, subindex: int, raw: bytes, lookup: TypeLookup
) -> SdoValue:
    """Complete access: sub 0 (8 bits, padded to 16 when the transfer starts at sub 0),
    then each entry by its size (ETG.1000.6 §5.6.2.1.2), each typed and named by the one
    lookup. An object no source describes, or an entry of unknown or fractional size,
    leaves the bytes (from there on) as octets."""
    count = raw[0] if subindex == 0 and raw else None
    found = lookup.object(index, count)
    if found is None:
        note = f"0x{index:04X}: no source describes the object: shown as octets"
        octets = type_name(DataType.OCTET_STRING)
        return SdoValue(
            slave, index, subindex, raw, raw, octets, "", "", True, note, DataType.OCTET_STRING
        )
    obj, source = found
    items: list[dict[str, Any]] = []
    pos = 0
    if subindex == 0 and raw:
        items.append(_item(lookup, index, 0, raw[0]))
        pos = 2
    subs = [e.subindex for e in obj if e.subindex > 0]
    if count is not None:
        subs = [s for s in subs if s <= count]
    note = ""
    for sub in subs:
        typed = lookup.entry_type(index, sub)
        size = _size_bytes(typed)
        chunk = raw[pos : pos + size] if size is not None else b""
        if size is None or len(chunk) < size:
            rest = raw[pos:]
            if rest:
                items.append(
                    {"subindex": sub, "name": "", "data_type": "OCTET_STRING", "value": rest}
                )
                note = f"0x{index:04X}:{sub:02X} and after: size not known, shown as octets"
            pos = len(raw)
            break
        value, code, _ = decode(chunk, typed)
        items.append(
            {
                "subindex": sub,
                "name": typed.name,
                "data_type": type_name(code) if code is not None else "?",
                "value": value,
            }
        )
        pos += size
    return SdoValue(
        slave, index, subindex, raw, items, obj.object_code.name, source, obj.name, True, note
    )


def _item(lookup: TypeLookup, index: int, sub: int, value: int) -> dict[str, Any]:
    typed = lookup.entry_type(index, sub)
    return {"subindex": sub, "name": typed.name, "data_type": "UNSIGNED8", "value": value}


def _size_bytes(typed: EntryType) -> int | None:
    if typed.bit_size is not None:
        return None if typed.bit_size % 8 else typed.bit_size // 8
    return None if typed.data_type is None else size_bytes(typed.data_type)


__all__ = [
    "SdoClient",
    "SdoValue",
    "abort_error",
    "complete_value",
    "decode",
    "encode_text",
    "json_value",
    "lookup_for",
    "read",
    "write",
]
