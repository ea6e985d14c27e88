"""`lolacli bus emulate`: serve the emulated chain on a network interface
(:class:`lolacli.emulator.run.Emulation`)."""

from __future__ import annotations

from typing import Annotated, Any

import typer

from lolacli.cli.bus import app
from lolacli.cli.common import default_eni, stderr_console
from lolacli.cli.options import (
    DriftOption,
    DropOption,
    DurationOption,
    EniOption,
    EsiOption,
    IfaceArgument,
    InterfaceOption,
    SeedOption,
    StuckSafeopOption,
)


def _usage(option: str, parse: Any) -> Any:
    """A ``callback=`` that parses an option's text with a library ``parse`` (None stays
    None), its UsageError a bad value of ``option``."""

    def callback(value: Any) -> Any:
        from lolacli.errors import UsageError

        try:
            return None if value is None else parse(value)
        except UsageError as exc:
            raise typer.BadParameter(str(exc), param_hint=option) from None

    return callback


def _link_down(text: str) -> tuple[int, float]:
    from lolacli.emulator.run import parse_link_down

    return parse_link_down(text)


def _bad_link(text: str) -> tuple[int, float]:
    from lolacli.emulator.run import parse_bad_link

    return parse_bad_link(text)


def _cpu(text: str) -> int | str:
    from lolacli.emulator.run import parse_cpu

    return parse_cpu(text)


def _probability(value: float) -> float:
    if not 0.0 <= value <= 1.0:
        raise typer.BadParameter(f"{value} is not in [0, 1]", param_hint="--corrupt-p")
    return value


CorruptOption = Annotated[
    float,
    typer.Option(
        "--corrupt-p",
        callback=_probability,
        help="Probability to damage a frame inside the line (RX error counters, lower WKC).",
    ),
]
FoePasswordOption = Annotated[
    int,
    typer.Option(
        "--foe-password",
        min=0,
        max=0xFFFF_FFFF,
        help="The slaves' FoE password (firmware read and write in BOOT).",
    ),
]
LinkDownOption = Annotated[
    str | None,
    typer.Option(
        "--link-down",
        metavar="K[@T]",
        callback=_usage("--link-down", _link_down),
        help="Cut the cable after slave position K (0: all), from the start or T "
        "after serving starts (seconds, or 500ms).",
    ),
]
BadLinkOption = Annotated[
    str | None,
    typer.Option(
        "--bad-link",
        metavar="K[:P]",
        callback=_usage("--bad-link", _bad_link),
        help="A bad cable into slave position K: it damages a frame with probability P "
        "(default 0.01): RX error counters rise from slave K on, the master loses the frame.",
    ),
]
QuietOption = Annotated[bool, typer.Option("--quiet", "-q", help="No status line.")]
PriorityOption = Annotated[
    int | None,
    typer.Option(
        "--realtime-priority",
        min=0,
        max=99,
        help="SCHED_FIFO priority (1-99; needs root or CAP_SYS_NICE), 0 for normal "
        "scheduling. Default: SCHED_FIFO 10 where permitted, else normal.",
    ),
]
AwakeOption = Annotated[
    bool,
    typer.Option(
        "--keep-cpus-awake/--let-cpus-sleep",
        help="While serving, hold the CPUs' wake-up latency at 0 (PM QoS, "
        "/dev/cpu_dma_latency; needs root) so a frame after a quiet spell does not "
        "wait for an idle core to wake, as cyclictest does.",
    ),
]
CpuOption = Annotated[
    str,
    typer.Option(
        "--cpu",
        metavar="follow|any|N",
        callback=_usage("--cpu", _cpu),
        help="Where the emulator runs: 'follow' moves it to the CPU the master's frames "
        "arrive on (the master's own on a veth pair), so each exchange runs on one "
        "core; 'any' leaves it to the OS; a number pins it to that CPU.",
    ),
]

CanOption = Annotated[
    str | None,
    typer.Option(
        "--can",
        metavar="CHANNEL",
        help="The CAN gateway's sensors from this python-can channel: their TPDOs "
        "(sdo serve --gateway --pdo) held in its process data until the next arrives.",
    ),
]


@app.command("emulate")
def emulate_cmd(
    iface: IfaceArgument,
    eni: EniOption = None,
    esi: EsiOption = None,
    drop_p: DropOption = 0.0,
    corrupt_p: CorruptOption = 0.0,
    stuck_safeop: StuckSafeopOption = None,
    drift_ppb: DriftOption = 0,
    seed: SeedOption = 0,
    foe_password: FoePasswordOption = 0,
    link_down: LinkDownOption = None,
    bad_link: BadLinkOption = None,
    duration_s: DurationOption = 0.0,
    quiet: QuietOption = False,
    realtime_priority: PriorityOption = None,
    keep_cpus_awake: AwakeOption = True,
    cpu: CpuOption = "follow",
    can: CanOption = None,
    interface: InterfaceOption = None,
) -> None:
    """Serve the ENI's slave chain on IFACE so a real master (SOEM, KickCAT, TwinCAT) can
    drive it. Ctrl-C (SIGINT) or SIGTERM stops it, with exit 130 or 143; --duration ends
    it with exit 0. With --can the CAN gateway's samples come live from a CAN bus; at
    the end each sensor's samples and their age at the master."""
    from lolacli.emulator.run import EmulateOptions, Emulation
    from lolacli.files import load_eni, load_esi
    from lolacli.interrupt import stop_signals

    cut: Any = link_down  # (position, seconds) from its callback
    options = EmulateOptions(
        drop_p, tuple(stuck_safeop or ()), drift_ppb, seed,
        cut[0] if cut else None, cut[1] if cut else 0.0, corrupt_p, foe_password,
        bad_link=bad_link,  # type: ignore[arg-type]  # (K, P) from its callback
    )
    emulation = Emulation(
        load_eni(eni if eni is not None else default_eni()), options,
        esi=[load_esi(p) for p in esi or ()],
    )
    console = stderr_console()
    status = None if quiet else lambda stats: _status(console, emulation, stats)
    bridge = _bridge(emulation, can, interface) if can is not None else None
    try:
        with stop_signals() as stop, stop.polled():  # the server polls: a stop ends it
            stats = emulation.serve(
                iface, lambda: stop() or (bridge is not None and bridge.error is not None),
                duration_s=duration_s, on_status=status,
                on_ready=lambda scheduling: _ready(console, emulation, iface, scheduling),
                realtime_priority=realtime_priority, keep_cpus_awake=keep_cpus_awake,
                cpu=cpu,  # follow, any or a CPU number from its callback
            )
    finally:
        if bridge is not None:
            bridge.close()  # the receiving thread stopped, the bus shut down
    if status is not None:
        status(stats)
    _stopped(console, stats, emulation.live)
    _end(stop, bridge)


def _bridge(emulation: Any, can: str, interface: str | None) -> Any:
    """The gateway bridged to the CAN bus (UsageError without a gateway, TransportError
    when the bus does not open): its receiver, running."""
    from lolacli.sdo.can_bridge import SensorBridge

    live = emulation.bridge_gateway()
    return SensorBridge(can, live, interface=interface)


def _end(stop: Any, bridge: Any) -> None:
    """The exit: the signal's code, 4 when the CAN bus failed, else 0."""
    from lolacli.errors import TransportError

    if stop.signum is not None:
        raise typer.Exit(stop.exit_code)
    if bridge is not None and bridge.error is not None:
        raise TransportError(bridge.error)


def _ready(console: Any, emulation: Any, iface: str, scheduling: str) -> None:
    """The lines that say the chain is served (scripts wait for the first)."""
    from lolacli.text import plural

    n = len(emulation.chain.slaves)
    console.print(
        f"emulating {plural(n, 'slave')} of {emulation.eni.source} on {iface}",
        highlight=False,
        soft_wrap=True,  # one line (a long path is not broken): scripts wait for it
    )
    console.print(f"scheduling: {scheduling}", highlight=False)
    if emulation.live is not None:
        console.print(  # the C core's gateway replays the model: a live one runs in Python
            "CAN gateway: its sensors' TPDOs held as they arrive (its cycle in Python)",
            highlight=False,
        )
    if emulation.esi_files:
        exact = sum(1 for m in emulation.esi if m.exact_revision)
        console.print(
            f"ESI SII: {len(emulation.esi)} of {n} slaves ({exact} with the exact revision)",
            highlight=False,
        )


def _status(console: Any, emulation: Any, stats: Any) -> None:
    s = emulation.status(stats)
    console.print(
        f"frames {s.frames} ({s.frames_per_s:.0f}/s) cycles {s.cycles} "
        f"lost {s.lost} damaged {s.damaged} | {s.states}",
        highlight=False,
    )


def _stopped(console: Any, stats: Any, live: Any = None) -> None:
    """What the server did: frames, reply times, placement; the CAN sensors' samples."""
    drops = "" if stats.socket_drops is None else f", {stats.socket_drops} dropped at the socket"
    console.print(
        f"stopped: {stats.received} frames received, {stats.answered} answered{drops}"
    )
    if stats.answered:
        for line in _latency_lines(stats):
            console.print(line, highlight=False, soft_wrap=True)  # whole lines: parsed
    if live is not None:
        for line in _sensor_lines(live.report()):
            console.print(line, highlight=False, soft_wrap=True)  # whole lines: parsed
    if stats.moves or stats.backoffs:
        console.print(
            f"placement: moved to the master's CPU {stats.moves} times, left it to the OS "
            f"{stats.backoffs} times",
            highlight=False,
            soft_wrap=True,
        )


def _latency_lines(stats: object) -> list[str]:
    """Reply time inside the emulator, a line each: kernel receive -> server (wake-up),
    server -> answer sent (answer)."""
    lines = []
    for label, name in (("wake-up", "wake"), ("answer", "service")):
        summary = getattr(stats, name).summary()
        if summary["count"]:
            lines.append(
                f"reply time: {label} p50 {summary['p50_us']:.0f} µs, p99 "
                f"{summary['p99_us']:.0f} µs, max {summary['max_us']:.0f} µs"
            )
    return lines


def _sensor_lines(report: dict[str, Any]) -> list[str]:
    """Per CAN sensor (``LiveSamples.report``): samples received at what rate, read by
    the master and their age at it; frames ignored and samples incomplete."""
    from lolacli.text import number, plural

    lines = []
    for s in report["sensors"]:
        rate = "" if s["rate_hz"] is None else f" at {number(s['rate_hz'], 'Hz')}"
        lines.append(f"CAN {s['name']}: {plural(s['samples_received'], 'sample')}{rate}, "
                     f"{s['samples_read']:,} read by the master")
        age = s["age_us"]
        if age is not None:
            lines.append(f"  age at the master: mean {number(age['mean'] / 1e3, 'ms')}, "
                         f"min {number(age['min'] / 1e3, 'ms')}, "
                         f"max {number(age['max'] / 1e3, 'ms')}")
    lines.append(f"CAN frames of no sensor ignored: {report['frames_ignored']}, samples "
                 f"incomplete: {report['samples_incomplete']}")
    return lines
