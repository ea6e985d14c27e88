"""Hypothesis round trips: decode(encode(x)) == x for every wire codec."""

from __future__ import annotations

from dataclasses import replace

from hypothesis import given, settings
from hypothesis import strategies as st

from lolacli.wire.coe import (
    CoeHeader,
    Emergency,
    decode_coe_header,
    decode_emergency,
    encode_coe_header,
    encode_emergency,
)
from lolacli.wire.frame import Datagram, EthernetHeader, Frame, decode_any, encode_frame
from lolacli.wire.mailbox import (
    Mailbox,
    MailboxError,
    MailboxHeader,
    decode_mailbox,
    decode_mailbox_error,
    encode_mailbox,
    encode_mailbox_error,
)
from lolacli.wire.registers import (
    Fmmu,
    SiiControlStatus,
    SyncManager,
    decode_fmmu,
    decode_sii_control_status,
    decode_sync_manager,
    decode_system_time_difference,
    encode_fmmu,
    encode_sii_control_status,
    encode_sync_manager,
    encode_system_time_difference,
)
from lolacli.wire.sdo import (
    EntryDescriptionRequest,
    EntryDescriptionResponse,
    ObjectDescriptionRequest,
    ObjectDescriptionResponse,
    OdListRequest,
    OdListResponse,
    SdoAbort,
    SdoDownloadRequest,
    SdoDownloadResponse,
    SdoDownloadSegmentRequest,
    SdoDownloadSegmentResponse,
    SdoInfoError,
    SdoInfoUnknown,
    SdoUploadRequest,
    SdoUploadResponse,
    SdoUploadSegmentRequest,
    SdoUploadSegmentResponse,
    decode_sdo,
    encode_sdo,
)
from lolacli.wire.udp import UdpInfo

EXAMPLES = settings(max_examples=150, deadline=None)

u8 = st.integers(0, 0xFF)
u16 = st.integers(0, 0xFFFF)
u32 = st.integers(0, 0xFFFFFFFF)
mac = st.binary(min_size=6, max_size=6)


def datagram(more: bool) -> st.SearchStrategy[Datagram]:
    return st.builds(
        Datagram,
        cmd=u8,
        index=u8,
        address=u32,
        data=st.binary(max_size=64),
        wkc=u16,
        irq=u16,
        circulating=st.booleans(),
        more=st.just(more),
        reserved=st.integers(0, 7),
    )


@st.composite
def frames(draw: st.DrawFn, udp: bool = False) -> Frame:
    n = draw(st.integers(1, 5))
    datagrams = tuple(draw(datagram(i < n - 1)) for i in range(n))
    eth = EthernetHeader(draw(mac), draw(mac), draw(st.none() | u16))
    info = draw(udp_infos()) if udp else None
    return Frame(eth, datagrams, 1, draw(st.integers(0, 1)), draw(st.binary(max_size=20)),
                 None, info)


@st.composite
def udp_infos(draw: st.DrawFn) -> UdpInfo:
    ports = draw(st.sampled_from(["src", "dst", "both"]))
    other = draw(u16)
    return UdpInfo(
        src_ip=draw(st.binary(min_size=4, max_size=4)),
        dst_ip=draw(st.binary(min_size=4, max_size=4)),
        src_port=0x88A4 if ports in ("src", "both") else other,
        dst_port=0x88A4 if ports in ("dst", "both") else other,
        ttl=draw(u8),
        tos=draw(u8),
        identification=draw(u16),
        dont_fragment=draw(st.booleans()),
        ip_options=draw(st.integers(0, 10).flatmap(lambda n: st.binary(min_size=4 * n,
                                                                       max_size=4 * n))),
        udp_checksum=draw(u16),
    )


@EXAMPLES
@given(frames())
def test_frame(frame: Frame) -> None:
    assert decode_any(encode_frame(frame)) == frame


@EXAMPLES
@given(frames(udp=True))
def test_udp_frame(frame: Frame) -> None:
    assert decode_any(encode_frame(frame)) == frame


@EXAMPLES
@given(frames(), st.integers(1, 20))
def test_frame_with_declared_length(frame: Frame, extra: int) -> None:
    frame = replace(frame, padding=bytes(extra) + frame.padding)
    frame = replace(frame, declared_length=frame.ecat_length + extra)
    if frame.declared_length is not None and frame.declared_length <= 0x7FF:
        assert decode_any(encode_frame(frame)) == frame


mailbox_headers = st.builds(
    MailboxHeader,
    length=st.just(0),
    address=u16,
    channel=st.integers(0, 63),
    priority=st.integers(0, 3),
    mailbox_type=st.integers(0, 15),
    counter=st.integers(0, 7),
    reserved=st.integers(0, 1),
)


@EXAMPLES
@given(mailbox_headers, st.binary(max_size=64), st.integers(0, 16))
def test_mailbox(header: MailboxHeader, payload: bytes, slack: int) -> None:
    mailbox = Mailbox(replace(header, length=len(payload)), payload)
    wire = encode_mailbox(mailbox, buffer_bytes=6 + len(payload) + slack)
    assert decode_mailbox(wire) == mailbox


@EXAMPLES
@given(st.builds(MailboxError, detail=u16, error_type=u16))
def test_mailbox_error(error: MailboxError) -> None:
    assert decode_mailbox_error(encode_mailbox_error(error)) == error


@EXAMPLES
@given(st.builds(CoeHeader, service=st.integers(0, 15), number=st.integers(0, 511),
                 reserved=st.integers(0, 7)))
def test_coe_header(header: CoeHeader) -> None:
    assert decode_coe_header(encode_coe_header(header)) == header


@EXAMPLES
@given(st.builds(Emergency, error_code=u16, error_register=u8,
                 data=st.binary(min_size=5, max_size=5)))
def test_emergency(emergency: Emergency) -> None:
    assert decode_emergency(encode_emergency(emergency)) == emergency


@st.composite
def initiates(draw: st.DrawFn, kind: type) -> object:
    index, subindex, ca = draw(u16), draw(u8), draw(st.booleans())
    if draw(st.booleans()):  # expedited
        sized = draw(st.booleans())
        n = draw(st.integers(1, 4)) if sized else 4
        data = draw(st.binary(min_size=n, max_size=n))
        filler = draw(st.binary(min_size=4 - n, max_size=4 - n + 8))
        return kind(index, subindex, data, ca, True, sized, 0, filler)
    data = draw(st.binary(max_size=40))
    return kind(index, subindex, data, ca, False, draw(st.booleans()), draw(u32), b"")


@st.composite
def segments(draw: st.DrawFn, kind: type) -> object:
    data = draw(st.binary(max_size=30))
    low = max(0, 7 - len(data))
    filler = draw(st.binary(min_size=low, max_size=low + 4)) if low else b""
    return kind(data, draw(st.booleans()), draw(st.booleans()), filler)


def addressed(kind: type) -> st.SearchStrategy[object]:
    return st.builds(kind, u16, u8, st.booleans(), st.binary(min_size=4, max_size=10))


def acks(kind: type) -> st.SearchStrategy[object]:
    return st.builds(kind, st.booleans(), st.binary(min_size=7, max_size=12))


info_head = {
    "incomplete": st.booleans(),
    "fragments_left": u16,
    "reserved": u8,
}
sdo_messages = st.one_of(
    initiates(SdoDownloadRequest),
    initiates(SdoUploadResponse),
    addressed(SdoUploadRequest),
    addressed(SdoDownloadResponse),
    segments(SdoDownloadSegmentRequest),
    segments(SdoUploadSegmentResponse),
    acks(SdoUploadSegmentRequest),
    acks(SdoDownloadSegmentResponse),
    st.builds(SdoAbort, u16, u8, u32, st.sampled_from([2, 3])),
    st.builds(OdListRequest, list_type=u16, **info_head),
    st.builds(OdListResponse, data=st.binary(max_size=40), **info_head),
    st.builds(ObjectDescriptionRequest, index=u16, **info_head),
    st.builds(ObjectDescriptionResponse, index=u16, data_type=u16, max_subindex=u8,
              object_code=u8, name=st.binary(max_size=30), **info_head),
    st.builds(EntryDescriptionRequest, index=u16, subindex=u8, value_info=u8, **info_head),
    st.builds(EntryDescriptionResponse, index=u16, subindex=u8, value_info=u8, data_type=u16,
              bit_length=u16, object_access=u16, data=st.binary(max_size=30), **info_head),
    st.builds(SdoInfoError, code=u32, **info_head),
    st.builds(SdoInfoUnknown, opcode=st.sampled_from([0, 8, 9, 0x7F]),
              data=st.binary(max_size=20), **info_head),
)


@settings(max_examples=600, deadline=None)
@given(sdo_messages)
def test_sdo(message: object) -> None:
    assert decode_sdo(encode_sdo(message)) == message  # type: ignore[arg-type]


@EXAMPLES
@given(st.builds(Fmmu, u32, u16, u8, u8, u16, u8, u8, u8, st.binary(min_size=3, max_size=3)))
def test_fmmu(fmmu: Fmmu) -> None:
    assert decode_fmmu(encode_fmmu(fmmu)) == fmmu


@EXAMPLES
@given(st.builds(SyncManager, u16, u16, u8, u8, u8, u8))
def test_sync_manager(sm: SyncManager) -> None:
    assert decode_sync_manager(encode_sync_manager(sm)) == sm


@EXAMPLES
@given(st.integers(-0x7FFFFFFF, 0x7FFFFFFF))
def test_system_time_difference(difference_ns: int) -> None:
    assert decode_system_time_difference(encode_system_time_difference(difference_ns)) == (
        difference_ns
    )


def test_sii_control_status_every_word() -> None:
    for word in range(0x10000):
        status = decode_sii_control_status(word)
        assert encode_sii_control_status(status) == word
        assert decode_sii_control_status(encode_sii_control_status(status)) == status


def test_sii_status_fields() -> None:
    status = SiiControlStatus(read_8_bytes=True, busy=True, command=1)
    assert encode_sii_control_status(status) == 0x8140
    assert status.read_bytes == 8
