"""The CoE SDO server through the ESC mailbox, spoken to with lolacli.wire's encoders."""

from __future__ import annotations

import struct

import pytest

from lolacli.devices.cia402 import Cia402Drive
from lolacli.emulator.mailbox.sdo_server import SdoServer
from lolacli.emulator.slave import build_chain
from lolacli.files import load_eni
from lolacli.wire.mailbox import MailboxType, decode_mailbox, encode_mailbox, make_mailbox
from lolacli.wire.sdo import (
    EntryDescriptionRequest,
    EntryDescriptionResponse,
    ObjectDescriptionRequest,
    ObjectDescriptionResponse,
    OdListRequest,
    OdListResponse,
    SdoAbort,
    SdoAbortCode,
    SdoDownloadResponse,
    SdoDownloadSegmentRequest,
    SdoInfoError,
    SdoUploadRequest,
    SdoUploadResponse,
    decode_sdo,
    encode_sdo,
    od_list_from_fragments,
)
from tests.emulator.bus import EXAMPLES, Bus

MBX = ((0x1800, 140), (0x1900, 140))
STATION = 0x03E9


@pytest.fixture
def bus() -> Bus:
    eni = load_eni(EXAMPLES / "single_drive.xml")
    b = Bus(build_chain(eni))
    b.transition(eni, "IP")
    return b


def test_expedited_upload_of_device_type_and_identity(bus: Bus) -> None:
    assert bus.sdo_upload(STATION, 0x1000, 0, MBX) == struct.pack("<I", 0x00020192)
    assert bus.sdo_upload(STATION, 0x1018, 1, MBX) == struct.pack("<I", 0x9A)
    assert bus.sdo_upload(STATION, 0x1018, 0, MBX) == b"\x04"


def test_segmented_upload_of_a_long_string_with_toggle_bits(bus: Bus) -> None:
    value = bus.sdo_upload(STATION, 0x1008, 0, MBX)
    assert value == Cia402Drive.LONG_NAME.encode()
    assert len(value) > 140 - 16  # did not fit one mailbox: segments were needed


def test_download_round_trip_and_aborts(bus: Bus) -> None:
    reply = bus.sdo_download(STATION, 0x607F, 0, struct.pack("<I", 50_000), MBX)
    assert isinstance(reply, SdoDownloadResponse)
    assert bus.sdo_upload(STATION, 0x607F, 0, MBX) == struct.pack("<I", 50_000)
    cases = [
        (0x2345, 0, b"\x01", SdoAbortCode.NO_OBJECT),
        (0x1018, 9, b"\x01", SdoAbortCode.NO_SUBINDEX),
        (0x1000, 0, b"\x01\x02\x03\x04", SdoAbortCode.READ_ONLY),
        (0x607F, 0, b"\x01\x02", SdoAbortCode.LENGTH_MISMATCH),
    ]
    for index, sub, data, code in cases:
        reply = bus.sdo_download(STATION, index, sub, data, MBX)
        assert isinstance(reply, SdoAbort) and reply.code == code, (index, reply)
    upload = bus.sdo_upload(STATION, 0x2345, 0, MBX)
    assert isinstance(upload, SdoAbort) and upload.code == 0x06020000


def test_normal_and_segmented_download(bus: Bus) -> None:
    drive = bus.chain.slaves[0].app.device  # type: ignore[union-attr]
    drive.od.add_var(0x2000, "Scratch", 0x000A, b"", access="rw")
    blob = bytes(range(200))
    reply = bus.sdo_download(STATION, 0x2000, 0, blob[:100], MBX)  # normal, one mailbox
    assert isinstance(reply, SdoDownloadResponse)
    assert drive.od.read(0x2000, 0) == blob[:100]
    reply = bus.sdo_download(STATION, 0x2000, 0, blob, MBX, segment_bytes=50)
    assert drive.od.read(0x2000, 0) == blob


def test_wrong_toggle_aborts_a_segmented_download(bus: Bus) -> None:
    drive = bus.chain.slaves[0].app.device  # type: ignore[union-attr]
    drive.od.add_var(0x2000, "Scratch", 0x000A, b"", access="rw")
    from lolacli.wire.sdo import SdoDownloadRequest

    first = SdoDownloadRequest(0x2000, 0, b"abc", expedited=False, complete_size=10)
    bus.mailbox_exchange(STATION, encode_sdo(first), *MBX)
    wrong = SdoDownloadSegmentRequest(b"defghij", toggle=True, last=True)
    reply = decode_sdo(bus.mailbox_exchange(STATION, encode_sdo(wrong), *MBX))
    assert isinstance(reply, SdoAbort) and reply.code == SdoAbortCode.TOGGLE_BIT_NOT_ALTERNATED


def test_complete_access_upload_of_pdo_assignment(bus: Bus) -> None:
    request = SdoUploadRequest(0x1C12, 0, complete_access=True)
    reply = decode_sdo(bus.mailbox_exchange(STATION, encode_sdo(request), *MBX))
    assert isinstance(reply, SdoUploadResponse)
    data = reply.data[: reply.value_bytes]
    assert data[:2] == b"\x01\x00" and struct.unpack_from("<H", data, 2)[0] == 0x1600


def test_sdo_information_services(bus: Bus) -> None:
    raw = bus.mailbox_exchange(STATION, encode_sdo(OdListRequest(list_type=1)), *MBX)
    fragments = [decode_sdo(raw)]
    while fragments[-1].fragments_left:  # type: ignore[union-attr]
        raw = decode_mailbox(bus.fprd(STATION, 0x1900, 140)).payload
        fragments.append(decode_sdo(raw))
    assert all(isinstance(f, OdListResponse) for f in fragments)
    _list_type, indexes = od_list_from_fragments(fragments)  # type: ignore[arg-type]
    assert {0x1000, 0x1018, 0x1C12, 0x6040, 0x607A} <= set(indexes)
    desc = decode_sdo(
        bus.mailbox_exchange(STATION, encode_sdo(ObjectDescriptionRequest(index=0x1018)), *MBX)
    )
    assert isinstance(desc, ObjectDescriptionResponse)
    assert (desc.max_subindex, desc.object_code, desc.name_text) == (4, 9, "Identity")
    entry = decode_sdo(
        bus.mailbox_exchange(
            STATION, encode_sdo(EntryDescriptionRequest(index=0x6041, subindex=0)), *MBX
        )
    )
    assert isinstance(entry, EntryDescriptionResponse)
    assert (entry.data_type, entry.bit_length) == (0x0006, 16)
    missing = decode_sdo(
        bus.mailbox_exchange(STATION, encode_sdo(ObjectDescriptionRequest(index=0x5555)), *MBX)
    )
    assert isinstance(missing, SdoInfoError) and missing.code == 0x06020000


def test_unsupported_mailbox_protocol_gets_a_mailbox_error() -> None:
    eni = load_eni(EXAMPLES / "single_drive.xml")
    from lolacli.devices import device_for

    server = SdoServer(device_for(eni.slaves[0]).od)
    eoe = encode_mailbox(make_mailbox(MailboxType.EoE, bytes(10)))
    (reply,) = server.handle(eoe)
    box = decode_mailbox(reply)
    assert box.mailbox_type == MailboxType.ERR
    assert struct.unpack_from("<HH", box.payload) == (1, 2)


def test_complete_access_download_of_a_pdo_mapping(bus: Bus) -> None:
    from lolacli.wire.sdo import SdoDownloadRequest

    entries = [0x60410010, 0x60640020]
    payload = bytes([len(entries), 0]) + b"".join(struct.pack("<I", e) for e in entries)
    request = SdoDownloadRequest(
        0x1A00, 0, payload, complete_access=True, expedited=False, complete_size=len(payload)
    )
    reply = decode_sdo(bus.mailbox_exchange(STATION, encode_sdo(request), *MBX))
    assert isinstance(reply, SdoDownloadResponse) and reply.complete_access
    drive = bus.chain.slaves[0].app.device  # type: ignore[union-attr]
    assert drive.process_data_bytes() == (11, 6)
    upload = decode_sdo(
        bus.mailbox_exchange(
            STATION, encode_sdo(SdoUploadRequest(0x1A00, 0, complete_access=True)), *MBX
        )
    )
    assert isinstance(upload, SdoUploadResponse)
    assert upload.data[:10] == payload


def test_drive_fault_sends_a_coe_emergency(bus: Bus) -> None:
    from lolacli.wire.coe import decode_emergency

    bus.chain.drive_fault(1, 0x7305)
    raw = bus.fprd(STATION, 0x1900, 140)
    box = decode_mailbox(raw)
    assert box.mailbox_type == MailboxType.CoE
    emergency = decode_emergency(box.payload)
    assert (emergency.error_code, emergency.error_register) == (0x7305, 0x01)
    drive = bus.chain.slaves[0].app.device  # type: ignore[union-attr]
    assert drive.od.get_int(0x603F) == 0x7305
    assert drive.od.get_int(0x6041) & 0x4F in (0x08, 0x0F)  # fault (reaction)
