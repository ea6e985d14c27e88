"""The lean paths of a master's mailbox traffic give the general codec's bytes and values:
one-datagram frames (wire.frame), mailbox messages (wire.mailbox), upload requests and
expedited upload answers (wire.sdo)."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from lolacli.errors import WireError
from lolacli.wire.frame import (
    Datagram,
    EthernetHeader,
    decode_frame,
    decode_single,
    encode_frame,
    encode_single,
    ethernet_head,
    make_frame,
)
from lolacli.wire.mailbox import (
    decode_mailbox,
    encode_mailbox,
    encode_mailbox_message,
    mailbox_type_and_payload,
    make_mailbox,
)
from lolacli.wire.sdo import (
    SdoAbort,
    SdoDownloadResponse,
    SdoUploadRequest,
    SdoUploadResponse,
    decode_sdo,
    encode_sdo,
    expedited_upload_data,
    upload_request,
)

MACS = st.binary(min_size=6, max_size=6)


@given(
    dst=MACS,
    src=MACS,
    cmd=st.integers(0, 14),
    index=st.integers(0, 255),
    address=st.integers(0, 0xFFFFFFFF),
    data=st.binary(max_size=1486),
)
def test_single_frames_are_the_general_codecs(dst, src, cmd, index, address, data) -> None:
    d = Datagram(cmd, index, address, data)
    general = encode_frame(make_frame([d], src=src, dst=dst), pad=True)
    assert encode_single(ethernet_head(dst, src), cmd, index, address, data) == general
    assert decode_single(general) == (cmd, index, address, data, 0)
    (back,) = decode_frame(general).datagrams
    assert (back.cmd, back.index, back.address, back.data, back.wkc) == (
        cmd,
        index,
        address,
        data,
        0,
    )


def test_decode_single_leaves_other_frames_to_the_general_decoder() -> None:
    two = encode_frame(
        make_frame([Datagram(4, 1, 0, b"ab"), Datagram(5, 2, 0, b"cd")], src=bytes(6)), pad=True
    )
    assert decode_single(two) is None
    tagged = encode_frame(
        make_frame([Datagram(4, 1, 0, b"ab")], src=bytes(6)),
        pad=True,
    )
    vlan = tagged[:12] + b"\x81\x00\x00\x05" + tagged[12:]
    assert decode_single(vlan) is None
    assert decode_single(tagged[:20]) is None  # cut short
    answered = bytearray(tagged)
    answered[28:30] = (3).to_bytes(2, "little")  # WKC after 2 data bytes
    assert decode_single(bytes(answered)) == (4, 1, 0, b"ab", 3)
    assert EthernetHeader().dst == b"\xff" * 6


@given(
    kind=st.integers(0, 15),
    payload=st.binary(max_size=200),
    counter=st.integers(0, 7),
    extra=st.integers(0, 40),
)
def test_mailbox_messages_are_the_general_codecs(kind, payload, counter, extra) -> None:
    size = len(payload) + 6 + extra
    general = encode_mailbox(make_mailbox(kind, payload, counter=counter), buffer_bytes=size)
    assert encode_mailbox_message(kind, payload, counter, size) == general
    decoded = decode_mailbox(general)
    assert mailbox_type_and_payload(general) == (int(decoded.mailbox_type), decoded.payload)


def test_mailbox_limits() -> None:
    import pytest

    with pytest.raises(WireError):
        encode_mailbox_message(3, bytes(10), 1, 15)
    with pytest.raises(WireError):
        mailbox_type_and_payload(b"\x05\x00")
    with pytest.raises(WireError):
        mailbox_type_and_payload(b"\x50\x00\x00\x00\x00\x03abc")


@given(index=st.integers(0, 0xFFFF), sub=st.integers(0, 255), ca=st.booleans())
def test_upload_requests(index, sub, ca) -> None:
    assert upload_request(index, sub, complete_access=ca) == encode_sdo(
        SdoUploadRequest(index, sub, ca)
    )


@given(data=st.binary(min_size=1, max_size=4), index=st.integers(0, 0xFFFF))
def test_expedited_answers_read_in_place(data, index) -> None:
    answer = encode_sdo(SdoUploadResponse(index, 1, data, False, True, True))
    assert expedited_upload_data(answer) == decode_sdo(answer).data == data


def test_other_answers_are_left_to_decode_sdo() -> None:
    for message in (
        SdoUploadResponse(0x1008, 0, b"abcdef", False, False, True, 6),
        SdoDownloadResponse(0x1000, 0),
        SdoAbort(0x1000, 0, 0x06020000),
    ):
        assert expedited_upload_data(encode_sdo(message)) is None
    assert expedited_upload_data(encode_sdo(SdoUploadRequest(0x1000, 0))) is None
    assert expedited_upload_data(b"\x00\x30\x43") is None
