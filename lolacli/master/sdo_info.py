"""The CoE SDO Information service over a slave's mailbox (ETG.1000.6 §5.6.3).

A slave that has it describes its own object dictionary: the list of its objects (Get OD
List), each object (Get Object Description: data type, highest subindex, object code,
name) and each entry (Get Entry Description: data type, bit length, access, name). An
answer longer than the slave's mailbox comes in fragments, each in a mailbox of its own
with the *incomplete* bit and the number of fragments still to come; the data of the
later fragments continues the first's (ETG.1000.6 Table 48). An SDO Info Error answer is
raised as :class:`~lolacli.errors.SdoAbortError` with its abort code.

The codecs are :mod:`lolacli.wire.sdo`'s; this module only runs the conversation through
a :class:`~lolacli.master.mailbox.MailboxClient`; what it reads is the one dictionary model
(:func:`lolacli.od.from_sdo_info`).
"""

from __future__ import annotations

from lolacli.errors import SdoAbortError, WireError
from lolacli.master.mailbox import MailboxClient
from lolacli.od import Dictionary, from_sdo_info
from lolacli.wire.coe import COE_HEADER_BYTES, CoeService, decode_coe_header
from lolacli.wire.mailbox import MailboxType
from lolacli.wire.sdo import (
    EntryDescriptionRequest,
    EntryDescriptionResponse,
    ObjectDescriptionRequest,
    ObjectDescriptionResponse,
    OdListRequest,
    OdListResponse,
    OdListType,
    SdoInfoError,
    abort_text,
    decode_sdo,
    encode_sdo,
    od_list_from_fragments,
)

#: CoE header + SDO Information header (opcode, reserved, fragments left)
_INFO_PREFIX_BYTES = COE_HEADER_BYTES + 4
_INCOMPLETE = 0x80


def _ask(mailbox: MailboxClient, request: object, index: int, subindex: int) -> object:
    """One SDO Information request and its whole answer (fragments joined)."""
    first = mailbox.request(MailboxType.CoE, encode_sdo(request))  # type: ignore[arg-type]
    payload = bytearray(first)
    last = first
    while _is_info(last) and len(last) >= _INFO_PREFIX_BYTES and last[2] & _INCOMPLETE:
        last = mailbox.receive(MailboxType.CoE)
        if not _is_info(last):
            raise WireError(f"station {mailbox.layout.station}: SDO Information fragment missing")
        payload += last[_INFO_PREFIX_BYTES:]
    if len(payload) >= _INFO_PREFIX_BYTES:
        payload[2] &= ~_INCOMPLETE & 0xFF
        payload[4:6] = b"\x00\x00"
    reply = decode_sdo(bytes(payload))
    if isinstance(reply, SdoInfoError):
        raise SdoAbortError(index, subindex, reply.code, abort_text(reply.code))
    return reply


def _is_info(payload: bytes) -> bool:
    return (
        len(payload) >= COE_HEADER_BYTES
        and decode_coe_header(payload).service == CoeService.SDO_INFO
    )


def od_list(mailbox: MailboxClient, list_type: int = OdListType.ALL) -> tuple[int, ...]:
    """The indexes of the slave's objects (Get OD List of ``list_type``)."""
    reply = _ask(mailbox, OdListRequest(list_type), 0, 0)
    if not isinstance(reply, OdListResponse):
        raise WireError(f"SDO Information: unexpected answer to Get OD List: {reply!r}")
    _kind, indexes = od_list_from_fragments([reply])
    return indexes


def object_description(mailbox: MailboxClient, index: int) -> ObjectDescriptionResponse:
    reply = _ask(mailbox, ObjectDescriptionRequest(index), index, 0)
    if not isinstance(reply, ObjectDescriptionResponse):
        raise WireError(f"SDO Information 0x{index:04X}: unexpected answer {reply!r}")
    return reply


def entry_description(
    mailbox: MailboxClient, index: int, subindex: int, value_info: int = 0
) -> EntryDescriptionResponse:
    reply = _ask(mailbox, EntryDescriptionRequest(index, subindex, value_info), index, subindex)
    if not isinstance(reply, EntryDescriptionResponse):
        raise WireError(
            f"SDO Information 0x{index:04X}:{subindex:02X}: unexpected answer {reply!r}"
        )
    return reply


def read_dictionary(mailbox: MailboxClient, indexes: tuple[int, ...] | None = None) -> Dictionary:
    """Every object of the slave (or those of ``indexes``, as :func:`od_list` gave them)
    with every entry from sub 0 to its highest subindex (a record's missing entries,
    answered with an error, are left out)."""
    out = []
    for index in od_list(mailbox) if indexes is None else indexes:
        obj = object_description(mailbox, index)
        entries = []
        for sub in range(obj.max_subindex + 1):
            try:
                e = entry_description(mailbox, index, sub)
            except SdoAbortError:
                continue
            name = e.description().decode("utf-8", "replace")
            entries.append((sub, name, e.data_type, e.bit_length, e.object_access))
        out.append((index, obj.name_text, obj.object_code, obj.data_type, 0, entries))
    return from_sdo_info(out)


__all__ = [
    "entry_description",
    "object_description",
    "od_list",
    "read_dictionary",
]
