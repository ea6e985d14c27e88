"""tshark as oracle for the messages the corpus does not hold: SDO segments, download
initiate (expedited and normal), SDO Information, emergency, EtherCAT over UDP, 802.1Q.

Frames are built with our encoders, written to a classic pcap in a temporary folder and
dissected by tshark once; each frame's expected tshark fields are written out by hand
from the specification, and our decoder must give the message back.
"""

from __future__ import annotations

import json
import struct
import subprocess
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from wire_corpus import TSHARK, _flatten

from lolacli.wire.coe import Emergency, decode_emergency, encode_emergency
from lolacli.wire.frame import Datagram, EthernetHeader, decode_any, encode_frame, make_frame
from lolacli.wire.mailbox import MailboxType, decode_mailbox, encode_mailbox, make_mailbox
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
    SdoUploadSegmentRequest,
    SdoUploadSegmentResponse,
    decode_sdo,
    encode_sdo,
)
from lolacli.wire.udp import UdpInfo

M = "ecat_mailbox.coe."

SDO_CASES: list[tuple[object, dict[str, str]]] = [
    (
        SdoDownloadRequest(0x6060, 0, b"\x08", filler=bytes(3)),
        {M + "type": "2", M + "sdoreq": "1", M + "sdoccsid": "0x2f", M + "sdoidx": "0x6060",
         M + "sdosub": "0x00", M + "sdodata": "0x08", M + "sdoccsid.expedited": "1"},
    ),
    (
        SdoDownloadRequest(0x2000, 1, b"0123456789", expedited=False, complete_size=10),
        {M + "sdoccsid": "0x21", M + "sdolength": "0x0000000a", M + "sdoccsid.expedited": "0",
         M + "dsoldata": b"0123456789".hex(":"), M + "sdosub": "0x01"},
    ),
    (
        SdoDownloadSegmentRequest(b"abc", toggle=True, last=True, filler=bytes(4)),
        {M + "sdoreq": "0", M + "sdoccsds.lastseg": "1", M + "sdoccsds.size": "4",
         M + "sdoccsds.toggle": "1"},
    ),
    (
        SdoDownloadSegmentRequest(b"0123456789", toggle=False, last=False),
        {M + "sdoccsds.lastseg": "0", M + "sdoccsds.size": "0", M + "sdoccsds.toggle": "0",
         M + "dsoldata": b"0123456789".hex(":")},
    ),
    (SdoDownloadSegmentResponse(toggle=True), {M + "type": "3", M + "sdores": "1",
                                              M + "sdoscsds_toggle": "1"}),
    (SdoUploadSegmentRequest(toggle=True), {M + "sdoreq": "3", M + "sdoccsus_toggle": "1"}),
    (
        SdoUploadSegmentResponse(b"hello world!", toggle=False, last=True),
        {M + "sdores": "0", M + "sdoscsus_lastseg": "1", M + "sdoscsus_bytes": "0",
         M + "sdoscsus_toggle": "0", M + "dsoldata": b"hello world!".hex(":")},
    ),
    (
        SdoUploadSegmentResponse(b"xy", toggle=True, last=True, filler=bytes(5)),
        {M + "sdoscsus_lastseg": "1", M + "sdoscsus_bytes": "5", M + "sdoscsus_toggle": "1"},
    ),
    (SdoDownloadResponse(0x6060, 0), {M + "sdores": "3", M + "sdoidx": "0x6060"}),
    (SdoAbort(0x6060, 0, 0x06090011), {M + "sdoreq": "4", M + "abortcode": "0x06090011"}),
    (
        OdListRequest(1),
        {M + "type": "8", M + "sdoinfoopcode": "1", M + "sdoinfolisttype": "0x0001"},
    ),
    (
        OdListResponse(struct.pack("<4H", 1, 0x1000, 0x1018, 0x6040), fragments_left=2),
        {M + "sdoinfoopcode": "2", M + "sdoinfofrag": "0x0002", M + "sdoinfolisttype": "0x0001"},
    ),
    (ObjectDescriptionRequest(index=0x1018), {M + "sdoinfoopcode": "3",
                                              M + "sdoinfoindex": "0x1018"}),
    (
        ObjectDescriptionResponse(
            index=0x1018, data_type=0x23, max_subindex=4, object_code=9, name=b"Identity"
        ),
        {M + "sdoinfoopcode": "4", M + "sdoinfoindex": "0x1018", M + "sdoinfodatatype": "0x0023",
         M + "sdoinfomaxsub": "0x04", M + "sdoinfoobjcode": "0x09", M + "sdoinfoname": "Identity"},
    ),
    (
        EntryDescriptionRequest(index=0x1018, subindex=1, value_info=0x7F),
        {M + "sdoinfoopcode": "5", M + "sdoinfosubindex": "0x01", M + "sdoinfovalueinfo": "0x7f"},
    ),
    (
        EntryDescriptionResponse(
            index=0x1018, subindex=1, data_type=7, bit_length=32, object_access=7,
            data=b"Vendor ID",
        ),
        {M + "sdoinfoopcode": "6", M + "sdoinfodatatype": "0x0007", M + "sdoinfobitlen": "0x0020",
         M + "sdoinfoobjaccess": "0x0007", M + "sdoinfoname": "Vendor ID"},
    ),
    (SdoInfoError(code=0x06020000), {M + "sdoinfoopcode": "7",
                                     M + "sdoinfoerrorcode": "0x06020000"}),
]


def _mailbox_frame(number: int, payload: bytes) -> bytes:
    mailbox = encode_mailbox(make_mailbox(MailboxType.CoE, payload, counter=number % 7 + 1),
                             buffer_bytes=128)
    datagram = Datagram.physical(5, 0x1001, 0x1000, mailbox, index=number, wkc=1)
    return encode_frame(make_frame([datagram], src=b"\x02" + bytes(5)), pad=True)


def _ecat_frames() -> list[bytes]:
    frame = make_frame(
        [Datagram.physical(4, 0x1001, 0x130, 2, index=7, wkc=1),
         Datagram.logical(12, 0x10000, b"abcd", index=8, wkc=3)],
        src=b"\x02" + bytes(5),
    )
    udp = UdpInfo(src_ip=bytes([192, 168, 1, 2]), dst_ip=bytes([192, 168, 1, 255]))
    tagged = replace(frame, ethernet=EthernetHeader(src=b"\x02" + bytes(5), vlan_tci=0x6005))
    return [encode_frame(replace(frame, udp=udp), pad=True), encode_frame(tagged, pad=True)]


def _dissect(tmp_path: Path, frames: list[bytes]) -> list[dict[str, Any]]:
    path = tmp_path / "synthetic.pcap"
    with path.open("wb") as out:
        out.write(struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, 65535, 1))
        for i, frame in enumerate(frames):
            out.write(struct.pack("<IIII", i, 0, len(frame), len(frame)) + frame)
    args = [str(TSHARK), "-r", str(path), "-T", "json", "--no-duplicate-keys"]
    args += ["-o", "ip.check_checksum:TRUE"]
    text = subprocess.run(args, capture_output=True, text=True, check=True).stdout
    packets = json.loads(text)
    assert len(packets) == len(frames)
    result = []
    for packet in packets:
        fields: dict[str, Any] = {}
        _flatten(packet["_source"]["layers"], fields)
        result.append(fields)
    return result


@pytest.fixture
def dissected(tmp_path: Path) -> list[dict[str, Any]]:
    if TSHARK is None:
        pytest.skip("tshark not installed")
    frames = [_mailbox_frame(i, encode_sdo(m)) for i, (m, _) in enumerate(SDO_CASES)]  # type: ignore[arg-type]
    emergency = Emergency(0x8130, 0x11, b"\x01\x02\x03\x04\x05")
    frames.append(_mailbox_frame(len(frames), encode_emergency(emergency)))
    return _dissect(tmp_path, frames + _ecat_frames())


def test_sdo_messages_as_tshark_reads_them(dissected: list[dict[str, Any]]) -> None:
    for i, (message, expected) in enumerate(SDO_CASES):
        fields = dissected[i]
        assert fields["ecat_mailbox.type"] == "3"
        for key, value in expected.items():
            assert fields.get(key) == value, (type(message).__name__, key, fields.get(key))


def test_our_decoder_reads_back_what_tshark_read(dissected: list[dict[str, Any]]) -> None:
    for i, (message, _) in enumerate(SDO_CASES):
        payload = bytes.fromhex(dissected[i]["ecat_mailbox.coe"].replace(":", ""))
        assert decode_sdo(payload) == message
        assert encode_sdo(decode_sdo(payload)) == payload


def test_emergency_as_tshark_reads_it(dissected: list[dict[str, Any]]) -> None:
    fields = dissected[len(SDO_CASES)]
    assert fields[M + "type"] == "1"
    payload = bytes.fromhex(fields["ecat_mailbox.coe"].replace(":", ""))
    assert decode_emergency(payload) == Emergency(0x8130, 0x11, b"\x01\x02\x03\x04\x05")


def test_udp_and_vlan_frames_as_tshark_reads_them(dissected: list[dict[str, Any]]) -> None:
    udp, tagged = dissected[-2:]
    assert udp["udp.dstport"] == str(0x88A4)
    assert udp["ip.checksum.status"] == "1"  # good
    assert tagged["vlan.id"] == "5" and tagged["vlan.priority"] == "3"
    for fields in (udp, tagged):
        assert fields["ecat.cmd"] == ["0x04", "0x0c"]
        assert fields["ecat.lad"] == "0x00010000"
        assert fields["ecat.cnt"] == ["1", "3"]
    frames = _ecat_frames()
    assert decode_any(frames[0]).udp is not None
    assert decode_any(frames[1]).ethernet.vlan_tci == 0x6005


def test_mailbox_header_fields(dissected: list[dict[str, Any]]) -> None:
    for i in range(len(SDO_CASES)):
        fields = dissected[i]
        payload = bytes.fromhex(fields["ecat_mailbox.coe"].replace(":", ""))
        assert int(fields["ecat_mailbox.length"]) == len(payload)
        assert int(fields["ecat_mailbox.counter"]) == i % 7 + 1
        mailbox = decode_mailbox(encode_mailbox(make_mailbox(MailboxType.CoE, payload)))
        assert mailbox.payload == payload
