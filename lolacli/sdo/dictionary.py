"""What a client knows about a slave's objects: names, data types, access, defaults.

A neutral description (no values, no IO) with one adapter per source, as cantools keeps
one model and one adapter per file format: an EDS/DCF through canopen's importer
(:func:`from_canopen`), an ESI ``<Dictionary>`` (:func:`from_esi`), the PDO entries an
ENI gives for a slave (:func:`from_eni`), the slave's own SDO Information service
(:func:`from_sdo_info`), and the CiA 301 / ETG.1000.6 communication objects every slave
has (:func:`standard_type`), used when nothing better is known. The order in which they
are asked is :mod:`lolacli.sdo.entry_type`'s.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from lolacli.wire.datatypes import (
    DataType,
    Value,
    bit_size,
    data_type_from_name,
    decode_value,
    type_name,
)

if TYPE_CHECKING:  # loads only where an ESI or ENI is read (start-up time)
    from lolacli.eni.esi_dictionary import EsiDictionary
    from lolacli.eni.model import Slave as EniSlave

VAR, ARRAY, RECORD = "VAR", "ARRAY", "RECORD"


@dataclass(frozen=True, slots=True)
class OdEntry:
    index: int
    subindex: int
    name: str
    data_type: int | None  # None: not a basic type known here
    access: str = "rw"  # ro, rw, wo, const
    bit_size: int | None = None
    default: Value | None = None
    pdo_mapping: bool = False

    @property
    def readable(self) -> bool:
        return self.access != "wo"

    @property
    def writable(self) -> bool:
        return self.access in ("rw", "wo")

    @property
    def type_label(self) -> str:
        return "?" if self.data_type is None else type_name(self.data_type)


@dataclass(frozen=True, slots=True)
class OdObject:
    index: int
    name: str
    object_code: str  # VAR, ARRAY, RECORD
    entries: tuple[OdEntry, ...]

    def entry(self, subindex: int) -> OdEntry | None:
        return next((e for e in self.entries if e.subindex == subindex), None)


@dataclass(frozen=True)
class Dictionary:
    """Objects by index; ``source`` says where they came from (``eds``, ``esi``, ``eni``,
    ``sdo-info``: the ``type_source`` of what is typed by it) and ``path`` which file, if
    any."""

    objects: tuple[OdObject, ...]
    source: str
    path: str = ""
    _index: dict[int, OdObject] = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        for obj in self.objects:
            self._index.setdefault(obj.index, obj)

    def __iter__(self) -> Iterator[OdObject]:
        return iter(self.objects)

    def __len__(self) -> int:
        return len(self.objects)

    def object(self, index: int) -> OdObject | None:
        return self._index.get(index)

    def entry(self, index: int, subindex: int) -> OdEntry | None:
        obj = self._index.get(index)
        return None if obj is None else obj.entry(subindex)

    def entries(self) -> Iterator[OdEntry]:
        for obj in self.objects:
            yield from obj.entries


# --- CiA 301 / ETG.1000.6 communication objects ------------------------------------------------

_U8, _U16, _U32 = DataType.UNSIGNED8, DataType.UNSIGNED16, DataType.UNSIGNED32
_STRING = DataType.VISIBLE_STRING
_VARS: dict[int, DataType] = {
    0x1000: _U32,  # device type
    0x1001: _U8,  # error register
    0x1002: _U32,  # manufacturer status register
    0x1005: _U32,  # COB-ID SYNC
    0x1006: _U32,  # communication cycle period
    0x1007: _U32,  # synchronous window length
    0x1008: _STRING,  # manufacturer device name
    0x1009: _STRING,  # manufacturer hardware version
    0x100A: _STRING,  # manufacturer software version
    0x100C: _U16,  # guard time
    0x100D: _U8,  # life time factor
    0x1014: _U32,  # COB-ID EMCY
    0x1015: _U16,  # inhibit time EMCY
    0x1017: _U16,  # producer heartbeat time
}
#: Arrays/records: (first index, last index) -> type of subindex 1.. (sub 0 is UNSIGNED8).
_RECORDS: tuple[tuple[int, int, dict[int, DataType] | DataType], ...] = (
    (0x1003, 0x1003, _U32),  # pre-defined error field
    (0x1010, 0x1011, _U32),  # store / restore parameters
    (0x1016, 0x1016, _U32),  # consumer heartbeat time
    (0x1018, 0x1018, _U32),  # identity: vendor, product, revision, serial
    (0x1200, 0x12FF, {1: _U32, 2: _U32, 3: _U8}),  # SDO server/client parameter
    (0x1400, 0x15FF, {1: _U32, 2: _U8, 3: _U16, 5: _U16}),  # RPDO communication
    (0x1600, 0x17FF, _U32),  # RxPDO mapping
    (0x1800, 0x19FF, {1: _U32, 2: _U8, 3: _U16, 5: _U16, 6: _U8}),  # TPDO communication
    (0x1A00, 0x1BFF, _U32),  # TxPDO mapping
    (0x1C00, 0x1C00, _U8),  # sync manager communication type
    (0x1C10, 0x1C2F, _U16),  # sync manager PDO assignment
)


def standard_type(index: int, subindex: int) -> DataType | None:
    """The data type of a CiA 301 / ETG.1000.6 communication object entry, if it is one."""
    if index in _VARS:
        return _VARS[index] if subindex == 0 else None
    for first, last, types in _RECORDS:
        if first <= index <= last:
            if subindex == 0:
                return _U8
            if isinstance(types, dict):
                return types.get(subindex)
            return types
    return None


#: CiA 301 / ETG.1000.6 names of the communication objects (ranges: the first index)
_NAMES: dict[int, str] = {
    0x1000: "Device type",
    0x1001: "Error register",
    0x1002: "Manufacturer status register",
    0x1003: "Pre-defined error field",
    0x1005: "COB-ID SYNC",
    0x1006: "Communication cycle period",
    0x1007: "Synchronous window length",
    0x1008: "Manufacturer device name",
    0x1009: "Manufacturer hardware version",
    0x100A: "Manufacturer software version",
    0x100C: "Guard time",
    0x100D: "Life time factor",
    0x1010: "Store parameters",
    0x1011: "Restore default parameters",
    0x1014: "COB-ID EMCY",
    0x1015: "Inhibit time EMCY",
    0x1016: "Consumer heartbeat time",
    0x1017: "Producer heartbeat time",
    0x1018: "Identity object",
    0x1200: "SDO server parameter",
    0x1280: "SDO client parameter",
    0x1400: "RPDO communication parameter",
    0x1600: "RPDO mapping parameter",
    0x1800: "TPDO communication parameter",
    0x1A00: "TPDO mapping parameter",
    0x1C00: "Sync manager communication type",
    0x1C10: "Sync manager PDO assignment",
}
_SDO_PARAMETER = {1: "COB-ID client to server", 2: "COB-ID server to client"}
_PDO_COMM = {1: "COB-ID", 2: "Transmission type", 3: "Inhibit time", 5: "Event timer"}
#: entry names by the first index of the object's range; a str is a pattern for every sub
_SUB_NAMES: dict[int, dict[int, str] | str] = {
    0x1003: "Standard error field {sub}",
    0x1010: {1: "Save all parameters", 2: "Save communication parameters",
             3: "Save application parameters"},
    0x1011: {1: "Restore all default parameters", 2: "Restore communication default parameters",
             3: "Restore application default parameters"},
    0x1016: "Consumer heartbeat time {sub}",
    0x1018: {1: "Vendor ID", 2: "Product code", 3: "Revision number", 4: "Serial number"},
    0x1200: _SDO_PARAMETER | {3: "Node-ID of the client"},
    0x1280: _SDO_PARAMETER | {3: "Node-ID of the server"},
    0x1400: _PDO_COMM,
    0x1600: "Mapped object {sub}",
    0x1800: _PDO_COMM | {6: "SYNC start value"},
    0x1A00: "Mapped object {sub}",
    0x1C00: "Communication type sync manager {sm}",
    0x1C10: "Assigned PDO {sub}",
}


def _object_name(index: int) -> tuple[int, str] | None:
    first = max((k for k in _NAMES if k <= index), default=None)
    if first is None:
        return None
    if 0x1C10 <= index <= 0x1C2F:
        return first, f"Sync manager {index - 0x1C10} PDO assignment"
    if first in (0x1400, 0x1600, 0x1800, 0x1A00):  # RPDO/TPDO n: CiA 301 counts from 1
        return first, f"{_NAMES[first]} {index - first + 1}"
    return first, _NAMES[first]


def standard_name(index: int, subindex: int) -> str:
    """The CiA 301 / ETG.1000.6 name of a communication object entry ("" if none): the
    object's name for a variable, "Number of entries" for sub 0 of an array/record, the
    entry's own name for the others."""
    found = _object_name(index) if standard_type(index, subindex) is not None else None
    if found is None:
        return ""
    first, name = found
    if index in _VARS:
        return name
    if subindex == 0:
        return "Number of entries"
    subs = _SUB_NAMES.get(first)
    if isinstance(subs, str):
        return subs.format(sub=subindex, sm=subindex - 1)
    return (subs or {}).get(subindex, f"{name}, sub {subindex}")


def standard_object(index: int, count: int) -> OdObject | None:
    """A CiA 301 array/record with ``count`` entries after sub 0, if ``index`` is one."""
    if standard_type(index, 0) is None or index in _VARS:
        return None
    entries = [OdEntry(index, 0, "Number of entries", _U8, "ro", 8)]
    for sub in range(1, count + 1):
        kind = standard_type(index, sub)
        if kind is None:
            return None
        entries.append(
            OdEntry(index, sub, standard_name(index, sub), kind, "ro", bit_size(kind))
        )
    found = _object_name(index)
    return OdObject(index, found[1] if found else "", RECORD, tuple(entries))


# --- adapters ----------------------------------------------------------------------------------


def _value(data_type: int | None, raw: bytes | None) -> Value | None:
    if raw is None:
        return None
    if data_type is None:
        return bytes(raw)
    try:
        return decode_value(data_type, raw)
    except Exception:  # a default that does not fit its type: keep the bytes
        return bytes(raw)


def from_esi(dictionary: EsiDictionary, path: str = "") -> Dictionary:
    """An ESI device's ``<Dictionary>`` (read by :mod:`lolacli.eni.esi_dictionary`)."""
    objects = []
    for o in dictionary.objects:
        entries = tuple(
            OdEntry(
                o.index,
                e.subindex,
                e.name,
                e.data_type,
                e.access,
                e.bit_size,
                _value(e.data_type, e.default),
                bool(e.pdo_mapping),
            )
            for e in o.entries
        )
        objects.append(OdObject(o.index, o.name, o.object_code, entries))
    return Dictionary(tuple(objects), "esi", path)


def from_canopen(od: Any, path: str = "") -> Dictionary:
    """A ``canopen.ObjectDictionary`` (an EDS/DCF through canopen's importer)."""
    from canopen import objectdictionary as cod

    objects = []
    for index in od:
        obj = od[index]
        if isinstance(obj, cod.ODVariable):
            objects.append(OdObject(index, obj.name, VAR, (_canopen_entry(obj),)))
            continue
        code = ARRAY if isinstance(obj, cod.ODArray) else RECORD
        entries = tuple(_canopen_entry(obj.subindices[s]) for s in sorted(obj.subindices))
        objects.append(OdObject(index, obj.name, code, entries))
    return Dictionary(tuple(objects), "eds", path)


def _canopen_entry(var: Any) -> OdEntry:
    data_type = var.data_type
    default = var.value if var.value is not None else var.default
    if isinstance(default, bytearray):
        default = bytes(default)
    if data_type == DataType.BOOLEAN and isinstance(default, int):
        default = bool(default)
    return OdEntry(
        var.index,
        var.subindex,
        var.name,
        data_type,
        var.access_type,
        None if data_type is None else len(var),
        default,
        bool(var.pdo_mappable),
    )


def from_eni(slave: EniSlave, path: str = "") -> Dictionary | None:
    """The objects an ENI's ``<RxPdo>``/``<TxPdo>`` entries map for ``slave``: index,
    subindex, name, data type (its IEC or CiA name) and size; None when it maps none.
    An object of entries after sub 0 is a RECORD whose own name the ENI does not give."""
    found: dict[int, dict[int, OdEntry]] = {}
    for pdo in slave.pdos:
        for e in pdo.entries:
            if e.index == 0:  # a gap in the PDO
                continue
            kind = data_type_from_name(e.data_type) if e.data_type else None
            entry = OdEntry(e.index, e.subindex, e.name, kind, "", e.bit_size or None, None, True)
            found.setdefault(e.index, {}).setdefault(e.subindex, entry)
    if not found:
        return None
    objects = []
    for index in sorted(found):
        entries = tuple(found[index][s] for s in sorted(found[index]))
        if len(entries) == 1 and entries[0].subindex == 0:
            objects.append(OdObject(index, entries[0].name, VAR, entries))
        else:
            objects.append(OdObject(index, "", RECORD, entries))
    return Dictionary(tuple(objects), "eni", path)


SdoInfoObject = tuple[int, str, int, int, int, Iterable[tuple[int, str, int, int, int]]]


def from_sdo_info(objects: Iterable[SdoInfoObject]) -> Dictionary:
    """SDO Information answers: per object ``(index, name, object code, data type, bit
    length, entries)`` with entries ``(subindex, name, data type, bit length, access
    bits)`` (ETG.1000.6 Tables 52 and 54; access bits 0–2 read in PREOP/SAFEOP/OP, 3–5
    write, 6–7 PDO mapping). A variable may come without entries (SOEM asks none for
    it): it is then one entry of the object's type, access not known (``""``)."""
    out = []
    codes = {7: VAR, 8: ARRAY, 9: RECORD}
    for index, name, code, data_type, bits, entries in objects:
        items = tuple(
            OdEntry(
                index,
                sub,
                entry_name,
                kind or None,
                access_text(access),
                size,
                None,
                bool(access & 0xC0),
            )
            for sub, entry_name, kind, size, access in entries
        )
        if not items:
            items = (OdEntry(index, 0, name, data_type or None, "", bits or None),)
        out.append(OdObject(index, name, codes.get(code, VAR), items))
    return Dictionary(tuple(out), "sdo-info")


def access_text(access: int) -> str:
    """``ro``/``rw``/``wo`` of an SDO Information access word (ETG.1000.6 Table 54)."""
    read, write = access & 0x07, access & 0x38
    if read and write:
        return "rw"
    if write:
        return "wo"
    return "ro"


__all__ = [
    "ARRAY",
    "access_text",
    "RECORD",
    "VAR",
    "Dictionary",
    "OdEntry",
    "OdObject",
    "from_canopen",
    "from_eni",
    "from_esi",
    "from_sdo_info",
    "standard_name",
    "standard_object",
    "standard_type",
]
