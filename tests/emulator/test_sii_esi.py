"""SII images built from ESI devices, and an emulated chain that takes them from ESI files."""

from __future__ import annotations

import dataclasses
import struct
from pathlib import Path

import pytest

from lolacli.emulator.run import EmulateOptions, esi_matches, make_chain
from lolacli.emulator.sii import sii_from_esi_device, sii_layout
from lolacli.eni.esi import EsiDevice
from lolacli.eni.model import Direction
from lolacli.files import load_eni, load_esi
from lolacli.wire.commands import Command
from lolacli.wire.sii import (
    CoeDetails,
    SiiCategory,
    SmType,
    decode_sii_dc_assign_activate,
)
from lolacli.wire.sii import sii_categories as categories
from tests.conftest import CORPUS, corpus_files
from tests.emulator.bus import EXAMPLES, Bus
from tests.emulator.test_masters import _stop, emulate, pysoem, veth  # noqa: F401 (fixtures)

ESI_FILES = corpus_files("esi", "*.xml")
ELMO = CORPUS / "esi" / "elmo_ethercat_sdk__Elmo_ECAT_00010420_V11.xml"
ROCOS = CORPUS / "eni" / "rocos-ethercat__eni.xml"
SM_KINDS = {"MBoxOut": 1, "MBoxIn": 2, "Outputs": 3, "Inputs": 4}


def _need(*paths: Path) -> None:
    for p in paths:
        if not p.is_file():
            pytest.skip(f"corpus file missing: {p}")


def _assigned_bytes(device: EsiDevice, direction: Direction) -> int:
    bits = sum(
        p.bit_size
        for p in device.pdos
        if p.direction == direction and (p.sync_manager is not None or p.mandatory)
    )
    return (bits + 7) // 8


@pytest.mark.parametrize("path", ESI_FILES, ids=lambda p: p.name[:30])
def test_sii_of_every_esi_device_reads_back(path: Path) -> None:
    for device in load_esi(path).devices:
        image = sii_from_esi_device(device, serial=0x1234)
        layout = sii_layout(image)
        ident = device.identity
        assert (layout.vendor_id, layout.product_code, layout.revision, layout.serial) == (
            ident.vendor_id,
            ident.product_code,
            ident.revision,
            0x1234,
        )
        assert layout.name == device.name[:255]
        assert [
            (
                s.sync_manager.physical_start,
                s.sync_manager.length_bytes,
                s.sync_manager.control,
                s.sync_manager.activate,
                s.type,
            )
            for s in layout.sync_managers
        ] == [
            (
                s.start_address,
                s.default_size_bytes,
                s.control,
                int(s.enable),
                SM_KINDS.get(s.kind, 0),
            )
            for s in device.sync_managers
        ]
        out, inn = device.sync_manager("MBoxOut"), device.sync_manager("MBoxIn")
        if out is not None and inn is not None:
            assert (layout.mailbox_out_start, layout.mailbox_out_bytes) == (
                out.start_address,
                out.default_size_bytes,
            )
            assert (layout.mailbox_in_start, layout.mailbox_in_bytes) == (
                inn.start_address,
                inn.default_size_bytes,
            )
        else:
            assert layout.mailbox_out_bytes == layout.protocols == 0
        assert layout.outputs_bytes == _assigned_bytes(device, Direction.OUTPUT)
        assert layout.inputs_bytes == _assigned_bytes(device, Direction.INPUT)
        kibit = struct.unpack_from("<H", image, 2 * 0x3E)[0] + 1
        assert len(image) == kibit * 128
        if device.eeprom is not None and device.eeprom.byte_size:
            assert len(image) >= device.eeprom.byte_size


def test_elmo_sii_categories_carry_the_esi_details() -> None:
    _need(ELMO)
    device = load_esi(ELMO).find(0x9A, 0x30924, 0x10420)
    assert device is not None
    image = sii_from_esi_device(device)
    cats = categories(image)
    strings = cats[SiiCategory.STRINGS]
    assert device.group.encode() in strings and device.name.encode() in strings
    general = cats[SiiCategory.GENERAL]
    assert general[5] == CoeDetails.SDO | CoeDetails.SDO_INFO | CoeDetails.PDO_ASSIGN | (
        CoeDetails.PDO_CONFIG
    )
    assert general[9] == 1  # one CiA 402 channel
    assert cats[SiiCategory.FMMU][:2] == bytes([1, 2])
    # assign-activate at byte 14 of the operation mode (ETG.2010 Table 16; it was at the
    # reserved bytes 20-21 before)
    assert decode_sii_dc_assign_activate(cats[SiiCategory.DC]) == (0x0300,)
    assert struct.unpack_from("<H", cats[SiiCategory.DC], 14)[0] == 0x0300
    assert device.eeprom is not None
    assert image[:6] == device.eeprom.config_data == bytes.fromhex("050c0304e803")
    assert struct.unpack_from("<H", image, 2 * 0x1C)[0] == 0x02 | 0x04 | 0x08  # EoE CoE FoE
    layout = sii_layout(image)
    assert layout.sync_managers[2].type == SmType.OUTPUTS
    assert layout.outputs_bytes == 10 and layout.inputs_bytes == 10  # RxPdo 0x1600, TxPdo 0x1A00


def _read_sii(bus: Bus, position: int, words: int) -> bytes:
    """Read ``words`` SII words of the slave at ``position`` (0-based) through 0x0502/0x0508."""
    adp = (-position) & 0xFFFF
    out = bytearray()
    word = 0
    while word < words:
        request = struct.pack("<HI", 0x0100, word)  # read command, word address
        assert bus.one(Command.APWR, adp, 0x0502, request).wkc == 1
        status = bus.one(Command.APRD, adp, 0x0502, 2).data
        chunk = 8 if struct.unpack("<H", status)[0] & 0x0040 else 4
        out += bus.one(Command.APRD, adp, 0x0508, chunk).data
        word += chunk // 2
    return bytes(out[: 2 * words])


def test_emulated_rocos_chain_answers_sii_reads_with_the_elmo_esi() -> None:
    _need(ELMO, ROCOS)
    eni, esi = load_eni(ROCOS), load_esi(ELMO)
    ident = eni.slaves[0].identity
    assert (ident.vendor_id, ident.product_code, ident.revision) == (0x9A, 0x30924, 0x10420)
    device = esi.find(ident.vendor_id, ident.product_code, ident.revision)
    assert device is not None
    matches = esi_matches(eni, [esi])
    assert [(m.position, m.exact_revision, m.device) for m in matches] == [(1, True, device)]

    with_esi = _read_sii(Bus(make_chain(eni, EmulateOptions(), esi=[esi])), 0, 0x200)
    from_eni = _read_sii(Bus(make_chain(eni, EmulateOptions())), 0, 0x200)
    assert with_esi == sii_from_esi_device(device)[: 2 * 0x200]
    assert with_esi != from_eni
    read = sii_layout(with_esi + b"\xff" * 64)
    assert (read.vendor_id, read.product_code, read.revision) == (0x9A, 0x30924, 0x10420)
    assert read.name == device.name != sii_layout(from_eni).name
    assert (read.mailbox_out_start, read.mailbox_out_bytes) == (0x1800, 0x8C)


def test_a_revision_fallback_keeps_the_eni_revision() -> None:
    _need(ELMO, ROCOS)
    eni, esi = load_eni(ROCOS), load_esi(ELMO)
    slave = eni.slaves[0]
    other = dataclasses.replace(slave.identity, revision=0x00777777)
    eni = dataclasses.replace(eni, slaves=(dataclasses.replace(slave, identity=other),))
    (match,) = esi_matches(eni, [esi])
    assert not match.exact_revision and match.device.identity.product_code == 0x30924
    layout = make_chain(eni, EmulateOptions(), esi=[esi]).slaves[0].layout
    assert layout.revision == 0x00777777 and layout.name == match.device.name


def test_esi_of_other_devices_leaves_the_eni_sii() -> None:
    lola = load_eni(EXAMPLES / "lola.xml")
    others = [load_esi(p) for p in ESI_FILES if "Elmo" not in p.name]
    expected = [
        i + 1
        for i, s in enumerate(lola.slaves)
        if any(
            f.find(s.identity.vendor_id, s.identity.product_code, s.identity.revision)
            for f in others
        )
    ]
    assert [m.position for m in esi_matches(lola, others)] == expected
    plain = make_chain(lola, EmulateOptions())
    chain = make_chain(lola, EmulateOptions(), esi=others)
    for i, (a, b) in enumerate(zip(plain.slaves, chain.slaves, strict=True), start=1):
        assert (a.sii == b.sii) == (i not in expected)


def test_bus_emulate_refuses_a_hostile_esi_before_opening_a_socket(cli, tmp_path: Path) -> None:
    evil = tmp_path / "evil.xml"
    evil.write_bytes(
        b'<?xml version="1.0"?>\n<!DOCTYPE l [<!ENTITY a "aaaaaaaa"><!ENTITY b "&a;&a;&a;">]>\n'
        b"<EtherCATInfo><Vendor><Id>&b;</Id></Vendor></EtherCATInfo>\n"
    )
    code, out, err = cli("bus", "emulate", "--iface", "lolacli-none0", "--esi", str(evil))
    assert code == 3, err
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "evil.xml:2" in lines[0] and "DOCTYPE" in lines[0]
    assert "Traceback" not in err and "interface" not in err


def test_bus_emulate_missing_esi_is_exit_3(cli, tmp_path: Path) -> None:
    code, _out, err = cli(
        "bus", "emulate", "--iface", "lolacli-none0", "--esi", str(tmp_path / "no.xml")
    )
    assert code == 3 and "no such file" in err


@pytest.mark.root
@pytest.mark.slow
def test_pysoem_config_init_reads_the_esi_identity(emulate, veth, pysoem) -> None:  # noqa: F811
    """SOEM over a veth pair: the single-drive example served with the Elmo ESI."""
    _need(ELMO)
    device = load_esi(ELMO).find(0x9A, 0x30924, 0x10420)
    assert device is not None
    proc = emulate(EXAMPLES / "single_drive.xml", "--esi", str(ELMO))
    master = pysoem.Master()
    try:
        master.open(veth[0])
        assert master.config_init() == 1
        slave = master.slaves[0]
        ident = device.identity
        assert (slave.man, slave.id, slave.rev) == (
            ident.vendor_id,
            ident.product_code,
            ident.revision,
        )
        assert slave.name == device.name  # STRINGS/GENERAL of the ESI image, not the ENI name
        assert slave.name != load_eni(EXAMPLES / "single_drive.xml").slaves[0].name
        assert master.config_map() > 0
        assert struct.unpack("<I", slave.sdo_read(0x1000, 0))[0] == 0x00020192
        assert master.state_check(pysoem.SAFEOP_STATE, 5_000_000) == pysoem.SAFEOP_STATE
        master.state = pysoem.INIT_STATE
        master.write_state()
    finally:
        master.close()
        err = _stop(proc)
    assert "ESI SII: 1 of 1 slaves (1 with the exact revision)" in err
