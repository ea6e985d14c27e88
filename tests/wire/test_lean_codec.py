"""The lean paths of a master's mailbox traffic give the general codec's bytes and values:
mailbox messages (wire.mailbox), upload requests and expedited upload answers (wire.sdo)."""

from __future__ import annotations

from hypothesis import given
from hypothesis import strategies as st

from lolacli.errors import WireError
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
