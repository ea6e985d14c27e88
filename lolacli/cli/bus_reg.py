"""`lolacli bus reg read|write`: an ESC register of one slave, by number or by name."""

from __future__ import annotations

from typing import Annotated, Any

import typer

from lolacli.cli.bus import app as bus_app
from lolacli.cli.common import FormatOption, OutputFormat, emit_json
from lolacli.cli.options import FrameTimeoutOption, IfaceArgument, SlaveArgument

SCHEMA = "lolacli.reg/1"
app = typer.Typer(no_args_is_help=True, help="ESC registers of one slave (read, write).")
bus_app.add_typer(app, name="reg")

RegisterArgument = Annotated[
    str,
    typer.Argument(
        metavar="ADDR[:LEN]",
        help="Address (0x0130) or register name (al_status, dl_status, rx_error_counter, "
        "sm2, fmmu0, …), LEN bytes (default: the register's size, else 1).",
        show_default=False,
    ),
]


@app.command("read")
def read_cmd(
    slave: SlaveArgument,
    register: RegisterArgument,
    iface: IfaceArgument,
    frame_timeout: FrameTimeoutOption = "20ms",
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Read LEN bytes of SLAVE's ESC from ADDR (lolacli.reg/1) and decode the known
    registers in them: AL status and its code's text, DL status per port, error
    counters, DC times, FMMUs, sync managers. Nothing is configured: the slave is read
    by its position. Exit 2 for an address outside the ESC's 64 KiB, 4 when the slave
    does not answer."""
    from lolacli.cli.bench_common import bench_bus, resolve
    from lolacli.master.bench import read_register, register_fields
    from lolacli.wire.registers import parse_register

    span = parse_register(register)
    with bench_bus(iface, frame_timeout) as bus:
        s = resolve(bus, slave)
        data = read_register(bus, s, span)
        fields = register_fields(bus, s, span.address, data)
    doc = _doc(iface, s, span, data, fields, None)
    _out(doc, fmt)


@app.command("write")
def write_cmd(
    slave: SlaveArgument,
    register: RegisterArgument,
    value: Annotated[
        str,
        typer.Argument(
            help="The value: a number (0x12, 4660) written little endian in LEN bytes, or "
            "hex bytes (de:ad:be:ef).",
            show_default=False,
        ),
    ],
    iface: IfaceArgument,
    force: Annotated[
        bool,
        typer.Option("--force", help="Write a configuration register (station address, AL "
                     "control, watchdog, FMMU, SM, DC SYNC) of a slave in SAFEOP or OP."),
    ] = False,
    frame_timeout: FrameTimeoutOption = "20ms",
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Write VALUE to SLAVE's ESC at ADDR and read it back (lolacli.reg/1: ``verified``
    false when it reads back otherwise, as read-only and self-clearing registers do). A
    write into what a master configures while the slave runs process data (SAFEOP, OP)
    needs --force. Exit 2 for bad input (nothing written), 4 when the slave does not answer."""
    from lolacli.cli.bench_common import bench_bus, resolve
    from lolacli.master.bench import register_fields, write_register
    from lolacli.wire.registers import parse_register

    span = parse_register(register)
    data = _value(value, span.length, explicit=":" in register or span.name is not None)
    span = type(span)(span.address, len(data), span.name)
    with bench_bus(iface, frame_timeout) as bus:
        s = resolve(bus, slave)
        back = write_register(bus, s, span, data, force=force)
        fields = register_fields(bus, s, span.address, back)
    doc = _doc(iface, s, span, back, fields, data)
    _out(doc, fmt)


def _value(text: str, length: int, *, explicit: bool) -> bytes:
    """VALUE as bytes: hex bytes as given; a number in ``length`` bytes when the length
    was given or named, else in the fewest of 1, 2, 4, 8 it fits."""
    from lolacli.errors import UsageError
    from lolacli.wire.datatypes import parse_int

    t = text.strip()
    if ":" in t or (" " in t):
        try:
            raw = bytes.fromhex(t.replace(":", " "))
        except ValueError:
            raise UsageError(f"value {text!r} is not hex bytes like de:ad:be:ef") from None
        if explicit and len(raw) != length:
            raise UsageError(f"value {text!r} has {len(raw)} bytes; the register has {length}")
        return raw
    try:
        n = parse_int(t, "value")
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if n < 0:
        raise UsageError(f"value {text!r} is negative; give the register's bits as a number")
    if not explicit:
        length = next((k for k in (1, 2, 4, 8) if n < 1 << (8 * k)), 9)
    if n >= 1 << (8 * length):
        raise UsageError(f"value {text!r} does not fit the register's {length} bytes")
    return n.to_bytes(length, "little")


def _doc(iface: str, s: Any, span: Any, data: bytes, fields: Any, written: bytes | None) -> dict[
    str, Any]:  # fmt: skip
    return {
        "schema": SCHEMA,
        "iface": iface,
        "slave": s.to_dict(),
        "al_state": _state(s.al_status),
        "address": f"0x{span.address:04X}",
        "length": span.length,
        "name": span.name,
        "data": data.hex(),
        "written": written.hex() if written is not None else None,
        "verified": (written == data) if written is not None else None,
        "fields": [f.to_dict() for f in fields],
    }


def _state(status: int) -> str:
    from lolacli.wire.registers import al_state_name

    return al_state_name(status)


def _out(doc: dict[str, Any], fmt: OutputFormat) -> None:
    if fmt is OutputFormat.json:
        emit_json(doc)
        return
    from rich.text import Text

    from lolacli.cli.bench_common import label
    from lolacli.cli.common import data_table, say, stdout_console
    from lolacli.master.bench import BenchSlave

    console = stdout_console()
    slave = doc["slave"]
    s = BenchSlave(slave["position"], slave["station_address"], name=slave["name"] or "")
    name = f" {doc['name']}" if doc["name"] else ""
    raw = " ".join(doc["data"][i : i + 2] for i in range(0, len(doc["data"]), 2))
    verb = "wrote" if doc["written"] is not None else "read"
    say(console, f"{label(s)}, {doc['al_state']}: {verb} {doc['address']}{name}, "
                 f"{doc['length']} B")  # fmt: skip
    say(console, f"  {raw}")
    if doc["written"] is not None and not doc["verified"]:
        say(console, "  reads back differently from what was written (a read-only or "
                     "self-clearing register)")  # fmt: skip
    if doc["fields"]:
        table = data_table()
        for column in ("address", "register", "value"):
            table.add_column(column)
        for f in doc["fields"]:
            table.add_row(f["address"], f["name"], Text(f["text"]))
        console.print(table)
