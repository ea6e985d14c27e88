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

#: What one addressed slave does with the datagram's data (ETG.1000.4 Table 13).
READS = frozenset({Command.APRD, Command.FPRD, Command.BRD, Command.LRD})
WRITES = frozenset({Command.APWR, Command.FPWR, Command.BWR, Command.LWR})
READ_WRITES = frozenset({Command.APRW, Command.FPRW, Command.BRW, Command.LRW})
#: The addressed slave reads, every other slave writes what it read.
READ_MULTIPLE_WRITES = frozenset({Command.ARMW, Command.FRMW})

# (for reading, for writing) per command: the working-counter rule below as a table
_WKC_WEIGHTS: dict[int, tuple[int, int]] = {
    **{int(c): (1, 0) for c in READS},
    **{int(c): (0, 1) for c in WRITES},
    **{int(c): (1, 2) for c in READ_WRITES},
}


def mnemonic(cmd: int) -> str:
    """The mnemonic of a command byte; unknown values read as ``CMD<n>``."""
    try:
        return Command(cmd).name
    except ValueError:
        return f"CMD{cmd}"


def wkc_increment(cmd: int, *, read: bool = True, write: bool = True) -> int:
    """How much one slave adds to the working counter: the one rule every layer uses
    (the ENI checks, the capture's expected counts, the emulated ESC, the frame plan).

    Read = 1, write = 1, read-write = 1 for the read + 2 for the write (ETG.1000.4 §5.2,
    Table 13; a slave that only reads an LRW's range adds 1, one that only writes adds 2).
    ``ARMW``/``FRMW`` add 1 in every slave that takes part: the addressed one reads, the
    others write. ``read``/``write`` say what the slave did (the default: both, as a
    physical read-write always does); NOP and unknown commands add nothing.
    """
    weights = _WKC_WEIGHTS.get(cmd)
    if weights is not None:
        return (weights[0] if read else 0) + (weights[1] if write else 0)
    if cmd in READ_MULTIPLE_WRITES:
        return 1 if (read or write) else 0
    return 0


def addressed_wkc(cmd: int, slave_count: int) -> int | None:
    """The working counter of a physical command on a chain of ``slave_count`` slaves when
    every slave it addresses takes part: broadcasts and ARMW/FRMW reach all of them, other
    position/station commands one; ``None`` for logical commands (they depend on FMMUs)."""
    if cmd in LOGICAL:
        return None
    if cmd in BROADCAST or cmd in READ_MULTIPLE_WRITES:
        return slave_count * wkc_increment(cmd)
    return wkc_increment(cmd)
