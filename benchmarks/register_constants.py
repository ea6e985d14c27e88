"""Why the emulated ESC reads register addresses as plain module ints, not ``Register``.

    python benchmarks/register_constants.py

The same register accesses the ESC's hot path makes (unpack a status word, index a
register byte, add to an address, slice a data register), once with
:mod:`lolacli.emulator.registers`' module constants and once with
:class:`lolacli.wire.registers.Register` members, in the same process; prints the time per
group of four accesses and the ratio (IntEnum / int), best of several repeats.
"""

from __future__ import annotations

import struct
import timeit
from typing import Any

from lolacli.emulator import registers as r
from lolacli.wire.registers import Register

_U16 = struct.Struct("<H")
_MEM = bytearray(0x10000)


def _accesses(names: Any) -> None:
    """1,000 times four accesses, the addresses read as ``names.X`` (``r.X`` in the ESC)."""
    mem, u16 = _MEM, _U16
    for _ in range(1000):
        u16.unpack_from(mem, names.AL_STATUS)
        mem[names.AL_CONTROL]
        names.DL_STATUS + 2
        mem[names.SII_DATA : names.SII_DATA + 8]


def _seconds_per_group(names: Any, n: int = 200) -> float:
    return min(timeit.repeat(lambda: _accesses(names), number=n, repeat=7)) / n / 1000


def main() -> None:
    ints = _seconds_per_group(r)
    enums = _seconds_per_group(Register)
    print(f"module ints   {ints * 1e9:7.0f} ns per 4 accesses")
    print(f"IntEnum       {enums * 1e9:7.0f} ns per 4 accesses")
    print(f"ratio IntEnum / int: {enums / ints:.2f}")


if __name__ == "__main__":
    main()
