"""CiA 402 drive: power state machine, CSP following, object dictionary access."""

from __future__ import annotations

import pytest

from lolacli.devices import CanGateway, Cia402Drive, DigitalIo, device_for
from lolacli.devices.cia402 import Cia402State, Command, decode_controlword
from lolacli.eni.model import Direction
from lolacli.errors import SdoAbortError
from lolacli.files import load_eni
from lolacli.wire.sdo import SdoAbortCode
from tests.emulator.bus import EXAMPLES

MS = 1_000_000


@pytest.fixture
def drive() -> Cia402Drive:
    d = device_for(load_eni(EXAMPLES / "single_drive.xml").slaves[0])
    assert isinstance(d, Cia402Drive)
    return d


def _run(drive: Cia402Drive, cw: int, t_ns: int, target: int = 0) -> int:
    drive.od.set(0x6040, 0, cw)
    drive.od.set(0x607A, 0, target)
    drive.step(t_ns)
    drive.t_ns = t_ns
    return drive.od.get_int(0x6041)


@pytest.mark.parametrize(
    ("cw", "previous", "command"),
    [
        (0x0006, 0x0000, Command.SHUTDOWN),
        (0x0007, 0x0006, Command.SWITCH_ON),
        (0x000F, 0x0007, Command.ENABLE_OPERATION),
        (0x0007, 0x000F, Command.DISABLE_OPERATION),
        (0x0000, 0x000F, Command.DISABLE_VOLTAGE),
        (0x0002, 0x000F, Command.QUICK_STOP),
        (0x0080, 0x0000, Command.FAULT_RESET),
        (0x0080, 0x0080, Command.DISABLE_VOLTAGE),  # no rising edge: not a reset
    ],
)
def test_controlword_commands(cw: int, previous: int, command: Command) -> None:
    assert decode_controlword(cw, previous) == command


def test_power_up_sequence_and_statuswords(drive: Cia402Drive) -> None:
    assert _run(drive, 0x0000, 1 * MS) & 0x4F == 0x40  # switch on disabled
    assert _run(drive, 0x0006, 2 * MS) & 0x6F == 0x21  # ready to switch on
    assert _run(drive, 0x0007, 3 * MS) & 0x6F == 0x23  # switched on
    status = _run(drive, 0x000F, 4 * MS)
    assert status & 0x6F == 0x27 and status & 0x0010  # operation enabled, voltage
    assert drive.power == Cia402State.OPERATION_ENABLED
    assert _run(drive, 0x0002, 5 * MS) & 0x6F == 0x07  # quick stop active
    assert _run(drive, 0x0000, 6 * MS) & 0x4F == 0x40


def test_fault_and_fault_reset(drive: Cia402Drive) -> None:
    for i, cw in enumerate((0x00, 0x06, 0x07, 0x0F)):
        _run(drive, cw, (i + 1) * MS)
    drive.fault(0x7300)
    _run(drive, 0x0F, 5 * MS)
    assert drive.od.get_int(0x6041) & 0x4F == 0x08 and drive.od.get_int(0x603F) == 0x7300
    _run(drive, 0x8F, 6 * MS)  # rising edge of bit 7
    assert drive.power == Cia402State.SWITCH_ON_DISABLED
    assert drive.od.get_int(0x603F) == 0


def test_csp_actual_follows_target_rate_limited(drive: Cia402Drive) -> None:
    drive.od.set(0x607F, 0, 1_000_000)  # counts per second
    for i, cw in enumerate((0x00, 0x06, 0x07, 0x0F)):
        _run(drive, cw, (i + 1) * MS)
    positions = [drive.od.get_int(0x6064)]
    for k in range(5):
        _run(drive, 0x0F, (10 + k) * MS, target=100_000)
        positions.append(drive.od.get_int(0x6064))
    steps = [b - a for a, b in zip(positions, positions[1:], strict=False)]
    assert steps[1:] == [1000] * 4  # 1 ms at 1e6 counts/s
    assert drive.od.get_int(0x606C) == 1_000_000
    drive.od.set(0x607F, 0, 0)  # no limit: jumps to target
    _run(drive, 0x0F, 20 * MS, target=100_000)
    assert drive.od.get_int(0x6064) == 100_000
    assert drive.od.get_int(0x6041) & 0x0400  # target reached


def test_object_access_checks(drive: Cia402Drive) -> None:
    with pytest.raises(SdoAbortError) as exc:
        drive.od.write(0x6041, 0, b"\x00\x00")
    assert exc.value.code == SdoAbortCode.READ_ONLY
    with pytest.raises(SdoAbortError) as exc:
        drive.od.read(0x6100, 0)
    assert exc.value.code == SdoAbortCode.NO_OBJECT
    with pytest.raises(SdoAbortError) as exc:
        drive.od.write(0x607A, 0, b"\x00" * 5)
    assert exc.value.code == SdoAbortCode.LENGTH_MISMATCH


def test_pdo_mapping_packs_and_unpacks(drive: Cia402Drive) -> None:
    assert drive.process_data_bytes() == (11, 11)
    outputs = bytes.fromhex("0f00") + b"\x08" + (4321).to_bytes(4, "little") + bytes(4)
    inputs = drive.cycle(outputs, 1 * MS)
    assert len(inputs) == 11
    assert drive.od.get_int(0x607A) == 4321 and drive.od.get_int(0x6040) == 0x0F
    mapping = drive.mapping(Direction.INPUT)
    assert [m[0] for m in mapping] == [0x6041, 0x6061, 0x6064, 0x606C]
    # remap via SDO-style writes: only the statusword
    drive.od.write(0x1A00, 0, b"\x01")
    assert drive.process_data_bytes() == (11, 2)


def test_lola_devices_by_kind() -> None:
    eni = load_eni(EXAMPLES / "lola.xml")
    kinds = [type(device_for(s)).__name__ for s in eni.slaves]
    assert kinds.count("Cia402Drive") == 21
    gateway = next(device_for(s) for s in eni.slaves if "Gateway" in s.name)
    assert isinstance(gateway, CanGateway)
    gateway.cycle(b"", 123 * MS)
    assert any(v != 0 for v in gateway.values().values())
    gpio = device_for(next(s for s in eni.slaves if s.name == "GPIO 8DI 8DO"))
    assert isinstance(gpio, DigitalIo)
    assert gpio.cycle(b"\x05", MS) == b"\x05"  # inputs echo the outputs


def _enable(drive: Cia402Drive, mode: int = 8) -> None:
    drive.od.set(0x6060, 0, mode)
    for i, cw in enumerate((0x00, 0x06, 0x07, 0x0F)):
        _run(drive, cw, (i + 1) * MS, target=drive.od.get_int(0x6064))
    assert drive.power == Cia402State.OPERATION_ENABLED


def test_profile_position_takes_a_set_point_on_the_rising_edge_of_bit_4(
    drive: Cia402Drive,
) -> None:
    _enable(drive, mode=1)
    drive.od.set(0x6081, 0, 2_000_000)  # profile velocity: 2000 increments a ms
    _run(drive, 0x0F, 10 * MS, target=5000)  # no new set-point: the target waits
    assert drive.od.get_int(0x6064) == 0 and drive.od.get_int(0x6041) & 0x1000 == 0
    status = _run(drive, 0x1F, 11 * MS, target=5000)  # bit 4 rises: accepted
    assert status & 0x1000  # set-point acknowledge while bit 4 stays high
    assert drive.od.get_int(0x60FC) == 5000 and drive.od.get_int(0x6064) == 2000
    _run(drive, 0x1F, 12 * MS, target=-7)  # held high: not a new set-point
    assert drive.od.get_int(0x60FC) == 5000 and drive.od.get_int(0x6064) == 4000
    status = _run(drive, 0x0F, 13 * MS, target=-7)
    assert drive.od.get_int(0x6064) == 5000 and status & 0x0400  # target reached
    _run(drive, 0x5F, 14 * MS, target=-1000)  # relative (bit 6): 5000 - 1000
    assert drive.od.get_int(0x60FC) == drive.od.get_int(0x6064) == 4000
    _run(drive, 0x0F, 15 * MS, target=9000)
    status = _run(drive, 0x11F, 16 * MS, target=9000)  # a set-point, halted (bit 8)
    assert drive.od.get_int(0x60FC) == 9000 and drive.od.get_int(0x6064) == 4000
    assert drive.od.get_int(0x606C) == 0 and status & 0x0400  # halted: stands
    assert drive.od.get_int(0x60F4) == 5000  # demand - actual
    _run(drive, 0x1F, 17 * MS, target=9000)  # halt released: on its way
    assert drive.od.get_int(0x6064) == 6000


def test_cyclic_torque_is_clamped_to_max_torque_and_the_follower_holds(
    drive: Cia402Drive,
) -> None:
    _enable(drive, mode=10)
    drive.od.set(0x6072, 0, 800)  # ‰ of rated torque
    drive.od.set(0x6071, 0, 500)
    drive.od.set(0x60B2, 0, 100)
    status = _run(drive, 0x0F, 10 * MS)
    assert drive.od.get_int(0x6077) == 600 and not status & 0x0800
    drive.od.set(0x6071, 0, -1200)
    status = _run(drive, 0x0F, 11 * MS)
    assert drive.od.get_int(0x6077) == -800 and status & 0x0800  # internal limit active
    assert drive.od.get_int(0x606C) == 0  # the kinematic follower has no inertia


def test_csv_velocity_with_offset_limited_by_max_motor_speed(drive: Cia402Drive) -> None:
    _enable(drive, mode=9)
    drive.od.set(0x60FF, 0, 30_000)
    drive.od.set(0x60B1, 0, 5_000)
    _run(drive, 0x0F, 10 * MS)
    _run(drive, 0x0F, 11 * MS)
    assert drive.od.get_int(0x606C) == 35_000
    drive.od.set(0x6080, 0, 20_000)  # max motor speed
    _run(drive, 0x0F, 12 * MS)
    assert drive.od.get_int(0x606C) == 20_000


def test_software_position_limits_clip_the_demand(drive: Cia402Drive) -> None:
    _enable(drive)
    drive.od.set(0x607D, 1, -100)
    drive.od.set(0x607D, 2, 300)
    status = _run(drive, 0x0F, 10 * MS, target=1000)
    assert drive.od.get_int(0x6064) == 300 and status & 0x0800
    status = _run(drive, 0x0F, 11 * MS, target=-1000)
    assert drive.od.get_int(0x6064) == -100 and status & 0x0800
    status = _run(drive, 0x0F, 12 * MS, target=50)
    assert drive.od.get_int(0x6064) == 50 and not status & 0x0800


def test_following_error_window_and_timeout(drive: Cia402Drive) -> None:
    drive.od.set(0x607F, 0, 100_000)  # 100 increments a ms
    drive.od.set(0x6065, 0, 500)
    drive.od.set(0x6066, 0, 3)  # ms
    _enable(drive)
    statuses = [_run(drive, 0x0F, (10 + k) * MS, target=10_000) for k in range(10)]
    errors_over = [bool(s & 0x2000) for s in statuses]
    first = errors_over.index(True)  # 10000 - 100 k > 500 from the start
    assert first == 0
    states = [s & 0x4F for s in statuses]
    # over the window from 10 ms: still enabled at 10..12 ms, fault reaction at 13 ms
    assert [s & 0x6F for s in statuses[:3]] == [0x27] * 3
    assert states[3] == 0x0F and states[4] == 0x08  # fault reaction active, then fault
    assert drive.od.get_int(0x603F) == 0x8611


def test_the_load_is_a_seam_and_a_plant_keeps_the_drive_in_python() -> None:
    from lolacli.devices.cia402 import Follower, Load
    from lolacli.devices.flat import flatten

    drive = device_for(load_eni(EXAMPLES / "single_drive.xml").slaves[0])
    assert isinstance(drive, Cia402Drive) and isinstance(drive.load, Follower)
    assert flatten(drive) is not None and drive.core_can_run()

    class Half(Load):  # a plant that covers half the way each step
        def follow(self, kind, demand, position, velocity, limit, dt_ns):  # type: ignore[no-untyped-def]
            return position + (demand - position) // 2, 0

    drive.load = Half()
    assert flatten(drive) is None  # the C core mirrors only the Follower and JointLoad
    _enable(drive)
    _run(drive, 0x0F, 10 * MS, target=1000)
    assert drive.od.get_int(0x6064) == 500
    drive.load = Follower()
    drive.od.set(0x6065, 0, 100)  # the monitor on: Python runs it too
    assert not drive.core_can_run() and flatten(drive) is None
