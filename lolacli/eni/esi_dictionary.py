"""The object dictionary of an ESI device: ``<Profile>/<Dictionary>`` (ETG.2000 §5.4.3).

Pure: lxml elements in, the one dictionary model out (:class:`lolacli.od.Dictionary`,
source ``esi``; its entries' values are the defaults). A dictionary has ``<DataTypes>`` (base
types by IEC name, records with ``<SubItem>``s, arrays with ``<ArrayInfo>``, enums with a
``<BaseType>``) and ``<Objects>``; each object names its type, and this module expands it
into the entries an SDO client addresses: one for a variable, sub 0 plus one per
record item or array element otherwise.

Default values come from ``<Info>``: ``<DefaultData>`` (hex, the bytes as on the wire),
``<DefaultValue>`` (a number) or ``<DefaultString>``. A record's ``<Info>/<SubItem>`` is
matched to an entry by name (the Elmo ESI gives only some of them), else by order after
the previous match (the Ingenia ESI renames array elements).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

from lolacli.errors import EniError
from lolacli.od.model import ARRAY, RECORD, VAR, Dictionary, OdEntry, OdObject
from lolacli.wire.datatypes import DataType, data_type_from_name

_El = Any  # an lxml element


class _Reader(Protocol):
    def number(self, el: _El, text: str | None, what: str, default: int | None = None) -> int: ...

    def error(self, el: _El | None, message: str) -> EniError: ...


@dataclass(frozen=True, slots=True)
class _SubItem:
    subindex: int | None
    name: str
    type_name: str
    bit_size: int
    access: str


@dataclass(frozen=True, slots=True)
class _Type:
    name: str
    bit_size: int
    base_type: str | None
    array: tuple[int, int] | None  # (lower bound, elements)
    items: tuple[_SubItem, ...]


def read_dictionary(el: _El | None, reader: _Reader) -> Dictionary | None:
    """The dictionary under ``<Dictionary>``, or None when the device has none."""
    if el is None:
        return None
    types: dict[str, _Type] = {}
    for t in el.iterfind("DataTypes/DataType"):
        parsed = _data_type(t, reader)
        types.setdefault(parsed.name, parsed)
    objects = [_object(o, types, reader) for o in el.iterfind("Objects/Object")]
    return Dictionary(objects, "esi")


def _text(el: _El | None, name: str) -> str:
    node = None if el is None else el.find(name)
    return "" if node is None or node.text is None else str(node.text).strip()


def _access(el: _El | None) -> str:
    access = _text(el, "Flags/Access").lower()
    return access if access in ("ro", "rw", "wo") else ""


def _data_type(el: _El, reader: _Reader) -> _Type:
    array = None
    info = el.find("ArrayInfo")
    if info is not None:
        lbound = reader.number(info, _text(info, "LBound"), "<LBound>", 0)
        elements = reader.number(info, _text(info, "Elements"), "<Elements>", 0)
        array = (lbound, elements)
    items = []
    for s in el.iterfind("SubItem"):
        sub = s.find("SubIdx")
        items.append(
            _SubItem(
                subindex=None if sub is None else reader.number(sub, sub.text, "<SubIdx>"),
                name=_text(s, "Name"),
                type_name=_text(s, "Type"),
                bit_size=reader.number(s, _text(s, "BitSize"), "<BitSize>", 0),
                access=_access(s),
            )
        )
    base = _text(el, "BaseType")
    return _Type(
        name=_text(el, "Name"),
        bit_size=reader.number(el, _text(el, "BitSize"), "<BitSize>", 0),
        base_type=base or None,
        array=array,
        items=tuple(items),
    )


def _basic(type_name: str, types: dict[str, _Type]) -> int | None:
    """The basic data type a type name stands for (following enum/alias base types)."""
    seen: set[str] = set()
    name = type_name
    while name and name not in seen:
        seen.add(name)
        known = data_type_from_name(name)
        if known is not None:
            return int(known)
        t = types.get(name)
        if t is None:
            return None
        if t.array is not None and t.base_type is not None:
            base = _basic(t.base_type, types)
            byte_like = base in (DataType.UNSIGNED8, DataType.BYTE, DataType.INTEGER8)
            return int(DataType.OCTET_STRING) if byte_like else None
        if t.items or t.base_type is None:
            return None
        name = t.base_type
    return None


def _object(el: _El, types: dict[str, _Type], reader: _Reader) -> OdObject:
    index = reader.number(el, _text(el, "Index"), "<Index>")
    name = _text(el, "Name")
    type_name = _text(el, "Type")
    access = _access(el) or "ro"
    pdo = bool(_text(el, "Flags/PdoMapping"))
    t = types.get(type_name)
    info = el.find("Info")
    if t is None or not t.items:
        bits = reader.number(el, _text(el, "BitSize"), "<BitSize>", 0)
        data_type = _basic(type_name, types)
        default = _default(info, data_type, bits, reader)
        entry = OdEntry(index, 0, name, data_type, access, bits, default or b"", pdo)
        return OdObject.of(index, name, VAR, [entry])
    entries = _expand(index, t, types, access)
    code = ARRAY if any(_is_array(i, types) for i in t.items) else RECORD
    return OdObject.of(index, name, code, _with_defaults(entries, info, reader))


def _is_array(item: _SubItem, types: dict[str, _Type]) -> bool:
    t = types.get(item.type_name)
    return item.subindex is None and t is not None and t.array is not None and not t.items


def _expand(index: int, t: _Type, types: dict[str, _Type], access: str) -> list[OdEntry]:
    entries: list[OdEntry] = []
    next_sub = 0
    for item in t.items:
        item_access = item.access or access
        arr = types.get(item.type_name)
        # an array item without SubIdx stands for its elements (sub 1..n of an ARRAY);
        # with SubIdx it is one entry (ARRAY [0..5] OF BYTE: an octet string)
        if item.subindex is None and arr is not None and arr.array is not None and not arr.items:
            lbound, count = arr.array
            base = arr.base_type or ""
            bits = arr.bit_size // count if count else 0
            data_type = _basic(base, types)
            start = item.subindex if item.subindex is not None else max(lbound, next_sub)
            for k in range(count):
                sub = start + k
                entries.append(
                    OdEntry(index, sub, f"{item.name} {k + 1}", data_type, item_access, bits)
                )
            next_sub = start + count
            continue
        sub = item.subindex if item.subindex is not None else next_sub
        data_type = _basic(item.type_name, types)
        entries.append(
            OdEntry(index, sub, item.name, data_type, item_access, item.bit_size)
        )
        next_sub = sub + 1
    return entries


def _with_defaults(entries: list[OdEntry], info: _El | None, reader: _Reader) -> list[OdEntry]:
    """Names and defaults of ``<Info>/<SubItem>``s, onto the entries (in place)."""
    if info is None:
        return entries
    out = entries
    used: set[int] = set()
    cursor = 0
    for sub_info in info.iterfind("SubItem"):
        name = _text(sub_info, "Name")
        k = next((i for i, e in enumerate(out) if e.name == name and i not in used), None)
        if k is None:
            k = next((i for i in range(cursor, len(out)) if i not in used), None)
            if k is None:
                continue
            out[k].name = name or out[k].name
        used.add(k)
        cursor = k + 1
        e = out[k]
        default = _default(sub_info.find("Info"), e.data_type, e.bits, reader)
        if default is not None:
            e.value = default
    return out


def _default(info: _El | None, data_type: int | None, bits: int, reader: _Reader) -> bytes | None:
    if info is None:
        return None
    data = info.find("DefaultData")
    if data is not None and data.text and data.text.strip():
        digits = "".join(str(data.text).split())
        try:
            return bytes.fromhex(digits)
        except ValueError:
            raise reader.error(data, f"<DefaultData>: not hex data: {digits[:40]!r}") from None
    text = info.find("DefaultString")
    if text is not None and text.text is not None:
        return str(text.text).encode("latin-1", "replace")
    value = info.find("DefaultValue")
    if value is not None and value.text and value.text.strip():
        number = reader.number(value, value.text, "<DefaultValue>")
        size = max(1, (bits + 7) // 8)
        if data_type in (DataType.REAL32, DataType.REAL64):
            size = 4 if data_type == DataType.REAL32 else 8
        try:
            signed = number < 0
            return number.to_bytes(size, "little", signed=signed)
        except OverflowError:
            raise reader.error(value, f"<DefaultValue> {number} does not fit {bits} bits") from None
    return None


__all__ = ["read_dictionary"]
