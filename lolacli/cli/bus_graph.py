"""`lolacli bus graph`: the line and its branches (:mod:`lolacli.master.topology`)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from lolacli.cli.bus import app
from lolacli.cli.common import FormatOption, OutputFormat, emit_json
from lolacli.cli.options import IfaceOption

if TYPE_CHECKING:
    from lolacli.master.topology import Graph

FORMATS = {".svg": "svg", ".dot": "dot", ".gv": "dot"}


@app.command("graph")
def graph_cmd(
    iface: IfaceOption = None,
    eni: Annotated[
        Path | None,
        typer.Option(
            "--eni",
            help="Draw the topology this ENI describes (default without "
            "--iface: the embedded LOLA chain).",
        ),
    ] = None,  # fmt: skip
    output: Annotated[
        Path | None,
        typer.Option(
            "--output",
            "-o",
            metavar="FILE",
            help="Write the graph: FILE.svg (Graphviz `dot` if installed, else "
            "drawn here) or FILE.dot (Graphviz DOT).",
        ),
    ] = None,  # fmt: skip
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Draw the bus's topology, like `ethercat graph`: slaves named, each link with the
    ports it joins, open ends marked. --iface IF scans the live bus (ports from DL status
    0x0110 and the port descriptor 0x0007, branches from the open ports); --eni F (or
    neither: the embedded LOLA chain) draws the ENI's slaves in order, joined as its
    <PreviousPort> says. Without -o an indented tree in the terminal; lolacli.graph/1
    with --format json. Exit 2 for both --iface and --eni or an -o it cannot write, 3
    for a bad ENI, 4 when nothing answers."""
    from lolacli.errors import UsageError

    if iface is not None and eni is not None:
        raise UsageError("--iface scans the bus, --eni draws an ENI: give one of them")
    kind = None
    if output is not None:
        kind = FORMATS.get(output.suffix.lower())
        if kind is None:
            raise UsageError(f"-o {output}: write a .svg or a .dot file")
    graph = _graph(iface, eni)
    if output is not None:
        assert kind is not None
        _write(graph, output, kind)
    if fmt is OutputFormat.json:
        doc = graph.to_dict()
        doc["output"] = str(output) if output is not None else None
        emit_json(doc)
    elif output is None:
        _render(graph)
    else:
        from lolacli.cli.common import say, stdout_console
        from lolacli.text import plural

        say(stdout_console(), f"wrote {output}: {plural(len(graph.nodes), 'slave')}, "
                              f"{plural(len(graph.links), 'link')}, "
                              f"{plural(graph.branches(), 'branch', 'branches')}")  # fmt: skip


def _graph(iface: str | None, eni: Path | None) -> Graph:
    from lolacli.master import topology

    if iface is None:
        from lolacli.cli.common import default_eni
        from lolacli.files import load_eni

        return topology.from_eni(load_eni(eni or default_eni()))
    from lolacli.master.scan import ScanOptions, scan
    from lolacli.master.transport import RawSocketTransport

    transport = RawSocketTransport(iface)
    try:
        report = scan(transport, options=ScanOptions(), iface=iface)
    finally:
        transport.close()
    return topology.from_scan(report.slaves, iface)


def _write(graph: Graph, output: Path, kind: str) -> None:
    from lolacli.errors import UsageError
    from lolacli.master import topology

    dot = topology.to_dot(graph)
    if kind == "dot":
        text = dot
    elif shutil.which("dot"):
        done = subprocess.run(["dot", "-Tsvg"], input=dot, capture_output=True, text=True,
                              timeout=60, check=False)  # fmt: skip
        text = done.stdout if done.returncode == 0 else topology.to_svg(graph)
    else:
        text = topology.to_svg(graph)
    try:
        output.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise UsageError(f"-o {output}: cannot write it ({exc.strerror})") from None


def _render(graph: Graph) -> None:
    from lolacli.cli.common import say, stdout_console
    from lolacli.master import topology
    from lolacli.text import plural

    console = stdout_console()
    g = graph
    source = f"scan of {g.where}" if g.source == "scan" else f"ENI {Path(g.where).name}"
    say(console, f"{plural(len(g.nodes), 'slave')}, {plural(len(g.links), 'link')}, "
                 f"{plural(g.branches(), 'branch', 'branches')} ({source}); "
                 "each line: from slave:port -> slave")  # fmt: skip
    width = min(console.width, 80)
    for line in topology.text_lines(g, width):
        console.print(line, highlight=False, soft_wrap=True)
    for note in g.notes:
        say(console, f"note: {note}")
