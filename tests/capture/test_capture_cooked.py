"""Linux cooked captures (SLL, link type 113; SLL2, link type 276), which `tcpdump -i any`
and `dumpcap -i any` write: every corpus capture rewritten as SLL and SLL2, in pcap and in
pcapng, must give the counts, pairs and verdicts of its Ethernet original; the packet type
is what tells the direction then (sent by the capturing host: the master's frame).

The converter below is written from the SLL/SLL2 header layouts (tcpdump.org
linktypes/LINKTYPE_LINUX_SLL.html and LINKTYPE_LINUX_SLL2.html), not from lolacli's reader.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import pytest
from capture_oracle import tshark_available
from conftest import corpus_files, corpus_ids

from lolacli.capture import writer as w
from lolacli.capture.analyze import analyze_file
from lolacli.capture.reader import iter_frames

CAPTURES = corpus_files("pcap")
PACKET_HOST, PACKET_BROADCAST, PACKET_OUTGOING = 0, 1, 4
ARPHRD_ETHER = 1

#: keys that describe the file rather than the bus: they may differ between the variants
FILE_KEYS = ("file", "format", "engine", "other", "direction_rule", "interfaces")


def _sll(eth: bytes, version: int) -> bytes:
    """An Ethernet frame as the Linux "any" device records it (header without the
    destination, packet type from the direction the master's NIC saw)."""
    if len(eth) < 14:
        return eth  # a damaged frame stays damaged (shorter than either header)
    src, etype, payload = eth[6:12], struct.unpack(">H", eth[12:14])[0], eth[14:]
    outgoing = not src[0] & 0x02  # the master's frames; returned ones have the bit set
    dst_group = eth[0] & 0x01
    ptype = PACKET_OUTGOING if outgoing else (PACKET_BROADCAST if dst_group else PACKET_HOST)
    if version == 1:
        head = struct.pack(">HHH8sH", ptype, ARPHRD_ETHER, 6, src.ljust(8, b"\0"), etype)
    else:
        head = struct.pack(">HHIHBB8s", etype, 0, 3, ARPHRD_ETHER, ptype, 6,
                           src.ljust(8, b"\0"))
    return head + payload


def convert(src: Path, dst: Path, version: int, pcapng: bool) -> Path:
    link = 113 if version == 1 else 276
    body = [w.shb() + w.idb(link_type=link, tsresol=9)] if pcapng else [
        w.pcap_header(ns=True, link_type=link)]
    for frame in iter_frames(src):
        data = _sll(frame.data, version)
        orig = frame.original_length - len(frame.data) + len(data)
        if pcapng:
            body.append(w.epb(frame.timestamp_ns, data, original_length=orig))
        else:
            body.append(w.pcap_record(frame.timestamp_ns, data, original_length=orig, ns=True))
    dst.write_bytes(b"".join(body))
    return dst


VARIANTS = [(1, False), (1, True), (2, False), (2, True)]


def _bus(rep: dict) -> dict:
    out = {k: v for k, v in rep.items() if k not in FILE_KEYS}
    # (a damaged 10-byte frame is the same packet, counted the same way)
    return json.loads(json.dumps(out))


@pytest.fixture(scope="module")
def cooked(tmp_path_factory) -> dict:
    folder = tmp_path_factory.mktemp("cooked")
    made = {}
    for path in CAPTURES:
        for version, ng in VARIANTS:
            dst = folder / f"{path.stem}.sll{version}.{'pcapng' if ng else 'pcap'}"
            made[(path.name, version, ng)] = convert(path, dst, version, ng)
    return made


@pytest.mark.parametrize("path", CAPTURES, ids=corpus_ids(CAPTURES))
def test_cooked_variants_give_the_ethernet_verdict(path, cooked):
    original = analyze_file(path).to_dict()
    for version, ng in VARIANTS:
        variant = cooked[(path.name, version, ng)]
        rep = analyze_file(variant).to_dict()
        assert rep["direction_rule"] == "packet_type", variant.name
        assert _bus(rep) == _bus(original), variant.name
        assert rep["verdict"] == original["verdict"]


@pytest.mark.parametrize("path", CAPTURES, ids=corpus_ids(CAPTURES))
def test_engines_agree_on_cooked_captures(path, cooked, fast):
    for version, ng in VARIANTS:
        variant = cooked[(path.name, version, ng)]
        got = analyze_file(variant, engine=fast).to_dict()
        slow = analyze_file(variant, engine="python", chunk_bytes=1 << 16).to_dict()
        got.pop("engine"), slow.pop("engine")
        assert got == slow, variant.name


def test_cooked_list_matches_the_ethernet_listing(cooked, cli):
    path = CAPTURES[0] if CAPTURES else None
    if path is None:
        pytest.skip("corpus not found")
    name = "ethercrab__replay-sdo-error.pcapng"
    eth = json.loads(cli("capture", "list", path.parent / name, "-f", "json")[1])["frames"]
    for version, ng in VARIANTS:
        code, out, _ = cli("capture", "list", cooked[(name, version, ng)], "-f", "json")
        assert code == 0 and json.loads(out)["frames"] == eth


@pytest.mark.skipif(not tshark_available(), reason="tshark not installed")
def test_tshark_reads_the_converted_files_as_ethercat(cooked):
    """The converter writes what tshark decodes as SLL/SLL2 carrying EtherCAT."""
    import subprocess

    name = "ethercrab__replay-issue-255.pcapng"
    for version, ng in VARIANTS:
        out = subprocess.run(
            ["tshark", "-r", str(cooked[(name, version, ng)]), "-Y", "ecat", "-T", "fields",
             "-e", "frame.protocols"], capture_output=True, text=True, check=True).stdout
        lines = out.splitlines()
        assert len(lines) == 2976
        assert all(x.startswith(f"{'sll' if version == 1 else 'sll'}:ethertype:ecatf:ecat")
                   for x in lines), set(lines)


def test_sll_packet_type_decides_against_the_mac(tmp_path):
    """A master whose MAC already has the locally administered bit (KickCAT's
    ca:de:ca:de:de:ff): in a cooked capture the packet type still tells the direction."""
    from lolacli.wire.commands import Command
    from lolacli.wire.frame import Datagram, encode_frame, make_frame

    mac = bytes.fromhex("cadecadedeff")
    records = []
    for i in range(20):
        for ret in (False, True):
            d = Datagram.logical(Command.LRW, 0, 8, index=i, wkc=3 if ret else 0)
            eth = encode_frame(make_frame([d], src=mac), pad=True)
            head = struct.pack(">HHH8sH", PACKET_HOST if ret else PACKET_OUTGOING,
                               ARPHRD_ETHER, 6, mac.ljust(8, b"\0"), 0x88A4)
            records.append(w.pcap_record(10**18 + i * 10**6 + (40_000 if ret else 0),
                                         head + eth[14:], ns=True))
    path = tmp_path / "kickcat-any.pcap"
    path.write_bytes(w.pcap_header(ns=True, link_type=113) + b"".join(records))
    rep = analyze_file(path).to_dict()
    assert rep["direction_rule"] == "packet_type"
    assert (rep["outgoing_frames"], rep["returned_frames"], rep["pairs"]) == (20, 20, 20)
    assert rep["round_trip_us"]["median"] == 40.0 and rep["verdict"] == "pass"
