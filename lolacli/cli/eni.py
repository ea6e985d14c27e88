"""`lolacli eni …` commands: inspect, vars, validate, diff.

Each command: an ``Annotated`` signature, one library call, rendering. The library
(``lolacli.files``, ``lolacli.eni.*``) and rich are imported inside the commands.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from lolacli.cli.common import FormatOption, OutputFormat, default_eni, emit_json

app = typer.Typer(no_args_is_help=True, help="Read, check and compare ENI files.")

OptionalEni = Annotated[
    Path | None,
    typer.Argument(
        help="ENI file (EtherCATConfig XML). Default: the embedded LOLA chain.",
        show_default=False,
    ),
]


def _load(path: Path | None) -> Any:
    from lolacli.files import load_eni

    return load_eni(path if path is not None else default_eni())


def _one_line(text: str) -> str:
    """ENI names may hold newlines (acontis exports); show them on one line."""
    return " ".join(text.split())


@app.command("inspect")
def inspect_cmd(file: OptionalEni = None, fmt: FormatOption = OutputFormat.human) -> None:
    """Slaves, cyclic frames with their datagrams (expected WKC, wire bytes and time at
    100 Mbit/s) and the process image of an ENI."""
    from lolacli.eni.report import inspect_report

    report = inspect_report(_load(file))
    if fmt is OutputFormat.json:
        emit_json(report)
        return
    _render_inspect(report)


def _render_inspect(report: dict[str, Any]) -> None:
    from rich.table import Table

    console = _console()
    cycle = report["cycle_time_us"]
    console.print(
        f"{report['source']}  ({report['root']})  {report['slave_count']} slaves, "
        f"cycle time {'—' if cycle is None else f'{cycle:g} µs'}"
    )
    slaves = Table(title="Slaves", title_justify="left")
    for col in (
        "#",
        "name",
        "vendor",
        "product",
        "revision",
        "station",
        "auto-inc",
        "in bits",
        "out bits",
        "mailbox",
        "DC",
    ):
        slaves.add_column(col, justify="left" if col in ("name", "mailbox") else "right")
    for s in report["slaves"]:
        dc = s["dc"]
        slaves.add_row(
            str(s["position"]),
            _one_line(s["name"]),
            f"0x{s['vendor_id']:X}",
            f"0x{s['product_code']:X}",
            f"0x{s['revision']:X}",
            str(s["station_address"]),
            f"0x{s['auto_inc_address']:04X}",
            str(s["inputs_bits"]),
            str(s["outputs_bits"]),
            ",".join(s["mailbox_protocols"]) or "-",
            "-" if dc is None else ("ref" if dc["reference_clock"] else "yes"),
        )
    console.print(slaves)
    for i, frame in enumerate(report["cyclic_frames"], 1):
        # the heading as a line of text (never broken inside a number), the table below
        console.print(
            f"Cyclic frame {i}: {frame['frame_bytes']} B on the wire, "
            f"{frame['wire_time_us']} µs at 100 Mbit/s "
            f"({frame['wire_time_with_overhead_us']} µs with preamble and gap)"
        )
        console.print(_frame_table(frame))
    pi = report["process_image"]
    console.print(
        f"Process image: inputs {pi['inputs_bytes']} B, outputs {pi['outputs_bytes']} B, "
        f"{pi['variable_count']} variables"
    )


def _frame_table(frame: dict[str, Any]) -> Any:
    from rich.table import Table

    table = Table()
    for col in ("cmd", "address", "length", "expected WKC", "states"):
        table.add_column(col, justify="left" if col in ("cmd", "address", "states") else "right")
    for d in frame["datagrams"]:
        if d["logical_address"] is not None:
            address = f"0x{d['logical_address']:08X}"
        else:
            address = f"{d['adp']}:0x{d['ado']:04X}"
        wkc = "-" if d["expected_wkc"] is None else str(d["expected_wkc"])
        table.add_row(d["cmd"], address, str(d["length_bytes"]), wkc, ",".join(d["states"]))
    return table


def _console() -> Any:
    from lolacli.cli.common import stdout_console

    return stdout_console()  # one width rule for every command group (cli/common.py)


@app.command("vars")
def vars_cmd(
    file: OptionalEni = None,
    filter_: Annotated[
        str | None,
        typer.Option("--filter", help="Glob on variable names, case-insensitive ('*Status*')."),
    ] = None,
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Process-image variables: name, direction, bit offset and size, data type."""
    from lolacli.eni.report import vars_report

    report = vars_report(_load(file), filter_)
    if fmt is OutputFormat.json:
        emit_json(report)
        return
    from rich.table import Table

    table = Table(title=f"{report['count']} variables", title_justify="left")
    for col in ("name", "dir", "bit offset", "byte.bit", "bits", "type"):
        table.add_column(col, justify="left" if col in ("name", "dir", "type") else "right")
    for v in report["variables"]:
        table.add_row(
            _one_line(v["name"]),
            v["direction"][:3],
            str(v["bit_offset"]),
            f"{v['bit_offset'] // 8}.{v['bit_offset'] % 8}",
            str(v["bit_size"]),
            v["data_type"],
        )
    _console().print(table)


@app.command("validate")
def validate_cmd(
    file: OptionalEni = None,
    strict: Annotated[bool, typer.Option("--strict", help="Warnings fail too (exit 1).")] = False,
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Semantic checks: duplicate or missing station addresses, overlapping FMMUs,
    overlapping cyclic commands, <Cnt> against the slaves addressed, PDOs overrunning their
    sync manager, variables outside the process image.

    Exit 0 when clean, 1 when there are errors (or warnings with --strict), 3 when the
    file cannot be read."""
    from rich.markup import escape

    from lolacli.eni.validate import validate_eni, validate_report
    from lolacli.findings import Severity

    eni = _load(file)
    findings = validate_eni(eni)
    report = validate_report(eni, findings)
    if fmt is OutputFormat.json:
        emit_json(report)
    else:
        console = _console()
        for f in findings:
            where = escape(f" [slave {f.slave}]") if f.slave is not None else ""
            style = "red" if f.severity is Severity.FAILURE else "yellow"
            console.print(
                f"[{style}]{f.severity.value}[/{style}] {f.kind}{where}: {f.message}", markup=True
            )
        console.print(f"{eni.source}: {report['errors']} error(s), {report['warnings']} warning(s)")
    failed = report["errors"] > 0 or (strict and report["warnings"] > 0)
    if failed:
        raise typer.Exit(1)


@app.command("diff")
def diff_cmd(
    a: Annotated[Path, typer.Argument(help="First ENI file.", show_default=False)],
    b: Annotated[Path, typer.Argument(help="Second ENI file.", show_default=False)],
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Differences between two ENIs: slaves (added, removed, identity, addresses), cyclic
    commands, process-image sizes and variables, cycle time.

    Exit 0 when the two are equal, 1 when they differ, 3 when a file cannot be read."""
    from lolacli.eni.diff import diff_eni, diff_report

    eni_a, eni_b = _load(a), _load(b)
    changes = diff_eni(eni_a, eni_b)
    report = diff_report(eni_a, eni_b, changes)
    if fmt is OutputFormat.json:
        emit_json(report)
    else:
        console = _console()
        marks = {"added": "+", "removed": "-", "changed": "~"}
        for c in changes:
            detail = (
                c.after
                if c.kind == "added"
                else c.before
                if c.kind == "removed"
                else (", ".join(f"{k}: {c.before[k]!r} -> {c.after[k]!r}" for k in c.before))
            )
            console.print(f"{marks[c.kind]} {c.area} {_one_line(c.key)}: {detail}", markup=False)
        console.print(f"{len(changes)} difference(s)" if changes else "no differences")
    if changes:
        raise typer.Exit(1)
