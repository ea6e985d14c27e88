"""CANopen over EtherCAT: the 2-byte CoE header and the emergency message.

CoE header (ETG.1000.6 §5.6.1, Table 29 "CoE header"), one little-endian u16::

    number:9 | reserved:3 | service:4

``number`` is the PDO number for PDO services and 0 otherwise (SDO). The CoE header is the
first part of a mailbox payload of type :attr:`~lolacli.wire.mailbox.MailboxType.CoE`; the
SDO and SDO Information bodies that follow it are in :mod:`lolacli.wire.sdo`.

Emergency (ETG.1000.6 §5.6.4, CiA 301 EMCY)::

    CoE header | error code u16 | error register u8 | manufacturer data 5 bytes
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum

from lolacli.errors import WireError
from lolacli.wire._codes import enum_or_int, need

COE_HEADER_BYTES = 2
EMERGENCY_BYTES = 8  # after the CoE header

_U16 = struct.Struct("<H")
_EMERGENCY = struct.Struct("<HB5s")


class CoeService(IntEnum):
    """CoE service (ETG.1000.6 Table 29, "Service")."""

    EMERGENCY = 1
    SDO_REQUEST = 2
    SDO_RESPONSE = 3
    TXPDO = 4
    RXPDO = 5
    TXPDO_RR = 6
    RXPDO_RR = 7
    SDO_INFO = 8


@dataclass(frozen=True, slots=True)
class CoeHeader:
    """The CoE header. ``service`` is a :class:`CoeService` where known, else an int."""

    service: int
    number: int = 0
    reserved: int = 0


@dataclass(frozen=True, slots=True)
class Emergency:
    """A CoE emergency message body (CiA 301 EMCY as carried by CoE)."""

    error_code: int
    error_register: int = 0
    data: bytes = bytes(5)


def decode_coe_header(buf: bytes | memoryview, offset: int = 0) -> CoeHeader:
    """The CoE header at ``offset`` (the start of a CoE mailbox payload)."""
    need(buf, offset, COE_HEADER_BYTES, "CoE header")
    (word,) = _U16.unpack_from(buf, offset)
    return CoeHeader(
        service=enum_or_int(CoeService, word >> 12),
        number=word & 0x1FF,
        reserved=(word >> 9) & 0x7,
    )


def encode_coe_header(header: CoeHeader) -> bytes:
    word = (header.number & 0x1FF) | ((header.reserved & 0x7) << 9)
    return _U16.pack(word | ((header.service & 0xF) << 12))


def decode_emergency(coe_payload: bytes | memoryview) -> Emergency:
    """An emergency from a CoE payload (CoE header included, service 1)."""
    header = decode_coe_header(coe_payload)
    if header.service != CoeService.EMERGENCY:
        raise WireError(f"CoE service {header.service} is not an emergency", offset=0)
    need(coe_payload, COE_HEADER_BYTES, EMERGENCY_BYTES, "CoE emergency")
    code, register, data = _EMERGENCY.unpack_from(coe_payload, COE_HEADER_BYTES)
    return Emergency(code, register, bytes(data))


def encode_emergency(emergency: Emergency) -> bytes:
    """CoE header + emergency body (the mailbox payload)."""
    if len(emergency.data) != 5:
        raise WireError(f"emergency data must be 5 bytes, not {len(emergency.data)}")
    body = _EMERGENCY.pack(
        emergency.error_code & 0xFFFF, emergency.error_register & 0xFF, emergency.data
    )
    return encode_coe_header(CoeHeader(CoeService.EMERGENCY)) + body
