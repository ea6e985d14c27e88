"""SII EEPROM decoding (lolacli.wire.sii): a real EL2004 image read back from a capture,
images our emulator builds from ENIs and ESIs, hypothesis round trips and fuzz."""

from __future__ import annotations

import random
import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st
from wire_corpus import CORPUS, ROOT, read_packets

from lolacli.errors import WireError
from lolacli.wire.commands import Command
from lolacli.wire.frame import decode_any
from lolacli.wire.registers import SyncManager
from lolacli.wire.sii import (
    HEADER_BYTES,
    MASTER_HEADER_WORDS,
    MailboxProtocol,
    SiiCategory,
    SiiGeneral,
    SiiHeader,
    SiiPdo,
    SiiPdoEntry,
    SiiSyncManager,
    SiiWords,
    crc8_sii,
    decode_sii,
    decode_sii_dc_assign_activate,
    decode_sii_general,
    decode_sii_header,
    decode_sii_pdos,
    decode_sii_strings,
    decode_sii_sync_managers,
    encode_sii_category,
    encode_sii_dc,
    encode_sii_general,
    encode_sii_header,
    encode_sii_pdos,
    encode_sii_strings,
    encode_sii_sync_managers,
    protocol_names,
    read_sii,
    sii_categories,
    sii_string,
)

RS_SII = CORPUS / "pcap" / "ethercrab__rs-example-sii-el2004.pcapng"


def sii_words_from_capture(packets: list[bytes], station: int) -> dict[int, bytes]:
    """The SII words a master read from the slave at ``station`` (FPWR of a read command
    to 0x0502, then FPRD of 0x0508), taken from the returned frames."""
    words: dict[int, bytes] = {}
    address: int | None = None
    for raw in packets:
        try:
            frame = decode_any(raw)
        except WireError:
            continue
        if not frame.ethernet.returned:
            continue
        for d in frame.datagrams:
            if d.adp != station or not d.wkc:
                continue
            if d.cmd == Command.FPWR and d.ado == 0x0502 and len(d.data) >= 4:
                control, word = struct.unpack_from("<HH", d.data)
                address = word if control & 0x0700 == 0x0100 else None
            elif d.cmd == Command.FPRD and d.ado == 0x0508 and address is not None:
                for i in range(len(d.data) // 2):
                    words[address + i] = d.data[2 * i : 2 * i + 2]
    return words


def test_el2004_image_read_by_ethercrab() -> None:
    """ethercrab__rs-example-sii-el2004.pcapng, packets 355-564: ethercrab reads the
    EL2004's (station 0x1001) identity words and its categories up to word 199."""
    if not RS_SII.is_file():
        pytest.skip(f"corpus capture {RS_SII.name} not found")
    words = sii_words_from_capture(read_packets(RS_SII), 0x1001)
    assert len(words) >= 100
    image = bytearray(2 * (max(words) + 1))
    for address, data in words.items():
        image[2 * address : 2 * address + 2] = data
    info = decode_sii(bytes(image))
    assert (info.header.vendor_id, info.header.product_code) == (0x00000002, 0x07D43052)
    assert info.name == "EL2004 4K. Dig. Ausgang 24V, 0.5A"
    assert info.order == "EL2004"
    assert info.group == "DigOut"
    assert [c[0] for c in info.categories[:2]] == [SiiCategory.STRINGS, SiiCategory.GENERAL]
    assert info.categories[0][1] == 0x40  # the first category sits at word 0x40


def test_emulator_images_of_every_lola_slave() -> None:
    """The SII the emulator builds from each ENI slave decodes to that slave's identity,
    name and mailbox protocols; the header checksum holds."""
    from lolacli.emulator.sii import sii_from_slave
    from lolacli.files import load_eni

    eni = load_eni(ROOT / "lolacli" / "eni_examples" / "lola.xml")
    for slave in eni.slaves:
        info = decode_sii(sii_from_slave(slave))
        ident = slave.identity
        h = info.header
        assert (h.vendor_id, h.product_code, h.revision, h.serial) == (
            ident.vendor_id,
            ident.product_code,
            ident.revision,
            ident.serial,
        )
        assert info.name == slave.name
        assert h.checksum_ok
        want = slave.mailbox.protocols if slave.mailbox is not None else ()
        assert set(protocol_names(h.mailbox_protocols)) == set(want)


@pytest.mark.parametrize("chunk_words", [2, 4])
def test_a_master_reads_what_decode_sii_reads_of_every_lola_image(chunk_words: int) -> None:
    """read_sii, fed 4 or 8 bytes a read as an ESC answers, gives the header, strings and
    general category decode_sii finds in the whole image, having read only the master's
    header words and the categories up to STRINGS and GENERAL."""
    from lolacli.emulator.sii import sii_from_slave
    from lolacli.files import load_eni

    eni = load_eni(ROOT / "lolacli" / "eni_examples" / "lola.xml")
    for slave in eni.slaves:
        image = sii_from_slave(slave)
        whole = decode_sii(image)
        walk, asked = read_sii(SiiWords()), []
        try:
            address = next(walk)
            while True:
                asked.append(address)
                address = walk.send(image[2 * address : 2 * (address + chunk_words)])
        except StopIteration as done:
            info = done.value
        assert info.header == whole.header and info.name == slave.name
        assert (info.strings, info.general) == (whole.strings, whole.general)
        header = [a for a in asked if a < 0x40]
        assert header[0] == 0 and set(header) <= {
            w for first, n in MASTER_HEADER_WORDS for w in range(first, first + n)
        }


def test_esi_images_name_the_device(corpus) -> None:
    """Images built from the corpus ESIs carry the device's type as order and name."""
    from lolacli.emulator.sii import sii_from_esi_device
    from lolacli.files import load_esi

    checked = 0
    for path in sorted((corpus / "esi").glob("*.xml")):
        esi = load_esi(path)
        for device in esi.devices[:3]:
            info = decode_sii(sii_from_esi_device(device))
            assert info.header.vendor_id == device.identity.vendor_id
            assert info.header.product_code == device.identity.product_code
            assert info.name  # every emulated image names its device
            checked += 1
    assert checked > 0


def test_header_checksum_detects_a_changed_word() -> None:
    head = bytearray(HEADER_BYTES)
    head[0:2] = b"\x05\x0c"
    head[14] = crc8_sii(bytes(head[:14]))
    assert decode_sii_header(bytes(head)).checksum_ok
    head[8] ^= 1  # the station alias changes, the checksum does not
    assert not decode_sii_header(bytes(head)).checksum_ok


def test_string_index_zero_and_out_of_range_are_none() -> None:
    strings = ("a", "b")
    assert sii_string(strings, 0) is None
    assert sii_string(strings, 3) is None
    assert sii_string(strings, 2) == "b"


def test_truncated_categories_are_wire_errors() -> None:
    image = bytearray(HEADER_BYTES) + struct.pack("<HH", SiiCategory.STRINGS, 10) + b"\x01\x03ab"
    with pytest.raises(WireError, match="runs past the image end"):
        decode_sii(bytes(image))
    with pytest.raises(WireError):
        decode_sii_strings(b"\x02\x03abc\x05ab")
    with pytest.raises(WireError):
        decode_sii_general(b"\x01\x02")
    with pytest.raises(WireError):
        decode_sii_header(bytes(100))


def _encode_strings(strings: list[bytes]) -> bytes:
    return bytes([len(strings)]) + b"".join(bytes([len(s)]) + s for s in strings)


@given(st.lists(st.binary(max_size=255).map(lambda b: b.replace(b"\x00", b"x")), max_size=30))
def test_strings_round_trip(strings: list[bytes]) -> None:
    decoded = decode_sii_strings(_encode_strings(strings))
    assert decoded == tuple(s.decode("latin-1") for s in strings)


@given(st.integers(0, 0x3F))
def test_protocol_names_name_every_bit(flags: int) -> None:
    names = protocol_names(flags)
    assert len(names) == bin(flags).count("1")
    assert bool(flags & MailboxProtocol.COE) == ("CoE" in names)


def test_random_bytes_raise_only_wire_error() -> None:
    rng = random.Random(11)
    seeds = [bytes(HEADER_BYTES) + struct.pack("<HH", 10, 3) + b"\x01\x03abc\xff\xff"]
    for _ in range(3000):
        base = bytearray(rng.choice(seeds))
        n = rng.randrange(0, len(base) + 40)
        data = bytes(rng.randrange(256) for _ in range(n)) if rng.random() < 0.3 else base
        data = bytearray(data)
        for _ in range(rng.randrange(1, 6)):
            if data:
                data[rng.randrange(len(data))] = rng.randrange(256)
        data = data[: rng.randrange(0, len(data) + 1)] if rng.random() < 0.3 else data
        for decoder in (decode_sii, decode_sii_strings, decode_sii_general, decode_sii_header):
            try:
                decoder(bytes(data))
            except WireError:
                pass


# ------------------------------------------------- encoders: the emulator writes with them
_u8, _u16, _u32 = st.integers(0, 0xFF), st.integers(0, 0xFFFF), st.integers(0, 0xFFFFFFFF)


@given(
    st.builds(
        SiiHeader,
        station_alias=_u16,
        vendor_id=_u32,
        product_code=_u32,
        revision=_u32,
        serial=_u32,
        rx_mailbox_offset=_u16,
        rx_mailbox_bytes=_u16,
        tx_mailbox_offset=_u16,
        tx_mailbox_bytes=_u16,
        mailbox_protocols=_u16,
        size_bytes=st.integers(1, 0x10000).map(lambda k: 128 * k),
        version=_u16,
        checksum=st.just(0),
        checksum_ok=st.just(True),
        bootstrap_rx_mailbox_offset=_u16,
        bootstrap_rx_mailbox_bytes=_u16,
        bootstrap_tx_mailbox_offset=_u16,
        bootstrap_tx_mailbox_bytes=_u16,
    ),
    st.binary(max_size=14),
)
def test_header_round_trip(header: SiiHeader, config: bytes) -> None:
    image = encode_sii_header(header, config)
    assert len(image) == HEADER_BYTES
    back = decode_sii_header(image)
    assert back.checksum_ok
    assert back == SiiHeader(**{**_fields(header), "checksum": back.checksum})
    assert image[:8] == (config[:8] + bytes(8))[:8]  # PDI words as given, alias after


def _fields(obj: object) -> dict[str, object]:
    return {name: getattr(obj, name) for name in obj.__slots__}  # type: ignore[attr-defined]


@given(st.builds(SiiGeneral, _u8, _u8, _u8, _u8, _u8, _u8, _u8, _u8, _u16))
def test_general_round_trip(general: SiiGeneral) -> None:
    assert decode_sii_general(encode_sii_general(general)) == general


@given(
    st.lists(st.text(st.characters(min_codepoint=1, max_codepoint=255), max_size=255), max_size=40)
)
def test_strings_encode_round_trip(strings: list[str]) -> None:
    assert decode_sii_strings(encode_sii_strings(strings)) == tuple(strings)


@given(
    st.lists(
        st.builds(
            SiiSyncManager,
            st.builds(SyncManager, _u16, _u16, _u8, _u8, _u8, st.just(0)),
            _u8,
        ),
        max_size=8,
    )
)
def test_sync_managers_round_trip(sms: list[SiiSyncManager]) -> None:
    data = encode_sii_sync_managers(tuple(sms))
    assert len(data) == 8 * len(sms)
    assert decode_sii_sync_managers(data) == tuple(sms)
    assert decode_sii_sync_managers(data + b"\x01\x02\x03") == tuple(sms)  # part entry left out


_entries = st.lists(st.builds(SiiPdoEntry, _u16, _u8, _u8, _u8, _u8, _u16), max_size=6)


@given(st.lists(st.builds(SiiPdo, _u16, _u8, _entries.map(tuple), _u8, _u8, _u16), max_size=6))
def test_pdos_round_trip(pdos: list[SiiPdo]) -> None:
    data = encode_sii_pdos(pdos)
    assert decode_sii_pdos(data) == tuple(pdos)
    # a cut category keeps the whole entries there are, never raises
    for cut in range(0, len(data), 5):
        decode_sii_pdos(data[:cut])


def test_dc_assign_activate_sits_at_byte_14_of_an_operation_mode() -> None:
    data = encode_sii_dc(0x0730)
    assert len(data) == 24 and struct.unpack_from("<H", data, 14)[0] == 0x0730
    assert data[20:] == bytes(4)  # reserved
    assert decode_sii_dc_assign_activate(data + data) == (0x0730, 0x0730)


def test_lenient_category_walk_takes_what_is_there() -> None:
    image = bytes(HEADER_BYTES) + encode_sii_category(10, b"\x01\x03abc") + b"\x1e\x00\x10\x00ab"
    cats = sii_categories(image)
    assert cats[10] == b"\x01\x03abc\x00" and cats[30] == b"ab"
    with pytest.raises(WireError):
        decode_sii(image)
