"""Bus Variables (seed 000 §IV-B, Fig. 4): typed variables linked to the process image by
their ENI names.

A Bus Variable (:class:`BusUInt16`, :class:`BusInt32`, :class:`BusReal32`, …) is an input
or an output. :meth:`ProcessImage.link` ties it to an ENI process-image variable
(``"Joint04 L Knee.Inputs.Position actual value"``) and checks, at link time, that the
name exists, that the directions agree and that the type fits (a :class:`BusInt32` takes
``DINT``; sizes must match); a failure is a :class:`~lolacli.errors.LinkError` naming the
variable.

Every cycle the master copies the returned inputs into the image and publishes an
immutable :class:`Snapshot` of them (the seed's copyRXData); reading an input variable
reads the latest snapshot. A reader on another thread that needs several inputs of one
cycle takes one snapshot and reads them from it (``snap[var]``): a snapshot never changes.
Writing an output variable packs the value into the outputs image under the image's
lock; the master copies the outputs into the frame under the same lock (copyTXData), so
``with image.lock:`` around several writes makes them reach the bus in one cycle.
"""

from __future__ import annotations

import difflib
import struct
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

from lolacli.eni.model import Direction, Slave, Variable
from lolacli.eni.model import ProcessImage as EniProcessImage
from lolacli.errors import LinkError, UsageError
from lolacli.wire.datatypes import DataType, data_type_from_name


@dataclass(frozen=True, slots=True)
class Snapshot:
    """The inputs image as it came back in cycle ``cycle`` (never changes)."""

    cycle: int
    data: bytes

    def __getitem__(self, variable: BusVariable) -> Any:
        return variable.read(self.data)


class BusVariable:
    """A typed process-data variable (see the module docstring). Make one with
    ``BusInt32.input()`` / ``BusInt32.output()`` (or ``BusInt32(Direction.INPUT)``)."""

    data_types: ClassVar[frozenset[DataType]] = frozenset()
    bit_size: ClassVar[int] = 0
    fmt: ClassVar[str] = ""

    __slots__ = ("direction", "name", "_image", "_byte", "_bit", "_bits", "_struct")

    def __init__(self, direction: Direction, name: str = "") -> None:
        self.direction = Direction(direction)
        self.name = name  # the ENI name once linked (or a relative one for BusSlave fields)
        self._image: ProcessImage | None = None
        self._byte = 0
        self._bit = 0
        self._bits = self.bit_size
        self._struct = struct.Struct("<" + self.fmt) if self.fmt else None

    @classmethod
    def input(cls, name: str = "") -> Any:
        return cls(Direction.INPUT, name)

    @classmethod
    def output(cls, name: str = "") -> Any:
        return cls(Direction.OUTPUT, name)

    def __repr__(self) -> str:
        where = f" {self.name!r}" if self.name else ""
        return f"<{type(self).__name__} {self.direction.value}{where}>"

    # -- linking
    def accepts(self, variable: Variable) -> str | None:
        """Why ``variable`` does not fit this type, or None when it does."""
        named = variable.data_type.strip()
        if self.data_types and named and data_type_from_name(named) not in self.data_types:
            taken = ", ".join(sorted(t.name for t in self.data_types))
            kind = type(self).__name__
            return f"is {variable.data_type} ({variable.bit_size} bits); {kind} takes {taken}"
        if variable.bit_size != self.bit_size:
            return f"is {variable.bit_size} bits wide; {type(self).__name__} is {self.bit_size}"
        return None

    def bind(self, image: ProcessImage, variable: Variable) -> None:
        self._image = image
        self.name = variable.name
        self._byte, self._bit = divmod(variable.bit_offset, 8)
        self._bits = variable.bit_size

    @property
    def linked(self) -> bool:
        return self._image is not None

    @property
    def byte_offset(self) -> int | None:
        """Where a linked variable of whole bytes (its own struct format) starts in its
        image; ``None`` for a bit-packed one."""
        return self._byte if self._bit == 0 and self._struct is not None else None

    # -- values
    def read(self, data: bytes | bytearray) -> Any:
        """This variable's value in an image ``data``."""
        if self._bit == 0 and self._struct is not None:
            return self._struct.unpack_from(data, self._byte)[0]
        return self._from_bits(data)

    def _from_bits(self, data: bytes | bytearray) -> Any:
        n = (self._bit + self._bits + 7) // 8
        raw = int.from_bytes(data[self._byte : self._byte + n], "little")
        return (raw >> self._bit) & ((1 << self._bits) - 1)

    def _to_bits(self, data: bytearray, value: int) -> None:
        n = (self._bit + self._bits + 7) // 8
        mask = ((1 << self._bits) - 1) << self._bit
        raw = int.from_bytes(data[self._byte : self._byte + n], "little")
        raw = (raw & ~mask) | ((int(value) << self._bit) & mask)
        data[self._byte : self._byte + n] = raw.to_bytes(n, "little")

    def check(self, value: Any) -> Any:
        return value

    @property
    def value(self) -> Any:
        image = self._need_image()
        data = image.snapshot.data if self.direction is Direction.INPUT else image.outputs
        if self._bit == 0 and self._struct is not None:
            return self._struct.unpack_from(data, self._byte)[0]
        return self.read(data)

    @value.setter
    def value(self, value: Any) -> None:
        # one pack_into is one step under the GIL: the master's copy of the outputs into
        # the frame sees the value before or after, never half of it (no lock needed for
        # one variable; hold image.lock around several to send them in one cycle)
        image = self._image
        if image is None or self.direction is Direction.INPUT:
            self._refuse_write()
        if self._bit == 0 and self._struct is not None:
            try:
                self._struct.pack_into(image.outputs, self._byte, value)  # type: ignore[union-attr]
                return
            except struct.error:
                self.check(value)
                raise
        self._to_bits(image.outputs, self.check(value))  # type: ignore[union-attr]

    def _refuse_write(self) -> None:
        if self._image is None:
            raise UsageError(f"{self!r} is not linked to a process-image variable")
        raise UsageError(f"bus variable {self.name!r} is an input: it cannot be written")

    def _need_image(self) -> ProcessImage:
        if self._image is None:
            raise UsageError(f"{self!r} is not linked to a process-image variable")
        return self._image


class _BusInt(BusVariable):
    __slots__ = ()
    signed: ClassVar[bool] = False

    def check(self, value: Any) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise LinkError(self.name, f"{type(self).__name__} takes an int, not {value!r}")
        lo = -(1 << (self.bit_size - 1)) if self.signed else 0
        hi = (1 << (self.bit_size - 1)) - 1 if self.signed else (1 << self.bit_size) - 1
        if not lo <= value <= hi:
            raise LinkError(self.name, f"{value} is outside {lo}..{hi}")
        return value


class BusBool(BusVariable):
    __slots__ = ()
    data_types = frozenset({DataType.BOOLEAN, DataType.BIT1})
    bit_size = 1

    def read(self, data: bytes | bytearray) -> bool:
        return bool(data[self._byte] >> self._bit & 1)

    def check(self, value: Any) -> int:
        if not isinstance(value, (bool, int)) or value not in (0, 1):
            raise LinkError(self.name, f"BusBool takes True/False, not {value!r}")
        return int(value)


class BusInt8(_BusInt):
    __slots__ = ()
    data_types = frozenset({DataType.INTEGER8})
    bit_size, fmt, signed = 8, "b", True


class BusUInt8(_BusInt):
    __slots__ = ()
    data_types = frozenset({DataType.UNSIGNED8, DataType.BYTE, DataType.BITARR8})
    bit_size, fmt = 8, "B"


class BusInt16(_BusInt):
    __slots__ = ()
    data_types = frozenset({DataType.INTEGER16})
    bit_size, fmt, signed = 16, "h", True


class BusUInt16(_BusInt):
    __slots__ = ()
    data_types = frozenset({DataType.UNSIGNED16, DataType.WORD, DataType.BITARR16})
    bit_size, fmt = 16, "H"


class BusInt32(_BusInt):
    __slots__ = ()
    data_types = frozenset({DataType.INTEGER32})
    bit_size, fmt, signed = 32, "i", True


class BusUInt32(_BusInt):
    __slots__ = ()
    data_types = frozenset({DataType.UNSIGNED32, DataType.DWORD, DataType.BITARR32})
    bit_size, fmt = 32, "I"


class BusInt64(_BusInt):
    __slots__ = ()
    data_types = frozenset({DataType.INTEGER64})
    bit_size, fmt, signed = 64, "q", True


class BusUInt64(_BusInt):
    __slots__ = ()
    data_types = frozenset({DataType.UNSIGNED64})
    bit_size, fmt = 64, "Q"


class BusReal32(BusVariable):
    __slots__ = ()
    data_types = frozenset({DataType.REAL32})
    bit_size, fmt = 32, "f"

    def check(self, value: Any) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise LinkError(self.name, f"{type(self).__name__} takes a number, not {value!r}")
        return float(value)


class BusReal64(BusReal32):
    __slots__ = ()
    data_types = frozenset({DataType.REAL64})
    bit_size, fmt = 64, "d"


class BusBytes(BusVariable):
    """An octet string (``ARRAY [0..n] OF BYTE``, ``STRING(n)``) of any size."""

    __slots__ = ()

    def accepts(self, variable: Variable) -> str | None:
        data_type = variable.data_type.upper()
        if variable.bit_size % 8 or not (
            data_type.startswith(("ARRAY", "STRING", "OCTET")) or not data_type
        ):
            what = f"{variable.data_type} ({variable.bit_size} bits)"
            return f"is {what}; BusBytes takes byte arrays and strings"
        return None

    def read(self, data: bytes | bytearray) -> bytes:
        return bytes(data[self._byte : self._byte + self._bits // 8])

    def check(self, value: Any) -> bytes:
        if not isinstance(value, (bytes, bytearray)) or len(value) != self._bits // 8:
            raise LinkError(self.name, f"BusBytes takes {self._bits // 8} bytes, not {value!r}")
        return bytes(value)

    @property
    def value(self) -> Any:
        return BusVariable.value.fget(self)  # type: ignore[attr-defined]

    @value.setter
    def value(self, value: Any) -> None:
        image = self._need_image()
        if self.direction is Direction.INPUT:
            raise UsageError(f"bus variable {self.name!r} is an input: it cannot be written")
        data = self.check(value)
        with image.lock:
            image.outputs[self._byte : self._byte + len(data)] = data


#: the Bus Variable type for a data type (where one type fits)
TYPE_FOR: dict[DataType, type[BusVariable]] = {
    t: cls
    for cls in (
        BusBool,
        BusInt8,
        BusUInt8,
        BusInt16,
        BusUInt16,
        BusInt32,
        BusUInt32,
        BusInt64,
        BusUInt64,
        BusReal32,
        BusReal64,
    )
    for t in cls.data_types
}


def variable_for(variable: Variable) -> BusVariable:
    """A Bus Variable of the type that fits an ENI variable (BusBytes for arrays)."""
    data_type = data_type_from_name(variable.data_type)
    cls = None if data_type is None else TYPE_FOR.get(data_type)
    if cls is None or cls.bit_size != variable.bit_size:
        cls = BusBytes if variable.bit_size % 8 == 0 else _Bits
    return cls(variable.direction)


class _Bits(_BusInt):
    __slots__ = ()

    def accepts(self, variable: Variable) -> str | None:
        return None

    def check(self, value: Any) -> int:
        if (
            isinstance(value, bool)
            or not isinstance(value, int)
            or not 0 <= value < 1 << self._bits
        ):
            raise LinkError(self.name, f"takes 0..{(1 << self._bits) - 1}, not {value!r}")
        return value


class ProcessImage:
    """The inputs and outputs images of one master and the Bus Variables linked to them
    (see the module docstring)."""

    def __init__(
        self,
        eni_image: EniProcessImage,
        inputs_bytes: int,
        outputs_bytes: int,
        slaves: Sequence[Slave],
    ) -> None:
        self.inputs = bytearray(inputs_bytes)
        self.outputs = bytearray(outputs_bytes)
        self.lock = threading.Lock()
        self.snapshot = Snapshot(-1, bytes(inputs_bytes))
        self.variables = {v.name: v for v in eni_image.variables}
        self.linked: list[BusVariable] = []
        self.slave_names = [s.name for s in slaves]  # by 1-based position
        #: (slave name, object index, subindex, direction) -> the variable an assigned PDO
        #: maps it to (ENI variables are named "<slave>.<PDO name>.<entry name>", ETG.2100)
        self.objects: dict[tuple[str, int, int, Direction], str] = {}
        for slave in slaves:
            for pdo in slave.pdos:
                if pdo.sync_manager is None:
                    continue  # not assigned: not in the process image
                for e in pdo.entries:
                    name = f"{slave.name}.{pdo.name}.{e.name}"
                    if e.index and name in self.variables:
                        key = (slave.name, e.index, e.subindex, pdo.direction)
                        self.objects.setdefault(key, name)

    def publish(self, cycle: int) -> None:
        """copyRXData: the inputs as they are now become the snapshot of ``cycle``."""
        self.snapshot = Snapshot(cycle, bytes(self.inputs))

    def slave_name(self, slave: str | int) -> str:
        """The ENI name of ``slave``: given by name, or by its 1-based position (an int)."""
        if isinstance(slave, bool) or not isinstance(slave, int):
            return str(slave)
        if not 1 <= slave <= len(self.slave_names):
            raise LinkError(
                f"slave {slave}", f"no slave at position {slave} (1 to {len(self.slave_names)})"
            )
        return self.slave_names[slave - 1]

    def find(self, name: str) -> Variable:
        """The ENI variable ``name``; LinkError with the closest names when unknown."""
        v = self.variables.get(name)
        if v is None:
            close = difflib.get_close_matches(name, list(self.variables), n=2)
            hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
            raise LinkError(name, f"no such variable in the ENI's process image{hint}")
        return v

    def link(self, name: str, variable: BusVariable) -> BusVariable:
        """Tie ``variable`` to the ENI variable ``name`` (checked: name, direction, type)."""
        v = self.find(name)
        if variable.direction != v.direction:
            raise LinkError(
                name,
                f"is an {v.direction.value} of the process image; "
                f"an {variable.direction.value} {type(variable).__name__} cannot link to it",
            )
        why = variable.accepts(v)
        if why is not None:
            raise LinkError(name, why)
        image_bytes = len(self.inputs if v.direction is Direction.INPUT else self.outputs)
        if (v.bit_offset + v.bit_size + 7) // 8 > image_bytes:
            raise LinkError(name, f"lies outside the {image_bytes}-byte {v.direction.value} image")
        variable.bind(self, v)
        self.linked.append(variable)
        return variable


__all__ = [
    "BusBool",
    "BusBytes",
    "BusInt8",
    "BusInt16",
    "BusInt32",
    "BusInt64",
    "BusReal32",
    "BusReal64",
    "BusUInt8",
    "BusUInt16",
    "BusUInt32",
    "BusUInt64",
    "BusVariable",
    "ProcessImage",
    "Snapshot",
    "variable_for",
]
