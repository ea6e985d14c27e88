"""PDO assignment, SII PDO sections, SM control bytes and object access, against every ENI.

A master that does not read the ENI (SOEM, KickCAT) learns the process image from the
slave: over CoE from 0x1C12/0x1C13 and the mapping objects they name, else from the SII
PDO categories. Either way it must come to the ENI's process image, slave by slave.
The CoE side is read here over the wire, through the mailbox, the way SOEM's
``ecx_readPDOmap`` does it; the SII side from the EEPROM image the ESC serves.
"""

from __future__ import annotations

import struct
from pathlib import Path

import pytest

from lolacli.emulator.sii import sii_from_slave, sii_layout, sync_managers_for
from lolacli.emulator.slave import build_chain, with_process_data_pdos
from lolacli.eni.model import Eni, Slave
from lolacli.files import load_eni
from lolacli.wire.sdo import SdoAbort
from lolacli.wire.sii import SmType
from tests.conftest import corpus_files, corpus_ids
from tests.emulator.bus import EXAMPLES, Bus

ENIS = corpus_files("eni", "*.xml") + sorted(EXAMPLES.glob("*.xml"))


def _mailbox(slave: Slave) -> tuple[tuple[int, int], tuple[int, int]]:
    mb = slave.mailbox
    assert mb is not None
    return (mb.out_start, mb.out_length_bytes), (mb.in_start, mb.in_length_bytes)


def _u(raw: object) -> int:
    assert isinstance(raw, bytes), raw
    return int.from_bytes(raw, "little")


def _coe_mapping_bits(bus: Bus, slave: Slave, assign: int) -> int:
    """Bits mapped by the PDOs ``assign`` (0x1C12/0x1C13) lists, read by SDO uploads."""
    mbx = _mailbox(slave)
    station = slave.station_address
    bits = 0
    for n in range(1, _u(bus.sdo_upload(station, assign, 0, mbx)) + 1):
        pdo = _u(bus.sdo_upload(station, assign, n, mbx))
        for k in range(1, _u(bus.sdo_upload(station, pdo, 0, mbx)) + 1):
            bits += _u(bus.sdo_upload(station, pdo, k, mbx)) & 0xFF
    return bits


@pytest.mark.parametrize("path", ENIS, ids=corpus_ids(ENIS))
def test_coe_and_sii_mapping_equal_the_enis_process_image(path: Path) -> None:
    eni = load_eni(path)
    chain = build_chain(eni)
    bus = Bus(chain)
    bus.transition(eni, "IP")  # mailboxes configured, PREOP
    for slave, esc in zip(eni.slaves, chain.slaves, strict=True):
        expected = ((slave.outputs_bits + 7) // 8, (slave.inputs_bits + 7) // 8)
        layout = sii_layout(bytes(esc.sii))
        if not (expected[0] or expected[1]) and not layout.outputs_bytes + layout.inputs_bytes:
            continue
        assert (layout.outputs_bytes, layout.inputs_bytes) == expected, slave.name
        if slave.mailbox is None or not slave.mailbox.out_length_bytes:
            continue
        coe = (
            (_coe_mapping_bits(bus, slave, 0x1C12) + 7) // 8,
            (_coe_mapping_bits(bus, slave, 0x1C13) + 7) // 8,
        )
        assert coe == expected, slave.name


def test_elmo_drives_assign_the_enis_pdos_not_every_pdo_listed(corpus: Path) -> None:
    """rocos eni4: 31 RxPDOs and 35 TxPDOs listed per drive, 5 of each assigned (14/14 B)."""
    eni = load_eni(corpus / "eni" / "rocos-ethercat__eni4.xml")
    slave = eni.slaves[0]
    assert len(slave.pdos) == 66
    chain = build_chain(eni)
    bus = Bus(chain)
    bus.transition(eni, "IP")
    mbx = _mailbox(slave)
    rx = [
        _u(bus.sdo_upload(slave.station_address, 0x1C12, n, mbx))
        for n in range(1, _u(bus.sdo_upload(slave.station_address, 0x1C12, 0, mbx)) + 1)
    ]
    assert rx == [0x160A, 0x160B, 0x160C, 0x160F, 0x161C]
    # the unassigned PDOs still exist as mapping objects, a master may assign them
    assert _u(bus.sdo_upload(slave.station_address, 0x1600, 0, mbx)) > 0


def test_a_slave_without_pdos_in_its_eni_maps_the_enis_sizes(corpus: Path) -> None:
    """rocos eni1 gives its drive's process image only as sizes (16 B out, 14 B in) and
    assigns 0x1605 / 0x1A0A.. by CoE InitCmds: those PDOs carry the bytes."""
    slave = load_eni(corpus / "eni" / "rocos-ethercat__eni1.xml").slaves[0]
    assert slave.pdos == ()
    pdos = with_process_data_pdos(slave).pdos
    assert [hex(p.index) for p in pdos][:2] == ["0x1605", "0x1a0a"]
    assert sum(p.bit_size for p in pdos if p.index < 0x1A00) == 128
    assert sum(p.bit_size for p in pdos if p.index >= 0x1A00) == 112


@pytest.mark.parametrize("bits", [8160, 8161, 0x8000 * 8 + 8, 0xFFFF * 8])
def test_large_areas_without_pdos_fit_the_pdos_and_the_sii(corpus: Path, bits: int) -> None:
    """An area up to what an FMMU maps (0xFFFF bytes): filler entries spread over PDOs and
    filler objects of at most 254 sub-indexes, 64-bit entries past 32 KiB, so the SII's
    PDO category (a byte of entries, a word of length) holds them; it overran a byte from
    255 entries (1020 bytes) on."""
    import re
    from dataclasses import replace

    from lolacli.eni.model import ProcessDataArea

    eni = load_eni(corpus / "eni" / "rocos-ethercat__eni1.xml")
    slave = replace(eni.slaves[0], outputs=(ProcessDataArea(0, bits),))
    pdos = with_process_data_pdos(slave).pdos
    outputs = [p for p in pdos if p.index < 0x1A00]
    assert sum(p.bit_size for p in outputs) == bits
    assert all(1 <= len(p.entries) <= 254 for p in outputs)
    assert all(1 <= e.subindex <= 254 for p in pdos for e in p.entries)
    assert len({(e.index, e.subindex) for p in outputs for e in p.entries}) == sum(
        len(p.entries) for p in outputs
    )  # every filler entry an object entry of its own
    assert len({p.index for p in pdos}) == len(pdos)
    layout = sii_layout(sii_from_slave(with_process_data_pdos(slave)))
    assert layout.outputs_bytes == (bits + 7) // 8
    build_chain(replace(eni, slaves=(slave,)))
    assert re.fullmatch(r"RxPDO 0x16[0-9A-F]{2}", outputs[-1].name)


@pytest.mark.parametrize(
    ("eni_name", "position", "sm"), [("lola.xml", 24, 1), ("ek1100_io.xml", 2, 0)]
)
def test_sm_control_bytes_stay_as_the_eni_gives_them(eni_name: str, position: int, sm: int) -> None:
    slave = load_eni(EXAMPLES / eni_name).slaves[position - 1]
    declared = next(m for m in slave.sync_managers if m.index == sm)
    assert declared.sync_manager.control == 0x00  # an inputs SM: buffered, ECAT reads, no interrupt
    assert sync_managers_for(slave)[sm].sync_manager.control == 0x00
    layout = sii_layout(sii_from_slave(slave))
    assert layout.sync_managers[sm].sync_manager.control == 0x00
    assert layout.sync_managers[sm].type == SmType.INPUTS


def _drive_bus() -> tuple[Bus, Eni, tuple[tuple[int, int], tuple[int, int]]]:
    eni = load_eni(EXAMPLES / "single_drive.xml")
    bus = Bus(build_chain(eni))
    bus.transition(eni, "IP")
    return bus, eni, _mailbox(eni.slaves[0])


def test_input_objects_are_read_only_and_outputs_writable() -> None:
    eni = load_eni(EXAMPLES / "ek1100_io.xml")
    bus = Bus(build_chain(eni))
    bus.transition(eni, "IP")
    inputs = [
        (i, e.index, e.subindex)
        for i, s in enumerate(eni.slaves)
        if s.mailbox is not None and s.mailbox.out_length_bytes
        for p in s.pdos
        if p.direction.name == "INPUT"
        for e in p.entries
        if e.index
    ]
    bus2, drive_eni, mbx = _drive_bus()
    station = drive_eni.slaves[0].station_address
    reply = bus2.sdo_download(station, 0x6041, 0, b"\x00\x00", mbx)  # statusword: an input
    assert isinstance(reply, SdoAbort) and reply.code == 0x06010002
    reply = bus2.sdo_download(station, 0x6040, 0, b"\x06\x00", mbx)  # controlword: an output
    assert not isinstance(reply, SdoAbort)
    for position, index, sub in inputs:  # terminals with a mailbox, if the ENI has any
        slave = eni.slaves[position]
        reply = bus.sdo_download(slave.station_address, index, sub, b"\x01", _mailbox(slave))
        assert isinstance(reply, SdoAbort) and reply.code == 0x06010002


def test_pdo_configuration_is_writable_in_preop_only() -> None:
    bus, eni, mbx = _drive_bus()
    station = eni.slaves[0].station_address
    before = bus.sdo_upload(station, 0x1C12, 1, mbx)
    assert isinstance(before, bytes)
    assert not isinstance(bus.sdo_download(station, 0x1C12, 1, before, mbx), SdoAbort)
    bus.transition(eni, "PS")
    assert bus.chain.slaves[0].al_state == 4  # SAFEOP
    for index, sub, data in ((0x1C12, 1, before), (0x1C12, 0, b"\x00"), (0x1600, 1, bytes(4))):
        reply = bus.sdo_download(station, index, sub, data, mbx)
        assert isinstance(reply, SdoAbort) and reply.code == 0x08000022, hex(index)
    assert bus.sdo_upload(station, 0x1C12, 1, mbx) == before  # reading is always allowed


def test_entry_description_states_the_access_rights_by_state() -> None:
    from lolacli.emulator.slave import device_of
    from lolacli.od import access_word

    bus, _eni, _mbx = _drive_bus()
    device = device_of(bus.chain.slaves[0])
    assert device is not None
    od = device.od
    assert access_word(od.require(0x6041, 0)) & 0x3F == 0x07  # read in every state
    assert access_word(od.require(0x6040, 0)) & 0x3F == 0x3F  # read and write in every state
    assert access_word(od.require(0x1C12, 1)) & 0x3F == 0x0F  # written in PREOP only
    assert struct.unpack("<B", od.entry(0x1C12, 0).value)[0] >= 1
