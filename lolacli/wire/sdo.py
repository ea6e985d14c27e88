"""CoE SDO and SDO Information messages: decode and encode (no IO).

Every function here works on a *CoE payload*: the mailbox payload of a CoE mailbox,
starting with the 2-byte CoE header (:mod:`lolacli.wire.coe`). The header's service tells a
request (client → server) from a response, which the SDO command byte alone cannot
(command specifier 0 is a download segment request but an upload segment response).

SDO body (ETG.1000.6 §5.6.2, Tables 30–47; CiA 301 §7.2.4.3)::

    command u8 | index u16 | subindex u8 | data 4      initiate, abort (code u32)
    command u8 | segment data (≥ 7 bytes)                segments

Initiate command byte: ``size indicated:1 expedited:1 unused-bytes:2 complete access:1
specifier:3``. Segment command byte: ``last:1 unused-bytes:3 toggle:1 specifier:3``.
A segment always carries at least 7 data bytes; with fewer the unused count says how
many of the 7 are padding. A normal (not expedited) initiate carries the complete size
u32 instead of data, and the first part of the data after it.

SDO Information (ETG.1000.6 §5.6.3, Tables 48–58)::

    opcode:7 incomplete:1 | reserved u8 | fragments left u16 | service data

Decoded messages are frozen dataclasses; the bytes that carry no meaning (unused data
bytes, reserved words) are kept in ``filler``/``reserved`` so that :func:`encode_sdo`
gives the received bytes back exactly.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

from lolacli.errors import WireError
from lolacli.wire._codes import enum_or_int, need
from lolacli.wire.coe import (
    COE_HEADER_BYTES,
    CoeHeader,
    CoeService,
    decode_coe_header,
    encode_coe_header,
)

SEGMENT_MIN_DATA_BYTES = 7
EXPEDITED_MAX_BYTES = 4

_ADDR = struct.Struct("<BHB")  # command, index, subindex
_U32 = struct.Struct("<I")
_U16 = struct.Struct("<H")
_INFO_HEAD = struct.Struct("<BBH")
_OBJ_DESC = struct.Struct("<HHBB")  # index, data type, max subindex, object code
_ENTRY_DESC = struct.Struct("<HBBHHH")  # index, subindex, value info, type, bits, access
_ENTRY_REQ = struct.Struct("<HBB")


class ClientCommand(IntEnum):
    """Client command specifier, bits 5–7 of a request (CiA 301 §7.2.4.3)."""

    DOWNLOAD_SEGMENT = 0
    INITIATE_DOWNLOAD = 1
    INITIATE_UPLOAD = 2
    UPLOAD_SEGMENT = 3
    ABORT = 4


class ServerCommand(IntEnum):
    """Server command specifier, bits 5–7 of a response (CiA 301 §7.2.4.3)."""

    UPLOAD_SEGMENT = 0
    DOWNLOAD_SEGMENT = 1
    INITIATE_UPLOAD = 2
    INITIATE_DOWNLOAD = 3
    ABORT = 4


class SdoInfoOpcode(IntEnum):
    """SDO Information opcode (ETG.1000.6 Table 48)."""

    GET_OD_LIST_REQUEST = 1
    GET_OD_LIST_RESPONSE = 2
    GET_OBJECT_DESCRIPTION_REQUEST = 3
    GET_OBJECT_DESCRIPTION_RESPONSE = 4
    GET_ENTRY_DESCRIPTION_REQUEST = 5
    GET_ENTRY_DESCRIPTION_RESPONSE = 6
    ERROR_REQUEST = 7


class OdListType(IntEnum):
    """List type of Get OD List (ETG.1000.6 Table 50)."""

    LENGTHS = 0
    ALL = 1
    RXPDO_MAPPABLE = 2
    TXPDO_MAPPABLE = 3
    STORED_FOR_REPLACEMENT = 4
    STARTUP_PARAMETERS = 5


class SdoAbortCode(IntEnum):
    """SDO abort codes (CiA 301 Table 22, with the ETG.1000.6 Table 41 additions)."""

    TOGGLE_BIT_NOT_ALTERNATED = 0x05030000
    TIMEOUT = 0x05040000
    UNKNOWN_COMMAND = 0x05040001
    INVALID_BLOCK_SIZE = 0x05040002
    INVALID_SEQUENCE_NUMBER = 0x05040003
    CRC_ERROR = 0x05040004
    OUT_OF_MEMORY = 0x05040005
    UNSUPPORTED_ACCESS = 0x06010000
    WRITE_ONLY = 0x06010001
    READ_ONLY = 0x06010002
    SUBINDEX_CANNOT_BE_WRITTEN = 0x06010003
    COMPLETE_ACCESS_VARIABLE_LENGTH = 0x06010004
    OBJECT_TOO_LONG_FOR_MAILBOX = 0x06010005
    MAPPED_TO_RXPDO = 0x06010006
    NO_OBJECT = 0x06020000
    CANNOT_BE_MAPPED = 0x06040041
    PDO_LENGTH_EXCEEDED = 0x06040042
    PARAMETER_INCOMPATIBLE = 0x06040043
    DEVICE_INCOMPATIBLE = 0x06040047
    HARDWARE_ERROR = 0x06060000
    LENGTH_MISMATCH = 0x06070010
    LENGTH_TOO_HIGH = 0x06070012
    LENGTH_TOO_LOW = 0x06070013
    NO_SUBINDEX = 0x06090011
    VALUE_RANGE_EXCEEDED = 0x06090030
    VALUE_TOO_HIGH = 0x06090031
    VALUE_TOO_LOW = 0x06090032
    MODULE_LIST_MISMATCH = 0x06090033
    MAX_LESS_THAN_MIN = 0x06090036
    RESOURCE_NOT_AVAILABLE = 0x060A0023
    GENERAL_ERROR = 0x08000000
    CANNOT_TRANSFER = 0x08000020
    CANNOT_TRANSFER_LOCAL_CONTROL = 0x08000021
    CANNOT_TRANSFER_DEVICE_STATE = 0x08000022
    NO_OBJECT_DICTIONARY = 0x08000023
    NO_DATA = 0x08000024


#: what each CiA 301 abort code means, in words of our own short enough that an error
#: line (``SDO 0x6099:05 aborted 0x06020000: …``) fits 80 columns
_ABORT_TEXT: dict[int, str] = {
    0x05030000: "toggle bit did not alternate",
    0x05040000: "SDO protocol timed out",
    0x05040001: "unknown command specifier",
    0x05040002: "invalid block size",
    0x05040003: "invalid sequence number",
    0x05040004: "CRC error",
    0x05040005: "out of memory",
    0x06010000: "unsupported access",
    0x06010001: "object is write-only",
    0x06010002: "object is read-only",
    0x06010003: "subindex 0 must be 0 to write",
    0x06010004: "no complete access here",
    0x06010005: "object larger than mailbox",
    0x06010006: "mapped to an RxPDO",
    0x06020000: "object does not exist",
    0x06040041: "object cannot be mapped",
    0x06040042: "PDO length exceeded",
    0x06040043: "parameters incompatible",
    0x06040047: "internal incompatibility",
    0x06060000: "hardware error",
    0x06070010: "data type or length mismatch",
    0x06070012: "value too long for its type",
    0x06070013: "value too short for its type",
    0x06090011: "subindex does not exist",
    0x06090030: "value out of range",
    0x06090031: "value too high",
    0x06090032: "value too low",
    0x06090033: "module ident list mismatch",
    0x06090036: "maximum below minimum",
    0x060A0023: "no SDO connection free",
    0x08000000: "general error",
    0x08000020: "data cannot be stored",
    0x08000021: "cannot store: local control",
    0x08000022: "cannot store in this state",
    0x08000023: "no object dictionary",
    0x08000024: "no data available",
}


def abort_text(code: int) -> str:
    """The text of an SDO abort code; unknown codes read ``unknown abort code``."""
    return _ABORT_TEXT.get(code, "unknown abort code")


def abort_code(code: int) -> SdoAbortCode | int:
    """The code as :class:`SdoAbortCode` where known, else the plain int."""
    return enum_or_int(SdoAbortCode, code)


# --- SDO messages ---------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SdoInitiate:
    """Initiate download request or initiate upload response: the part that carries data.

    ``expedited``: ``data`` (1–4 bytes, or 4 when the size is not indicated) sits in the
    4-byte data field, ``filler`` holds the unused rest. Otherwise ``complete_size`` is
    the size of the whole object and ``data`` is the first part of it (the rest of the
    mailbox) — ``filler`` is then empty.
    """

    index: int
    subindex: int
    data: bytes
    complete_access: bool = False
    expedited: bool = True
    size_indicated: bool = True
    complete_size: int = 0
    filler: bytes = b""

    @property
    def value_bytes(self) -> int:
        """The size of the object: the expedited data length, or the complete size."""
        return len(self.data) if self.expedited else self.complete_size


@dataclass(frozen=True, slots=True)
class SdoDownloadRequest(SdoInitiate):
    """Initiate SDO download request (ETG.1000.6 Tables 32 and 35)."""


@dataclass(frozen=True, slots=True)
class SdoUploadResponse(SdoInitiate):
    """Initiate SDO upload response (ETG.1000.6 Tables 39 and 40)."""


@dataclass(frozen=True, slots=True)
class SdoAddressed:
    """A message with index/subindex and 4 reserved bytes (no data)."""

    index: int
    subindex: int
    complete_access: bool = False
    reserved: bytes = bytes(4)


@dataclass(frozen=True, slots=True)
class SdoUploadRequest(SdoAddressed):
    """Initiate SDO upload request (ETG.1000.6 Table 38)."""


@dataclass(frozen=True, slots=True)
class SdoDownloadResponse(SdoAddressed):
    """Initiate SDO download response (ETG.1000.6 Tables 33 and 36)."""


@dataclass(frozen=True, slots=True)
class SdoSegment:
    """A segment that carries data; ``last`` is the "no more segments" flag."""

    data: bytes
    toggle: bool = False
    last: bool = False
    filler: bytes = b""


@dataclass(frozen=True, slots=True)
class SdoDownloadSegmentRequest(SdoSegment):
    """Download SDO segment request (ETG.1000.6 Table 34)."""


@dataclass(frozen=True, slots=True)
class SdoUploadSegmentResponse(SdoSegment):
    """Upload SDO segment response (ETG.1000.6 Table 43)."""


@dataclass(frozen=True, slots=True)
class SdoSegmentAck:
    """A segment message without data: only the toggle bit counts."""

    toggle: bool = False
    reserved: bytes = bytes(SEGMENT_MIN_DATA_BYTES)


@dataclass(frozen=True, slots=True)
class SdoUploadSegmentRequest(SdoSegmentAck):
    """Upload SDO segment request (ETG.1000.6 Table 42)."""


@dataclass(frozen=True, slots=True)
class SdoDownloadSegmentResponse(SdoSegmentAck):
    """Download SDO segment response (ETG.1000.6 Table 37)."""


@dataclass(frozen=True, slots=True)
class SdoAbort:
    """Abort SDO transfer request (ETG.1000.6 Table 44).

    Either side may abort, and both send it with the CoE service SDO request (a server's
    abort is a request too; see replay-sdo-error frame 544). ``coe_service`` keeps the
    service as received, so a peer that uses SDO response survives a round trip.
    """

    index: int
    subindex: int
    code: int
    coe_service: int = CoeService.SDO_REQUEST

    @property
    def text(self) -> str:
        return abort_text(self.code)


# --- SDO Information messages -----------------------------------------------------------


@dataclass(frozen=True, slots=True)
class SdoInfoBase:
    """Fields of the SDO Information header shared by every opcode (ETG.1000.6 Table 48)."""

    incomplete: bool = field(default=False, kw_only=True)
    fragments_left: int = field(default=0, kw_only=True)
    reserved: int = field(default=0, kw_only=True)


@dataclass(frozen=True, slots=True)
class OdListRequest(SdoInfoBase):
    """Get OD List request (ETG.1000.6 Table 49)."""

    list_type: int = OdListType.ALL


@dataclass(frozen=True, slots=True)
class OdListResponse(SdoInfoBase):
    """One fragment of a Get OD List response (ETG.1000.6 Table 50).

    The first fragment starts with the list type, later fragments carry only more
    indexes; ``words`` are the u16 values as sent. See :func:`od_list_from_fragments`.
    """

    data: bytes = b""

    @property
    def words(self) -> tuple[int, ...]:
        n = len(self.data) // 2
        return struct.unpack_from(f"<{n}H", self.data) if n else ()


@dataclass(frozen=True, slots=True)
class ObjectDescriptionRequest(SdoInfoBase):
    """Get Object Description request (ETG.1000.6 Table 51)."""

    index: int = 0


@dataclass(frozen=True, slots=True)
class ObjectDescriptionResponse(SdoInfoBase):
    """Get Object Description response (ETG.1000.6 Table 52). ``name`` as sent."""

    index: int = 0
    data_type: int = 0
    max_subindex: int = 0
    object_code: int = 0
    name: bytes = b""

    @property
    def name_text(self) -> str:
        return self.name.decode("utf-8", "replace")


@dataclass(frozen=True, slots=True)
class EntryDescriptionRequest(SdoInfoBase):
    """Get Entry Description request (ETG.1000.6 Table 53). ``value_info`` asks for the
    unit (0x08), default (0x10), minimum (0x20) and maximum (0x40) values."""

    index: int = 0
    subindex: int = 0
    value_info: int = 0


@dataclass(frozen=True, slots=True)
class EntryDescriptionResponse(SdoInfoBase):
    """Get Entry Description response (ETG.1000.6 Table 54).

    ``data`` holds what follows the access word: unit type, default/minimum/maximum
    values as asked for by ``value_info``, then the description text; see
    :meth:`description`.
    """

    index: int = 0
    subindex: int = 0
    value_info: int = 0
    data_type: int = 0
    bit_length: int = 0
    object_access: int = 0
    data: bytes = b""

    def description(self) -> bytes:
        """The description text after the optional unit and values."""
        skip = 2 if self.value_info & 0x08 else 0
        value_bytes = (self.bit_length + 7) // 8
        skip += value_bytes * sum(1 for bit in (0x10, 0x20, 0x40) if self.value_info & bit)
        return self.data[skip:]


@dataclass(frozen=True, slots=True)
class SdoInfoError(SdoInfoBase):
    """SDO Info Error request (ETG.1000.6 Table 55): an abort code for the last request."""

    code: int = 0

    @property
    def text(self) -> str:
        return abort_text(self.code)


@dataclass(frozen=True, slots=True)
class SdoInfoUnknown(SdoInfoBase):
    """An SDO Information message with an opcode this codec does not know."""

    opcode: int = 0
    data: bytes = b""


SdoMessage = (
    SdoDownloadRequest
    | SdoUploadResponse
    | SdoUploadRequest
    | SdoDownloadResponse
    | SdoDownloadSegmentRequest
    | SdoUploadSegmentResponse
    | SdoUploadSegmentRequest
    | SdoDownloadSegmentResponse
    | SdoAbort
)
SdoInfoMessage = (
    OdListRequest
    | OdListResponse
    | ObjectDescriptionRequest
    | ObjectDescriptionResponse
    | EntryDescriptionRequest
    | EntryDescriptionResponse
    | SdoInfoError
    | SdoInfoUnknown
)

_INFO_OPCODE: dict[type, int] = {
    OdListRequest: SdoInfoOpcode.GET_OD_LIST_REQUEST,
    OdListResponse: SdoInfoOpcode.GET_OD_LIST_RESPONSE,
    ObjectDescriptionRequest: SdoInfoOpcode.GET_OBJECT_DESCRIPTION_REQUEST,
    ObjectDescriptionResponse: SdoInfoOpcode.GET_OBJECT_DESCRIPTION_RESPONSE,
    EntryDescriptionRequest: SdoInfoOpcode.GET_ENTRY_DESCRIPTION_REQUEST,
    EntryDescriptionResponse: SdoInfoOpcode.GET_ENTRY_DESCRIPTION_RESPONSE,
    SdoInfoError: SdoInfoOpcode.ERROR_REQUEST,
}


# --- decoding ---------------------------------------------------------------------------


def decode_sdo(coe_payload: bytes | memoryview) -> SdoMessage | SdoInfoMessage:
    """Decode an SDO or SDO Information message from a CoE payload (CoE header first).

    Raises :class:`WireError` for other CoE services, unknown command specifiers and
    messages too short for their kind.
    """
    header = decode_coe_header(coe_payload)
    body = bytes(coe_payload[COE_HEADER_BYTES:])
    if header.service == CoeService.SDO_REQUEST:
        return _decode_request(body)
    if header.service == CoeService.SDO_RESPONSE:
        return _decode_response(body)
    if header.service == CoeService.SDO_INFO:
        return _decode_info(body)
    raise WireError(f"CoE service {header.service} is not SDO", offset=0)


def _decode_request(body: bytes) -> SdoMessage:
    need(body, 0, 1, "SDO command")
    spec = body[0] >> 5
    if spec == ClientCommand.INITIATE_DOWNLOAD:
        return SdoDownloadRequest(*_initiate_fields(body))
    if spec == ClientCommand.DOWNLOAD_SEGMENT:
        return SdoDownloadSegmentRequest(*_segment_fields(body))
    if spec == ClientCommand.INITIATE_UPLOAD:
        return SdoUploadRequest(*_addressed_fields(body))
    if spec == ClientCommand.UPLOAD_SEGMENT:
        return SdoUploadSegmentRequest(*_ack_fields(body))
    if spec == ClientCommand.ABORT:
        return _decode_abort(body, CoeService.SDO_REQUEST)
    raise WireError(f"unknown SDO client command specifier {spec}", offset=COE_HEADER_BYTES)


def _decode_response(body: bytes) -> SdoMessage:
    need(body, 0, 1, "SDO command")
    spec = body[0] >> 5
    if spec == ServerCommand.INITIATE_UPLOAD:
        return SdoUploadResponse(*_initiate_fields(body))
    if spec == ServerCommand.UPLOAD_SEGMENT:
        return SdoUploadSegmentResponse(*_segment_fields(body))
    if spec == ServerCommand.INITIATE_DOWNLOAD:
        return SdoDownloadResponse(*_addressed_fields(body))
    if spec == ServerCommand.DOWNLOAD_SEGMENT:
        return SdoDownloadSegmentResponse(*_ack_fields(body))
    if spec == ServerCommand.ABORT:
        return _decode_abort(body, CoeService.SDO_RESPONSE)
    raise WireError(f"unknown SDO server command specifier {spec}", offset=COE_HEADER_BYTES)


def _initiate_fields(
    body: bytes,
) -> tuple[int, int, bytes, bool, bool, bool, int, bytes]:
    need(body, 0, _ADDR.size + 4, "SDO initiate")
    command, index, subindex = _ADDR.unpack_from(body, 0)
    sized, expedited, complete = bool(command & 1), bool(command & 2), bool(command & 0x10)
    rest = body[_ADDR.size :]
    if expedited:
        n = EXPEDITED_MAX_BYTES - ((command >> 2) & 3) if sized else EXPEDITED_MAX_BYTES
        return index, subindex, rest[:n], complete, True, sized, 0, rest[n:]
    (size,) = _U32.unpack_from(rest, 0)
    return index, subindex, rest[4:], complete, False, sized, size, b""


def _addressed_fields(body: bytes) -> tuple[int, int, bool, bytes]:
    need(body, 0, _ADDR.size, "SDO initiate")
    command, index, subindex = _ADDR.unpack_from(body, 0)
    return index, subindex, bool(command & 0x10), body[_ADDR.size :]


def _segment_fields(body: bytes) -> tuple[bytes, bool, bool, bytes]:
    need(body, 0, 1, "SDO segment")
    command = body[0]
    unused = (command >> 1) & 7
    rest = body[1:]
    if unused:
        n = SEGMENT_MIN_DATA_BYTES - unused
        need(rest, 0, SEGMENT_MIN_DATA_BYTES, "SDO segment data")
        return rest[:n], bool(command & 0x10), bool(command & 1), rest[n:]
    return rest, bool(command & 0x10), bool(command & 1), b""


def _ack_fields(body: bytes) -> tuple[bool, bytes]:
    need(body, 0, 1, "SDO segment")
    return bool(body[0] & 0x10), body[1:]


def _decode_abort(body: bytes, service: int) -> SdoAbort:
    need(body, 0, _ADDR.size + 4, "SDO abort")
    _, index, subindex = _ADDR.unpack_from(body, 0)
    (code,) = _U32.unpack_from(body, _ADDR.size)
    return SdoAbort(index, subindex, abort_code(code), service)


def _decode_info(body: bytes) -> SdoInfoMessage:
    need(body, 0, _INFO_HEAD.size, "SDO Information header")
    op_byte, reserved, frags = _INFO_HEAD.unpack_from(body, 0)
    head: dict[str, Any] = {
        "incomplete": bool(op_byte & 0x80),
        "fragments_left": frags,
        "reserved": reserved,
    }
    opcode = op_byte & 0x7F
    data = body[_INFO_HEAD.size :]
    if opcode == SdoInfoOpcode.GET_OD_LIST_REQUEST:
        need(data, 0, 2, "Get OD List request")
        return OdListRequest(enum_or_int(OdListType, _U16.unpack_from(data)[0]), **head)
    if opcode == SdoInfoOpcode.GET_OD_LIST_RESPONSE:
        return OdListResponse(data, **head)
    if opcode == SdoInfoOpcode.GET_OBJECT_DESCRIPTION_REQUEST:
        need(data, 0, 2, "Get Object Description request")
        return ObjectDescriptionRequest(_U16.unpack_from(data)[0], **head)
    if opcode == SdoInfoOpcode.GET_OBJECT_DESCRIPTION_RESPONSE:
        need(data, 0, _OBJ_DESC.size, "Get Object Description response")
        index, data_type, max_sub, code = _OBJ_DESC.unpack_from(data)
        name = data[_OBJ_DESC.size :]
        return ObjectDescriptionResponse(index, data_type, max_sub, code, name, **head)
    if opcode == SdoInfoOpcode.GET_ENTRY_DESCRIPTION_REQUEST:
        need(data, 0, _ENTRY_REQ.size, "Get Entry Description request")
        return EntryDescriptionRequest(*_ENTRY_REQ.unpack_from(data), **head)
    if opcode == SdoInfoOpcode.GET_ENTRY_DESCRIPTION_RESPONSE:
        need(data, 0, _ENTRY_DESC.size, "Get Entry Description response")
        index, sub, info, data_type, bits, access = _ENTRY_DESC.unpack_from(data)
        rest = data[_ENTRY_DESC.size :]
        return EntryDescriptionResponse(index, sub, info, data_type, bits, access, rest, **head)
    if opcode == SdoInfoOpcode.ERROR_REQUEST:
        need(data, 0, 4, "SDO Info Error request")
        return SdoInfoError(abort_code(_U32.unpack_from(data)[0]), **head)
    return SdoInfoUnknown(opcode, data, **head)


def od_list_from_fragments(fragments: list[OdListResponse]) -> tuple[int, tuple[int, ...]]:
    """The list type and the indexes of a Get OD List answer given as all its fragments."""
    words: list[int] = []
    for fragment in fragments:
        words.extend(fragment.words)
    if not words:
        raise WireError("Get OD List response without a list type")
    return enum_or_int(OdListType, words[0]), tuple(words[1:])


# --- encoding ---------------------------------------------------------------------------


def encode_sdo(message: SdoMessage | SdoInfoMessage) -> bytes:
    """CoE header + body: the mailbox payload of a CoE mailbox."""
    if isinstance(message, SdoInfoBase):
        return encode_coe_header(CoeHeader(CoeService.SDO_INFO)) + _encode_info(message)
    service: int = CoeService.SDO_RESPONSE
    if isinstance(message, SdoAbort):
        body = _encode_abort(message)
        service = message.coe_service
    elif isinstance(message, SdoInitiate):
        body = _encode_initiate(message)
    elif isinstance(message, SdoAddressed):
        body = _encode_addressed(message)
    elif isinstance(message, SdoSegment):
        body = _encode_segment(message)
    else:
        body = _encode_ack(message)
    if isinstance(message, _REQUESTS):
        service = CoeService.SDO_REQUEST
    return encode_coe_header(CoeHeader(service)) + body


_REQUESTS = (
    SdoDownloadRequest,
    SdoUploadRequest,
    SdoDownloadSegmentRequest,
    SdoUploadSegmentRequest,
)
_SPECIFIER: dict[type, int] = {
    SdoDownloadRequest: ClientCommand.INITIATE_DOWNLOAD,
    SdoUploadRequest: ClientCommand.INITIATE_UPLOAD,
    SdoDownloadSegmentRequest: ClientCommand.DOWNLOAD_SEGMENT,
    SdoUploadSegmentRequest: ClientCommand.UPLOAD_SEGMENT,
    SdoUploadResponse: ServerCommand.INITIATE_UPLOAD,
    SdoDownloadResponse: ServerCommand.INITIATE_DOWNLOAD,
    SdoUploadSegmentResponse: ServerCommand.UPLOAD_SEGMENT,
    SdoDownloadSegmentResponse: ServerCommand.DOWNLOAD_SEGMENT,
}


def _fit(data: bytes, size: int) -> bytes:
    return data + bytes(max(0, size - len(data)))


def _encode_initiate(m: SdoInitiate) -> bytes:
    command = (_SPECIFIER[type(m)] << 5) | (0x10 if m.complete_access else 0)
    command |= (1 if m.size_indicated else 0) | (2 if m.expedited else 0)
    if m.expedited:
        if len(m.data) > EXPEDITED_MAX_BYTES:
            raise WireError(f"expedited SDO data of {len(m.data)} bytes exceeds 4")
        if m.size_indicated:
            command |= (EXPEDITED_MAX_BYTES - len(m.data)) << 2
        payload = _fit(m.data + m.filler, EXPEDITED_MAX_BYTES)
    else:
        payload = _U32.pack(m.complete_size & 0xFFFFFFFF) + m.data
    return _ADDR.pack(command, m.index & 0xFFFF, m.subindex & 0xFF) + payload


def _encode_addressed(m: SdoAddressed) -> bytes:
    command = (_SPECIFIER[type(m)] << 5) | (0x10 if m.complete_access else 0)
    head = _ADDR.pack(command, m.index & 0xFFFF, m.subindex & 0xFF)
    return head + _fit(m.reserved, 4)


def _encode_segment(m: SdoSegment) -> bytes:
    n = len(m.data)
    unused = SEGMENT_MIN_DATA_BYTES - n if n < SEGMENT_MIN_DATA_BYTES else 0
    command = (_SPECIFIER[type(m)] << 5) | (0x10 if m.toggle else 0) | (1 if m.last else 0)
    command |= unused << 1
    payload = _fit(m.data + m.filler, SEGMENT_MIN_DATA_BYTES) if unused else m.data
    return bytes([command]) + payload


def _encode_ack(m: SdoSegmentAck) -> bytes:
    command = (_SPECIFIER[type(m)] << 5) | (0x10 if m.toggle else 0)
    return bytes([command]) + _fit(m.reserved, SEGMENT_MIN_DATA_BYTES)


def _encode_abort(m: SdoAbort) -> bytes:
    head = _ADDR.pack(ClientCommand.ABORT << 5, m.index & 0xFFFF, m.subindex & 0xFF)
    return head + _U32.pack(m.code & 0xFFFFFFFF)


def _encode_info(m: SdoInfoMessage) -> bytes:
    opcode = m.opcode if isinstance(m, SdoInfoUnknown) else _INFO_OPCODE[type(m)]
    op_byte = (opcode & 0x7F) | (0x80 if m.incomplete else 0)
    head = _INFO_HEAD.pack(op_byte, m.reserved & 0xFF, m.fragments_left & 0xFFFF)
    return head + _info_data(m)


def _info_data(m: SdoInfoMessage) -> bytes:
    if isinstance(m, OdListRequest):
        return _U16.pack(m.list_type & 0xFFFF)
    if isinstance(m, ObjectDescriptionRequest):
        return _U16.pack(m.index & 0xFFFF)
    if isinstance(m, ObjectDescriptionResponse):
        head = _OBJ_DESC.pack(m.index, m.data_type, m.max_subindex, m.object_code)
        return head + m.name
    if isinstance(m, EntryDescriptionRequest):
        return _ENTRY_REQ.pack(m.index, m.subindex, m.value_info)
    if isinstance(m, EntryDescriptionResponse):
        fields = (m.index, m.subindex, m.value_info, m.data_type, m.bit_length)
        return _ENTRY_DESC.pack(*fields, m.object_access) + m.data
    if isinstance(m, SdoInfoError):
        return _U32.pack(m.code & 0xFFFFFFFF)
    return m.data  # OdListResponse, SdoInfoUnknown


# --- convenience builders for clients and servers ----------------------------------------


_UPLOAD_REQUEST = struct.Struct("<HBHBI")  # CoE header, command, index, subindex, reserved


def upload_request(index: int, subindex: int, *, complete_access: bool = False) -> bytes:
    """The CoE payload of an initiate upload (read) request: the bytes of
    ``encode_sdo(SdoUploadRequest(index, subindex, complete_access))``, packed at once
    (a master's most frequent message)."""
    command = (ClientCommand.INITIATE_UPLOAD << 5) | (0x10 if complete_access else 0)
    return _UPLOAD_REQUEST.pack(
        CoeService.SDO_REQUEST << 12, command, index & 0xFFFF, subindex & 0xFF, 0
    )


def expedited_upload_data(coe_payload: bytes) -> bytes | None:
    """The data of an expedited initiate upload response (CoE service SDO response,
    server command 2, the e bit set), ``None`` for any other message: the common answer
    to a read, taken without decoding it into objects (:func:`decode_sdo` gives the same
    data in an :class:`SdoUploadResponse`)."""
    if len(coe_payload) < COE_HEADER_BYTES + _ADDR.size + 4:
        return None
    command = coe_payload[2]
    if coe_payload[1] >> 4 != CoeService.SDO_RESPONSE or command >> 5 != 2 or not command & 2:
        return None
    size = EXPEDITED_MAX_BYTES - ((command >> 2) & 3) if command & 1 else EXPEDITED_MAX_BYTES
    start = COE_HEADER_BYTES + _ADDR.size
    return bytes(coe_payload[start : start + size])


def download_request(
    index: int, subindex: int, data: bytes, *, complete_access: bool = False
) -> bytes:
    """The CoE payload of an initiate download (write): expedited up to 4 bytes, else
    normal with the complete size and all the data (the caller checks the mailbox size)."""
    if len(data) <= EXPEDITED_MAX_BYTES and data:
        message = SdoDownloadRequest(index, subindex, data, complete_access)
    else:
        message = SdoDownloadRequest(
            index, subindex, data, complete_access, expedited=False, complete_size=len(data)
        )
    return encode_sdo(message)


def abort(index: int, subindex: int, code: int) -> bytes:
    """The CoE payload of an abort (CoE service SDO request, from either side)."""
    return encode_sdo(SdoAbort(index, subindex, code))
