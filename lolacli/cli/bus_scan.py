"""`lolacli bus scan`: a live bus as our master sees it, and its differences from an ENI."""

from __future__ import annotations

from typing import Annotated, Any

import typer

from lolacli.cli.bus import app
from lolacli.cli.common import FormatOption, OutputFormat, emit_json
from lolacli.cli.options import EniCheckOption, IfaceArgument


@app.command("scan")
def scan_cmd(
    iface: IfaceArgument,
    eni: EniCheckOption = None,
    state: Annotated[
        str | None,
        typer.Option(
            "--state",
            metavar="init|preop|safeop|op",
            help="First bring the bus to this state with the ENI's InitCmds (configures "
            "the bus; needs --eni), then scan: refusals show with their AL status codes.",
        ),
    ] = None,
    timeout: Annotated[
        str, typer.Option("--timeout", help="Wait this long for each frame (e.g. 20ms).")
    ] = "20ms",
    retries: Annotated[
        int, typer.Option("--retries", min=0, help="Send a lost frame again this often.")
    ] = 3,
    no_sii: Annotated[
        bool, typer.Option("--no-sii", help="Do not read the SII EEPROM (no identities).")
    ] = False,
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Scan the bus on IFACE with our master (lolacli.scan/1): every slave with its
    identity and name from the SII, AL state and status code, ports and topology from
    DL status, error counters 0x0300-0x0313. Without --state nothing is configured:
    slaves are read by auto-increment address and no station address is assigned. With
    --eni, every difference (missing, extra or wrong slave, wrong revision, the line
    ending early, a state not reached) is exit 1; exit 0 when the bus matches; exit 4
    when nothing answers, the interface does not exist or the socket is not permitted."""
    from lolacli.files import load_eni
    from lolacli.master.scan import ScanOptions, parse_state, scan
    from lolacli.master.transport import RawSocketTransport
    from lolacli.timing.model import parse_duration_ns

    target = parse_state(state) if state is not None else None
    timeout_ns = parse_duration_ns(timeout, None, "--timeout")
    if timeout_ns <= 0:
        raise typer.BadParameter(f"{timeout!r} is not a positive duration", param_hint="--timeout")
    model = load_eni(eni) if eni is not None else None
    if target is not None and model is None:
        raise typer.BadParameter("--state needs --eni (its InitCmds bring the bus up)")
    options = ScanOptions(timeout_ns=timeout_ns, retries=retries, read_sii=not no_sii, state=target)
    transport = RawSocketTransport(iface)
    try:
        report = scan(transport, eni=model, options=options, iface=iface)
    finally:
        transport.close()
    doc = report.to_dict()
    if fmt is OutputFormat.json:
        emit_json(doc)
    else:
        _render(doc)
    if report.failed:
        raise typer.Exit(1)


def _ports(s: dict[str, Any]) -> str:
    return " ".join(
        f"{p['port']}{'+' if p['open'] else '-'}"
        for p in s["ports"]
        if p["physical"] != "not implemented" or p["open"]
    )


def _errors(s: dict[str, Any]) -> str:
    from lolacli.text import plural

    c = s["error_counters"]
    if c is None:
        return "not read"
    total = (
        sum(c["invalid_frame"])
        + sum(c["rx_error"])
        + sum(c["forwarded_rx_error"])
        + c["processing_unit_error"]
        + c["pdi_error"]
    )
    lost = sum(c["lost_link"])
    text = plural(total, "error") if total else "none"
    return text + (f", {plural(lost, 'lost link')}" if lost else "")


def _al_state(s: dict[str, Any]) -> str:
    if s["al_error"] or s["al_status_code"] != "0x0000":
        return f"{s['al_state']} {s['al_status_code']} {s['al_status_text']}"
    return str(s["al_state"])


def _render(doc: dict[str, Any]) -> None:
    from lolacli.cli.common import data_table, say, stdout_console
    from lolacli.text import hex32, plural, station, transition_text

    console = stdout_console()
    table = data_table(f"Bus on {doc['iface']}")
    for column in ("#", "station", "name", "AL state", "ports", "parent", "errors"):
        table.add_column(column, justify="right" if column == "#" else "left")
    for s in doc["slaves"]:
        table.add_row(
            str(s["position"]),
            (station(s["station_address"]) if s["station_address"] else "none")
            + (f"\nalias {s['station_alias']}" if s["station_alias"] else ""),
            _text(" ".join((s["name"] or ("-" if s["answered"] else "no answer")).split())),
            _al_state(s),
            _ports(s),
            str(s["parent_position"]) if s["parent_position"] else "master",
            _errors(s),
        )
    console.print(table)
    say(console, "ports: + a frame leaves and comes back, - closed; parent: the position "
                 "of the slave it hangs off")
    console.print()
    idents = data_table("Identities (SII)")
    for column in ("#", "vendor ID", "product code", "revision", "serial", "mailbox"):
        idents.add_column(column, justify="right" if column == "#" else "left")
    for s in doc["slaves"]:
        if s["vendor_id"] is None:
            idents.add_row(str(s["position"]), "not read", "", "", "", "")
            continue
        idents.add_row(str(s["position"]), hex32(s["vendor_id"]), hex32(s["product_code"]),
                       hex32(s["revision"]), hex32(s["serial"]),
                       " ".join(s["mailbox_protocols"]) or "none")
    console.print(idents)
    console.print()
    for r in doc["refusals"]:
        if r["position"] > doc["slaves_counted"]:
            continue  # a missing slave: named below
        say(console, f"refused: slave {r['position']} ({r['slave']}) "
                     f"{transition_text(r['transition'])}: {r['text']}")
    for f in doc["findings"]:
        say(console, f"note: {f['message']}")
    for d in doc["differences"]:
        say(console, f"differs: {d['message']}")
    summary = f"{plural(doc['slaves_counted'], 'slave')} on {doc['iface']}"
    if doc["eni"] is not None:
        n = len(doc["differences"])
        summary += ("; matches the ENI" if n == 0
                    else f"; {plural(n, 'difference')} from the ENI")
    say(console, summary)


def _text(value: str) -> Any:
    from rich.text import Text

    return Text(value)  # names are data, not rich markup
