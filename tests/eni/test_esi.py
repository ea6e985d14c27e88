"""The ESI reader against the corpus ESI files, with stdlib ElementTree as the independent count."""

from __future__ import annotations

import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from lolacli.eni.esi import parse_esi
from lolacli.eni.model import Direction
from lolacli.errors import EniError
from lolacli.files import load_esi
from tests.conftest import corpus_files

ESI_FILES = corpus_files("esi", "*.xml")
ELMO = next((p for p in ESI_FILES if "Elmo" in p.name), None)
EL1XXX = next((p for p in ESI_FILES if "EL1xxx" in p.name), None)


def _num(text: str | None) -> int:
    t = (text or "0").strip()
    return int(t[2:], 16) if t.lower().startswith(("#x", "0x")) else int(t)


def _et_devices(path: Path) -> tuple[ET.Element, list[ET.Element]]:
    root = ET.parse(path).getroot()  # the corpus is trusted; stdlib is the second opinion
    return root, root.findall("Descriptions/Devices/Device")


def _et_name(el: ET.Element) -> str:
    names = el.findall("Name")
    english = [n for n in names if n.get("LcId") == "1033"]
    return ((english or names)[0].text or "").strip()


def test_the_corpus_has_the_seven_esi_files() -> None:
    if not ESI_FILES:
        pytest.skip("corpus not found")
    assert len(ESI_FILES) == 7


@pytest.mark.parametrize("path", ESI_FILES, ids=lambda p: p.name[:30])
def test_every_corpus_esi_parses_like_elementtree(path: Path) -> None:
    esi = load_esi(path)
    root, devices = _et_devices(path)
    assert len(esi.devices) == len(devices) > 0
    assert esi.vendor_id == _num(root.findtext("Vendor/Id"))
    assert esi.source == str(path)
    for dev, el in zip(esi.devices, devices, strict=True):
        kind = el.find("Type")
        assert kind is not None
        assert dev.identity.vendor_id == esi.vendor_id
        assert dev.identity.product_code == _num(kind.get("ProductCode"))
        assert dev.identity.revision == _num(kind.get("RevisionNo"))
        assert dev.name == _et_name(el)
        sms = el.findall("Sm")
        assert [s.kind for s in dev.sync_managers] == [(s.text or "").strip() for s in sms]
        assert [s.start_address for s in dev.sync_managers] == [
            _num(s.get("StartAddress")) for s in sms
        ]
        for direction, tag in ((Direction.OUTPUT, "RxPdo"), (Direction.INPUT, "TxPdo")):
            ours = [p for p in dev.pdos if p.direction == direction]
            theirs = el.findall(tag)
            assert [p.index for p in ours] == [_num(p.findtext("Index")) for p in theirs]
            assert [p.bit_size for p in ours] == [
                sum(_num(e.findtext("BitLen")) for e in p.findall("Entry")) for p in theirs
            ]
            assert [p.sync_manager for p in ours] == [
                None if p.get("Sm") is None else _num(p.get("Sm")) for p in theirs
            ]
        assert len(dev.dc_op_modes) == len(el.findall("Dc/OpMode"))


def test_elmo_gold_identity_mailbox_and_find() -> None:
    if ELMO is None:
        pytest.skip("corpus not found")
    esi = load_esi(ELMO)
    assert (esi.vendor_id, esi.vendor_name) == (0x9A, "Elmo Motion Control")
    drive = esi.find(0x9A, 0x30924, 0x10420)
    assert drive is not None and drive.identity.revision == 0x10420
    assert drive.mailbox_protocols == ("EoE", "CoE", "FoE")
    assert drive.coe is not None and drive.coe.sdo_info and drive.coe.pdo_assign
    out = drive.sync_manager("MBoxOut")
    assert out is not None and (out.start_address, out.default_size_bytes) == (0x1800, 0x8C)
    assert out.control == 0x26 and out.enable
    assert drive.profile_no == 402
    assert drive.dc_op_modes[0].assign_activate == 0x0300
    assert drive.eeprom is not None and drive.eeprom.byte_size == 2048
    assert drive.eeprom.config_data[:2] == bytes.fromhex("050c")
    # another revision of the same product: the highest revision described
    fallback = esi.find(0x9A, 0x30924, 0x12345)
    assert fallback is not None and fallback.identity.revision == max(
        d.identity.revision for d in esi.devices if d.identity.product_code == 0x30924
    )
    assert esi.find(0x9A, 0x1234, 0x10420) is None
    assert esi.find(0x2, 0x30924, 0x10420) is None


def test_iso_8859_1_names_survive() -> None:
    path = next((p for p in ESI_FILES if "EK11xx" in p.name), None)
    if path is None:
        pytest.skip("corpus not found")
    assert path.read_bytes().startswith(b'<?xml version="1.0" encoding="ISO-8859-1"?>')
    esi = load_esi(path)
    root, _devices = _et_devices(path)
    assert esi.vendor_name == (root.findtext("Vendor/Name") or "").strip()
    assert len({d.identity.revision for d in esi.devices}) > 1


def test_the_4_mb_beckhoff_file_is_fast() -> None:
    if EL1XXX is None:
        pytest.skip("corpus not found")
    data = EL1XXX.read_bytes()
    assert len(data) > 4_000_000
    best = float("inf")
    for _ in range(2):
        t0 = time.perf_counter()
        esi = parse_esi(data, str(EL1XXX))
        best = min(best, time.perf_counter() - t0)
    assert len(esi.devices) == 155
    assert best < 3.0, f"{best:.2f} s for {len(data)} bytes"


def test_a_str_document_parses() -> None:
    text = """<EtherCATInfo><Vendor><Id>#x1337</Id><Name>rt-labs</Name></Vendor>
    <Descriptions><Devices><Device Physics="YY">
      <Type ProductCode="4660" RevisionNo="#x2">x</Type><Name LcId="1031">Gerät</Name>
      <Name LcId="1033">Device</Name>
      <Sm StartAddress="#x1000" DefaultSize="128" ControlByte="#x26" Enable="1">MBoxOut</Sm>
      <TxPdo Sm="3" Mandatory="true"><Index>#x1A00</Index><Name>in</Name>
        <Entry><Index>#x6000</Index><SubIndex>1</SubIndex><BitLen>1</BitLen></Entry></TxPdo>
    </Device></Devices></Descriptions></EtherCATInfo>"""
    dev = parse_esi(text).devices[0]
    assert (dev.identity.vendor_id, dev.identity.product_code, dev.identity.revision) == (
        0x1337,
        4660,
        2,
    )
    assert dev.name == "Device" and dev.physics == "YY"
    assert dev.assigned_pdos[0].mandatory and dev.assigned_pdos[0].sync_manager == 3


HOSTILE = {
    "billion laughs": b'<?xml version="1.0"?>\n<!DOCTYPE l [<!ENTITY a "aaaaaaaaaa">'
    b'<!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;">]>\n<EtherCATInfo><Vendor><Id>&b;</Id>'
    b"</Vendor></EtherCATInfo>",
    "external entity": b'<?xml version="1.0"?>\n<!DOCTYPE x [<!ENTITY e SYSTEM '
    b'"file:///etc/passwd">]>\n<EtherCATInfo><Vendor><Id>&e;</Id></Vendor></EtherCATInfo>',
    "truncated": b"<EtherCATInfo><Vendor><Id>1</Id></Vendor><Descriptions><Devi",
    "wrong root": b"<EtherCATConfig><Config/></EtherCATConfig>",
    "no vendor": b"<EtherCATInfo><Descriptions/></EtherCATInfo>",
    "bad number": b"<EtherCATInfo><Vendor><Id>1</Id></Vendor><Descriptions><Devices>"
    b'<Device><Type ProductCode="#xZZ">x</Type></Device></Devices></Descriptions>'
    b"</EtherCATInfo>",
    "bad config data": b"<EtherCATInfo><Vendor><Id>1</Id></Vendor><Descriptions><Devices>"
    b'<Device><Type ProductCode="1">x</Type><Eeprom><ConfigData>XYZ</ConfigData></Eeprom>'
    b"</Device></Devices></Descriptions></EtherCATInfo>",
    "empty": b"",
}


@pytest.mark.parametrize("name", sorted(HOSTILE))
def test_hostile_or_broken_esi_is_one_eni_error(name: str) -> None:
    with pytest.raises(EniError) as exc:
        parse_esi(HOSTILE[name], "evil.xml")
    message = str(exc.value)
    assert message.startswith("evil.xml") and "\n" not in message
    assert "passwd" not in message and "root:" not in message
    if name not in ("empty",):
        assert exc.value.line is not None


def test_load_esi_missing_file(tmp_path: Path) -> None:
    with pytest.raises(EniError, match="no such file"):
        load_esi(tmp_path / "nope.xml")
