"""`lolacli bus state`: request an AL state of some or all slaves, see what each reached."""

from __future__ import annotations

from typing import Annotated, Any

import typer

from lolacli.cli.bus import app
from lolacli.cli.common import FormatOption, OutputFormat, emit_json
from lolacli.cli.options import FrameTimeoutOption, IfaceArgument

SCHEMA = "lolacli.state/1"


@app.command("state")
def state_cmd(
    args: Annotated[
        list[str],
        typer.Argument(
            metavar="[SLAVE...|all] STATE",
            help="The slaves (positions, @station addresses, names; all: every slave, the "
            "default) and last the state: INIT, PREOP, BOOT, SAFEOP or OP.",
            show_default=False,
        ),
    ],
    iface: IfaceArgument,
    timeout: Annotated[
        str, typer.Option("--timeout", help="Wait this long for each step (e.g. 10s).")
    ] = "10s",
    frame_timeout: FrameTimeoutOption = "20ms",
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Request STATE of the slaves and wait for it (lolacli.state/1); report per slave
    the state reached and, for a refusal, the AL status code and its meaning (ETG.1000.6).
    Each slave goes one state at a time from where it is (BOOT through INIT), set up from
    its SII on the way: mailbox SMs for PREOP (bootstrap mailbox for BOOT), process-data
    SMs and an output FMMU for SAFEOP, zero outputs and the process-data watchdog off for
    OP (nothing sends process data after the command). Exit 1 when any slave refuses or
    times out, 2 for a state that does not exist, 4 when the bus does not answer."""
    from lolacli.cli.bench_common import bench_bus, duration_ns, resolve
    from lolacli.master.bench import parse_state_name, request_states

    target = parse_state_name(args[-1])
    specs = args[:-1] or ["all"]
    step_ns = duration_ns(timeout, "--timeout")
    with bench_bus(iface, frame_timeout) as bus:
        if any(spec.lower() == "all" for spec in specs):
            chosen = list(bus.slaves)
        else:
            chosen = []
            for spec in specs:
                s = resolve(bus, spec)
                if s not in chosen:
                    chosen.append(s)
        if not any(s.name for s in bus.slaves):
            bus.read_names()
        results = request_states(bus, chosen, target, timeout_ns=step_ns)
    doc = {
        "schema": SCHEMA,
        "iface": iface,
        "requested": target.name,
        "slaves": [r.to_dict() for r in results],
        "refused": sum(not r.ok for r in results),
    }
    if fmt is OutputFormat.json:
        emit_json(doc)
    else:
        _render(doc)
    if doc["refused"]:
        raise typer.Exit(1)


def _render(doc: dict[str, Any]) -> None:
    from rich.text import Text

    from lolacli.cli.common import data_table, say, stdout_console
    from lolacli.text import plural

    console = stdout_console()
    table = data_table(f"{doc['requested']} requested on {doc['iface']}")
    for column in ("#", "name", "before", "reached", "refused"):
        table.add_column(column, justify="right" if column == "#" else "left")
    for s in doc["slaves"]:
        why = ""
        if s["refused"]:
            how = "timed out" if s["timed_out"] else "refused"
            why = f"{s['refused']} {how}: {s['al_status_code']} {s['al_status_text']}"
        table.add_row(str(s["position"]), Text(s["name"] or "-"), s["before"], s["reached"],
                      Text(why))  # fmt: skip
    console.print(table)
    n = len(doc["slaves"])
    if doc["refused"]:
        say(console, f"{plural(doc['refused'], 'slave')} of {n} did not reach "
                     f"{doc['requested']}")  # fmt: skip
    else:
        say(console, f"{plural(n, 'slave')} in {doc['requested']}")
