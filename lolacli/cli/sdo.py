"""`lolacli sdo …`: read, write, list, check, serve.

Thin: options -> :class:`lolacli.sdo.session.TransportOptions`, one library call, render.
canopen, python-can, pysoem and PyYAML are imported by the library only when a command
runs, so ``lolacli --help`` stays fast.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from lolacli.cli.common import FormatOption, OutputFormat, emit_json, warn

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
        "u16, i32, f64, UDINT… Default: from --eds/--esi, the CiA 301 objects, or a guess "
        "from the length (reads).",
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
InterfaceOption = Annotated[
    str | None,
    typer.Option(
        "--interface",
        help="python-can interface: socketcan, pcan, kvaser, virtual, udp_multicast… "
        "Default: python-can's configuration.",
    ),
]
NodeOption = Annotated[
    int | None,
    typer.Option("--node", min=1, max=127, help="CANopen node ID (the same as SLAVE)."),
]
IfaceOption = Annotated[
    str | None,
    typer.Option("--iface", "-i", metavar="IF", help="EtherCAT: the network interface."),
]
BackendOption = Annotated[
    str,
    typer.Option(
        "--backend",
        help="EtherCAT master: lolacli (ours, in process or --iface) or soem (pysoem, --iface).",
    ),
]
EniOption = Annotated[
    Path | None,
    typer.Option(
        "--eni",
        help="ENI: the chain emulated in process (default: the embedded LOLA chain), or the "
        "configuration of the --iface bus; resolves SLAVE names and station addresses.",
    ),
]
EdsOption = Annotated[
    Path | None, typer.Option("--eds", help="EDS/DCF of the CANopen node (value types, list).")
]
EsiOption = Annotated[
    list[Path] | None,
    typer.Option(
        "--esi",
        help="ESI file(s) of the EtherCAT slaves (value types, list; the emulated slaves' SII).",
    ),
]
TimeoutOption = Annotated[
    float,
    typer.Option("--timeout", min=0.001, max=3600.0, help="Seconds to wait for each SDO answer."),
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
    if fmt is OutputFormat.json:
        emit_json(result.to_dict())
        return
    _render_value(result)


def _render_value(result: Any) -> None:
    from lolacli.sdo.client import display_value

    name = f"  {result.name}" if result.name else ""
    sys.stdout.write(
        f"{result.slave} 0x{result.index:04X}:{result.subindex:02X}{name}  "
        f"{result.data_type} = {display_value(result.value)}\n"
    )
    if result.note:
        warn(f"note: {result.note}")


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
            dictionary=target.dictionary,
            complete_access=complete,
        )

    _run_access(fmt, _base(slave, obj), lambda: _access(slave, obj, options, action))


@app.command("write")
def write_cmd(
    slave: SlaveArgument,
    obj: ObjectArgument,
    value: Annotated[
        str,
        typer.Argument(
            help="The value: a number (0x hex allowed), true/false, text, or hex bytes "
            "for octet strings and --complete.",
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
    dictionary (--eds/--esi) or the CiA 301 objects; an abort is exit 1."""
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
            dictionary=target.dictionary,
            complete_access=complete,
        )

    if options.can is None and options.iface is None:
        from lolacli.cli.common import warn

        warn(
            "note: the emulated chain lives in this process: the value is gone when it ends "
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
    from rich.table import Table

    from lolacli.cli.common import stdout_console

    console = stdout_console()
    console.print(
        f"slave {report['slave']}: {len(report['objects'])} objects from {report['source']}"
        + (f" ({report['path']})" if report.get("path") else "")
    )
    table = Table(show_edge=False, pad_edge=False, box=None)
    for col in ("object", "name", "type", "access", "default"):
        table.add_column(col, overflow="fold")
    for obj in report["objects"]:
        for e in obj["entries"]:
            name = e["name"] if obj["object_code"] == "VAR" else f"{obj['name']}: {e['name']}"
            default = "" if e["default"] is None else str(e["default"])
            table.add_row(e["object"], name, e["data_type"] or "?", e["access"] or "?", default)
    console.print(table)


@app.command("check")
def check_cmd(
    file: Annotated[
        Path,
        typer.Argument(
            help="YAML/JSON file of writes and expected reads (docs/sdo-check.md).",
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
    file, 4 when the bus does not answer."""
    from lolacli.sdo.check import parse_check, run_check
    from lolacli.sdo.files import read_text_file
    from lolacli.sdo.session import open_session

    check = parse_check(read_text_file(file, "a check file"), str(file))
    options = _options(can, interface, node, iface, backend, eni, eds, esi, timeout)
    with open_session(options) as session:
        report = run_check(check, session)
    if fmt is OutputFormat.json:
        emit_json(report.to_dict())
    else:
        _render_check(report)
    if report.failed:
        raise typer.Exit(1)


def _render_check(report: Any) -> None:
    from lolacli.sdo.client import display_value

    out = []
    for r in report.results:
        item = r.item
        status = "ok  " if r.ok else "FAIL"
        what = display_value(r.value) if r.abort_code is None else f"abort 0x{r.abort_code:08X}"
        detail = f"  {r.message}" if r.message and (not r.ok or r.abort_code is not None) else ""
        out.append(
            f"{status} {item.kind:<5} {item.slave} {item.address} {r.data_type or '?'} "
            f"{what}{detail}"
        )
    n = len(report.results)
    out.append(f"{n} checks: {n - report.failed} passed, {report.failed} failed")
    sys.stdout.write("\n".join(out) + "\n")


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
    duration_s: Annotated[
        float, typer.Option("--duration", min=0.0, help="Stop after this many seconds (0: Ctrl-C).")
    ] = 0.0,
) -> None:
    """Serve CANopen nodes from EDS files (canopen LocalNode) for tests and for trying
    the CANopen commands without hardware: with --interface udp_multicast every process
    on this host sees them. Ctrl-C (or SIGTERM) stops it with exit 0."""
    import signal
    import time

    from lolacli.errors import UsageError
    from lolacli.sdo.node import NodeServer, NodeSpec, gateway_nodes

    files, ids = list(eds or ()), list(node or ())
    if len(files) != len(ids):
        raise UsageError(f"{len(files)} --eds but {len(ids)} --node: give one node ID per EDS")
    specs = [NodeSpec(f, n) for f, n in zip(files, ids, strict=True)]
    if gateway:
        specs += gateway_nodes()
    if not specs:
        raise UsageError("nothing to serve: give --eds FILE --node N, or --gateway")
    taken = [s.node_id for s in specs]
    if len(set(taken)) != len(taken):
        raise UsageError(f"node IDs given twice: {taken}")
    stop = {"flag": False}

    def _stop(_signum: int, _frame: object) -> None:
        stop["flag"] = True

    signal.signal(signal.SIGINT, _stop)
    signal.signal(signal.SIGTERM, _stop)
    deadline = time.monotonic() + duration_s if duration_s > 0 else None
    with NodeServer(can, specs, interface=interface):
        names = ", ".join(f"{s.node_id} ({s.eds.name})" for s in specs)
        sys.stderr.write(f"serving CANopen nodes {names} on {interface or 'CAN'} {can}\n")
        sys.stderr.flush()
        while not stop["flag"] and (deadline is None or time.monotonic() < deadline):
            time.sleep(0.05)
