"""scapy's EtherCAT layer (``scapy.contrib.ethercat``) as a second, independent decoding
oracle: every frame of every corpus capture (the frames tshark checks in
test_wire_tshark_oracle.py), frames built from hypothesis-drawn datagrams, and those
frames mutated, are decoded by scapy and by :func:`lolacli.wire.frame.decode_frame`, and
the EtherCAT header and every datagram field (command, index, address, length, reserved
bits, circulating and more flags, IRQ, data, WKC) must agree.

What scapy's layer does not do, and how the comparison allows for it; each was found on
these frames (the cap on the corpus, the others on drawn and mutated frames) and is
pinned by test_where_scapy_differs, so a scapy that changes shows here. On the corpus,
every one of the 24,861 distinct EtherCAT frames decodes equal.

* By default it decodes no datagram of more than 100 data bytes (``conf.max_list_count``
  caps every list field, here each data byte is an item; a longer datagram ends its chain
  as ``Raw``): the test raises the cap to 2048, the 11-bit length's maximum + 1.
* It decodes only type-12 read/write commands 0x01-0x0E. A NOP (0x00) or an unknown
  command after the first datagram ends its chain (the rest is ``Raw``); ours goes on.
  As the first datagram it is decoded all the same (scapy falls back to the EtherCAT
  layer's first binding, the APRD layout, which is every command's). Compared: the
  datagrams scapy decodes.
* It ignores the M ("more") flag and the EtherCAT header's length: after the last
  datagram it reads the bytes that follow (the Ethernet padding) as more datagrams when
  they happen to start with a command byte 0x01-0x0E. Ours stops at the datagram without
  M, and checks the chain against the header's length. Compared: scapy's first datagrams,
  as many as ours; scapy's extras must start in our padding.
* It ignores the EtherCAT type: frames of type 4 (network variables) and 5 (mailbox
  gateway) get their payload decoded as datagrams too; ours decodes datagrams only for
  type 1. Compared: the header.
* A datagram that does not fit the frame becomes ``Raw`` (no error); ours raises
  :class:`~lolacli.errors.WireError`. Where ours refuses a frame, scapy must not have
  found a complete chain (ending with M clear) inside the header's length: that is the
  one frame both would have to accept.
* EtherCAT over UDP (port 0x88A4) has no binding in scapy (read from its source): not
  compared (tshark checks it).
"""

from __future__ import annotations

import logging
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_wire_roundtrip import frames
from wire_corpus import PCAP_IDS, PCAPS, read_packets

from lolacli.errors import WireError
from lolacli.wire.frame import Frame, decode_frame, encode_frame

scapy_l2 = pytest.importorskip("scapy.layers.l2", reason="scapy is in the test extras")
scapy_ecat = pytest.importorskip("scapy.contrib.ethercat")

# scapy logs an error for every datagram of a command it does not know
logging.getLogger("scapy.runtime").setLevel(logging.CRITICAL)
# scapy reads a list field of at most conf.max_list_count (100) items: a datagram with
# more data bytes would end its chain as Raw; datagrams hold up to 2047
pytest.importorskip("scapy.config").conf.max_list_count = 2048

ECAT_COMMANDS = range(0x01, 0x0F)
ETHERTYPE_ECAT = 0x88A4


def _scapy(raw: bytes) -> tuple[tuple[int, int] | None, list[dict[str, Any]]]:
    """scapy's view of a frame: the EtherCAT header (length, type) or None, and its
    datagrams as dicts of our field names."""
    header = scapy_l2.Ether(raw).getlayer(scapy_ecat.EtherCat)
    if header is None:
        return None, []
    out: list[dict[str, Any]] = []
    layer = header.payload
    while isinstance(layer, scapy_ecat.EtherCatType12DLPDU):
        f = layer.fields
        logical = "adr" in f
        out.append({
            "cmd": f["_cmd"],
            "index": f["idx"],
            "address": f["adr"] if logical else f["adp"] | f["ado"] << 16,
            "length": f["len"],
            "reserved": f["_reserved"],
            "circulating": bool(f["c"]),
            "more": bool(f["next"]),
            "irq": f["irq"],
            "data": bytes(f["data"]),
            "wkc": f["wkc"],
        })
        layer = layer.payload
    return (header.length, header.type), out


def _ours(frame: Frame) -> list[dict[str, Any]]:
    return [
        {"cmd": d.cmd, "index": d.index, "address": d.address, "length": d.length,
         "reserved": d.reserved, "circulating": d.circulating, "more": d.more,
         "irq": d.irq, "data": d.data, "wkc": d.wkc}
        for d in frame.datagrams
    ]


def _ethertype(raw: bytes) -> tuple[int | None, int]:
    """The ethertype (behind one 802.1Q tag) and where the EtherCAT header starts."""
    if len(raw) < 14:
        return None, 14
    etype = int.from_bytes(raw[12:14], "big")
    if etype == 0x8100:
        return (int.from_bytes(raw[16:18], "big") if len(raw) >= 18 else None), 18
    return etype, 14


def compare(raw: bytes) -> str:
    """Check one frame against scapy; returns what was compared (for the tallies)."""
    etype, start = _ethertype(raw)
    if etype != ETHERTYPE_ECAT:
        with pytest.raises(WireError):
            decode_frame(raw)
        return "not ethercat"
    header, theirs = _scapy(raw)
    try:
        frame = decode_frame(raw)
    except WireError:
        _refused_by_us(raw, start + 2, header, theirs)
        return "refused"
    assert header == (frame.header_length, frame.ecat_type), raw.hex()
    if frame.ecat_type != 1:
        return "other type"
    ours = _ours(frame)
    # the first datagram is decoded whatever its command (see above)
    known = next((i for i, d in enumerate(ours) if i and d["cmd"] not in ECAT_COMMANDS),
                 len(ours))
    assert theirs[:known] == ours[:known], raw.hex()
    if known < len(ours):
        assert len(theirs) == known, raw.hex()  # scapy stops at the unknown command
        return "nop or unknown command"
    if len(theirs) > len(ours):  # read on into the bytes after our last datagram
        assert frame.padding and frame.padding[0] in ECAT_COMMANDS, raw.hex()
        return "padding read as datagrams"
    return "equal"


def _refused_by_us(raw: bytes, start: int, header: tuple[int, int] | None,
                   theirs: list[dict[str, Any]]) -> None:
    """Ours refused the frame: scapy must not hold a complete chain inside the header's
    length (from ``start``, the first datagram) that ends with M clear."""
    if header is None or header[1] != 1:
        return
    length = header[0]
    if start + length > len(raw):
        return  # the header's length runs past the frame: scapy does not look at it
    used = 0
    for d in theirs:
        used += 12 + len(d["data"])
        if used > length:
            return  # runs past the header's length: ours refuses, scapy does not check
        if not d["more"]:
            raise AssertionError(f"scapy decodes a whole chain that ours refused: {raw.hex()}")


@pytest.mark.parametrize("path", PCAPS, ids=PCAP_IDS)
def test_every_corpus_frame_as_scapy_reads_it(path):
    tally: dict[str, int] = {}
    for raw in dict.fromkeys(read_packets(path)):  # each distinct frame once
        kind = compare(raw)
        tally[kind] = tally.get(kind, 0) + 1
    assert tally.get("equal", 0) > 0, tally


EXAMPLES = settings(max_examples=300, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])


@EXAMPLES
@given(frames())
def test_drawn_frames_as_scapy_reads_them(frame):
    compare(encode_frame(frame))


@EXAMPLES
@given(frames(), st.data())
def test_mutated_frames_as_scapy_reads_them(frame, data):
    buf = bytearray(encode_frame(frame, pad=True))
    kind = data.draw(st.sampled_from(["flip", "cut", "length", "splice"]))
    if kind == "flip":
        for i in data.draw(st.lists(st.integers(0, len(buf) - 1), min_size=1, max_size=4)):
            buf[i] ^= 1 << data.draw(st.integers(0, 7))
    elif kind == "cut":
        del buf[data.draw(st.integers(14, len(buf))):]
    elif kind == "length":  # the EtherCAT header's or a datagram's length word
        head = 18 if frame.ethernet.vlan_tci is not None else 14
        spot = data.draw(st.sampled_from([head, head + 8]))
        if spot + 2 <= len(buf):
            buf[spot:spot + 2] = data.draw(st.integers(0, 0xFFFF)).to_bytes(2, "little")
    else:
        i = data.draw(st.integers(14, len(buf)))
        buf[i:i] = data.draw(st.binary(min_size=1, max_size=8))
    compare(bytes(buf))


def test_where_scapy_differs():
    """The differences the comparison allows for, each on one frame."""
    from lolacli.wire.commands import Command
    from lolacli.wire.frame import Datagram, make_frame

    lrw = Datagram.logical(Command.LRW, 0x10000, b"abcd", index=1, wkc=3)
    # padding that starts with a command byte: scapy reads on past the M flag
    brd_bytes = bytes([7, 2, 0, 0, 0x30, 1, 2, 0, 0, 0, 0, 0, 0, 0])
    raw = encode_frame(make_frame([lrw], src=b"\x02" + bytes(5))) + brd_bytes
    assert compare(raw) == "padding read as datagrams"
    # a NOP after the first datagram ends scapy's chain, ours goes on
    nop = Datagram.physical(0, 0, 0, 2, index=2)
    raw = encode_frame(make_frame([lrw, nop, lrw], src=b"\x02" + bytes(5)))
    assert compare(raw) == "nop or unknown command" and len(_scapy(raw)[1]) == 1
    # a mailbox-gateway frame (type 5): scapy decodes datagrams all the same
    raw = bytearray(encode_frame(make_frame([lrw], src=b"\x02" + bytes(5))))
    raw[15] = (raw[15] & 0x0F) | 0x50
    assert compare(bytes(raw)) == "other type" and len(_scapy(bytes(raw))[1]) == 1
    # a datagram longer than the frame: ours refuses, scapy keeps it as Raw
    raw = encode_frame(make_frame([lrw], src=b"\x02" + bytes(5)))[:-3]
    assert compare(raw) == "refused" and _scapy(raw)[1] == []
    # a datagram of more than 100 bytes needs the raised cap
    big = Datagram.logical(Command.LRW, 0, bytes(846), index=1, wkc=75)
    assert compare(encode_frame(make_frame([big], src=b"\x02" + bytes(5)))) == "equal"
