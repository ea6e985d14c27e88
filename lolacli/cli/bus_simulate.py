"""`lolacli bus simulate`: the ENI-driven master against the emulated chain, virtual time."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from lolacli.cli.bus import app
from lolacli.cli.common import FormatOption, OutputFormat, default_eni, emit_json
from lolacli.cli.options import (
    CanBitrateOption,
    DriftOption,
    DropOption,
    EniOption,
    FtsRateOption,
    ImuRateOption,
    JointModelFlag,
    JointsOption,
    KeOption,
    MaxLostOption,
    MaxWkcOption,
    SeedOption,
    SetValueOption,
    StuckSafeopOption,
)

Rate = Annotated[float, typer.Option("--rate", help="Cycle rate in Hz.")]
Duration = Annotated[
    str | None, typer.Option("--duration", help="Simulated time: 10s, 500ms, … (default 10s).")
]
Cycles = Annotated[
    int | None,
    typer.Option(
        "--cycles",
        min=0,
        help="Number of cycles (instead of --duration): slots of the schedule; one a "
        "late cycle ran past is skipped, not made up for.",
    ),
]
Pcap = Annotated[
    Path | None, typer.Option("--pcap", help="Write every frame, both directions, as pcapng.")
]
Mcap = Annotated[
    Path | None,
    typer.Option("--mcap", help="Write MCAP: every frame, per-cycle timing, joints, DC "
                 "error (JSON; the channels of capture export --mcap)."),
]
LinkDown = Annotated[
    str | None,
    typer.Option(
        "--link-down",
        metavar="K[@T]",
        help="Cut the cable after slave K (0: at the master), from the start or T "
        "into the cyclic run (seconds, or 500ms).",
    ),
]
BadLink = Annotated[
    str | None,
    typer.Option(
        "--bad-link",
        metavar="K[:P]",
        help="A bad cable into slave K damages a frame with probability P (default "
        "0.01): the master loses it, RX error counters rise from slave K on.",
    ),
]
Shm = Annotated[
    str | None,
    typer.Option(
        "--shm",
        metavar="NAME",
        help="Publish inputs and take outputs through shared memory NAME "
        "(lolacli.master.shm.ShmClient).",
    ),
]
Pace = Annotated[bool, typer.Option("--pace", help="Run no faster than real time (with --shm).")]
Watch = Annotated[
    list[str] | None,
    typer.Option("--watch", metavar="VARIABLE", help="Report this variable's last value."),
]
SetValue = SetValueOption
NoMiddleware = Annotated[
    bool,
    typer.Option(
        "--no-middleware", help="Only the frames: no Bus Variables, drives stay disabled."
    ),
]
Iface = Annotated[
    str | None,
    typer.Option(
        "--iface",
        "-i",
        help="Run in real time on this interface (a live bus: `bus emulate` or hardware) "
        "instead of the emulated chain in virtual time.",
    ),
]
BusyWait = Annotated[
    float | None,
    typer.Option(
        "--busy-wait-us",
        help="With --iface: busy-wait this last part of every cycle (default 200 µs, at most "
        "40% of a cycle).",
    ),
]
RealtimePriority = Annotated[
    int,
    typer.Option(
        "--realtime-priority",
        min=0,
        max=99,
        help="With --iface: ask for SCHED_FIFO at this priority (0: do not ask); the "
        "report says what the OS granted.",
    ),
]
MaxOverruns = Annotated[
    int,
    typer.Option(
        "--max-overruns",
        min=0,
        help="Cycles not kept (slots skipped, or sent over half a cycle late) allowed "
        "before exit 1.",
    ),
]
HostLatencyUs = Annotated[
    str | None,
    typer.Option(
        "--host-latency-us",
        metavar="MEAN[:STD]",
        help="The master host's send+receive latency in µs, drawn every frame (log-normal "
        "of this mean and std, seeded by --seed; default none: the round trip is the bus "
        "alone). The LOLA seed's figures: 31.2:10.2.",
    ),
]
Forwarding = Annotated[
    str,
    typer.Option(
        "--forwarding",
        metavar="model|physics",
        help="Per-slave delay: model (1000 ns each, the timing model's assumption) or "
        "physics (from each slave's ENI <Physics>: 100BASE-TX 1000 ns, E-bus 300 ns).",
    ),
]
CableM = Annotated[
    list[str] | None,
    typer.Option(
        "--cable-m",
        metavar="M|K=M",
        help="Cable length in metres of every segment (M) or of segment K (K=M; 1: master "
        "to slave 1), 0-100 m at 5 ns/m; default 1 m; repeatable.",
    ),
]
Move = Annotated[
    list[str] | None,
    typer.Option(
        "--move",
        metavar="JOINT:DISTANCE[:V:A:J]",
        help="Move a drive by DISTANCE from where it starts on a jerk-limited S-curve "
        "streamed in CSP, one set-point a cycle; JOINT a slave name (Joint04 L Knee, L "
        "Knee, Joint04), its position (4), or all. Units: the drive's increments, V/A/J in "
        "increments/s, /s², /s³ (default 100000:1e6:2e7). Repeatable; replaces the "
        "back-and-forth (drives without a move hold still). The JSON's moves give each "
        "joint's following error.",
    ),
]
Trajectory = Annotated[
    Path | None,
    typer.Option(
        "--trajectory",
        metavar="FILE",
        help="Goals to stream like --move, at their times: CSV with the header "
        "time_s,joint,distance[,v,a,j] (a goal interrupts the joint's running move), or "
        "JSON, a list of objects with those keys.",
    ),
]
Quiet = Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar.")]


@app.command("simulate")
def simulate_cmd(
    eni: EniOption = None,
    rate: Rate = 2000.0,
    duration: Duration = None,
    cycles: Cycles = None,
    pcap: Pcap = None,
    mcap: Mcap = None,
    drop_p: DropOption = 0.0,
    stuck_safeop: StuckSafeopOption = None,
    link_down: LinkDown = None,
    bad_link: BadLink = None,
    drift_ppb: DriftOption = 0,
    seed: SeedOption = 0,
    shm: Shm = None,
    pace: Pace = False,
    watch: Watch = None,
    set_value: SetValue = None,
    no_middleware: NoMiddleware = False,
    iface: Iface = None,
    busy_wait_us: BusyWait = None,
    realtime_priority: RealtimePriority = 80,
    max_lost: MaxLostOption = 0,
    max_wkc: MaxWkcOption = 0,
    max_overruns: MaxOverruns = 0,
    host_latency_us: HostLatencyUs = None,
    forwarding: Forwarding = "model",
    cable_m: CableM = None,
    move: Move = None,
    trajectory: Trajectory = None,
    imu_rate: ImuRateOption = 200.0,
    fts_rate: FtsRateOption = 1000.0,
    can_bitrate: CanBitrateOption = 1_000_000,
    joints: JointModelFlag = False,
    joints_file: JointsOption = None,
    ke: KeOption = None,
    quiet: Quiet = False,
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Bring the ENI's chain (default: LOLA) to OP with our master in virtual time, move
    every joint (or --move/--trajectory S-curves) and report round trip, WKC, lost frames,
    DC error, CAN sensor ages and the software sections with a verdict (lolacli.simulate/1).
    --iface: the same in real time on a live bus. Exit 1 when the verdict fails, 2 bad
    options, 3 a bad ENI, 4 no slave answers, 130/143 stopped."""
    from lolacli.simulate import options_from_cli

    _check_recordings(pcap, mcap, [("--eni", eni), ("--trajectory", trajectory),
                                   ("--joints", joints_file)])
    options = options_from_cli(
        rate_hz=rate, duration=duration, cycles=cycles, link_down=link_down, bad_link=bad_link,
        set_values=set_value or (), stuck_safeop=stuck_safeop or (), watch=watch or (),
        pcap=pcap, mcap=mcap, drop_probability=drop_p, drift_ppb=drift_ppb, seed=seed,
        middleware=not no_middleware, shm=shm, pace=pace, iface=iface,
        busy_wait_us=busy_wait_us, realtime_priority=realtime_priority, max_lost=max_lost,
        max_wkc_mismatches=max_wkc, max_overruns=max_overruns,
        host_latency_us=host_latency_us, forwarding=forwarding, cable_m=cable_m or (),
        moves=move or (), trajectory=trajectory, imu_rate_hz=imu_rate, fts_rate_hz=fts_rate,
        can_bitrate=can_bitrate, joints=joints, joints_file=joints_file,
        k_e=ke)  # fmt: skip
    _run(eni, options, quiet or iface is not None, fmt)


def _check_recordings(pcap: Path | None, mcap: Path | None,
                      inputs: list[tuple[str, Path | None]]) -> None:
    """UsageError (exit 2) when a recording would be written over an input or the other
    recording, or is no regular file (lolacli.files.check_output_file)."""
    from lolacli.files import check_output_file

    if pcap is not None:
        check_output_file(pcap, "--pcap", inputs)
    if mcap is not None:
        check_output_file(mcap, "--mcap", [*inputs, ("--pcap", pcap)])


def _run(eni: Path | None, options: Any, quiet: bool, fmt: OutputFormat) -> None:
    """The simulation with a progress bar (none when ``quiet`` or stderr is no terminal),
    its report and exit code."""
    from lolacli.files import load_eni
    from lolacli.interrupt import stop_signals
    from lolacli.simulate import simulate

    with stop_signals() as stop:
        with _progress(quiet or not sys.stderr.isatty()) as progress:
            result = simulate(load_eni(eni or default_eni()), options, progress=progress, stop=stop)
    _finish(result, fmt, stop.exit_code)


def _finish(result: Any, fmt: OutputFormat, stop_code: int) -> None:
    """The report on stdout, then the exit code: the stop's, 1 for a failed verdict."""
    if fmt is OutputFormat.json:
        emit_json(result.doc)
    else:
        _render(result.doc)
    if result.interrupted:
        sys.stderr.write("lolacli: stopped; the report covers the cycles run, recordings "
                         "are kept up to the last cycle\n")
        raise typer.Exit(stop_code)
    if result.failed:
        raise typer.Exit(1)


class _progress:
    """A rich progress bar on stderr (nothing when ``off``; a live run has none: its
    refresh thread would take the GIL mid-cycle)."""

    def __init__(self, off: bool) -> None:
        self.off = off
        self._bar: Any = None
        self._task: Any = None

    def __enter__(self) -> Any:
        if self.off:
            return None
        from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

        from lolacli.cli.common import stderr_console

        self._bar = Progress(
            TextColumn("simulating"),
            BarColumn(),
            TextColumn("{task.completed}/{task.total} cycles"),
            TimeRemainingColumn(),
            console=stderr_console(),
            transient=True,
        )
        self._bar.__enter__()
        self._task = self._bar.add_task("cycles", total=None)

        def update(done: int, total: int) -> None:
            self._bar.update(self._task, completed=done, total=total)

        return update

    def __exit__(self, *exc: object) -> None:
        if self._bar is not None:
            self._bar.__exit__(*exc)


def _us(stats: dict[str, Any] | None, *keys: str) -> str:
    if not stats:
        return "none measured"
    return ", ".join(f"{k} {stats[k]:,.3g} µs" if abs(stats[k]) < 1000 else
                     f"{k} {stats[k]:,.0f} µs" for k in keys)


def _rows(doc: dict[str, Any]) -> list[tuple[str, str]]:
    software = doc["software_us_per_cycle"]
    rates = f"{doc['max_rate_hz'] or 0:,} Hz round trip only"
    if doc["max_rate_with_software_hz"]:
        rates += f", {doc['max_rate_with_software_hz']:,} Hz with the software"
    dc = doc["dc_max_error_ns"]
    rows = [
        ("cycles", f"{doc['cycles']:,} at {doc['rate_hz']:,g} Hz "
                   f"(+{doc['startup_cycles']:,} start-up)"),
        ("slaves", str(doc["slaves"])),
        ("frame", f"{doc['frame_bytes']:,} B, {doc['wire_time_us']:g} µs on the wire"),
        ("round trip", _us(doc["round_trip_us"], "mean", "std", "p99", "max")),
        ("cycle period", _us(doc["cycle_period_us"], "mean", "std", "max")),
        ("WKC mismatches", f"{doc['wkc_mismatches']:,} of {doc['wkc_checked']:,} checked"),
        ("frames", f"{doc['lost_frames']:,} lost, {doc['late_frames'] or 0:,} late"),
        ("cycles not kept", f"{doc['skipped_cycles'] or 0:,} slots skipped, "
                            f"{doc['overruns'] or 0:,} sent over half a cycle late"),
        ("DC max error", f"{dc:,} ns" if dc is not None else
         ("not measured" if doc["dc_slaves"] else "no DC slaves")),
        ("drives enabled", f"{doc['drives_enabled']} of {doc['drives']}"),
        ("drive loads", _loads(doc)),
        ("software per cycle", f"{software:g} µs" if software is not None else "not timed"),
        ("max rate", rates),
    ]
    if doc.get("can_gateway"):
        rows += _sensor_rows(doc["can_gateway"])
    if doc.get("timing_sources"):
        rows += _source_rows(doc["timing_sources"])
    if doc.get("mode") == "realtime":
        rows += _live_rows(doc)
    else:
        rows.append(("virtual / wall time", f"{doc['realtime_factor']:g}× real time"))
    return rows


def _loads(doc: dict[str, Any]) -> str:
    """What the drives move: kinematic followers, or --joint-model's joints behind some."""
    from lolacli.text import plural

    joints = doc.get("joints")
    if not joints:
        return "kinematic (a follower of the demand)"
    k_e = joints.get("k_e") or 0.0
    return (f"a joint (motor, gear, link, cascade) behind {plural(len(joints['drives']), 'drive')}"
            f", from {joints['file']}" + (f", k_e {k_e:g}" if k_e else ""))


def _sensor_rows(gateway: dict[str, Any]) -> list[tuple[str, str]]:
    """Each CAN sensor's age at the master (seed 000 §III)."""
    from lolacli.text import number

    rows = []
    for s in gateway["sensors"]:
        age = s["age_us"]
        text = (
            f"{number(age['mean'], 'µs', 1)} mean, {number(age['max'], 'µs', 1)} max "
            f"at {number(s['rate_hz'], 'Hz')}" if age is not None else "no sample read"
        )
        rows.append((f"{s['name']} age", text))
    return rows


def _source_rows(src: dict[str, Any]) -> list[tuple[str, str]]:
    """Which inputs made the round trip (lolacli.simulate.variation)."""
    from lolacli.text import number

    fwd, cable, host = src["forwarding"], src["cable"], src["host_latency"]
    by_delay = ", ".join(
        f"{n} × {number(int(d), 'ns')}" for d, n in reversed(fwd["slaves_by_delay_ns"].items())
    )
    how = "by port physics (ENI)" if fwd["mode"] == "physics" else "assumed (timing model)"
    lengths = cable["m_per_segment"]
    metres = (
        f"{number(lengths, 'm')} a segment" if not isinstance(lengths, list)
        else f"{number(min(lengths), 'm')} to {number(max(lengths), 'm')} a segment"
    )
    host_text = (
        "none (the round trip is the bus alone)" if host is None
        else f"{host['distribution']}, mean {number(host['mean'], 'µs')}, std "
        f"{number(host['std'], 'µs')}, --seed {src['seed']}"
    )
    formula = f"{number(src['formula_bus_round_trip_us'], 'µs')} bus"
    if host is not None:
        formula += f", {number(src['formula_round_trip_us'], 'µs')} with the host's mean"
    return [
        ("slave delays", f"{by_delay}, {how}"),
        ("cable", f"{metres}, {number(cable['ns_per_m'], 'ns/m')}"),
        ("host latency", host_text),
        ("formula", formula),
    ]


def _live_rows(doc: dict[str, Any]) -> list[tuple[str, str]]:
    late = doc["wakeup_lateness_us"]
    sched = doc["scheduling"]
    granted = sched["policy"] + (f" {sched['priority']}" if sched["priority"] else "")
    if sched["error"]:
        granted += f" ({sched['error']})"
    load = doc["load"]
    return [
        ("interface", str(doc["iface"])),
        ("wake-up lateness", _us(late, "p99", "max")),
        ("scheduling", f"{granted}, busy-wait {sched['busy_wait_us']:g} µs"),
        ("host load (1 min)", f"{load['before']['loadavg_1min']} before, "
                              f"{load['after']['loadavg_1min']} after, "
                              f"{load['before']['cpus']} CPUs"),
        ("master CPU", f"{doc['master_cpu_percent']} % of one core"),
    ]


def _render_moves(console: Any, moves: list[dict[str, Any]]) -> None:
    """The moves' table: each joint's distance, profile time and following error (the
    set-point sent against the actual position received in the same cycle)."""
    from lolacli.cli.common import data_table, fit_table
    from lolacli.text import number

    unit = moves[0]["unit"]
    table = data_table(f"Moves (inc: {unit}; error: set-point sent - actual received)")
    for column in ("slave", "joint", "distance", "duration", "error RMS", "error max"):
        table.add_column(column, justify="left" if column == "joint" else "right")
    for m in moves:
        if m["duration_s"] is None:
            cells = ["never started"] * 4
        else:
            cells = [
                number(m["distance"], "inc"),
                number(m["duration_s"], "s") + ("" if m["complete"] else " (cut)"),
                number(m["following_error_rms"], "inc", 1),
                number(m["following_error_max"], "inc", 0),
            ]
        table.add_row(str(m["slave"]), m["joint"], *cells)
    fit_table(table, console, min(console.width, 80))
    console.print(table)


def _render(doc: dict[str, Any]) -> None:
    from rich.table import Table

    from lolacli.cli.common import data_table, stdout_console
    from lolacli.cli.verdict import render_verdict

    console = stdout_console()
    console.print(f"Simulation of {doc['eni']}")
    table = Table.grid(padding=(0, 2))
    table.add_column(no_wrap=True)
    table.add_column(overflow="fold")
    for name, value in _rows(doc):
        table.add_row(name, value)
    console.print(table, width=min(console.width, 80))
    if doc["sections_us"]:
        console.print("Per-cycle sections (seed Tables I/II, Fig. 7)")
        sections = data_table()
        for column in ("section", "thread", "mean µs", "p99 µs", "max µs"):
            sections.add_column(
                column, justify="left" if column in ("section", "thread") else "right"
            )
        for name, s in doc["sections_us"].items():
            sections.add_row(name, s["thread"], f"{s['mean']:g}", f"{s['p99']:g}", f"{s['max']:g}")
        console.print(sections)
    if doc.get("moves"):
        _render_moves(console, doc["moves"])
    render_verdict(console, doc["verdict"], doc["findings"])
