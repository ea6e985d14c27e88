"""The bus's topology as a graph (`bus graph`, like IgH's ``ethercat graph``).

Two sources:

* a scan (:func:`from_scan`): each slave's ports from DL status 0x0110 and the port
  descriptor 0x0007 (:func:`lolacli.master.scan.decode_ports`), the slave each one hangs
  off from the count of open ports (:func:`lolacli.master.scan.assign_parents`, SOEM's
  rule). A frame enters a slave on port 0 and leaves through its open ports in the
  processing order 3, 1, 2 (ETG.1000.4 §3.5): the children of a slave, in line order,
  take its open ports in that order;
* an ENI (:func:`from_eni`): the slaves in order, each one's ``<PreviousPort>`` (the port
  letter A-D of the slave named by its station address) where the ENI has it, else the
  line (port 1 of the previous slave).

A node is a slave (position, name, station address, each port: its physical layer and
whether it is open, linked, or in use); a link joins a port of one slave to port 0 of the
next; the master is not a node (``master_link`` says which slave it feeds). Renderers:
:func:`to_dot` (Graphviz), :func:`to_svg` (hand-written boxes: the line left to right,
a branch on a row of its own below), :func:`text_lines` (an indented tree).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from html import escape
from typing import Any

from lolacli.eni.model import Eni
from lolacli.master.scan import ScannedSlave
from lolacli.text import station

SCHEMA = "lolacli.graph/1"
#: a frame leaves a slave through its ports in this order after entering on port 0
FORWARD_ORDER = (3, 1, 2)
PORT_LETTERS = "ABCD"


@dataclass(slots=True)
class GraphPort:
    port: int
    physical: str | None = None  # "MII", "EBUS", … (a scan); None: the ENI does not say
    link: bool | None = None
    open: bool | None = None  # a frame leaves and comes back through it (a scan)
    used: bool = False  # a link of the graph uses it

    @property
    def dangling(self) -> bool:
        """Open (or linked) but nothing on the graph behind it: an open end of the line."""
        return bool(self.open) and not self.used and self.port != 0

    def to_dict(self) -> dict[str, Any]:
        return {"port": self.port, "physical": self.physical, "link": self.link,
                "open": self.open, "used": self.used, "dangling": self.dangling}  # fmt: skip


@dataclass(slots=True)
class Node:
    position: int
    name: str
    station_address: int
    parent: int = 0  # 0: the master
    ports: list[GraphPort] = field(default_factory=list)

    def port(self, p: int) -> GraphPort:
        return self.ports[p]

    def to_dict(self) -> dict[str, Any]:
        return {
            "id": f"slave{self.position}",
            "position": self.position,
            "name": self.name,
            "station_address": self.station_address,
            "parent": self.parent,
            "ports": [p.to_dict() for p in self.ports],
        }


@dataclass(frozen=True, slots=True)
class Link:
    source: int  # position
    source_port: int
    target: int
    target_port: int = 0

    def to_dict(self) -> dict[str, Any]:
        return {"from": self.source, "from_port": self.source_port,
                "to": self.target, "to_port": self.target_port}  # fmt: skip


@dataclass(slots=True)
class Graph:
    source: str  # "scan" or "eni"
    where: str  # the interface or the ENI's path
    nodes: list[Node]
    links: list[Link]
    notes: list[str] = field(default_factory=list)

    @property
    def master_link(self) -> int | None:
        return self.nodes[0].position if self.nodes else None

    def children(self, position: int) -> list[tuple[Link, Node]]:
        by_pos = {n.position: n for n in self.nodes}
        return [(k, by_pos[k.target]) for k in self.links if k.source == position]

    def branches(self) -> int:
        """Slaves with more than one link out."""
        out: dict[int, int] = {}
        for k in self.links:
            out[k.source] = out.get(k.source, 0) + 1
        return sum(1 for n in out.values() if n > 1)

    def to_dict(self) -> dict[str, Any]:
        return {
            "schema": SCHEMA,
            "source": self.source,
            "where": self.where,
            "master_link": {"to": self.master_link, "to_port": 0} if self.nodes else None,
            "nodes": [n.to_dict() for n in self.nodes],
            "links": [k.to_dict() for k in self.links],
            "branches": self.branches(),
            "notes": self.notes,
        }


# ---------------------------------------------------------------------------- building
def from_scan(slaves: Sequence[ScannedSlave], where: str = "") -> Graph:
    """The graph of a scan (parents already assigned; see the module docstring)."""
    nodes = []
    for s in slaves:
        ports = [GraphPort(p.port, p.physical, p.link, p.open) for p in s.ports]
        nodes.append(Node(s.position, s.name or "", s.station_address, s.parent, ports))
    by_pos = {n.position: n for n in nodes}
    links: list[Link] = []
    notes: list[str] = []
    if nodes:
        nodes[0].ports[0].used = True
    for n in nodes[1:]:
        parent = by_pos.get(n.parent)
        if parent is None:
            continue
        free = [p for p in FORWARD_ORDER if parent.port(p).open and not parent.port(p).used]
        if not free:  # the counts do not add up (a port reads closed): take the next one
            free = [p for p in FORWARD_ORDER if not parent.port(p).used]
            notes.append(f"slave {n.position}: no open port left on slave {parent.position} "
                         f"for it; drawn on port {free[0] if free else 1}")  # fmt: skip
        port = free[0] if free else 1
        if port < len(parent.ports):
            parent.port(port).used = True
        n.ports[0].used = True
        links.append(Link(parent.position, port, n.position))
    return Graph("scan", where, nodes, links, notes)


def from_eni(eni: Eni) -> Graph:
    """The graph an ENI describes (see the module docstring)."""
    nodes = [Node(s.position, s.name, s.station_address, 0,
                  [GraphPort(p) for p in range(4)]) for s in eni.slaves]  # fmt: skip
    by_station = {s.station_address: s.position for s in eni.slaves}
    links: list[Link] = []
    notes: list[str] = []
    with_ports = sum(s.previous_port is not None for s in eni.slaves[1:])
    if len(eni.slaves) > 1 and with_ports == 0:
        notes.append("the ENI has no <PreviousPort>: drawn as a line (port 1 to port 0)")
    if nodes:
        nodes[0].ports[0].used = True
    for i, s in enumerate(eni.slaves[1:], start=1):
        parent = by_station.get(s.previous_station_address or -1)
        letter = (s.previous_port or "").strip().upper()
        port = PORT_LETTERS.index(letter) if len(letter) == 1 and letter in PORT_LETTERS else 1
        if parent is None or parent >= s.position:
            if s.previous_port is not None:
                notes.append(f"slave {s.position}: <PreviousPort> names station "
                             f"{s.previous_station_address}, not a slave before it; drawn "
                             "after the previous slave")  # fmt: skip
            parent = eni.slaves[i - 1].position
        node = nodes[i]
        node.parent = parent
        node.ports[0].used = True
        nodes[parent - 1].ports[port].used = True
        links.append(Link(parent, port, s.position))
    return Graph("eni", eni.source or "", nodes, links, notes)


# ---------------------------------------------------------------------------- rendering
def _label(n: Node) -> str:
    return f"{n.position}: {n.name}" if n.name else f"slave {n.position}"


def _dot_text(text: str) -> str:
    return text.replace("\\", "\\\\").replace('"', '\\"')


def to_dot(graph: Graph) -> str:
    """Graphviz DOT, as ``ethercat graph`` writes it: the master, a box a slave (name,
    station address), an edge a link labelled with its ports; open ends marked."""
    out = ["digraph lolacli_topology {", "  rankdir=TB;", '  node [fontname="Helvetica"];',
           '  edge [fontname="Helvetica", fontsize=9, arrowhead=none];',
           '  master [shape=doublecircle, label="EtherCAT\\nmaster"];']  # fmt: skip
    for n in graph.nodes:
        ports = "  ".join(
            f"{p.port}{'*' if p.dangling else ''}" for p in n.ports if p.used or p.dangling
        )
        label = f"{_dot_text(_label(n))}\\n0x{n.station_address:04X}\\nports {ports}"
        out.append(f'  slave{n.position} [shape=box, label="{label}"];')
        for p in n.ports:
            if p.dangling:
                out.append(f'  open{n.position}_{p.port} [shape=plaintext, label="open"];')
                out.append(f'  slave{n.position} -> open{n.position}_{p.port} '
                           f'[taillabel="{p.port}", style=dashed];')  # fmt: skip
    if graph.nodes:
        out.append(f'  master -> slave{graph.nodes[0].position} [headlabel="0"];')
    for k in graph.links:
        out.append(f'  slave{k.source} -> slave{k.target} '
                   f'[taillabel="{k.source_port}", headlabel="{k.target_port}"];')  # fmt: skip
    out.append("}")
    return "\n".join(out) + "\n"


def _rows(graph: Graph) -> list[tuple[Node, int, Link | None]]:
    """Each node with its depth (branches taken to reach it) in tree order."""
    out: list[tuple[Node, int, Link | None]] = []
    if not graph.nodes:
        return out
    kids: dict[int, list[tuple[Link, Node]]] = {}
    by_pos = {n.position: n for n in graph.nodes}
    for k in graph.links:
        kids.setdefault(k.source, []).append((k, by_pos[k.target]))
    stack: list[tuple[Node, int, Link | None]] = [(graph.nodes[0], 0, None)]
    while stack:
        node, depth, link = stack.pop()
        out.append((node, depth, link))
        children = kids.get(node.position, [])
        # the first child continues the line at this depth; later ones are branches
        for j in range(len(children) - 1, -1, -1):
            k, child = children[j]
            stack.append((child, depth + (1 if j else 0), k))
    return out


def text_lines(graph: Graph, width: int = 80) -> list[str]:
    """The tree as lines of at most ``width`` characters: one a slave, the line going on
    at the same indent, each branch indented two more."""
    lines = ["master"]
    for node, depth, link in _rows(graph):
        indent = "  " * min(depth, 10)
        via = f"{link.source}:{link.source_port}" if link is not None else "master"
        ends = [str(p.port) for p in node.ports if p.dangling]
        at = f"  {station(node.station_address)}" if node.station_address else ""
        tail = at + (f"  open: port {', '.join(ends)}"
                                                    if ends else "")  # fmt: skip
        head = f"{indent}{via} -> {node.position} "
        room = max(width - len(head) - len(tail), 8)
        name = node.name or f"slave {node.position}"
        if len(name) > room:
            name = name[: room - 1] + "…"
        lines.append(f"{head}{name}{tail}"[:width])
    return lines


# SVG: a box a slave; the line runs left to right and wraps; a branch starts a new row
_BOX_W, _BOX_H, _GAP_X, _GAP_Y, _PER_ROW = 150, 46, 30, 34, 6


def to_svg(graph: Graph) -> str:
    """A hand-written SVG of the tree (no Graphviz needed)."""
    places: dict[int, tuple[float, float]] = {}
    row, col, last_depth = 0, 0, -1
    for node, depth, link in _rows(graph):
        branch = link is not None and depth != last_depth
        if places and (branch or col >= _PER_ROW):
            row, col = row + 1, 0
        if col == 0:
            col = min(depth, 3)  # a branch's row starts indented
        places[node.position] = (20 + (col + 1) * (_BOX_W + _GAP_X),
                                 20 + row * (_BOX_H + _GAP_Y))  # fmt: skip
        col += 1
        last_depth = depth
    width = 40 + (_PER_ROW + 4) * (_BOX_W + _GAP_X)
    height = 40 + (row + 1) * (_BOX_H + _GAP_Y)
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
           f'font-family="Helvetica, Arial, sans-serif" font-size="11">',
           '<rect x="20" y="20" width="150" height="46" rx="23" fill="#eee" stroke="#333"/>',
           '<text x="95" y="47" text-anchor="middle">EtherCAT master</text>']  # fmt: skip

    def edge(x1: float, y1: float, x2: float, y2: float, a: str, b: str) -> None:
        out.append(f'<line x1="{x1}" y1="{y1}" x2="{x2}" y2="{y2}" stroke="#333"/>')
        out.append(f'<text x="{x1 + 3}" y="{y1 - 3}" font-size="9">{a}</text>')
        out.append(f'<text x="{x2 - 9}" y="{y2 - 3}" font-size="9">{b}</text>')

    if graph.nodes:
        x, y = places[graph.nodes[0].position]
        edge(170, 43, x, y + _BOX_H / 2, "", "0")
    for k in graph.links:
        x1, y1 = places[k.source]
        x2, y2 = places[k.target]
        if y1 == y2:
            edge(x1 + _BOX_W, y1 + _BOX_H / 2, x2, y2 + _BOX_H / 2, str(k.source_port),
                 str(k.target_port))  # fmt: skip
        else:
            edge(x1 + _BOX_W / 2, y1 + _BOX_H, x2, y2 + _BOX_H / 2, str(k.source_port),
                 str(k.target_port))  # fmt: skip
    for n in graph.nodes:
        x, y = places[n.position]
        name = n.name if len(n.name) <= 24 else n.name[:23] + "…"
        out.append(f'<g id="slave{n.position}"><rect x="{x}" y="{y}" width="{_BOX_W}" '
                   f'height="{_BOX_H}" fill="#fff" stroke="#333"/>')  # fmt: skip
        out.append(f'<text x="{x + 6}" y="{y + 18}">{n.position}: {escape(name)}</text>')
        out.append(f'<text x="{x + 6}" y="{y + 36}" fill="#555">0x{n.station_address:04X}'
                   '</text>')  # fmt: skip
        for p in n.ports:
            if p.dangling:
                out.append(f'<text x="{x + _BOX_W - 60}" y="{y + 36}" fill="#b00">'
                           f"open port {p.port}</text>")  # fmt: skip
        out.append("</g>")
    out.append("</svg>")
    return "\n".join(out) + "\n"


__all__ = [
    "SCHEMA",
    "Graph",
    "GraphPort",
    "Link",
    "Node",
    "from_eni",
    "from_scan",
    "text_lines",
    "to_dot",
    "to_svg",
]
