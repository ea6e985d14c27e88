"""pcap and pcapng record encoders (pure: they return bytes).

The inverse of :mod:`lolacli.capture.reader`, used for synthetic captures (tests,
benchmarks). See the reader for the formats. Timestamps are integer nanoseconds;
pcapng interfaces default to ``if_tsresol`` = 9 (nanoseconds).
"""

from __future__ import annotations

import struct

from lolacli.capture.reader import (
    BLOCK_EPB,
    BLOCK_IDB,
    BLOCK_OPB,
    BLOCK_SPB,
    LINKTYPE_ETHERNET,
    OPT_IF_TSOFFSET,
    OPT_IF_TSRESOL,
    PCAP_MAGIC_NS,
    PCAP_MAGIC_US,
    PCAPNG_BYTE_ORDER_MAGIC,
    PCAPNG_SHB,
)


def _o(big: bool) -> str:
    return ">" if big else "<"


def pcap_header(
    *, big: bool = False, ns: bool = False, link_type: int = LINKTYPE_ETHERNET,
    snaplen: int = 65535,
) -> bytes:
    magic = PCAP_MAGIC_NS if ns else PCAP_MAGIC_US
    return struct.pack(_o(big) + "IHHiIII", magic, 2, 4, 0, 0, snaplen, link_type)


def pcap_record(
    ts_ns: int, data: bytes, *, original_length: int | None = None, big: bool = False,
    ns: bool = False,
) -> bytes:
    sec, rem = divmod(ts_ns, 1_000_000_000)
    frac = rem if ns else rem // 1000
    orig = len(data) if original_length is None else original_length
    return struct.pack(_o(big) + "IIII", sec, frac, len(data), orig) + data


def _pad4(data: bytes) -> bytes:
    return data + bytes(-len(data) % 4)


def _block(btype: int, body: bytes, big: bool) -> bytes:
    body = _pad4(body)
    total = 12 + len(body)
    o = _o(big)
    return struct.pack(o + "II", btype, total) + body + struct.pack(o + "I", total)


def _option(code: int, value: bytes, big: bool) -> bytes:
    return struct.pack(_o(big) + "HH", code, len(value)) + _pad4(value)


def shb(*, big: bool = False) -> bytes:
    """A Section Header Block (version 1.0, unknown section length)."""
    body = struct.pack(_o(big) + "IHHq", PCAPNG_BYTE_ORDER_MAGIC, 1, 0, -1)
    return _block(PCAPNG_SHB, body, big)


def idb(
    *, link_type: int = LINKTYPE_ETHERNET, tsresol: int | None = 9, tsoffset_s: int = 0,
    snaplen: int = 0, big: bool = False,
) -> bytes:
    """An Interface Description Block; ``tsresol=None`` leaves the 10^-6 default."""
    body = struct.pack(_o(big) + "HHI", link_type, 0, snaplen)
    opts = b""
    if tsresol is not None:
        opts += _option(OPT_IF_TSRESOL, bytes([tsresol]), big)
    if tsoffset_s:
        opts += _option(OPT_IF_TSOFFSET, struct.pack(_o(big) + "q", tsoffset_s), big)
    if opts:
        opts += _option(0, b"", big)
    return _block(BLOCK_IDB, body + opts, big)


def epb(
    units: int, data: bytes, *, interface: int = 0, original_length: int | None = None,
    big: bool = False,
) -> bytes:
    """An Enhanced Packet Block; ``units`` in the interface's timestamp resolution."""
    orig = len(data) if original_length is None else original_length
    head = struct.pack(
        _o(big) + "IIIII", interface, units >> 32, units & 0xFFFFFFFF, len(data), orig
    )
    return _block(BLOCK_EPB, head + data, big)


def opb(units: int, data: bytes, *, interface: int = 0, big: bool = False) -> bytes:
    """An (obsolete) Packet Block."""
    head = struct.pack(
        _o(big) + "HHIIII", interface, 0, units >> 32, units & 0xFFFFFFFF, len(data), len(data)
    )
    return _block(BLOCK_OPB, head + data, big)


def spb(data: bytes, *, big: bool = False) -> bytes:
    """A Simple Packet Block (no interface id, no timestamp)."""
    return _block(BLOCK_SPB, struct.pack(_o(big) + "I", len(data)) + data, big)


def custom_block(btype: int, body: bytes, *, big: bool = False) -> bytes:
    """Any block, e.g. one of a type the reader must skip."""
    return _block(btype, body, big)
