"""`lolacli bus emulate`: serve the emulated chain on a network interface."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer

from lolacli.cli.bus import app
from lolacli.cli.common import default_eni, stderr_console


@app.command("emulate")
def emulate_cmd(
    iface: Annotated[
        str, typer.Option("--iface", "-i", help="Interface to serve on (veth, TAP, NIC).")
    ],
    eni: Annotated[
        Path | None,
        typer.Option("--eni", help="ENI of the chain. Default: the embedded LOLA chain."),
    ] = None,
    esi: Annotated[
        list[Path] | None,
        typer.Option(
            "--esi",
            help="ESI file; slaves whose identity it describes take their SII from it. Repeatable.",
        ),
    ] = None,
    drop_p: Annotated[float, typer.Option("--drop-p", help="Probability to lose a frame.")] = 0.0,
    corrupt_p: Annotated[
        float,
        typer.Option(
            "--corrupt-p",
            help="Probability to damage a frame inside the line (RX error counters, lower WKC).",
        ),
    ] = 0.0,
    stuck_safeop: Annotated[
        list[int] | None,
        typer.Option(
            "--stuck-safeop", help="Slave position (1-based) that refuses OP; repeatable."
        ),
    ] = None,
    drift_ppb: Annotated[
        int, typer.Option("--drift-ppb", help="Clock drift step along the line.")
    ] = 0,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the fault generator.")] = 0,
    foe_password: Annotated[
        int,
        typer.Option(
            "--foe-password",
            min=0,
            max=0xFFFF_FFFF,
            help="The slaves' FoE password (firmware read and write in BOOT).",
        ),
    ] = 0,
    link_down: Annotated[
        str | None,
        typer.Option(
            "--link-down",
            metavar="K[@T]",
            help="Cut the cable after slave position K (0: all), from the start or T "
            "after serving starts (seconds, or 500ms).",
        ),
    ] = None,
    duration_s: Annotated[
        float,
        typer.Option("--duration", min=0.0, help="Stop after this many seconds (0: until Ctrl-C)."),
    ] = 0.0,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No status line.")] = False,
    realtime_priority: Annotated[
        int | None,
        typer.Option(
            "--realtime-priority",
            min=0,
            max=99,
            help="SCHED_FIFO priority (1-99; needs root or CAP_SYS_NICE), 0 for normal "
            "scheduling. Default: SCHED_FIFO 10 where permitted, else normal.",
        ),
    ] = None,
    keep_cpus_awake: Annotated[
        bool,
        typer.Option(
            "--keep-cpus-awake/--let-cpus-sleep",
            help="While serving, hold the CPUs' wake-up latency at 0 (PM QoS, "
            "/dev/cpu_dma_latency; needs root) so a frame after a quiet spell does not "
            "wait for an idle core to wake, as cyclictest does.",
        ),
    ] = True,
    cpu: Annotated[
        str,
        typer.Option(
            "--cpu",
            metavar="follow|any|N",
            help="Where the emulator runs: 'follow' moves it to the CPU the master's frames "
            "arrive on (the master's own on a veth pair), so each exchange runs on one "
            "core; 'any' leaves it to the OS; a number pins it to that CPU.",
        ),
    ] = "follow",
) -> None:
    """Serve the ENI's slave chain on IFACE so a real master (SOEM, KickCAT, TwinCAT) can
    drive it. Ctrl-C (SIGINT) or SIGTERM stops it, with exit 130 or 143; --duration ends
    it with exit 0."""
    from lolacli.emulator.run import (
        EmulateOptions,
        arm_link_loss,
        esi_matches,
        make_chain,
        parse_link_down,
        serve,
        state_summary,
    )
    from lolacli.errors import UsageError
    from lolacli.files import load_eni, load_esi
    from lolacli.interrupt import stop_signals
    from lolacli.text import plural

    placement: int | str = cpu
    if cpu not in ("follow", "any"):
        if not cpu.isdigit():
            raise typer.BadParameter(
                f"{cpu!r}: expected follow, any or a CPU number", param_hint="--cpu"
            )
        placement = int(cpu)
    if not 0.0 <= corrupt_p <= 1.0:
        raise typer.BadParameter(f"{corrupt_p} is not in [0, 1]", param_hint="--corrupt-p")
    try:
        cut = parse_link_down(link_down) if link_down is not None else None
    except UsageError as exc:
        raise typer.BadParameter(str(exc), param_hint="--link-down") from None
    model = load_eni(eni if eni is not None else default_eni())
    esi_files = [load_esi(p) for p in esi or ()]
    options = EmulateOptions(
        drop_p,
        tuple(stuck_safeop or ()),
        drift_ppb,
        seed,
        cut[0] if cut else None,
        cut[1] if cut else 0.0,
        corrupt_p,
        foe_password,
    )
    chain = make_chain(model, options, esi=esi_files)
    deadline = time.monotonic() + duration_s if duration_s > 0 else None
    console = stderr_console()
    esi_note = ""
    if esi_files:
        matched = esi_matches(model, esi_files)
        exact = sum(1 for m in matched if m.exact_revision)
        esi_note = (
            f"ESI SII: {len(matched)} of {len(chain.slaves)} slaves "
            f"({exact} with the exact revision)"
        )

    def ready(scheduling: str) -> None:
        arm_link_loss(chain, options, time.monotonic_ns())  # the server's time base
        console.print(
            f"emulating {plural(len(chain.slaves), 'slave')} of {model.source} on {iface}",
            highlight=False,
            soft_wrap=True,  # one line (a long path is not broken): scripts wait for it
        )
        console.print(f"scheduling: {scheduling}", highlight=False)
        if esi_note:
            console.print(esi_note, highlight=False)

    def ended() -> bool:
        return deadline is not None and time.monotonic() >= deadline

    def status(stats: object) -> None:
        if quiet:
            return
        s = chain.stats
        elapsed = max(1e-9, (time.monotonic_ns() - getattr(stats, "started_ns", 0)) / 1e9)
        console.print(
            f"frames {s.frames} ({s.frames / elapsed:.0f}/s) cycles {s.logical_frames} "
            f"lost {s.dropped} damaged {s.corrupted} | {state_summary(chain)}",
            highlight=False,
        )

    scratch = make_chain(model, EmulateOptions(), esi=esi_files)  # warms the code up
    with stop_signals() as stop, stop.polled():  # the server polls: a stop ends it whole
        stats = serve(
            iface,
            chain,
            lambda: stop() or ended(),
            status,
            on_ready=ready,
            realtime_priority=realtime_priority,
            scratch=scratch,
            keep_cpus_awake=keep_cpus_awake,
            cpu=placement,
        )
    status(stats)
    drops = "" if stats.socket_drops is None else f", {stats.socket_drops} dropped at the socket"
    console.print(
        f"stopped: {stats.received} frames received, {stats.answered} answered{drops}"
    )
    if stats.answered:
        for line in _latency_lines(stats):
            console.print(line, highlight=False, soft_wrap=True)  # whole lines: parsed
    if stats.moves or stats.backoffs:
        console.print(
            f"placement: moved to the master's CPU {stats.moves} times, left it to the OS "
            f"{stats.backoffs} times",
            highlight=False,
            soft_wrap=True,
        )
    if stop.signum is not None:
        raise typer.Exit(stop.exit_code)


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
