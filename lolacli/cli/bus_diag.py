"""`lolacli bus diag`: the error counters of every port over an interval, and the link
where errors enter the line (:mod:`lolacli.master.diag`)."""

from __future__ import annotations

from typing import Annotated, Any

import typer

from lolacli.cli.bus import app
from lolacli.cli.common import FormatOption, OutputFormat, emit_json
from lolacli.cli.options import IfaceArgument


@app.command("diag")
def diag_cmd(
    iface: IfaceArgument,
    interval: Annotated[
        str,
        typer.Option("--interval", help="How long to watch the counters (e.g. 10s, 500ms)."),
    ] = "10s",
    reset: Annotated[
        bool, typer.Option("--reset", help="Clear the error counters first (0x0300-0x0313).")
    ] = False,
    probe_hz: Annotated[
        float,
        typer.Option(
            "--probe-hz",
            min=0.0,
            max=100_000.0,
            help="Probe frames a second meanwhile (each passes every cable), 0: none "
            "(another master drives the bus).",
        ),
    ] = 1000.0,
    timeout: Annotated[
        str, typer.Option("--timeout", help="Wait this long for each frame (e.g. 20ms).")
    ] = "20ms",
    retries: Annotated[
        int, typer.Option("--retries", min=0, help="Send a lost frame again this often.")
    ] = 10,
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Read the error counters (0x0300-0x0313: RX errors, forwarded RX errors,
    processing unit and PDI errors, lost links) of every port on IFACE before and after
    an interval, sending probe frames meanwhile, and name the link where errors enter
    the line: the first port on the frame's path whose RX errors rose, and its upstream
    neighbour (lolacli.diag/1). Exit 0 when no counter rose, 1 when one did, 4 when
    nothing answers."""
    from lolacli.master.diag import DiagOptions, diagnose
    from lolacli.master.transport import RawSocketTransport
    from lolacli.timing.model import parse_duration_ns

    interval_ns = parse_duration_ns(interval, "s", "--interval")
    timeout_ns = parse_duration_ns(timeout, None, "--timeout")
    if interval_ns <= 0:
        raise typer.BadParameter(f"{interval!r} is not a positive duration",
                                 param_hint="--interval")  # fmt: skip
    if timeout_ns <= 0:
        raise typer.BadParameter(f"{timeout!r} is not a positive duration", param_hint="--timeout")
    options = DiagOptions(interval_ns, reset, probe_hz, timeout_ns, retries)
    transport = RawSocketTransport(iface)
    try:
        report = diagnose(transport, options=options, iface=iface)
    finally:
        transport.close()
    doc = report.to_dict()
    if fmt is OutputFormat.json:
        emit_json(doc)
    else:
        render(doc)
    if report.errors:
        raise typer.Exit(1)


def _who(position: int, names: dict[str, Any]) -> str:
    if position == 0:
        return "the master"
    name = names.get(str(position))
    return f"slave {position}" + (f" ({' '.join(name.split())})" if name else "")


def render(doc: dict[str, Any]) -> None:
    from lolacli.cli.common import data_table, say, stdout_console
    from lolacli.text import number, plural

    console = stdout_console()
    names = doc["names"]
    risen = [p for p in doc["ports"] if p["rx_errors"] or p["lost_links"]]
    forwarded = [p for p in doc["ports"] if p["forwarded_rx_errors"]]
    seconds = number(doc["interval_s"], "s")
    probes = (f"{plural(doc['probe_frames'], 'probe frame')}, "
              f"{doc['probe_frames_lost']} lost")  # fmt: skip
    say(console, f"{plural(doc['slaves'], 'slave')} on {doc['iface']} watched for {seconds} "
                 f"({probes})" + ("; counters cleared first" if doc["reset"] else ""))
    if risen:
        table = data_table("RX errors and lost links that rose")
        for column in ("#", "port", "RX errors", "forwarded", "lost links"):
            table.add_column(column, justify="right")
        for p in risen:
            table.add_row(str(p["position"]), str(p["port"]), str(p["rx_errors"]),
                          str(p["forwarded_rx_errors"]), str(p["lost_links"]))
        console.print(table)
    if forwarded:
        most = max(p["forwarded_rx_errors"] for p in forwarded)
        say(console, f"forwarded RX errors rose at {plural(len(forwarded), 'port')} "
                     f"(up to +{most} each): frames damaged upstream passing by")
    for o in doc["other_errors"]:
        say(console, f"{_who(o['position'], names)}: processing unit errors "
                     f"+{o['processing_unit_errors']}, PDI errors +{o['pdi_errors']}")
    link = doc["suspect_link"]
    if link is None:
        if not risen and not forwarded and not doc["other_errors"]:
            say(console, f"no errors: no error counter rose in {seconds}")
        return
    say(console, f"suspect link: {_who(link['upstream'], names)} -> "
                 f"{_who(link['downstream'], names)}, seen at slave {link['at']} port "
                 f"{link['port']}")
    for line in link["evidence"]:
        say(console, f"  {line}", hang=4)
