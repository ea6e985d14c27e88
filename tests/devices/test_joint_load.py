"""A joint behind an emulated CiA 402 drive (lolacli.devices.joint_load): the drive's
actual values come from the motor, gear and link under the seed's cascade, in encoder
increments, instead of the kinematic follower's."""

from __future__ import annotations

import pytest

from lolacli.devices import Cia402Drive, device_for
from lolacli.devices.cia402 import MODE_CSP, MODE_CST, MODE_CSV, Follower
from lolacli.devices.joint_load import JointLoad
from lolacli.files import load_eni, load_joints
from lolacli.motion.joint import JointParams, find_joint
from tests.emulator.bus import EXAMPLES

CYCLE = 500_000  # 2 kHz


def _hip() -> JointParams:
    hip = find_joint(load_joints(), "L Hip Pitch")
    assert hip is not None
    return hip


def _drive(load: object, mode: int = MODE_CSP) -> tuple[Cia402Drive, list[int]]:
    d = device_for(load_eni(EXAMPLES / "single_drive.xml").slaves[0])
    assert isinstance(d, Cia402Drive)
    d.load = load  # type: ignore[assignment]
    d.od.set(0x6060, 0, mode)
    clock = [0]
    for cw in (0x00, 0x06, 0x07, 0x0F):
        _cycle(d, clock, cw)
    assert d.od.get_int(0x6041) & 0x6F == 0x27  # operation enabled
    return d, clock


def _cycle(d: Cia402Drive, clock: list[int], cw: int = 0x0F, period: int = CYCLE) -> None:
    clock[0] += period
    d.od.set(0x6040, 0, cw)
    d.step(clock[0])
    d.t_ns = clock[0]


@pytest.mark.parametrize("period", [CYCLE, 333_333])  # 3 kHz: not whole 0.1 ms periods
def test_a_position_step_lags_then_settles_on_the_target(period: int) -> None:
    hip = _hip()
    d, clock = _drive(JointLoad(hip))
    target = 20_000  # 2.4 mrad of link
    d.od.set(0x607A, 0, target)
    trace = []
    for _ in range(round(0.3e9 / period)):
        _cycle(d, clock, period=period)
        trace.append(d.od.get_int(0x6064))
    # the first cycle ran on the target held before it: the joint had not moved yet
    assert trace[0] == 0
    assert 0 < trace[1] < target  # then it moves, not at once as the follower does
    assert max(trace) > target  # a stiff loop overshoots a step a little
    assert abs(trace[-1] - target) <= 3  # and settles
    assert d.od.get_int(0x606C) == 0 or abs(d.od.get_int(0x606C)) < 2000


def test_the_kinematic_follower_is_there_at_once() -> None:
    d, clock = _drive(Follower())
    d.od.set(0x607A, 0, 20_000)
    _cycle(d, clock)
    assert d.od.get_int(0x6064) == 20_000


def test_velocity_mode_reaches_the_target_velocity_and_a_quick_stop_ramps_it_down() -> None:
    d, clock = _drive(JointLoad(_hip()), MODE_CSV)
    want = 400_000  # increments/s: 0.048 rad/s of link
    d.od.set(0x60FF, 0, want)
    for _ in range(300):
        _cycle(d, clock)
    before = d.od.get_int(0x6064)
    for _ in range(100):  # 50 ms
        _cycle(d, clock)
    assert (d.od.get_int(0x6064) - before) / 0.05 == pytest.approx(want, rel=0.002)
    assert d.od.get_int(0x606C) == pytest.approx(want, rel=0.03)  # within a cycle
    d.od.set(0x6085, 0, 4_000_000)  # quick stop deceleration: 0.1 s to rest
    speeds = []
    for _ in range(400):
        _cycle(d, clock, 0x0B)  # quick stop
        speeds.append(d.od.get_int(0x606C))
    assert speeds[20] == pytest.approx(want * 0.9, rel=0.05)  # 10 ms into the ramp
    assert abs(speeds[-1]) < 1000


def test_torque_mode_holds_still() -> None:
    d, clock = _drive(JointLoad(_hip()), MODE_CST)
    d.od.set(0x6071, 0, 500)
    for _ in range(20):
        _cycle(d, clock)
    assert (d.od.get_int(0x6064), d.od.get_int(0x606C)) == (0, 0)


def test_a_drive_with_a_joint_runs_in_python_not_in_the_core() -> None:
    d, _ = _drive(JointLoad(_hip()))
    assert not d.core_can_run()
