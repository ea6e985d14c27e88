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

The other categories a slave states its process data with (FMMU 40, SYNCM 41, TXPDO 50,
RXPDO 51, DC 60) are coded here too, both ways: a master decodes them, the emulator encodes
the images its slaves answer with.

Pure: bytes in, values out (and back); a short or inconsistent image is a
:class:`WireError`.
"""

from __future__ import annotations

import struct
from collections.abc import Generator
from dataclasses import dataclass
from enum import IntEnum, IntFlag

from lolacli.errors import WireError
from lolacli.wire._codes import need
from lolacli.wire.registers import SyncManager

HEADER_WORDS = 0x40
HEADER_BYTES = 2 * HEADER_WORDS
CATEGORY_HEADER_BYTES = 4
CATEGORY_END = 0xFFFF
GENERAL_BYTES = 32  # ETG.2010 Table 8; older images may carry fewer
MAX_WORDS = 0x4000  # a category walk stops here (32 KiB: beyond any real SII)

_HEADER = struct.Struct("<64H")
_CATEGORY = struct.Struct("<HH")
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_SYNC_MANAGER = struct.Struct("<HHBBBB")  # ETG.2010 Table 12
_PDO = struct.Struct("<HBBBBH")  # ETG.2010 Table 14: the PDO, then each entry
_PDO_ENTRY = struct.Struct("<HBBBBH")
SII_SYNC_MANAGER_BYTES = _SYNC_MANAGER.size
_DC = struct.Struct("<IiihHhBB4x")  # ETG.2010 Table 16: one DC operation mode
DC_BYTES = _DC.size
#: the SM of a PDO that no sync manager takes by default (ETG.2010 Table 14)
PDO_NOT_ASSIGNED = 0xFF


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


class SmType(IntEnum):
    """What a SYNCM category entry is for (ETG.2010 Table 12, "type")."""

    UNUSED = 0
    MAILBOX_OUT = 1
    MAILBOX_IN = 2
    OUTPUTS = 3
    INPUTS = 4


class FmmuUsage(IntEnum):
    """What an FMMU category byte says the FMMU is for (ETG.2010 Table 10)."""

    UNUSED = 0
    OUTPUTS = 1
    INPUTS = 2
    SYNCM_STATUS = 3


class CoeDetails(IntFlag):
    """GENERAL category CoE details (ETG.2010 Table 8)."""

    SDO = 0x01
    SDO_INFO = 0x02
    PDO_ASSIGN = 0x04
    PDO_CONFIG = 0x08
    UPLOAD_AT_STARTUP = 0x10
    SDO_COMPLETE_ACCESS = 0x20


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
    bootstrap_rx_mailbox_offset: int = 0
    bootstrap_rx_mailbox_bytes: int = 0
    bootstrap_tx_mailbox_offset: int = 0
    bootstrap_tx_mailbox_bytes: int = 0


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
        bootstrap_rx_mailbox_offset=w[SiiWord.BOOTSTRAP_RX_MAILBOX_OFFSET],
        bootstrap_rx_mailbox_bytes=w[SiiWord.BOOTSTRAP_RX_MAILBOX_SIZE],
        bootstrap_tx_mailbox_offset=w[SiiWord.BOOTSTRAP_TX_MAILBOX_OFFSET],
        bootstrap_tx_mailbox_bytes=w[SiiWord.BOOTSTRAP_TX_MAILBOX_SIZE],
    )


def encode_sii_header(header: SiiHeader, config: bytes = b"") -> bytes:
    """The 64-word header of ``header``: ``config`` gives words 0-6 (PDI control and
    configuration, as an ESI's ``<ConfigData>``), the station alias of ``header`` then
    overwrites word 4; the checksum is computed (``header.checksum`` is not used)."""
    head = bytearray(HEADER_BYTES)
    head[: min(len(config), 14)] = config[:14]
    _U16.pack_into(head, 2 * SiiWord.STATION_ALIAS, header.station_alias & 0xFFFF)
    for word, value in (
        (SiiWord.VENDOR_ID, header.vendor_id),
        (SiiWord.PRODUCT_CODE, header.product_code),
        (SiiWord.REVISION, header.revision),
        (SiiWord.SERIAL, header.serial),
    ):
        _U32.pack_into(head, 2 * word, value & 0xFFFFFFFF)
    for word, value in (
        (SiiWord.BOOTSTRAP_RX_MAILBOX_OFFSET, header.bootstrap_rx_mailbox_offset),
        (SiiWord.BOOTSTRAP_RX_MAILBOX_SIZE, header.bootstrap_rx_mailbox_bytes),
        (SiiWord.BOOTSTRAP_TX_MAILBOX_OFFSET, header.bootstrap_tx_mailbox_offset),
        (SiiWord.BOOTSTRAP_TX_MAILBOX_SIZE, header.bootstrap_tx_mailbox_bytes),
        (SiiWord.RX_MAILBOX_OFFSET, header.rx_mailbox_offset),
        (SiiWord.RX_MAILBOX_SIZE, header.rx_mailbox_bytes),
        (SiiWord.TX_MAILBOX_OFFSET, header.tx_mailbox_offset),
        (SiiWord.TX_MAILBOX_SIZE, header.tx_mailbox_bytes),
        (SiiWord.MAILBOX_PROTOCOL, header.mailbox_protocols),
        (SiiWord.SIZE, max(header.size_bytes // 128 - 1, 0)),
        (SiiWord.VERSION, header.version),
    ):
        _U16.pack_into(head, 2 * word, value & 0xFFFF)
    _U16.pack_into(head, 2 * SiiWord.CHECKSUM, crc8_sii(bytes(head[:14])))
    return bytes(head)


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


def encode_sii_general(general: SiiGeneral) -> bytes:
    """The GENERAL category's 32 data bytes (fields :class:`SiiGeneral` does not hold are 0)."""
    out = bytearray(GENERAL_BYTES)
    out[0:4] = bytes(
        (general.group_index, general.image_index, general.order_index, general.name_index)
    )
    out[5], out[6], out[7] = general.coe_details, general.foe_details, general.eoe_details
    out[9] = general.ds402_channels
    _U16.pack_into(out, 16, general.physical_ports & 0xFFFF)
    return bytes(out)


def encode_sii_strings(strings: tuple[str, ...] | list[str]) -> bytes:
    """The STRINGS category's data: a count byte, then each string with its length byte
    (Latin-1, at most 255 bytes each; up to 255 strings)."""
    out = bytearray([len(strings[:255])])
    for text in strings[:255]:
        raw = text.encode("latin-1", "replace")[:255]
        out += bytes([len(raw)]) + raw
    return bytes(out)


def encode_sii_category(kind: int, data: bytes) -> bytes:
    """A category: type, length in words, data (a 0 byte pads odd data to a word)."""
    if len(data) % 2:
        data += b"\x00"
    return _CATEGORY.pack(kind, len(data) // 2) + data


def sii_categories(image: bytes | memoryview) -> dict[int, bytes]:
    """Category type -> data of its first occurrence, from word 0x40 to 0xFFFF or the
    image's end; lenient, as a slave reading its own EEPROM: a category running past the
    end gets the bytes there are (:func:`decode_sii` is the strict walk)."""
    out: dict[int, bytes] = {}
    pos = HEADER_BYTES
    while pos + CATEGORY_HEADER_BYTES <= len(image):
        kind, words = _CATEGORY.unpack_from(image, pos)
        if kind == CATEGORY_END:
            break
        start = pos + CATEGORY_HEADER_BYTES
        out.setdefault(kind, bytes(image[start : start + 2 * words]))
        pos = start + 2 * words
    return out


def encode_sii_fmmus(usages: tuple[int, ...]) -> bytes:
    """The FMMU category's data: a :class:`FmmuUsage` byte per FMMU, 0xFF pads to a word."""
    return bytes(usages) + (b"\xff" if len(usages) % 2 else b"")


@dataclass(frozen=True, slots=True)
class SiiSyncManager:
    """A SYNCM category entry (ETG.2010 Table 12): the sync manager's register content as
    the slave proposes it (``activate`` holds the entry's enable byte: bit 0 enable, then
    fixed content, virtual, OP only) and what it is for."""

    sync_manager: SyncManager
    type: int = SmType.UNUSED


def encode_sii_sync_managers(sync_managers: tuple[SiiSyncManager, ...]) -> bytes:
    """The SYNCM category's data, 8 bytes per sync manager."""
    return b"".join(
        _SYNC_MANAGER.pack(
            s.sync_manager.physical_start & 0xFFFF,
            s.sync_manager.length_bytes & 0xFFFF,
            s.sync_manager.control & 0xFF,
            s.sync_manager.status & 0xFF,
            s.sync_manager.activate & 0xFF,
            s.type & 0xFF,
        )
        for s in sync_managers
    )


def decode_sii_sync_managers(data: bytes | memoryview) -> tuple[SiiSyncManager, ...]:
    """The SYNCM category's entries (a trailing part entry is left out)."""
    out = []
    for pos in range(0, len(data) - SII_SYNC_MANAGER_BYTES + 1, SII_SYNC_MANAGER_BYTES):
        start, length, control, status, enable, kind = _SYNC_MANAGER.unpack_from(data, pos)
        out.append(SiiSyncManager(SyncManager(start, length, control, status, enable), kind))
    return tuple(out)


@dataclass(frozen=True, slots=True)
class SiiPdoEntry:
    """A PDO entry in a TXPDO/RXPDO category (ETG.2010 Table 15)."""

    index: int
    subindex: int
    bit_length: int
    data_type: int = 0  # CoE data type code (ETG.1000.6 Table 64)
    name_index: int = 0
    flags: int = 0


@dataclass(frozen=True, slots=True)
class SiiPdo:
    """A PDO in a TXPDO (inputs) or RXPDO (outputs) category (ETG.2010 Table 14);
    ``sync_manager`` :data:`PDO_NOT_ASSIGNED` (0xFF): no SM takes it by default."""

    index: int
    sync_manager: int
    entries: tuple[SiiPdoEntry, ...] = ()
    synchronization: int = 0
    name_index: int = 0
    flags: int = 0  # bit 0 mandatory, bit 4 fixed content

    @property
    def bit_length(self) -> int:
        return sum(e.bit_length for e in self.entries)


def encode_sii_pdos(pdos: tuple[SiiPdo, ...] | list[SiiPdo]) -> bytes:
    """A TXPDO or RXPDO category's data: each PDO, then its entries, 8 bytes each."""
    out = bytearray()
    for p in pdos:
        out += _PDO.pack(
            p.index, len(p.entries), p.sync_manager, p.synchronization, p.name_index, p.flags
        )
        for e in p.entries:
            out += _PDO_ENTRY.pack(
                e.index, e.subindex, e.name_index, e.data_type, e.bit_length, e.flags
            )
    return bytes(out)


def decode_sii_pdos(data: bytes | memoryview) -> tuple[SiiPdo, ...]:
    """A TXPDO or RXPDO category's PDOs; a PDO cut short keeps the entries there are."""
    out: list[SiiPdo] = []
    pos = 0
    while pos + _PDO.size <= len(data):
        index, count, sm, sync, name, flags = _PDO.unpack_from(data, pos)
        pos += _PDO.size
        entries = []
        for _ in range(count):
            if pos + _PDO_ENTRY.size > len(data):
                break
            e_index, sub, e_name, dtype, bits, e_flags = _PDO_ENTRY.unpack_from(data, pos)
            entries.append(SiiPdoEntry(e_index, sub, bits, dtype, e_name, e_flags))
            pos += _PDO_ENTRY.size
        out.append(SiiPdo(index, sm, tuple(entries), sync, name, flags))
    return tuple(out)


def encode_sii_dc(assign_activate: int) -> bytes:
    """A DC category with one operation mode (ETG.2010 Table 16: SYNC0 cycle time, SYNC0
    and SYNC1 shift, SYNC1 cycle factor, assign-activate, SYNC0 cycle factor, name and
    description string indices, 4 reserved bytes) whose times the master sets (0)."""
    return _DC.pack(0, 0, 0, 0, assign_activate & 0xFFFF, 0, 0, 0)


def decode_sii_dc_assign_activate(data: bytes | memoryview) -> tuple[int, ...]:
    """The assign-activate word of each operation mode in a DC category."""
    return tuple(
        _DC.unpack_from(data, pos)[4] for pos in range(0, len(data) - DC_BYTES + 1, DC_BYTES)
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
#: with the station alias and the identity, the bootstrap and standard mailboxes and the
#: protocols, the EEPROM size and version: every field of :class:`SiiHeader`.
MASTER_HEADER_WORDS = (
    (SiiWord.PDI_CONTROL, 16),
    (SiiWord.BOOTSTRAP_RX_MAILBOX_OFFSET, 9),
    (SiiWord.SIZE, 2),
)


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
    "DC_BYTES",
    "PDO_NOT_ASSIGNED",
    "SII_SYNC_MANAGER_BYTES",
    "CoeDetails",
    "FmmuUsage",
    "SiiPdo",
    "SiiPdoEntry",
    "SiiSyncManager",
    "SmType",
    "decode_sii_dc_assign_activate",
    "decode_sii_pdos",
    "decode_sii_sync_managers",
    "encode_sii_category",
    "encode_sii_dc",
    "encode_sii_fmmus",
    "encode_sii_general",
    "encode_sii_header",
    "encode_sii_pdos",
    "encode_sii_strings",
    "encode_sii_sync_managers",
    "sii_categories",
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
