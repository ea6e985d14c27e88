"""EtherCAT frames and datagrams: decode and encode (no IO).

Layout (ETG.1000.4 §5.3, Tables 12 and 14)::

    Ethernet  dst(6) src(6) [0x8100 TCI(2)] type(2)=0x88A4
    EtherCAT  header(2): length:11 | reserved:1 | type:4        (little endian)
    datagram  cmd(1) idx(1) address(4) len:11|r:3|C:1|M:1 (2) IRQ(2) data(len) WKC(2)

The address field is ADP (16 bits) then ADO (16 bits) for physical addressing, or one
32-bit logical address for LRD/LWR/LRW; both little endian. ``Datagram.address`` keeps the
raw 32-bit value and offers both views.

EtherCAT over UDP (ETG.1000.4 §5.3.2): the same EtherCAT header and datagrams are the
payload of a UDP datagram to port 0x88A4.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from lolacli.errors import WireError
from lolacli.wire.commands import LOGICAL, mnemonic

if TYPE_CHECKING:
    from lolacli.wire.udp import UdpInfo

ETHERTYPE_ECAT = 0x88A4
ETHERTYPE_VLAN = 0x8100
ETHERTYPE_IPV4 = 0x0800
UDP_PORT_ECAT = 0x88A4

#: EtherCAT header "type" field values (ETG.1000.4 Table 12).
ECAT_TYPE_COMMANDS = 1
ECAT_TYPE_NETWORK_VARIABLES = 4
ECAT_TYPE_MAILBOX = 5

DATAGRAM_HEADER_BYTES = 10
WKC_BYTES = 2
ETH_HEADER_BYTES = 14
ECAT_HEADER_BYTES = 2
FCS_BYTES = 4
MIN_FRAME_BYTES = 64  # incl. FCS
MAX_DATAGRAM_DATA = 0x7FF

_ETH = struct.Struct("<6s6sH")  # type read big-endian separately
_U16BE = struct.Struct(">H")
_U16 = struct.Struct("<H")
_DGRAM_HEAD = struct.Struct("<BBIHH")


@dataclass(frozen=True, slots=True)
class Datagram:
    """One EtherCAT datagram (ETG.1000.4 Table 14).

    ``cmd`` is the command byte (a :class:`~lolacli.wire.commands.Command` where known).
    ``address`` is the raw 32-bit address field; see :attr:`adp`, :attr:`ado` and
    :attr:`logical_address`. ``more`` is the M flag as sent (set on every datagram but the
    last when the frame is built by :func:`make_frame`). ``reserved`` keeps bits 11–13 of
    the length word so that decoding and encoding are exact inverses.
    """

    cmd: int
    index: int
    address: int
    data: bytes
    wkc: int = 0
    irq: int = 0
    circulating: bool = False
    more: bool = False
    reserved: int = 0

    @property
    def adp(self) -> int:
        return self.address & 0xFFFF

    @property
    def ado(self) -> int:
        return self.address >> 16

    @property
    def logical_address(self) -> int | None:
        return self.address if self.cmd in LOGICAL else None

    @property
    def length(self) -> int:
        return len(self.data)

    @property
    def mnemonic(self) -> str:
        return mnemonic(self.cmd)

    @property
    def wire_bytes(self) -> int:
        return DATAGRAM_HEADER_BYTES + len(self.data) + WKC_BYTES

    @staticmethod
    def physical(
        cmd: int, adp: int, ado: int, data: bytes | int, *, index: int = 0, wkc: int = 0
    ) -> Datagram:
        """A physically addressed datagram; ``data`` may be a length (zeros)."""
        payload = bytes(data) if isinstance(data, int) else data
        return Datagram(cmd, index, (adp & 0xFFFF) | ((ado & 0xFFFF) << 16), payload, wkc)

    @staticmethod
    def logical(
        cmd: int, address: int, data: bytes | int, *, index: int = 0, wkc: int = 0
    ) -> Datagram:
        """A logically addressed datagram; ``data`` may be a length (zeros)."""
        payload = bytes(data) if isinstance(data, int) else data
        return Datagram(cmd, index, address & 0xFFFFFFFF, payload, wkc)


@dataclass(frozen=True, slots=True)
class EthernetHeader:
    dst: bytes = b"\xff" * 6
    src: bytes = b"\x01\x01\x01\x01\x01\x01"
    vlan_tci: int | None = None

    @property
    def returned(self) -> bool:
        """True when the first source-MAC octet has the locally administered bit set.

        The first ESC of the chain sets it, so a frame seen with it set has passed the
        slaves (docs/architecture.md "Direction").
        """
        return bool(self.src[0] & 0x02)


@dataclass(frozen=True, slots=True)
class Frame:
    """An EtherCAT frame: Ethernet header, EtherCAT header type, datagrams.

    ``udp`` is ``None`` for EtherCAT directly over Ethernet, else the UDP/IP information
    (see :mod:`lolacli.wire.udp`). ``padding`` holds bytes after the last datagram up to
    the end of the captured Ethernet frame (zero padding, or an FCS).

    ``declared_length`` is the EtherCAT header's length field where it differs from the
    datagrams' total (some masters count padding in it); ``None`` when they agree.
    """

    ethernet: EthernetHeader = field(default_factory=EthernetHeader)
    datagrams: tuple[Datagram, ...] = ()
    ecat_type: int = ECAT_TYPE_COMMANDS
    ecat_reserved: int = 0
    padding: bytes = b""
    declared_length: int | None = None
    udp: UdpInfo | None = None

    @property
    def ecat_length(self) -> int:
        return sum(d.wire_bytes for d in self.datagrams)

    @property
    def header_length(self) -> int:
        """The EtherCAT header's length field as sent."""
        return self.ecat_length if self.declared_length is None else self.declared_length


def frame_bytes_on_wire(datagram_data_lengths: list[int] | tuple[int, ...]) -> int:
    """Frame bytes per docs/architecture.md: 14 + 2 + Σ(10 + data + 2) + FCS 4, padded to 64."""
    total = ETH_HEADER_BYTES + ECAT_HEADER_BYTES + FCS_BYTES
    total += sum(DATAGRAM_HEADER_BYTES + n + WKC_BYTES for n in datagram_data_lengths)
    return max(total, MIN_FRAME_BYTES)


def make_frame(datagrams: list[Datagram] | tuple[Datagram, ...], **eth: object) -> Frame:
    """A frame with the M flag set on every datagram but the last."""
    from dataclasses import replace

    n = len(datagrams)
    fixed = tuple(replace(d, more=i < n - 1) for i, d in enumerate(datagrams))
    header = EthernetHeader(**eth)  # type: ignore[arg-type]
    return Frame(header, fixed)


def decode_datagrams(
    buf: bytes | memoryview, offset: int = 0, end: int | None = None
) -> tuple[tuple[Datagram, ...], int]:
    """Decode datagrams from ``buf[offset:end]`` until one without the M flag.

    Returns the datagrams and the offset just after the last one. Raises
    :class:`WireError` when a datagram does not fit.
    """
    stop = len(buf) if end is None else end
    out: list[Datagram] = []
    pos = offset
    while True:
        if pos + DATAGRAM_HEADER_BYTES > stop:
            raise WireError("datagram header truncated", offset=pos)
        cmd, idx, addr, lenw, irq = _DGRAM_HEAD.unpack_from(buf, pos)
        n = lenw & 0x7FF
        data_start = pos + DATAGRAM_HEADER_BYTES
        if data_start + n + WKC_BYTES > stop:
            raise WireError(f"datagram data ({n} bytes) runs past the frame", offset=pos)
        data = bytes(buf[data_start : data_start + n])
        (wkc,) = _U16.unpack_from(buf, data_start + n)
        more = bool(lenw & 0x8000)
        out.append(
            Datagram(
                cmd=cmd,
                index=idx,
                address=addr,
                data=data,
                wkc=wkc,
                irq=irq,
                circulating=bool(lenw & 0x4000),
                more=more,
                reserved=(lenw >> 11) & 0x7,
            )
        )
        pos = data_start + n + WKC_BYTES
        if not more:
            return tuple(out), pos


def decode_ecat_payload(
    buf: bytes | memoryview, offset: int = 0
) -> tuple[int, int, tuple[Datagram, ...], int]:
    """Decode the EtherCAT header and datagrams starting at ``offset``.

    Returns ``(ecat_type, reserved, datagrams, end_offset)``. Only type 1 (commands)
    carries datagrams; other types return no datagrams and the end of the header.
    """
    if offset + ECAT_HEADER_BYTES > len(buf):
        raise WireError("EtherCAT header truncated", offset=offset)
    (word,) = _U16.unpack_from(buf, offset)
    length = word & 0x7FF
    reserved = (word >> 11) & 1
    ecat_type = word >> 12
    start = offset + ECAT_HEADER_BYTES
    if ecat_type != ECAT_TYPE_COMMANDS:
        return ecat_type, reserved, (), start
    if start + length > len(buf):
        raise WireError(f"EtherCAT length {length} runs past the frame", offset=offset)
    datagrams, end = decode_datagrams(buf, start, start + length)
    return ecat_type, reserved, datagrams, end


def decode_ethernet_header(buf: bytes | memoryview) -> tuple[EthernetHeader, int, int]:
    """Ethernet header (with one optional 802.1Q tag): header, ethertype, payload offset."""
    if len(buf) < ETH_HEADER_BYTES:
        raise WireError(f"Ethernet frame too short ({len(buf)} bytes)", offset=0)
    dst = bytes(buf[0:6])
    src = bytes(buf[6:12])
    (etype,) = _U16BE.unpack_from(buf, 12)
    pos = 14
    tci: int | None = None
    if etype == ETHERTYPE_VLAN:
        if len(buf) < pos + 4:
            raise WireError("802.1Q tag truncated", offset=pos)
        (tci,) = _U16BE.unpack_from(buf, pos)
        (etype,) = _U16BE.unpack_from(buf, pos + 2)
        pos += 4
    return EthernetHeader(dst, src, tci), etype, pos


def declared_length_if_odd(
    buf: bytes | memoryview, pos: int, datagrams: tuple[Datagram, ...]
) -> int | None:
    """The EtherCAT header length at ``pos`` when it differs from the datagrams' total."""
    length = _U16.unpack_from(buf, pos)[0] & 0x7FF
    total = sum(d.wire_bytes for d in datagrams)
    return None if length == total else length


def decode_frame(buf: bytes | memoryview) -> Frame:
    """Decode an Ethernet frame that carries EtherCAT (ethertype 0x88A4).

    For EtherCAT over UDP use :func:`lolacli.wire.udp.decode_udp_frame`. Raises
    :class:`WireError` for anything else or for malformed content.
    """
    header, etype, pos = decode_ethernet_header(buf)
    if etype != ETHERTYPE_ECAT:
        raise WireError(f"not an EtherCAT frame (ethertype 0x{etype:04X})", offset=12)
    ecat_type, reserved, datagrams, end = decode_ecat_payload(buf, pos)
    declared = declared_length_if_odd(buf, pos, datagrams)
    return Frame(header, datagrams, ecat_type, reserved, bytes(buf[end:]), declared)


def decode_any(buf: bytes | memoryview) -> Frame:
    """Decode EtherCAT in any of its Ethernet forms: ethertype 0x88A4 (also behind one
    802.1Q tag) or IPv4/UDP to port 0x88A4 (``Frame.udp`` set). Raises
    :class:`WireError` for any other frame or malformed content."""
    _, etype, _ = decode_ethernet_header(buf)
    if etype == ETHERTYPE_IPV4:
        from lolacli.wire.udp import decode_udp_frame

        return decode_udp_frame(buf)
    return decode_frame(buf)


def encode_datagram(d: Datagram) -> bytes:
    if len(d.data) > MAX_DATAGRAM_DATA:
        raise WireError(f"datagram data of {len(d.data)} bytes exceeds {MAX_DATAGRAM_DATA}")
    lenw = (
        len(d.data)
        | ((d.reserved & 0x7) << 11)
        | (0x4000 if d.circulating else 0)
        | (0x8000 if d.more else 0)
    )
    head = _DGRAM_HEAD.pack(d.cmd & 0xFF, d.index & 0xFF, d.address & 0xFFFFFFFF, lenw, d.irq)
    return head + d.data + _U16.pack(d.wkc & 0xFFFF)


def encode_ecat_payload(frame: Frame) -> bytes:
    body = b"".join(encode_datagram(d) for d in frame.datagrams)
    if len(body) > 0x7FF:
        raise WireError(f"EtherCAT payload of {len(body)} bytes exceeds 2047")
    length = len(body) if frame.declared_length is None else frame.declared_length
    word = (length & 0x7FF) | ((frame.ecat_reserved & 1) << 11) | ((frame.ecat_type & 0xF) << 12)
    return _U16.pack(word) + body


def encode_frame(frame: Frame, *, pad: bool = False) -> bytes:
    """Ethernet frame bytes (no FCS). ``pad`` pads to the 60-byte minimum without FCS;
    otherwise ``frame.padding`` is appended as it is. A frame with ``udp`` set is encoded
    as EtherCAT over UDP."""
    if frame.udp is not None:
        from lolacli.wire.udp import encode_udp_frame

        out = encode_udp_frame(frame)
        if pad:
            return out + bytes(max(0, MIN_FRAME_BYTES - FCS_BYTES - len(out)))
        return out
    eth = frame.ethernet
    head = eth.dst + eth.src
    if eth.vlan_tci is not None:
        head += _U16BE.pack(ETHERTYPE_VLAN) + _U16BE.pack(eth.vlan_tci)
    head += _U16BE.pack(ETHERTYPE_ECAT)
    out = head + encode_ecat_payload(frame)
    if pad:
        return out + bytes(max(0, MIN_FRAME_BYTES - FCS_BYTES - len(out)))
    return out + frame.padding
