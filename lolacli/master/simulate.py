"""``lolacli bus simulate``: the master against the emulated chain in virtual time, or
against a live bus in real time.

The one module of :mod:`lolacli.master` that knows the emulator: it builds the chain of an
ENI with the requested faults (:func:`lolacli.emulator.run.make_chain`), puts it behind a
:class:`~lolacli.master.transport.ChainTransport` and lets a :class:`Master` bring it to
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
from collections.abc import Callable
from contextlib import nullcontext
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from lolacli.eni.model import Eni
from lolacli.errors import EniError, LinkError, TransportError, UsageError
from lolacli.findings import Finding, Findings, Severity, verdict
from lolacli.interrupt import Stop
from lolacli.master.core import SECTIONS, Master, MasterOptions
from lolacli.master.slaves import Cia402Drive, ForceTorqueSensor, Imu, has_field
from lolacli.master.transport import ChainTransport, Transport
from lolacli.master.variables import BusVariable, variable_for
from lolacli.motion.profile import back_and_forth
from lolacli.text import transition_text
from lolacli.timing.model import (
    INTER_FRAME_GAP_BYTES,
    LINK_100_MBIT_S,
    PREAMBLE_SFD_BYTES,
    wire_time_ns,
)
from lolacli.timing.stats import summarize_array
from lolacli.wire.commands import Command
from lolacli.wire.frame import Datagram
from lolacli.wire.registers import Register, al_state_name

SCHEMA = "lolacli.simulate/1"


@dataclass(frozen=True, slots=True)
class SimulateOptions:
    rate_hz: float = 2000.0
    cycles: int = 20_000
    pcap: Path | None = None
    mcap: Path | None = None
    drop_probability: float = 0.0
    stuck_safeop: tuple[int, ...] = ()
    link_down: tuple[int, float] | None = None  # (after slave K, seconds into the run; 0: start)
    drift_ppb: int = 0
    seed: int = 0
    middleware: bool = True  # Bus Variables, drives enabled, joints moving
    shm: str | None = None
    pace: bool = False  # no faster than real time
    watch: tuple[str, ...] = ()
    set_values: tuple[tuple[str, str], ...] = ()
    amplitude_counts: int = 20_000
    period_s: float = 2.0
    time_sections: bool = True
    iface: str | None = None  # a live bus in real time instead of the emulated chain
    # live: busy-wait this last part of every cycle (None: 200 µs, at most 40% of a cycle)
    busy_wait_us: float | None = None
    realtime_priority: int = 80  # live: SCHED_FIFO priority where permitted (0: do not ask)
    frame_timeout_ms: float = 10.0  # live: an acyclic frame not back by then is lost
    max_lost: int = 0  # lost frames allowed before the run fails
    max_wkc_mismatches: int = 0
    max_overruns: int = 0  # cycles not kept (slots skipped + sent over half a cycle late)


@dataclass(slots=True)
class SimulationResult:
    doc: dict[str, Any]
    failed: bool
    interrupted: bool = False
    notes: list[str] = field(default_factory=list)


Progress = Callable[[int, int], None]


def simulate(
    eni: Eni,
    options: SimulateOptions,
    *,
    progress: Progress | None = None,
    stop: Stop | None = None,
) -> SimulationResult:
    """Run the simulation (see the module docstring). ``stop``: the CLI's
    :class:`~lolacli.interrupt.Stop`; a signal during the cyclic run ends it early with the
    report of the cycles run (:attr:`SimulationResult.interrupted`)."""
    _check(eni, options)
    recorders = _open_recorders(options)
    shm = None
    try:
        if options.iface is not None:
            return _live(eni, options, recorders, progress, stop)
        from lolacli.emulator.run import EmulateOptions, arm_link_loss, make_chain

        cut = options.link_down
        emulate = EmulateOptions(
            drop_probability=options.drop_probability,
            stuck_safeop=options.stuck_safeop,
            drift_ppb=options.drift_ppb,
            seed=options.seed,
            link_down_after=cut[0] if cut else None,
            link_down_at_s=cut[1] if cut else 0.0,
        )
        chain = make_chain(eni, emulate)
        transport = ChainTransport(chain)
        master, app, shm = _compose(eni, options, transport, recorders)
        clock = _clock(master, transport)
        wall0 = time.perf_counter()
        _bring_up(master)
        start_ns = transport.now_ns()
        arm_link_loss(chain, emulate, start_ns)
        app.enable()
        app.start_run()
        skipped0 = master.stats.skipped_cycles
        clock.active = True
        interrupted = _run(master, options, progress, stop, wall0)
        clock.active = False
        app.last_cycle, app.last_skipped = master.stats.cycles, master.stats.skipped_cycles
        master.drain()
        states = app.final_states = _final_states(master)
        wall_s = time.perf_counter() - wall0
        doc = _report(eni, options, master, app, states, wall_s, start_ns, recorders)
        doc.update(_NO_LIVE_KEYS)
        doc.update(_timing(master, clock, app.skipped_in_run(skipped0, options.cycles)))
        return _result(doc, options, master, app, interrupted, stop)
    finally:
        for r in recorders:
            if r is not None:
                r.close()
        if shm is not None:
            shm.close()


def _compose(
    eni: Eni, options: SimulateOptions, transport: Transport, recorders: tuple[Any, Any]
) -> tuple[Master, _Application, Any]:
    """The master over ``transport`` with recorders, application and shared memory."""
    pcap, mcap = recorders
    if pcap is not None:
        transport.taps.append(pcap)
    master_options = MasterOptions(
        cycle_time_ns=round(1e9 / options.rate_hz), time_sections=options.time_sections
    )
    if options.iface is not None:
        master_options.frame_timeout_ns = round(options.frame_timeout_ms * 1e6)
        master_options.realtime = True
    master = Master(eni, transport, options=master_options)
    app = _Application(master, options)
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


def _result(
    doc: dict[str, Any],
    options: SimulateOptions,
    master: Master,
    app: _Application,
    interrupted: bool,
    stop: Stop | None,
) -> SimulationResult:
    doc["interrupted"] = interrupted
    findings = _findings(doc, options, master, app, stop if interrupted else None)
    doc["verdict"] = verdict(findings)
    doc["findings"] = [f.to_dict() for f in findings]
    return SimulationResult(doc, doc["verdict"] == "fail", interrupted)


def _findings(
    doc: dict[str, Any],
    options: SimulateOptions,
    master: Master,
    app: _Application,
    stopped: Stop | None,
) -> list[Finding]:
    """The verdict's findings (the one model of :mod:`lolacli.findings`)."""
    out = Findings()
    stats = master.stats
    fail, warn = Severity.FAILURE, Severity.WARNING
    for r in master.refusals:
        code = "" if r.al_status_code is None else f", AL status code 0x{r.al_status_code:04X}"
        out.add("refused", fail, f"slave {r.position} ({r.slave}) refused "
                f"{transition_text(r.transition)}{code}: {r.text}", slave=r.position)
    refused = {r.position for r in master.refusals}
    for slave in master.eni.slaves:
        state = app.final_states.get(slave.position, "no answer")
        if state != "OP" and slave.position not in refused:
            out.add("not-op", fail, f"slave {slave.position} ({slave.name}) ended in {state}, "
                    "not OP", slave=slave.position)
    _overrun_finding(out, doc, master, options, app)
    lost, late = doc["lost_frames"], doc["late_frames"] or 0
    over = lost + late > options.max_lost
    if lost:
        cyclic = doc["cyclic_lost_frames"]
        out.add("lost", fail if over else warn,
                f"{lost:,} frames never came back ({cyclic:,} of them cyclic; threshold "
                f"--max-lost {options.max_lost})", cycles=app.run_cycles(master.lost_cycles()),
                count=lost)
    if late:
        out.add("late", fail if over else warn,
                f"{late:,} cyclic frames came back after their cycle had ended: those cycles "
                "ran without their inputs", cycles=app.run_cycles(stats.late_at), count=late)
    if doc["wkc_mismatches"]:
        out.add("wkc-mismatch", fail if doc["wkc_mismatches"] > options.max_wkc_mismatches
                else warn,
                f"{doc['wkc_mismatches']:,} of {doc['wkc_checked']:,} working counters differed"
                f" from the ENI's <Cnt>, in {doc['cycles_with_wkc_mismatch']:,} cycles (threshold "
                f"--max-wkc-mismatches {options.max_wkc_mismatches})",
                cycles=app.run_cycles(stats.mismatch_at), count=doc["wkc_mismatches"])
    if doc["drives_enabled"] < doc["drives"]:
        out.add("drives-disabled", warn,
                f"{doc['drives'] - doc['drives_enabled']} of {doc['drives']} drives were not "
                "enabled (CiA 402 state machine short of Operation enabled)")
    for name, value in doc["watch"].items():
        shown = f"{value:.6g}" if isinstance(value, float) else value
        out.add("watch", Severity.INFO, f"{name} = {shown} (last value)")
    if stopped is not None:
        signame = "SIGTERM" if stopped.exit_code == 143 else "SIGINT"
        out.add("interrupted", warn,
                f"stopped by {signame} after {doc['cycles']:,} cycles of {options.cycles:,}: the "
                "figures cover the cycles run")
    return out.ordered()


def _overrun_finding(
    out: Findings, doc: dict[str, Any], master: Master, options: SimulateOptions,
    app: _Application,
) -> None:
    """Cycles not kept: the slots skipped and the cycles sent over half a cycle late, and
    why — a bus too slow for the rate (with the rate it holds), or the host."""
    skipped, overruns = doc["skipped_cycles"] or 0, doc["overruns"] or 0
    if not skipped and not overruns:
        return
    cycle_us = master.cycle_time_ns / 1000
    rt = doc["round_trip_us"]
    why = ""
    holds = doc["max_rate_with_software_hz"] or doc["max_rate_hz"]
    if rt is not None and doc["max_rate_hz"]:
        why = (f"; a round trip takes {rt['median']:g} µs, so this bus holds at most "
               f"{doc['max_rate_hz']:,} Hz")
        if doc["max_rate_with_software_hz"]:
            why += f" ({doc['max_rate_with_software_hz']:,} Hz with the software)"
        if holds and holds >= doc["rate_hz"]:
            why += ": the cycles were lost to the host (scheduling, load), not to the bus"
    severity = Severity.FAILURE if skipped + overruns > options.max_overruns else Severity.WARNING
    out.add("overrun", severity,
            f"the cycle of {cycle_us:g} µs ({doc['rate_hz']:,g} Hz) was not kept: {skipped:,} "
            f"cycle slots skipped, {overruns:,} cycles sent over half a cycle late (threshold "
            f"--max-overruns {options.max_overruns}){why}",
            cycles=app.run_cycles(master.stats.skipped_at), count=skipped + overruns)


#: keys only a run on a live bus fills (null in virtual time)
_NO_LIVE_KEYS: dict[str, Any] = {
    "mode": "virtual",
    "iface": None,
    "wakeup_lateness_us": None,
    "scheduling": None,
    "load": None,
    "master_cpu_percent": None,
    "kernel_timestamps": None,
}


def _clock(master: Master, transport: Transport) -> Any:
    """A tap that times every cyclic frame against the master's schedule."""
    from lolacli.master.realtime import CycleClock

    clock = CycleClock(master.cycle_time_ns, lambda: master.next_cycle_ns)
    transport.taps.append(clock)
    return clock


def _timing(master: Master, clock: Any, skipped: int) -> dict[str, Any]:
    """Cycle period, jitter and lateness as the frames left, in both times; frames late
    and never back as the master saw them (a late one came back after it had stopped
    waiting: the cycle ran without its inputs)."""
    stats = master.stats
    doc: dict[str, Any] = clock.report(master.cycle_time_ns)
    doc["late_frames"] = stats.late_frames
    doc["never_returned_frames"] = stats.cyclic_lost
    doc["skipped_cycles"] = skipped
    return doc


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
        with realtime_section(
            options.realtime_priority, busy_wait_us=busy_us
        ) as scheduling:
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
            states = app.final_states = _live_states(master)
            master.drain()
        wall_s = time.perf_counter() - wall0
        doc = _report(eni, options, master, app, states, wall_s, start_ns, recorders)
        doc.update(_NO_LIVE_KEYS)
        doc.update(_timing(master, clock, app.skipped_in_run(skipped0, options.cycles)))
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
        return _result(doc, options, master, app, interrupted, stop)
    finally:
        transport.close()
        if shm is not None:
            shm.close()


#: the most cycle slots one run takes: the per-cycle figures are kept for the statistics
#: (about 100 B a cycle), so a longer run would outgrow the memory of a small host
MAX_CYCLES = 20_000_000
MAX_RATE_HZ = 100_000.0


def _check(eni: Eni, options: SimulateOptions) -> None:
    """Options no bus can have: UsageError naming the option and its range (exit 2)."""
    from lolacli.emulator.run import MAX_DRIFT_PPB

    if not eni.slaves:
        raise EniError("the ENI has no <Slave>: nothing to simulate", path=eni.source)
    if not eni.cyclic_frames:
        raise EniError("the ENI has no cyclic frame: nothing to simulate", path=eni.source)
    n = len(eni.slaves)
    if not 1.0 <= options.rate_hz <= MAX_RATE_HZ:
        raise UsageError(f"--rate {options.rate_hz:g}: expected 1 to {MAX_RATE_HZ:.0f} Hz")
    if not 1 <= options.cycles <= MAX_CYCLES:
        raise UsageError(
            f"--cycles {options.cycles}: expected 1 to {MAX_CYCLES:,} cycles (a --duration "
            "shorter than one cycle is 0 cycles)"
        )
    if not 0.0 <= options.drop_probability <= 1.0:
        raise UsageError(f"--drop-p {options.drop_probability:g}: expected 0 to 1")
    if abs(options.drift_ppb) > MAX_DRIFT_PPB:
        raise UsageError(
            f"--drift-ppb {options.drift_ppb}: expected -{MAX_DRIFT_PPB:,} to "
            f"{MAX_DRIFT_PPB:,} ppb (a crystal drifts about ±100,000 ppb)"
        )
    for position in options.stuck_safeop:
        if not 1 <= position <= n:
            raise UsageError(f"--stuck-safeop {position}: expected a slave position 1 to {n}")
    if options.link_down is not None:
        after, at_s = options.link_down
        if not 0 <= after <= n:
            raise UsageError(f"--link-down {after}: expected 0 (at the master) to {n}")
        run_s = options.cycles / options.rate_hz
        if at_s >= run_s:
            raise UsageError(
                f"--link-down {after}@{at_s:g}s: after the run ends ({run_s:g} s of cycles)"
            )
    if options.iface is not None:
        _check_live(options)


def _check_live(options: SimulateOptions) -> None:
    faults = [
        name
        for name, given in (
            ("--drop-p", options.drop_probability > 0),
            ("--stuck-safeop", bool(options.stuck_safeop)),
            ("--link-down", options.link_down is not None),
            ("--drift-ppb", options.drift_ppb != 0),
        )
        if given
    ]
    if faults:
        raise UsageError(
            f"{', '.join(faults)}: faults of the emulated chain; on a live bus give them "
            "to the `bus emulate` serving it"
        )
    if options.pace:
        raise UsageError("--pace: a live bus runs in real time anyway")
    busy = options.busy_wait_us
    if busy is not None and (busy < 0 or busy * 1000 > 1e9 / options.rate_hz):
        raise UsageError(
            f"--busy-wait-us {busy:g}: expected 0 to one cycle time ({1e6 / options.rate_hz:g} µs)"
        )


def busy_wait_us(options: SimulateOptions) -> float:
    """The busy-wait of a live cycle: as given, else 200 µs but at most 40% of a cycle."""
    if options.busy_wait_us is not None:
        return options.busy_wait_us
    return min(200.0, 0.4 * 1e6 / options.rate_hz)


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


class _Application:
    """What runs on top of the middleware: drives enabled, joints moving, sensors read,
    --set/--watch variables, shared memory, MCAP."""

    def __init__(self, master: Master, options: SimulateOptions) -> None:
        self.master = master
        self.options = options
        self.drives: list[Cia402Drive] = []
        self.sensors: list[Any] = []
        self.watch: dict[str, BusVariable] = {}
        self.fixed: list[tuple[BusVariable, Any]] = []
        self.shm: Any = None
        self.mcap: Any = None
        self.homes: dict[int, int] = {}
        self.final_states: dict[int, str] = {}  # position -> AL state at the end
        self.t_enable_ns = 0
        self.first_cycle = 0
        # the cycle count when the run's own cycles ended (a live run's closing reads of
        # the AL states go on cycling, and those cycles are not the run's)
        self.last_cycle: int | None = None
        self.last_skipped = 0
        image = master.image
        for name in options.watch:
            self.watch[name] = image.link(name, variable_for(image.find(name)))
        for name, text in options.set_values:
            variable = image.link(name, variable_for(image.find(name)))
            self.fixed.append((variable, _parse_value(variable, text)))
        if options.middleware:
            self._devices()

    def _devices(self) -> None:
        master = self.master
        for slave in master.eni.slaves:
            if has_field(master.image, slave.name, Cia402Drive.statusword) and has_field(
                master.image, slave.name, Cia402Drive.target
            ):
                self.drives.append(Cia402Drive(master, slave.name))
            elif has_field(master.image, slave.name, Imu.rate_x):
                self.sensors.append(Imu(master, slave.name))
                for side in ("left", "right"):
                    try:
                        self.sensors.append(ForceTorqueSensor(master, slave.name, side))
                    except LinkError:
                        pass

    def install(self, mcap: Any) -> None:
        self.mcap = mcap
        master = self.master
        if self.shm is not None:
            master.control.append(self._publish)
        if self.drives:
            master.control.append(self._move)
        if self.fixed:
            master.control.append(self._set_fixed)
        if self.shm is not None:
            master.control.append(self._apply_shm)
        if mcap is not None:
            master.admin.append(self._record)

    def start_run(self) -> None:
        """The cyclic run starts: findings name its cycles from 0 on (those of the
        bring-up before it are forgotten)."""
        stats = self.master.stats
        self.first_cycle = stats.cycles
        for at in (stats.lost_at, stats.late_at, stats.mismatch_at, stats.skipped_at):
            at.clear()

    def skipped_in_run(self, skipped0: int, slots: int) -> int:
        """The slots of the run skipped (a stall in its last cycle skips past its end:
        those are not the run's)."""
        ran = (self.last_cycle or 0) - self.first_cycle
        return max(0, min(self.last_skipped - skipped0, slots - ran))

    def run_cycles(self, cycles: list[int]) -> list[int]:
        """``cycles`` (the master's count) as cycles of the run, 0 its first."""
        return [c - self.first_cycle for c in cycles if c >= self.first_cycle]

    def enable(self) -> None:
        for drive in self.drives:
            drive.enable()
        self.t_enable_ns = self.master.transport.now_ns()

    def _publish(self, master: Master) -> None:
        self.shm.publish(master.stats.cycles, master.transport.now_ns(), master.image.inputs)

    def _apply_shm(self, master: Master) -> None:
        with master.image.lock:
            self.shm.apply(master.image.outputs)

    def _set_fixed(self, master: Master) -> None:
        for variable, value in self.fixed:
            variable.value = value

    def _move(self, master: Master) -> None:
        t = master.transport.now_ns() - self.t_enable_ns
        period = round(self.options.period_s * 1e9)
        amplitude = self.options.amplitude_counts
        homes = self.homes
        for i, drive in enumerate(self.drives):
            if not drive.enabled:
                continue
            home = homes.get(i)
            if home is None:
                home = homes[i] = drive.actual_position
            sign = 1 if i % 2 == 0 else -1
            drive.target_position = home + round(sign * back_and_forth(t, period, amplitude))

    def _record(self, master: Master) -> None:
        stats = master.stats
        t = master.transport.now_ns()
        rt = stats.round_trip_ns[-1] if stats.round_trip_ns else None
        sections = {name: values[-1] for name, values in master.sections_ns.items() if values}
        self.mcap.write(
            "/cycle",
            t,
            {
                "cycle": stats.cycles,
                "t_ns": t,
                "round_trip_ns": rt,
                "wkc_mismatches": stats.wkc_mismatches,
                "lost_frames": stats.frames_lost,
                "sections_ns": sections,
            },
        )
        if self.drives:
            self.mcap.write(
                "/joints",
                t,
                {
                    "cycle": stats.cycles,
                    "names": [d.slave for d in self.drives],
                    "target": [d.target_position for d in self.drives],
                    "actual": [d.actual_position for d in self.drives],
                },
            )
        if stats.dc_errors_ns and stats.dc_errors_ns[-1][0] >= t - master.cycle_time_ns:
            at, worst = stats.dc_errors_ns[-1]
            self.mcap.write("/dc", at, {"t_ns": at, "max_error_ns": worst})


def _parse_value(variable: BusVariable, text: str) -> Any:
    """A --set value for ``variable``'s type; LinkError (exit 2) when it does not parse."""
    from lolacli.master.variables import BusBool, BusBytes, BusReal32

    try:
        if isinstance(variable, BusBool):
            lowered = text.strip().lower()
            if lowered not in ("0", "1", "true", "false"):
                raise ValueError
            value: Any = lowered in ("1", "true")
        elif isinstance(variable, BusReal32):
            value = float(text)
        elif isinstance(variable, BusBytes):
            value = bytes.fromhex(text)
        else:
            value = int(text, 0)
    except ValueError:
        raise LinkError(
            variable.name, f"{text!r} is not a value of type {type(variable).__name__}"
        ) from None
    variable.check(value)
    return value


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


def _live_states(master: Master) -> dict[int, str]:
    """AL state of every slave at the end of a live run, read in one frame while the
    master still cycles (read after the cycling stops, one frame per slave, a slow host
    takes long enough for the slaves' process-data watchdogs to drop them to SAFEOP)."""
    try:
        got = master.al_states()
    except TransportError:
        return {s.position: "no answer" for s in master.eni.slaves}
    return {
        s.position: al_state_name(status) if status is not None else "no answer"
        for s, (_position, status) in zip(master.eni.slaves, got, strict=True)
    }


def _final_states(master: Master) -> dict[int, str]:
    """AL state of every slave at the end (the capture's closing frames): after twice the
    frame timeout, so every earlier frame is older than a capture reader's timeout."""
    master.idle(2 * master.options.frame_timeout_ns)
    out: dict[int, str] = {}
    for s in master.eni.slaves:
        read = Datagram.physical(Command.FPRD, s.station_address, Register.AL_STATUS, 2)
        try:
            got = master.exchange([read], retries=20)[0]
        except TransportError:
            out[s.position] = "no answer"
            continue
        out[s.position] = al_state_name(got.data[0]) if got.wkc == 1 else "no answer"
    return out


def _report(
    eni: Eni,
    options: SimulateOptions,
    master: Master,
    app: _Application,
    states: dict[int, str],
    wall_s: float,
    start_ns: int,
    recorders: tuple[Any, Any],
) -> dict[str, Any]:
    stats = master.stats
    frame = eni.cyclic_frames[0]
    n_bytes = frame.frame_bytes
    rt = summarize_array(stats.round_trip_ns)
    sections: dict[str, Any] = {}
    software_ns = 0.0
    first = app.first_cycle
    timed_from = first - (stats.cycles - len(master.sections_ns["rx"]))
    for name, thread in SECTIONS:
        s = summarize_array(master.sections_ns[name][timed_from:])
        if s is not None:
            sections[name] = {"thread": thread, **s.to_dict(scale=1e-3)}
            software_ns += s.mean
    run_cycles = (stats.cycles if app.last_cycle is None else app.last_cycle) - first
    simulated_s = run_cycles * master.cycle_time_ns / 1e9
    emulation = summarize_array(master.bus_emulation_ns[timed_from:])
    # the rate the bus holds in a typical cycle: the median round trip (late frames that
    # waited behind others in a queue would drag a mean far from it)
    rt_typical = rt.median if rt is not None else None
    dc_errors = [e for t, e in stats.dc_errors_ns if t >= start_ns]
    pcap, mcap = recorders
    return {
        "schema": SCHEMA,
        "eni": eni.source,
        "rate_hz": options.rate_hz,
        "cycle_time_us": master.cycle_time_ns / 1000,
        "cycles": run_cycles,
        "startup_cycles": first,
        "slaves": len(eni.slaves),
        "frame_bytes": n_bytes,
        "wire_time_us": wire_time_ns(n_bytes, LINK_100_MBIT_S) / 1000,
        "wire_time_with_overhead_us": wire_time_ns(
            n_bytes + PREAMBLE_SFD_BYTES + INTER_FRAME_GAP_BYTES, LINK_100_MBIT_S
        )
        / 1000,
        "round_trip_us": rt.to_dict(scale=1e-3) if rt is not None else None,
        "wkc_mismatches": stats.wkc_mismatches,
        "wkc_checked": stats.wkc_checked,
        "cycles_with_wkc_mismatch": stats.cycles_with_mismatch,
        "lost_frames": stats.frames_lost,
        "cyclic_lost_frames": stats.cyclic_lost,
        "frames_sent": stats.frames_sent,
        "cyclic_frames": stats.cyclic_frames,
        "acyclic_frames": stats.acyclic_frames,
        "dc_max_error_ns": max(dc_errors) if dc_errors else None,
        "dc_slaves": len(master.dc_slaves),
        "dc_reference": master.dc_reference.name if master.dc_reference else None,
        "sections_us": sections,
        "software_us_per_cycle": round(software_ns / 1000, 3) if sections else None,
        "bus_emulation_us": emulation.to_dict(scale=1e-3) if emulation is not None else None,
        "max_rate_hz": round(1e9 / rt_typical) if rt_typical else None,
        "max_rate_with_software_hz": round(1e9 / (rt_typical + software_ns))
        if rt_typical and sections
        else None,
        "realtime_factor": round(simulated_s / wall_s, 3) if wall_s > 0 else None,
        "simulated_s": simulated_s,
        "wall_s": round(wall_s, 3),
        "refusals": [r.to_dict() for r in master.refusals],
        "states": {s.name: states.get(s.position, "no answer") for s in eni.slaves},
        "drives": len(app.drives),
        "drives_enabled": sum(1 for d in app.drives if d.enabled),
        "watch": {name: _jsonable(v.value) for name, v in app.watch.items()},
        "faults": {
            "drop_p": options.drop_probability,
            "stuck_safeop": list(options.stuck_safeop),
            "link_down": list(options.link_down) if options.link_down else None,
            "drift_ppb": options.drift_ppb,
            "seed": options.seed,
        },
        "pcap": {"path": pcap.path, "frames": pcap.frames} if pcap is not None else None,
        "mcap": {"path": mcap.path, "messages": mcap.messages} if mcap is not None else None,
        "shm": options.shm,
    }


def _jsonable(value: Any) -> Any:
    return value.hex() if isinstance(value, bytes) else value
