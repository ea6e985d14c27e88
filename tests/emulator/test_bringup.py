"""The ENI examples' own InitCmds bring the emulated chains to OP; cyclic WKC as the ENI says."""

from __future__ import annotations

import struct

import pytest

from lolacli.devices.cia402 import Cia402Drive
from lolacli.emulator.registers import AlState
from lolacli.emulator.slave import build_chain, device_of
from lolacli.files import load_eni
from tests.emulator.bus import EXAMPLES, Bus


@pytest.mark.parametrize("name", ["single_drive.xml", "ek1100_io.xml", "lola.xml"])
def test_eni_init_cmds_reach_op_and_cyclic_wkc_matches(name: str) -> None:
    eni = load_eni(EXAMPLES / name)
    bus = Bus(build_chain(eni))
    bus.bring_up(eni)
    assert {esc.al_state for esc in bus.chain.slaves} == {AlState.OP}
    expected = [c.expected_wkc for c in eni.cyclic_frames[0].commands]
    for _ in range(20):
        replies, _ = bus.cycle(eni)
        assert [d.wkc for d in replies] == expected


def test_lola_drive_follows_target_through_the_process_image() -> None:
    eni = load_eni(EXAMPLES / "lola.xml")
    bus = Bus(build_chain(eni))
    bus.bring_up(eni)
    out_size = eni.cyclic_frames[0].commands[0].data_length_bytes
    image = bytearray(out_size)
    # the first drive's outputs: controlword, mode, target position at offsets 0, 2, 3
    replies = None
    for cw in (0x06, 0x07, 0x0F, 0x0F):
        struct.pack_into("<HbI", image, 0, cw, 8, 12345)
        replies, inputs = bus.cycle(eni, bytes(image))
    assert replies is not None
    status, mode, actual = struct.unpack_from("<Hbi", inputs, 0)
    assert status & 0x6F == 0x27  # operation enabled
    assert mode == 8
    assert actual == 12345
    drive = device_of(bus.chain.slaves[0])
    assert isinstance(drive, Cia402Drive)


def test_outputs_are_ignored_until_op_and_op_waits_for_valid_outputs() -> None:
    eni = load_eni(EXAMPLES / "single_drive.xml")
    bus = Bus(build_chain(eni))
    bus.transition(eni, "IP")
    bus.transition(eni, "PS")
    esc = bus.chain.slaves[0]
    assert esc.al_state == AlState.SAFEOP
    station = eni.slaves[0].station_address
    assert bus.fpwr(station, 0x0120, b"\x08\x00") == 1
    assert esc.al_state == AlState.SAFEOP and esc.pending_op and not esc.al_error
    bus.cycle(eni)  # first outputs
    assert esc.al_state == AlState.OP
