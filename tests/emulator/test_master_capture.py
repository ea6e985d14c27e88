"""The real-master tests' capture reading (tests/emulator/master_capture.py): in a Linux
cooked v2 capture the kernel's packet type pairs each answer with its request, whatever
the master's MAC; answers to nothing and other interfaces' frames are told apart."""

from __future__ import annotations

import struct
from pathlib import Path

from lolacli.capture import writer as w
from lolacli.wire.commands import Command as C
from lolacli.wire.frame import Datagram, encode_frame, make_frame
from tests.emulator.master_capture import Exchange, read_capture, read_exchanges

PACKET_HOST, PACKET_OUTGOING = 0, 4
KICKCAT_MAC = bytes.fromhex("cadecadedeff")  # the local bit set, as KickCAT's own MAC
MASTER, OTHER = 7, 8  # interface indexes


def _sll2(ecat_frame: bytes, ifindex: int, outgoing: bool) -> bytes:
    """An Ethernet frame as the "any" device records it in Linux cooked v2."""
    etype, payload = struct.unpack(">H", ecat_frame[12:14])[0], ecat_frame[14:]
    ptype = PACKET_OUTGOING if outgoing else PACKET_HOST
    head = struct.pack(">HHIHBB8s", etype, 0, ifindex, 1, ptype, 6, KICKCAT_MAC.ljust(8, b"\0"))
    return head + payload


def _frame(index: int, wkc: int = 0, ado: int = 0x0130) -> bytes:
    d = Datagram.physical(C.FPRD, 0x1001, ado, bytes(2), index=index, wkc=wkc)
    return encode_frame(make_frame([d], src=KICKCAT_MAC), pad=True)


def _write(path: Path, frames: list[tuple[int, bytes, int, bool]]) -> Path:
    body = [w.shb(), w.idb(link_type=276, tsresol=9)]
    body += [w.epb(t, _sll2(f, ifindex, out)) for t, f, ifindex, out in frames]
    path.write_bytes(b"".join(body))
    return path


def test_the_packet_type_pairs_answers_a_guess_from_the_mac_cannot(tmp_path: Path) -> None:
    frames = [
        (1_000, _frame(1), MASTER, True),
        (1_020, _frame(1, wkc=0), MASTER, False),  # answered, WKC unchanged (no slave hit)
        (2_000, _frame(2), MASTER, True),
        (2_600, _frame(2), MASTER, True),  # sent again after a time-out (as SOEM does)
        (2_700, _frame(2, wkc=1), MASTER, False),  # the late answer to the first copy
        (2_720, _frame(2, wkc=1), MASTER, False),  # the second copy's
        (3_000, _frame(3), OTHER, True),  # another interface's frames: not the master's
        (3_010, _frame(3, wkc=1), OTHER, False),
        (4_000, _frame(4), MASTER, True),  # never answered
        (5_000, _frame(5, wkc=1), MASTER, False),  # an answer to nothing
    ]
    report = read_capture(_write(tmp_path / "m.pcapng", frames), MASTER)
    assert report.exchanges == [
        Exchange(1_000, 1_020, "FPRD"),
        Exchange(2_000, 2_700, "FPRD"),
        Exchange(2_600, 2_720, "FPRD"),
        Exchange(4_000, None, "FPRD"),
    ]
    assert report.orphans == [5_000]
    # the Ethernet guess takes the unchanged answer for the master sending again
    eth = tmp_path / "e.pcapng"
    eth.write_bytes(w.shb() + w.idb(tsresol=9) + w.epb(1_000, _frame(1)) + w.epb(1_020, _frame(1)))
    assert read_exchanges(eth) == [Exchange(1_000, None, "FPRD"), Exchange(1_020, None, "FPRD")]
