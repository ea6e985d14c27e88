"""SII images: structure, CRC, categories; and SII read transcripts from real captures
replayed against emulated ESCs holding the EEPROM contents those captures read."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest

from lolacli.emulator.chain import Chain
from lolacli.emulator.esc import Esc
from lolacli.emulator.sii import sii_from_slave, sii_layout
from lolacli.files import load_eni
from lolacli.wire.commands import Command as C
from lolacli.wire.frame import Frame, decode_frame
from lolacli.wire.sii import SiiCategory, SmType, crc8_sii
from lolacli.wire.sii import sii_categories as categories
from tests.conftest import corpus_files
from tests.emulator.bus import EXAMPLES
from tests.emulator.pcapng_frames import pcapng_frames


@pytest.mark.parametrize(
    "header_hex",
    [
        "000d0000000000000000000000004600",  # EK1100
        "040100000000ff00000000000000e200",  # EL2828
        "09000008000000000000000000001000",  # Kollmorgen AKD
        "06050000100001000000000000002b00",  # EL2262
    ],
)
def test_crc8_matches_real_eeprom_headers(header_hex: str) -> None:
    """Words 0..7 of real EEPROM dumps (ethercrab repository, dumps/eeprom/*.hex|bin):
    the low byte of word 7 is CRC-8 (x^8+x^2+x+1, init 0xFF) of words 0..6."""
    header = bytes.fromhex(header_hex)
    assert crc8_sii(header[:14]) == header[14]


def test_single_drive_image_header_and_categories() -> None:
    slave = load_eni(EXAMPLES / "single_drive.xml").slaves[0]
    image = sii_from_slave(slave)
    words = struct.unpack_from("<64H", image)
    assert crc8_sii(image[:14]) == words[7] & 0xFF
    assert words[8] | words[9] << 16 == slave.identity.vendor_id
    assert words[10] | words[11] << 16 == slave.identity.product_code
    assert words[12] | words[13] << 16 == slave.identity.revision
    assert words[14] | words[15] << 16 == slave.identity.serial
    assert (words[0x18], words[0x19]) == (0x1800, 140)  # standard receive (SM0)
    assert (words[0x1A], words[0x1B]) == (0x1900, 140)
    assert words[0x1C] & 0x04  # CoE
    cats = categories(image)
    assert set(cats) >= {
        SiiCategory.STRINGS,
        SiiCategory.GENERAL,
        SiiCategory.FMMU,
        SiiCategory.SYNCM,
        SiiCategory.TXPDO,
        SiiCategory.RXPDO,
    }
    strings = cats[SiiCategory.STRINGS]
    assert strings[1 : 2 + len(slave.name)] == bytes([len(slave.name)]) + slave.name.encode()
    assert cats[SiiCategory.GENERAL][3] == 1  # name is string 1 (SOEM reads string 1)
    layout = sii_layout(image)
    assert [sm.type for sm in layout.sync_managers] == [
        SmType.MAILBOX_OUT,
        SmType.MAILBOX_IN,
        SmType.OUTPUTS,
        SmType.INPUTS,
    ]
    assert (layout.outputs_bytes, layout.inputs_bytes) == (11, 11)
    assert layout.name == slave.name


def test_every_lola_slave_has_a_consistent_image() -> None:
    eni = load_eni(EXAMPLES / "lola.xml")
    for slave in eni.slaves:
        layout = sii_layout(sii_from_slave(slave))
        assert layout.vendor_id == slave.identity.vendor_id
        assert layout.product_code == slave.identity.product_code
        assert layout.outputs_bytes * 8 >= slave.outputs_bits
        assert layout.inputs_bytes * 8 >= slave.inputs_bits
        for sm in slave.sync_managers:  # SM index = position in the SYNCM category
            assert layout.sync_managers[sm.index].sync_manager.physical_start == (
                sm.sync_manager.physical_start
            )


# ---------------------------------------------------------------- transcripts
def _pairs(frames: list[bytes]) -> list[tuple[bytes, Frame]]:
    """(outgoing bytes, returned frame) for every master frame answered next."""
    decoded: list[Frame | None] = []
    for raw in frames:
        try:
            decoded.append(decode_frame(raw))
        except Exception:
            decoded.append(None)
    out = []
    for i in range(len(frames) - 1):
        a, b = decoded[i], decoded[i + 1]
        if a is None or b is None or a.ethernet.returned or not b.ethernet.returned:
            continue
        if [(d.cmd, d.index) for d in a.datagrams] == [(d.cmd, d.index) for d in b.datagrams]:
            out.append((frames[i], b))
    return out


def _positions(pairs: list[tuple[bytes, Frame]]) -> dict[int, int]:
    """Station address -> 0-based position, from APWR 0x0010 in the capture."""
    out = {}
    for raw, _ in pairs:
        for d in decode_frame(raw).datagrams:
            if d.cmd == C.APWR and d.ado == 0x0010 and len(d.data) == 2:
                out[struct.unpack("<H", d.data)[0]] = (-d.adp) & 0xFFFF
    return out


def _position(d, positions: dict[int, int]) -> int | None:
    if d.cmd in (C.APRD, C.APWR):
        return (-d.adp) & 0xFFFF
    if d.cmd in (C.FPRD, C.FPWR):
        return positions.get(d.adp)
    return None


def _eeprom_contents(pairs, positions) -> dict[int, dict[int, int]]:
    """Position -> {byte offset: byte read} from 0x0502 commands and 0x0502/0x0508 reads."""
    address: dict[int, int] = {}
    words: dict[int, dict[int, int]] = {}
    for raw, back in pairs:
        for d, r in zip(decode_frame(raw).datagrams, back.datagrams, strict=True):
            pos = _position(d, positions)
            if pos is None or r.wkc != 1:
                continue
            if d.cmd in (C.APWR, C.FPWR) and d.ado == 0x0502 and len(d.data) >= 6:
                if d.data[1] & 0x07 == 0x01:
                    address[pos] = struct.unpack_from("<I", d.data, 2)[0]
            start = None
            if d.cmd in (C.APRD, C.FPRD) and d.ado == 0x0508:
                start = 0
            elif d.cmd in (C.APRD, C.FPRD) and d.ado == 0x0502 and len(d.data) > 6:
                start = 6
            if start is not None and pos in address:
                known = words.setdefault(pos, {})
                for i, byte in enumerate(r.data[start:]):
                    known[2 * address[pos] + i] = byte
    return words


def _image(known: dict[int, int]) -> bytes:
    image = bytearray(b"\xff" * 4096)
    for offset, byte in known.items():
        image[offset] = byte
    return bytes(image)


CAPTURES = [
    p
    for p in corpus_files("pcap", "ethercrab__*.pcapng")
    if p.name in ("ethercrab__twincat-scan-boxes.pcapng", "ethercrab__rs-example-sii-el2004.pcapng")
]


@pytest.mark.parametrize("path", CAPTURES, ids=[p.name for p in CAPTURES])
def test_sii_transcript_replays_against_emulated_escs(path: Path) -> None:
    pairs = _pairs(pcapng_frames(path))
    positions = _positions(pairs)
    contents = _eeprom_contents(pairs, positions)
    assert contents, "no SII reads found"
    slaves = max(max(contents), max(positions.values(), default=0)) + 1
    chain = Chain([Esc(_image(contents.get(i, {}))) for i in range(slaves)])
    compared = 0
    for raw, back in pairs:
        reply, _ = chain.process(raw, 0)
        assert reply is not None
        ours = decode_frame(reply).datagrams
        for d, theirs, mine in zip(decode_frame(raw).datagrams, back.datagrams, ours, strict=True):
            if d.ado not in (0x0502, 0x0508) or d.cmd not in (C.APRD, C.FPRD):
                continue
            if theirs.wkc != 1:
                continue
            assert mine.wkc == theirs.wkc
            if d.ado == 0x0508:
                assert mine.data == theirs.data, (path.name, d)
            else:  # control/status: command, busy and error bits; then address and data
                assert mine.data[1] == theirs.data[1]
                assert mine.data[2:] == theirs.data[2:]
            compared += 1
    assert compared >= 8
    vendor = struct.unpack_from("<I", _image(contents[0]), 16)[0]
    assert vendor == 2  # Beckhoff, as the capture's slaves say
