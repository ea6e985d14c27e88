"""`lolacli bus sii read|write` and `lolacli bus alias`: a slave's SII EEPROM."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from lolacli.cli.bus import app as bus_app
from lolacli.cli.common import FormatOption, OutputFormat, emit_json
from lolacli.cli.options import FrameTimeoutOption, IfaceArgument, SlaveArgument

SCHEMA = "lolacli.sii/1"
ALIAS_SCHEMA = "lolacli.alias/1"
app = typer.Typer(no_args_is_help=True, help="A slave's SII EEPROM (read, write).")
bus_app.add_typer(app, name="sii")


@app.command("read")
def read_cmd(
    slave: SlaveArgument,
    iface: IfaceArgument,
    output: Annotated[
        Path | None, typer.Option("--output", "-o", help="Also save the image (binary) here.")
    ] = None,
    frame_timeout: FrameTimeoutOption = "20ms",
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Read SLAVE's whole SII EEPROM image (lolacli.sii/1) and decode it: identity,
    mailboxes, the GENERAL category (names, CoE details), STRINGS, FMMUs, sync managers,
    TX/RX PDOs with their entries, DC; the header checksum (CRC-8 of words 0-6) checked.
    Exit 1 when the checksum is wrong, 4 when the EEPROM does not read."""
    from lolacli.cli.bench_common import bench_bus, resolve
    from lolacli.master.bench import describe_sii, read_image

    with bench_bus(iface, frame_timeout) as bus:
        s = resolve(bus, slave)
        image = read_image(bus, s)
    if output is not None:
        output.write_bytes(image)
    sii = describe_sii(image)
    doc: dict[str, Any] = {"schema": SCHEMA, "iface": iface, "slave": s.to_dict(),
                           "saved_to": str(output) if output is not None else None,
                           "sii": sii}  # fmt: skip
    if fmt is OutputFormat.json:
        emit_json(doc)
    else:
        _render(doc)
    if not sii["checksum_ok"]:
        raise typer.Exit(1)


@app.command("write")
def write_cmd(
    slave: SlaveArgument,
    image: Annotated[Path, typer.Argument(help="The SII image (binary).", show_default=False)],
    iface: IfaceArgument,
    force: Annotated[
        bool,
        typer.Option("--force", help="Write an image whose checksum is wrong or whose "
                     "identity (vendor, product) is not the slave's."),
    ] = False,
    frame_timeout: FrameTimeoutOption = "20ms",
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Write IMAGE to SLAVE's SII EEPROM (the words that differ) and read it back
    (lolacli.sii/1). The image must have a right header checksum and the slave's vendor
    and product code (--force to override); else exit 3 and nothing is written. Exit 1
    when the image does not read back as written, 4 when the EEPROM does not answer."""
    from lolacli.cli.bench_common import bench_bus, resolve
    from lolacli.errors import InputError
    from lolacli.master.bench import check_image, describe_sii, read_image, write_sii

    try:
        data = image.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read {image}: {exc.strerror}", path=str(image)) from None
    check_image(data, data, force=True, path=str(image))  # its shape, before the bus
    with bench_bus(iface, frame_timeout) as bus:
        s = resolve(bus, slave)
        current = read_image(bus, s)
        check_image(data, current, force=force, path=str(image))
        done = write_sii(bus, s, data, current)
    doc = {"schema": SCHEMA, "iface": iface, "slave": s.to_dict(), "written_from": str(image),
           "words_written": done.words_written, "verified": done.verified,
           "sii": describe_sii(done.image)}  # fmt: skip
    if fmt is OutputFormat.json:
        emit_json(doc)
    else:
        from lolacli.cli.common import say, stdout_console
        from lolacli.text import plural

        say(stdout_console(), f"slave {s.position}: {plural(done.words_written, 'word')} "
            f"written from {image}; " + ("reads back as written" if done.verified
                                         else "DOES NOT read back as written"))  # fmt: skip
    if not done.verified:
        raise typer.Exit(1)


@bus_app.command("alias")
def alias_cmd(
    slave: SlaveArgument,
    alias: Annotated[
        str, typer.Argument(metavar="N", help="The alias, 0-65535 (0: none).", show_default=False)
    ],
    iface: IfaceArgument,
    no_reload: Annotated[
        bool,
        typer.Option("--no-reload", help="Do not reload the ESC from the EEPROM: 0x0012 "
                     "shows the alias only after the next power-up."),
    ] = False,
    frame_timeout: FrameTimeoutOption = "20ms",
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Set SLAVE's configured station alias in its SII EEPROM (word 4, with the header
    checksum, word 7), as `ethercat alias` does (lolacli.alias/1); then have the ESC reload
    its configuration area from the EEPROM so that register 0x0012 holds it, as after a
    power cycle. Exit 2 for an alias outside 0-65535, 4 when the EEPROM does not answer."""
    from lolacli.cli.bench_common import bench_bus, resolve
    from lolacli.errors import UsageError
    from lolacli.master.bench import set_alias
    from lolacli.wire.datatypes import parse_int

    try:
        n = parse_int(alias.strip(), "alias")
    except ValueError:
        raise UsageError(f"alias {alias!r} is not a number 0-65535") from None
    if not 0 <= n <= 0xFFFF:
        raise UsageError(f"alias {alias!r} is outside 0-65535")
    with bench_bus(iface, frame_timeout) as bus:
        s = resolve(bus, slave)
        change = set_alias(bus, s, n, reload=not no_reload)
    doc = {"schema": ALIAS_SCHEMA, "iface": iface, "slave": s.to_dict(),
           "previous": change.previous, "alias": change.alias,
           "words_written": change.words_written, "reloaded": not no_reload,
           "register": change.register}  # fmt: skip
    if fmt is OutputFormat.json:
        emit_json(doc)
        return
    from lolacli.cli.common import say, stdout_console
    from lolacli.text import station

    where = ("0x0012 holds it now" if not no_reload
             else f"0x0012 holds {station(change.register)} until the next power-up")
    say(stdout_console(), f"slave {s.position}: alias {station(change.previous)} -> "
                          f"{station(change.alias)} in the EEPROM; {where}")  # fmt: skip


def _render(doc: dict[str, Any]) -> None:
    from rich.text import Text

    from lolacli.cli.common import data_table, say, stdout_console
    from lolacli.text import hex32, plural, station

    console = stdout_console()
    sii = doc["sii"]
    g = sii["general"] or {}
    ident = sii["identity"]
    say(console, f"slave {doc['slave']['position']}: {g.get('name') or 'no name'}"
                 + (f" (order {g['order']})" if g.get("order") else ""))  # fmt: skip
    say(console, f"  vendor {hex32(ident['vendor_id'])}, product {hex32(ident['product_code'])}"
                 f", revision {hex32(ident['revision'])}, serial {hex32(ident['serial'])}")
    ok = "right" if sii["checksum_ok"] else f"WRONG (expected {sii['checksum_expected']})"
    say(console, f"  alias {station(sii['station_alias'])}; checksum {sii['checksum']} {ok}; "
                 f"{sii['bytes']} B read of a {sii['eeprom_bytes']} B EEPROM")
    mb = sii["mailbox"]
    if mb["out"]["bytes"]:
        say(console, f"  mailbox out 0x{mb['out']['offset']:04X} {mb['out']['bytes']} B, in "
                     f"0x{mb['in']['offset']:04X} {mb['in']['bytes']} B; "
                     f"{', '.join(mb['protocols']) or 'no protocols'}")
    else:
        say(console, "  no mailbox")
    if g.get("coe_details"):
        say(console, f"  CoE: {', '.join(g['coe_details'])}")
    if sii["fmmus"]:
        say(console, f"  FMMUs: {', '.join(sii['fmmus'])}")
    if sii["dc_assign_activate"]:
        say(console, f"  DC assign-activate: {', '.join(sii['dc_assign_activate'])}")
    if sii["sync_managers"]:
        table = data_table("Sync managers")
        for column in ("SM", "type", "start", "length", "control", "enable"):
            table.add_column(column, justify="right" if column == "SM" else "left")
        for sm in sii["sync_managers"]:
            table.add_row(str(sm["index"]), sm["type"], f"0x{sm['start']:04X}",
                          f"{sm['bytes']} B", sm["control"], str(sm["enable"]))  # fmt: skip
        console.print(table)
    for key, title in (("rx_pdos", "RX PDOs (outputs)"), ("tx_pdos", "TX PDOs (inputs)")):
        if not sii[key]:
            continue
        table = data_table(title)
        for column in ("PDO", "SM", "entry", "bits", "name"):
            table.add_column(column)
        for p in sii[key]:
            sm = "-" if p["sync_manager"] is None else str(p["sync_manager"])
            table.add_row(p["index"], sm, "", f"{p['bits']} bit", Text(p["name"] or ""))
            for e in p["entries"]:
                table.add_row("", "", f"{e['index']}:{e['subindex']:02X}", f"{e['bits']} bit",
                              Text(e["name"] or ""))  # fmt: skip
        console.print(table)
    say(console, f"{plural(len(sii['strings']), 'string')}, "
                 f"{plural(len(sii['categories']), 'category', 'categories')}")
