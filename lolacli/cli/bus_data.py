"""`lolacli bus data`: the live process image by ENI variable name (:mod:`lolacli.master.data`)."""

from __future__ import annotations

import json
import sys
import time
from typing import Annotated, Any

import typer

from lolacli.cli.bus import app
from lolacli.cli.common import FormatOption, OutputFormat, emit_json
from lolacli.cli.options import EniOption, IfaceOption, SetValueOption

#: cycles run after OP (and after --set) before a snapshot is shown: outputs out, inputs back
SETTLE_CYCLES = 20
#: a watch waits for its next sample in steps no longer than this (a stop is seen within it)
POLL_NS = 100_000_000


Filters = Annotated[
    list[str] | None,
    typer.Option(
        "--filter",
        metavar="GLOB",
        help="Only variables whose names match (shell wildcards, any case; "
        "no wildcard: a part of the name); repeatable.",
    ),
]
WatchHz = Annotated[
    float | None,
    typer.Option(
        "--watch",
        metavar="HZ",
        min=0.01,
        max=1000.0,
        help="Print a JSON line (lolacli.data/1) this often until Ctrl-C or --count.",
    ),
]
Count = Annotated[
    int | None, typer.Option("--count", min=1, help="With --watch: stop after N samples.")
]
DataRate = Annotated[
    float | None,
    typer.Option(
        "--rate",
        min=1.0,
        max=100_000.0,
        help="Cycle rate in Hz (default: the ENI's cycle time, else 1 kHz).",
    ),
]


@app.command("data")
def data_cmd(
    iface: IfaceOption = None,
    eni: EniOption = None,
    filters: Filters = None,
    set_values: SetValueOption = None,
    watch: WatchHz = None,
    count: Count = None,
    rate: DataRate = None,
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Bring the ENI's bus (default: the embedded LOLA chain, emulated in process; --iface
    IF: a live bus) to OP with our master and show the process image by variable name,
    typed as the ENI says (lolacli.data/1). --set NAME=VALUE writes an output first
    (every value is checked before anything is written). --watch HZ prints one JSON line
    a sample for scripts until Ctrl-C (exit 130, the bus left cleanly) or --count N.
    Exit 2 for an unknown variable or a bad value, 3 for a bad ENI, 4 when nothing
    answers."""
    from lolacli.cli.common import default_eni
    from lolacli.errors import UsageError
    from lolacli.files import load_eni
    from lolacli.interrupt import stop_signals
    from lolacli.master.data import parse_setting, select

    if count is not None and watch is None:
        raise UsageError("--count goes with --watch HZ")
    config = load_eni(eni or default_eni())
    settings = [parse_setting(config, item) for item in set_values or ()]
    variables = select(config, filters or ())
    transport = _transport(config, iface)
    from lolacli.master.data import LiveData

    live = LiveData(config, transport, variables, rate_hz=rate, realtime=iface is not None)
    with stop_signals() as stop, stop.polled():
        transport.stop = stop
        try:
            live.bring_up()
            if settings:
                live.write(settings)
            live.run_for(SETTLE_CYCLES * live.master.cycle_time_ns)
            if watch is not None:
                _watch(live, watch, count, stop, virtual=iface is None)
            elif not stop():
                doc = _snapshot(live, config, iface, settings)
        finally:
            live.leave()
            transport.close()
    if stop():
        raise typer.Exit(stop.exit_code)
    if watch is not None:
        return
    if fmt is OutputFormat.json:
        emit_json(doc)
    else:
        _render(doc)


def _transport(config: Any, iface: str | None) -> Any:
    """The in-process emulated chain of ``config``, or a live bus on ``iface``."""
    if iface is None:
        from lolacli.simulate import VirtualBus

        return VirtualBus(config).transport
    from lolacli.master.transport import RawSocketTransport

    return RawSocketTransport(iface)


def _watch(live: Any, hz: float, count: int | None, stop: Any, *, virtual: bool) -> None:
    period_ns = round(1e9 / hz)
    n = 0
    wall_next = time.monotonic_ns()
    while not stop():
        sys.stdout.write(json.dumps(live.sample(), ensure_ascii=False) + "\n")
        sys.stdout.flush()
        n += 1
        if count is not None and n >= count:
            return
        wall_next += period_ns
        if virtual:  # virtual time runs at once: the wall clock paces the samples
            live.run_for(period_ns)
            while not stop() and (left := wall_next - time.monotonic_ns()) > 0:
                time.sleep(min(left, POLL_NS) / 1e9)
        else:
            left_ns = period_ns
            while left_ns > 0 and not stop():
                step = min(left_ns, POLL_NS)
                live.run_for(step)
                left_ns -= step


def _snapshot(live: Any, config: Any, iface: str | None, settings: list[Any]) -> dict[str, Any]:
    from lolacli.master.data import show

    doc: dict[str, Any] = live.sample()
    doc.update(
        {
            "eni": config.source,
            "iface": iface,
            "bus": "live" if iface else "emulated",
            "variables": live.table(),
            "written": [{"name": s.variable.name, "value": show(s.value)} for s in settings],
            "states": live.states(),
            "refusals": [r.to_dict() for r in live.refusals],
        }
    )
    return doc


def _render(doc: dict[str, Any]) -> None:
    from pathlib import Path

    from rich.text import Text

    from lolacli.cli.common import data_table, fit_table, say, stdout_console
    from lolacli.text import plural

    console = stdout_console()
    where = doc["iface"] or f"the emulated chain ({Path(doc['eni'] or 'ENI').name})"
    states = doc["states"]
    in_op = sum(s["state"] == "OP" for s in states)
    say(console, f"{plural(len(states), 'slave')} on {where}, {in_op} in OP; "
                 f"cycle {doc['cycle']:,}, {doc['lost_frames']:,} frames lost")  # fmt: skip
    for s in states:
        if s["state"] != "OP":
            say(console, f"slave {s['position']} ({s['name']}): {s['state'] or 'no answer'}")
    for w in doc["written"]:
        say(console, f"wrote {w['name']} = {w['value']}")
    table = data_table()
    table.add_column("variable")
    table.add_column("dir")
    table.add_column("type")
    table.add_column("value", justify="right")
    for v in doc["variables"]:
        table.add_row(Text(v["name"]), "in" if v["direction"] == "input" else "out",
                      Text(v["type"]), Text(str(v["value"])))  # fmt: skip
    fit_table(table, console)
    console.print(table)
    say(console, plural(len(doc["variables"]), "variable"))
