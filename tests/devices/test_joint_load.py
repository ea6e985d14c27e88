"""A joint behind an emulated CiA 402 drive (lolacli.devices.joint_load): the drive's
actual values come from the motor, gear and link under the seed's cascade, in encoder
increments, instead of the kinematic follower's."""

from __future__ import annotations

import math

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


def _closed_form(p: JointParams, torque_nm: float, t: float) -> float:
    """θ(t) from rest at θ = 0 under a constant link torque: J θ̈ + b θ̇ + G θ = τ − F_c
    (gravity linearised, sin θ ≈ θ; Coulomb friction at its full F_c for θ̇ > 0)."""
    j, b, g = p.inertia_kgm2, p.viscous_nm_s_per_rad, p.gravity_nm
    w0 = math.sqrt(g / j)
    zeta = b / (2 * j * w0)
    assert zeta < 1  # the hip's link swings: underdamped
    wd = w0 * math.sqrt(1 - zeta**2)
    decay = math.exp(-zeta * w0 * t)
    return (torque_nm - p.coulomb_nm) / g * (
        1 - decay * (math.cos(wd * t) + zeta * w0 / wd * math.sin(wd * t)))


@pytest.mark.parametrize(("permille", "rated_mnm"), [(200, 0), (400, 100_000)])
def test_a_constant_torque_accelerates_the_joint_as_the_closed_form_says(
    permille: int, rated_mnm: int
) -> None:
    """CST: 0x6071 ‰ of 0x6076 (0: the joint's N k_t I_max = 200 N·m) is the link torque,
    40 N·m both times, the current command τ / (N k_t) with the position and velocity
    loops bypassed. From rest hanging (θ = 0) against gravity, friction and the viscous
    drag, θ follows the damped swing of the closed form within 2.5 %: the current PI's
    lag behind the back-EMF, which ramps with the speed (ė / (K_p K_i) = N k_t θ̈ / 3142
    V/A/s ≈ 0.05 A of the 4 A commanded, 1.2 % of the torque), its 80 µs rise (0.2 %), the
    Coulomb friction below F_c while θ̇ < ω_s (0.1 %) and sin θ ≈ θ (< 0.1 % up to 0.1 s)."""
    hip = _hip()
    load = JointLoad(hip)
    assert load.rated_torque_mnm == 200_000
    d, clock = _drive(load, MODE_CST)
    d.od.set(0x6076, 0, rated_mnm)
    d.od.set(0x6071, 0, permille)
    _cycle(d, clock)  # the torque holds from this step on
    start, theta = clock[0], []
    for _ in range(200):  # 0.1 s
        _cycle(d, clock)
        theta.append((clock[0] - start, d.od.get_int(0x6064) / load.scale))
    assert d.od.get_int(0x6077) == permille  # torque actual: the demand
    for t_ns, got in theta[19::20]:
        want = _closed_form(hip, 40.0, t_ns * 1e-9)
        assert got == pytest.approx(want, rel=0.025), (t_ns, got, want)
    assert theta[-1][1] == pytest.approx(_closed_form(hip, 40.0, 0.1), rel=0.02)
    # the position loop would have held it: CSP on the same target does not move
    still, clock2 = _drive(JointLoad(hip), MODE_CSP)
    for _ in range(200):
        _cycle(still, clock2)
    assert abs(still.od.get_int(0x6064)) <= 3


def test_a_torque_beyond_the_current_limit_is_clamped_and_csp_takes_over_from_there() -> None:
    """1000 ‰ of 400 N·m would be 40 A: the current command stops at I_max (20 A), so
    the joint moves exactly as under 1000 ‰ of the joint's own 200 N·m. Back in CSP the
    targets start from the joint as it is (no jump to where CST began)."""
    runs = []
    for rated in (400_000, 0):
        d, clock = _drive(JointLoad(_hip()), MODE_CST)
        d.od.set(0x6076, 0, rated)
        d.od.set(0x6071, 0, 1000)
        trace = []
        for _ in range(20):
            _cycle(d, clock)
            trace.append((d.od.get_int(0x6064), d.od.get_int(0x606C)))
        runs.append(trace)
    assert runs[0] == runs[1] and runs[0][-1][1] > 0
    here = d.od.get_int(0x6064)
    d.od.set(0x607A, 0, here)
    d.od.set(0x6060, 0, MODE_CSP)
    for _ in range(600):
        _cycle(d, clock)
    assert abs(d.od.get_int(0x6064) - here) < 0.1 * here  # caught near where it was
    assert abs(d.od.get_int(0x606C)) < 2000


def test_a_drive_with_a_joint_runs_in_the_core_unless_it_is_a_subclass() -> None:
    d, _ = _drive(JointLoad(_hip()))
    assert d.core_can_run()

    class Other(JointLoad):
        pass

    d.load = Other(_hip())
    assert not d.core_can_run()
