"""Distributed clocks start-up arithmetic (pure): propagation delays and offsets.

The master latches every slave's port receive times with one frame (a write to 0x0900;
ETG.1000.4 §6.8, ET1100 datasheet "Propagation delay measurement"), reads them back
(0x0900 port 0, 0x0904 port 1, and 0x0918 the 64-bit local time of the processing unit),
and computes for a line:

* the *loop time* of slave i, ``t1 - t0``: how long the frame took from its port 0 to come
  back on its port 1 (0 for a slave whose port 1 is closed, the end of the line);
* the propagation delay between slave i and i+1 as half the difference of their loop
  times (the path out and the path back are taken as equally long, as SOEM and the
  ESC datasheets do), summed along the line from the reference clock;
* the system time offset of each slave: the reference clock's time at the latch plus the
  slave's delay, minus the slave's own local time at the latch.

Integer nanoseconds; 32-bit port times wrap.
"""

from __future__ import annotations

from collections.abc import Sequence

_U32 = 1 << 32
_U64 = 1 << 64


def loop_time_ns(port0: int, port1: int | None) -> int:
    """Port 1 minus port 0 receive time (32-bit wrap), 0 when port 1 saw nothing."""
    if port1 is None or port1 == port0:
        return 0
    return (port1 - port0) % _U32


def propagation_delays(loops: Sequence[int]) -> list[int]:
    """Delay of each slave of a line from the first one, from their loop times."""
    delays = [0] * len(loops)
    for i in range(1, len(loops)):
        delays[i] = delays[i - 1] + (loops[i - 1] - loops[i]) // 2
    return delays


def system_time_offsets(
    local_at_latch: Sequence[int], delays: Sequence[int], reference: int, reference_offset: int
) -> list[int]:
    """0x0920 for each slave: ``reference`` is the index of the reference clock in the
    lists, ``reference_offset`` the offset the master gives it (system time - its local
    time). ``delays`` are relative to the reference."""
    ref_time = local_at_latch[reference] + reference_offset
    return [(ref_time + delays[i] - local_at_latch[i]) % _U64 for i in range(len(local_at_latch))]

