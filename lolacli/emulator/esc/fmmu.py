"""Logical addressing through the FMMUs (ETG.1000.4 §6.5): LRD/LWR/LRW bit- or byte-wise
between the datagram and the slave's memory."""

from __future__ import annotations

from lolacli.emulator.esc.memory import PLAN_FREE_REGISTERS
from lolacli.emulator.esc.sm import SyncManagers
from lolacli.wire.commands import Command, wkc_increment
from lolacli.wire.registers import Fmmu, decode_fmmu, fmmu_address


def byte_aligned(f: Fmmu) -> bool:
    return f.logical_start_bit == 0 and f.logical_stop_bit == 7 and f.physical_start_bit == 0


def _bit_pairs(f: Fmmu, address: int, n: int) -> list[tuple[int, int]]:
    """(datagram bit, memory bit) for every bit the FMMU maps inside the datagram."""
    first = f.logical_start * 8 + f.logical_start_bit
    last = (f.logical_start + f.length_bytes - 1) * 8 + f.logical_stop_bit
    lo = max(first, address * 8)
    hi = min(last, (address + n) * 8 - 1)
    base = f.physical_start * 8 + f.physical_start_bit - first
    return [(b - address * 8, b + base) for b in range(lo, hi + 1)]


class Fmmus(SyncManagers):
    """The FMMUs' registers and the logical commands that go through them."""

    def fmmu(self, index: int) -> Fmmu:
        return decode_fmmu(self._view, fmmu_address(index))

    def logical(self, cmd: int, address: int, data: memoryview, t_ns: int) -> int:
        """LRD/LWR/LRW through the FMMUs (ETG.1000.4 §6.5): this slave's write FMMUs
        take from the datagram first, then its read FMMUs put into it; the WKC as
        :func:`~lolacli.wire.commands.wkc_increment` counts what it did."""
        end = address + len(data)
        config = self.configuration()
        wrote = read = False
        if cmd != Command.LRD:
            for f in config.write_fmmus:
                if f.logical_start < end and address < f.logical_start + f.length_bytes:
                    self._fmmu_write(f, address, data)
                    wrote = True
        if cmd != Command.LWR:
            for f in config.read_fmmus:
                if f.logical_start < end and address < f.logical_start + f.length_bytes:
                    self._fmmu_read(f, address, data)
                    read = True
        return wkc_increment(cmd, read=read, write=wrote)

    def _fmmu_write(self, f: Fmmu, address: int, incoming: memoryview) -> None:
        if f.physical_start < PLAN_FREE_REGISTERS:
            self.epoch[0] += 1  # a write into registers, bypassing their side effects
            self.addressing[0] += 1
        if byte_aligned(f):
            lo = max(address, f.logical_start)
            hi = min(address + len(incoming), f.logical_start + f.length_bytes)
            p = f.physical_start + (lo - f.logical_start)
            self.mem[p : p + hi - lo] = incoming[lo - address : hi - address]
            self._sm_written(p, p + hi - lo)
            return
        for lbit, pbit in _bit_pairs(f, address, len(incoming)):
            value = (incoming[lbit >> 3] >> (lbit & 7)) & 1
            byte = pbit >> 3
            self.mem[byte] = (self.mem[byte] & ~(1 << (pbit & 7))) | (value << (pbit & 7))
        self._sm_written(f.physical_start, f.physical_start + f.length_bytes)

    def _fmmu_read(self, f: Fmmu, address: int, data: memoryview) -> None:
        if byte_aligned(f):
            lo = max(address, f.logical_start)
            hi = min(address + len(data), f.logical_start + f.length_bytes)
            p = f.physical_start + (lo - f.logical_start)
            data[lo - address : hi - address] = self.mem[p : p + hi - lo]
            self._after_read(p, p + hi - lo)
            return
        for lbit, pbit in _bit_pairs(f, address, len(data)):
            value = (self.mem[pbit >> 3] >> (pbit & 7)) & 1
            i = lbit >> 3
            data[i] = (data[i] & ~(1 << (lbit & 7))) | (value << (lbit & 7))
