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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from lolacli.eni.model import Eni
from lolacli.errors import EniError, LinkError, TransportError, UsageError
from lolacli.master.core import SECTIONS, Master, MasterOptions
from lolacli.master.slaves import Cia402Drive, ForceTorqueSensor, Imu, has_field
from lolacli.master.transport import ChainTransport, Transport
from lolacli.master.variables import BusVariable, variable_for
from lolacli.motion.profile import back_and_forth
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
    busy_wait_us: float = 200.0  # live: busy-wait this last part of every cycle
    realtime_priority: int = 80  # live: SCHED_FIFO priority where permitted (0: do not ask)
    frame_timeout_ms: float = 10.0  # live: an acyclic frame not back by then is lost
    max_lost: int = 0  # lost frames allowed before the run fails
    max_wkc_mismatches: int = 0


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
    should_stop: Callable[[], bool] | None = None,
) -> SimulationResult:
    """Run the simulation (see the module docstring)."""
    _check(eni, options)
    recorders = _open_recorders(options)
    shm = None
    try:
        if options.iface is not None:
            return _live(eni, options, recorders, progress, should_stop)
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
        wall0 = time.perf_counter()
        _bring_up(master)
        start_ns = transport.now_ns()
        arm_link_loss(chain, emulate, start_ns)
        app.enable()
        app.first_cycle = master.stats.cycles
        interrupted = _run(master, options, progress, should_stop, wall0)
        app.last_cycle = master.stats.cycles
        master.drain()
        states = _final_states(master)
        wall_s = time.perf_counter() - wall0
        doc = _report(eni, options, master, app, states, wall_s, start_ns, recorders)
        doc.update(_NO_LIVE_KEYS)
        return _result(doc, options, master, interrupted)
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
    doc: dict[str, Any], options: SimulateOptions, master: Master, interrupted: bool
) -> SimulationResult:
    doc["interrupted"] = interrupted
    failed = bool(
        doc["wkc_mismatches"] > options.max_wkc_mismatches
        or doc["lost_frames"] > options.max_lost
        or master.refusals
    )
    return SimulationResult(doc, failed, interrupted)


#: keys only a run on a live bus fills (null in virtual time)
_NO_LIVE_KEYS: dict[str, Any] = {
    "mode": "virtual",
    "iface": None,
    "cycle_period_us": None,
    "cycle_jitter_us": None,
    "wakeup_lateness_us": None,
    "send_offset_us": None,
    "overruns": None,
    "late_frames": None,
    "never_returned_frames": None,
    "scheduling": None,
    "load": None,
    "master_cpu_percent": None,
    "kernel_timestamps": None,
    "skipped_cycles": None,
}


def _live(
    eni: Eni,
    options: SimulateOptions,
    recorders: tuple[Any, Any],
    progress: Progress | None,
    should_stop: Callable[[], bool] | None,
) -> SimulationResult:
    """The master in real time on a live bus (``options.iface``): a raw socket, the
    cycle busy-waited at its end, SCHED_FIFO where permitted (see
    :mod:`lolacli.master.realtime`)."""
    from lolacli.master.realtime import CycleClock, load_now, realtime_section
    from lolacli.master.transport import RawSocketTransport

    assert options.iface is not None
    transport = RawSocketTransport(options.iface, spin_ns=round(options.busy_wait_us * 1000))
    shm = None
    try:
        master, app, shm = _compose(eni, options, transport, recorders)
        clock = CycleClock(master.cycle_time_ns, lambda: master.next_cycle_ns)
        transport.taps.append(clock)
        load_before = load_now()
        with realtime_section(
            options.realtime_priority, busy_wait_us=options.busy_wait_us
        ) as scheduling:
            wall0 = time.perf_counter()
            _bring_up(master)
            start_ns = transport.now_ns()
            app.enable()
            app.first_cycle = master.stats.cycles
            master.start_cyclic()  # the schedule starts now, not where start-up left it
            skipped0 = master.stats.skipped_cycles
            cpu0, run0 = time.process_time(), time.perf_counter()
            clock.active = True
            wakes: list[int] = []
            transport.wake_lateness_ns = wakes
            interrupted = _run(master, options, progress, should_stop, wall0)
            app.last_cycle = master.stats.cycles
            transport.wake_lateness_ns = None
            clock.active = False
            cpu_s, run_s = time.process_time() - cpu0, time.perf_counter() - run0
            states = _live_states(master)
            master.drain()
        wall_s = time.perf_counter() - wall0
        doc = _report(eni, options, master, app, states, wall_s, start_ns, recorders)
        doc.update(_NO_LIVE_KEYS)
        doc.update(clock.report(master.cycle_time_ns))
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
                "skipped_cycles": master.stats.skipped_cycles - skipped0,
            }
        )
        return _result(doc, options, master, interrupted)
    finally:
        transport.close()
        if shm is not None:
            shm.close()


def _check(eni: Eni, options: SimulateOptions) -> None:
    if not eni.slaves:
        raise EniError("the ENI has no <Slave>: nothing to simulate", path=eni.source)
    if not eni.cyclic_frames:
        raise EniError("the ENI has no cyclic frame: nothing to simulate", path=eni.source)
    if not 1.0 <= options.rate_hz <= 100_000.0:
        raise UsageError(f"--rate {options.rate_hz:g}: expected 1 to 100000 Hz")
    if options.cycles < 0:
        raise UsageError("the number of cycles cannot be negative")
    if options.iface is not None:
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
        if options.busy_wait_us < 0 or options.busy_wait_us * 1000 > 1e9 / options.rate_hz:
            raise UsageError(
                f"--busy-wait-us {options.busy_wait_us:g}: expected 0 to one cycle time"
            )


def _open_recorders(options: SimulateOptions) -> tuple[Any, Any]:
    from lolacli.master.record import McapRecorder, PcapngRecorder

    pcap = PcapngRecorder(options.pcap) if options.pcap is not None else None
    try:
        mcap = McapRecorder(options.mcap) if options.mcap is not None else None
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
        self.t_enable_ns = 0
        self.first_cycle = 0
        # the cycle count when the run's own cycles ended (a live run's closing reads of
        # the AL states go on cycling, and those cycles are not the run's)
        self.last_cycle: int | None = None
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
    variable._check(value)
    return value


def _run(
    master: Master,
    options: SimulateOptions,
    progress: Progress | None,
    should_stop: Callable[[], bool] | None,
    wall0: float,
) -> bool:
    """The cyclic run; True when stopped early by ``should_stop``."""
    if not master._cyclic:
        master.start_cyclic()
    total = options.cycles
    cycle = master.cycle
    step = 256
    virtual0 = master.transport.now_ns()
    done = 0
    while done < total:
        n = min(step, total - done)
        for _ in range(n):
            cycle()
        done += n
        if progress is not None:
            progress(done, total)
        if should_stop is not None and should_stop():
            return True
        if options.pace:
            ahead = (master.transport.now_ns() - virtual0) / 1e9 - (time.perf_counter() - wall0)
            if ahead > 0:
                time.sleep(ahead)
    return False


def _live_states(master: Master) -> dict[str, str]:
    """AL state of every slave at the end of a live run, read in one frame while the
    master still cycles (read after the cycling stops, one frame per slave, a slow host
    takes long enough for the slaves' process-data watchdogs to drop them to SAFEOP)."""
    try:
        got = master.al_states()
    except TransportError:
        return {s.name: "no answer" for s in master.eni.slaves}
    return {
        s.name: al_state_name(status) if status is not None else "no answer"
        for s, (_position, status) in zip(master.eni.slaves, got, strict=True)
    }


def _final_states(master: Master) -> dict[str, str]:
    """AL state of every slave at the end (the capture's closing frames): after twice the
    frame timeout, so every earlier frame is older than a capture reader's timeout."""
    master.idle(2 * master.options.frame_timeout_ns)
    out: dict[str, str] = {}
    for s in master.eni.slaves:
        read = Datagram.physical(Command.FPRD, s.station_address, Register.AL_STATUS, 2)
        try:
            got = master.exchange([read], retries=20)[0]
        except TransportError:
            out[s.name] = "no answer"
            continue
        out[s.name] = al_state_name(got.data[0]) if got.wkc == 1 else "no answer"
    return out


def _report(
    eni: Eni,
    options: SimulateOptions,
    master: Master,
    app: _Application,
    states: dict[str, str],
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
    rt_mean = rt.mean if rt is not None else None
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
        "max_rate_hz": round(1e9 / rt_mean) if rt_mean else None,
        "max_rate_with_software_hz": round(1e9 / (rt_mean + software_ns))
        if rt_mean and sections
        else None,
        "realtime_factor": round(simulated_s / wall_s, 3) if wall_s > 0 else None,
        "simulated_s": simulated_s,
        "wall_s": round(wall_s, 3),
        "refusals": [r.to_dict() for r in master.refusals],
        "states": states,
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
