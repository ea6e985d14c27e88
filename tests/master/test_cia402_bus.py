"""The CiA 402 drive through the bus: our master writes the controlword into the process
data of the emulated chain (in-process virtual bus) and reads the statusword back, for
every transition of the power state machine, fault (following error, 0x8611 in 0x603F),
fault reset on the rising edge of bit 7, quick stop with its option code, the fault
reaction; checked against the standard's tables (tests/devices/cia402_tables.py). And the
master's own Cia402Drive helper: its enable sequence and its fault reset."""

from __future__ import annotations

import struct

import pytest

from lolacli.files import load_eni
from lolacli.master import BusInt8, BusInt32, BusUInt16, Cia402Drive, Master, MasterOptions
from lolacli.simulate import EmulateOptions, VirtualBus
from tests.devices.cia402_tables import (
    DISABLE_VOLTAGE,
    ENABLE_OPERATION,
    FAULT_RESET,
    PATH,
    QUICK_STOP,
    SHUTDOWN,
    SWITCH_ON,
    TRANSITIONS,
    states_of,
)
from tests.emulator.bus import EXAMPLES


class Bench:
    """One drive (single_drive.xml) in OP, its controlword and statusword as Bus Variables."""

    def __init__(self) -> None:
        eni = load_eni(EXAMPLES / "single_drive.xml")
        bus = VirtualBus(eni, EmulateOptions())
        self.master = Master(eni, bus.transport, options=MasterOptions(dc_drift_frames=50))
        link = self.master.link
        self.cw = link("Drive.Outputs.Controlword", BusUInt16.output())
        self.sw = link("Drive.Inputs.Statusword", BusUInt16.input())
        self.mode = link("Drive.Outputs.Modes of operation", BusInt8.output())
        self.target = link("Drive.Outputs.Target position", BusInt32.output())
        self.velocity_offset = link("Drive.Outputs.Velocity offset", BusInt32.output())
        self.actual = link("Drive.Inputs.Position actual value", BusInt32.input())
        self.velocity = link("Drive.Inputs.Velocity actual value", BusInt32.input())
        assert self.master.bring_up() == []
        self.sdo = self.master.sdo(1)
        self.mode.value = 8

    def send(self, cw: int, cycles: int = 3) -> str:
        """``cw`` for ``cycles`` cycles; the one state the statusword then shows."""
        self.cw.value = cw
        self.master.run(cycles)
        states = states_of(self.sw.value)
        assert len(states) == 1, (hex(self.sw.value), states)
        return states[0]

    def home(self) -> None:
        """Back to switch on disabled from wherever (disable voltage; fault reset)."""
        if self.send(DISABLE_VOLTAGE) == "Fault":
            assert self.send(FAULT_RESET) == "Switch on disabled"
        assert self.send(DISABLE_VOLTAGE) == "Switch on disabled"

    def write(self, index: int, fmt: str, value: int) -> None:
        self.sdo.download(index, 0, struct.pack(fmt, value))

    def read(self, index: int, fmt: str) -> int:
        return int(struct.unpack(fmt, self.sdo.upload(index, 0))[0])


@pytest.fixture(scope="module")
def bench() -> Bench:
    return Bench()


def test_power_up_shows_switch_on_disabled(bench: Bench) -> None:
    assert bench.send(DISABLE_VOLTAGE) == "Switch on disabled"  # transitions 0 and 1


@pytest.mark.parametrize(("number", "source", "cw", "goal"), TRANSITIONS, ids=lambda x: str(x))
def test_every_commanded_transition(
    bench: Bench, number: str, source: str, cw: int, goal: str
) -> None:
    bench.home()
    for step in PATH[source]:
        bench.send(step)
    assert bench.send(cw if cw else DISABLE_VOLTAGE, cycles=1) in (source, goal)
    assert bench.send(cw) == goal, f"transition {number}"
    bench.home()


def test_following_error_faults_and_the_reset_needs_a_rising_edge(bench: Bench) -> None:
    bench.home()
    bench.write(0x6065, "<I", 50)  # window: 50 increments
    bench.write(0x6066, "<H", 3)  # timeout: 3 ms
    bench.write(0x607F, "<I", 10_000)  # the follower: 10 increments a 1 ms cycle
    try:
        for cw in PATH["Operation enabled"]:
            bench.send(cw)
        start = bench.actual.value
        bench.target.value = start + 40  # inside the window: no fault
        assert bench.send(ENABLE_OPERATION, cycles=10) == "Operation enabled"
        # bit 7 set while enabled (no effect there), then far outside: after the timeout
        # a fault, with bit 7 still set: no rising edge, no reset
        bench.target.value = start + 10_000
        assert bench.send(ENABLE_OPERATION | FAULT_RESET, cycles=4) == "Operation enabled"
        assert bench.sw.value & 0x2000  # statusword bit 13: following error
        assert bench.send(ENABLE_OPERATION | FAULT_RESET, cycles=6) == "Fault"
        assert bench.read(0x603F, "<H") == 0x8611  # following error
        assert bench.send(FAULT_RESET, cycles=5) == "Fault"  # bit 7 held: no edge
        assert bench.send(DISABLE_VOLTAGE) == "Fault"
        bench.target.value = bench.actual.value
        assert bench.send(FAULT_RESET) == "Switch on disabled"  # the edge: transition 15
        assert bench.read(0x603F, "<H") == 0
        assert bench.send(FAULT_RESET) == "Switch on disabled"  # held: no new reset
    finally:
        bench.write(0x6065, "<I", 0xFFFFFFFF)
        bench.write(0x607F, "<I", 0)
        bench.home()


@pytest.mark.parametrize("option", [0, 1, 2, 3, 4, 5, 6, 7, 8])
def test_quick_stop_follows_its_option_code(bench: Bench, option: int) -> None:
    """0-4: stop, then switch on disabled on its own (transition 12); 5-8: stay in quick
    stop active, enable operation goes back (16). 1/5 ramp at 0x6084, 2/6 at 0x6085."""
    bench.home()
    bench.write(0x605A, "<h", option)
    bench.write(0x6084, "<I", 2_000_000)  # 2 increments/ms per 1 ms cycle
    bench.write(0x6085, "<I", 4_000_000)
    try:
        bench.mode.value = 9  # CSV, the velocity from the offset
        bench.velocity_offset.value = 40_000  # increments/s
        for cw in PATH["Operation enabled"]:
            bench.send(cw)
        assert bench.send(ENABLE_OPERATION, cycles=5) == "Operation enabled"
        assert bench.velocity.value == 40_000
        ramp = {1: 2_000_000, 5: 2_000_000, 2: 4_000_000, 6: 4_000_000}.get(option)
        bench.cw.value = QUICK_STOP
        trace = []  # (state, velocity) each cycle
        for _ in range(40_000 * 1000 // ramp + 8 if ramp else 8):
            bench.master.run(1)
            trace.append((states_of(bench.sw.value)[0], bench.velocity.value))
        states = [state for state, _ in trace]
        first = next(i for i, state in enumerate(states) if state != "Operation enabled")
        assert states[first] == "Quick stop active"  # transition 11: x00x 0111
        stopping = [v for state, v in trace if state == "Quick stop active"]
        if ramp:  # decelerating: 2 or 4 increments/s less each 1 ms cycle
            steps = [b - a for a, b in zip(stopping, stopping[1:], strict=False)]
            assert steps[:5] == [-ramp // 1000] * 5
        assert trace[-1][1] == 0
        rest = states[first:]
        if option <= 4:  # transition 12 on its own once stopped
            assert rest[-1] == "Switch on disabled"
            assert rest == sorted(rest, key=["Quick stop active", "Switch on disabled"].index)
        else:
            assert set(rest) == {"Quick stop active"}
            assert bench.send(ENABLE_OPERATION) == "Operation enabled"  # transition 16
    finally:
        bench.velocity_offset.value = 0
        bench.mode.value = 8
        bench.write(0x605A, "<h", 6)
        bench.home()


def test_fault_reaction_ramps_then_fault(bench: Bench) -> None:
    """Fault reaction option code 2: fault reaction active while it brakes on the quick
    stop ramp, then fault (transitions 13, 14)."""
    bench.home()
    bench.write(0x605E, "<h", 2)
    bench.write(0x6085, "<I", 4_000_000)
    bench.write(0x6065, "<I", 0)  # any error past 0 faults
    try:
        bench.mode.value = 8
        bench.write(0x607F, "<I", 40_000)
        for cw in PATH["Operation enabled"]:
            bench.send(cw)
        bench.target.value = bench.actual.value + 1_000_000
        bench.cw.value = ENABLE_OPERATION
        bench.master.run(1)
        states = []
        for _ in range(20):
            bench.master.run(1)
            states.append(states_of(bench.sw.value)[0])
        assert "Fault reaction active" in states and states[-1] == "Fault"
        reacting = states.index("Fault reaction active")
        assert states[reacting : reacting + 5] == ["Fault reaction active"] * 5  # braking
        assert bench.read(0x603F, "<H") == 0x8611
    finally:
        bench.write(0x6065, "<I", 0xFFFFFFFF)
        bench.write(0x607F, "<I", 0)
        bench.write(0x605E, "<h", 0)
        bench.home()


def test_the_master_helper_enables_resets_and_quick_stops() -> None:
    eni = load_eni(EXAMPLES / "single_drive.xml")
    bus = VirtualBus(eni, EmulateOptions())
    master = Master(eni, bus.transport, options=MasterOptions(dc_drift_frames=50))
    drive = Cia402Drive(master, "Drive")
    assert master.bring_up() == []
    sent: list[int] = []
    drive.enable()
    master.run(8, on_cycle=lambda _c: sent.append(drive.controlword.value))
    assert drive.enabled
    # the enable sequence: shutdown, switch on, enable operation (each once the drive shows
    # the state before)
    steps = [cw for i, cw in enumerate(sent) if i == 0 or cw != sent[i - 1]]
    assert steps == [SHUTDOWN, SWITCH_ON, ENABLE_OPERATION]
    sdo = master.sdo(1)
    sdo.download(0x6065, 0, struct.pack("<I", 10))
    drive.target_position = drive.actual_position + 10**6  # no rate limit: jumps, so...
    sdo.download(0x607F, 0, struct.pack("<I", 1000))  # ...a limit makes it lag
    drive.target_position = drive.actual_position + 10**6
    sent.clear()
    master.run(6, on_cycle=lambda _c: sent.append(drive.controlword.value))
    assert drive.faults == 1
    sdo.download(0x6065, 0, struct.pack("<I", 0xFFFFFFFF))
    master.run(6)
    assert drive.enabled  # reset on a rising edge of bit 7, then enabled again
    assert DISABLE_VOLTAGE in sent and FAULT_RESET in sent
    assert sent.index(FAULT_RESET) > sent.index(DISABLE_VOLTAGE)
    drive.quick_stop()
    master.run(3)
    assert drive.state.name == "QUICK_STOP_ACTIVE"  # type: ignore[union-attr]
    drive.quick_stop(False)
    master.run(3)
    assert drive.enabled
    drive.disable()
    master.run(3)
    assert drive.state.name == "READY_TO_SWITCH_ON"  # type: ignore[union-attr]
