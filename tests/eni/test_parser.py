"""parse_eni: the model it builds, number formats, register decoding, fuzzing."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lolacli.eni.model import ConfiguredFmmu, ConfiguredSyncManager, Direction, InitCmd
from lolacli.eni.parser import (
    fmmus_from_init_cmds,
    parse_eni,
    parse_number,
    sync_managers_from_init_cmds,
)
from lolacli.errors import EniError
from lolacli.files import load_eni
from lolacli.wire.registers import Fmmu, SyncManager
from tests.conftest import CORPUS

FIXTURES = Path(__file__).resolve().parent.parent / "fixtures" / "eni"
VALID = (FIXTURES / "eni-small-valid.xml").read_bytes()


def corpus_eni(name: str):
    path = CORPUS / "eni" / name
    if not path.is_file():
        pytest.skip("corpus not found")
    return load_eni(path)


@pytest.mark.parametrize(
    "text, value",
    [
        ("0", 0),
        ("1001", 1001),
        ("#x1A00", 0x1A00),
        ("#x1a00", 0x1A00),
        ("0x0910", 0x910),
        ("0X10", 16),
        (" 65535 ", 65535),
        ("-1", -1),
        ("#x0", 0),
    ],
)
def test_parse_number(text, value):
    assert parse_number(text) == value


@pytest.mark.parametrize(
    "text",
    ["", "#x", "12a", "0xZZ", "1.5", "one", "\u0663", "\u00b2", "0x-1", "--5", "+-5", "#x 1",
     "1e3", "9" * 5000],
)
def test_parse_number_rejects(text):
    with pytest.raises(ValueError):
        parse_number(text)


@settings(max_examples=200, deadline=None)
@given(
    st.integers(min_value=0, max_value=2**32 - 1),
    st.sampled_from(["{}", "#x{:x}", "#x{:X}", "0x{:04x}"]),
)
def test_parse_number_round_trip(value, form):
    assert parse_number(form.format(value)) == value


def test_fmmu_pinned_from_twincat_export():
    """kpierczy-ethercat-lib__test_eni.xml, slave WheelRearLeft, InitCmd 'set fmmu 0 (outputs)'."""
    block = bytes.fromhex("00080001060000070011000201000000")
    (fmmu,) = fmmus_from_init_cmds([InitCmd(("PS",), 5, 0x1001, 0x0600, block, 1)])
    assert fmmu == ConfiguredFmmu(0, Fmmu(0x01000800, 6, 0, 7, 0x1100, 0, 2, 1))


def test_sync_manager_pinned_from_twincat_export():
    """Same slave, InitCmd 'set sm 3 (inputs)'."""
    block = bytes.fromhex("80110e0020000100")
    (sm,) = sync_managers_from_init_cmds([InitCmd(("PS",), 5, 0x1001, 0x0818, block, 1)])
    assert sm == ConfiguredSyncManager(3, SyncManager(0x1180, 14, 0x20, 0, 1))


def test_small_fixture_model():
    eni = parse_eni(VALID, "small.xml")
    assert eni.source == "small.xml" and eni.root == "EtherCATConfig"
    assert eni.master.name == "Test master"
    assert eni.master.source_mac == bytes.fromhex("020000000001")
    assert eni.master.ethertype == 0x88A4
    assert len(eni.master.init_cmds) == 1 and eni.master.init_cmds[0].ado == 0x130
    coupler, drive, terminal = eni.slaves
    assert [s.position for s in eni.slaves] == [1, 2, 3]
    assert coupler.identity.product_code == 0x044C2C52
    assert drive.identity.vendor_id == 0x9A and drive.identity.product_code == 0x30924
    assert (drive.station_address, drive.auto_inc_address) == (1002, 0xFFFF)
    assert (drive.previous_port, drive.previous_station_address) == ("B", 1001)
    fmmus = [(f.index, f.fmmu.logical_start, f.fmmu.length_bytes, f.fmmu.type) for f in drive.fmmus]
    assert fmmus == [
        (0, 0x10000, 6, 2),
        (1, 0x10000, 8, 1),
    ]
    sms = [(m.index, m.sync_manager.physical_start, m.sync_manager.length_bytes, m.kind)
           for m in drive.sync_managers]
    assert sms == [
        (0, 0x1800, 140, "MBoxOut"),
        (1, 0x1900, 140, "MBoxIn"),
        (2, 0x1100, 6, "Outputs"),
        (3, 0x1180, 8, "Inputs"),
    ]
    assigned = [(p.index, p.direction, p.sync_manager, p.bit_size) for p in drive.pdos]
    assert assigned == [
        (0x1600, Direction.OUTPUT, 2, 48),
        (0x1601, Direction.OUTPUT, None, 32),
        (0x1A00, Direction.INPUT, 3, 64),
    ]
    assert drive.mailbox is not None and drive.mailbox.protocols == ("CoE",)
    (coe,) = drive.mailbox.coe_init_cmds
    assert (coe.index, coe.subindex, coe.data, coe.fixed, coe.ccs) == (0x6060, 0, b"\x08", True, 1)
    assert drive.dc is not None and drive.dc.reference_clock
    assert (drive.dc.cycle_time0_ns, drive.dc.assign_activate) == (500_000, 0x0300)
    validated = [ic for ic in drive.init_cmds if ic.validate_data is not None]
    assert [(ic.validate_data, ic.validate_mask, ic.validate_timeout_ms) for ic in validated] == [
        (b"\x00\x03", b"\xff\xff", 100)
    ]
    assert (drive.inputs_bits, drive.outputs_bits) == (64, 48)
    assert [(m.index, m.kind) for m in terminal.sync_managers] == [(0, "Inputs")]
    assert eni.cycle_time_ns == 500_000
    lrw, brd = eni.cyclic_frames[0].commands
    assert (lrw.logical_address, lrw.adp, lrw.expected_wkc, lrw.states) == (
        0x10000,
        None,
        4,
        ("SAFEOP", "OP"),
    )
    assert (brd.adp, brd.ado, brd.logical_address, brd.input_offset_bytes) == (0, 0x130, None, 10)
    assert eni.cyclic_frames[0].frame_bytes == 64
    pi = eni.process_image
    assert (pi.inputs_bytes, pi.outputs_bytes, len(pi.variables)) == (12, 12, 6)
    assert pi.variables[-1].direction is Direction.OUTPUT


def test_namespaced_document_reads_the_same():
    namespaced = VALID.replace(
        b'<EtherCATConfig Version="1.3">',
        b'<EtherCATConfig xmlns="urn:example:eni" Version="1.3">',
    )
    assert parse_eni(namespaced) == parse_eni(VALID)


@pytest.mark.parametrize("encoding", ["utf-8", "utf-16"])
def test_prefixed_elements_read_the_same(encoding):
    """Elements in a prefixed namespace (``<e:Slave>``), in UTF-8 and UTF-16 (where the
    parser cannot see the prefixes in the bytes and must look at every element)."""
    text = re.sub(r"<(/?)([A-Za-z])", r"<\1e:\2", VALID.decode())
    text = text.replace(
        '<e:EtherCATConfig Version="1.3">',
        '<e:EtherCATConfig xmlns:e="urn:example:eni" Version="1.3">',
    )
    assert text.count("xmlns:e") == 1 and "<e:Slave>" in text
    if encoding == "utf-16":
        text = text.replace('encoding="UTF-8"', 'encoding="UTF-16"')
    data = text.encode(encoding)
    assert parse_eni(data) == parse_eni(VALID)


def test_twincat_export_details():
    eni = corpus_eni("kpierczy-ethercat-lib__test_eni.xml")
    assert len(eni.master.init_cmds) == 12
    wheel = eni.slaves[1]
    assert wheel.name == "WheelRearLeft"
    assert wheel.mailbox is not None and wheel.mailbox.protocols == ("EoE", "CoE", "FoE")
    assert wheel.mailbox.coe_init_cmds[0].index == 0x1C12
    assert wheel.fmmus[0] == ConfiguredFmmu(0, Fmmu(0x01000800, 6, 0, 7, 0x1100, 0, 2, 1))
    assert wheel.dc is not None and wheel.dc.cycle_time0_ns == 10_000_000
    assert [p.index for p in wheel.pdos if p.sync_manager is not None] == [
        0x1601,
        0x1A03,
    ]  # <Sm2><Pdo>5633, <Sm3><Pdo>6659
    assert eni.cyclic[0].comment.startswith("synchronized with task")


def test_elmo_application_studio_quirks():
    eni = corpus_eni("rocos-ethercat__eni1.xml")
    assert eni.cycle_time_ns is None  # no <Cyclic><CycleTime>
    assert eni.master.cycle_time_ns == 1_000_000  # <Master><CycleTime>1000</CycleTime>
    assert eni.cyclic[0].cycle_time_factor == 0
    assert eni.cyclic_frames[0].cycle_time_factor == 0
    (drive,) = eni.slaves
    assert drive.name == "Elmo Drive" and drive.station_address == 1001
    assert len(eni.process_image.variables) == 12  # ElmoSpecialResources variables ignored


def test_encrypted_root_with_plain_body():
    eni = corpus_eni("murrelektronik-variox__eni.xml")
    assert eni.root == "EncryptedEtherCATConfig"
    assert [s.identity.product_code for s in eni.slaves] == [10156485, 54632]


def test_slave_names_keep_their_newline():
    eni = corpus_eni("rocos-ethercat__eni_tech6.xml")
    assert eni.slaves[0].name == "Slave_1001 [RDM\n]"


def test_str_input_is_accepted():
    assert parse_eni(VALID.decode()) == parse_eni(VALID)


@settings(max_examples=150, deadline=None)
@given(st.binary(max_size=400))
def test_random_bytes_raise_only_eni_error(data):
    try:
        parse_eni(data, "fuzz.xml")
    except EniError as exc:
        assert exc.path == "fuzz.xml"


@settings(max_examples=100, deadline=None)
@given(st.integers(min_value=0, max_value=len(VALID) - 1), st.binary(min_size=1, max_size=8))
def test_corrupted_fixture_raises_only_eni_error(at, junk):
    try:
        parse_eni(VALID[:at] + junk + VALID[at + len(junk) :], "c.xml")
    except EniError as exc:
        assert exc.path == "c.xml"


def _without_fmmu_init_cmds(data: bytes) -> bytes:
    """Drop every InitCmd writing FMMU registers 0x0600/0x0610/0x0620 (Ado 1536/1552/1568)."""
    import re

    pattern = (
        rb"<InitCmd>(?:(?!</InitCmd>).)*?<Ado>15(?:36|52|68)</Ado>(?:(?!</InitCmd>).)*?</InitCmd>"
    )
    stripped, count = re.subn(pattern, b"", data, flags=re.S)
    assert count > 0
    return stripped


def _process_fmmus(slave) -> list[tuple]:
    return [
        (
            f.logical_start,
            f.length_bytes,
            f.logical_start_bit,
            f.logical_stop_bit,
            f.physical_start,
            f.type,
        )
        for f in (c.fmmu for c in slave.fmmus)
        if f.length_bytes and f.type in (1, 2) and f.physical_start != 0x080D  # not mailbox state
    ]


@pytest.mark.parametrize(
    "name",
    [
        "kpierczy-ethercat-lib__test_eni.xml",  # TwinCAT: image offsets follow the frame
        "rocos-ethercat__eni7.xml",  # acontis: offsets point at the data
        "rocos-ethercat__eni1.xml",  # Elmo: separate LRD + LWR
    ],
)
def test_fmmus_from_process_data_equal_the_init_cmd_ones(name):
    """With the FMMU InitCmds removed, <ProcessData> + cyclic commands give the same FMMUs."""
    path = CORPUS / "eni" / name
    if not path.is_file():
        pytest.skip("corpus not found")
    data = path.read_bytes()
    full, bare = parse_eni(data), parse_eni(_without_fmmu_init_cmds(data))
    for a, b in zip(full.slaves, bare.slaves, strict=True):
        assert _process_fmmus(b) == _process_fmmus(a) != [] or not (a.inputs or a.outputs)


def test_fmmus_from_process_data_on_the_small_fixture():
    bare = parse_eni(_without_fmmu_init_cmds(VALID))
    assert _process_fmmus(bare.slaves[1]) == [
        (0x10000, 6, 0, 7, 0x1100, 2),
        (0x10000, 8, 0, 7, 0x1180, 1),
    ]
    assert _process_fmmus(bare.slaves[2]) == [(0x10008, 2, 0, 7, 0x1000, 1)]
