"""Fault injection: each fault's effect on the replies (WKC) and on the ESC error
counters 0x0300..0x0313 as a master reads them back, on planned cyclic frames too."""

from __future__ import annotations

import struct

import pytest

from lolacli.emulator import registers as r
from lolacli.emulator.chain import Chain, Faults
from lolacli.emulator.registers import AlState
from lolacli.emulator.run import EmulateOptions, make_chain, parse_link_down
from lolacli.emulator.slave import build_chain
from lolacli.errors import UsageError
from lolacli.files import load_eni
from lolacli.wire.commands import Command as C
from lolacli.wire.registers import AlStatusCode
from tests.emulator.bus import EXAMPLES, Bus
from tests.emulator.test_esc import _addressed_dc_chain

LOLA = load_eni(EXAMPLES / "lola.xml")
SLAVES = len(LOLA.slaves)
COUNTERS = r.ERROR_COUNTERS_END - r.RX_ERROR_COUNTER  # 0x0300..0x0313


def _counters(bus: Bus, position: int) -> bytes:
    """Error counters of the slave at 1-based ``position``, read with APRD like a master."""
    d = bus.one(C.APRD, (1 - position) & 0xFFFF, r.RX_ERROR_COUNTER, COUNTERS)
    assert d.wkc == 1
    return d.data


def _quiet(chain: Chain) -> None:
    chain.faults.corrupt_probability = 0.0
    chain.faults.drop_probability = 0.0


def _cyclic_wkc(bus: Bus) -> list[int]:
    return [d.wkc for d in bus.cycle(LOLA)[0]]


def _expected_cyclic_wkc() -> list[int]:
    return [c.expected_wkc or 0 for c in LOLA.cyclic_frames[0].commands]


def test_corrupt_at_slave_stops_processing_and_counts_like_escs() -> None:
    chain = build_chain(LOLA, faults=Faults(corrupt_probability=1.0, corrupt_at_slave=3))
    bus = Bus(chain)
    for _ in range(4):
        d = bus.one(C.BRD, 0, r.DL_STATUS, 2)
        assert d.wkc == 3  # slaves 4..25 discard the damaged frame
    d = bus.one(C.APRD, (-5) & 0xFFFF, r.DL_STATUS, 2)
    assert d.wkc == 0 and d.adp == (-5 + 3) & 0xFFFF  # only three slaves incremented it
    assert chain.stats.corrupted == 5
    _quiet(chain)
    assert bus.one(C.BRD, 0, r.DL_STATUS, 2).wkc == SLAVES
    first = _counters(bus, 1)
    assert first[0] == 0 and first[8] == 0 and first[9] == 5  # port 1 back: forwarded
    assert _counters(bus, 3)[0] == 0
    fourth = _counters(bus, 4)
    assert fourth[0] == 5 and fourth[1] == 0 and fourth[8] == 0  # bad FCS on port 0
    assert fourth[9] == 5
    for position in (5, 12, SLAVES):
        c = _counters(bus, position)
        assert c[0] == 0 and c[8] == 5  # marked by slave 4: forwarded RX error port 0
        assert c[9] == (0 if position == SLAVES else 5)
    assert all(c == 0 for c in _counters(bus, 7)[0x10:])  # no link lost


def test_corrupt_in_the_last_loop_back_keeps_all_wkc() -> None:
    chain = build_chain(LOLA, faults=Faults(corrupt_probability=1.0, corrupt_at_slave=SLAVES))
    bus = Bus(chain)
    assert bus.one(C.BRD, 0, 0, 1).wkc == SLAVES
    _quiet(chain)
    assert _counters(bus, SLAVES - 1)[2] == 1  # invalid frame on port 1
    assert _counters(bus, 1)[9] == 1


def test_random_corruption_share_and_one_invalid_frame_count_each() -> None:
    chain = build_chain(LOLA, faults=Faults(corrupt_probability=0.2, seed=11))
    bus = Bus(chain)
    low = sum(bus.one(C.BRD, 0, 0, 1).wkc < SLAVES for _ in range(1000))
    assert 150 < low < 250
    assert chain.stats.corrupted >= low  # damage at the master's cable also gives 0
    _quiet(chain)
    invalid = sum(_counters(bus, p)[0] for p in range(1, SLAVES + 1))
    assert invalid == chain.stats.corrupted  # each damaged frame fails one FCS check


def test_corruption_bypasses_the_frame_plan_of_the_cyclic_frame() -> None:
    chain = build_chain(LOLA)
    bus = Bus(chain)
    bus.bring_up(LOLA)
    for _ in range(5):
        assert _cyclic_wkc(bus) == _expected_cyclic_wkc()
    planned = chain.stats.planned_frames
    assert planned >= 3
    chain.faults.corrupt_at_slave = 2
    chain.faults.corrupt_probability = 1.0
    for _ in range(3):
        wkc = _cyclic_wkc(bus)
        assert wkc != _expected_cyclic_wkc() and sum(wkc) < sum(_expected_cyclic_wkc())
    assert chain.stats.planned_frames == planned and chain.stats.corrupted == 3
    _quiet(chain)
    for _ in range(3):
        assert _cyclic_wkc(bus) == _expected_cyclic_wkc()
    assert chain.stats.planned_frames > planned
    assert _counters(bus, 3)[0] == 3


def test_dropped_frames_count_on_the_first_slaves_port_0_planned_or_not() -> None:
    chain = build_chain(LOLA)
    bus = Bus(chain)
    bus.bring_up(LOLA)
    for _ in range(4):
        bus.cycle(LOLA)
    chain.faults.drop_probability = 1.0
    with pytest.raises(AssertionError):
        bus.cycle(LOLA)  # nothing comes back
    with pytest.raises(AssertionError):
        bus.one(C.BRD, 0, 0, 1)
    assert chain.stats.dropped == 2
    _quiet(chain)
    first = _counters(bus, 1)
    assert first[0] == 2 and first[1] == 2  # invalid frame and RX error, port 0
    assert all(b == 0 for b in _counters(bus, 2))


def test_scheduled_link_loss_before_and_after_its_time() -> None:
    chain = build_chain(LOLA)
    bus = Bus(chain)
    bus.bring_up(LOLA)
    at_ns = bus.t_ns + 10_000_000
    chain.schedule_link_loss(after=10, at_ns=at_ns)
    while bus.t_ns + 1_000_000 < at_ns:  # planned cyclic frames up to the cut
        assert _cyclic_wkc(bus) == _expected_cyclic_wkc()
    assert bus.one(C.BRD, 0, 0, 1).wkc == SLAVES
    status = struct.unpack("<H", bus.one(C.APRD, (-9) & 0xFFFF, r.DL_STATUS, 2).data)[0]
    assert status & 0x0C20 == 0x0820  # port 1 open, link, communication
    assert _counters(bus, 10)[0x11] == 0
    bus.t_ns = at_ns
    wkc = _cyclic_wkc(bus)
    assert sum(wkc) < sum(_expected_cyclic_wkc())
    assert bus.one(C.BRD, 0, 0, 1).wkc == 10
    status = struct.unpack("<H", bus.one(C.APRD, (-9) & 0xFFFF, r.DL_STATUS, 2).data)[0]
    assert status & 0x0C20 == 0x0400  # port 1: loop closed, no link
    tenth = _counters(bus, 10)
    assert tenth[0x11] == 1 and tenth[0x10] == 0  # lost link counter, port 1
    assert chain.stats.links_lost == 1
    chain.restore_link()
    assert _counters(bus, 11)[0x10] == 1  # the slave behind lost its port 0 link
    assert bus.one(C.BRD, 0, 0, 1).wkc == SLAVES


def test_link_loss_position_is_checked() -> None:
    chain = build_chain(LOLA)
    with pytest.raises(UsageError, match="1..25"):
        chain.schedule_link_loss(after=26, at_ns=0)
    with pytest.raises(UsageError, match="1..25"):
        make_chain(LOLA, EmulateOptions(link_down_after=26, link_down_at_s=1.0))


def test_stuck_in_safeop_answers_op_request_with_al_status_code() -> None:
    chain = make_chain(LOLA, EmulateOptions(stuck_safeop=(3,)))
    bus = Bus(chain)
    bus.transition(LOLA, "IP")
    bus.transition(LOLA, "PS")
    bus.cycle(LOLA)
    assert bus.one(C.BWR, 0, r.AL_CONTROL, struct.pack("<H", AlState.OP)).wkc == SLAVES
    bus.cycle(LOLA)
    assert bus.one(C.BRD, 0, r.AL_STATUS, 2).wkc == SLAVES
    status = struct.unpack("<H", bus.one(C.APRD, (-2) & 0xFFFF, r.AL_STATUS, 2).data)[0]
    code = struct.unpack("<H", bus.one(C.APRD, (-2) & 0xFFFF, r.AL_STATUS_CODE, 2).data)[0]
    assert status == AlState.SAFEOP | 0x10  # error indication bit (ETG.1000.6 AL status)
    assert code == AlStatusCode.NO_VALID_OUTPUTS
    other = struct.unpack("<H", bus.one(C.APRD, (-3) & 0xFFFF, r.AL_STATUS, 2).data)[0]
    assert other == AlState.OP


def test_dc_drift_makes_the_system_time_difference_grow() -> None:
    diffs = {}
    for drift in (0, 20_000):
        chain, bus = _addressed_dc_chain(drift_ppb=drift)
        grown = []
        for _ in range(3):
            bus.t_ns += 20_000_000
            bus.one(C.FRMW, 0x1000, r.DC_SYSTEM_TIME, 8)
            raw = bus.fprd(0x1000 + SLAVES - 1, r.DC_SYSTEM_TIME_DIFFERENCE, 4)
            grown.append(abs(chain.slaves[-1].system_time_difference_ns))
            assert raw == chain.slaves[-1].mem[0x092C:0x0930]
        diffs[drift] = grown
    assert max(diffs[0]) < 100
    first, second, third = diffs[20_000]
    assert 9_000 < first < 10_000  # the last slave runs 480 ppm fast: 9.6 µs in 20 ms
    assert first < second < third  # the single FRMW per 20 ms cannot catch up


def test_parse_link_down() -> None:
    assert parse_link_down("3") == (3, 0.0)
    assert parse_link_down("3@1.5") == (3, 1.5)
    # the form the issue writes, and any duration unit
    assert parse_link_down("5@0.5s") == parse_link_down("5@500ms") == (5, 0.5)
    for bad in ("x", "3@", "3@0", "3@-1", "-1", "3@abc", "3@1@2"):
        with pytest.raises(UsageError):
            parse_link_down(bad)


@pytest.mark.parametrize(
    "args",
    [
        ("--corrupt-p", "1.5"),
        ("--corrupt-p", "-0.1"),
        ("--corrupt-p", "abc"),
        ("--link-down", "3@x"),
        ("--link-down", "3@0"),
        ("--link-down", "26@1.5"),
    ],
)
def test_bad_fault_flags_exit_2(cli, args: tuple[str, str]) -> None:
    code, _out, err = cli("bus", "emulate", "--iface", "nosuchif0", *args)
    assert code == 2, err
    assert "nosuchif0" not in err  # refused before any socket


def test_good_fault_flags_reach_the_socket(cli) -> None:
    code, _out, err = cli(
        "bus", "emulate", "--iface", "nosuchif0", "--corrupt-p", "0.01", "--link-down", "3@1.5"
    )
    assert code == 4, err
    assert "no such interface: nosuchif0" in err


def test_clearing_rx_error_counters_keeps_the_lost_link_counters() -> None:
    chain = build_chain(LOLA, faults=Faults(corrupt_probability=1.0, corrupt_at_slave=1))
    bus = Bus(chain)
    bus.one(C.BRD, 0, 0, 1)
    _quiet(chain)
    chain.schedule_link_loss(after=1, at_ns=bus.t_ns)
    assert bus.one(C.BRD, 0, 0, 1).wkc == 1
    chain.restore_link()
    assert _counters(bus, 2)[0] == 1 and _counters(bus, 2)[0x10] == 1
    assert bus.one(C.BWR, 0, r.RX_ERROR_COUNTER, 8).wkc == SLAVES  # as SOEM's config_init
    second = _counters(bus, 2)
    assert second[0] == 0 and second[0x10] == 1  # the lost link group stays
    bus.one(C.BWR, 0, r.LOST_LINK_COUNTER, 1)
    assert _counters(bus, 2)[0x10] == 0
