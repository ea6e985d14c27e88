"""`lolacli sdo …`: read, write, list, check, serve.

Thin: options -> :class:`lolacli.sdo.session.TransportOptions`, one library call, render.
canopen, python-can, pysoem and PyYAML are imported by the library only when a command
runs, so ``lolacli --help`` stays fast.

Human output fits the terminal (``$COLUMNS``; 80 columns when piped): a line longer than
that is wrapped between words, its continuation indented. Every command says an entry
the same way — ``Device type  UNSIGNED32 = 131474 (0x00020192)``: name, type, value by
:func:`lolacli.od.lookup.format_value` — and notes (a guessed type, a --type that
overrides the dictionary) go to stderr, once.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from lolacli.cli.common import FormatOption, OutputFormat, emit_json, text_width, wrapped
from lolacli.cli.options import (
    DurationOption,
    EniOption,
    EsiOption,
    FtsRateOption,
    IfaceOption,
    ImuRateOption,
    InterfaceOption,
    not_nan,
)

app = typer.Typer(
    no_args_is_help=True,
    help="SDO upload/download, object dictionaries and value checks: EtherCAT through "
    "lolacli's master (the emulated chain in process by default, --iface IF for a live "
    "bus) or pysoem (--iface IF --backend soem), or CANopen (--can).",
)

SlaveArgument = Annotated[
    str,
    typer.Argument(
        metavar="SLAVE",
        help="EtherCAT: a position (3), @station address (@1003) or slave name; "
        "CANopen: the node ID.",
        show_default=False,
    ),
]
ObjectArgument = Annotated[
    str,
    typer.Argument(
        metavar="INDEX[:SUB]",
        help="Object entry, hexadecimal: 0x6041, 0x1018:01 (subindex 0 if none).",
        show_default=False,
    ),
]
TypeOption = Annotated[
    str | None,
    typer.Option(
        "--type",
        "-t",
        help="Data type: UNSIGNED32, INTEGER24, REAL32, VISIBLE_STRING, OCTET_STRING, "
        "u16, i32, f64, UDINT… Default: from --eds/--esi/the ENI, the slave's SDO "
        "Information, the CiA 301 objects, or (reads) a guess from the bytes, said on "
        "stderr.",
    ),
]
CompleteOption = Annotated[
    bool,
    typer.Option("--complete", help="Complete access: the whole object from sub 0 or 1 (CoE)."),
]
CanOption = Annotated[
    str | None,
    typer.Option(
        "--can",
        metavar="CHANNEL",
        help="CANopen through python-can on this channel (can0, a udp_multicast group…).",
    ),
]
NodeOption = Annotated[
    int | None,
    typer.Option("--node", min=1, max=127, help="CANopen node ID (the same as SLAVE)."),
]
BackendOption = Annotated[
    str,
    typer.Option(
        "--backend",
        help="EtherCAT master: lolacli (ours, in process or --iface) or soem (pysoem, --iface).",
    ),
]
EdsOption = Annotated[
    Path | None, typer.Option("--eds", help="EDS/DCF of the CANopen node (value types, list).")
]
TimeoutOption = Annotated[
    float,
    typer.Option(
        "--timeout",
        min=0.001,
        max=3600.0,
        callback=not_nan,
        help="Seconds to wait for each SDO answer.",
    ),
]


def _options(
    can: str | None,
    interface: str | None,
    node: int | None,
    iface: str | None,
    backend: str,
    eni: Path | None,
    eds: Path | None,
    esi: list[Path] | None,
    timeout: float,
) -> Any:
    from lolacli.sdo.session import TransportOptions

    return TransportOptions(
        can=can,
        interface=interface,
        node=node,
        iface=iface,
        backend=backend,
        eni=eni,
        eds=eds,
        esi=tuple(esi or ()),
        timeout_s=timeout,
    )


def _data_type(name: str | None) -> int | None:
    if name is None:
        return None
    from lolacli.wire.datatypes import data_type_from_name

    known = data_type_from_name(name)
    if known is None:
        raise typer.BadParameter(f"unknown data type {name!r}", param_hint="--type")
    return int(known)


def _json_error(exc: Exception, base: dict[str, Any]) -> None:
    """The error document of ``lolacli.sdo/1``: an abort (exit 1) or a transport failure."""
    from lolacli.errors import SdoAbortError

    error: dict[str, Any] = {"message": str(exc)}
    if isinstance(exc, SdoAbortError):
        error = {"abort_code": f"0x{exc.code:08X}", "message": exc.text}
    else:
        error["abort_code"] = None
    emit_json({"schema": "lolacli.sdo/1", **base, "error": error})


def _run_access(fmt: OutputFormat, base: dict[str, Any], call: Any) -> None:
    from lolacli.errors import SdoAbortError, TransportError

    try:
        result = call()
    except (SdoAbortError, TransportError) as exc:
        if fmt is not OutputFormat.json:
            raise
        _json_error(exc, base)
        raise typer.Exit(exc.exit_code) from None
    if result.note:
        _note(result.note)
    if fmt is OutputFormat.json:
        emit_json(result.to_dict())
        return
    _render_value(result)


def _print(*lines: str) -> None:
    _write_lines(line for text in lines for line in wrapped(text))


def _write_lines(lines: Any) -> None:
    from lolacli.cli.common import silence_stdout

    try:
        sys.stdout.write("".join(f"{line}\n" for line in lines))
        sys.stdout.flush()
    except BrokenPipeError:
        silence_stdout()


def _note(text: str) -> None:
    """A note on stderr (``lolacli: note: …``), wrapped like the rest."""
    sys.stderr.write("".join(f"{line}\n" for line in wrapped(f"lolacli: note: {text}")))


def _render_value(result: Any) -> None:
    from lolacli.od.lookup import describe, format_value
    from lolacli.wire.datatypes import data_type_from_name

    where = f"{result.slave} 0x{result.index:04X}:{result.subindex:02X}"
    if not result.complete_access:
        _print(f"{where}  {describe(result.name, result.data_type, result.text)}")
        return
    if not isinstance(result.value, list):  # not described: the bytes
        _print(f"{where}  {describe(result.name, result.data_type, result.text)}")
        return
    from lolacli.text import plural

    size = plural(len(result.raw), "byte")
    _print(f"{where}  {describe(result.name, result.data_type)}  (complete access, {size})")
    for item in result.value:
        code = data_type_from_name(item["data_type"]) if item["data_type"] != "?" else None
        text = format_value(item["value"], code)
        _print(f"  :{item['subindex']:02X}  {describe(item['name'], item['data_type'], text)}")


def _access(
    slave: str,
    obj: str,
    options: Any,
    action: Any,
) -> Any:
    from lolacli.sdo.address import parse_object
    from lolacli.sdo.session import open_session

    address = parse_object(obj)
    with open_session(options) as session:
        target = session.target(slave)
        return action(target, address)


@app.command("read")
def read_cmd(
    slave: SlaveArgument,
    obj: ObjectArgument,
    type_name: TypeOption = None,
    complete: CompleteOption = False,
    can: CanOption = None,
    interface: InterfaceOption = None,
    node: NodeOption = None,
    iface: IfaceOption = None,
    backend: BackendOption = "lolacli",
    eni: EniOption = None,
    eds: EdsOption = None,
    esi: EsiOption = None,
    timeout: TimeoutOption = 1.0,
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Read an object entry (SDO upload). An abort is exit 1 with its code and text; no
    answer within --timeout is exit 4."""
    from lolacli.sdo.client import read

    data_type = _data_type(type_name)
    options = _options(can, interface, node, iface, backend, eni, eds, esi, timeout)

    def action(target: Any, address: Any) -> Any:
        return read(
            target.client,
            address.index,
            address.subindex,
            slave=target.label,
            data_type=data_type,
            lookup=target.lookup,
            complete_access=complete,
        )

    _run_access(fmt, _base(slave, obj), lambda: _access(slave, obj, options, action))


@app.command("write", context_settings={"ignore_unknown_options": True})
def write_cmd(
    slave: SlaveArgument,
    obj: ObjectArgument,
    value: Annotated[
        str,
        typer.Argument(
            help="The value: a number (0x hex allowed; a negative one as is: -1000), "
            "true/false, text, or hex bytes for octet strings and --complete.",
            show_default=False,
        ),
    ],
    type_name: TypeOption = None,
    complete: CompleteOption = False,
    can: CanOption = None,
    interface: InterfaceOption = None,
    node: NodeOption = None,
    iface: IfaceOption = None,
    backend: BackendOption = "lolacli",
    eni: EniOption = None,
    eds: EdsOption = None,
    esi: EsiOption = None,
    timeout: TimeoutOption = 1.0,
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Write an object entry (SDO download). The type comes from --type, the object
    dictionary (--eds/--esi/the ENI), the slave's SDO Information or the CiA 301 objects;
    an abort is exit 1."""
    from lolacli.sdo.client import write

    data_type = _data_type(type_name)
    options = _options(can, interface, node, iface, backend, eni, eds, esi, timeout)

    def action(target: Any, address: Any) -> Any:
        return write(
            target.client,
            address.index,
            address.subindex,
            value,
            slave=target.label,
            data_type=data_type,
            lookup=target.lookup,
            complete_access=complete,
        )

    if options.can is None and options.iface is None:
        _note(
            "the emulated chain lives in this process: the value is gone when it ends "
            "(sdo check runs a file's writes and reads on one chain)"
        )
    _run_access(fmt, _base(slave, obj), lambda: _access(slave, obj, options, action))


def _base(slave: str, obj: str) -> dict[str, Any]:
    """What the error document says about the request (the address as far as it parses)."""
    from lolacli.errors import UsageError
    from lolacli.sdo.address import parse_object

    try:
        address = parse_object(obj)
    except UsageError:
        return {"slave": slave, "index": None, "subindex": None}
    return {"slave": slave, "index": address.index, "subindex": address.subindex}


@app.command("list")
def list_cmd(
    slave: SlaveArgument,
    can: CanOption = None,
    interface: InterfaceOption = None,
    node: NodeOption = None,
    iface: IfaceOption = None,
    backend: BackendOption = "lolacli",
    eni: EniOption = None,
    eds: EdsOption = None,
    esi: EsiOption = None,
    timeout: TimeoutOption = 1.0,
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """The slave's object dictionary: by its SDO Information service where it has one,
    else from --esi (EtherCAT) or --eds (CANopen). With --eds and no --can, the EDS alone."""
    from lolacli.sdo.listing import list_dictionary

    options = _options(can, interface, node, iface, backend, eni, eds, esi, timeout)
    report = list_dictionary(slave, options)
    if fmt is OutputFormat.json:
        emit_json(report)
        return
    _render_list(report)


def _render_list(report: dict[str, Any]) -> None:
    """The listing as a table within the width: names and defaults wrapped in their
    cells (a word too long for its cell broken after an underscore, else where it must)."""
    from rich.table import Table

    from lolacli.cli.common import stdout_console
    from lolacli.text import plural

    path = f" ({report['path']})" if report.get("path") else ""
    count = plural(len(report["objects"]), "object")
    _print(f"slave {report['slave']}: {count} from {report['source']}{path}")
    rows: list[tuple[str, str, str, str, str]] = []
    for obj in report["objects"]:
        if obj["object_code"] != "VAR":
            rows.append((obj["object"], obj["name"] or "", obj["object_code"], "", ""))
        for e in obj["entries"]:
            kind, access = e["data_type"] or "?", e["access"] or ""
            rows.append((e["object"], e["name"] or "", kind, access, _list_default(e)))
    headers = ("object", "name", "type", "access", "default")
    widest = [max([len(h), *(len(r[i]) for r in rows)]) for i, h in enumerate(headers)]
    room = text_width() - widest[0] - widest[2] - widest[3] - 2 * (len(headers) - 1)
    name_w = max(16, room - min(widest[4], 20))
    default_w = max(8, room - min(name_w, widest[1]))
    table = Table(show_edge=False, pad_edge=False, box=None)
    for header in headers:
        table.add_column(header)
    for where, name, kind, access, default in rows:
        table.add_row(where, _cell(name, name_w), kind, access, _cell(default, default_w))
    console = stdout_console()
    with console.capture() as captured:  # fitted to the width; cells padded: strip them
        console.print(table)
    _write_lines(line.rstrip() for line in captured.get().splitlines())


def _cell(text: str, width: int) -> str:
    """``text`` in lines of at most ``width``: broken between words, and a word longer
    than a line after an underscore (``interpolation_data_…``) or else where it must."""
    lines: list[str] = []
    line = ""
    for word in text.split():
        while word:
            sep = " " if line else ""
            if len(line) + len(sep) + len(word) <= width:
                line += sep + word
                break
            if line and (len(word) <= width or width - len(line) - 1 < 8):
                lines.append(line)
                line = ""
                continue
            room = width - len(line) - len(sep)
            cut = word.rfind("_", 0, room) + 1 or room
            lines.append(line + sep + word[:cut])
            line, word = "", word[cut:]
    return "\n".join([*lines, line] if line else lines)


def _list_default(entry: dict[str, Any]) -> str:
    """An entry's default as read/write/check print values (JSON has octets as hex)."""
    from lolacli.od.lookup import format_value
    from lolacli.wire.datatypes import data_type_from_name

    default = entry["default"]
    if default is None:
        return ""
    code = data_type_from_name(entry["data_type"]) if entry["data_type"] else None
    if isinstance(default, str) and code is not None and not _is_text(code):
        try:
            default = bytes.fromhex(default)
        except ValueError:
            pass
    return format_value(default, code)


def _is_text(code: int) -> bool:
    from lolacli.wire.datatypes import DataType

    return code in (DataType.VISIBLE_STRING, DataType.UNICODE_STRING)


@app.command("check")
def check_cmd(
    file: Annotated[
        Path,
        typer.Argument(
            help="YAML/JSON file of writes and expected reads (docs/sdo.md).",
            show_default=False,
        ),
    ],
    can: CanOption = None,
    interface: InterfaceOption = None,
    node: NodeOption = None,
    iface: IfaceOption = None,
    backend: BackendOption = "lolacli",
    eni: EniOption = None,
    eds: EdsOption = None,
    esi: EsiOption = None,
    timeout: TimeoutOption = 1.0,
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Make the file's writes, then its reads, and compare each read with its expected
    value: exit 0 when all match, 1 when any differs or aborts unexpectedly, 3 for a bad
    file, 4 when the bus does not answer. Each result is printed as it is made; Ctrl-C
    or SIGTERM stops with the results so far, exit 130 or 143."""
    from lolacli.interrupt import exit_code
    from lolacli.sdo.check import CheckReport, parse_check, run_check
    from lolacli.sdo.files import read_text_file
    from lolacli.sdo.session import open_session

    check = parse_check(read_text_file(file, "a check file"), str(file))
    options = _options(can, interface, node, iface, backend, eni, eds, esi, timeout)
    report = CheckReport(check.path, len(check.items))
    notes: set[str] = set()
    printed = [0]  # results printed (a stop may come between a result and its line)

    def done(result: Any) -> None:  # each result as it is made: a stop keeps them
        if result.note and result.note not in notes:
            notes.add(result.note)
            _note(result.note)
        if fmt is not OutputFormat.json:
            _print(*_check_lines(result))
        printed[0] += 1

    try:
        with open_session(options) as session:
            run_check(check, session, report, done)
    except KeyboardInterrupt as exc:
        import signal

        code = exit_code(exc)
        report.stopped_by = signal.Signals(code - 128).name
        _finish_check(report, fmt, printed[0])
        raise typer.Exit(code) from None
    _finish_check(report, fmt, printed[0])
    if report.failed:
        raise typer.Exit(1)


def _check_lines(r: Any) -> list[str]:
    """One result: status, kind, slave, object, and the entry as read and write say it;
    why it failed (or the abort's text) on the next line."""
    from lolacli.od.lookup import describe

    item = r.item
    status = "ok  " if r.ok else "FAIL"
    head = f"{status} {item.kind:<5} {item.slave} {item.address}"
    if r.abort_code is not None:
        said = f"abort 0x{r.abort_code:08X}"
        why = r.message.removeprefix(f"{said}: ")
        return [f"{head}  {describe(r.name, '', said)}", *([f"    {why}"] if why else [])]
    if r.value is None and r.raw is None:  # not made: a value that does not fit its type
        return [f"{head}  {describe(r.name, r.data_type)}", f"    {r.message}"]
    lines = [f"{head}  {describe(r.name, r.data_type, r.text)}"]
    if r.message and not r.ok:
        lines.append(f"    {r.message}")
    return lines


def _finish_check(report: Any, fmt: OutputFormat, printed: int) -> None:
    """The JSON document, or the results not printed yet and the summary."""
    from lolacli.text import plural

    if fmt is OutputFormat.json:
        emit_json(report.to_dict())
        return
    for result in report.results[printed:]:
        _print(*_check_lines(result))
    n = len(report.results)
    tally = f"{n - report.failed} passed, {report.failed} failed"
    if report.stopped_by is not None:
        _print(
            f"stopped by {report.stopped_by} after {plural(n, 'check')} of {report.items}: {tally}"
        )
    else:
        _print(f"{plural(n, 'check')}: {tally}")


@app.command("serve")
def serve_cmd(
    can: Annotated[
        str,
        typer.Option("--can", metavar="CHANNEL", help="python-can channel to serve on."),
    ],
    interface: InterfaceOption = None,
    eds: Annotated[
        list[Path] | None, typer.Option("--eds", help="EDS/DCF of a node to serve (repeatable).")
    ] = None,
    node: Annotated[
        list[int] | None,
        typer.Option("--node", min=1, max=127, help="Node ID of each --eds, in order."),
    ] = None,
    gateway: Annotated[
        bool,
        typer.Option(
            "--gateway",
            help="Serve the LOLA CAN gateway's sensors: IMU (node 16), force/torque left "
            "(17) and right (18).",
        ),
    ] = False,
    pdo: Annotated[
        bool,
        typer.Option(
            "--pdo",
            help="With --gateway: the sensors also send each sample as TPDOs at their "
            "rates (COB-IDs 0x181-0x185, 0x189-0x18B, 0x191-0x193), for bus emulate --can.",
        ),
    ] = False,
    imu_rate: ImuRateOption = 200.0,
    fts_rate: FtsRateOption = 1000.0,
    duration_s: DurationOption = 0.0,
) -> None:
    """Serve CANopen nodes from EDS files (canopen LocalNode) for tests and for trying
    the CANopen commands without hardware: with --interface udp_multicast every process
    on this host sees them. Ctrl-C stops it with exit 130, SIGTERM with 143; --duration
    with 0."""
    from lolacli.devices.can import CanConfig, lola_sensors
    from lolacli.errors import UsageError
    from lolacli.sdo.node import node_specs

    if pdo and not gateway:
        raise UsageError("--pdo: only the gateway's sensors (--gateway) send samples")
    config = CanConfig(sensors=lola_sensors(imu_rate, fts_rate)) if pdo else None
    specs = node_specs(list(eds or ()), list(node or ()), gateway=gateway)
    _serve(can, interface, specs, config, duration_s)


def _serve(can: str, interface: str | None, specs: Any, pdo: Any, duration_s: float) -> None:
    """``sdo serve``'s run: the nodes on the bus until the end, a line each way."""
    import time

    from lolacli.errors import TransportError
    from lolacli.interrupt import exit_code
    from lolacli.sdo.node import NodeServer
    from lolacli.text import number

    def say(text: str) -> None:
        sys.stderr.write("".join(f"{line}\n" for line in wrapped(text)))
        sys.stderr.flush()

    deadline = time.monotonic() + duration_s if duration_s > 0 else None
    server = None
    try:
        with NodeServer(can, specs, interface=interface, pdo=pdo) as server:  # closed at the end
            names = ", ".join(f"{s.node_id} ({s.eds.name})" for s in specs)
            say(f"serving CANopen nodes {names} on {interface or 'CAN'} {can}")
            sender = server.transmitter
            if sender is not None:
                say("sending TPDOs: " + ", ".join(
                    f"{s.name} {number(s.rate_hz, 'Hz')}" for s in sender.config.sensors))
            while deadline is None or time.monotonic() < deadline:
                time.sleep(0.05)  # the root's handlers raise a stop here at once
                if sender is not None and sender.error is not None:
                    raise TransportError(sender.error)
    except KeyboardInterrupt as exc:
        _sent(server, say)
        sys.stderr.write(f"lolacli: {exc or 'stopped by SIGINT'}: nodes closed\n")
        raise typer.Exit(exit_code(exc)) from None
    _sent(server, say)


def _sent(server: Any, say: Any) -> None:
    """What the TPDO sender did, a line (nothing without one)."""
    from lolacli.text import plural

    sender = server.transmitter if server is not None else None
    if sender is not None:
        say("TPDOs sent: " + ", ".join(
            f"{r['name']} {plural(r['samples_sent'], 'sample')} "
            f"({r['samples_skipped']} skipped)" for r in sender.report()))
