"""`eni generate`: the ENI of a bus written from a scan of it, checked against the ENI the
emulated bus was made from (every example and corpus ENI the emulator serves).

In process: the bus is :class:`lolacli.simulate.VirtualBus` of the source ENI (the
emulated chain `bus emulate` serves, in virtual time). The generated ENI must name the
same slaves with the same identities and process-data sizes, the same sync managers,
the working counter those slaves give an LRW, and bring that very bus to OP through our
master, cycling without a working-counter mismatch.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from lolacli.eni.diff import diff_eni
from lolacli.eni.model import Eni, Slave
from lolacli.eni.parser import parse_eni
from lolacli.eni.writer import write_eni
from lolacli.files import load_eni
from lolacli.master.core import Master, MasterOptions
from lolacli.master.generate import Generated, GenerateOptions, generate
from lolacli.simulate.bus import VirtualBus
from lolacli.wire.commands import Command, wkc_increment
from lolacli.wire.registers import AlState
from tests.conftest import corpus_files, corpus_ids
from tests.eni.test_examples import EXAMPLES

ENIS = sorted(EXAMPLES.glob("*.xml")) + corpus_files("eni", "*.xml")


def _generate(source: Eni, **options: object) -> tuple[Generated, VirtualBus]:
    bus = VirtualBus(source)
    return generate(bus.transport, options=GenerateOptions(**options), where="virtual"), bus  # type: ignore[arg-type]


def _sms(slave: Slave) -> list[tuple[int, int, int, int]]:
    """The sync managers that carry something: index, start, length, control byte."""
    return [
        (m.index, sm.physical_start, sm.length_bytes, sm.control)
        for m in slave.sync_managers
        if (sm := m.sync_manager).length_bytes
    ]




def _lrw_wkc(eni: Eni) -> int:
    """The working counter an LRW over every slave's process data comes back with."""
    return sum(
        wkc_increment(Command.LRW, read=bool(s.inputs_bits), write=bool(s.outputs_bits))
        for s in eni.slaves
    )


@pytest.mark.parametrize("path", ENIS, ids=corpus_ids(ENIS))
def test_generated_eni_describes_the_bus_it_was_made_from(path: Path) -> None:
    source = load_eni(path)
    result, _bus = _generate(source)
    generated = parse_eni(write_eni(result.eni), "generated.xml")  # what the file says
    slave_changes = [c for c in diff_eni(source, generated) if c.area == "slave"]
    assert slave_changes == [], [c.describe() for c in slave_changes]
    for a, b in zip(source.slaves, generated.slaves, strict=True):
        assert b.identity == a.identity
        assert (b.inputs_bits, b.outputs_bits) == (a.inputs_bits, a.outputs_bits), a.name
        assert _sms(b) == _sms(a), a.name
    lrw = [c for f in generated.cyclic_frames for c in f.commands if c.cmd == Command.LRW]
    if _lrw_wkc(source):
        assert [c.expected_wkc for c in lrw] == [_lrw_wkc(source)]
        assert lrw[0].data_length_bytes == sum(
            max(s.inputs_bits, s.outputs_bits) // 8 for s in generated.slaves
        )
    # a source that moves its process data in one LRW expects the same count
    source_lrw = [c for f in source.cyclic_frames for c in f.commands if c.cmd == Command.LRW]
    if len(source_lrw) == 1 and source_lrw[0].data_length_bytes * 8 >= sum(
        max(s.inputs_bits, s.outputs_bits) for s in source.slaves
    ):
        assert lrw[0].expected_wkc == source_lrw[0].expected_wkc


def test_lola_image_is_the_lola_enis() -> None:
    """The LOLA ENI lays its image out as the generator does: the same sizes, and every
    variable of the same size at the same bit (names differ: the SII names no entry)."""
    source = load_eni(EXAMPLES / "lola.xml")
    generated = _generate(source, cycle_time_ns=500_000)[0].eni
    pi, gi = source.process_image, generated.process_image
    assert (gi.inputs_bytes, gi.outputs_bytes) == (pi.inputs_bytes, pi.outputs_bytes) == (780, 246)
    layout = sorted((v.direction, v.bit_offset, v.bit_size) for v in pi.variables)
    assert sorted((v.direction, v.bit_offset, v.bit_size) for v in gi.variables) == layout
    changes = diff_eni(source, generated)
    # what differs: the DC time distribution (no ESI: no DC) and the variable names
    assert {c.area for c in changes} <= {"cyclic", "variable"}
    assert [c.key for c in changes if c.area == "cyclic"] == ["frame 1 cmd 2", "frame 1 cmd 3"]


@pytest.mark.parametrize("path", ENIS, ids=corpus_ids(ENIS))
def test_generated_eni_brings_the_same_bus_to_op(path: Path) -> None:
    source = load_eni(path)
    result, bus = _generate(source)
    eni = parse_eni(write_eni(result.eni), "generated.xml")
    master = Master(eni, bus.transport, options=MasterOptions(dc_drift_frames=50))
    assert master.bring_up() == []
    assert {esc.al_state for esc in bus.chain.slaves} == {AlState.OP}
    master.run(50)
    master.drain()
    assert master.stats.wkc_mismatches == 0 and master.stats.cyclic_lost == 0
    assert master.stats.wkc_checked >= 50


def test_pdos_from_the_sii_when_coe_is_not_asked(tmp_path: Path) -> None:
    source = load_eni(EXAMPLES / "lola.xml")
    by_coe = _generate(source)[0]
    by_sii = _generate(source, coe=False)[0]
    assert sum(s.pdo_source == "coe" for s in by_coe.slaves) >= 20  # the drives
    assert "coe" not in {s.pdo_source for s in by_sii.slaves}
    assert by_sii.eni.process_image == by_coe.eni.process_image
    assert [s.sync_managers for s in by_sii.eni.slaves] == [
        s.sync_managers for s in by_coe.eni.slaves
    ]


def test_slaves_are_left_in_init() -> None:
    source = load_eni(EXAMPLES / "single_drive.xml")
    _result, bus = _generate(source)
    assert {esc.al_state for esc in bus.chain.slaves} == {AlState.INIT}


def test_cli_writes_the_eni_and_its_summary(cli, tmp_path: Path, monkeypatch) -> None:
    """The command over the emulated LOLA chain (the raw socket swapped for the in-process
    bus): the file is the ENI, the JSON says what went into it."""
    import lolacli.master.transport as transport

    source = load_eni(EXAMPLES / "lola.xml")
    monkeypatch.setattr(transport, "RawSocketTransport", lambda iface: VirtualBus(source).transport)
    out = tmp_path / "bus.xml"
    code, stdout, err = cli("eni", "generate", "--iface", "veth0", "-o", str(out),
                            "--cycle-time", "500us", "--format", "json")  # fmt: skip
    assert code == 0, err
    doc = json.loads(stdout)
    assert doc["schema"] == "lolacli.eni-generate/1"
    assert doc["slave_count"] == 25 and doc["cycle_time_us"] == 500
    assert doc["process_image"] == {
        "inputs_bytes": 780, "outputs_bytes": 246, "variables": 294,
    }  # fmt: skip
    assert [c["expected_wkc"] for c in doc["cyclic_frames"][0]["commands"]] == [70, 25]
    assert load_eni(out).slaves[0].identity == source.slaves[0].identity
    code, human, err = cli("eni", "generate", "--iface", "veth0", "-o", str(out))
    assert code == 0, err
    assert max(len(line) for line in human.splitlines()) <= 80
    words = " ".join(human.split())
    assert "25 slaves;" in words and f"written to {out}" in words
    code, diff, err = cli("eni", "diff", str(EXAMPLES / "lola.xml"), str(out), "--format", "json")
    report = json.loads(diff)
    by_area = report["changes_by_area"]
    assert by_area["slave"] == 0 and by_area["process_image"] == 0


@pytest.mark.parametrize(
    ("args", "code"),
    [
        (["--cycle-time", "0ms"], 2),
        (["--esi", "/nonexistent/x.xml"], 3),
    ],
)
def test_cli_bad_input(cli, tmp_path: Path, args: list[str], code: int) -> None:
    out = tmp_path / "bus.xml"
    got, _out, err = cli("eni", "generate", "--iface", "nosuchif0", "-o", str(out), *args)
    assert got == code, err
    assert not out.exists()


def test_cli_output_over_an_esi_or_a_fifo_is_refused(cli, tmp_path: Path) -> None:
    """The ENI is renamed over its target: an -o that is an --esi given, a FIFO or a
    folder is refused, exit 2, one line, before the bus is touched; nothing changed."""
    import os

    esi = tmp_path / "esi.xml"
    esi.write_text("<EtherCATInfo/>\n")
    os.mkfifo(tmp_path / "fifo")
    for out, args, says in [(esi, ["--esi", str(esi)], "is the same file as --esi"),
                            (tmp_path / "fifo", [], "is a FIFO"),
                            (tmp_path, [], "is a directory")]:
        got, _out, err = cli("eni", "generate", "--iface", "nosuchif0", "-o", str(out), *args)
        assert got == 2 and says in err and err.count("\n") == 1, err
        assert esi.read_text() == "<EtherCATInfo/>\n" and (tmp_path / "fifo").is_fifo()
        assert sorted(p.name for p in tmp_path.iterdir()) == ["esi.xml", "fifo"]


def test_cli_output_into_a_missing_folder(cli, tmp_path: Path) -> None:
    out = tmp_path / "nope" / "bus.xml"
    got, _out, err = cli("eni", "generate", "--iface", "nosuchif0", "-o", str(out))
    assert got == 3 and "no such folder" in err


def test_esi_gives_pdos_sync_managers_and_dc(corpus: Path) -> None:
    """The rocos Elmo drive emulated with the Elmo ESI's SII: with the ESI, the generated
    ENI takes the ESI's default PDO assignment (0x1600/0x1A00, 10 bytes each way: the
    rocos ENI assigns other PDOs), its sync managers, its DC op mode, CoE InitCmds that
    write that assignment, and the bus reaches OP with it."""
    from lolacli.files import load_esi

    source = load_eni(corpus / "eni" / "rocos-ethercat__eni.xml")
    esi = load_esi(corpus / "esi" / "elmo_ethercat_sdk__Elmo_ECAT_00010420_V11.xml")
    device = esi.find(0x9A, 0x30924, 0x10420)
    assert device is not None
    result = generate(VirtualBus(source, esi=[esi]).transport, esi=[esi])
    [origin] = result.slaves
    assert (origin.pdo_source, origin.dc) == ("esi", True)
    [slave] = parse_eni(write_eni(result.eni), "generated.xml").slaves
    assert [(p.index, p.sync_manager) for p in slave.pdos] == [
        (p.index, p.sync_manager) for p in device.assigned_pdos
    ]
    assert (slave.inputs_bits, slave.outputs_bits) == (80, 80)
    esi_sms = {s.index: (s.start_address, s.control) for s in device.sync_managers}
    for m in slave.sync_managers:
        assert (m.sync_manager.physical_start, m.sync_manager.control) == esi_sms[m.index]
    dc_mode = next(m for m in device.dc_op_modes if m.assign_activate)
    assert slave.dc is not None and slave.dc.assign_activate == dc_mode.assign_activate
    assert slave.mailbox is not None
    coe = slave.mailbox.coe_init_cmds
    assigned = [c for c in coe if c.index in (0x1C12, 0x1C13) and c.subindex]
    assert [int.from_bytes(c.data, "little") for c in assigned] == [0x1600, 0x1A00]
    bus = VirtualBus(source, esi=[esi])
    master = Master(result.eni, bus.transport, options=MasterOptions(dc_drift_frames=50))
    assert master.bring_up() == []
    master.run(50)
    master.drain()
    assert master.stats.wkc_mismatches == 0 and master.stats.cyclic_lost == 0
