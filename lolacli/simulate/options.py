"""What a simulation runs: :class:`SimulateOptions` (the ``bus simulate`` options) checked
against the ENI (:func:`check`), and what it gives back (:class:`SimulationResult`)."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from lolacli.eni.model import Eni
from lolacli.errors import EniError, UsageError
from lolacli.simulate.moves import Goal
from lolacli.timing.model import HostLatency

if TYPE_CHECKING:
    from lolacli.motion.joint import JointParams


@dataclass(frozen=True, slots=True)
class SimulateOptions:
    rate_hz: float = 2000.0
    cycles: int = 20_000
    pcap: Path | None = None
    mcap: Path | None = None
    drop_probability: float = 0.0
    stuck_safeop: tuple[int, ...] = ()
    link_down: tuple[int, float] | None = None  # (after slave K, seconds into the run; 0: start)
    bad_link: tuple[int, float] | None = None  # (K, P): the cable into slave K damages frames
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
    # the line and the host (lolacli.simulate.variation): None / "model" / () is the
    # timing model's formula, every cycle the same round trip
    host_latency: HostLatency | None = None  # drawn a frame, seeded with ``seed``
    forwarding: str = "model"  # "physics": each slave's delay from its ports' physics
    cable_m: tuple[str, ...] = ()  # "M" (every segment) and "K=M" (segment K) items
    # --move / --trajectory (lolacli.simulate.moves): S-curves streamed in CSP instead of
    # the back-and-forth; drives without a goal hold their position
    moves: tuple[Goal, ...] = ()
    # the emulated CAN gateway's sensors (lolacli.devices.can; seed 000 §III)
    imu_rate_hz: float = 200.0
    fts_rate_hz: float = 1000.0
    can_bitrate: int = 1_000_000
    # --joint-model: a joint behind each drive these parameters name (lolacli.devices.joint_load;
    # matched by slave name, lolacli.motion.joint.find_joint); empty: kinematic drives
    joints: tuple[JointParams, ...] = ()
    joints_source: str | None = None  # the file they came from (for messages)
    k_e: float = 0.0  # --ke: every joint's velocity feed-forward k_vel,ff = 1 + k_e

    def joint(self, slave: str) -> JointParams | None:
        """The joint behind the drive ``slave`` (its ENI name) with --joints, else None."""
        if not self.joints:
            return None
        from lolacli.motion.joint import find_joint

        return find_joint({p.name: p for p in self.joints}, slave)

    def can_config(self) -> Any:
        """The emulated gateway's :class:`~lolacli.devices.can.CanConfig`."""
        from lolacli.devices.can import CanConfig, lola_sensors

        return CanConfig(self.can_bitrate, lola_sensors(self.imu_rate_hz, self.fts_rate_hz))


@dataclass(frozen=True, slots=True)
class SimulationSeries:
    """The per-cycle figures behind the report's statistics, as measured (for plots:
    ``lolacli report``). Times in ns of the simulation's clock."""

    round_trip_ns: Sequence[int]  # every cyclic frame's, start-up included, in order
    sent_ns: Sequence[int]  # when each cyclic frame of the run left (periods: differences)
    dc_error_ns: Sequence[tuple[int, int]]  # (when, largest |system time difference|)
    start_ns: int  # when the cyclic run started (DC errors before it: start-up)
    #: --move/--trajectory: each moved drive's (s since the moves began, following error in
    #: increments) per cycle of its motion (:meth:`lolacli.simulate.moves.Moves.errors`)
    following_error: Mapping[str, tuple[Any, Any]] = field(default_factory=dict)


@dataclass(slots=True)
class SimulationResult:
    doc: dict[str, Any]
    failed: bool
    interrupted: bool = False
    notes: list[str] = field(default_factory=list)
    series: SimulationSeries | None = None


#: progress(cycle slots done, of)
Progress = Callable[[int, int], None]


#: --ke: the k_e a joint's velocity feed-forward may have (k_vel,ff = 1 + k_e from 0, none,
#: to 6; seed 000's learning ends well inside, at 0.5 to 1)
K_E_RANGE = (-1.0, 5.0)

#: the most cycle slots one run takes: the per-cycle figures are kept for the statistics
#: (about 100 B a cycle), so a longer run would outgrow the memory of a small host
MAX_CYCLES = 20_000_000
MAX_RATE_HZ = 100_000.0


def check(eni: Eni, options: SimulateOptions) -> None:
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
    if not K_E_RANGE[0] <= options.k_e <= K_E_RANGE[1]:
        raise UsageError(f"--ke {options.k_e:g}: expected {K_E_RANGE[0]:g} to {K_E_RANGE[1]:g} "
                         "(the joints' velocity feed-forward is 1 + k_e)")
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
    if options.bad_link is not None and not 1 <= options.bad_link[0] <= n:
        raise UsageError(f"--bad-link {options.bad_link[0]}: expected a slave position 1 to {n}")
    if options.link_down is not None:
        after, at_s = options.link_down
        if not 0 <= after <= n:
            raise UsageError(f"--link-down {after}: expected 0 (at the master) to {n}")
        run_s = options.cycles / options.rate_hz
        if at_s >= run_s:
            raise UsageError(
                f"--link-down {after}@{at_s:g}s: after the run ends ({run_s:g} s of cycles)"
            )
    from lolacli.devices.can import MAX_RATE_HZ as MAX_SENSOR_HZ

    for flag, hz in (("--imu-rate", options.imu_rate_hz), ("--fts-rate", options.fts_rate_hz)):
        if not (math.isfinite(hz) and 0 < hz <= MAX_SENSOR_HZ):
            raise UsageError(f"{flag} {hz:g}: expected above 0 to {MAX_SENSOR_HZ:g} Hz")
    options.can_config().check()  # the bitrate, and a bus the sensors do not saturate
    from lolacli.simulate.variation import check_forwarding
    from lolacli.timing.model import parse_cable_m

    check_forwarding(options.forwarding)
    parse_cable_m(options.cable_m, n)
    if options.iface is not None:
        _check_live(options)


def _check_live(options: SimulateOptions) -> None:
    faults = [
        name
        for name, given in (
            ("--drop-p", options.drop_probability > 0),
            ("--stuck-safeop", bool(options.stuck_safeop)),
            ("--link-down", options.link_down is not None),
            ("--bad-link", options.bad_link is not None),
            ("--drift-ppb", options.drift_ppb != 0),
        )
        if given
    ]
    if faults:
        raise UsageError(
            f"{', '.join(faults)}: faults of the emulated chain; on a live bus give them "
            "to the `bus emulate` serving it"
        )
    modelled = [
        name
        for name, given in (
            ("--host-latency-us", options.host_latency is not None),
            ("--forwarding", options.forwarding != "model"),
            ("--cable-m", bool(options.cable_m)),
        )
        if given
    ]
    if modelled:
        raise UsageError(
            f"{', '.join(modelled)}: inputs of the simulated line; a live bus has its own "
            "delays and measures them"
        )
    if options.joints:
        raise UsageError("--joint-model (--joints, --ke): joints behind the emulated drives; "
                         "a live bus's drives move what they move")
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


DEFAULT_DURATION_NS = 10_000_000_000


def options_from_cli(
    *,
    rate_hz: float = 2000.0,
    duration: str | None = None,
    cycles: int | None = None,
    link_down: str | None = None,
    bad_link: str | None = None,
    set_values: Sequence[str] = (),
    stuck_safeop: Sequence[int] = (),
    watch: Sequence[str] = (),
    host_latency_us: str | None = None,
    cable_m: Sequence[str] = (),
    moves: Sequence[str] = (),
    trajectory: Path | None = None,
    joints: bool = False,
    joints_file: Path | None = None,
    k_e: float | None = None,
    **fields: Any,
) -> SimulateOptions:
    """:class:`SimulateOptions` from the command line's spelling: ``duration`` (``10s``,
    ``500ms``; default 10 s) or ``cycles``, ``link_down`` as ``K[@T]``, ``set_values`` as
    ``VARIABLE=VALUE``, ``host_latency_us`` as ``MEAN[:STD]`` (µs), ``cable_m`` as ``M``
    or ``K=M`` items, ``moves`` as ``JOINT:DISTANCE[:V:A:J]`` and ``trajectory`` a goals
    file (:mod:`lolacli.simulate.moves`), ``joints`` (or a ``joints_file``, or a ``k_e``:
    each implies it) the packaged joints behind the drives (or that file's: InputError when
    it does not parse) with k_vel,ff = 1 + ``k_e`` (default 0); the
    other ``fields`` as they are. UsageError for what does not parse or contradicts
    itself."""
    from lolacli.emulator.run import parse_bad_link, parse_link_down
    from lolacli.timing.model import parse_cable_m, parse_duration_ns, parse_host_latency

    if duration is not None and cycles is not None:
        raise UsageError("--duration and --cycles contradict each other; give one")
    n_cycles = cycles
    if n_cycles is None:
        ns = (
            parse_duration_ns(duration, "s", what="--duration")
            if duration is not None
            else DEFAULT_DURATION_NS
        )
        n_cycles = round(ns * rate_hz / 1e9) if rate_hz > 0 else 0
    pairs = []
    for item in set_values:
        name, eq, value = item.rpartition("=")
        if not eq or not name:
            raise UsageError(f"--set {item!r}: expected VARIABLE=VALUE")
        pairs.append((name, value))
    return SimulateOptions(
        rate_hz=rate_hz,
        cycles=n_cycles,
        link_down=parse_link_down(link_down) if link_down is not None else None,
        bad_link=parse_bad_link(bad_link) if bad_link is not None else None,
        set_values=tuple(pairs),
        stuck_safeop=tuple(stuck_safeop),
        watch=tuple(watch),
        host_latency=parse_host_latency(host_latency_us) if host_latency_us is not None
        else None,
        cable_m=_cable_items(tuple(cable_m), parse_cable_m),
        moves=_goals(moves, trajectory, fields.get("middleware", True)),
        **_joints(joints or k_e is not None, joints_file, k_e),
        **fields,
    )


def _joints(joints: bool, path: Path | None, k_e: float | None) -> dict[str, Any]:
    """``joints``, ``joints_source`` and ``k_e`` of --joint-model/--joints/--ke (read; the
    range of k_e is :func:`check`'s)."""
    if not joints and path is None:
        return {}
    from lolacli.files import joints_path, load_joints

    table = load_joints(path)
    return {"joints": tuple(table.values()), "joints_source": str(path or joints_path()),
            "k_e": 0.0 if k_e is None else float(k_e)}


def _goals(moves: Sequence[str], trajectory: Path | None, middleware: bool) -> tuple[Goal, ...]:
    """The goals of ``--move`` items and a ``--trajectory`` file (checked; the joints wait
    for the ENI: :meth:`lolacli.simulate.application.Application`)."""
    from lolacli.simulate.moves import parse_move, parse_trajectory

    goals = [parse_move(m) for m in moves]
    if trajectory is not None:
        goals += parse_trajectory(trajectory)
    if goals and not middleware:
        raise UsageError("--move/--trajectory and --no-middleware contradict each other: the "
                         "moves go through the Bus Variables")
    return tuple(goals)


def _cable_items(items: tuple[str, ...], parse: Callable[..., Any]) -> tuple[str, ...]:
    """The ``--cable-m`` items, their spelling checked already (segment numbers wait for
    the ENI: :func:`check`)."""
    parse(tuple(i for i in items if "=" not in i), 0)
    for item in items:
        if "=" in item:
            k, _, m = item.rpartition("=")
            if not k.strip().isdigit():
                raise UsageError(f"--cable-m {item!r}: expected M or K=M (metres, segment K)")
            parse((m,), 0)
    return items
