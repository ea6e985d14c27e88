"""EtherCAT over UDP (ETG.1000.4 §5.3.2): Ethernet + IPv4 + UDP port 0x88A4, whose payload
is the EtherCAT header and datagrams exactly as in an 0x88A4 Ethernet frame.

IPv4 header: RFC 791 §3.1; UDP header: RFC 768. The IPv4 checksum is the RFC 1071 one's
complement sum over the header. Fragmented IPv4 packets are not reassembled here.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from lolacli.errors import WireError
from lolacli.wire._codes import need
from lolacli.wire.frame import (
    ETHERTYPE_IPV4,
    ETHERTYPE_VLAN,
    UDP_PORT_ECAT,
    EthernetHeader,
    Frame,
    declared_length_if_odd,
    decode_ecat_payload,
    decode_ethernet_header,
    encode_ecat_payload,
)

IPV4_HEADER_BYTES = 20
UDP_HEADER_BYTES = 8
IP_PROTO_UDP = 17

_IPV4 = struct.Struct(">BBHHHBBH4s4s")
_UDP = struct.Struct(">HHHH")
_U16BE = struct.Struct(">H")


@dataclass(frozen=True, slots=True)
class UdpInfo:
    """The IPv4 and UDP headers around an EtherCAT payload.

    Lengths are derived on encoding. ``ip_checksum`` is ``None`` when the received header
    checksum was right (it is computed on encoding), else the wrong value as received.
    ``udp_checksum`` is kept as sent (0 = none, allowed over IPv4).
    """

    src_ip: bytes = bytes(4)
    dst_ip: bytes = b"\xff\xff\xff\xff"
    src_port: int = UDP_PORT_ECAT
    dst_port: int = UDP_PORT_ECAT
    ttl: int = 64
    tos: int = 0
    identification: int = 0
    dont_fragment: bool = False
    ip_options: bytes = b""
    ip_checksum: int | None = None
    udp_checksum: int = 0

    @property
    def src(self) -> str:
        return ".".join(str(b) for b in self.src_ip)

    @property
    def dst(self) -> str:
        return ".".join(str(b) for b in self.dst_ip)


def ipv4_checksum(header: bytes) -> int:
    """RFC 1071 checksum of an IPv4 header whose checksum field is zero."""
    if len(header) % 2:
        header += b"\x00"
    total: int = sum(struct.unpack(f">{len(header) // 2}H", header))
    while total > 0xFFFF:
        total = (total & 0xFFFF) + (total >> 16)
    return int(~total & 0xFFFF)


def _decode_ipv4(buf: bytes | memoryview, pos: int) -> tuple[UdpInfo, int, int]:
    """IPv4 + UDP headers at ``pos``: info, payload offset, payload end."""
    need(buf, pos, IPV4_HEADER_BYTES, "IPv4 header")
    ver_ihl, tos, total, ident, frag, ttl, proto, checksum, src, dst = _IPV4.unpack_from(buf, pos)
    ihl_bytes = (ver_ihl & 0x0F) * 4
    if ver_ihl >> 4 != 4 or ihl_bytes < IPV4_HEADER_BYTES:
        raise WireError(f"not an IPv4 header (version/IHL 0x{ver_ihl:02X})", offset=pos)
    if proto != IP_PROTO_UDP:
        raise WireError(f"IPv4 protocol {proto} is not UDP", offset=pos + 9)
    if frag & 0x3FFF:
        raise WireError("fragmented IPv4 packet", offset=pos + 6)
    need(buf, pos, max(total, ihl_bytes), "IPv4 packet")
    if total < ihl_bytes + UDP_HEADER_BYTES:
        raise WireError(f"IPv4 total length {total} too short for UDP", offset=pos + 2)
    header = bytes(buf[pos : pos + ihl_bytes])
    zeroed = header[:10] + b"\x00\x00" + header[12:]
    bad = None if ipv4_checksum(zeroed) == checksum else checksum
    udp_pos = pos + ihl_bytes
    sport, dport, udp_len, udp_sum = _UDP.unpack_from(buf, udp_pos)
    if udp_len < UDP_HEADER_BYTES or udp_pos + udp_len > pos + total:
        raise WireError(f"UDP length {udp_len} does not fit the IPv4 packet", offset=udp_pos + 4)
    if UDP_PORT_ECAT not in (sport, dport):
        raise WireError(f"UDP ports {sport}/{dport} are not EtherCAT (0x88A4)", offset=udp_pos)
    info = UdpInfo(
        src, dst, sport, dport, ttl, tos, ident, bool(frag & 0x4000),
        header[IPV4_HEADER_BYTES:], bad, udp_sum,
    )
    return info, udp_pos + UDP_HEADER_BYTES, udp_pos + udp_len


def decode_udp_frame(buf: bytes | memoryview) -> Frame:
    """An Ethernet frame carrying EtherCAT over IPv4/UDP; ``Frame.udp`` holds the IP/UDP
    information. Raises :class:`WireError` for anything else."""
    eth, etype, pos = decode_ethernet_header(buf)
    if etype != ETHERTYPE_IPV4:
        raise WireError(f"not an IPv4 frame (ethertype 0x{etype:04X})", offset=12)
    info, start, end = _decode_ipv4(buf, pos)
    view = bytes(buf[:end])
    ecat_type, reserved, datagrams, stop = decode_ecat_payload(view, start)
    if stop != end:
        raise WireError(f"{end - stop} bytes after the last datagram in the UDP payload")
    declared = declared_length_if_odd(view, start, datagrams)
    return Frame(eth, datagrams, ecat_type, reserved, bytes(buf[end:]), declared, info)


def _ipv4_udp_bytes(info: UdpInfo, payload: bytes) -> bytes:
    if len(info.ip_options) % 4 or len(info.ip_options) > 40:
        raise WireError("IPv4 options must be a multiple of 4 bytes, at most 40")
    ihl_bytes = IPV4_HEADER_BYTES + len(info.ip_options)
    udp_len = UDP_HEADER_BYTES + len(payload)
    total = ihl_bytes + udp_len
    if total > 0xFFFF:
        raise WireError(f"IPv4 packet of {total} bytes is too long")
    flags = 0x4000 if info.dont_fragment else 0

    def header(checksum: int) -> bytes:
        fixed = _IPV4.pack(
            0x40 | ihl_bytes // 4, info.tos & 0xFF, total, info.identification & 0xFFFF,
            flags, info.ttl & 0xFF, IP_PROTO_UDP, checksum, info.src_ip, info.dst_ip,
        )
        return fixed + info.ip_options

    checksum = ipv4_checksum(header(0)) if info.ip_checksum is None else info.ip_checksum
    udp = _UDP.pack(info.src_port & 0xFFFF, info.dst_port & 0xFFFF, udp_len, info.udp_checksum)
    return header(checksum & 0xFFFF) + udp + payload


def encode_udp_frame(frame: Frame, info: UdpInfo | None = None) -> bytes:
    """Ethernet + IPv4 + UDP + EtherCAT bytes (no FCS), then ``frame.padding``.

    ``info`` defaults to ``frame.udp`` (or a default :class:`UdpInfo`).
    """
    udp = info or frame.udp or UdpInfo()
    if len(udp.src_ip) != 4 or len(udp.dst_ip) != 4:
        raise WireError("IPv4 addresses must be 4 bytes")
    eth: EthernetHeader = frame.ethernet
    head = eth.dst + eth.src
    if eth.vlan_tci is not None:
        head += _U16BE.pack(ETHERTYPE_VLAN) + _U16BE.pack(eth.vlan_tci)
    head += _U16BE.pack(ETHERTYPE_IPV4)
    return head + _ipv4_udp_bytes(udp, encode_ecat_payload(frame)) + frame.padding
