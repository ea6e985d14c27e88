"""Streaming readers for classic pcap and pcapng captures.

Classic pcap (libpcap file format, draft-ietf-opsawg-pcap): a 24-byte file header whose
magic 0xA1B2C3D4 (microseconds) or 0xA1B23C4D (nanoseconds) also gives the byte order,
then records of ``ts_sec(4) ts_frac(4) incl_len(4) orig_len(4) data``.

pcapng (draft-ietf-opsawg-pcapng): blocks of ``type(4) total_length(4) body total_length(4)``.
A Section Header Block (type 0x0A0D0D0A, byte-order magic 0x1A2B3C4D) starts each section
and resets its interfaces; an Interface Description Block (type 1) declares one interface
(link type, snaplen, options such as ``if_tsresol`` (9) and ``if_tsoffset`` (14)); packets
come in Enhanced (6), Simple (3) or obsolete Packet (2) blocks. Unknown blocks are skipped.

Link types analysed: 1 (Ethernet), 113 (Linux cooked, SLL) and 276 (Linux cooked v2, SLL2),
which ``tcpdump -i any`` and ``dumpcap -i any`` write; their packet type tells a frame
this host sent from one it received. Files are read in bounded chunks: nothing here
holds the whole file in memory. Damaged records are counted, not fatal; a file that is
not a capture at all raises :class:`~lolacli.errors.CaptureError`.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

from lolacli.errors import CaptureError

LINKTYPE_ETHERNET = 1
LINKTYPE_LINUX_SLL = 113
LINKTYPE_LINUX_SLL2 = 276
ANALYSED_LINK_TYPES = (LINKTYPE_ETHERNET, LINKTYPE_LINUX_SLL, LINKTYPE_LINUX_SLL2)

PCAP_MAGIC_US = 0xA1B2C3D4
PCAP_MAGIC_NS = 0xA1B23C4D
PCAPNG_SHB = 0x0A0D0D0A
PCAPNG_BYTE_ORDER_MAGIC = 0x1A2B3C4D
BLOCK_IDB = 1
BLOCK_OPB = 2
BLOCK_SPB = 3
BLOCK_EPB = 6
OPT_END = 0
OPT_IF_NAME = 2
OPT_IF_DESCRIPTION = 3
OPT_IF_TSRESOL = 9
OPT_IF_OS = 12
OPT_IF_TSOFFSET = 14

PCAP_HEADER_BYTES = 24
PCAP_RECORD_BYTES = 16
#: Upper bound on one record or block; larger values mean a corrupt file.
MAX_RECORD_BYTES = 16 * 1024 * 1024
DEFAULT_CHUNK_BYTES = 4 * 1024 * 1024

FORMAT_PCAP = 0
FORMAT_PCAPNG = 1


@dataclass(frozen=True, slots=True)
class Interface:
    """One capture interface and how its timestamps convert to nanoseconds.

    ``tsresol`` is the raw ``if_tsresol`` byte: bit 7 clear means 10^-n seconds, set
    means 2^-n seconds (default 6, microseconds). ``tsoffset_s`` is ``if_tsoffset``.
    """

    link_type: int
    snaplen: int = 0
    tsresol: int = 6
    tsoffset_s: int = 0
    name: str = ""  # if_name, if_description, if_os (the capturing host)
    description: str = ""
    os: str = ""

    @property
    def analysed(self) -> bool:
        """Ethernet or Linux cooked (SLL/SLL2)."""
        return self.link_type in ANALYSED_LINK_TYPES

    def ts_params(self) -> tuple[int, int, int, int]:
        """``(mode, a, b, offset_ns)`` for :func:`ts_to_ns`."""
        return ts_params(self.tsresol, self.tsoffset_s)


def ts_params(tsresol: int, tsoffset_s: int = 0) -> tuple[int, int, int, int]:
    """Integer parameters turning raw timestamp units into nanoseconds.

    mode 0: ``ns = units * a // b`` (decimal resolutions); mode 1: binary resolution
    2^-a seconds.
    """
    n = tsresol & 0x7F
    offset_ns = tsoffset_s * 1_000_000_000
    if tsresol & 0x80:
        return 1, n, 0, offset_ns
    if n <= 9:
        return 0, 10 ** (9 - n), 1, offset_ns
    if n - 9 >= 19:
        # exact for units below 10^19 (the scanner converts only units below 2^63),
        # and the divisor stays in int64 (the scanner's parameter array)
        return 0, 0, 1, offset_ns
    return 0, 1, 10 ** (n - 9), offset_ns


def ts_to_ns(units: int, mode: int, a: int, b: int, offset_ns: int) -> int:
    """Nanoseconds from raw pcapng timestamp units (see :func:`ts_params`)."""
    if mode == 0:
        return units * a // b + offset_ns
    seconds = units >> a
    frac = units & ((1 << a) - 1)
    if a > 30:
        frac >>= a - 30
        return seconds * 1_000_000_000 + ((frac * 1_000_000_000) >> 30) + offset_ns
    return seconds * 1_000_000_000 + ((frac * 1_000_000_000) >> a) + offset_ns


@dataclass(frozen=True, slots=True)
class CapturedFrame:
    """One captured link-layer frame.

    ``number`` is 1-based over all packets of the file, like Wireshark's frame number.
    ``original_length`` is the length on the wire; ``data`` may be shorter (snaplen).
    """

    number: int
    timestamp_ns: int
    data: bytes
    original_length: int
    interface: int = 0
    link_type: int = LINKTYPE_ETHERNET


@dataclass(frozen=True, slots=True)
class FileHeader:
    """What the first bytes of a capture say: format, byte order, classic-pcap details."""

    format: int
    big_endian: bool
    nanoseconds: bool = False
    link_type: int = LINKTYPE_ETHERNET
    snaplen: int = 0


def read_file_header(path: str | Path, head: bytes) -> FileHeader:
    """Identify a capture from its first bytes; :class:`CaptureError` when it is none."""
    name = str(path)
    if len(head) == 0:
        raise CaptureError("empty file, not a pcap/pcapng capture", path=name, offset=0)
    if len(head) < 4:
        raise CaptureError("file too short for a capture header", path=name, offset=0)
    magic_le = struct.unpack_from("<I", head)[0]
    magic_be = struct.unpack_from(">I", head)[0]
    if magic_le == PCAPNG_SHB:
        return _pcapng_header(name, head)
    for big, magic in ((False, magic_le), (True, magic_be)):
        if magic in (PCAP_MAGIC_US, PCAP_MAGIC_NS):
            return _pcap_header(name, head, big, magic == PCAP_MAGIC_NS)
    raise CaptureError(
        f"not a pcap/pcapng capture (magic 0x{magic_be:08X})", path=name, offset=0
    )


def _pcap_header(name: str, head: bytes, big: bool, ns: bool) -> FileHeader:
    if len(head) < PCAP_HEADER_BYTES:
        raise CaptureError("truncated pcap file header", path=name, offset=len(head))
    order = ">" if big else "<"
    _, _major, _minor, _zone, _sigfigs, snaplen, network = struct.unpack_from(
        order + "IHHiIII", head
    )
    link_type = network & 0x0FFFFFFF
    if link_type not in ANALYSED_LINK_TYPES:
        raise CaptureError(
            f"link type {link_type} is neither Ethernet (1) nor Linux cooked (113, 276); "
            "only those captures are analysed",
            path=name,
            offset=20,
        )
    return FileHeader(FORMAT_PCAP, big, ns, link_type, snaplen)


def _pcapng_header(name: str, head: bytes) -> FileHeader:
    if len(head) < 12:
        raise CaptureError("truncated pcapng section header", path=name, offset=len(head))
    bom = struct.unpack_from("<I", head, 8)[0]
    if bom == PCAPNG_BYTE_ORDER_MAGIC:
        return FileHeader(FORMAT_PCAPNG, False)
    if bom == 0x4D3C2B1A:
        return FileHeader(FORMAT_PCAPNG, True)
    raise CaptureError("pcapng section header with a bad byte-order magic", path=name, offset=8)


def parse_shb(block: bytes | memoryview) -> bool:
    """Byte order of a Section Header Block: True for big endian."""
    bom = struct.unpack_from("<I", block, 8)[0]
    if bom == PCAPNG_BYTE_ORDER_MAGIC:
        return False
    if bom == 0x4D3C2B1A:
        return True
    raise ValueError("bad byte-order magic")


def parse_idb(block: bytes | memoryview, big: bool) -> Interface:
    """An Interface Description Block (whole block incl. type and lengths).

    Raises ValueError for a block too short to hold the IDB body (20 bytes)."""
    if len(block) < 20:
        raise ValueError("interface description block shorter than 20 bytes")
    order = ">" if big else "<"
    total = struct.unpack_from(order + "I", block, 4)[0]
    link_type, _reserved, snaplen = struct.unpack_from(order + "HHI", block, 8)
    tsresol = 6
    tsoffset = 0
    texts = {OPT_IF_NAME: "", OPT_IF_DESCRIPTION: "", OPT_IF_OS: ""}
    pos, end = 16, total - 4
    while pos + 4 <= end:
        code, length = struct.unpack_from(order + "HH", block, pos)
        value = bytes(block[pos + 4 : pos + 4 + length])
        if code == OPT_END:
            break
        if code == OPT_IF_TSRESOL and length >= 1:
            tsresol = value[0]
        elif code == OPT_IF_TSOFFSET and length >= 8:
            tsoffset = struct.unpack_from(order + "q", value)[0]
        elif code in texts:
            texts[code] = value.decode("utf-8", "replace")
        pos += 4 + length + (-length % 4)
    return Interface(link_type, snaplen, tsresol, tsoffset, texts[OPT_IF_NAME],
                     texts[OPT_IF_DESCRIPTION], texts[OPT_IF_OS])


@dataclass(slots=True)
class ReadStats:
    """Counters of what a reader had to skip."""

    packets: int = 0
    malformed_records: int = 0
    non_ethernet_packets: int = 0
    skipped_blocks: int = 0
    sections: int = 0
    interfaces: list[Interface] = field(default_factory=list)
    stopped_at: int | None = None  # offset where a corrupt record ended reading


class ChunkedFile:
    """A file read forward in bounded chunks with a small look-ahead window."""

    def __init__(self, stream: BinaryIO, chunk_bytes: int = DEFAULT_CHUNK_BYTES) -> None:
        self._stream = stream
        self._chunk = chunk_bytes
        self._buf = b""
        self._pos = 0  # position of _buf[0] in the file
        self._eof = False

    def window(self, offset: int, need: int) -> bytes | None:
        """``need`` bytes at file ``offset`` or None at end of file."""
        start = offset - self._pos
        while start + need > len(self._buf) and not self._eof:
            more = self._stream.read(max(self._chunk, need))
            if not more:
                self._eof = True
                break
            drop = min(start, len(self._buf))
            self._buf = self._buf[drop:] + more
            self._pos += drop
            start -= drop
        if start + need > len(self._buf):
            return None
        return self._buf[start : start + need]

    def at_end(self, offset: int) -> bool:
        return self.window(offset, 1) is None


class CaptureReader:
    """Iterate the frames of a pcap or pcapng file: ``for frame in CaptureReader(path)``.

    Frames of non-Ethernet interfaces are counted and skipped; records that are cut off
    or inconsistent are counted in :attr:`stats` (``malformed_records``).
    """

    def __init__(self, path: str | Path, chunk_bytes: int = DEFAULT_CHUNK_BYTES) -> None:
        self.path = Path(path)
        self.stats = ReadStats()
        self._chunk = chunk_bytes
        try:
            with open(self.path, "rb") as f:
                head = f.read(PCAP_HEADER_BYTES)
        except OSError as e:
            raise CaptureError(f"cannot open: {e.strerror}", path=str(path)) from e
        self.header = read_file_header(path, head)

    def __iter__(self) -> Iterator[CapturedFrame]:
        with open(self.path, "rb") as f:
            src = ChunkedFile(f, self._chunk)
            if self.header.format == FORMAT_PCAP:
                yield from self._pcap(src)
            else:
                yield from self._pcapng(src)

    def _pcap(self, src: ChunkedFile) -> Iterator[CapturedFrame]:
        order = ">" if self.header.big_endian else "<"
        rec = struct.Struct(order + "IIII")
        frac_ns = 1 if self.header.nanoseconds else 1000
        link = self.header.link_type
        self.stats.interfaces = [Interface(link, self.header.snaplen)]
        pos = PCAP_HEADER_BYTES
        while True:
            head = src.window(pos, PCAP_RECORD_BYTES)
            if head is None:
                if not src.at_end(pos):
                    self._corrupt(pos)
                return
            sec, frac, incl, orig = rec.unpack(head)
            if incl > MAX_RECORD_BYTES:
                self._corrupt(pos)
                return
            data = src.window(pos + PCAP_RECORD_BYTES, incl)
            if data is None:
                self._corrupt(pos)
                return
            self.stats.packets += 1
            yield CapturedFrame(
                self.stats.packets, sec * 1_000_000_000 + frac * frac_ns, data, orig,
                link_type=link,
            )
            pos += PCAP_RECORD_BYTES + incl

    def _corrupt(self, pos: int) -> None:
        self.stats.malformed_records += 1
        self.stats.stopped_at = pos

    def _pcapng(self, src: ChunkedFile) -> Iterator[CapturedFrame]:
        big = self.header.big_endian
        ifaces: list[Interface] = []
        params: list[tuple[int, int, int, int]] = []
        last_ts = 0
        pos = 0
        while True:
            head = src.window(pos, 8)
            if head is None:
                if not src.at_end(pos):
                    self._corrupt(pos)
                return
            if struct.unpack_from("<I", head)[0] == PCAPNG_SHB:
                bom = src.window(pos + 8, 4)
                if bom is None:
                    self._corrupt(pos)
                    return
                big = parse_shb(b"\0" * 8 + bom)
            order = ">" if big else "<"
            btype, total = struct.unpack(order + "II", head)
            if total < 12 or total % 4 or total > MAX_RECORD_BYTES:
                self._corrupt(pos)
                return
            block = src.window(pos, total)
            if block is None:
                self._corrupt(pos)
                return
            pos += total
            if btype == PCAPNG_SHB:
                self.stats.sections += 1
                ifaces, params = [], []
            elif btype == BLOCK_IDB:
                try:
                    iface = parse_idb(block, big)
                except ValueError:
                    self._corrupt(pos - total)
                    return
                ifaces.append(iface)
                params.append(iface.ts_params())
                self.stats.interfaces.append(iface)
            elif btype in (BLOCK_EPB, BLOCK_OPB, BLOCK_SPB):
                frame = self._packet(block, btype, order, ifaces, params, last_ts)
                if frame is not None:
                    last_ts = frame.timestamp_ns
                    yield frame
            else:
                self.stats.skipped_blocks += 1

    def _packet(
        self,
        block: bytes,
        btype: int,
        order: str,
        ifaces: list[Interface],
        params: list[tuple[int, int, int, int]],
        last_ts: int,
    ) -> CapturedFrame | None:
        total = len(block)
        self.stats.packets += 1
        number = self.stats.packets
        if btype == BLOCK_SPB:
            if total < 16:
                self.stats.malformed_records += 1
                return None
            (orig,) = struct.unpack_from(order + "I", block, 8)
            iface_id, ts, start = 0, None, 12
            incl = min(orig, total - 16)
        else:
            if total < 32:
                self.stats.malformed_records += 1
                return None
            if btype == BLOCK_EPB:
                iface_id, hi, lo, incl, orig = struct.unpack_from(order + "IIIII", block, 8)
            else:
                iface_id, _drops, hi, lo, incl, orig = struct.unpack_from(
                    order + "HHIIII", block, 8
                )
            ts, start = (hi << 32) | lo, 28
            if start + incl > total - 4:
                self.stats.malformed_records += 1
                return None
        if iface_id >= len(ifaces):
            self.stats.malformed_records += 1
            return None
        iface = ifaces[iface_id]
        if not iface.analysed:
            self.stats.non_ethernet_packets += 1
            return None
        ts_ns = last_ts if ts is None else ts_to_ns(ts, *params[iface_id])
        return CapturedFrame(number, ts_ns, block[start : start + incl], orig, iface_id,
                             iface.link_type)


def iter_frames(path: str | Path) -> Iterator[CapturedFrame]:
    """The Ethernet and Linux cooked frames of a capture, in file order."""
    return iter(CaptureReader(path))


#: Linux packet type (SLL/SLL2) of a frame this host sent
PACKET_OUTGOING = 4
ETHERTYPE_VLAN = 0x8100


@dataclass(frozen=True, slots=True)
class LinkHeader:
    """The link layer of one captured frame: what it carries, where, and which way.

    ``returned``: for Ethernet, the locally administered bit of the source MAC (docs/architecture.md
    "Direction"); for Linux cooked frames, a packet type other than "sent by this host".
    """

    ethertype: int
    payload: int
    returned: bool
    source: bytes


def link_header(frame: CapturedFrame) -> LinkHeader:
    """Decode the link-layer header (Ethernet, SLL or SLL2, one optional 802.1Q tag).

    Raises :class:`ValueError` when the frame is too short for it."""
    data = frame.data
    if frame.link_type == LINKTYPE_LINUX_SLL:
        if len(data) < 16:
            raise ValueError("SLL header truncated")
        ptype, _, alen = struct.unpack_from(">HHH", data)
        source = bytes(data[6 : 6 + min(alen, 8)])
        etype, pos, returned = struct.unpack_from(">H", data, 14)[0], 16, ptype != PACKET_OUTGOING
    elif frame.link_type == LINKTYPE_LINUX_SLL2:
        if len(data) < 20:
            raise ValueError("SLL2 header truncated")
        etype = struct.unpack_from(">H", data)[0]
        ptype, alen = data[10], data[11]
        source = bytes(data[12 : 12 + min(alen, 8)])
        pos, returned = 20, ptype != PACKET_OUTGOING
    else:
        if len(data) < 14:
            raise ValueError("Ethernet header truncated")
        source = bytes(data[6:12])
        etype, pos, returned = struct.unpack_from(">H", data, 12)[0], 14, bool(data[6] & 0x02)
    if etype == ETHERTYPE_VLAN:
        if len(data) < pos + 4:
            raise ValueError("802.1Q tag truncated")
        etype, pos = struct.unpack_from(">H", data, pos + 2)[0], pos + 4
    return LinkHeader(etype, pos, returned, source)
