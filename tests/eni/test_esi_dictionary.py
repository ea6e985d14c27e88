"""ESI object dictionaries: every corpus ESI loads; objects counted by ElementTree agree;
values the files state are read back."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest

from lolacli.errors import EniError
from lolacli.files import load_esi
from lolacli.wire.datatypes import DataType, decode_value
from tests.conftest import corpus_files, corpus_ids

ESI = corpus_files("esi", "*.xml")


def _device(name: str, index: int = -1):
    [path] = [p for p in ESI if p.name.startswith(name)]
    return load_esi(path).devices[index]


@pytest.mark.parametrize("path", ESI, ids=corpus_ids(ESI))
def test_every_corpus_esi_dictionary_matches_element_tree(path, corpus) -> None:
    """Per device, as many objects as its <Dictionary>/<Objects>/<Object> elements; every
    object has entries, every entry its object's index and a subindex in 0..255."""
    esi = load_esi(path)
    root = ET.parse(path).getroot()
    expected = []
    for device in root.iter("Device"):
        if device.find("Type") is None:
            continue
        objects = device.findall("Profile/Dictionary/Objects/Object")
        expected.append(len(objects) if device.find("Profile/Dictionary") is not None else None)
    got = [None if d.dictionary is None else len(d.dictionary.objects) for d in esi.devices]
    assert got == expected
    for device in esi.devices:
        for obj in device.dictionary or ():
            assert obj.entries, hex(obj.index)
            assert all(0 <= e.subindex <= 255 for e in obj)
            assert all((e.index, e.subindex) == (obj.index, sub) for sub, e in obj.entries.items())


def test_elmo_device_type_and_name(corpus) -> None:
    od = _device("elmo_ethercat_sdk").dictionary
    device_type = od.object(0x1000).entries[0]
    assert device_type.data_type == DataType.UNSIGNED32 and device_type.access == "ro"
    assert decode_value(DataType.UNSIGNED32, device_type.value) == 0x00020192
    assert device_type.default == 0x00020192
    name = od.object(0x1008).entries[0]
    assert name.data_type == DataType.VISIBLE_STRING
    assert name.value == b"Elmo Motion Control" and name.default == "Elmo Motion Control"
    # the boot firmware's DT1400: <Info> names only some sub items; matched by name
    # (sub 2, not sub 1)
    pdo = _device("elmo_ethercat_sdk", 0).dictionary.object(0x1400)
    assert pdo.object_code.name == "RECORD"
    assert pdo.entry(0).value == b"\x04"
    assert pdo.entry(2).name == "Transmission Type" and pdo.entry(2).value == b"\xff"
    assert pdo.entry(1).default is None
    controlword = od.object(0x6040).entries[0]
    assert (controlword.data_type, controlword.access, controlword.pdo_mapping) == (
        DataType.UNSIGNED16,
        "rw",
        True,
    )


def test_ingenia_array_elements_take_info_names(corpus) -> None:
    od = _device("kickcat__ingenia").dictionary
    assign = od.object(0x1C12)
    assert assign.object_code.name == "ARRAY"
    assert [e.subindex for e in assign] == [0, 1, 2, 3]
    assert [e.data_type for e in assign][1:] == [DataType.UNSIGNED16] * 3
    assert assign.entries[1].name == "RxPDO assign Element 1"
    assert assign.entries[1].value == b"\x00\x00"
    assert assign.entries[0].access == "rw"


def test_soes_default_value_and_string(corpus) -> None:
    od = _device("soes__rtl_xmc4").dictionary
    assert od.object(0x1000).entries[0].value == (0x1389).to_bytes(4, "little")
    assert od.object(0x1008).entries[0].value == b"xmc48relax"
    identity = od.object(0x1018)
    assert identity.entry(1).value == (0x1337).to_bytes(4, "little")
    assert identity.entry(0).data_type == DataType.UNSIGNED8


def test_devices_without_dictionary(corpus) -> None:
    assert _device("kickcat-fork__Beckhoff_EK11xx", 0).dictionary is None
    assert _device("soes__EasyCAT", 0).dictionary is None


def _esi(dictionary: str) -> bytes:
    return f"""<?xml version="1.0"?>
<EtherCATInfo><Vendor><Id>1</Id><Name>t</Name></Vendor><Descriptions><Devices>
<Device><Type ProductCode="#x2" RevisionNo="1">T</Type><Name>T</Name>
<Profile><Dictionary>{dictionary}</Dictionary></Profile></Device>
</Devices></Descriptions></EtherCATInfo>""".encode()


def test_bad_default_data_names_line(tmp_path) -> None:
    path = tmp_path / "bad.xml"
    path.write_bytes(
        _esi(
            "<Objects><Object><Index>#x2000</Index><Name>x</Name><Type>UDINT</Type>"
            "<BitSize>32</BitSize><Info>\n<DefaultData>zz</DefaultData></Info></Object></Objects>"
        )
    )
    with pytest.raises(EniError, match=r"bad.xml:\d+: <DefaultData>: not hex data"):
        load_esi(path)


def test_unknown_types_and_enums(tmp_path) -> None:
    path = tmp_path / "enum.xml"
    path.write_bytes(
        _esi(
            "<DataTypes><DataType><Name>DTENUM</Name><BaseType>UINT</BaseType><BitSize>16</BitSize>"
            "<EnumInfo><Text>a</Text><Enum>0</Enum></EnumInfo></DataType></DataTypes>"
            "<Objects><Object><Index>#x2000</Index><Name>e</Name><Type>DTENUM</Type>"
            "<BitSize>16</BitSize><Info><DefaultValue>7</DefaultValue></Info>"
            "<Flags><Access>rw</Access></Flags></Object>"
            "<Object><Index>#x2001</Index><Name>u</Name><Type>MYSTERY</Type>"
            "<BitSize>8</BitSize></Object></Objects>"
        )
    )
    od = load_esi(path).devices[0].dictionary
    enum = od.object(0x2000).entries[0]
    assert (enum.data_type, enum.value, enum.access) == (DataType.UNSIGNED16, b"\x07\x00", "rw")
    assert od.object(0x2001).entries[0].data_type is None
