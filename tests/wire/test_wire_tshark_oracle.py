"""tshark as oracle: every EtherCAT frame of every corpus capture, datagram by datagram, and
every mailbox tshark decodes, field by field.

Raw bytes come from our own minimal reader (wire_corpus.read_packets); tshark is run once
per capture for datagram fields (-T fields) and once for mailbox frames (-T json).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from wire_corpus import (
    PCAP_IDS,
    PCAPS,
    need_corpus_and_tshark,
    read_packets,
    tshark_datagrams,
    tshark_mailboxes,
    tshark_malformed,
)

from lolacli.errors import WireError
from lolacli.wire.coe import decode_coe_header
from lolacli.wire.commands import LOGICAL
from lolacli.wire.frame import Datagram, Frame, decode_frame
from lolacli.wire.mailbox import decode_mailbox
from lolacli.wire.sdo import (
    SdoAbort,
    SdoAddressed,
    SdoDownloadRequest,
    SdoInitiate,
    SdoUploadRequest,
    SdoUploadResponse,
    decode_sdo,
    encode_sdo,
)


def _int(text: str) -> int:
    return int(text, 0)


def _check_datagrams(number: int, frame: Frame, row: dict[str, list[str]]) -> None:
    dgs = frame.datagrams
    where = f"frame {number}"
    assert [_int(x) for x in row["ecat.cmd"]] == [d.cmd for d in dgs], where
    assert [_int(x) for x in row["ecat.idx"]] == [d.index for d in dgs], where
    assert [_int(x) for x in row["ecat.int"]] == [d.irq for d in dgs], where
    assert [_int(x) for x in row["ecat.cnt"]] == [d.wkc for d in dgs], where
    assert [_int(x) for x in row["ecat.subframe.length"]] == [d.length for d in dgs], where
    assert [x == "1" for x in row["ecat.subframe.circulating"]] == [
        d.circulating for d in dgs
    ], where
    assert [x == "1" for x in row["ecat.subframe.more"]] == [d.more for d in dgs], where
    logical = [d for d in dgs if d.cmd in LOGICAL]
    physical = [d for d in dgs if d.cmd not in LOGICAL]
    assert [_int(x) for x in row["ecat.lad"]] == [d.address for d in logical], where
    assert [_int(x) for x in row["ecat.adp"]] == [d.adp for d in physical], where
    assert [_int(x) for x in row["ecat.ado"]] == [d.ado for d in physical], where
    assert [_int(x) for x in row["ecatf.type"]] == [frame.ecat_type], where
    assert [_int(x) for x in row["ecatf.length"]] == [frame.header_length], where


@pytest.mark.parametrize("path", PCAPS, ids=PCAP_IDS)
def test_every_ecat_frame_matches_tshark(path: Path) -> None:
    need_corpus_and_tshark()
    packets = read_packets(path)
    rows = tshark_datagrams(path)
    malformed = tshark_malformed(path)
    compared = 0
    for number, raw in enumerate(packets, start=1):
        if number in rows and number not in malformed:
            _check_datagrams(number, decode_frame(raw), rows[number])
            compared += 1
        else:
            with pytest.raises(WireError):
                decode_frame(raw)
    assert compared == len(rows) - len(malformed & rows.keys())
    assert compared > 0


def test_truncated_sii_frames_are_wire_errors() -> None:
    """rs-example-sii-el2004 holds 58 10-byte frames tshark calls malformed."""
    need_corpus_and_tshark()
    path = next((p for p in PCAPS if "rs-example-sii-el2004" in p.name), None)
    if path is None:
        pytest.skip("rs-example-sii-el2004 not in corpus")
    packets = read_packets(path)
    malformed = sorted(tshark_malformed(path))
    assert len(malformed) == 58
    for number in malformed:
        with pytest.raises(WireError):
            decode_frame(packets[number - 1])


def _find_datagram(frame: Frame, head: dict[str, Any], used: set[int]) -> Datagram:
    for i, d in enumerate(frame.datagrams):
        if i in used:
            continue
        if d.cmd == _int(head["ecat.cmd"]) and d.ado == _int(head["ecat.ado"]):
            used.add(i)
            return d
    raise AssertionError(f"no datagram matches tshark header {head}")


def _check_mailbox(d: Datagram, f: dict[str, Any]) -> None:
    mailbox = decode_mailbox(d.data)
    h = mailbox.header
    assert h.length == _int(f["ecat_mailbox.length"])
    assert h.address == _int(f["ecat_mailbox.address"])
    assert h.priority == _int(f["ecat_mailbox.priority"])
    assert h.mailbox_type == _int(f["ecat_mailbox.type"])
    assert h.counter == _int(f["ecat_mailbox.counter"])
    if "ecat_mailbox.coe.type" not in f:
        return
    coe = decode_coe_header(mailbox.payload)
    assert coe.service == _int(f["ecat_mailbox.coe.type"])
    assert coe.number == _int(f["ecat_mailbox.coe.number"])
    message = decode_sdo(mailbox.payload)
    assert encode_sdo(message) == mailbox.payload
    _check_sdo(message, f)


def _check_sdo(m: object, f: dict[str, Any]) -> None:
    spec = f.get("ecat_mailbox.coe.sdoreq", f.get("ecat_mailbox.coe.sdores"))
    kinds = {("2", "2"): SdoUploadRequest, ("2", "1"): SdoDownloadRequest}
    kinds |= {("3", "2"): SdoUploadResponse, ("2", "4"): SdoAbort, ("3", "4"): SdoAbort}
    expected = kinds.get((f["ecat_mailbox.coe.type"], spec))
    if expected is not None:
        assert isinstance(m, expected), (m, f)
    has_index = "ecat_mailbox.coe.sdoidx" in f  # tshark shows none for an abort
    if isinstance(m, SdoInitiate | SdoAddressed) or (isinstance(m, SdoAbort) and has_index):
        assert m.index == _int(f["ecat_mailbox.coe.sdoidx"])
        assert m.subindex == _int(f["ecat_mailbox.coe.sdosub"])
    if isinstance(m, SdoAbort):
        assert m.code == _int(f["ecat_mailbox.coe.abortcode"])
    if isinstance(m, SdoUploadResponse):
        _check_upload_response(m, f)


def _check_upload_response(m: SdoUploadResponse, f: dict[str, Any]) -> None:
    pre = "ecat_mailbox.coe.sdoscsiu_"
    assert m.size_indicated == (f[pre + "sizeind"] == "1")
    assert m.expedited == (f[pre + "expedited"] == "1")
    assert m.complete_access == (f[pre + "complete"] == "1")
    if m.expedited:
        raw = (m.data + m.filler)[:4]
        assert int.from_bytes(raw, "little") == _int(f["ecat_mailbox.coe.sdodata"])
    else:
        assert m.complete_size == _int(f["ecat_mailbox.coe.sdolength"])
        if "ecat_mailbox.coe.dsoldata" in f:
            assert m.data.hex(":") == f["ecat_mailbox.coe.dsoldata"]


@pytest.mark.parametrize("path", PCAPS, ids=PCAP_IDS)
def test_every_tshark_mailbox_matches(path: Path) -> None:
    need_corpus_and_tshark()
    packets = read_packets(path)
    mailboxes = tshark_mailboxes(path)
    compared = 0
    for number, entries in mailboxes.items():
        frame = decode_frame(packets[number - 1])
        used: set[int] = set()
        for head, fields in entries:
            _check_mailbox(_find_datagram(frame, head, used), fields)
            compared += 1
    assert compared == sum(len(v) for v in mailboxes.values())
