"""What a number of an ENI can be: the width of the frame field, register or object it is
written into (ETG.1000.4 datagrams, FMMUs and sync managers, ETG.1000.6 CoE, CiA 301), and
lolacli's limits where the specifications give none.

One table for both readers of it: the parser refuses a file holding a value outside its
field (:class:`~lolacli.errors.EniError`, exit 3, naming the line), so no command ever sees
a station address of 70000 or a datagram of -56 bytes; ``eni validate`` checks models that
did not come from the parser (built in code, read from the cache) against the same table
(:func:`lolacli.eni.validate.check_field_ranges`). Odd values a master can still run with
(station address 0, a ``<Cnt>`` the slaves do not give, a variable of 0 bits) are no limit
here: they are ``eni validate`` findings.
"""

from __future__ import annotations

from dataclasses import dataclass

from lolacli.wire.frame import DATAGRAM_HEADER_BYTES, ECAT_HEADER_BYTES, WKC_BYTES


@dataclass(frozen=True, slots=True)
class Width:
    """The values an ENI number can take (``hi`` None: no upper bound).

    ``wraps``: the file may write the upper half of an unsigned field as a negative number
    (ENIs write the auto-increment address 0xFFFF as -1); the parser reads -1 as ``hi``.
    A model always holds the unsigned value.
    """

    lo: int
    hi: int | None
    name: str
    wraps: bool = False

    def holds(self, value: int) -> bool:
        return self.lo <= value and (self.hi is None or value <= self.hi)

    def read(self, value: int) -> int | None:
        """``value`` as written in a file, as the model holds it; None when out of range."""
        if self.holds(value):
            return value
        if self.wraps and self.hi is not None and -((self.hi + 1) // 2) <= value < 0:
            return value & self.hi
        return None

    def __str__(self) -> str:
        if self.hi is None:
            return f">= {self.lo} ({self.name})"
        register = self.hi > 0xFF and not (self.hi + 1) & self.hi  # 0xFFFF, 0xFFFF_FFFF
        hi = f"0x{self.hi:X}" if register else str(self.hi)
        lo = f"-0x{(self.hi + 1) // 2:X}" if self.wraps else str(self.lo)
        return f"{lo}..{hi} ({self.name})"


#: Ethernet payload of one frame: the EtherCAT header and its datagrams.
ETHERNET_PAYLOAD_BYTES = 1500
#: Data one datagram carries when it is alone in a frame (1500 - 2 - 10 - 2 = 1486).
MAX_DATAGRAM_DATA_IN_FRAME = (
    ETHERNET_PAYLOAD_BYTES - ECAT_HEADER_BYTES - DATAGRAM_HEADER_BYTES - WKC_BYTES
)
#: lolacli's limit on a process image, each direction (the specifications give none: the
#: image lies in the 4 GiB logical space). Real images are kilobytes; 16 MiB of cyclic data
#: take 1.3 s of frames on a 100 Mbit/s link.
MAX_IMAGE_BYTES = 16 * 1024 * 1024
#: Highest EtherCAT command (ETG.1000.4 Table 22: 0 NOP .. 14 FRMW; 15..255 reserved).
MAX_COMMAND = 14

U8 = Width(0, 0xFF, "u8")
U16 = Width(0, 0xFFFF, "u16")
U32 = Width(0, 0xFFFF_FFFF, "u32")
I32 = Width(-(2**31), 2**31 - 1, "i32")
#: a 16-bit address (station, auto-increment, ADP/ADO); the file may write 0xFFFF as -1
ADDRESS16 = Width(0, 0xFFFF, "u16", wraps=True)
#: a 32-bit address or identity field (logical address, vendor, product, revision, serial)
WORD32 = Width(0, 0xFFFF_FFFF, "u32", wraps=True)
COMMAND = Width(0, MAX_COMMAND, "an EtherCAT command: 0 NOP .. 14 FRMW")
SM_INDEX = Width(0, 15, "an ESC has 16 sync managers")
CCS = Width(0, 7, "3-bit SDO command specifier")
DATA_LENGTH = Width(0, MAX_DATAGRAM_DATA_IN_FRAME, "bytes a datagram carries in a frame")
WKC = Width(0, 0xFFFF, "u16 working counter")
BIT_LEN = Width(0, 0xFF, "u8 bit length of a PDO mapping entry; 0 pads")
LOGICAL_BIT = Width(0, 0xFFFF_FFFF * 8 + 7, "a bit of the 4 GiB logical space")
#: a slave's inputs or outputs area: one FMMU maps at most 0xFFFF bytes
AREA_BITS = Width(0, 0xFFFF * 8, "an FMMU maps at most 0xFFFF bytes")
IMAGE_BYTES = Width(0, MAX_IMAGE_BYTES, "a process image of at most 16 MiB")
IMAGE_BIT = Width(0, MAX_IMAGE_BYTES * 8, "a bit of a 16 MiB process image")
#: times in ms (InitCmd and CoE timeouts, mailbox poll time)
MILLISECONDS = Width(0, 0xFFFF_FFFF, "u32 ms")
RETRIES = Width(0, 0xFFFF, "u16 count of repeats")
#: cycle times in ns: positive, and what the 32-bit SYNC0/SYNC1 cycle registers hold
CYCLE_NS = Width(1, 0xFFFF_FFFF, "positive, at most the u32 ns of a DC cycle register")
COUNT = Width(0, None, "not negative")
POSITIVE = Width(1, None, "positive")


__all__ = [
    "ADDRESS16",
    "AREA_BITS",
    "BIT_LEN",
    "CCS",
    "COMMAND",
    "COUNT",
    "CYCLE_NS",
    "DATA_LENGTH",
    "ETHERNET_PAYLOAD_BYTES",
    "I32",
    "IMAGE_BIT",
    "IMAGE_BYTES",
    "LOGICAL_BIT",
    "MAX_COMMAND",
    "MAX_DATAGRAM_DATA_IN_FRAME",
    "MAX_IMAGE_BYTES",
    "MILLISECONDS",
    "POSITIVE",
    "RETRIES",
    "SM_INDEX",
    "U8",
    "U16",
    "U32",
    "WKC",
    "WORD32",
    "Width",
]
