"""`bus scan` logic against the emulated chain in process (no root, virtual time): what a
scan reads and writes, differences from ENIs, faults, topology. The same scans over a
veth pair against `bus emulate` and beside pysoem are in test_scan_live.py."""

from __future__ import annotations

import dataclasses
import struct
from pathlib import Path

import pytest

from lolacli.emulator.chain import Chain
from lolacli.emulator.run import EmulateOptions, make_chain
from lolacli.eni.model import Eni
from lolacli.errors import EniError, TransportError, UsageError
from lolacli.files import load_eni
from lolacli.master.scan import (
    ScannedSlave,
    ScanOptions,
    assign_parents,
    decode_error_counters,
    decode_ports,
    parse_state,
    scan,
)
from lolacli.master.transport import ChainTransport
from lolacli.wire.commands import Command
from lolacli.wire.frame import decode_frame
from lolacli.wire.registers import AlState
from tests.conftest import corpus_files
from tests.live import EXAMPLES, LOLA

WRITES = {Command.APWR, Command.FPWR, Command.BWR, Command.APRW, Command.FPRW, Command.BRW}


@pytest.fixture(scope="module")
def lola() -> Eni:
    return load_eni(LOLA)


def _scan(chain: Chain, **kwargs):
    return scan(ChainTransport(chain), **kwargs)


def test_lola_chain_as_found(lola: Eni) -> None:
    chain = make_chain(lola, EmulateOptions())
    report = _scan(chain, eni=lola)
    assert report.slaves_counted == 25 and not report.failed
    assert report.differences == [] and report.findings == []
    for s, want in zip(report.slaves, lola.slaves, strict=True):
        assert s.name == want.name
        ident = s.identity
        assert ident is not None
        assert (ident.vendor_id, ident.product_code, ident.revision, ident.serial) == (
            want.identity.vendor_id,
            want.identity.product_code,
            want.identity.revision,
            want.identity.serial,
        )
        assert s.al_state == "INIT" and s.al_status_code == 0
        assert s.parent == s.position - 1
        assert s.counters is not None and s.counters.total == 0
        assert s.sii is not None and s.sii.header.checksum_ok
        assert s.sii.header.mailbox_protocols == (0x04 if want.mailbox else 0)
    ports = [tuple(p.open for p in s.ports[:2]) for s in report.slaves]
    assert ports == [(True, True)] * 24 + [(True, False)]
    doc = report.to_dict()
    assert doc["schema"] == "lolacli.scan/1" and doc["matches_eni"] is True
    assert doc["slaves"][21]["name"] == "CAN Gateway (IMU, FTS)"


def test_a_scan_configures_nothing(lola: Eni) -> None:
    """No station address, no state request, no counter cleared: the only writes are the
    EEPROM read commands (0x0502)."""
    chain = make_chain(lola, EmulateOptions())
    for esc in chain.slaves:
        esc.count_invalid_frame(1)  # something to keep
    transport = ChainTransport(chain)
    written: list[tuple[int, int]] = []

    def tap(_t: int, frame: bytes, returned: bool) -> None:
        if not returned:
            written.extend((d.cmd, d.ado) for d in decode_frame(frame).datagrams if d.cmd in WRITES)

    transport.taps.append(tap)
    report = scan(transport)
    assert {ado for _cmd, ado in written} == {0x0502}
    assert {cmd for cmd, _ado in written} == {Command.APWR}
    assert all(esc.station_address == 0 and esc.al_state == AlState.INIT for esc in chain.slaves)
    assert [s.counters.invalid_frame[1] for s in report.slaves if s.counters] == [1] * 25


def test_an_eeprom_held_by_the_pdi_is_taken_and_given_back(lola: Eni) -> None:
    chain = make_chain(lola, EmulateOptions())
    chain.slaves[6].mem[0x0500] = 0x01  # offered to the PDI
    report = _scan(chain)
    assert report.slaves[6].name == lola.slaves[6].name
    assert chain.slaves[6].mem[0x0500] == 0x01
    assert chain.slaves[5].mem[0x0500] == 0x00


def test_every_difference_from_another_eni(lola: Eni) -> None:
    """single_drive.xml's drive has Joint01's identity: scanned with the other's ENI, the
    LOLA chain has 24 extra slaves, the one-drive chain ends 24 slaves early."""
    single = load_eni(EXAMPLES / "single_drive.xml")
    report = _scan(make_chain(lola, EmulateOptions()), eni=single)
    assert [(d.kind, d.position) for d in report.differences] == [
        ("extra_slave", k) for k in range(2, 26)
    ]
    assert report.failed and "slave 25 (GPIO 2AI): not in the ENI" in report.differences[-1].message
    report = _scan(make_chain(single, EmulateOptions()), eni=lola)
    assert [(d.kind, d.position) for d in report.differences] == [("line_ends", 1)] + [
        ("missing_slave", k) for k in range(2, 26)
    ]


def test_wrong_revision_and_wrong_slave_are_named(lola: Eni) -> None:
    chain = make_chain(lola, EmulateOptions())
    slaves = list(lola.slaves)
    ident = slaves[6].identity
    slaves[6] = dataclasses.replace(
        slaves[6], identity=dataclasses.replace(ident, revision=ident.revision + 1)
    )
    slaves[22] = dataclasses.replace(
        slaves[22], identity=dataclasses.replace(slaves[22].identity, product_code=0x1234)
    )
    expected = dataclasses.replace(lola, slaves=tuple(slaves))
    report = _scan(chain, eni=expected)
    assert [(d.kind, d.position) for d in report.differences] == [
        ("wrong_revision", 7),
        ("wrong_slave", 23),
    ]
    assert "revision 0x00010420, ENI: 0x00010421" in report.differences[0].message
    assert "GPIO Coupler" in report.differences[1].message


def test_a_cut_line_names_the_last_slave_and_the_missing_ones(lola: Eni) -> None:
    chain = make_chain(lola, EmulateOptions(link_down_after=10))
    report = _scan(chain, eni=lola)
    assert report.slaves_counted == 10
    first = report.differences[0]
    assert (first.kind, first.position) == ("line_ends", 10)
    assert "Joint10 R Hip Pitch" in first.message and "port 1 closed" in first.message
    assert [(d.kind, d.position) for d in report.differences[1:]] == [
        ("missing_slave", k) for k in range(11, 26)
    ]


def test_a_link_lost_while_running_shows_in_the_lost_link_counter(lola: Eni) -> None:
    chain = make_chain(lola, EmulateOptions())
    transport = ChainTransport(chain)
    chain.schedule_link_loss(12, transport.now_ns() + 1_000_000)
    transport.wait_until(transport.now_ns() + 2_000_000)
    report = scan(transport, eni=lola)
    assert report.slaves_counted == 12
    lost = [f for f in report.findings if f.kind == "lost_link"]
    assert [(f.position, f.message) for f in lost] == [
        (12, "slave 12 (Joint12 R Ankle A): lost link counter port 1: 1")
    ]
    assert "lost link counter 1" in report.differences[0].message


def test_stuck_in_safeop_shows_only_after_op_was_asked_for(lola: Eni) -> None:
    chain = make_chain(lola, EmulateOptions(stuck_safeop=(5,)))
    plain = _scan(chain, eni=lola)
    assert not plain.failed and plain.slaves[4].al_state == "INIT"  # nothing to see yet
    report = _scan(chain, eni=lola, options=ScanOptions(state=AlState.OP))
    assert [(d.kind, d.position) for d in report.differences] == [("state_not_reached", 5)]
    message = report.differences[0].message
    assert "SAFEOP+ERR, not OP, AL status code 0x0019 No valid outputs" in message
    assert message.endswith("refused SAFEOP to OP: No valid outputs")
    assert [(r.position, r.transition, r.al_status_code) for r in report.refusals] == [
        (5, "SO", 0x0019)
    ]
    assert [s.al_state for s in report.slaves].count("OP") == 24
    assert all(f.kind != "al_error" for f in report.findings)  # named once, as a difference
    # a later scan without --state reads the error the slave still shows
    after = _scan(chain)
    assert [(f.kind, f.position) for f in after.findings] == [("al_error", 5)]


def test_lost_frames_are_sent_again_and_counted_by_the_first_slave(lola: Eni) -> None:
    chain = make_chain(lola, EmulateOptions(drop_probability=0.2, seed=3))
    report = _scan(chain, eni=lola, options=ScanOptions(retries=10))
    assert not report.failed and report.frames_lost == chain.stats.dropped > 0
    chain.faults.drop_probability = 0.0
    again = _scan(chain)
    counters = again.slaves[0].counters
    assert counters is not None
    assert counters.invalid_frame[0] == counters.rx_error[0] == chain.stats.dropped
    assert [(f.kind, f.position) for f in again.findings] == [("error_counters", 1)]


def test_nothing_answering_is_a_transport_error(lola: Eni) -> None:
    chain = make_chain(lola, EmulateOptions(link_down_after=0))
    with pytest.raises(TransportError, match="no slave answers on veth9"):
        scan(ChainTransport(chain), iface="veth9", options=ScanOptions(retries=1))


def test_state_needs_an_eni_and_a_known_name(lola: Eni) -> None:
    chain = make_chain(lola, EmulateOptions())
    with pytest.raises(UsageError, match="give --eni"):
        _scan(chain, options=ScanOptions(state=AlState.OP))
    assert parse_state("SafeOp") is AlState.SAFEOP and parse_state("pre-op") is AlState.PREOP
    with pytest.raises(UsageError, match="expected init, preop, safeop or op"):
        parse_state("boot")


CORPUS_ENIS = corpus_files("eni", "*.xml")


@pytest.mark.parametrize("path", CORPUS_ENIS, ids=[p.name for p in CORPUS_ENIS])
def test_every_corpus_chain_matches_its_eni(path: Path) -> None:
    """The chain each corpus ENI describes, as the emulator builds it, scans without a
    difference from that ENI (vendors, products, revisions, line length)."""
    try:
        eni = load_eni(path)
        chain = make_chain(eni, EmulateOptions())
    except EniError as exc:  # the emulator refuses some (the simulate tests say which)
        pytest.skip(f"not emulated: {exc}")
    report = _scan(chain, eni=eni)
    assert report.slaves_counted == len(eni.slaves)
    assert report.differences == []
    assert all(s.identity is not None for s in report.slaves)


def test_ports_and_counters_decode_the_register_bits() -> None:
    ports = decode_ports(0x5A31, 0x0F)  # the emulator's middle slave
    assert [(p.physical, p.link, p.loop_closed, p.communication) for p in ports] == [
        ("MII", True, False, True),
        ("MII", True, False, True),
        ("not implemented", False, True, False),
        ("not implemented", False, True, False),
    ]
    raw = bytes([1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 0, 0, 15, 16, 17, 18])
    c = decode_error_counters(raw)
    assert (c.invalid_frame, c.rx_error) == ((1, 3, 5, 7), (2, 4, 6, 8))
    assert (c.forwarded_rx_error, c.processing_unit_error, c.pdi_error) == ((9, 10, 11, 12), 13, 14)
    assert c.lost_link == (15, 16, 17, 18)


def _slave(position: int, open_ports: int) -> ScannedSlave:
    status = 0
    for p in range(open_ports):
        status |= 1 << (4 + p) | 1 << (9 + 2 * p)  # link, communication, loop open
    for p in range(open_ports, 4):
        status |= 1 << (8 + 2 * p)  # loop closed
    return ScannedSlave(position, dl_status=status, port_descriptor=0xFF)


def test_parents_of_a_tree() -> None:
    """A junction (3 ports, like an EK1122) with a branch of one slave, then a line of
    two: SOEM's rule gives the same parents."""
    slaves = [_slave(1, 2), _slave(2, 3), _slave(3, 1), _slave(4, 2), _slave(5, 1)]
    assign_parents(slaves)
    assert [s.parent for s in slaves] == [0, 1, 2, 2, 4]


def test_error_counters_need_twenty_bytes() -> None:
    with pytest.raises(ValueError):
        decode_error_counters(struct.pack("<8B", *range(8)))
