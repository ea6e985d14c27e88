"""ESC behaviour, frame bytes in -> frame bytes out: addressing, WKC, AL states, SII,
mailbox handshake, FMMU bit mapping, DC."""

from __future__ import annotations

import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lolacli.emulator import registers as r
from lolacli.emulator.chain import Chain, ChainTiming
from lolacli.emulator.esc import Esc
from lolacli.emulator.esc.memory import register_write
from lolacli.emulator.registers import AlState
from lolacli.emulator.sii import sii_from_slave
from lolacli.emulator.slave import build_chain
from lolacli.files import load_eni
from lolacli.wire.commands import Command as C
from lolacli.wire.frame import Datagram
from lolacli.wire.registers import AlStatusCode
from tests.emulator.bus import EXAMPLES, Bus


@pytest.fixture
def lola_bus() -> Bus:
    return Bus(build_chain(load_eni(EXAMPLES / "lola.xml")))


@pytest.fixture
def drive_bus() -> Bus:
    return Bus(build_chain(load_eni(EXAMPLES / "single_drive.xml")))


def test_brd_counts_every_slave_and_ors_data(lola_bus: Bus) -> None:
    d = lola_bus.one(C.BRD, 0, r.TYPE, 2)
    assert d.wkc == 25
    assert d.adp == 25  # every slave incremented ADP
    assert d.data == bytes([0x11, 0x02])


def test_auto_increment_addresses_the_slave_that_sees_zero(lola_bus: Bus) -> None:
    # ADP = -2 reaches the third slave: write its station address, read it back
    assert lola_bus.one(C.APWR, 0xFFFE, r.STATION_ADDRESS, struct.pack("<H", 0x1234)).wkc == 1
    assert lola_bus.chain.slaves[2].station_address == 0x1234
    assert lola_bus.chain.slaves[1].station_address == 0
    d = lola_bus.one(C.APRD, 0xFFFE, r.STATION_ADDRESS, 2)
    assert (d.wkc, d.data, d.adp) == (1, b"\x34\x12", (0xFFFE + 25) & 0xFFFF)
    assert lola_bus.one(C.APRD, 25, r.STATION_ADDRESS, 2).wkc == 0  # past the end


def test_configured_address_and_alias(drive_bus: Bus) -> None:
    esc = drive_bus.chain.slaves[0]
    drive_bus.one(C.APWR, 0, r.STATION_ADDRESS, struct.pack("<H", 0x03E9))
    assert drive_bus.one(C.FPRD, 0x03E9, r.AL_STATUS, 2).wkc == 1
    assert drive_bus.one(C.FPRD, 0x03EA, r.AL_STATUS, 2).wkc == 0
    esc.mem[r.STATION_ALIAS : r.STATION_ALIAS + 2] = struct.pack("<H", 0x0777)
    assert drive_bus.one(C.FPRD, 0x0777, r.AL_STATUS, 2).wkc == 0  # alias not enabled
    drive_bus.one(C.FPWR, 0x03E9, r.DL_CONTROL_ALIAS_ENABLE_BYTE, b"\x01")
    assert drive_bus.one(C.FPRD, 0x0777, r.AL_STATUS, 2).wkc == 1


def test_read_write_wkc_is_three_and_read_only_registers_hold(drive_bus: Bus) -> None:
    d = drive_bus.one(C.APRW, 0, r.STATION_ADDRESS, struct.pack("<H", 0x1001))
    assert d.wkc == 3 and d.data == b"\x00\x00"
    assert drive_bus.one(C.APRD, 0, r.STATION_ADDRESS, 2).data == b"\x01\x10"
    drive_bus.one(C.APWR, 0, r.TYPE, b"\xaa\xbb")  # ESC information is read-only
    assert drive_bus.one(C.APRD, 0, r.TYPE, 2).data == b"\x11\x02"


def test_al_state_machine_refusals_and_acknowledge(drive_bus: Bus) -> None:
    esc = drive_bus.chain.slaves[0]
    drive_bus.one(C.APWR, 0, r.AL_CONTROL, b"\x04\x00")  # INIT -> SAFEOP
    assert esc.al_state == AlState.INIT and esc.al_error
    assert esc.al_status_code == AlStatusCode.INVALID_REQUESTED_STATE_CHANGE
    status = drive_bus.one(C.APRD, 0, r.AL_STATUS, 6).data
    assert status[0] == 0x11 and struct.unpack_from("<H", status, 4)[0] == 0x0011
    drive_bus.one(C.APWR, 0, r.AL_CONTROL, b"\x02\x00")  # not acknowledged: ignored
    assert esc.al_error and esc.al_state == AlState.INIT
    drive_bus.one(C.APWR, 0, r.AL_CONTROL, b"\x12\x00")  # ack + PREOP, mailbox SMs unset
    assert esc.al_state == AlState.INIT and esc.al_error
    assert esc.al_status_code == AlStatusCode.INVALID_MAILBOX_CONFIGURATION_PREOP
    drive_bus.one(C.APWR, 0, r.AL_CONTROL, b"\x16\x00")  # ack + unknown state 6
    assert esc.al_status_code == AlStatusCode.UNKNOWN_REQUESTED_STATE
    drive_bus.one(C.APWR, 0, r.AL_CONTROL, b"\x11\x00")  # ack + INIT
    assert not esc.al_error and esc.al_status_code == 0
    drive_bus.one(C.APWR, 0, r.AL_CONTROL, b"\x13\x00")  # BOOT
    assert esc.al_status_code == AlStatusCode.INVALID_MAILBOX_CONFIGURATION_BOOT  # SMs unset


def _configure_mailbox(bus: Bus) -> None:
    bus.one(C.APWR, 0, r.STATION_ADDRESS, struct.pack("<H", 0x03E9))
    bus.one(C.FPWR, 0x03E9, 0x0800, bytes.fromhex("00188c0026000100 00198c0022000100"))


def test_preop_to_safeop_needs_consistent_process_sync_managers(drive_bus: Bus) -> None:
    esc = drive_bus.chain.slaves[0]
    _configure_mailbox(drive_bus)
    drive_bus.fpwr(0x03E9, r.AL_CONTROL, b"\x02\x00")
    assert esc.al_state == AlState.PREOP
    drive_bus.fpwr(0x03E9, 0x0810, bytes.fromhex("00110a0064000100"))  # 10 bytes, needs 11
    drive_bus.fpwr(0x03E9, 0x0818, bytes.fromhex("80110b0020000100"))
    drive_bus.fpwr(0x03E9, r.AL_CONTROL, b"\x04\x00")
    assert esc.al_state == AlState.PREOP
    assert esc.al_status_code == AlStatusCode.INVALID_OUTPUT_CONFIGURATION
    drive_bus.fpwr(0x03E9, 0x0810, bytes.fromhex("00110b0064000100"))
    drive_bus.fpwr(0x03E9, 0x0818, bytes.fromhex("80110a0020000100"))
    drive_bus.fpwr(0x03E9, r.AL_CONTROL, b"\x14\x00")
    assert esc.al_status_code == AlStatusCode.INVALID_INPUT_CONFIGURATION
    drive_bus.fpwr(0x03E9, 0x0818, bytes.fromhex("80110b0020000100"))
    drive_bus.fpwr(0x03E9, r.AL_CONTROL, b"\x14\x00")
    assert esc.al_state == AlState.SAFEOP and not esc.al_error


def test_stuck_in_safeop_fault(drive_bus: Bus) -> None:
    eni = load_eni(EXAMPLES / "single_drive.xml")
    drive_bus.chain.stuck_in_safeop(1)
    drive_bus.transition(eni, "IP")
    drive_bus.transition(eni, "PS")
    drive_bus.cycle(eni)
    drive_bus.fpwr(0x03E9, r.AL_CONTROL, b"\x08\x00")
    esc = drive_bus.chain.slaves[0]
    assert esc.al_state == AlState.SAFEOP and esc.al_error
    assert esc.al_status_code == AlStatusCode.NO_VALID_OUTPUTS


@pytest.mark.parametrize("eight_bytes", [True, False])
def test_sii_read_through_the_eeprom_interface(eight_bytes: bool) -> None:
    from lolacli.emulator.esc import EscConfig

    slave = load_eni(EXAMPLES / "single_drive.xml").slaves[0]
    sii = sii_from_slave(slave)
    bus = Bus(Chain([Esc(sii, config=EscConfig(eeprom_8_byte_reads=eight_bytes))]))
    status = bus.one(C.APRD, 0, r.SII_CONTROL_STATUS, 2).data
    assert bool(status[0] & 0x40) == eight_bytes  # ESC advertises 4- or 8-byte reads
    # SOEM style: control word + address in one 6-byte write, then read the data register
    assert bus.one(C.APWR, 0, r.SII_CONTROL_STATUS, struct.pack("<HHH", 0x0100, 0x0008, 0)).wkc == 1
    assert not bus.one(C.APRD, 0, r.SII_CONTROL_STATUS, 2).data[1] & 0x80  # not busy
    data = bus.one(C.APRD, 0, r.SII_DATA, 8).data
    n = 8 if eight_bytes else 4
    assert data[:n] == sii[16 : 16 + n]
    assert struct.unpack_from("<I", data)[0] == slave.identity.vendor_id


def test_sii_reload_command_is_0x0400() -> None:
    """ET1100 datasheet, 0x0502 bits 8-10: 001 read, 010 write, 100 reload; others are
    invalid commands (the emulated ESC took 0x0300 for reload until the codes came from wire)."""
    slave = load_eni(EXAMPLES / "single_drive.xml").slaves[0]
    sii = bytearray(sii_from_slave(slave))
    sii[8:10] = (0x4321).to_bytes(2, "little")  # word 4: configured station alias
    bus = Bus(Chain([Esc(bytes(sii))]))
    bus.one(C.APWR, 0, r.STATION_ALIAS, b"\x00\x00")
    assert bus.one(C.APWR, 0, r.SII_CONTROL_STATUS, struct.pack("<HHH", 0x0300, 0, 0)).wkc == 1
    assert bus.one(C.APRD, 0, r.SII_CONTROL_STATUS, 2).data[1] & 0x20  # command error
    assert bus.one(C.APWR, 0, r.SII_CONTROL_STATUS, struct.pack("<HHH", 0x0400, 0, 0)).wkc == 1
    assert not bus.one(C.APRD, 0, r.SII_CONTROL_STATUS, 2).data[1] & 0x20
    assert bus.one(C.APRD, 0, r.STATION_ALIAS, 2).data == b"\x21\x43"


def test_mailbox_handshake_full_bit_blocks_and_read_empties(drive_bus: Bus) -> None:
    _configure_mailbox(drive_bus)
    drive_bus.fpwr(0x03E9, r.AL_CONTROL, b"\x02\x00")
    esc = drive_bus.chain.slaves[0]
    esc.post_mailbox(b"\x0a\x00" + bytes(4) + b"unsolicit!")
    assert drive_bus.fprd(0x03E9, 0x080D, 1)[0] & 0x08
    esc.post_mailbox(b"\x02\x00" + bytes(4) + b"2nd")
    partial = drive_bus.fprd(0x03E9, 0x1900, 16)  # not up to the last byte: stays full
    assert partial[6:16] == b"unsolicit!"
    assert drive_bus.fprd(0x03E9, 0x080D, 1)[0] & 0x08
    drive_bus.fprd(0x03E9, 0x1900, 140)  # reads the last byte: next message posted
    assert drive_bus.fprd(0x03E9, 0x1900, 140)[6:9] == b"2nd"
    assert not drive_bus.fprd(0x03E9, 0x080D, 1)[0] & 0x08
    assert drive_bus.one(C.FPRD, 0x03E9, 0x1900, 140).wkc == 0  # empty mailbox: no WKC


def test_a_mailbox_written_in_init_reaches_no_protocol(drive_bus: Bus) -> None:
    """A master whose PREOP request was lost writes its SDO request to a slave still in
    INIT: the firmware keeps its mailbox SMs deactivated there from power-on (as after
    any return to INIT), so no protocol answers, not even with a mailbox error. After
    PREOP the same request is served."""
    _configure_mailbox(drive_bus)
    upload = bytes.fromhex("0a00 0000 0013 0020 4000 1000 00000000")  # SDO upload 0x1000
    assert drive_bus.fprd(0x03E9, 0x0807, 1)[0] & 0x01  # SM0: deactivated by the PDI
    drive_bus.fpwr(0x03E9, 0x1800, upload + bytes(140 - len(upload)))
    assert not drive_bus.fprd(0x03E9, 0x080D, 1)[0] & 0x08  # nothing in the read mailbox
    drive_bus.fpwr(0x03E9, r.AL_CONTROL, b"\x02\x00")
    assert drive_bus.chain.slaves[0].al_state == AlState.PREOP
    drive_bus.fpwr(0x03E9, 0x1800, upload + bytes(140 - len(upload)))
    answer = drive_bus.fprd(0x03E9, 0x1900, 140)
    assert answer[5] & 0x0F == 3 and answer[8] >> 5 == 2  # CoE, SDO upload response


def test_fmmu_bit_granular_mapping_and_wkc() -> None:
    eni = load_eni(EXAMPLES / "ek1100_io.xml")
    bus = Bus(build_chain(eni))
    bus.bring_up(eni)
    do8 = bus.chain.slaves[2]
    # remap the DO terminal's FMMU: logical 0x20000 bits 4..7 -> physical 0x0F00 bits 0..3
    fmmu = struct.pack("<IHBBHBBB3x", 0x20000, 1, 4, 7, 0x0F00, 0, 2, 1)
    assert bus.fpwr(0x03EB, 0x0600, fmmu) == 1
    d = bus.frame(Datagram.logical(C.LWR, 0x20000, b"\xa5"))[0]
    assert d.wkc == 1
    assert do8.mem[0x0F00] & 0x0F == 0x0A  # high nibble of 0xA5
    d = bus.frame(Datagram.logical(C.LRW, 0x20000, b"\x5f"))[0]
    assert d.wkc == 2  # a write-only FMMU adds 2 for LRW


def test_dc_receive_time_latch_and_system_time() -> None:
    eni = load_eni(EXAMPLES / "lola.xml")
    bus = Bus(build_chain(eni))
    bus.one(C.BWR, 0, r.DC_RECEIVE_TIME_PORT0, 4)
    first, second = bus.chain.slaves[0], bus.chain.slaves[1]
    t0_a, t1_a = struct.unpack_from("<II", first.mem, 0x0900)
    t0_b, t1_b = struct.unpack_from("<II", second.mem, 0x0900)
    # the loop through slave 2 and beyond takes longer than the loop beyond slave 3
    loop_a = (t1_a - t0_a) & 0xFFFFFFFF
    loop_b = (t1_b - t0_b) & 0xFFFFFFFF
    assert loop_a > loop_b > 0
    timing = bus.chain.timing
    assert loop_a - loop_b == 2 * timing.cable_ns + timing.processing_ns + timing.forward_ns
    last = bus.chain.slaves[-1]
    assert struct.unpack_from("<I", last.mem, 0x0904)[0] == 0  # last port 1 closed
    # system time = local time + offset; offsets written by the master
    bus.one(C.APWR, 0, r.STATION_ADDRESS, struct.pack("<H", 0x100))
    offset = -first.clock.local_ns(bus.t_ns) + 10**12
    bus.fpwr(0x100, r.DC_SYSTEM_TIME_OFFSET, struct.pack("<q", offset))
    systime = struct.unpack("<Q", bus.fprd(0x100, r.DC_SYSTEM_TIME, 8))[0]
    assert abs(systime - 10**12) < 1_000_000


def _addressed_dc_chain(drift_ppb: int) -> tuple[Chain, Bus]:
    """Station addresses, then delay and offset compensation the way SOEM's config_dc
    does it: propagation delays from the latched port receive times of a line."""
    timing = ChainTiming(processing_ns=500, forward_ns=500, cable_ns=10)  # symmetric ports
    chain = build_chain(load_eni(EXAMPLES / "lola.xml"), drift_ppb=drift_ppb, timing=timing)
    bus = Bus(chain)
    for i in range(len(chain.slaves)):
        bus.one(C.APWR, (-i) & 0xFFFF, r.STATION_ADDRESS, struct.pack("<H", 0x1000 + i))
    bus.one(C.BWR, 0, r.DC_RECEIVE_TIME_PORT0, 4)
    loops = []
    for i in range(len(chain.slaves)):
        t0, t1 = struct.unpack("<II", bus.fprd(0x1000 + i, r.DC_RECEIVE_TIME_PORT0, 8))
        loops.append((t1 - t0) & 0xFFFFFFFF if i < len(chain.slaves) - 1 else 0)
    delay = 0
    for i in range(1, len(chain.slaves)):
        delay += (loops[i - 1] - loops[i]) // 2
        bus.fpwr(0x1000 + i, r.DC_SYSTEM_TIME_DELAY, struct.pack("<I", delay))
    for i, esc in enumerate(chain.slaves):
        offset = chain.slaves[0].clock.local_ns(bus.t_ns) - esc.clock.local_ns(bus.t_ns)
        bus.fpwr(0x1000 + i, r.DC_SYSTEM_TIME_OFFSET, struct.pack("<q", offset))
    return chain, bus


def test_frmw_drift_compensation_keeps_clocks_together() -> None:
    chain, bus = _addressed_dc_chain(drift_ppb=20_000)  # the last slave runs 480 ppm fast
    sent_ns = bus.t_ns
    d = bus.one(C.FRMW, 0x1000, r.DC_SYSTEM_TIME, 8)
    assert d.wkc == 25
    arrival_ns = sent_ns + chain.timing.cable_ns
    assert struct.unpack("<Q", d.data)[0] == chain.slaves[0].system_time_ns(arrival_ns)
    for _ in range(200):
        bus.t_ns += 1_000_000
        bus.one(C.FRMW, 0x1000, r.DC_SYSTEM_TIME, 8)
    t = bus.t_ns
    ref = chain.slaves[0].system_time_ns(t)
    spread = max(abs(esc.system_time_ns(t) - ref) for esc in chain.slaves)
    assert spread < 2_000  # without the FRMW the last slave would be 96 µs off
    assert all(abs(e.system_time_difference_ns) < 2_000 for e in chain.slaves[1:])


def test_without_frmw_the_clocks_drift_apart() -> None:
    chain, bus = _addressed_dc_chain(drift_ppb=20_000)
    t = bus.t_ns + 200_000_000
    ref = chain.slaves[0].system_time_ns(t)
    assert abs(chain.slaves[-1].system_time_ns(t) - ref) > 90_000


def test_error_counters_count_invalid_frames_and_clear_on_write(drive_bus: Bus) -> None:
    chain = drive_bus.chain
    assert chain.process(b"\x01" * 20, 0) == (None, 0)
    assert chain.process(bytes(6) + bytes(6) + b"\x88\xa4" + b"\xff\x17", 0) == (None, 0)
    assert chain.slaves[0].mem[r.RX_ERROR_COUNTER] == 2
    assert drive_bus.one(C.APRD, 0, r.RX_ERROR_COUNTER, 1).data == b"\x02"
    drive_bus.one(C.APWR, 0, r.RX_ERROR_COUNTER, 1)
    assert drive_bus.one(C.APRD, 0, r.RX_ERROR_COUNTER, 1).data == b"\x00"


def test_process_data_watchdog_drops_to_safeop_without_outputs(drive_bus: Bus) -> None:
    eni = load_eni(EXAMPLES / "single_drive.xml")
    drive_bus.bring_up(eni)
    esc = drive_bus.chain.slaves[0]
    assert esc.watchdog_timeout_ns() == 100_000_000  # ENI: divider 0x09C2, 1000 ticks
    for _ in range(150):  # outputs every 1 ms keep it in OP for 150 ms
        drive_bus.cycle(eni)
    assert esc.al_state == AlState.OP and not esc.al_error
    drive_bus.t_ns += 101_000_000  # silence longer than the watchdog
    drive_bus.one(C.BRD, 0, r.AL_STATUS, 2)
    assert esc.al_state == AlState.SAFEOP and esc.al_error
    assert esc.al_status_code == AlStatusCode.SYNC_MANAGER_WATCHDOG
    assert drive_bus.fprd(0x03E9, r.WD_STATUS_PD, 4) == b"\x00\x00\x01\x00"


def test_mailbox_repeat_request_posts_the_last_message_again(drive_bus: Bus) -> None:
    """SOEM after a lost mailbox read: toggle SM1 activate bit 1 (word write at 0x080D),
    wait for PDI control bit 1 (0x080F) to follow, read the mailbox again."""
    _configure_mailbox(drive_bus)
    drive_bus.fpwr(0x03E9, r.AL_CONTROL, b"\x02\x00")
    esc = drive_bus.chain.slaves[0]
    esc.post_mailbox(b"\x05\x00" + bytes(4) + b"first")
    assert drive_bus.fprd(0x03E9, 0x1900, 140)[6:11] == b"first"  # ...and the reply is lost
    assert not drive_bus.fprd(0x03E9, 0x080D, 1)[0] & 0x08
    status = struct.unpack("<H", drive_bus.fprd(0x03E9, 0x080D, 2))[0]
    assert drive_bus.fpwr(0x03E9, 0x080D, struct.pack("<H", status ^ 0x0200)) == 1
    assert drive_bus.fprd(0x03E9, 0x080F, 1)[0] & 0x02 == (status ^ 0x0200) >> 8 & 0x02
    assert drive_bus.fprd(0x03E9, 0x080D, 1)[0] & 0x08  # full again
    assert drive_bus.fprd(0x03E9, 0x1900, 140)[6:11] == b"first"


def test_nothing_outside_the_esc_package_reads_its_private_members() -> None:
    """The frame plan, the C core's glue, the chain and the tests use the ESC through its
    public interface: no ``x._name`` for a private member of an Esc (attribute or method)
    except on ``self`` inside the esc package."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    esc = build_chain(load_eni(EXAMPLES / "single_drive.xml")).slaves[0]
    assert isinstance(esc, Esc)
    private = {n for n in [*vars(esc), *dir(Esc)] if n.startswith("_") and not n.endswith("__")}
    assert {"_cache", "_mailbox_queue"} <= private
    package = root / "lolacli" / "emulator" / "esc"
    found = []
    for path in [*(root / "lolacli").rglob("*.py"), *(root / "tests").rglob("*.py")]:
        if package in path.parents:
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if (
                isinstance(node, ast.Attribute)
                and node.attr in private
                and not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"))
            ):
                found.append(f"{path.relative_to(root)}:{node.lineno} .{node.attr}")
    assert found == []


@settings(max_examples=300, deadline=None)
@given(
    start=st.integers(0, r.PROCESS_RAM - 1),  # at and past it: no registers (process RAM)
    payload=st.binary(min_size=1, max_size=300),
    seed=st.binary(min_size=512, max_size=512),
)
def test_a_register_write_stores_the_writable_bytes_run_by_run_or_masked_alike(
    start: int, payload: bytes, seed: bytes
) -> None:
    """The one-step store (masked where read-only bytes lie between writable ones) leaves
    the memory exactly as storing each writable run on its own does, and the one-step
    store of a payload worked out once for many slaves (a BWR) too."""
    plan = register_write(start, start + len(payload))
    before = bytearray(r.MEMORY_BYTES)
    before[start : start + 512] = seed[: max(0, min(512, r.MEMORY_BYTES - start))]
    runs = bytearray(before)
    for lo, hi in plan.segments:
        runs[lo:hi] = payload[lo - start : hi - start]
    one_step = bytearray(before)
    plan.store(one_step, start, payload)
    assert one_step == runs
    shared = bytearray(before)
    plan.store_bits(shared, start, plan.writable_bits(payload))
    assert shared == runs


def test_register_classes_say_what_a_write_of_each_byte_does() -> None:
    """The C core's class of each register byte (made by ranges) is what
    register_write of that byte alone says, flag for flag."""
    from lolacli.emulator import registers as r
    from lolacli.emulator.esc import memory as m

    classes = m.register_classes()
    assert len(classes) == r.PROCESS_RAM
    for a in range(r.PROCESS_RAM):
        w = m.register_write.__wrapped__(a, a + 1)
        want = (m.REGISTER_READONLY if m._READONLY[a] else 0)
        for flag, cls in (("configuration", m.REGISTER_CONFIGURATION),
                          ("watchdog", m.REGISTER_CONFIGURATION),
                          ("sync_managers", m.REGISTER_SYNC_MANAGER),
                          ("eeprom", m.REGISTER_EEPROM), ("al_control", m.REGISTER_AL_CONTROL),
                          ("addressing", m.REGISTER_ADDRESSING), ("latch", m.REGISTER_DC),
                          ("system_time", m.REGISTER_DC)):
            if getattr(w, flag):
                want |= cls
        if w.clear_groups:
            want |= m.REGISTER_CLEAR
        assert classes[a] == want, hex(a)
    assert classes[r.AL_CONTROL] & m.REGISTER_AL_CONTROL
    assert classes[r.STATION_ADDRESS] & m.REGISTER_ADDRESSING
