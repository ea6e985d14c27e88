"""File access over EtherCAT (FoE): the body of a mailbox of type
:attr:`~lolacli.wire.mailbox.MailboxType.FoE` (ETG.1000.5 §5.9, ETG.1000.6 §5.9).

Every FoE message starts with an opcode byte and a reserved byte; a 32-bit field and a
variable part follow, little endian::

    read request  (1)  opcode | 0 | password u32     | file name
    write request (2)  opcode | 0 | password u32     | file name
    data          (3)  opcode | 0 | packet number u32 | data
    ack           (4)  opcode | 0 | packet number u32
    error         (5)  opcode | 0 | error code u32    | error text
    busy          (6)  opcode | 0 | done u16 | entire u16 | busy text

A file goes in data packets numbered from 1; the receiver acknowledges each by its
number, a write request by an ack of packet 0. The file ends with the first data packet
shorter than the most a mailbox carries (one of no data after a file of whole packets).
A busy answer asks the sender of data to send the packet again later; ``done``/``entire``
tell how far the receiver is. Error codes 0x8000… are :class:`FoeErrorCode`.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum

from lolacli.errors import WireError
from lolacli.wire._codes import enum_or_int, need
from lolacli.wire.mailbox import MAILBOX_HEADER_BYTES

#: opcode, reserved and the 32-bit field in front of a name, data or text
FOE_HEADER_BYTES = 6

_HEAD = struct.Struct("<BBI")
_BUSY = struct.Struct("<BBHH")


class FoeOpCode(IntEnum):
    """FoE opcodes (ETG.1000.6 Table 87)."""

    READ = 1
    WRITE = 2
    DATA = 3
    ACK = 4
    ERROR = 5
    BUSY = 6


class FoeErrorCode(IntEnum):
    """FoE error codes (ETG.1000.6 Table 92 and the codes slave stacks define after it)."""

    NOT_DEFINED = 0x8000
    NOT_FOUND = 0x8001
    ACCESS_DENIED = 0x8002
    DISK_FULL = 0x8003
    ILLEGAL = 0x8004
    PACKET_NUMBER_WRONG = 0x8005
    ALREADY_EXISTS = 0x8006
    NO_USER = 0x8007
    BOOTSTRAP_ONLY = 0x8008
    NOT_BOOTSTRAP = 0x8009
    NO_RIGHTS = 0x800A
    PROGRAM_ERROR = 0x800B
    INVALID_CHECKSUM = 0x800C
    INVALID_FIRMWARE = 0x800D
    NO_FILE = 0x800F
    NO_FILE_HEADER = 0x8010
    FLASH_ERROR = 0x8011


_ERROR_TEXT = {
    FoeErrorCode.NOT_DEFINED: "not defined",
    FoeErrorCode.NOT_FOUND: "file not found",
    FoeErrorCode.ACCESS_DENIED: "access to the file is denied",
    FoeErrorCode.DISK_FULL: "the disk is full",
    FoeErrorCode.ILLEGAL: "illegal FoE operation",
    FoeErrorCode.PACKET_NUMBER_WRONG: "the packet number is wrong",
    FoeErrorCode.ALREADY_EXISTS: "the file already exists",
    FoeErrorCode.NO_USER: "no user",
    FoeErrorCode.BOOTSTRAP_ONLY: "only in BOOT (bootstrap) state",
    FoeErrorCode.NOT_BOOTSTRAP: "not in BOOT (bootstrap) state",
    FoeErrorCode.NO_RIGHTS: "no rights: the password is wrong",
    FoeErrorCode.PROGRAM_ERROR: "program error",
    FoeErrorCode.INVALID_CHECKSUM: "the file's checksum is wrong",
    FoeErrorCode.INVALID_FIRMWARE: "the firmware does not fit the hardware",
    FoeErrorCode.NO_FILE: "no file",
    FoeErrorCode.NO_FILE_HEADER: "the file header is missing or wrong",
    FoeErrorCode.FLASH_ERROR: "the flash cannot be accessed",
}


def foe_error_text(code: int) -> str:
    """Text of an FoE error code; unknown codes read ``unknown FoE error 0x….``."""
    try:
        return _ERROR_TEXT[FoeErrorCode(code)]
    except ValueError:
        return f"unknown FoE error 0x{code:04X}"


@dataclass(frozen=True, slots=True)
class FoeReadRequest:
    name: str
    password: int = 0


@dataclass(frozen=True, slots=True)
class FoeWriteRequest:
    name: str
    password: int = 0


@dataclass(frozen=True, slots=True)
class FoeData:
    packet: int
    data: bytes


@dataclass(frozen=True, slots=True)
class FoeAck:
    packet: int


@dataclass(frozen=True, slots=True)
class FoeError:
    code: int
    text: str = ""

    @property
    def meaning(self) -> str:
        """What the code means (the slave's own ``text`` may say more)."""
        return foe_error_text(self.code)


@dataclass(frozen=True, slots=True)
class FoeBusy:
    done: int
    entire: int
    text: str = ""


FoeMessage = FoeReadRequest | FoeWriteRequest | FoeData | FoeAck | FoeError | FoeBusy


def _text(raw: bytes) -> str:
    """A name or text as sent: up to the first NUL (some masters pad with them)."""
    return raw.split(b"\0", 1)[0].decode("latin-1")


def decode_foe(payload: bytes | memoryview) -> FoeMessage:
    """One FoE message from a mailbox payload (the bytes after the mailbox header).

    Raises :class:`WireError` for a truncated message or an unknown opcode."""
    need(payload, 0, FOE_HEADER_BYTES, "FoE header")
    opcode, _reserved, value = _HEAD.unpack_from(payload, 0)
    rest = bytes(payload[FOE_HEADER_BYTES:])
    if opcode == FoeOpCode.READ:
        return FoeReadRequest(_text(rest), value)
    if opcode == FoeOpCode.WRITE:
        return FoeWriteRequest(_text(rest), value)
    if opcode == FoeOpCode.DATA:
        return FoeData(value, rest)
    if opcode == FoeOpCode.ACK:
        return FoeAck(value)
    if opcode == FoeOpCode.ERROR:
        return FoeError(enum_or_int(FoeErrorCode, value), _text(rest))
    if opcode == FoeOpCode.BUSY:
        _op, _res, done, entire = _BUSY.unpack_from(payload, 0)
        return FoeBusy(done, entire, _text(rest))
    raise WireError(f"unknown FoE opcode {opcode}", offset=MAILBOX_HEADER_BYTES)


def encode_foe(message: FoeMessage) -> bytes:
    """The mailbox payload of ``message``."""
    if isinstance(message, FoeReadRequest | FoeWriteRequest):
        op = FoeOpCode.READ if isinstance(message, FoeReadRequest) else FoeOpCode.WRITE
        return _HEAD.pack(op, 0, _u32(message.password, "password")) + _name(message.name)
    if isinstance(message, FoeData):
        return _HEAD.pack(FoeOpCode.DATA, 0, _u32(message.packet, "packet number")) + bytes(
            message.data
        )
    if isinstance(message, FoeAck):
        return _HEAD.pack(FoeOpCode.ACK, 0, _u32(message.packet, "packet number"))
    if isinstance(message, FoeError):
        return _HEAD.pack(FoeOpCode.ERROR, 0, _u32(message.code, "error code")) + _name(
            message.text
        )
    if isinstance(message, FoeBusy):
        if not (0 <= message.done <= 0xFFFF and 0 <= message.entire <= 0xFFFF):
            raise WireError(f"FoE busy {message.done}/{message.entire} out of 16 bits")
        return _BUSY.pack(FoeOpCode.BUSY, 0, message.done, message.entire) + _name(message.text)
    raise WireError(f"not an FoE message: {message!r}")


def _u32(value: int, what: str) -> int:
    if not 0 <= value <= 0xFFFF_FFFF:
        raise WireError(f"FoE {what} {value} is not a 32-bit unsigned number")
    return value


def _name(text: str) -> bytes:
    try:
        return text.encode("latin-1")
    except UnicodeEncodeError:
        raise WireError(f"FoE name or text {text!r} is not Latin-1") from None


def data_bytes_per_packet(mailbox_bytes: int) -> int:
    """File bytes one data packet carries in a mailbox buffer of ``mailbox_bytes``."""
    return max(0, mailbox_bytes - MAILBOX_HEADER_BYTES - FOE_HEADER_BYTES)


__all__ = [
    "FOE_HEADER_BYTES",
    "FoeAck",
    "FoeBusy",
    "FoeData",
    "FoeError",
    "FoeErrorCode",
    "FoeMessage",
    "FoeOpCode",
    "FoeReadRequest",
    "FoeWriteRequest",
    "data_bytes_per_packet",
    "decode_foe",
    "encode_foe",
    "foe_error_text",
]
