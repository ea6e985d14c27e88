"""EtherCAT mailbox: the 6-byte header in front of every AoE/EoE/CoE/FoE/SoE/VoE message.

Layout (ETG.1000.4 Table 29 "Mailbox header"), little endian::

    length u16 | address u16 | channel:6 priority:2 | type:4 counter:3 reserved:1 | data

``length`` counts the bytes after the header. A mailbox is written into a sync manager
buffer that is usually longer than the message, so the buffer may carry padding after
``6 + length`` bytes; :func:`decode_mailbox` keeps the message exactly and drops the rest.

Type 0 is the mailbox error reply (ETG.1000.4 Table 30): ``type u16`` (1 = mailbox
command) then ``detail u16`` from :class:`MailboxErrorDetail`.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum

from lolacli.errors import WireError
from lolacli.wire._codes import enum_or_int

MAILBOX_HEADER_BYTES = 6
MAILBOX_ERROR_BYTES = 4

_HEADER = struct.Struct("<HHBB")
_ERROR = struct.Struct("<HH")


class MailboxType(IntEnum):
    """Mailbox protocol (ETG.1000.4 Table 29, "Type")."""

    ERR = 0
    AoE = 1
    EoE = 2
    CoE = 3
    FoE = 4
    SoE = 5
    VoE = 15


class MailboxErrorDetail(IntEnum):
    """Detail word of a mailbox error reply (ETG.1000.4 Table 30)."""

    SYNTAX = 1
    UNSUPPORTED_PROTOCOL = 2
    INVALID_CHANNEL = 3
    SERVICE_NOT_SUPPORTED = 4
    INVALID_HEADER = 5
    SIZE_TOO_SHORT = 6
    NO_MORE_MEMORY = 7
    INVALID_SIZE = 8
    SERVICE_IN_WORK = 9


_ERROR_TEXT = {
    MailboxErrorDetail.SYNTAX: "syntax of the 6-octet mailbox header is wrong",
    MailboxErrorDetail.UNSUPPORTED_PROTOCOL: "the mailbox protocol is not supported",
    MailboxErrorDetail.INVALID_CHANNEL: "channel field holds a wrong value",
    MailboxErrorDetail.SERVICE_NOT_SUPPORTED: "the protocol service is not supported",
    MailboxErrorDetail.INVALID_HEADER: "the mailbox protocol header is wrong",
    MailboxErrorDetail.SIZE_TOO_SHORT: "the received mailbox data is too short",
    MailboxErrorDetail.NO_MORE_MEMORY: "the service cannot be handled for lack of memory",
    MailboxErrorDetail.INVALID_SIZE: "the length of the data is inconsistent",
    MailboxErrorDetail.SERVICE_IN_WORK: "the mailbox service is already in use",
}


@dataclass(frozen=True, slots=True)
class MailboxHeader:
    """The mailbox header (ETG.1000.4 Table 29). ``mailbox_type`` is a
    :class:`MailboxType` where known, else the plain int."""

    length: int
    address: int = 0
    channel: int = 0
    priority: int = 0
    mailbox_type: int = MailboxType.CoE
    counter: int = 0
    reserved: int = 0


@dataclass(frozen=True, slots=True)
class Mailbox:
    """A mailbox message: header and exactly ``header.length`` payload bytes."""

    header: MailboxHeader
    payload: bytes

    @property
    def mailbox_type(self) -> int:
        return self.header.mailbox_type

    @property
    def counter(self) -> int:
        return self.header.counter


@dataclass(frozen=True, slots=True)
class MailboxError:
    """A mailbox error reply body (type 0, ETG.1000.4 Table 30)."""

    detail: int
    error_type: int = 1

    @property
    def text(self) -> str:
        return mailbox_error_text(self.detail)


def mailbox_error_text(detail: int) -> str:
    """Text of a mailbox error detail code; unknown codes read ``unknown error 0x….``."""
    try:
        return _ERROR_TEXT[MailboxErrorDetail(detail)]
    except ValueError:
        return f"unknown mailbox error 0x{detail:04X}"


def decode_mailbox_header(buf: bytes | memoryview, offset: int = 0) -> MailboxHeader:
    """The 6-byte header at ``offset``; raises :class:`WireError` when truncated."""
    if offset < 0 or offset + MAILBOX_HEADER_BYTES > len(buf):
        raise WireError("mailbox header truncated", offset=offset)
    length, address, b4, b5 = _HEADER.unpack_from(buf, offset)
    return MailboxHeader(
        length=length,
        address=address,
        channel=b4 & 0x3F,
        priority=b4 >> 6,
        mailbox_type=enum_or_int(MailboxType, b5 & 0x0F),
        counter=(b5 >> 4) & 0x7,
        reserved=b5 >> 7,
    )


def decode_mailbox(buf: bytes | memoryview) -> Mailbox:
    """A mailbox message from a sync-manager buffer (trailing padding is ignored).

    Raises :class:`WireError` when the header or the ``length`` bytes do not fit.
    """
    header = decode_mailbox_header(buf)
    end = MAILBOX_HEADER_BYTES + header.length
    if end > len(buf):
        raise WireError(
            f"mailbox length {header.length} runs past the {len(buf)}-byte buffer",
            offset=0,
        )
    return Mailbox(header, bytes(buf[MAILBOX_HEADER_BYTES:end]))


def encode_mailbox_header(header: MailboxHeader) -> bytes:
    b4 = (header.channel & 0x3F) | ((header.priority & 0x3) << 6)
    b5 = (header.mailbox_type & 0x0F) | ((header.counter & 0x7) << 4)
    b5 |= (header.reserved & 1) << 7
    return _HEADER.pack(header.length & 0xFFFF, header.address & 0xFFFF, b4, b5)


def encode_mailbox(mailbox: Mailbox, *, buffer_bytes: int | None = None) -> bytes:
    """Header + payload; the header's ``length`` is taken from the payload.

    ``buffer_bytes`` pads with zeros to a sync-manager buffer size.
    """
    from dataclasses import replace

    if len(mailbox.payload) > 0xFFFF:
        raise WireError(f"mailbox payload of {len(mailbox.payload)} bytes is too long")
    header = replace(mailbox.header, length=len(mailbox.payload))
    out = encode_mailbox_header(header) + mailbox.payload
    if buffer_bytes is not None:
        if len(out) > buffer_bytes:
            raise WireError(f"mailbox of {len(out)} bytes exceeds the {buffer_bytes}-byte buffer")
        out += bytes(buffer_bytes - len(out))
    return out


def make_mailbox(
    mailbox_type: int,
    payload: bytes,
    *,
    counter: int = 0,
    address: int = 0,
    channel: int = 0,
    priority: int = 0,
) -> Mailbox:
    """A mailbox message with a consistent ``length``."""
    header = MailboxHeader(len(payload), address, channel, priority, mailbox_type, counter)
    return Mailbox(header, payload)


def next_counter(counter: int) -> int:
    """The next mailbox counter: 1..7 cyclic; 0 is reserved for the first message
    (ETG.1000.4 §5.6.1, "Cnt")."""
    return counter % 7 + 1


def decode_mailbox_error(payload: bytes | memoryview) -> MailboxError:
    """The body of a type-0 mailbox message."""
    if len(payload) < MAILBOX_ERROR_BYTES:
        raise WireError("mailbox error reply truncated", offset=MAILBOX_HEADER_BYTES)
    error_type, detail = _ERROR.unpack_from(payload, 0)
    return MailboxError(enum_or_int(MailboxErrorDetail, detail), error_type)


def encode_mailbox_error(error: MailboxError) -> bytes:
    return _ERROR.pack(error.error_type & 0xFFFF, error.detail & 0xFFFF)


# --- the lean path of a master's mailbox traffic --------------------------------------------


def encode_mailbox_message(
    mailbox_type: int, payload: bytes, counter: int, buffer_bytes: int
) -> bytes:
    """``encode_mailbox(make_mailbox(mailbox_type, payload, counter=counter),
    buffer_bytes=buffer_bytes)`` without the intermediate objects."""
    n = len(payload)
    if n + MAILBOX_HEADER_BYTES > buffer_bytes:
        raise WireError(
            f"mailbox of {n + MAILBOX_HEADER_BYTES} bytes exceeds the {buffer_bytes}-byte buffer"
        )
    head = _HEADER.pack(n, 0, 0, (mailbox_type & 0x0F) | ((counter & 0x7) << 4))
    return head + payload + bytes(buffer_bytes - n - MAILBOX_HEADER_BYTES)


def mailbox_type_and_payload(buf: bytes | memoryview) -> tuple[int, bytes]:
    """The type (low nibble) and the payload of a mailbox message in a sync-manager
    buffer: what :func:`decode_mailbox` gives, without the objects."""
    if len(buf) < MAILBOX_HEADER_BYTES:
        raise WireError("mailbox header truncated", offset=0)
    length = buf[0] | buf[1] << 8
    end = MAILBOX_HEADER_BYTES + length
    if end > len(buf):
        raise WireError(f"mailbox length {length} runs past the {len(buf)}-byte buffer", offset=0)
    return buf[5] & 0x0F, bytes(buf[MAILBOX_HEADER_BYTES:end])
