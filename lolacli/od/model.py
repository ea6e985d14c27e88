"""The one object-dictionary model of lolacli (CiA 301 §7.4, ETG.1000.6 §5.6).

A :class:`Dictionary` holds :class:`OdObject` s by index, each with its :class:`OdEntry` s
by subindex. An entry says what it is — name, data type, access, size, PDO mapping — and
holds a value as the bytes it has on the wire (little endian): the default of a
description read from a file, the current value of a dictionary a device serves. Values
are typed through :mod:`lolacli.wire.datatypes`, the one codec.

Every source is an adapter producing this model directly: an ESI ``<Dictionary>``
(:mod:`lolacli.eni.esi_dictionary`), an ENI's PDO entries and CoE InitCmds
(:mod:`lolacli.eni.dictionary`), an EDS/DCF through canopen's importer
(:func:`lolacli.od.eds.from_canopen`), the SDO Information service (:func:`from_sdo_info`,
also what the emulated slave answers with) and the CiA 301 communication objects
(:mod:`lolacli.od.cia301`). The emulated devices build their dictionary with
:meth:`Dictionary.add_var`/:meth:`~Dictionary.add_record` and serve it through
:meth:`~Dictionary.read`/:meth:`~Dictionary.write`, which check access and length and
raise :class:`~lolacli.errors.SdoAbortError` with the CiA 301 abort code.

Why not canopen's ``objectdictionary`` as the model (the EDS adapter uses its importer
to read EDS/DCF files), measured here (canopen 2.4.1, Python 3.11, a shared 2-core host):

* import time: ``python3 -X importtime -c 'import canopen.objectdictionary'`` 86 ms
  cumulative at best of 7 (up to 190 ms), nearly all of it python-can, which it imports;
  ``import lolacli.od`` 18 ms at best of 7, the ``lolacli`` package and the wire layer
  included. Every ``sdo`` command, the ESI/ENI readers and the emulator import this;
* its codec (``ODVariable.encode_raw``/``decode_raw``) differs from
  :mod:`lolacli.wire.datatypes` (which refuses or decodes each exactly):

  ====================================  ==========================  ====================
  case                                  canopen                     lolacli
  ====================================  ==========================  ====================
  INTEGER24 ``2**30``                   ``00 00 00`` (truncated)    refused
  UNSIGNED24 ``2**24``                  ``00 00 00``                refused
  UNSIGNED40 ``2**40``                  five zero bytes             refused
  BOOLEAN ``2``                         ``01``                      refused
  VISIBLE_STRING ``"Größe"``            UnicodeEncodeError (ASCII)  ``47 72 f6 df 65``
  decode VISIBLE_STRING ``47 72 f6..``  ``'Gre'`` (bytes dropped)   ``'Größe'``
  BYTE/WORD/DWORD/BITARRn/BITn encode   TypeError                   by their size
  BYTE ``05``, BIT3 ``ff`` decode       raw bytes                   ``5``, ``7``
  ====================================  ==========================  ====================

* it holds no values (canopen keeps them in a ``LocalNode``'s ``data_store``, beside the
  dictionary), and has no EtherCAT access word (read/write per PREOP/SAFEOP/OP), no PDO
  configuration writable in PREOP only, no ESI/ENI/SDO Information source;
* ``benchmarks/od_model.py`` times the emulator's hot paths on both (SdoServer upload
  and download, a device's typed get/set): this model 1.2–1.4× faster on SDO, 3× on a
  typed set, the same on a typed get (a run of 20 000 calls here).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from enum import IntEnum

from lolacli.errors import SdoAbortError, WireError
from lolacli.wire.datatypes import DataType, Value, decode_value, encode_value, type_name
from lolacli.wire.datatypes import bit_size as type_bits
from lolacli.wire.registers import AlState


class ObjectCode(IntEnum):
    """Object codes (CiA 301 Table 42, ETG.1000.6 Table 52)."""

    VAR = 0x07
    ARRAY = 0x08
    RECORD = 0x09


VAR, ARRAY, RECORD = ObjectCode.VAR, ObjectCode.ARRAY, ObjectCode.RECORD

#: the access word of SDO Information (ETG.1000.6 Table 54): read in PREOP/SAFEOP/OP
#: (bits 0-2), write in PREOP/SAFEOP/OP (bits 3-5), RxPDO/TxPDO mappable (bits 6-7)
ACCESS_READ = 0x07
ACCESS_WRITE = 0x38
ACCESS_WRITE_PREOP = 0x08
ACCESS_PDO = 0xC0


@dataclass(slots=True)
class OdEntry:
    """One sub-index. ``data_type`` None: not a basic type known here; ``access`` ro, rw,
    wo, const or "" (not known); ``bit_size`` as the source gives it (None: from the type
    or the value, see :attr:`bits`); ``value`` the bytes on the wire (a description's
    default, a served dictionary's current value; empty: none given)."""

    index: int
    subindex: int
    name: str
    data_type: int | None
    access: str = "rw"
    bit_size: int | None = None
    value: bytes = b""
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

    @property
    def bits(self) -> int:
        """The entry's size in bits: as given, else its type's, else its value's."""
        if self.bit_size is not None:
            return self.bit_size
        if self.data_type is not None:
            bits = type_bits(self.data_type)
            if bits is not None:
                return bits
        return 8 * len(self.value)

    @property
    def default(self) -> Value | None:
        """The value typed (bytes where it does not fit its type or the type is not
        known); None when there is none (or it is an empty string)."""
        return typed_value(self.data_type, self.value) if self.value else None


def typed_value(data_type: int | None, raw: bytes) -> Value:
    """``raw`` decoded as ``data_type``; the bytes themselves where they do not fit."""
    if data_type is None:
        return bytes(raw)
    try:
        return decode_value(data_type, raw)
    except WireError:
        return bytes(raw)


@dataclass(slots=True)
class OdObject:
    index: int
    name: str
    object_code: ObjectCode
    entries: dict[int, OdEntry] = field(default_factory=dict)

    @classmethod
    def of(
        cls, index: int, name: str, object_code: ObjectCode, entries: Iterable[OdEntry]
    ) -> OdObject:
        """An object of ``entries`` (the first of a subindex given twice is kept)."""
        obj = cls(index, name, object_code)
        for e in entries:
            obj.entries.setdefault(e.subindex, e)
        return obj

    def entry(self, subindex: int) -> OdEntry | None:
        return self.entries.get(subindex)

    def __iter__(self) -> Iterator[OdEntry]:
        """The entries by subindex."""
        return iter(sorted(self.entries.values(), key=lambda e: e.subindex))

    @property
    def max_subindex(self) -> int:
        return max(self.entries) if self.entries else 0


def pdo_configuration(index: int) -> bool:
    """PDO mapping (0x1600-0x17FF, 0x1A00-0x1BFF) and sync manager PDO assignment
    (0x1C10-0x1C2F) objects: writable in PREOP only (ETG.1000.6 §5.6.7.4; a change
    in SAFEOP or OP is refused with abort 0x08000022)."""
    return 0x1600 <= index < 0x1800 or 0x1A00 <= index < 0x1C00 or 0x1C10 <= index < 0x1C30


def access_word(entry: OdEntry) -> int:
    """The entry's access as SDO Information's entry description gives it (ETG.1000.6
    Table 54); the PDO configuration is writable in PREOP only."""
    read = 0 if entry.access == "wo" else ACCESS_READ
    write = ACCESS_WRITE if entry.writable else 0
    if write and pdo_configuration(entry.index):
        write = ACCESS_WRITE_PREOP
    return read | write | (ACCESS_PDO if entry.pdo_mapping else 0)


def access_text(access: int) -> str:
    """``ro``/``rw``/``wo`` of an SDO Information access word (ETG.1000.6 Table 54)."""
    read, write = access & ACCESS_READ, access & ACCESS_WRITE
    if read and write:
        return "rw"
    if write:
        return "wo"
    return "ro"


class Dictionary:
    """Objects by index. ``source`` says where they came from (``eds``, ``esi``, ``eni``,
    ``sdo-info``, ``device``: the ``type_source`` of what is typed by it) and ``path``
    which file, if any.

    Served by a device (the emulator): :meth:`read`/:meth:`write` are the SDO server's,
    :meth:`get`/:meth:`set` the device's own typed access. ``al_state`` is the state of
    the slave the dictionary is behind (None: not behind an ESC; writes of the PDO
    configuration are refused outside PREOP); ``version`` counts checked writes and
    definitions (caches of mappings key on it), ``writes`` every write."""

    def __init__(
        self, objects: Iterable[OdObject] = (), source: str = "device", path: str = ""
    ) -> None:
        self.objects: dict[int, OdObject] = {}
        for obj in objects:
            self.objects.setdefault(obj.index, obj)
        self.source = source
        self.path = path
        self.al_state: int | None = None
        self.version = 0
        self.writes = 0

    def __iter__(self) -> Iterator[OdObject]:
        """The objects by index."""
        return iter(sorted(self.objects.values(), key=lambda o: o.index))

    def __len__(self) -> int:
        return len(self.objects)

    def __contains__(self, key: tuple[int, int]) -> bool:
        obj = self.objects.get(key[0])
        return obj is not None and key[1] in obj.entries

    def __repr__(self) -> str:
        return f"Dictionary({len(self.objects)} objects, source={self.source!r})"

    def object(self, index: int) -> OdObject | None:
        return self.objects.get(index)

    def entry(self, index: int, subindex: int) -> OdEntry | None:
        obj = self.objects.get(index)
        return None if obj is None else obj.entries.get(subindex)

    def entries(self) -> Iterator[OdEntry]:
        for obj in self:
            yield from obj

    def relabeled(self, source: str, path: str) -> Dictionary:
        """The same objects (shared, not copied) from another source or path."""
        return Dictionary(self.objects.values(), source, path)

    # ---------------------------------------------------------- definition
    def add_var(
        self,
        index: int,
        name: str,
        data_type: int,
        value: Value = 0,
        *,
        access: str = "rw",
        pdo: bool = False,
    ) -> OdEntry:
        """A VAR object (replacing one of the same index)."""
        raw = encode_value(data_type, value)
        entry = OdEntry(index, 0, name, data_type, access, None, raw, pdo)
        self.objects[index] = OdObject(index, name, VAR, {0: entry})
        self.version += 1
        return entry

    def add_record(
        self,
        index: int,
        name: str,
        subs: Sequence[tuple[str, int, Value, str]],
        *,
        code: ObjectCode = RECORD,
        writable_count: bool = False,
    ) -> OdObject:
        """An ARRAY/RECORD: sub 0 (UNSIGNED8, number of entries) then ``subs`` (name, data
        type, value, access) from 1."""
        count = "rw" if writable_count else "ro"
        obj = OdObject(index, name, code)
        obj.entries[0] = OdEntry(
            index, 0, "Number of entries", DataType.UNSIGNED8, count, None, bytes([len(subs)])
        )
        for i, (sub_name, dtype, value, access) in enumerate(subs, start=1):
            obj.entries[i] = OdEntry(
                index, i, sub_name, dtype, access, None, encode_value(dtype, value)
            )
        self.objects[index] = obj
        self.version += 1
        return obj

    def ensure_entry(
        self,
        index: int,
        subindex: int,
        name: str,
        data_type: int,
        access: str = "rw",
        bit_size: int | None = None,
    ) -> OdEntry:
        """The entry, created (zero value of its type's size or ``bit_size``,
        PDO-mappable, ``access``) if it is not there."""
        obj = self.objects.get(index)
        if obj is None:
            obj = OdObject(index, name, VAR if subindex == 0 else RECORD)
            self.objects[index] = obj
        entry = obj.entries.get(subindex)
        if entry is None:
            bits = type_bits(data_type) or bit_size or 8
            value = bytes(max(1, (bits + 7) // 8))
            entry = OdEntry(index, subindex, name, data_type, access, None, value, True)
            obj.entries[subindex] = entry
            self.version += 1
            if subindex and 0 not in obj.entries:
                obj.entries[0] = OdEntry(
                    index, 0, "Number of entries", DataType.UNSIGNED8, "ro", None, b"\x00"
                )
            if subindex:
                count = obj.entries[0]
                count.value = bytes([max(count.value[0] if count.value else 0, subindex)])
        return entry

    # -------------------------------------------------------- served access
    def require(self, index: int, subindex: int) -> OdEntry:
        """The entry, or the abort an SDO server answers when it is not there."""
        obj = self.objects.get(index)
        if obj is None:
            raise _abort(index, subindex, "NO_OBJECT")
        entry = obj.entries.get(subindex)
        if entry is None:
            raise _abort(index, subindex, "NO_SUBINDEX")
        return entry

    def read(self, index: int, subindex: int) -> bytes:
        """SDO upload: the entry's bytes, or an abort."""
        entry = self.require(index, subindex)
        if not entry.readable:
            raise _abort(index, subindex, "WRITE_ONLY")
        return entry.value

    def write(self, index: int, subindex: int, data: bytes) -> None:
        """SDO download: read-only refused, the PDO configuration outside PREOP refused,
        the length checked against the type's."""
        entry = self.require(index, subindex)
        if not entry.writable:
            raise _abort(index, subindex, "READ_ONLY")
        if self.al_state not in (None, AlState.PREOP) and pdo_configuration(index):
            raise _abort(index, subindex, "CANNOT_TRANSFER_DEVICE_STATE")
        bits = None if entry.data_type is None else type_bits(entry.data_type)
        if bits is not None and len(data) != max(1, (bits + 7) // 8):
            # CiA 301 also has 0x06070012 (too high) and 0x06070013 (too low); the
            # general 0x06070010 is what CANopen stacks and SOEM's slaves answer, so
            # every backend of `lolacli sdo write` reports one code for one mistake
            raise _abort(index, subindex, "LENGTH_MISMATCH")
        entry.value = bytes(data)
        self.version += 1
        self.writes += 1

    def get(self, index: int, subindex: int = 0) -> Value:
        """The entry's value, typed (bytes where they do not fit the type)."""
        entry = self.require(index, subindex)
        return typed_value(entry.data_type, entry.value)

    def get_int(self, index: int, subindex: int = 0) -> int:
        value = self.get(index, subindex)
        return int(value) if isinstance(value, int | float) else 0

    def set(self, index: int, subindex: int, value: Value) -> None:
        """Device-side write: no access check; the value must fit the entry's type."""
        entry = self.require(index, subindex)
        if entry.data_type is None:
            raise ValueError(f"0x{index:04X}:{subindex:02X} has no data type to encode by")
        entry.value = encode_value(entry.data_type, value)
        self.writes += 1


def _abort(index: int, subindex: int, code: str) -> SdoAbortError:
    """The abort of a served access (CiA 301 code by name). :mod:`lolacli.wire.sdo` loads
    here, on an abort only: the ESI/ENI readers that build dictionaries need none of its
    import time (15–40 ms on a loaded host)."""
    from lolacli.wire.sdo import SdoAbortCode

    return SdoAbortError(index, subindex, SdoAbortCode[code])


# --- SDO Information ---------------------------------------------------------------------------


def info_entry(
    index: int, subindex: int, name: str, data_type: int, bits: int, access: int
) -> OdEntry:
    """An entry as a Get Entry Description answer gives it (ETG.1000.6 Table 54): data
    type 0 or bit length 0 are not known."""
    return OdEntry(
        index,
        subindex,
        name,
        data_type or None,
        access_text(access),
        bits or None,
        b"",
        bool(access & ACCESS_PDO),
    )


SdoInfoObject = tuple[int, str, int, int, int, Iterable[tuple[int, str, int, int, int]]]


def from_sdo_info(objects: Iterable[SdoInfoObject]) -> Dictionary:
    """SDO Information answers: per object ``(index, name, object code, data type, bit
    length, entries)`` with entries ``(subindex, name, data type, bit length, access
    word)`` (ETG.1000.6 Tables 52 and 54). A variable may come without entries (SOEM asks
    none for it): it is then one entry of the object's type, access not known (``""``)."""
    out = []
    for index, name, code, data_type, bits, entries in objects:
        items = [
            info_entry(index, sub, entry_name, kind, size, access)
            for sub, entry_name, kind, size, access in entries
        ]
        if not items:
            items = [OdEntry(index, 0, name, data_type or None, "", bits or None)]
        out.append(OdObject.of(index, name, object_code(code), items))
    return Dictionary(out, "sdo-info")


def object_code(code: int) -> ObjectCode:
    """An object code from the wire; one this model does not know counts as a VAR."""
    try:
        return ObjectCode(code)
    except ValueError:
        return VAR


__all__ = [
    "ACCESS_PDO",
    "ACCESS_READ",
    "ACCESS_WRITE",
    "ARRAY",
    "RECORD",
    "VAR",
    "Dictionary",
    "ObjectCode",
    "OdEntry",
    "OdObject",
    "SdoInfoObject",
    "access_text",
    "access_word",
    "from_sdo_info",
    "info_entry",
    "object_code",
    "pdo_configuration",
    "typed_value",
]
