"""`lolacli eni …` commands: inspect, vars, validate, diff, generate.

Each command: an ``Annotated`` signature, one library call, rendering. The library
(``lolacli.files``, ``lolacli.eni.*``) and rich are imported inside the commands.
"""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

import typer

from lolacli.cli.common import (
    FormatOption,
    OutputFormat,
    break_long_words,
    data_table,
    default_eni,
    emit_json,
    say,
)
from lolacli.cli.options import FrameTimeoutOption, IfaceArgument

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
    """Slaves (station address, name, process data, mailbox, DC; then their identities),
    cyclic frames with their datagrams (expected WKC, wire bytes and time at 100 Mbit/s)
    and the process image of an ENI."""
    from lolacli.eni.report import inspect_report

    eni = _load(file)
    report = inspect_report(eni)
    if fmt is OutputFormat.json:
        emit_json(report)
        return
    _render_inspect(eni, report)


def _render_inspect(eni: Any, report: dict[str, Any]) -> None:
    from lolacli.text import number, plural

    console = _console()
    cycle = report["cycle_time_us"]
    cycle_text = "not given" if cycle is None else number(cycle, "µs")
    say(console, report["source"])
    say(console, f"{report['root']}: {plural(report['slave_count'], 'slave')}, "
                 f"cycle time {cycle_text}")
    console.print()
    console.print(_slaves_table(report["slaves"]))
    console.print()
    console.print(_identities_table(report["slaves"]))
    for i, (frame, model) in enumerate(zip(report["cyclic_frames"], eni.cyclic_frames,
                                           strict=True), 1):
        console.print()
        say(console, f"Cyclic frame {i}: {number(frame['frame_bytes'], 'B', 0)}, "
                     f"{number(frame['wire_time_us'], 'µs')} on the wire at 100 Mbit/s "
                     f"({number(frame['wire_time_with_overhead_us'], 'µs')} with preamble "
                     "and inter-frame gap)")
        console.print(_frame_table(frame, model))
    pi = report["process_image"]
    console.print()
    say(console, f"Process image: inputs {number(pi['inputs_bytes'], 'B', 0)}, outputs "
                 f"{number(pi['outputs_bytes'], 'B', 0)}, "
                 f"{plural(pi['variable_count'], 'variable')} (eni vars lists them)")


def _slaves_table(slaves: list[dict[str, Any]]) -> Any:
    from rich.text import Text

    from lolacli.text import number, station

    table = data_table("Slaves")
    for col in ("#", "station", "name", "inputs", "outputs", "mailbox", "DC"):
        table.add_column(col, justify="right" if col in ("#", "inputs", "outputs") else "left")
    for s in slaves:
        dc = s["dc"]
        table.add_row(
            str(s["position"]),
            station(s["station_address"]),
            Text(_one_line(s["name"])),
            number(s["inputs_bits"], "bit", 0),
            number(s["outputs_bits"], "bit", 0),
            " ".join(s["mailbox_protocols"]) or "none",
            "no" if dc is None else ("ref" if dc["reference_clock"] else "yes"),
        )
    return table


def _identities_table(slaves: list[dict[str, Any]]) -> Any:
    from lolacli.text import hex32, station

    table = data_table("Slave identities")
    for col in ("#", "station", "vendor ID", "product code", "revision", "auto-inc"):
        table.add_column(col, justify="right" if col == "#" else "left")
    for s in slaves:
        table.add_row(
            str(s["position"]),
            station(s["station_address"]),
            hex32(s["vendor_id"]),
            hex32(s["product_code"]),
            hex32(s["revision"]),
            f"0x{s['auto_inc_address']:04X}",
        )
    return table


def _frame_table(frame: dict[str, Any], model: Any) -> Any:
    from lolacli.eni.report import datagram_where
    from lolacli.text import number

    table = data_table()
    for col in ("cmd", "address", "length", "expected WKC", "states"):
        table.add_column(col, justify="right" if col in ("length", "expected WKC") else "left")
    for d, c in zip(frame["datagrams"], model.commands, strict=True):
        wkc = "none" if d["expected_wkc"] is None else str(d["expected_wkc"])
        table.add_row(d["cmd"], datagram_where(c), number(d["length_bytes"], "B", 0), wkc,
                      ", ".join(d["states"]) or "any")
    return table


def _console() -> Any:
    from lolacli.cli.common import stdout_console

    return stdout_console()  # one width rule for every command group (cli/common.py)


class VarsFormat(StrEnum):
    human = "human"
    json = "json"
    csv = "csv"


@app.command("vars")
def vars_cmd(
    file: OptionalEni = None,
    filter_: Annotated[
        str | None,
        typer.Option("--filter", help="Glob on variable names, case-insensitive ('*Status*')."),
    ] = None,
    fmt: Annotated[
        VarsFormat,
        typer.Option(
            "--format",
            "-f",
            help="human (a table), json (lolacli.eni-vars/1) or csv: a header row, then a "
            "row per variable with the JSON's keys name, direction, bit_offset, byte_offset, "
            "bit_size, data_type, pdo_index, pdo_entry, slave_station_address, comment "
            "(empty where the ENI does not say).",
        ),
    ] = VarsFormat.human,
) -> None:
    """Process-image variables: direction, offset (byte.bit) and size, data type, the PDO
    entry (index:subindex) where the ENI gives it, and name. bit_offset counts from the
    start of the inputs or the outputs image; pdo_index is the PDO (0x1A00), pdo_entry
    its entry (0x6041:00), slave_station_address the slave whose PDO it is."""
    from lolacli.eni.report import vars_report

    report = vars_report(_load(file), filter_)
    if fmt is VarsFormat.json:
        emit_json(report)
    elif fmt is VarsFormat.csv:
        _emit_csv(report["variables"])
    else:
        _render_vars(report)


def _emit_csv(rows: list[dict[str, Any]]) -> None:
    import csv
    import sys

    from lolacli.cli.common import silence_stdout
    from lolacli.eni.report import VARS_FIELDS

    writer = csv.DictWriter(sys.stdout, fieldnames=VARS_FIELDS, lineterminator="\n")
    try:
        writer.writeheader()
        writer.writerows(rows)
        sys.stdout.flush()
    except BrokenPipeError:
        silence_stdout()


def _render_vars(report: dict[str, Any]) -> None:
    from rich.text import Text

    from lolacli.text import number, plural

    console = _console()
    title = plural(report["count"], "variable")
    if report["filter"]:
        title += f" matching {report['filter']}"
    table = data_table(title)
    columns = ("dir", "byte.bit", "size", "type", "PDO entry")
    rows = [
        (
            "in" if v["direction"] == "input" else "out",
            f"{v['bit_offset'] // 8}.{v['bit_offset'] % 8}",
            number(v["bit_size"], "bit", 0),
            v["data_type"] or "-",
            v["pdo_entry"] or "-",
        )
        for v in report["variables"]
    ]
    # the room a name has beside the narrowest other columns (two spaces between columns);
    # a name wider than that with no space in it wraps after a dot
    narrowest = [max(len(w) for cell in (col, *cells) for w in cell.split())
                 for col, *cells in zip(columns, *rows, strict=True)] if rows else []
    room = console.width - sum(narrowest) - 2 * len(columns)
    for col in (*columns, "name"):
        table.add_column(col, justify="right" if col in ("byte.bit", "size") else "left")
    for row, v in zip(rows, report["variables"], strict=True):
        table.add_row(*row, Text(break_long_words(_one_line(v["name"]), max(room, 20))))
    console.print(table)


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
    from lolacli.eni.validate import validate_eni, validate_report

    eni = _load(file)
    findings = validate_eni(eni)
    report = validate_report(eni, findings)
    if fmt is OutputFormat.json:
        emit_json(report)
    else:
        _render_findings(eni, findings, report)
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
        _render_diff(eni_a, eni_b, changes)
    if changes:
        raise typer.Exit(1)


def _render_findings(eni: Any, findings: Any, report: dict[str, Any]) -> None:
    """A paragraph per finding, its severity in colour; the slave by station address."""
    from rich.text import Text

    from lolacli.findings import Severity
    from lolacli.text import plural, station

    console = _console()
    for f in findings:
        style = "red" if f.severity is Severity.FAILURE else "yellow"
        line = Text(f.severity.value, style=style)
        line.append(f" {f.kind}")
        if f.slave is not None and 0 < f.slave <= len(eni.slaves):
            line.append(f" at {station(eni.slaves[f.slave - 1].station_address)}")
        line.append(f": {f.message}")
        say(console, line)
    say(console, f"{plural(report['errors'], 'error')}, {plural(report['warnings'], 'warning')}"
                 f" in {eni.source}")


_AREA_NOUNS = {
    "cycle_time": "cycle time",
    "slave": "slave",
    "cyclic": "cyclic command",
    "process_image": "process image",
    "variable": "variable",
}


def _render_diff(a: Any, b: Any, changes: Any) -> None:
    """The files, then each difference in words, a line per field, then the count."""
    from lolacli.eni.diff import AREAS
    from lolacli.text import plural

    console = _console()
    say(console, f"A is {a.source}")
    say(console, f"B is {b.source}")
    for change in changes:
        for line in change.describe():
            say(console, line)
    if not changes:
        say(console, "no differences")
        return
    counts = {area: sum(c.area == area for c in changes) for area in AREAS}
    parts = [plural(n, _AREA_NOUNS[area]) for area, n in counts.items() if n]
    say(console, f"{plural(len(changes), 'difference')}: {', '.join(parts)}")


# ------------------------------------------------------------------------- generate


def _esi_files(paths: list[Path]) -> list[Any]:
    """Every ESI given: a file, or each ``*.xml`` of a folder (files that are no ESI are
    skipped in a folder, an error when named)."""
    from lolacli.errors import EniError, InputError
    from lolacli.files import load_esi

    out = []
    for p in paths:
        if p.is_dir():
            for f in sorted(p.glob("*.xml")):
                try:
                    out.append(load_esi(f))
                except EniError:
                    continue
        elif p.exists():
            out.append(load_esi(p))
        else:
            raise InputError("no such file or folder", path=str(p))
    return out


def _write_atomically(path: Path, data: bytes) -> None:
    """``data`` to ``path`` through a temporary file beside it: never a half-written ENI."""
    import os
    import tempfile

    from lolacli.errors import InputError

    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except OSError as exc:
        raise InputError(f"cannot write: {exc.strerror or exc}", path=str(path)) from None
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


_GenOutput = Annotated[
    Path, typer.Option("--output", "-o", help="The ENI file to write.", show_default=False)
]
_GenEsi = Annotated[
    list[Path] | None,
    typer.Option("--esi", help="ESI file or folder of ESI files: slaves it describes take "
                 "their PDOs, sync managers and DC from it. Repeatable."),
]
_GenCycle = Annotated[
    str, typer.Option("--cycle-time", help="Cycle time written in the ENI (e.g. 1ms, 500us).")
]
_GenNoCoe = Annotated[
    bool, typer.Option("--no-coe", help="Take the PDOs from the SII, not from CoE "
                       "0x1C12/0x1C13.")
]


@app.command("generate")
def generate_cmd(
    iface: IfaceArgument,
    output: _GenOutput,
    esi: _GenEsi = None,
    cycle_time: _GenCycle = "1ms",
    no_coe: _GenNoCoe = False,
    frame_timeout: FrameTimeoutOption = "20ms",
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Scan the bus on IF and write its ENI (lolacli.eni-generate/1): identities and
    names from the SII; PDO assignment from an ESI where given, else over CoE (0x1C12/
    0x1C13 and the mapping objects, as SOEM reads them), else from the SII; sync managers,
    FMMUs, one logical image (one LRW with its expected working counter), InitCmds per
    transition, DC of the ESI. Station addresses 1001, 1002, … in line order. The slaves
    are left in INIT. Exit 0 when written, 3 for an unreadable ESI or an output that cannot
    be written, 4 when the bus does not answer."""
    from lolacli.eni.writer import write_eni
    from lolacli.master.generate import GenerateOptions, generate
    from lolacli.master.transport import RawSocketTransport

    cycle_ns = _positive_duration(cycle_time, "--cycle-time")
    timeout_ns = _positive_duration(frame_timeout, "--frame-timeout")
    from lolacli.files import check_output_file

    check_output_file(output, "-o", [("--esi", p) for p in esi or ()])
    _check_output(output)
    esi_files = _esi_files(list(esi or ()))
    options = GenerateOptions(cycle_time_ns=cycle_ns, frame_timeout_ns=timeout_ns,
                              coe=not no_coe)
    transport = RawSocketTransport(iface)
    try:
        result = generate(transport, esi=esi_files, options=options, where=iface)
    finally:
        transport.close()
    _write_atomically(output, write_eni(result.eni))
    doc = result.to_dict(str(output))
    if fmt is OutputFormat.json:
        emit_json(doc)
    else:
        _render_generate(doc)


def _positive_duration(raw: str, name: str) -> int:
    from lolacli.timing.model import parse_duration_ns

    value = parse_duration_ns(raw, None, name)
    if value <= 0:
        raise typer.BadParameter(f"{raw!r} is not a positive duration", param_hint=name)
    return value


def _check_output(output: Path) -> None:
    """InputError (exit 3) before the bus is touched when the ENI cannot go there."""
    from lolacli.errors import InputError

    folder = output.parent if str(output.parent) else Path(".")
    if output.is_dir():
        raise InputError("is a directory; give the ENI's file name", path=str(output))
    if not folder.is_dir():
        raise InputError("no such folder for the ENI", path=str(output))


def _render_generate(doc: dict[str, Any]) -> None:
    from lolacli.text import number, plural, station

    console = _console()
    table = data_table("Generated ENI")
    for column in ("#", "station", "name", "PDOs from", "in", "out"):
        table.add_column(column, justify="right" if column in ("#", "in", "out") else "left")
    for s in doc["slaves"]:
        table.add_row(
            str(s["position"]),
            station(s["station_address"]),
            _text(" ".join(s["name"].split())),
            s["pdo_source"] + (" DC" if s["dc"] else ""),
            number(s["inputs_bits"] / 8, "B", 0),
            number(s["outputs_bits"] / 8, "B", 0),
        )
    console.print(table)
    for s in doc["slaves"]:
        for note in s["notes"]:
            say(console, f"note: slave {s['position']}: {note}")
    pi = doc["process_image"]
    for frame in doc["cyclic_frames"]:
        cmds = ", ".join(
            f"{c['cmd']} {number(c['length_bytes'], 'B', 0)} WKC {c['expected_wkc']}"
            for c in frame["commands"]
        )
        say(console, f"cyclic frame: {cmds}")
    say(
        console,
        f"{plural(doc['slave_count'], 'slave')}; process image "
        f"{number(pi['inputs_bytes'], 'B', 0)} in, {number(pi['outputs_bytes'], 'B', 0)} out, "
        f"{plural(pi['variables'], 'variable')}; cycle time "
        f"{number(doc['cycle_time_us'], 'µs')}; written to {doc['output']}",
    )


def _text(value: str) -> Any:
    from rich.text import Text

    return Text(value)  # names are data, not rich markup
