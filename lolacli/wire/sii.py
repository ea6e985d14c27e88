"""SII EEPROM contents as a master reads them (ETG.1000.6 §5.4 Tables 16-19, ETG.2010).

The first 64 words are a fixed header (word addresses)::

    0x00 PDI control   0x01 PDI configuration   0x02 SYNC impulse length  0x03 PDI config 2
    0x04 configured station alias                0x07 checksum (CRC-8 of words 0..6, low byte)
    0x08 vendor id (2 words)  0x0A product code  0x0C revision  0x0E serial number
    0x14/0x15 bootstrap receive mailbox offset/size   0x16/0x17 bootstrap send mailbox
    0x18/0x19 standard receive mailbox (master -> slave)  0x1A/0x1B standard send mailbox
    0x1C mailbox protocols   0x3E EEPROM size (KiBit - 1)   0x3F version

From word 0x40 on come categories: type (word), length in words (word), data; type
0xFFFF ends the list. A master needs two of them to name a slave: STRINGS (10: a count
byte, then length-prefixed strings, referred to by 1-based index) and GENERAL (30: the
indices of the group, image, order and name strings, CoE/FoE/EoE details, ports).

Pure: bytes in, values out; a short or inconsistent image is a :class:`WireError`.
"""

from __future__ import annotations

import struct
from collections.abc import Generator
from dataclasses import dataclass
from enum import IntEnum, IntFlag

from lolacli.errors import WireError
from lolacli.wire._codes import need

HEADER_WORDS = 0x40
HEADER_BYTES = 2 * HEADER_WORDS
CATEGORY_HEADER_BYTES = 4
CATEGORY_END = 0xFFFF
GENERAL_BYTES = 32  # ETG.2010 Table 8; older images may carry fewer
MAX_WORDS = 0x4000  # a category walk stops here (32 KiB: beyond any real SII)

_HEADER = struct.Struct("<64H")
_CATEGORY = struct.Struct("<HH")


class SiiWord(IntEnum):
    """Word addresses of the SII header (ETG.1000.6 Table 16)."""

    PDI_CONTROL = 0x00
    PDI_CONFIGURATION = 0x01
    SYNC_IMPULSE_LENGTH = 0x02
    PDI_CONFIGURATION_2 = 0x03
    STATION_ALIAS = 0x04
    CHECKSUM = 0x07
    VENDOR_ID = 0x08
    PRODUCT_CODE = 0x0A
    REVISION = 0x0C
    SERIAL = 0x0E
    BOOTSTRAP_RX_MAILBOX_OFFSET = 0x14
    BOOTSTRAP_RX_MAILBOX_SIZE = 0x15
    BOOTSTRAP_TX_MAILBOX_OFFSET = 0x16
    BOOTSTRAP_TX_MAILBOX_SIZE = 0x17
    RX_MAILBOX_OFFSET = 0x18
    RX_MAILBOX_SIZE = 0x19
    TX_MAILBOX_OFFSET = 0x1A
    TX_MAILBOX_SIZE = 0x1B
    MAILBOX_PROTOCOL = 0x1C
    SIZE = 0x3E
    VERSION = 0x3F
    FIRST_CATEGORY = 0x40


class SiiCategory(IntEnum):
    """Category types (ETG.1000.6 Table 19)."""

    NOP = 0
    STRINGS = 10
    DATA_TYPES = 20
    GENERAL = 30
    FMMU = 40
    SYNCM = 41
    TXPDO = 50
    RXPDO = 51
    DC = 60
    END = CATEGORY_END


class MailboxProtocol(IntFlag):
    """Mailbox protocols, SII word 0x1C (ETG.1000.6 Table 18)."""

    AOE = 0x01
    EOE = 0x02
    COE = 0x04
    FOE = 0x08
    SOE = 0x10
    VOE = 0x20


#: the ENI's spelling of each protocol (``<Mailbox><Protocol>``)
PROTOCOL_NAMES: tuple[tuple[MailboxProtocol, str], ...] = (
    (MailboxProtocol.AOE, "AoE"),
    (MailboxProtocol.EOE, "EoE"),
    (MailboxProtocol.COE, "CoE"),
    (MailboxProtocol.FOE, "FoE"),
    (MailboxProtocol.SOE, "SoE"),
    (MailboxProtocol.VOE, "VoE"),
)


def protocol_names(flags: int) -> tuple[str, ...]:
    """``("CoE", "FoE")`` for the bits of word 0x1C (unknown bits are left out)."""
    return tuple(name for bit, name in PROTOCOL_NAMES if flags & bit)


@dataclass(frozen=True, slots=True)
class SiiHeader:
    """The identity and mailbox words of the SII header (ETG.1000.6 Table 16)."""

    station_alias: int
    vendor_id: int
    product_code: int
    revision: int
    serial: int
    rx_mailbox_offset: int
    rx_mailbox_bytes: int
    tx_mailbox_offset: int
    tx_mailbox_bytes: int
    mailbox_protocols: int
    size_bytes: int  # word 0x3E is the size in KiBit - 1
    version: int
    checksum: int
    checksum_ok: bool


def decode_sii_header(buf: bytes | memoryview, offset: int = 0) -> SiiHeader:
    """The 64-word header at ``offset``."""
    need(buf, offset, HEADER_BYTES, "SII header")
    w = _HEADER.unpack_from(buf, offset)
    first = bytes(buf[offset : offset + 14])
    return SiiHeader(
        station_alias=w[SiiWord.STATION_ALIAS],
        vendor_id=w[8] | w[9] << 16,
        product_code=w[10] | w[11] << 16,
        revision=w[12] | w[13] << 16,
        serial=w[14] | w[15] << 16,
        rx_mailbox_offset=w[SiiWord.RX_MAILBOX_OFFSET],
        rx_mailbox_bytes=w[SiiWord.RX_MAILBOX_SIZE],
        tx_mailbox_offset=w[SiiWord.TX_MAILBOX_OFFSET],
        tx_mailbox_bytes=w[SiiWord.TX_MAILBOX_SIZE],
        mailbox_protocols=w[SiiWord.MAILBOX_PROTOCOL],
        size_bytes=(w[SiiWord.SIZE] + 1) * 128,
        version=w[SiiWord.VERSION],
        checksum=w[SiiWord.CHECKSUM] & 0xFF,
        checksum_ok=crc8_sii(first) == w[SiiWord.CHECKSUM] & 0xFF,
    )


def crc8_sii(data: bytes) -> int:
    """CRC-8 of the header's first 14 bytes (ETG.1000.6 §5.4: x^8+x^2+x+1, initial 0xFF)."""
    crc = 0xFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x07) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc


def decode_category_header(buf: bytes | memoryview, offset: int = 0) -> tuple[int, int]:
    """(type, length in words) of the category header at ``offset``."""
    need(buf, offset, CATEGORY_HEADER_BYTES, "SII category header")
    kind, words = _CATEGORY.unpack_from(buf, offset)
    return int(kind), int(words)


def decode_sii_strings(data: bytes | memoryview) -> tuple[str, ...]:
    """The STRINGS category: a count byte, then that many length-prefixed strings.
    Trailing NULs are dropped; bytes outside ASCII are read as Latin-1."""
    need(data, 0, 1, "SII strings")
    count = data[0]
    out: list[str] = []
    pos = 1
    for i in range(count):
        need(data, pos, 1, f"SII string {i + 1} of {count}")
        n = data[pos]
        need(data, pos + 1, n, f"SII string {i + 1} of {count}")
        out.append(bytes(data[pos + 1 : pos + 1 + n]).decode("latin-1").rstrip("\x00"))
        pos += 1 + n
    return tuple(out)


@dataclass(frozen=True, slots=True)
class SiiGeneral:
    """The GENERAL category (ETG.2010 Table 8): string indices (1-based, 0 = none) and
    what the device supports."""

    group_index: int
    image_index: int
    order_index: int
    name_index: int
    coe_details: int = 0
    foe_details: int = 0
    eoe_details: int = 0
    ds402_channels: int = 0
    physical_ports: int = 0  # 4 bits per port: 0 none, 1 MII, 2 reserved, 3 EBUS


def decode_sii_general(data: bytes | memoryview) -> SiiGeneral:
    """The GENERAL category's data (at least the four string indices)."""
    need(data, 0, 4, "SII general category")
    raw = bytes(data[:GENERAL_BYTES]).ljust(GENERAL_BYTES, b"\x00")
    return SiiGeneral(
        group_index=raw[0],
        image_index=raw[1],
        order_index=raw[2],
        name_index=raw[3],
        coe_details=raw[5],
        foe_details=raw[6],
        eoe_details=raw[7],
        ds402_channels=raw[9],
        physical_ports=raw[16] | raw[17] << 8,
    )


def sii_string(strings: tuple[str, ...], index: int) -> str | None:
    """String ``index`` (1-based; 0 or out of range: ``None``)."""
    return strings[index - 1] if 1 <= index <= len(strings) else None


@dataclass(frozen=True, slots=True)
class SiiInfo:
    """What a master learns from an SII image: header, strings, general category, and
    the names they give (``None`` where the image has no such string)."""

    header: SiiHeader
    strings: tuple[str, ...] = ()
    general: SiiGeneral | None = None
    categories: tuple[tuple[int, int, int], ...] = ()  # (type, word address, words)

    @property
    def name(self) -> str | None:
        g = self.general
        return sii_string(self.strings, g.name_index) if g is not None else None

    @property
    def order(self) -> str | None:
        g = self.general
        return sii_string(self.strings, g.order_index) if g is not None else None

    @property
    def group(self) -> str | None:
        g = self.general
        return sii_string(self.strings, g.group_index) if g is not None else None


def decode_sii(image: bytes | memoryview) -> SiiInfo:
    """Header and category list of a whole (or leading part of an) SII image; the walk
    stops at 0xFFFF or where the image ends."""
    header = decode_sii_header(image)
    strings: tuple[str, ...] = ()
    general: SiiGeneral | None = None
    cats: list[tuple[int, int, int]] = []
    pos = HEADER_BYTES
    while pos + CATEGORY_HEADER_BYTES <= len(image):
        kind, words = decode_category_header(image, pos)
        if kind == CATEGORY_END:
            break
        start = pos + CATEGORY_HEADER_BYTES
        data = image[start : start + 2 * words]
        if len(data) < 2 * words:
            raise WireError(
                f"SII category {kind} at word 0x{pos // 2:X} runs past the image end",
                offset=pos,
            )
        cats.append((kind, pos // 2, words))
        if kind == SiiCategory.STRINGS and not strings:
            strings = decode_sii_strings(data)
        elif kind == SiiCategory.GENERAL and general is None:
            general = decode_sii_general(data)
        pos = start + 2 * words
    return SiiInfo(header, strings, general, tuple(cats))


class SiiWords:
    """The SII words of one slave read so far (word address -> 2 bytes), for a reader
    that asks for words one at a time: :meth:`read` is a generator that yields each
    missing word address and is sent the bytes read there (one or more words)."""

    def __init__(self) -> None:
        self.words: dict[int, bytes] = {}

    def take(self, address: int, data: bytes) -> None:
        for i in range(len(data) // 2):
            self.words[address + i] = data[2 * i : 2 * i + 2]

    def read(self, address: int, count: int) -> Generator[int, bytes, bytes]:
        """The bytes of ``count`` words from ``address``, asking for those missing."""
        for a in range(address, address + count):
            while a not in self.words:
                self.take(a, (yield a))
        return b"".join(self.words[a] for a in range(address, address + count))


#: The header words a master reads of a slave, (first word, count): the checksummed area
#: with the station alias and the identity, the standard mailbox with its protocols, the
#: EEPROM size and version: every field of :class:`SiiHeader`.
MASTER_HEADER_WORDS = ((SiiWord.PDI_CONTROL, 16), (SiiWord.RX_MAILBOX_OFFSET, 5), (SiiWord.SIZE, 2))


def read_sii_header(words: SiiWords) -> Generator[int, bytes, SiiHeader]:
    """The header fields a master needs (:data:`MASTER_HEADER_WORDS`), read word by word
    through ``words`` (words it does not read count as zero)."""
    for address, count in MASTER_HEADER_WORDS:
        yield from words.read(address, count)
    head = b"".join(words.words.get(a, b"\x00\x00") for a in range(HEADER_WORDS))
    return decode_sii_header(head)


SiiNames = tuple[tuple[str, ...], "SiiGeneral | None", tuple[tuple[int, int, int], ...]]


def read_sii_names(words: SiiWords) -> Generator[int, bytes, SiiNames]:
    """(strings, general, categories so far): the categories from word 0x40 up to STRINGS
    and GENERAL (or the end), read word by word through ``words``."""
    strings: tuple[str, ...] = ()
    general: SiiGeneral | None = None
    cats: list[tuple[int, int, int]] = []
    address = HEADER_WORDS
    while address < MAX_WORDS:
        kind, length = decode_category_header((yield from words.read(address, 2)))
        if kind == CATEGORY_END or length == 0xFFFF:
            break
        cats.append((kind, address, length))
        if kind == SiiCategory.STRINGS and not strings:
            strings = decode_sii_strings((yield from words.read(address + 2, length)))
        elif kind == SiiCategory.GENERAL and general is None:
            data = yield from words.read(address + 2, min(length, GENERAL_BYTES // 2))
            general = decode_sii_general(data)
        if strings and general is not None:
            break
        address += 2 + length
    return strings, general, tuple(cats)


def read_sii(words: SiiWords) -> Generator[int, bytes, SiiInfo]:
    """What a master reads of a slave's SII (header fields, STRINGS, GENERAL), word by word:
    yields each word address it needs and is sent the bytes read there (4 or 8)."""
    header = yield from read_sii_header(words)
    strings, general, cats = yield from read_sii_names(words)
    return SiiInfo(header, strings, general, cats)


__all__ = [
    "MASTER_HEADER_WORDS",
    "MAX_WORDS",
    "SiiWords",
    "CATEGORY_END",
    "HEADER_BYTES",
    "HEADER_WORDS",
    "MailboxProtocol",
    "SiiCategory",
    "SiiGeneral",
    "SiiHeader",
    "SiiInfo",
    "SiiNames",
    "SiiWord",
    "crc8_sii",
    "decode_category_header",
    "decode_sii",
    "decode_sii_general",
    "decode_sii_header",
    "decode_sii_strings",
    "protocol_names",
    "read_sii",
    "read_sii_header",
    "read_sii_names",
    "sii_string",
]
