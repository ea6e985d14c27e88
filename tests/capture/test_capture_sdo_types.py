"""The SDO transactions of a capture are named, typed and printed as ``sdo read`` does
(lolacli/capture/sdo.py over lolacli/od/lookup.py): by the ENI's PDO entries when one is
given, else by the SDO Information answers the capture holds, else CiA 301, else a guess.

The mailbox traffic is real: the emulated drive's own SDO server (the dictionary of
tests/sdo/test_one_typing.py's ENI: an INTEGER24, a VISIBLE_STRING with latin-1 bytes, a
REAL32, a BOOLEAN) answers each request, and the tracker reads both directions as it reads
them from a pcap (FPWR to the mailbox out, FPRD from the mailbox in)."""

from __future__ import annotations

from pathlib import Path

import pytest

from lolacli.capture.sdo import SdoTracker
from lolacli.devices import device_for
from lolacli.emulator.mailbox.sdo_server import SdoServer
from lolacli.files import load_eni
from lolacli.wire.mailbox import MailboxType, encode_mailbox, make_mailbox
from lolacli.wire.sdo import EntryDescriptionRequest, encode_sdo, upload_request
from tests.sdo.test_one_typing import _TYPED, _typed_eni

FPRD, FPWR = 4, 5
STATION = 0x03E9


class _Wire:
    """A master's requests to the drive and its answers, fed to a tracker in order."""

    def __init__(self, eni: Path) -> None:
        self.eni = load_eni(eni)
        self.slave = self.eni.slaves[0]
        self.device = device_for(self.slave)
        self.server = SdoServer(self.device.od, mailbox_bytes=140)
        self.tracker = SdoTracker()
        self.frame = 0

    def ask(self, coe_payload: bytes) -> None:
        mailbox = make_mailbox(MailboxType.CoE, coe_payload, counter=1 + self.frame % 7)
        request = encode_mailbox(mailbox)
        self._feed(FPWR, request)
        for reply in self.server.handle(request):
            self._feed(FPRD, reply)

    def _feed(self, cmd: int, data: bytes) -> None:
        self.frame += 1
        address = self.slave.station_address | (0x1000 << 16)
        self.tracker.feed(self.frame, self.frame * 1000, cmd, address, data)


@pytest.fixture
def wire(tmp_path) -> _Wire:
    w = _Wire(_typed_eni(tmp_path))
    for obj, _value, _kind, _printed, raw in _TYPED:
        index, sub = (int(part, 16) for part in obj.split(":"))
        w.device.od.write(index, sub, raw)  # as sdo write does
    return w


def _objects() -> list[tuple[int, int, str, str]]:
    out = []
    for obj, _value, kind, printed, _raw in _TYPED:
        index, sub = (int(part, 16) for part in obj.split(":"))
        out.append((index, sub, kind, printed))
    return out


def test_typed_by_the_sdo_information_the_capture_holds(wire) -> None:
    for index, sub, _kind, _printed in _objects():
        wire.ask(encode_sdo(EntryDescriptionRequest(index, sub, 0)))
        wire.ask(upload_request(index, sub))
    wire.tracker.describe(None)
    uploads = [t for t in wire.tracker.transactions if t.kind == "upload"]
    assert len(uploads) == 4 and wire.tracker.stats.sdo_info_messages == 8
    for t, (index, sub, kind, printed) in zip(uploads, _objects(), strict=True):
        d = t.to_dict()
        assert (t.index, t.subindex, d["status"]) == (index, sub, "ok")
        assert (d["data_type"], d["type_source"], d["value_text"]) == (kind, "sdo-info", printed)
        assert d["name"] == wire.device.od.entry(index, sub).name
    assert [t.to_dict()["value"] for t in uploads][1:] == ["Maß 1°", pytest.approx(0.1), True]


def test_typed_by_the_eni_and_without_any_source_guessed(wire) -> None:
    for index, sub, _kind, _printed in _objects():
        wire.ask(upload_request(index, sub))
    wire.ask(upload_request(0x1018, 1))
    wire.tracker.describe(wire.eni)
    *typed, identity = wire.tracker.transactions
    for t, (_index, _sub, kind, printed) in zip(typed, _objects(), strict=True):
        assert (t.data_type, t.type_source, t.value_text) == (kind, "eni", printed)
    assert (identity.name, identity.data_type, identity.type_source) == (
        "Vendor ID",
        "UNSIGNED32",
        "cia301",
    )
    assert identity.value_text == "154 (0x0000009A)"
    wire.tracker.describe(None)  # no ENI, no SDO Information: the 3 bytes are a guess
    assert (typed[0].type_source, typed[0].data_type) == ("guess", "OCTET_STRING")
    assert typed[0].value_text == (-70000).to_bytes(3, "little", signed=True).hex(" ")
