"""``lolacli bus simulate``: the master against the emulated chain in virtual time, or
against a live bus in real time.

:class:`Simulation` builds the chain of an ENI with the requested faults behind the
master's in-process transport (:class:`~lolacli.simulate.bus.VirtualBus`) and lets a
:class:`Master` bring it to
OP, enable every CiA 402 drive and move every joint on a minimum-jerk back-and-forth
(:mod:`lolacli.motion`), recording what was asked for. The report is
``lolacli.simulate/1`` (DESIGN.md).

Faults (the emulator's, see :class:`lolacli.emulator.chain.Faults`): frames dropped on
the master's cable with a probability, slaves stuck in SAFEOP, the cable cut after slave
K from the start or T seconds after the cyclic run starts, clock drift along the line.

With ``iface`` the same master and application run in real time on a network interface
(a ``bus emulate`` on the other end of a veth pair, or hardware) through a
:class:`~lolacli.master.transport.RawSocketTransport`: every cycle is busy-waited at its
end, the thread runs SCHED_FIFO where the OS allows it, and the report adds what real
time costs: the cycle period and its jitter as the frames left, how late each cycle left
against its schedule, frames that came back late or never, the scheduling the OS
granted, the host's load and the master's CPU share.
"""

from __future__ import annotations

import time
from contextlib import nullcontext
from dataclasses import replace
from typing import Any

from lolacli.devices.io import CanGateway
from lolacli.emulator.slave import device_of
from lolacli.eni.model import Eni
from lolacli.errors import TransportError, UsageError
from lolacli.interrupt import Stop
from lolacli.master.core import Master, MasterOptions
from lolacli.master.transport import Transport
from lolacli.simulate.application import Application
from lolacli.simulate.bus import EmulateOptions, VirtualBus
from lolacli.simulate.options import (
    Progress,
    SimulateOptions,
    SimulationResult,
    SimulationSeries,
    busy_wait_us,
    check,
)
from lolacli.simulate.report import (
    LIVE_VARIATION,
    NO_LIVE_KEYS,
    final_states,
    live_states,
    report,
    result,
    timing,
    variation,
)
from lolacli.timing.stats import summarize_array


def simulate(
    eni: Eni,
    options: SimulateOptions,
    *,
    progress: Progress | None = None,
    stop: Stop | None = None,
) -> SimulationResult:
    """Run the simulation (see the module docstring): in virtual time against the
    emulated chain (:class:`Simulation`), or with ``options.iface`` in real time on a
    live bus. ``stop``: the CLI's :class:`~lolacli.interrupt.Stop`; a signal during the
    cyclic run ends it early with the report of the cycles run
    (:attr:`SimulationResult.interrupted`)."""
    check(eni, options)
    if options.iface is not None:
        recorders = _open_recorders(options)
        try:
            return _live(eni, options, recorders, progress, stop)
        finally:
            _close(recorders)
    return Simulation(eni, options).run(progress=progress, stop=stop)


def emulate_options(options: SimulateOptions) -> EmulateOptions:
    """The emulated chain's faults of a simulation."""
    cut = options.link_down
    return EmulateOptions(
        drop_probability=options.drop_probability,
        stuck_safeop=options.stuck_safeop,
        drift_ppb=options.drift_ppb,
        seed=options.seed,
        link_down_after=cut[0] if cut else None,
        link_down_at_s=cut[1] if cut else 0.0,
        bad_link=options.bad_link,
    )


class Simulation:
    """Our master against the emulated chain of ``eni`` in virtual time, with the faults,
    application and recordings of ``options``: :meth:`run` brings the chain to OP, runs
    ``options.cycles`` cycle slots and reports (``lolacli.simulate/1``). :attr:`bus` is
    the :class:`~lolacli.simulate.bus.VirtualBus` it runs on (its chain and transport)."""

    def __init__(self, eni: Eni, options: SimulateOptions) -> None:
        check(eni, options)
        if options.iface is not None:
            raise UsageError("--iface: a live bus is not simulated; use simulate()")
        from lolacli.simulate.variation import line_timing

        self.eni = eni
        self.options = options
        self.timing = line_timing(eni, options.forwarding, options.cable_m)
        faults = replace(emulate_options(options), timing=self.timing)
        self.bus = VirtualBus(eni, faults, host_latency=options.host_latency)
        config = options.can_config()
        for esc in self.bus.chain.slaves:
            device = device_of(esc)
            if isinstance(device, CanGateway):
                device.configure(config)
        _attach_joints(eni, self.bus, options)

    def run(
        self, *, progress: Progress | None = None, stop: Stop | None = None
    ) -> SimulationResult:
        eni, options, bus = self.eni, self.options, self.bus
        recorders = _open_recorders(options)
        shm = None
        try:
            master, app, shm = _compose(eni, options, bus.transport, recorders)
            clock = _clock(master, bus.transport)
            wall0 = time.perf_counter()
            _bring_up(master)
            start_ns = bus.now_ns()
            bus.arm_faults()
            app.enable()
            app.start_run(sensor_ages=True)
            skipped0 = master.stats.skipped_cycles
            clock.active = True
            interrupted = _run(master, options, progress, stop, wall0)
            clock.active = False
            app.end_run()
            app.last_cycle, app.last_skipped = master.stats.cycles, master.stats.skipped_cycles
            master.drain()
            states = app.final_states = final_states(master)
            app.read_drive_faults(states)
            wall_s = time.perf_counter() - wall0
            doc = report(eni, options, master, app, states, wall_s, start_ns, recorders)
            doc.update(NO_LIVE_KEYS)
            doc.update(timing(master, clock, app.skipped_in_run(skipped0, options.cycles)))
            doc.update(variation(eni, options, self.timing))
            return _with_series(result(doc, options, master, app, interrupted, stop), master, app,
                                clock, start_ns)
        finally:
            _close(recorders)
            if shm is not None:
                shm.close()


def _attach_joints(eni: Eni, bus: VirtualBus, options: SimulateOptions) -> None:
    """--joint-model: a :class:`~lolacli.devices.joint_load.JointLoad` behind every drive the
    joints name, k_vel,ff = 1 + --ke (the chain core runs them as the kinematic drives).
    UsageError when no drive of the ENI has one."""
    if not options.joints:
        return
    from lolacli.devices.cia402 import Cia402Drive
    from lolacli.devices.joint_load import JointLoad

    attached = 0
    for slave, esc in zip(eni.slaves, bus.chain.slaves, strict=True):
        device = device_of(esc)
        params = options.joint(slave.name)
        if isinstance(device, Cia402Drive) and params is not None:
            device.load = JointLoad(params, kvel_ff=1.0 + options.k_e)
            attached += 1
    if not attached:
        raise UsageError(
            f"--joints: no drive of {eni.source} has a joint in {options.joints_source} "
            f"(it names {len(options.joints)}, e.g. {options.joints[0].name!r})"
        )


def _with_series(
    res: SimulationResult, master: Master, app: Application, clock: Any, start_ns: int
) -> SimulationResult:
    moves = app.moves.errors([d.slave for d in app.drives]) if app.moves is not None else {}
    res.series = SimulationSeries(
        master.stats.round_trip_ns, clock.sent_ns, master.stats.dc_errors_ns, start_ns, moves
    )
    return res


def _close(recorders: tuple[Any, Any]) -> None:
    for r in recorders:
        if r is not None:
            r.close()


def _compose(
    eni: Eni, options: SimulateOptions, transport: Transport, recorders: tuple[Any, Any]
) -> tuple[Master, Application, Any]:
    """The master over ``transport`` with recorders, application and shared memory."""
    pcap, mcap = recorders
    if pcap is not None:
        transport.taps.append(pcap)
    if mcap is not None:
        transport.taps.append(mcap)  # /frames
    master_options = MasterOptions(
        cycle_time_ns=round(1e9 / options.rate_hz), time_sections=options.time_sections
    )
    if options.iface is not None:
        master_options.frame_timeout_ns = round(options.frame_timeout_ms * 1e6)
        master_options.realtime = True
    master = Master(eni, transport, options=master_options)
    app = Application(master, options)
    shm = None
    if options.shm:
        from lolacli.master.shm import ShmPublisher

        shm = ShmPublisher(options.shm, len(master.image.inputs), len(master.image.outputs))
        app.shm = shm
    app.install(mcap)
    return master, app, shm


def _bring_up(master: Master) -> None:
    master.bring_up(strict=False)
    if master.stats.slaves_found == 0:
        raise TransportError("no slaves answering (the line is cut at the master)")


def _clock(master: Master, transport: Transport) -> Any:
    """A tap that times every cyclic frame against the master's schedule."""
    from lolacli.master.realtime import CycleClock

    clock = CycleClock(master.cycle_time_ns, lambda: master.next_cycle_ns)
    transport.taps.append(clock)
    return clock


def _live(
    eni: Eni,
    options: SimulateOptions,
    recorders: tuple[Any, Any],
    progress: Progress | None,
    stop: Stop | None,
) -> SimulationResult:
    """The master in real time on a live bus (``options.iface``): a raw socket, the
    cycle busy-waited at its end, SCHED_FIFO where permitted (see
    :mod:`lolacli.master.realtime`)."""
    from lolacli.master.realtime import CycleClock, load_now, realtime_section
    from lolacli.master.transport import RawSocketTransport

    assert options.iface is not None
    busy_us = busy_wait_us(options)
    transport = RawSocketTransport(options.iface, spin_ns=round(busy_us * 1000))
    transport.stop = stop  # a slow cycle's wait ends at a stop
    shm = None
    try:
        master, app, shm = _compose(eni, options, transport, recorders)
        clock = CycleClock(master.cycle_time_ns, lambda: master.next_cycle_ns)
        transport.taps.append(clock)
        load_before = load_now()
        with realtime_section(options.realtime_priority, busy_wait_us=busy_us) as scheduling:
            wall0 = time.perf_counter()
            _bring_up(master)
            start_ns = transport.now_ns()
            app.enable()
            app.start_run()
            master.start_cyclic()  # the schedule starts now, not where start-up left it
            skipped0 = master.stats.skipped_cycles
            cpu0, run0 = time.process_time(), time.perf_counter()
            clock.active = True
            wakes: list[int] = []
            transport.wake_lateness_ns = wakes
            interrupted = _run(master, options, progress, stop, wall0)
            app.last_cycle, app.last_skipped = master.stats.cycles, master.stats.skipped_cycles
            transport.wake_lateness_ns = None
            clock.active = False
            cpu_s, run_s = time.process_time() - cpu0, time.perf_counter() - run0
            states = app.final_states = live_states(master)
            master.drain()
            app.read_drive_faults(states)
        wall_s = time.perf_counter() - wall0
        doc = report(eni, options, master, app, states, wall_s, start_ns, recorders)
        doc.update(NO_LIVE_KEYS)
        doc.update(timing(master, clock, app.skipped_in_run(skipped0, options.cycles)))
        doc.update(LIVE_VARIATION)
        wake = summarize_array(wakes)
        doc["wakeup_lateness_us"] = wake.to_dict(scale=1e-3) if wake is not None else None
        doc.update(
            {
                "mode": "realtime",
                "iface": options.iface,
                "bus_emulation_us": None,
                "scheduling": scheduling.to_dict(),
                "load": {"before": load_before, "after": load_now()},
                "master_cpu_percent": round(100 * cpu_s / run_s, 1) if run_s > 0 else None,
                "kernel_timestamps": transport.kernel_timestamps,
            }
        )
        return _with_series(result(doc, options, master, app, interrupted, stop), master, app,
                            clock, start_ns)
    finally:
        transport.close()
        if shm is not None:
            shm.close()


def _open_recorders(options: SimulateOptions) -> tuple[Any, Any]:
    from lolacli.master.record import McapRecorder, PcapngRecorder, WallClock

    clock = WallClock()  # one wall-clock time base for both recordings
    pcap = PcapngRecorder(options.pcap, clock) if options.pcap is not None else None
    try:
        mcap = McapRecorder(options.mcap, clock) if options.mcap is not None else None
    except BaseException:
        if pcap is not None:
            pcap.close()
        raise
    return pcap, mcap


def _run(
    master: Master,
    options: SimulateOptions,
    progress: Progress | None,
    stop: Stop | None,
    wall0: float,
) -> bool:
    """The cyclic run over ``options.cycles`` cycle slots (a cycle that runs past the next
    slot makes the master skip it, as a cycle timer does); True when stopped early by
    ``stop`` (a signal, polled between cycles so that what ran is whole)."""
    if not master.cycling:
        master.start_cyclic()
    stats = master.stats
    target = stats.cycles + stats.skipped_cycles + options.cycles
    cycle = master.cycle
    # a look at the stop request every 50 ms of the schedule (at most 256 cycles apart)
    step = max(1, min(256, round(options.rate_hz / 20)))
    virtual0 = master.transport.now_ns()
    with stop.polled() if stop is not None else nullcontext():
        while True:
            done = stats.cycles + stats.skipped_cycles
            if done >= target:
                return False
            for _ in range(min(step, target - done)):
                cycle()
                if stats.skipped_cycles and stats.cycles + stats.skipped_cycles >= target:
                    break
            if progress is not None:
                slots = stats.cycles + stats.skipped_cycles - (target - options.cycles)
                progress(min(options.cycles, slots), options.cycles)
            if stop is not None and stop():
                return True
            if options.pace:
                now_s = (master.transport.now_ns() - virtual0) / 1e9
                ahead = now_s - (time.perf_counter() - wall0)
                if ahead > 0:
                    time.sleep(min(ahead, 0.1))
