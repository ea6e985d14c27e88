"""Process data in shared memory: the bus process publishes each cycle's inputs and takes
outputs from other processes (both seeds connect their planners this way).

One ``multiprocessing.shared_memory`` block, little endian::

    0   magic "LOLASHM1"
    8   inputs sequence u64     (odd while the bus writes the inputs)
    16  cycle u64               (of the inputs)
    24  time ns u64             (of the inputs, the bus's clock)
    32  inputs bytes u32, outputs bytes u32
    40  outputs sequence u64    (odd while a client writes outputs and mask)
    48  reserved (16)
    64  inputs image | outputs image | outputs mask (1 = the client sets this byte)

Both directions use a sequence lock: the writer makes the sequence odd, writes, makes it
even again; a reader copies between two reads of the sequence and keeps the copy only when
both are the same even number — no torn snapshot, no lock shared between processes. One
writer per direction: the bus for the inputs, one client for the outputs.

:class:`ShmPublisher` is the bus side (``lolacli bus simulate --shm NAME``);
:class:`ShmClient` the other process's side: ``read()`` a snapshot, ``get(name)`` a
variable of it, ``set(name, value)`` and ``commit()`` outputs, by ENI variable names.
"""

from __future__ import annotations

import struct
import time
from multiprocessing import shared_memory
from typing import Any

from lolacli.eni.model import Direction, Eni
from lolacli.errors import TransportError, UsageError
from lolacli.master.variables import BusVariable, ProcessImage, Snapshot, variable_for

MAGIC = b"LOLASHM1"
HEADER_BYTES = 64
_U64 = struct.Struct("<Q")
_SIZES = struct.Struct("<II")
_IN_SEQ, _CYCLE, _TIME, _SIZES_AT, _OUT_SEQ = 8, 16, 24, 32, 40


def _spans(mask: bytes | bytearray) -> list[tuple[int, int]]:
    """Runs of nonzero mask bytes as (start, end)."""
    out: list[tuple[int, int]] = []
    start = None
    for i, m in enumerate(mask):
        if m and start is None:
            start = i
        elif not m and start is not None:
            out.append((start, i))
            start = None
    if start is not None:
        out.append((start, len(mask)))
    return out


class ShmPublisher:
    """The bus side: creates the block, publishes inputs, applies client outputs."""

    def __init__(self, name: str, inputs_bytes: int, outputs_bytes: int) -> None:
        size = HEADER_BYTES + inputs_bytes + 2 * outputs_bytes
        try:
            self.shm = shared_memory.SharedMemory(name=name, create=True, size=size)
        except FileExistsError:
            raise UsageError(f"--shm {name}: a shared memory block of that name exists") from None
        except (OSError, ValueError) as exc:
            raise UsageError(f"--shm {name}: {exc}") from None
        self.name = name
        self.n_in, self.n_out = inputs_bytes, outputs_bytes
        buf = self._buf()
        buf[0:8] = MAGIC
        _SIZES.pack_into(buf, _SIZES_AT, inputs_bytes, outputs_bytes)
        self._in_at = HEADER_BYTES
        self._out_at = HEADER_BYTES + inputs_bytes
        self._mask_at = self._out_at + outputs_bytes
        self._seq = 0
        self._out_seq = 0
        self._spans: list[tuple[int, int]] = []
        self._outputs = b""
        self.applied = 0

    def publish(self, cycle: int, t_ns: int, inputs: bytes | bytearray) -> None:
        buf = self._buf()
        self._seq += 1
        _U64.pack_into(buf, _IN_SEQ, self._seq)  # odd: writing
        buf[self._in_at : self._in_at + self.n_in] = inputs
        _U64.pack_into(buf, _CYCLE, cycle)
        _U64.pack_into(buf, _TIME, t_ns)
        self._seq += 1
        _U64.pack_into(buf, _IN_SEQ, self._seq)

    def apply(self, outputs: bytearray) -> None:
        """Copy the bytes a client set (its mask) into ``outputs``, as of its last commit."""
        buf = self._buf()
        seq = _U64.unpack_from(buf, _OUT_SEQ)[0]
        if seq != self._out_seq and not seq & 1:
            data = bytes(buf[self._out_at : self._out_at + self.n_out])
            mask = bytes(buf[self._mask_at : self._mask_at + self.n_out])
            if _U64.unpack_from(buf, _OUT_SEQ)[0] == seq:  # not torn
                self._out_seq = seq
                self._outputs = data
                self._spans = _spans(mask)
        data = self._outputs
        for start, end in self._spans:
            outputs[start:end] = data[start:end]
        if self._spans:
            self.applied += 1

    def _buf(self) -> memoryview:
        buf = self.shm.buf
        assert buf is not None  # open until close()
        return buf

    def close(self) -> None:
        try:
            self.shm.close()
            self.shm.unlink()
        except (FileNotFoundError, BufferError):
            pass


class ShmClient:
    """Another process's side of a bus's shared memory (see the module docstring).

    ``eni`` is the bus's ENI (for the variable names and offsets)."""

    def __init__(self, name: str, eni: Eni, *, timeout_s: float = 10.0) -> None:
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                self.shm = shared_memory.SharedMemory(name=name, create=False)
                break
            except FileNotFoundError:
                if time.monotonic() >= deadline:
                    raise TransportError(f"no shared memory block {name!r}") from None
                time.sleep(0.01)
        _untrack(self.shm)
        buf = self._buf()
        while bytes(buf[0:8]) != MAGIC:  # the bus may still be writing the header
            if time.monotonic() >= deadline:
                raise TransportError(f"{name!r} is not a lolacli shared memory block")
            time.sleep(0.01)
        self.n_in, self.n_out = _SIZES.unpack_from(buf, _SIZES_AT)
        self._in_at = HEADER_BYTES
        self._out_at = HEADER_BYTES + self.n_in
        self._mask_at = self._out_at + self.n_out
        self.image = ProcessImage(eni.process_image, self.n_in, self.n_out, eni.slaves)
        self._mask = bytearray(self.n_out)
        self._vars: dict[str, BusVariable] = {}

    def read(self) -> Snapshot:
        """The inputs of the latest complete cycle (retries while the bus writes)."""
        buf = self._buf()
        while True:
            seq = _U64.unpack_from(buf, _IN_SEQ)[0]
            if seq & 1:
                continue
            data = bytes(buf[self._in_at : self._in_at + self.n_in])
            cycle = _U64.unpack_from(buf, _CYCLE)[0]
            if _U64.unpack_from(buf, _IN_SEQ)[0] == seq:
                snap = Snapshot(int(cycle), data)
                self.image.snapshot = snap
                return snap

    def variable(self, name: str) -> BusVariable:
        v = self._vars.get(name)
        if v is None:
            v = self.image.link(name, variable_for(self.image.find(name)))
            self._vars[name] = v
        return v

    def get(self, name: str, snapshot: Snapshot | None = None) -> Any:
        snap = snapshot if snapshot is not None else self.read()
        return snap[self.variable(name)]

    def set(self, name: str, value: Any) -> None:
        """Stage an output; it reaches the bus with :meth:`commit`."""
        v = self.variable(name)
        if v.direction is not Direction.OUTPUT:
            raise UsageError(f"{name!r} is an input: a client cannot set it")
        v.value = value
        info = self.image.find(name)
        first, last = info.bit_offset // 8, (info.bit_offset + info.bit_size - 1) // 8
        self._mask[first : last + 1] = b"\x01" * (last - first + 1)

    def commit(self) -> None:
        """Hand the staged outputs to the bus (one consistent update)."""
        buf = self._buf()
        seq = _U64.unpack_from(buf, _OUT_SEQ)[0] | 1  # odd: writing
        _U64.pack_into(buf, _OUT_SEQ, seq)
        buf[self._out_at : self._out_at + self.n_out] = self.image.outputs
        buf[self._mask_at : self._mask_at + self.n_out] = self._mask
        _U64.pack_into(buf, _OUT_SEQ, seq + 1)

    def _buf(self) -> memoryview:
        buf = self.shm.buf
        assert buf is not None  # open until close()
        return buf

    def close(self) -> None:
        self.shm.close()


def _untrack(shm: shared_memory.SharedMemory) -> None:
    """Python < 3.13 registers an attached block with the resource tracker, which would
    unlink it when this process ends; the bus owns it."""
    try:
        from multiprocessing import resource_tracker

        # the tracked name (with its leading slash) is private to the stdlib
        name = shm._name  # type: ignore[attr-defined]  # noqa: SLF001
        resource_tracker.unregister(name, "shared_memory")
    except Exception:  # noqa: BLE001 - best effort; newer Pythons do not track
        pass
