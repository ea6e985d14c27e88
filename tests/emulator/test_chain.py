"""The chain: direction bit, delay model, faults, and robustness against garbage frames."""

from __future__ import annotations

import os
import random
import struct

from hypothesis import given, settings
from hypothesis import strategies as st

from lolacli.emulator.chain import ChainTiming, Faults
from lolacli.emulator.slave import build_chain
from lolacli.files import load_eni
from lolacli.wire.commands import Command as C
from lolacli.wire.frame import Datagram, decode_frame, encode_frame, frame_bytes_on_wire, make_frame
from tests.emulator.bus import EXAMPLES, Bus

LOLA = load_eni(EXAMPLES / "lola.xml")


def _brd() -> bytes:
    return encode_frame(make_frame([Datagram.physical(C.BRD, 0, 0x0130, 2)]), pad=True)


def test_returned_frame_has_the_locally_administered_bit_and_same_length() -> None:
    chain = build_chain(LOLA)
    frame = _brd()
    reply, _ = chain.process(frame, 0)
    assert reply is not None and len(reply) == len(frame)
    assert decode_frame(reply).ethernet.returned
    assert not decode_frame(frame).ethernet.returned
    assert reply[:6] == frame[:6] and reply[7:12] == frame[7:12]


def test_delay_is_wire_time_plus_slaves_plus_cables() -> None:
    timing = ChainTiming()
    chain = build_chain(LOLA, timing=timing)
    cyclic = LOLA.cyclic_frames[0]
    datagrams = [
        Datagram.logical(c.cmd, c.logical_address, c.data_length_bytes)
        if c.logical_address is not None
        else Datagram.physical(c.cmd, c.adp or 0, c.ado or 0, c.data_length_bytes)
        for c in cyclic.commands
    ]
    frame = encode_frame(make_frame(datagrams))
    _, delay = chain.process(frame, 0)
    wire_bytes = frame_bytes_on_wire([c.data_length_bytes for c in cyclic.commands])
    assert wire_bytes == cyclic.frame_bytes == 846  # DESIGN.md: the LOLA frame
    assert delay == wire_bytes * 80 + 25 * (1000 + 2 * 5)  # 80 ns/byte, 1 µs/slave, 1 m cables
    assert wire_bytes * 80 == 67_680  # 67.7 µs (DESIGN.md)
    # the same number as the timing model predicts for this frame
    from lolacli.timing.model import cable_delay_ns, predict_total_ns, wire_time_ns

    assert delay == predict_total_ns(wire_time_ns(846), 25, 1000, cable_delay_ns([1.0] * 25))


def test_armw_reference_reads_the_others_write() -> None:
    bus = Bus(build_chain(LOLA))
    d = bus.one(C.ARMW, 0, 0x0910, 8)
    assert d.wkc == 25
    assert struct.unpack("<Q", d.data)[0] == bus.chain.slaves[0].system_time_ns(
        bus.t_ns - 50_000 + bus.chain.timing.cable_ns
    )


def test_drop_fault_loses_about_the_asked_share() -> None:
    chain = build_chain(LOLA, faults=Faults(drop_probability=0.25, seed=7))
    frame = _brd()
    lost = sum(chain.process(frame, 0)[0] is None for _ in range(2000))
    assert 400 < lost < 600
    assert chain.stats.dropped == lost


def test_random_and_mutated_frames_never_raise_and_valid_frames_still_answer() -> None:
    eni = load_eni(EXAMPLES / "single_drive.xml")
    chain = build_chain(eni)
    bus = Bus(chain)
    bus.bring_up(eni)
    rng = random.Random(1234)
    valid = [
        encode_frame(
            make_frame(
                [Datagram.logical(C.LRW, 0x10000, 11), Datagram.physical(C.BRD, 0, 0x130, 2)]
            ),
            pad=True,
        ),
        encode_frame(make_frame([Datagram.physical(C.FPWR, 0x3E9, 0x1800, 140)]), pad=True),
        _brd(),
    ]
    malformed = 0
    frames = int(os.environ.get("LOLACLI_FUZZ_FRAMES", "100000"))  # 1 000 000 in slow runs
    for i in range(frames):
        base = bytearray(rng.choice(valid))
        kind = i % 4
        if kind == 0:
            frame = rng.randbytes(rng.randrange(0, 80))
        elif kind == 1:
            for _ in range(rng.randrange(1, 6)):
                base[rng.randrange(12, len(base))] = rng.randrange(256)
            frame = bytes(base)
        elif kind == 2:
            frame = bytes(base[: rng.randrange(0, len(base))])
        else:
            frame = bytes(base[:12]) + b"\x88\xa4" + rng.randbytes(40)
        reply, _ = chain.process(frame, i)
        malformed += reply is None
    assert chain.stats.malformed == malformed > frames // 10
    assert chain.slaves[0].mem[0x0300] == 0xFF  # the invalid-frame counter saturates
    reply, _ = chain.process(_brd(), 0)
    assert reply is not None and decode_frame(reply).datagrams[0].wkc == 1


@settings(max_examples=300, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.sampled_from(list(C)),
            st.integers(0, 0xFFFF),
            st.integers(0, 0x2000),
            st.binary(max_size=64),
        ),
        min_size=1,
        max_size=6,
    )
)
def test_any_well_formed_frame_is_answered(dgrams: list[tuple[C, int, int, bytes]]) -> None:
    chain = build_chain(load_eni(EXAMPLES / "ek1100_io.xml"))
    frame = encode_frame(
        make_frame([Datagram.physical(c, adp, ado, data) for c, adp, ado, data in dgrams]), pad=True
    )
    reply, delay = chain.process(frame, 0)
    assert reply is not None and delay > 0
    back = decode_frame(reply).datagrams
    assert [(d.cmd, d.index, len(d.data)) for d in back] == [
        (c, 0, len(data)) for c, _, _, data in dgrams
    ]
    for d in back:
        assert d.wkc <= 3 * len(chain.slaves)


def test_link_down_fault_shortens_the_line() -> None:
    chain = build_chain(LOLA)
    bus = Bus(chain)
    assert bus.one(C.BRD, 0, 0x0000, 1).wkc == 25
    chain.break_link(10)
    d = bus.one(C.BRD, 0, 0x0110, 2)
    assert d.wkc == 10 and d.adp == 10
    status = struct.unpack("<H", bus.one(C.APRD, (-9) & 0xFFFF, 0x0110, 2).data)[0]
    assert status & 0x0C00 == 0x0400  # slave 10 closed its port 1
    assert bus.one(C.APRD, (-10) & 0xFFFF, 0x0000, 1).wkc == 0
    _, delay = chain.process(_brd(), 0)
    assert delay == chain.timing.round_trip_ns([2], 10)
    chain.break_link(0)
    assert chain.process(_brd(), 0) == (None, 0)
    chain.restore_link()
    assert bus.one(C.BRD, 0, 0x0000, 1).wkc == 25


def test_link_down_position_is_checked(cli) -> None:
    code, _out, err = cli("bus", "emulate", "--iface", "lo", "--link-down", "26")
    assert code == 2
    assert "the chain has slaves 1..25" in err


def _deferred(chain, t_ns: int, cmd: int, adp: int, ado: int, data: bytes | int) -> Datagram:
    """One datagram as the raw-socket server sends it through: the slaves' firmware work
    stays queued until the server runs it, a piece at a time."""
    raw = encode_frame(make_frame([Datagram.physical(cmd, adp, ado, data)]), pad=True)
    reply, _delay = chain.process(raw, t_ns, defer_cycles=True)
    assert reply is not None
    return decode_frame(reply).datagrams[0]


def test_an_al_transition_is_pieces_of_firmware_a_frame_may_come_between() -> None:
    """The check of a SAFEOP request and entering SAFEOP are two pieces, the device's
    take-in into the C core more after them: a frame the master sends meanwhile is
    answered after one short piece, and reads the state not yet entered."""
    eni = load_eni(EXAMPLES / "single_drive.xml")
    chain = build_chain(eni, engine="c")
    bus = Bus(chain)
    bus.transition(eni, "IP")
    bus.transition(eni, "PS")  # the ENI's SM and FMMU set-up, then SAFEOP...
    station = eni.slaves[0].station_address
    assert bus.fpwr(station, 0x0120, b"\x02\x00") == 1  # ...and back to PREOP
    assert chain.slaves[0].al_state == 0x02
    t = bus.t_ns
    assert _deferred(chain, t, C.FPWR, station, 0x0120, b"\x04\x00").wkc == 1
    assert chain.firmware_pending == 1
    chain.run_firmware(1)  # the checks
    assert chain.firmware_pending == 1  # entering SAFEOP comes next
    assert _deferred(chain, t + 10_000, C.FPRD, station, 0x0130, 2).data == b"\x02\x00"
    chain.run_firmware(1)
    assert _deferred(chain, t + 20_000, C.FPRD, station, 0x0130, 2).data == b"\x04\x00"
    core = chain._core
    assert core is not None and 0 in core.devices_released
    core._flat[0] = None  # as when a master's SDO writes in PREOP changed the dictionary
    pieces = 0
    while chain.firmware_pending:  # the take-in: flatten the device again, then load it
        chain.run_firmware(1)
        pieces += 1
    assert pieces == 2 and 0 not in core.devices_released


def test_each_al_control_request_is_handled_as_written() -> None:
    """A master that asks for SAFEOP and then for OP before the slave's firmware came to
    the first (SOEM's config_map, then a write of OP to all) gets SAFEOP and OP pending,
    not a refused PREOP -> OP (0x0011): the firmware of all slaves shares one core here."""
    eni = load_eni(EXAMPLES / "single_drive.xml")
    chain = build_chain(eni, engine="c")
    bus = Bus(chain)
    bus.transition(eni, "IP")
    bus.transition(eni, "PS")
    station = eni.slaves[0].station_address
    assert bus.fpwr(station, 0x0120, b"\x02\x00") == 1
    t = bus.t_ns
    _deferred(chain, t, C.FPWR, station, 0x0120, b"\x04\x00")
    _deferred(chain, t + 10_000, C.BWR, 0, 0x0120, b"\x08\x00")
    while chain.firmware_pending:
        chain.run_firmware(1)
    esc = chain.slaves[0]
    assert (esc.al_state, esc.al_error, esc.al_status_code) == (0x04, False, 0)
    assert esc.pending_op  # OP with the first valid outputs
