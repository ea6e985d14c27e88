"""What runs on top of the middleware in a simulation: drives enabled, joints moving on a
minimum-jerk back-and-forth (:mod:`lolacli.motion`), sensors read, ``--set`` and
``--watch`` variables, shared memory and the MCAP recording."""

from __future__ import annotations

import struct
import time
from operator import itemgetter
from typing import Any

from lolacli.devices.cia402 import ERROR_CODE, Cia402State
from lolacli.errors import LinkError, LolaError, UsageError
from lolacli.master.core import Master
from lolacli.master.slaves import BusSlave, Cia402Drive, ForceTorqueSensor, Imu, has_field
from lolacli.master.variables import BusVariable, ProcessImage, variable_for
from lolacli.motion.profile import back_and_forth
from lolacli.simulate.moves import Moves, resolve
from lolacli.simulate.options import SimulateOptions
from lolacli.simulate.sensors import SensorAges

_ENABLED = Cia402State.OPERATION_ENABLED


class Drives(BusSlave):
    """The application's CiA 402 drives as one device of the master (its procData).

    Each drive's state machine (:meth:`Cia402Drive.process`) runs only in a cycle whose
    statuswords differ from the last cycle's (or, while a drive is not yet enabled or not
    asked to be, whose statuswords or actual positions do): with the same inputs its
    process changes nothing (the same state, controlword and, while not enabled, target).
    So that this holds, the drives are enabled and disabled through :meth:`enable`.
    :meth:`move` sends every enabled drive its set-point with one pack each."""

    def __init__(self, image: ProcessImage, drives: list[Cia402Drive]) -> None:
        self.slave = "drives"
        self.image = image
        self.drives = drives
        self.steady = False  # every drive enabled and asked to be, as of the last process
        self._last: tuple[int, ...] | None = None
        self._words = _byte_getter([d.statusword for d in drives])
        # ... and while not steady the positions the targets follow
        self._inputs = _byte_getter([v for d in drives for v in (d.statusword, d.position_actual)])
        self._last_inputs: tuple[int, ...] | None = None
        self._offset: int | None = None  # the offset move sent last with the rows
        self._rows: list[tuple[Any, int, int, int]] | None = None  # pack, at, home, sign
        self._packs: list[tuple[Any, int, int]] = []  # (pack_into, offset, sign) per drive
        packs: dict[str, Any] = {}  # one pack_into per format
        for i, drive in enumerate(drives):
            target = drive.target
            at = target.byte_offset if target is not None else None
            if at is None or target is None:
                self._packs = []
                break
            pack = packs.setdefault(target.fmt, struct.Struct("<" + target.fmt).pack_into)
            self._packs.append((pack, at, -1 if i % 2 else 1))

    def enable(self, on: bool = True) -> None:
        for drive in self.drives:
            if on:
                drive.enable()
            else:
                drive.disable()
        self._last = None

    def process(self) -> None:
        data = self.image.snapshot.data
        words = self._words(data) if self._words is not None else None
        if words is not None and words == self._last:
            if self.steady:
                return
            inputs = self._inputs(data) if self._inputs is not None else None
            if inputs is not None and inputs == self._last_inputs:
                return  # the same statuswords and positions: the same state, cw, target
        for drive in self.drives:
            drive.process()
        self._last = words
        self._last_inputs = self._inputs(data) if self._inputs is not None else None
        self.steady = all(d.want_enabled and d.state is _ENABLED for d in self.drives)

    def move(self, offset: int, homes: dict[int, int]) -> None:
        """Every enabled drive to its home plus ``offset`` (even positions) or minus it
        (odd positions); a drive's home is its position when it is first moved."""
        rows = self._rows
        if rows is None and self.steady and self._packs and len(homes) == len(self.drives):
            rows = self._rows = [
                (pack, at, homes[i], sign) for i, (pack, at, sign) in enumerate(self._packs)
            ]
        if rows is not None and self.steady:
            outputs = self.image.outputs
            try:
                for pack, at, home, sign in rows:
                    pack(outputs, at, home + sign * offset)
            except struct.error:
                pass  # out of range: the drive's own setter says so
            else:
                self._offset = offset
                return
        self._offset = None
        for i, drive in enumerate(self.drives):
            if not drive.enabled:
                continue
            if i not in homes:
                homes[i] = drive.actual_position
            drive.target_position = homes[i] + (offset if i % 2 == 0 else -offset)

    def target_positions(self) -> list[int]:
        """The set-points the drives were sent last."""
        if self._offset is None or self._rows is None or not self.steady:
            return [d.target_position for d in self.drives]
        return [home + sign * self._offset for _, _, home, sign in self._rows]


def _byte_getter(variables: list[Any]) -> Any:
    """One call that takes the bytes of ``variables`` from an image (``None`` when one is
    bit-packed)."""
    places: list[int] = []
    for v in variables:
        at = v.byte_offset
        if at is None:
            return None
        places += range(at, at + v.bit_size // 8)
    return itemgetter(*places) if len(places) > 1 else None


class Application:
    """What runs on top of the middleware: drives enabled, joints moving, sensors read,
    --set/--watch variables, shared memory, MCAP."""

    def __init__(self, master: Master, options: SimulateOptions) -> None:
        self.master = master
        self.options = options
        self.drives: list[Cia402Drive] = []
        self.group: Drives | None = None
        self._period_ns = round(options.period_s * 1e9)
        self.sensors: list[Any] = []
        self.watch: dict[str, BusVariable] = {}
        self.fixed: list[tuple[BusVariable, Any]] = []
        self.shm: Any = None
        self.mcap: Any = None
        self._last_record_ns: int | None = None  # the /cycle message's time, last cycle
        self.homes: dict[int, int] = {}
        self.final_states: dict[int, str] = {}  # position -> AL state at the end
        self.drive_faults: list[dict[str, Any]] = []  # read_drive_faults
        self.t_enable_ns = 0
        self.first_cycle = 0
        # the cycle count when the run's own cycles ended (a live run's closing reads of
        # the AL states go on cycling, and those cycles are not the run's)
        self.last_cycle: int | None = None
        self.last_skipped = 0
        self.moves: Moves | None = None  # --move / --trajectory
        self.planner_ns: list[int] = []  # the planner's time each cycle (section "planner")
        self.sensor_ages: SensorAges | None = None  # the CAN gateway's sensors (virtual)
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
                drive = Cia402Drive(master.image, slave.name)
                drive.reset_faults = False  # a fault stands: a finding, with its 0x603F
                self.drives.append(drive)
            elif has_field(master.image, slave.name, Imu.rate_x):
                # on the image, not the master: they have no procData to run each cycle
                self.sensors.append(Imu(master.image, slave.name))
                if self.options.iface is None and self.sensor_ages is None:
                    ages = SensorAges(master.image, slave.name, self.options.can_config())
                    self.sensor_ages = ages if ages.sensors else None
                for side in ("left", "right"):
                    try:
                        self.sensors.append(ForceTorqueSensor(master.image, slave.name, side))
                    except LinkError:
                        pass
        if self.options.moves:
            slaves = [(s.position, s.name) for s in master.eni.slaves]
            names = [d.slave for d in self.drives]
            goals = resolve(self.options.moves, slaves, names)
            for drive in self.drives:
                if drive.target is None or drive.target.byte_offset is None or (
                        drive.position_actual.byte_offset is None):
                    raise UsageError(f"--move: drive {drive.slave}'s target or actual position "
                                     "is not byte-aligned in the process image")
            self.moves = Moves(goals, len(self.drives), self.options.cycles,
                               1.0 / self.options.rate_hz)

    def install(self, mcap: Any) -> None:
        self.mcap = mcap
        master = self.master
        if self.drives:
            self.group = Drives(master.image, self.drives)
            master.devices.append(self.group)
        if self.shm is not None:
            master.control.append(self._publish)
        if self.moves is not None:
            master.control.append(self._planner)
        elif self.drives:
            master.control.append(self._move)
        if self.fixed:
            master.control.append(self._set_fixed)
        if self.shm is not None:
            master.control.append(self._apply_shm)
        if mcap is not None:
            master.admin.append(self._record)
        if self.sensor_ages is not None:
            master.control.append(self.sensor_ages.hook)

    def start_run(self, *, sensor_ages: bool = False) -> None:
        """The cyclic run starts: findings name its cycles from 0 on (those of the
        bring-up before it are forgotten); with ``sensor_ages`` the gateway's sensors'
        ages are recorded until :meth:`end_run`."""
        stats = self.master.stats
        self.first_cycle = stats.cycles
        for at in (stats.lost_at, stats.late_at, stats.mismatch_at, stats.skipped_at):
            at.clear()
        if self.sensor_ages is not None:
            self.sensor_ages.active = sensor_ages

    def end_run(self) -> None:
        if self.sensor_ages is not None:
            self.sensor_ages.active = False

    def skipped_in_run(self, skipped0: int, slots: int) -> int:
        """The slots of the run skipped (a stall in its last cycle skips past its end:
        those are not the run's)."""
        ran = (self.last_cycle or 0) - self.first_cycle
        return max(0, min(self.last_skipped - skipped0, slots - ran))

    def run_cycles(self, cycles: list[int]) -> list[int]:
        """``cycles`` (the master's count) as cycles of the run, 0 its first."""
        return [c - self.first_cycle for c in cycles if c >= self.first_cycle]

    def enable(self) -> None:
        if self.group is not None:
            self.group.enable()
        self.t_enable_ns = self.master.transport.now_ns()

    def read_drive_faults(self, states: dict[int, str]) -> list[dict[str, Any]]:
        """The drives that went to fault in the run (:attr:`drive_faults`): slave position
        and name, how often, and the error code the drive holds in 0x603F (read by SDO
        after the run; None where it cannot be). Only drives still in OP count: the
        statusword of a slave the frames no longer reach is no statusword."""
        master = self.master
        positions = {s.name: s.position for s in master.eni.slaves}
        out: list[dict[str, Any]] = []
        for drive in self.drives:
            position = positions[drive.slave]
            if not drive.faults or states.get(position) != "OP":
                continue
            code: int | None
            try:
                code = int.from_bytes(master.sdo(position).upload(ERROR_CODE, 0)[:2], "little")
            except LolaError:
                code = None
            out.append(
                {"slave": position, "name": drive.slave, "faults": drive.faults, "error_code": code}
            )
        self.drive_faults = out
        return out

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
        offset = round(back_and_forth(t, self._period_ns, self.options.amplitude_counts))
        self.group.move(offset, self.homes)  # type: ignore[union-attr]

    def _planner(self, master: Master) -> None:
        """--move/--trajectory: the S-curves' set-points of this cycle (once every drive
        is enabled; their positions then are where the moves start)."""
        timed = master.options.time_sections
        t0 = time.perf_counter_ns() if timed else 0
        moves = self.moves
        assert moves is not None and self.group is not None
        if not moves.started and self.group.steady:
            drives = self.drives
            moves.begin(
                [d.actual_position for d in drives], master.image.inputs,
                master.image.outputs,
                [d.position_actual.byte_offset for d in drives],
                [d.target.byte_offset for d in drives],
            )
        if moves.started:
            moves.cycle()
        if timed:
            self.planner_ns.append(time.perf_counter_ns() - t0)

    def _record(self, master: Master) -> None:
        stats = master.stats
        t = master.transport.now_ns()
        rt = stats.round_trip_ns[-1] if stats.round_trip_ns else None
        sections = {name: values[-1] for name, values in master.sections_ns.items() if values}
        self._last_record_ns, last = t, self._last_record_ns
        self.mcap.write(
            "/cycle",
            t,
            {
                "cycle": stats.cycles,
                "t_ns": t,
                "round_trip_ns": rt,
                "period_ns": None if last is None else t - last,
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
                    "target": self.moves.last_targets()
                    if self.moves is not None and self.moves.started
                    else self.group.target_positions() if self.group else [],
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
