"""`bus graph`: the topology from an ENI, from a scan of the emulated chain (in process),
and over veth; DOT, SVG, the tree, lolacli.graph/1."""

from __future__ import annotations

import dataclasses
import json
import shutil
import subprocess
import xml.etree.ElementTree as ET

import pytest
from typer.testing import CliRunner

from lolacli.cli.main import app
from lolacli.files import load_eni
from lolacli.master import topology
from lolacli.master.scan import scan
from lolacli.simulate import VirtualBus
from tests.live import LOLA

runner = CliRunner()


@pytest.fixture(scope="module")
def lola():
    return load_eni(LOLA)


def _dot_edges(dot: str) -> list[tuple[str, str]]:
    import re

    return re.findall(r"^\s+(\w+) -> (\w+) \[", dot, re.M)


def test_lola_eni_is_a_line_of_25_nodes_and_24_links(lola) -> None:
    g = topology.from_eni(lola)
    assert len(g.nodes) == 25 and len(g.links) == 24 and g.branches() == 0
    for k in g.links:  # each <PreviousPort> of the LOLA ENI: port B of the one before
        assert (k.source, k.source_port, k.target_port) == (k.target - 1, 1, 0)
    assert [n.name for n in g.nodes] == [s.name for s in lola.slaves]


def test_scan_of_the_emulated_chain_agrees_with_the_eni(lola) -> None:
    report = scan(VirtualBus(lola).transport)
    g = topology.from_scan(report.slaves, "emulated")
    e = topology.from_eni(lola)
    assert [k.to_dict() for k in g.links] == [k.to_dict() for k in e.links]
    assert [n.name for n in g.nodes] == [s.name for s in lola.slaves] and not g.notes
    last = g.nodes[-1]
    assert last.ports[0].open and not last.ports[1].open  # the end of the line


def test_a_branch_in_the_eni_is_drawn_indented(lola) -> None:
    # slave 5 hangs off port D (3) of slave 2 instead of port B of slave 4
    s2 = lola.slaves[1]
    slaves = list(lola.slaves)
    slaves[4] = dataclasses.replace(
        slaves[4], previous_port="D", previous_station_address=s2.station_address
    )
    g = topology.from_eni(dataclasses.replace(lola, slaves=tuple(slaves)))
    assert g.branches() == 1 and len(g.links) == 24
    assert topology.Link(2, 3, 5) in g.links
    lines = topology.text_lines(g, 80)
    branch = next(line for line in lines if line.lstrip().startswith("2:3 -> 5 "))
    assert branch.startswith("  ") and all(len(x) <= 80 for x in lines)


def test_scan_with_a_junction_gives_its_ports_in_forwarding_order() -> None:
    from lolacli.master.scan import ScannedSlave, assign_parents

    # DL status: link on port p is bit 4+p, loop closed 8+2p, communication 9+2p
    def dl(*open_ports: int) -> int:
        v = 0
        for p in range(4):
            v |= (1 << (9 + 2 * p)) | (1 << (4 + p)) if p in open_ports else 1 << (8 + 2 * p)
        return v

    mii = 0xFF  # four MII ports
    slaves = [
        ScannedSlave(1, dl_status=dl(0, 1, 3), port_descriptor=mii),  # a junction
        ScannedSlave(2, dl_status=dl(0), port_descriptor=mii),  # end of port 3
        ScannedSlave(3, dl_status=dl(0), port_descriptor=mii),
    ]  # end of port 1
    assign_parents(slaves)
    g = topology.from_scan(slaves)
    assert [(k.source, k.source_port, k.target) for k in g.links] == [(1, 3, 2), (1, 1, 3)]
    assert g.branches() == 1 and not g.notes


def test_cli_tree_json_dot_svg(tmp_path) -> None:
    r = runner.invoke(app, ["bus", "graph"], env={"COLUMNS": "80"})
    assert r.exit_code == 0, r.output
    lines = r.stdout.splitlines()
    assert max(map(len, lines)) <= 80 and "25 slaves, 24 links" in lines[0]
    r = runner.invoke(app, ["bus", "graph", "--eni", str(LOLA), "-f", "json"])
    doc = json.loads(r.stdout)
    assert doc["schema"] == "lolacli.graph/1"
    assert len(doc["nodes"]) == 25 and len(doc["links"]) == 24
    assert {"from", "from_port", "to", "to_port"} <= set(doc["links"][0])
    dot_file, svg_file = tmp_path / "topo.dot", tmp_path / "topo.svg"
    assert runner.invoke(app, ["bus", "graph", "-o", str(dot_file)]).exit_code == 0
    dot = dot_file.read_text()
    edges = _dot_edges(dot)
    assert ("master", "slave1") in edges and len(edges) == 25
    assert dot.count("{") == dot.count("}") == 1
    if shutil.which("dot"):
        done = subprocess.run(["dot", "-Tplain"], input=dot, text=True, capture_output=True)
        assert done.returncode == 0, done.stderr
    assert runner.invoke(app, ["bus", "graph", "-o", str(svg_file)]).exit_code == 0
    svg = ET.parse(svg_file).getroot()  # well-formed XML
    assert svg.tag.endswith("svg")
    if not shutil.which("dot"):
        groups = [g for g in svg.iter() if g.get("id", "").startswith("slave")]
        assert len(groups) == 25


@pytest.mark.parametrize(
    ("args", "code", "words"),
    [
        (["-o", "/nonexistent-dir/topo.dot"], 2, "cannot write"),
        (["-o", "topo.png"], 2, ".svg or a .dot"),
        (["--iface", "lo", "--eni", str(LOLA)], 2, "give one of them"),
        (["--eni", "/nonexistent.xml"], 3, "nonexistent.xml"),
    ],
)
def test_bad_inputs_are_one_line(args: list[str], code: int, words: str) -> None:
    r = runner.invoke(app, ["bus", "graph", *args])
    assert r.exit_code == code, r.output
    assert words in r.stderr and len(r.stderr.strip().splitlines()) == 1


@pytest.mark.root
@pytest.mark.slow
def test_graph_of_a_live_bus_over_veth(lola) -> None:
    from tests.live import make_bus, remove_bus, run_json, start_emulator, stop_emulator

    bus = make_bus("g")
    try:
        proc = start_emulator(bus)
        try:
            code, doc, err = run_json("bus", "graph", "--iface", bus.master, bus=bus,
                                      timeout=180)  # fmt: skip
        finally:
            stop_emulator(proc)
    finally:
        remove_bus(bus)
    assert code == 0, err
    assert doc["source"] == "scan" and len(doc["nodes"]) == 25 and len(doc["links"]) == 24
    expected = topology.from_eni(lola).to_dict()["links"]
    assert doc["links"] == expected
    assert [n["name"] for n in doc["nodes"]] == [s.name for s in lola.slaves]
