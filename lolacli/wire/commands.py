"""EtherCAT datagram commands (ETG.1000.4, Table 13 "EtherCAT command types")."""

from __future__ import annotations

from enum import IntEnum


class Command(IntEnum):
    """Datagram command byte. Mnemonics stay upper case, as in the specification."""

    NOP = 0
    APRD = 1
    APWR = 2
    APRW = 3
    FPRD = 4
    FPWR = 5
    FPRW = 6
    BRD = 7
    BWR = 8
    BRW = 9
    LRD = 10
    LWR = 11
    LRW = 12
    ARMW = 13
    FRMW = 14


#: Commands whose 32-bit address is a logical (process-image) address.
LOGICAL = frozenset({Command.LRD, Command.LWR, Command.LRW})
#: Auto-increment addressing: every slave increments ADP; the one that sees 0 is addressed.
AUTO_INCREMENT = frozenset({Command.APRD, Command.APWR, Command.APRW, Command.ARMW})
#: Configured (fixed) station addressing: ADP is the station address.
CONFIGURED = frozenset({Command.FPRD, Command.FPWR, Command.FPRW, Command.FRMW})
#: Broadcast: every slave is addressed, and every slave increments ADP.
BROADCAST = frozenset({Command.BRD, Command.BWR, Command.BRW})

_READS = frozenset({Command.APRD, Command.FPRD, Command.BRD, Command.LRD})
_WRITES = frozenset({Command.APWR, Command.FPWR, Command.BWR, Command.LWR})
_READ_WRITES = frozenset({Command.APRW, Command.FPRW, Command.BRW, Command.LRW})


def mnemonic(cmd: int) -> str:
    """The mnemonic of a command byte; unknown values read as ``CMD<n>``."""
    try:
        return Command(cmd).name
    except ValueError:
        return f"CMD{cmd}"


def wkc_increment(cmd: int, *, read: bool = True, write: bool = True) -> int:
    """How much one addressed slave adds to the working counter.

    Read = 1, write = 1, read-write = 3 when the slave both reads and writes, else the part
    it did (ETG.1000.3 §4.8.3). ``ARMW``/``FRMW`` count as read for the slave that reads
    and as write for the others; callers give ``read``/``write`` for those.
    """
    if cmd in _READS:
        return 1 if read else 0
    if cmd in _WRITES:
        return 1 if write else 0
    if cmd in _READ_WRITES:
        return (1 if read else 0) + (2 if write else 0)
    if cmd in (Command.ARMW, Command.FRMW):
        return 1 if (read or write) else 0
    return 0
