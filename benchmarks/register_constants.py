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

from lolacli.emulator import registers as r
from lolacli.wire.registers import Register

_U16 = struct.Struct("<H")
_MEM = bytearray(0x10000)


def _module_ints() -> None:
    mem, u16 = _MEM, _U16
    for _ in range(1000):
        u16.unpack_from(mem, r.AL_STATUS)
        mem[r.AL_CONTROL]
        r.DL_STATUS + 2
        mem[r.SII_DATA : r.SII_DATA + 8]


def _enum_members() -> None:
    mem, u16 = _MEM, _U16
    for _ in range(1000):
        u16.unpack_from(mem, Register.AL_STATUS)
        mem[Register.AL_CONTROL]
        Register.DL_STATUS + 2
        mem[Register.SII_DATA : Register.SII_DATA + 8]


def main() -> None:
    n = 200
    ints = min(timeit.repeat(_module_ints, number=n, repeat=7)) / n / 1000
    enums = min(timeit.repeat(_enum_members, number=n, repeat=7)) / n / 1000
    print(f"module ints   {ints * 1e9:7.0f} ns per 4 accesses")
    print(f"IntEnum       {enums * 1e9:7.0f} ns per 4 accesses")
    print(f"ratio IntEnum / int: {enums / ints:.2f}")


if __name__ == "__main__":
    main()
