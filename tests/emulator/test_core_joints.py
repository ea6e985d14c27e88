"""Drives with a joint behind them (``bus simulate --joint-model``) in the chain's C core
give the same bytes and the same state as the Python reference, bit for bit.

The joint (lolacli.devices.joint_load.JointLoad: the cascade of lolacli.motion.joint in
encoder increments) runs in _ccore.c operation for operation, so the doubles are the same.
Two chains of LOLA get the same frames (tests/emulator/test_core.py's Twin: every reply
compared, which holds each drive's actual position, velocity and following error; every
29 frames, or never, the whole state given back and compared, the joints' doubles and the
drives' rest caches with it): CSP moves with and without the 0x607F rate limit, profile
position, a hold long enough for the joints to come to rest (the rest cache), CSV, quick
stop and fault reaction ramps (0x6084/0x6085, option codes 1, 2, 6), CST through the
joint, at 2 kHz and at 3 kHz, whose 333 333 ns are not whole 0.1 ms control periods. And
``bus simulate --move all --joint-model`` itself, both engines, the same moves and
following errors.
"""

from __future__ import annotations

import math

import pytest

from lolacli.devices.cia402 import Cia402Drive, Cia402State
from lolacli.devices.joint_load import JointLoad
from lolacli.emulator.chain import Chain
from lolacli.emulator.core import F_REST, WORDS, ChainCore, core_available
from lolacli.emulator.slave import device_of
from lolacli.eni.model import Eni
from lolacli.files import load_eni, load_joints
from lolacli.motion.joint import find_joint
from lolacli.simulate import options_from_cli
from lolacli.simulate.run import Simulation
from tests.emulator.bus import EXAMPLES
from tests.emulator.test_core import Script, Twin, bring_up

pytestmark = pytest.mark.skipif(not core_available(), reason="C core not built")

LOLA = EXAMPLES / "lola.xml"
QSA = Cia402State.QUICK_STOP_ACTIVE


def _state(load: JointLoad) -> tuple[object, ...]:
    c = load.cascade
    return (c.current, c.theta, c.omega, c.vint, c.iint, c.kvel_ff, load.ref, load.ref_v,
            load.ff, load.pending_ns, load.last, load.torque)


class JointTwin(Twin):
    """The Twin with a JointLoad behind every drive of both chains; its state comparison
    also compares the joints and the drives' rest caches."""

    def __init__(self, eni: Eni, *, kvel_ff: float | None = 1.0, compare_every: int = 29
                 ) -> None:
        """``kvel_ff`` None: the drives keep their kinematic followers."""
        super().__init__(eni, compare_every=compare_every)
        self.eni = eni
        joints = load_joints()
        self.drives: list[int] = []
        for chain in (self.c, self.py):
            for i, (slave, esc) in enumerate(zip(self.eni.slaves, chain._slaves, strict=True)):
                device = device_of(esc)
                params = find_joint(joints, slave.name)
                if isinstance(device, Cia402Drive) and params is not None:
                    if kvel_ff is not None:
                        device.load = JointLoad(params, kvel_ff=kvel_ff)
                    if chain is self.c:
                        self.drives.append(i)
        self.rested = 0  # comparisons where a drive of the reference was at rest

    def same_state(self) -> None:
        super().same_state()
        for i in self.drives:
            a, b = device_of(self.c.slaves[i]), device_of(self.py.slaves[i])
            assert isinstance(a, Cia402Drive) and isinstance(b, Cia402Drive)
            if not isinstance(b.load, JointLoad):
                continue  # a follower: a step at rest changes nothing, the core takes none
            assert isinstance(a.load, JointLoad)
            assert _state(a.load) == _state(b.load), f"frame {self.frames}, slave {i + 1}"
            assert a.rest_cache == b.rest_cache, f"frame {self.frames}, slave {i + 1}"
            self.rested += b.rest_cache is not None


class JointScript(Script):
    """The master's side: CiA 402 sequences for joints (smooth enough to follow), with
    the objects that set velocities, torques and ramps written between frames."""

    def __init__(self, twin: JointTwin, period_ns: int) -> None:
        super().__init__(twin.eni, twin, plannable_only=False)
        self.period_ns = period_ns
        self.drives = [i + 1 for i in twin.drives]
        self.goal = [0] * 64
        self.seen: dict[str, list[int]] = {}  # the drives' power states at points of run()

    def _powers(self) -> list[int]:
        return [device_of(self.twin.py.slaves[p - 1]).power for p in self.drives]  # type: ignore[union-attr]

    def cycle(self, step_ns: int | None = None) -> None:
        super().cycle(self.period_ns if step_ns is None else step_ns)

    def hold(self, n: int, *, controlword: int = 0x0F, mode: int = 8) -> None:
        out = self.outputs
        for _ in range(n):
            out.set("controlword", controlword)
            out.set("mode", mode)
            out.set("target_position", lambda k: self.goal[k])
            self.cycle()

    def swing(self, n: int, amplitude: int) -> None:
        """CSP: every drive from its goal by amplitude × (k + 1) and back, a cosine."""
        start = list(self.goal)
        for step in range(n):
            s = (1 - math.cos(2 * math.pi * (step + 1) / n)) / 2
            self.goal = [g + round(amplitude * (k + 1) * (-1) ** k * s) for k, g in
                         enumerate(start)]
            self.hold(1)

    def param(self, position: int, index: int, value: int) -> None:
        """An object of the drive at ``position`` set in both chains, as an SDO write
        does it (the core gives the drive back first): deterministic, where the mailbox
        of a Twin, whose firmware runs in random pieces, may not answer in time."""

        def write(chain: Chain) -> None:
            app = chain._slaves[position - 1].app
            if app.before_use is not None:
                app.before_use()
            app.device.od.set(index, 0, value)

        self.twin.both(write)

    def each(self, index: int, value: int) -> None:
        for position in self.drives:
            self.param(position, index, value)

    def enable(self, mode: int = 8) -> None:
        for cw in (0x06, 0x07, 0x0F):
            self.hold(1, controlword=cw, mode=mode)

    def run(self) -> None:
        bring_up(self.bus, self.eni, self.outputs, plannable_only=False)
        twin = self.twin
        self.hold(4, controlword=0x00)
        self.enable()
        self.swing(120, 20_000)  # CSP, no rate limit
        self.each(0x607F, 3_000_000)
        self.swing(80, 40_000)  # CSP with the 0x607F rate limit on the demand
        self.each(0x607F, 0)
        self.hold(700)  # the joints settle: at rest, their steps skipped
        for cw in (0x0F, 0x1F, 0x0F, 0x5F, 0x15F, 0x0F):  # profile position, a halt
            self.hold(1, controlword=cw, mode=1)
        self.hold(40, mode=1)
        self.each(0x60FF, 300_000)
        self.hold(60, mode=9)  # CSV
        self.each(0x6085, 6_000_000)
        self.param(self.drives[1], 0x605A, 2)  # stop, then disabled
        ramp = round(0.125e9 / self.period_ns)  # 125 ms: 300 000/s at 6e6/s² takes 50
        self.hold(ramp, controlword=0x02, mode=9)  # quick stop on the ramp
        self.seen["quick stop"] = self._powers()
        self.hold(3, mode=9)  # option 6: back to operation enabled
        self.enable(mode=9)
        self.hold(30, mode=9)
        self.each(0x6084, 5_000_000)
        self.param(self.drives[0], 0x605E, 1)  # on 0x6084
        twin.both(lambda ch: ch.drive_fault(self.drives[0]))
        self.hold(ramp, mode=9)  # fault reaction on its ramp, the others on
        self.seen["fault reaction"] = self._powers()
        self.hold(5, controlword=0x8F, mode=9)
        self.goal = [0] * 64
        self.each(0x6071, 60)
        self.enable(mode=10)
        self.hold(50, mode=10)  # CST: 60 ‰ of N k_t I_max through the joint
        self.each(0x6076, 50_000)  # the rated torque given: 3 N·m
        self.hold(30, mode=10)
        self.goal = [self._actual(k) for k in range(len(self.goal))]
        self.hold(80)  # CSP from where the torque left each joint
        self.hold(4, controlword=0x00)
        twin.same_state()

    def _actual(self, k: int) -> int:
        """The k-th drive's actual position in the reference (0 past the drives)."""
        if k >= len(self.drives):
            return 0
        device = device_of(self.twin.py.slaves[self.drives[k] - 1])
        assert isinstance(device, Cia402Drive)
        return device.od.get_int(0x6064)


@pytest.mark.parametrize(
    ("period_ns", "compare_every", "kvel_ff"),
    [(500_000, 29, 1.0), (333_333, 0, 1.3), (500_000, 29, None)],
    ids=["2kHz-compared", "3kHz-held", "kinematic"],
)
def test_joints_in_the_core_match_the_reference(
    period_ns: int, compare_every: int, kvel_ff: float | None
) -> None:
    """The script's quick stop and fault reaction ramps run in the core for the kinematic
    follower too (kinematic: the same script without joints)."""
    eni = load_eni(LOLA)
    twin = JointTwin(eni, compare_every=compare_every, kvel_ff=kvel_ff)
    assert len(twin.drives) == 21
    moved, rested_in_core = set(), 0
    script = JointScript(twin, period_ns)

    def note(frame: bytes, t_ns: int, **kw: bool) -> object:
        nonlocal rested_in_core
        reply = process(frame, t_ns, **kw)
        core = twin.c._core
        assert isinstance(core, ChainCore)
        rested_in_core += sum(core._words[i * WORDS + F_REST] for i in twin.drives
                              if i in core.held_devices())
        for i in twin.drives:
            device = device_of(twin.py.slaves[i])
            assert isinstance(device, Cia402Drive)
            if abs(device.od.get_int(0x6064)) > 100:
                moved.add(i)
        return reply

    process, twin.process = twin.process, note  # type: ignore[method-assign]
    script.run()
    assert twin.compiled_frames > 1000  # answered by the C core
    assert twin.held_cycles == len(eni.slaves)  # every drive's cycle, joint and all, in C
    assert moved == set(twin.drives)
    if kvel_ff is None:
        assert rested_in_core == 0  # a follower steps at rest: the same, and cheap
    else:
        assert rested_in_core > 100  # the core skipped steps of drives at rest
    if compare_every and kvel_ff is not None:
        assert twin.rested > 20  # and gave the rest caches back as the reference has them
    # the drive with quick stop option 2 came to rest and went to switch on disabled, the
    # others stayed in quick stop active (6); the faulted one's reaction ended in fault
    assert script.seen["quick stop"][:3] == [QSA, Cia402State.SWITCH_ON_DISABLED, QSA]
    assert script.seen["fault reaction"][0] == Cia402State.FAULT
    assert script.seen["fault reaction"][2:] == [Cia402State.OPERATION_ENABLED] * 19
    final = [device_of(twin.py.slaves[i]) for i in twin.drives]
    assert {d.power for d in final} == {Cia402State.SWITCH_ON_DISABLED}  # type: ignore[union-attr]


@pytest.mark.parametrize("rate_hz", [3000.0])
def test_bus_simulate_with_joints_is_the_same_in_both_engines(
    rate_hz: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``bus simulate --rate 3000 --move all:20000 --joint-model``: every joint in the C
    core, the same moves, following errors and end positions as the Python reference."""
    runs = []
    for engine in ("c", "python"):
        monkeypatch.setenv("LOLACLI_CHAIN_ENGINE", engine)
        options = options_from_cli(rate_hz=rate_hz, duration="0.5s", moves=("all:20000",),
                                   joints=True)
        sim = Simulation(load_eni(LOLA), options)
        result = sim.run()
        core = sim.bus.chain._core
        if engine == "c":
            assert isinstance(core, ChainCore)
            assert core.held_devices() == list(range(25))
        else:
            assert core is None
        runs.append(result)
    c, py = runs
    assert c.doc["verdict"] == py.doc["verdict"] == "pass"
    assert len(c.doc["moves"]) == 21 and all(m["load"] == "joint" for m in c.doc["moves"])
    assert c.doc["moves"] == py.doc["moves"]
    assert c.series is not None and py.series is not None
    errors_c, errors_py = c.series.following_error, py.series.following_error
    assert errors_c.keys() == errors_py.keys() and len(errors_c) == 21
    for name, (t_c, e_c) in errors_c.items():
        t_py, e_py = errors_py[name]
        assert list(t_c) == list(t_py) and list(e_c) == list(e_py), name
        assert max(abs(x) for x in e_c) > 0  # the joints lag: not the follower's zero

