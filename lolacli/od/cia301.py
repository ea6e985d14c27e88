"""The CiA 301 / ETG.1000.6 communication objects every slave has: their data types and
names, used where no dictionary of the device describes an entry (type source
``cia301``), and by the emulated devices for the names of their own."""

from __future__ import annotations

from lolacli.od.model import RECORD, OdEntry, OdObject
from lolacli.wire.datatypes import DataType, bit_size

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
    return OdObject.of(index, found[1] if found else "", RECORD, entries)


__all__ = ["standard_name", "standard_object", "standard_type"]
