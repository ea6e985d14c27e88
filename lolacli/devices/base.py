"""The device behind an ESC: object dictionary, PDO mapping, one step per cycle.

A device owns a :class:`~lolacli.od.Dictionary` (the one model, holding the values) with
the communication objects of CiA 301 / ETG.1000.6 (0x1000 device type, 0x1008 name,
0x1018 identity, 0x1C00 SM types, 0x1C12/0x1C13 PDO assignment, 0x16xx/0x1Axx PDO
mappings) built from what the ENI says of the slave — its PDOs and CoE InitCmds, read by
:func:`lolacli.eni.dictionary.from_eni` and typed as the ``sdo`` commands type them.
Every cycle it unpacks the outputs through the RxPDO mapping into the dictionary, runs
:meth:`Device.step`, and packs the inputs through the TxPDO mapping.
"""

from __future__ import annotations

from typing import Any

from lolacli.eni.dictionary import from_eni
from lolacli.eni.model import Direction, Pdo, Slave
from lolacli.od import ARRAY, Dictionary, OdEntry
from lolacli.wire.datatypes import DataType

MAPPING_RX = 0x1600
MAPPING_TX = 0x1A00
ASSIGN_RX = 0x1C12
ASSIGN_TX = 0x1C13
SM_TYPES = 0x1C00
MAX_ENTRIES = 8  # sub-indices of a PDO mapping object (the count in sub 0 says how many are used)
MAX_PDOS = 4  # sub-indices of a PDO assignment object


def assigned_pdos(pdos: tuple[Pdo, ...], direction: Direction) -> list[Pdo]:
    """The PDOs of ``direction`` an ENI assigns to a sync manager (``<SmN><Pdo>`` or
    ``Sm=``); an ENI that assigns none of them lists only the ones it uses: all."""
    of = [p for p in pdos if p.direction == direction]
    return [p for p in of if p.sync_manager is not None] or of


_UNSIGNED_BY_LENGTH = {
    1: DataType.UNSIGNED8,
    2: DataType.UNSIGNED16,
    4: DataType.UNSIGNED32,
    8: DataType.UNSIGNED64,
}


def device_type_of(entry: OdEntry) -> int:
    """The type a device gives an entry the ENI describes: the ENI's, else unsigned by
    its size (BOOLEAN for one bit), else an octet string."""
    if entry.data_type is not None:
        return entry.data_type
    if entry.bits == 1:
        return DataType.BOOLEAN
    if entry.bits % 8 == 0 and entry.bits // 8 in _UNSIGNED_BY_LENGTH:
        return _UNSIGNED_BY_LENGTH[entry.bits // 8]
    return DataType.OCTET_STRING if entry.bits > 8 else DataType.UNSIGNED8


class Device:
    """A generic device: its process data are plain object-dictionary entries."""

    device_type = 0x00000000

    def __init__(self, slave: Slave) -> None:
        self.slave = slave
        self.od = Dictionary()
        self._eni = from_eni(slave, init_cmds=True) or Dictionary(source="eni")
        self.state = 1
        self.t_ns = 0
        self._layouts: dict[Direction, tuple[tuple[Direction, int], list[Any]]] = {}
        self._sizes: tuple[int, tuple[int, int]] | None = None
        self._byte_layouts: dict[
            Direction, tuple[tuple[Direction, int], list[tuple[OdEntry | None, int, int]] | None]
        ] = {}
        # (outputs, od.writes, inputs) after a step that changed nothing: the same outputs
        # with the dictionary untouched give the same inputs without stepping
        self.rest_cache: tuple[bytes, int, bytes] | None = None
        self._communication_objects()
        self._pdo_objects(slave.pdos)
        self.define()
        self._init_cmd_objects()

    # ---------------------------------------------------------- definition
    def define(self) -> None:
        """Subclasses add their objects here."""

    def _communication_objects(self) -> None:
        od, ident = self.od, self.slave.identity
        od.add_var(0x1000, "Device type", DataType.UNSIGNED32, self.device_type, access="ro")
        od.add_var(
            0x1008,
            "Manufacturer device name",
            DataType.VISIBLE_STRING,
            self.slave.name,
            access="const",
        )
        od.add_var(
            0x1009, "Manufacturer hardware version", DataType.VISIBLE_STRING, "1.0", access="const"
        )
        od.add_var(
            0x100A,
            "Manufacturer software version",
            DataType.VISIBLE_STRING,
            "lolacli emulator",
            access="const",
        )
        od.add_record(
            0x1018,
            "Identity",
            [
                ("Vendor ID", DataType.UNSIGNED32, ident.vendor_id, "ro"),
                ("Product code", DataType.UNSIGNED32, ident.product_code, "ro"),
                ("Revision", DataType.UNSIGNED32, ident.revision, "ro"),
                ("Serial number", DataType.UNSIGNED32, ident.serial, "ro"),
            ],
        )
        od.add_record(
            SM_TYPES,
            "Sync manager communication type",
            [
                ("SM0", DataType.UNSIGNED8, 1, "ro"),
                ("SM1", DataType.UNSIGNED8, 2, "ro"),
                ("SM2", DataType.UNSIGNED8, 3, "ro"),
                ("SM3", DataType.UNSIGNED8, 4, "ro"),
            ],
            code=ARRAY,
        )

    def _pdo_objects(self, pdos: tuple[Pdo, ...]) -> None:
        """Mapping objects for every PDO the ENI lists; 0x1C12/0x1C13 assign those the
        ENI assigns to a sync manager (all of a direction where it assigns none)."""
        rx = assigned_pdos(pdos, Direction.OUTPUT)
        tx = assigned_pdos(pdos, Direction.INPUT)
        for pdo in pdos:
            subs = []
            for e in pdo.entries:
                value = (e.index << 16) | (e.subindex << 8) | e.bit_size
                subs.append((e.name or "Mapped object", DataType.UNSIGNED32, value, "rw"))
                described = self._eni.entry(e.index, e.subindex) if e.index else None
                if described is not None:  # inputs are the device's to write: read-only
                    access = "ro" if pdo.direction == Direction.INPUT else "rw"
                    kind = device_type_of(described)
                    self.od.ensure_entry(
                        e.index, e.subindex, described.name, kind, access, described.bits
                    )
            used = len(subs)
            subs += [("Mapped object", DataType.UNSIGNED32, 0, "rw")] * (MAX_ENTRIES - used)
            self.od.add_record(
                pdo.index, pdo.name or f"PDO 0x{pdo.index:04X}", subs, writable_count=True
            )
            self.od.set(pdo.index, 0, used)
        for index, assigned in ((ASSIGN_RX, rx), (ASSIGN_TX, tx)):
            subs = [("PDO", DataType.UNSIGNED16, p.index, "rw") for p in assigned]
            used = len(subs)
            subs += [("PDO", DataType.UNSIGNED16, 0, "rw")] * max(0, MAX_PDOS - used)
            self.od.add_record(
                index, "PDO assignment", subs, code=ARRAY, writable_count=True
            )
            self.od.set(index, 0, used)

    def _init_cmd_objects(self) -> None:
        """Objects the ENI's CoE InitCmds write that the model lacks (a manufacturer's
        parameter, a generic device's 0x6060): the configurator took them from the device's
        ESI, so the real device has them. Each becomes a read-write entry of the written
        length (unsigned for 1/2/4/8 bytes, else an octet string). Complete-access writes
        are left alone: the sub-indexes' sizes are not in the ENI."""
        for e in self._eni.entries():
            if not e.value or (e.index, e.subindex) in self.od:
                continue  # not an InitCmd's, or an object the model has
            data_type = _UNSIGNED_BY_LENGTH.get(len(e.value), DataType.OCTET_STRING)
            name = e.name or f"Object 0x{e.index:04X}:{e.subindex:02X}"
            entry = self.od.ensure_entry(e.index, e.subindex, name, data_type)
            entry.value = bytes(len(e.value))

    # ------------------------------------------------------------- mapping
    def mapping(self, direction: Direction) -> list[tuple[int, int, int]]:
        """(index, subindex, bits) in process-image order, from 0x1C12/0x1C13."""
        return [(index, sub, bits) for index, sub, bits, _ in self.pdo_layout(direction)]

    def pdo_layout(self, direction: Direction) -> list[tuple[int, int, int, OdEntry | None]]:
        key = (direction, self.od.version)
        cached = self._layouts.get(direction)
        if cached is not None and cached[0] == key:
            return cached[1]
        assign = ASSIGN_RX if direction == Direction.OUTPUT else ASSIGN_TX
        out: list[tuple[int, int, int, OdEntry | None]] = []
        for n in range(1, self.od.get_int(assign, 0) + 1):
            pdo = self.od.get_int(assign, n)
            if pdo not in self.od.objects:
                continue
            for k in range(1, self.od.get_int(pdo, 0) + 1):
                word = self.od.get_int(pdo, k)
                index, sub, bits = word >> 16, (word >> 8) & 0xFF, word & 0xFF
                entry = self.od.entry(index, sub) if index else None
                out.append((index, sub, bits, entry))
        self._layouts[direction] = (key, out)
        return out

    def process_data_bytes(self) -> tuple[int, int]:
        version = self.od.version
        if self._sizes is None or self._sizes[0] != version:
            outputs = sum(m[2] for m in self.pdo_layout(Direction.OUTPUT))
            inputs = sum(m[2] for m in self.pdo_layout(Direction.INPUT))
            self._sizes = (version, ((outputs + 7) // 8, (inputs + 7) // 8))
        return self._sizes[1]

    def byte_layout_of(self, direction: Direction) -> list[tuple[OdEntry | None, int, int]] | None:
        """(entry, byte offset, bytes) when every mapped entry is whole bytes, else None."""
        key = (direction, self.od.version)
        cached = self._byte_layouts.get(direction)
        if cached is not None and cached[0] == key:
            return cached[1]
        layout = self.pdo_layout(direction)
        out: list[tuple[OdEntry | None, int, int]] | None = []
        bit = 0
        for _index, _sub, bits, entry in layout:
            if bits % 8 or out is None:
                out = None
                break
            if entry is not None and len(entry.value) != bits // 8:
                out = None  # a mapping narrower or wider than the object: bit path
                break
            out.append((entry, bit // 8, bits // 8))
            bit += bits
        self._byte_layouts[direction] = (key, out)
        return out

    def unpack_outputs(self, outputs: bytes) -> None:
        fast = self.byte_layout_of(Direction.OUTPUT)
        if fast is not None:
            for entry, offset, size in fast:
                if entry is not None:
                    entry.value = outputs[offset : offset + size]
            return
        image = int.from_bytes(outputs, "little")
        bit = 0
        for _index, _sub, bits, entry in self.pdo_layout(Direction.OUTPUT):
            if entry is not None:
                value = (image >> bit) & ((1 << bits) - 1)
                entry.value = value.to_bytes((bits + 7) // 8 or 1, "little")
            bit += bits

    def pack_inputs(self) -> bytes:
        fast = self.byte_layout_of(Direction.INPUT)
        if fast is not None:
            return b"".join(e.value if e is not None else bytes(n) for e, _o, n in fast)
        image = 0
        bit = 0
        for _index, _sub, bits, entry in self.pdo_layout(Direction.INPUT):
            if entry is not None:
                image |= (int.from_bytes(entry.value, "little") & ((1 << bits) - 1)) << bit
            bit += bits
        return image.to_bytes((bit + 7) // 8, "little")

    # ---------------------------------------------------------------- cycle
    def state_changed(self, state: int) -> None:
        self.state = state
        self.rest_cache = None

    def cycle(self, outputs: bytes, t_ns: int) -> bytes:
        """Outputs in (empty in SAFEOP), one step, inputs out."""
        rest = self.rest_cache
        if rest is not None and rest[0] == outputs and rest[1] == self.od.writes:
            self.t_ns = t_ns  # at rest: a step would change nothing
            return rest[2]
        if outputs:
            self.unpack_outputs(outputs)
        self.step(t_ns)
        self.t_ns = t_ns
        inputs = self.pack_inputs()
        self.rest_cache = (outputs, self.od.writes, inputs) if self.at_rest() else None
        return inputs

    def step(self, t_ns: int) -> None:
        """One application cycle at time ``t_ns``; subclasses move their values here."""

    def at_rest(self) -> bool:
        """True when, after this step, another step with the same outputs at any later
        time would change nothing (a fixed point); devices that change with time say no."""
        return False
