"""Distributed clocks (ETG.1000.4 §6.8, ET1100 datasheet §9): the slave's local clock,
system time, receive-time latches and the time control loop."""

from __future__ import annotations

import struct
from dataclasses import dataclass

from lolacli.emulator import registers as r
from lolacli.emulator.esc.memory import EscMemory
from lolacli.wire.registers import decode_system_time_difference

_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_I64 = struct.Struct("<q")
MAX_CORRECTION_NS = 1000
_TWICE_MAX_CORRECTION_NS = 2 * MAX_CORRECTION_NS
_DELAY = r.DC_SYSTEM_TIME_DELAY
_OFFSET = r.DC_SYSTEM_TIME_OFFSET
_DIFFERENCE = r.DC_SYSTEM_TIME_DIFFERENCE
_unpack_u32 = _U32.unpack_from
_unpack_i64 = _I64.unpack_from
_pack_u32 = _U32.pack_into


@dataclass(slots=True)
class DcClock:
    """The slave's local clock: ``local = t × (1 + drift_ppm·1e-6) + start_ns + correction``."""

    start_ns: int = 0
    drift_ppb: int = 0
    correction_ns: int = 0

    def local_ns(self, t_ns: int) -> int:
        return t_ns + (t_ns * self.drift_ppb) // 1_000_000_000 + self.start_ns + self.correction_ns


@dataclass(slots=True)
class PortTimes:
    """When the frame reached this slave: port 0 on the way out, port 1 on the way back."""

    port0_ns: int
    port1_ns: int | None


class DistributedClock(EscMemory):
    """The DC unit: system time, receive times, the control loop's registers."""

    clock: DcClock
    frame_t_ns: int  # when the current frame left the master
    port_offsets: PortTimes | None  # its arrival at port 0 / port 1, relative

    def system_time_ns(self, t_ns: int) -> int:
        offset = int(_I64.unpack_from(self.mem, r.DC_SYSTEM_TIME_OFFSET)[0])
        return self.clock.local_ns(t_ns) + offset

    def _latch_receive_times(self) -> None:
        offsets = self.port_offsets
        if offsets is None:
            return
        local0 = self.clock.local_ns(self.frame_t_ns + offsets.port0_ns)
        _U32.pack_into(self.mem, r.DC_RECEIVE_TIME_PORT0, local0 & 0xFFFFFFFF)
        if offsets.port1_ns is not None:
            local1 = self.clock.local_ns(self.frame_t_ns + offsets.port1_ns)
            _U32.pack_into(self.mem, r.DC_RECEIVE_TIME_PORT0 + 4, local1 & 0xFFFFFFFF)
        _U64.pack_into(self.mem, r.DC_RECEIVE_TIME_PU, local0 & (2**64 - 1))

    def _system_time_written(self, start: int, end: int, payload: bytes, t_ns: int) -> None:
        """A write to 0x0910 feeds the time control loop (ETG.1000.4 §6.8, ET1100 §9.2)."""
        self.system_time_received(*system_time_written(start, end, payload), t_ns)

    def system_time_received(self, value: int, width_bits: int, t_ns: int) -> None:
        """The time control loop's step for a received system time of ``width_bits``."""
        system_time_loop(
            [(self.mem, self.clock, 0, self.dc_offset_minus_delay_ns())], value, width_bits, t_ns
        )

    def dc_offset_minus_delay_ns(self) -> int:
        """System time offset (0x0920) minus system time delay (0x0928): what the time
        control loop adds to the local time before comparing with a received time."""
        return int(_unpack_i64(self.mem, _OFFSET)[0]) - int(_unpack_u32(self.mem, _DELAY)[0])

    @property
    def system_time_difference_ns(self) -> int:
        return decode_system_time_difference(memoryview(self.mem), r.DC_SYSTEM_TIME_DIFFERENCE)


def system_time_written(start: int, end: int, payload: bytes) -> tuple[int, int]:
    """The system time a write of ``payload`` to ``[start, end)`` gives the time control
    loop, and its width in bits (from 0x0910 to the write's last byte of it)."""
    lo = max(start, r.DC_SYSTEM_TIME)
    hi = min(end, r.DC_SYSTEM_TIME + 8)
    raw = bytearray(8)
    raw[lo - r.DC_SYSTEM_TIME : hi - r.DC_SYSTEM_TIME] = payload[lo - start : hi - start]
    return int.from_bytes(raw, "little"), 8 * (hi - r.DC_SYSTEM_TIME)


def system_time_loop(
    slaves: list[tuple[bytearray, DcClock, int, int]], value: int, width_bits: int, t_ns: int
) -> None:
    """One step of the time control loop (ETG.1000.4 §6.8, ET1100 §9.2) in every slave
    ``(memory, clock, time offset, offset minus delay registers)`` that receives the
    system time ``value`` at ``t_ns + time offset``: the difference of its own system time
    to the received one plus the delay goes to 0x092C, and the clock runs a little faster
    or slower. One loop for a whole line: the DC time distribution runs it for every
    slave in every cycle."""
    half = 1 << (width_bits - 1)
    mask = (1 << width_bits) - 1
    base = t_ns - value + half
    for mem, clock, offset_ns, registers_ns in slaves:
        # own system time - delay - received, as in Esc.system_time_ns, inlined
        x = base + offset_ns + clock.start_ns + clock.correction_ns + registers_ns
        if clock.drift_ppb:
            x += ((t_ns + offset_ns) * clock.drift_ppb) // 1_000_000_000
        diff = (x & mask) - half
        # 0x092C in sign and magnitude; the clock never jumps: half the error per write,
        # at most MAX_CORRECTION_NS (offsets are the master's job)
        if diff < 0:
            _pack_u32(mem, _DIFFERENCE, (-diff if diff > -0x7FFFFFFF else 0x7FFFFFFF) | 0x80000000)
            clock.correction_ns -= (
                diff >> 1 if diff > -_TWICE_MAX_CORRECTION_NS else -MAX_CORRECTION_NS
            )
        else:
            _pack_u32(mem, _DIFFERENCE, diff if diff < 0x7FFFFFFF else 0x7FFFFFFF)
            clock.correction_ns -= (
                diff >> 1 if diff < _TWICE_MAX_CORRECTION_NS else MAX_CORRECTION_NS
            )
