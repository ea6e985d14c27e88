"""The FoE codec (lolacli.wire.foe): every opcode through tshark as an independent
oracle (its EtherCAT mailbox dissector reads FoE; it calls the password of a request
"filelength", the data of a data packet "busydata"), round trips, refusals."""

from __future__ import annotations

import json
import struct
import subprocess
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st
from wire_corpus import TSHARK, _flatten

from lolacli.errors import WireError
from lolacli.wire.foe import (
    FoeAck,
    FoeBusy,
    FoeData,
    FoeError,
    FoeErrorCode,
    FoeReadRequest,
    FoeWriteRequest,
    data_bytes_per_packet,
    decode_foe,
    encode_foe,
    foe_error_text,
)
from lolacli.wire.frame import Datagram, encode_frame, make_frame
from lolacli.wire.mailbox import MailboxType, encode_mailbox, make_mailbox

F = "ecat_mailbox.foe_"

CASES: list[tuple[object, dict[str, str]]] = [
    (FoeReadRequest("firmware.bin", 0x12345678),
     {F + "opmode": "0x01", F + "filelength": "305419896", F + "filename": "firmware.bin"}),
    (FoeWriteRequest("app", 7),
     {F + "opmode": "0x02", F + "filelength": "7", F + "filename": "app"}),
    (FoeData(3, b"\x01\x02\x03\x04"),
     {F + "opmode": "0x03", F + "packetno": "3", F + "busydata": "01:02:03:04"}),
    (FoeAck(0), {F + "opmode": "0x04", F + "packetno": "0"}),
    (FoeError(FoeErrorCode.NO_RIGHTS, "password"),
     {F + "opmode": "0x05", F + "errcode": "32778", F + "errtext": "password"}),
    (FoeBusy(40, 100),
     {F + "opmode": "0x06", F + "busydone": "0x0028", F + "busyentire": "0x0064"}),
]  # fmt: skip


def _frame(number: int, payload: bytes) -> bytes:
    box = make_mailbox(MailboxType.FoE, payload, counter=number % 7 + 1)
    datagram = Datagram.physical(5, 0x1001, 0x1000, encode_mailbox(box, buffer_bytes=128), wkc=1)
    return encode_frame(make_frame([datagram], src=b"\x02" + bytes(5)), pad=True)


def _dissect(tmp_path: Path, frames: list[bytes]) -> list[dict[str, Any]]:
    path = tmp_path / "foe.pcap"
    with path.open("wb") as out:
        out.write(struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, 65535, 1))
        for i, frame in enumerate(frames):
            out.write(struct.pack("<IIII", i, 0, len(frame), len(frame)) + frame)
    args = [str(TSHARK), "-r", str(path), "-T", "json", "--no-duplicate-keys"]
    packets = json.loads(subprocess.run(args, capture_output=True, text=True, check=True).stdout)
    out_fields = []
    for packet in packets:
        fields: dict[str, Any] = {}
        _flatten(packet["_source"]["layers"], fields)
        out_fields.append(fields)
    return out_fields


def test_every_opcode_as_tshark_reads_it(tmp_path: Path) -> None:
    if TSHARK is None:
        pytest.skip("tshark not installed")
    frames = [_frame(i, encode_foe(m)) for i, (m, _) in enumerate(CASES)]  # type: ignore[arg-type]
    dissected = _dissect(tmp_path, frames)
    assert len(dissected) == len(CASES)
    for (message, expected), fields in zip(CASES, dissected, strict=True):
        assert fields["ecat_mailbox.type"] == "4"
        for key, value in expected.items():
            assert fields.get(key) == value, (message, key, fields.get(key))
        assert decode_foe(encode_foe(message)) == message  # type: ignore[arg-type]


@given(
    st.integers(0, 0xFFFF_FFFF),
    st.binary(max_size=300),
    st.text(st.characters(min_codepoint=1, max_codepoint=255), max_size=40),
)
def test_round_trips(number: int, data: bytes, name: str) -> None:
    for message in (
        FoeReadRequest(name, number),
        FoeWriteRequest(name, number),
        FoeData(number, data),
        FoeAck(number),
        FoeError(number, name),
    ):
        assert decode_foe(encode_foe(message)) == message


def test_a_name_padded_with_nul_reads_up_to_the_nul() -> None:
    raw = encode_foe(FoeWriteRequest("fw", 1)) + bytes(10)
    assert decode_foe(raw) == FoeWriteRequest("fw", 1)


def test_error_texts_cover_every_code_and_name_unknown_ones() -> None:
    texts = {code: foe_error_text(code) for code in FoeErrorCode}
    assert len(set(texts.values())) == len(texts)
    assert foe_error_text(0x800A) == "no rights: the password is wrong"
    assert foe_error_text(0x9000) == "unknown FoE error 0x9000"
    assert FoeError(0x8008).meaning == "only in BOOT (bootstrap) state"


@pytest.mark.parametrize(
    "raw",
    [b"", b"\x03\x00\x01", bytes([9, 0, 0, 0, 0, 0])],
    ids=["empty", "truncated", "unknown-opcode"],
)
def test_malformed_messages_are_wire_errors(raw: bytes) -> None:
    with pytest.raises(WireError):
        decode_foe(raw)


def test_out_of_range_fields_are_refused() -> None:
    with pytest.raises(WireError):
        encode_foe(FoeData(1 << 32, b""))
    with pytest.raises(WireError):
        encode_foe(FoeBusy(70_000, 1))
    with pytest.raises(WireError):
        encode_foe(FoeWriteRequest("π-€", 0))


def test_data_bytes_per_packet() -> None:
    assert data_bytes_per_packet(128) == 116  # what SOEM sends: mailbox length - 12
    assert data_bytes_per_packet(1024) == 1012
    assert data_bytes_per_packet(8) == 0
