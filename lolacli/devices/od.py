"""A CANopen object dictionary (CiA 301 §7.4): objects, entries, typed values, access.

Values are kept as the bytes they have on the wire (little endian). Access errors raise
:class:`~lolacli.errors.SdoAbortError` with the CiA 301 abort code, so an SDO server can
answer with it directly.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from enum import IntEnum

from lolacli.errors import SdoAbortError
from lolacli.wire.registers import AlState
from lolacli.wire.sdo import SdoAbortCode


class DataType(IntEnum):
    """CoE/CANopen basic data types (CiA 301 Table 44, ETG.1000.6 Table 64)."""

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
    REAL64 = 0x0011
    INTEGER64 = 0x0015
    UNSIGNED64 = 0x001B


class ObjectCode(IntEnum):
    """Object codes (CiA 301 Table 42)."""

    VAR = 0x07
    ARRAY = 0x08
    RECORD = 0x09


_INT_FORMATS: dict[int, str] = {
    DataType.BOOLEAN: "<B",
    DataType.INTEGER8: "<b",
    DataType.INTEGER16: "<h",
    DataType.INTEGER32: "<i",
    DataType.UNSIGNED8: "<B",
    DataType.UNSIGNED16: "<H",
    DataType.UNSIGNED32: "<I",
    DataType.INTEGER64: "<q",
    DataType.UNSIGNED64: "<Q",
    DataType.REAL32: "<f",
    DataType.REAL64: "<d",
}
_STRUCTS = {k: struct.Struct(v) for k, v in _INT_FORMATS.items()}
_VARIABLE_LENGTH = frozenset({DataType.VISIBLE_STRING, DataType.OCTET_STRING})

#: ENI/ESI type names -> data types.
TYPE_NAMES: dict[str, DataType] = {
    "BOOL": DataType.BOOLEAN,
    "BIT": DataType.BOOLEAN,
    "SINT": DataType.INTEGER8,
    "INT": DataType.INTEGER16,
    "DINT": DataType.INTEGER32,
    "LINT": DataType.INTEGER64,
    "USINT": DataType.UNSIGNED8,
    "BYTE": DataType.UNSIGNED8,
    "UINT": DataType.UNSIGNED16,
    "WORD": DataType.UNSIGNED16,
    "UDINT": DataType.UNSIGNED32,
    "DWORD": DataType.UNSIGNED32,
    "ULINT": DataType.UNSIGNED64,
    "REAL": DataType.REAL32,
    "LREAL": DataType.REAL64,
    "STRING": DataType.VISIBLE_STRING,
}


def data_type_for(name: str, bit_size: int) -> DataType:
    """A data type from an ENI type name, else from the bit size (unsigned)."""
    known = TYPE_NAMES.get(name.upper().split("(")[0].strip())
    if known is not None:
        return known
    return {
        1: DataType.BOOLEAN,
        8: DataType.UNSIGNED8,
        16: DataType.UNSIGNED16,
        32: DataType.UNSIGNED32,
        64: DataType.UNSIGNED64,
    }.get(bit_size, DataType.UNSIGNED8)


def type_bits(data_type: int) -> int:
    fmt = _STRUCTS.get(data_type)
    if fmt is None:
        return 0
    return 1 if data_type == DataType.BOOLEAN else fmt.size * 8


@dataclass(slots=True)
class Entry:
    """One sub-index: its type, access ("ro", "rw", "wo", "const") and current value."""

    index: int
    subindex: int
    name: str
    data_type: int
    access: str = "rw"
    value: bytes = b""
    pdo_mappable: bool = False

    @property
    def bit_size(self) -> int:
        bits = type_bits(self.data_type)
        return bits if bits else 8 * len(self.value)

    @property
    def readable(self) -> bool:
        return self.access != "wo"

    @property
    def writable(self) -> bool:
        return self.access in ("rw", "wo")


@dataclass(slots=True)
class OdObject:
    index: int
    name: str
    object_code: ObjectCode
    entries: dict[int, Entry] = field(default_factory=dict)

    @property
    def max_subindex(self) -> int:
        return max(self.entries) if self.entries else 0


def encode_value(data_type: int, value: int | float | str | bytes) -> bytes:
    """Wire bytes of a value of a basic type (strings latin-1)."""
    if isinstance(value, bytes):
        return value
    if isinstance(value, str):
        return value.encode("latin-1")
    fmt = _STRUCTS.get(data_type)
    if fmt is None:
        raise ValueError(f"no fixed size for data type 0x{data_type:04X}")
    if fmt.format[-1] in "fd":
        return fmt.pack(float(value))
    bits = fmt.size * 8
    if fmt.format[-1].islower():
        return fmt.pack(int(value))
    return fmt.pack(int(value) & ((1 << bits) - 1))


def decode_value(data_type: int, raw: bytes) -> int | float | str | bytes:
    if data_type == DataType.VISIBLE_STRING:
        return raw.decode("latin-1")
    fmt = _STRUCTS.get(data_type)
    if fmt is None or len(raw) < fmt.size:
        return raw
    value: int | float = fmt.unpack_from(raw)[0]
    return value


def pdo_configuration(index: int) -> bool:
    """PDO mapping (0x1600-0x17FF, 0x1A00-0x1BFF) and sync manager PDO assignment
    (0x1C10-0x1C2F) objects: writable in PREOP only (ETG.1000.6 §5.6.7.4; a change
    in SAFEOP or OP is refused with abort 0x08000022)."""
    return 0x1600 <= index < 0x1800 or 0x1A00 <= index < 0x1C00 or 0x1C10 <= index < 0x1C30


def access_flags(entry: Entry) -> int:
    """The entry's access rights as an SDO information entry description gives them
    (ETG.1000.6 Table 48): read in PREOP/SAFEOP/OP (bits 0-2), write in PREOP/SAFEOP/OP
    (bits 3-5), PDO mappable (bit 6)."""
    read = 0 if entry.access == "wo" else 0x07
    write = 0x38 if entry.writable else 0
    if write and pdo_configuration(entry.index):
        write = 0x08
    return read | write | (0x40 if entry.pdo_mappable else 0)


class ObjectDictionary:
    """Objects by index; typed get/set for device logic, checked read/write for SDO.

    ``al_state``: the AL state of the slave the dictionary is behind (``None``: not
    behind an ESC); SDO writes of the PDO configuration are refused outside PREOP."""

    def __init__(self) -> None:
        self.al_state: int | None = None
        self.objects: dict[int, OdObject] = {}
        self.version = 0  # bumped by every checked write: caches of mappings key on it
        self.writes = 0  # bumped by every write, checked or not: devices' rest states key on it

    def __iter__(self) -> Iterator[OdObject]:
        return iter(sorted(self.objects.values(), key=lambda o: o.index))

    def __contains__(self, key: tuple[int, int]) -> bool:
        obj = self.objects.get(key[0])
        return obj is not None and key[1] in obj.entries

    # ---------------------------------------------------------- definition
    def add_var(
        self,
        index: int,
        name: str,
        data_type: int,
        value: int | float | str | bytes = 0,
        *,
        access: str = "rw",
        pdo: bool = False,
    ) -> Entry:
        obj = OdObject(index, name, ObjectCode.VAR)
        self.objects[index] = obj
        self.version += 1
        entry = Entry(index, 0, name, data_type, access, encode_value(data_type, value), pdo)
        obj.entries[0] = entry
        return entry

    def add_record(
        self,
        index: int,
        name: str,
        subs: Sequence[tuple[str, int, int | float | str | bytes, str]],
        *,
        code: ObjectCode = ObjectCode.RECORD,
        writable_count: bool = False,
    ) -> OdObject:
        """An ARRAY/RECORD: sub 0 (UNSIGNED8, number of entries) then ``subs`` from 1."""
        obj = OdObject(index, name, code)
        count_access = "rw" if writable_count else "ro"
        obj.entries[0] = Entry(
            index, 0, "Number of entries", DataType.UNSIGNED8, count_access, bytes([len(subs)])
        )
        for i, (sub_name, dtype, value, access) in enumerate(subs, start=1):
            obj.entries[i] = Entry(index, i, sub_name, dtype, access, encode_value(dtype, value))
        self.objects[index] = obj
        self.version += 1
        return obj

    def ensure_entry(
        self, index: int, subindex: int, name: str, data_type: int, access: str = "rw"
    ) -> Entry:
        """The entry, created (zero value, PDO-mappable, ``access``) if it is not there."""
        obj = self.objects.get(index)
        if obj is None:
            obj = OdObject(index, name, ObjectCode.VAR if subindex == 0 else ObjectCode.RECORD)
            self.objects[index] = obj
        entry = obj.entries.get(subindex)
        if entry is None:
            size = max(1, (type_bits(data_type) + 7) // 8)
            entry = Entry(index, subindex, name, data_type, access, bytes(size), True)
            obj.entries[subindex] = entry
            self.version += 1
            if subindex and 0 not in obj.entries:
                obj.entries[0] = Entry(
                    index, 0, "Number of entries", DataType.UNSIGNED8, "ro", b"\x00"
                )
            if subindex:
                obj.entries[0].value = bytes([max(obj.entries[0].value[0], subindex)])
        return entry

    # ---------------------------------------------------------------- access
    def entry(self, index: int, subindex: int) -> Entry:
        obj = self.objects.get(index)
        if obj is None:
            raise SdoAbortError(index, subindex, SdoAbortCode.NO_OBJECT)
        entry = obj.entries.get(subindex)
        if entry is None:
            raise SdoAbortError(index, subindex, SdoAbortCode.NO_SUBINDEX)
        return entry

    def read(self, index: int, subindex: int) -> bytes:
        """SDO upload: the entry's bytes, or an abort."""
        entry = self.entry(index, subindex)
        if not entry.readable:
            raise SdoAbortError(index, subindex, SdoAbortCode.WRITE_ONLY)
        return entry.value

    def write(self, index: int, subindex: int, data: bytes) -> None:
        """SDO download: type length checked, read-only refused."""
        entry = self.entry(index, subindex)
        if not entry.writable:
            raise SdoAbortError(index, subindex, SdoAbortCode.READ_ONLY)
        if self.al_state not in (None, AlState.PREOP) and pdo_configuration(index):
            raise SdoAbortError(index, subindex, SdoAbortCode.CANNOT_TRANSFER_DEVICE_STATE)
        if entry.data_type not in _VARIABLE_LENGTH:
            size = max(1, (type_bits(entry.data_type) + 7) // 8)
            if len(data) != size:
                # CiA 301 also has 0x06070012 (too high) and 0x06070013 (too low); the
                # general 0x06070010 is what CANopen stacks and SOEM's slaves answer, so
                # every backend of `lolacli sdo write` reports one code for one mistake
                raise SdoAbortError(index, subindex, SdoAbortCode.LENGTH_MISMATCH)
        entry.value = bytes(data)
        self.version += 1
        self.writes += 1

    def get(self, index: int, subindex: int = 0) -> int | float | str | bytes:
        entry = self.entry(index, subindex)
        return decode_value(entry.data_type, entry.value)

    def get_int(self, index: int, subindex: int = 0) -> int:
        value = self.get(index, subindex)
        return int(value) if isinstance(value, int | float) else 0

    def set(self, index: int, subindex: int, value: int | float | str | bytes) -> None:
        """Device-side write: no access check."""
        entry = self.entry(index, subindex)
        entry.value = encode_value(entry.data_type, value)
        self.writes += 1
