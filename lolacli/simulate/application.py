"""What runs on top of the middleware in a simulation: drives enabled, joints moving on a
minimum-jerk back-and-forth (:mod:`lolacli.motion`), sensors read, ``--set`` and
``--watch`` variables, shared memory and the MCAP recording."""

from __future__ import annotations

from typing import Any

from lolacli.errors import LinkError
from lolacli.master.core import Master
from lolacli.master.slaves import Cia402Drive, ForceTorqueSensor, Imu, has_field
from lolacli.master.variables import BusVariable, variable_for
from lolacli.motion.profile import back_and_forth
from lolacli.simulate.options import SimulateOptions


class Application:
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
            self.fixed.append((variable, parse_value(variable, text)))
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


def parse_value(variable: BusVariable, text: str) -> Any:
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
