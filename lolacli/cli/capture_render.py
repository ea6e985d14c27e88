"""Human output of ``capture analyze``: the verdict and its findings first, then the numbers
behind them, in tables and lines that read at 80 columns (the width rule of
:mod:`lolacli.cli.common`; lines of prose wrap between words). Renders the
``lolacli.capture/1`` document, so it shows exactly what the JSON says."""

from __future__ import annotations

from typing import Any

from lolacli.cli.plain import Table, fill, keep, write
from lolacli.text import number, plural, station

SDO_ROWS = 50
_SEVERITY = {"failure": "FAIL", "warning": "WARN", "info": "info"}
_STATS = ("count", "min", "mean", "median", "std", "p99", "max")
_RULES = {"mac": "by the source MAC", "packet_type": "by packet type (Linux cooked)",
          "packet_type+mac": "by packet type and source MAC", "inferred": "inferred"}
_CONFIGURED = ("FPRD", "FPWR", "FPRW", "FRMW")  # adp is a station address


class _Out:
    """The lines of the report, laid out at the width of human output."""

    def __init__(self) -> None:
        from lolacli.cli.common import text_width

        self.width = text_width()
        self.lines: list[str] = []

    def say(self, text: str) -> None:
        """A line of prose, wrapped between words."""
        self.lines += fill(text, self.width)

    def table(self, table: Table) -> None:
        """A table, after a blank line."""
        self.lines += ["", *table.lines(self.width)]


def render_analysis(d: dict[str, Any], show_all: bool = False) -> None:
    out = _Out()
    out.lines.append(d["file"])  # whole, however long
    out.say(f"{d['format']}, {number(d['time_span_us'] / 1e6, 's')}, "
            f"{plural(d['frames_total'], 'packet')}, engine {d['engine']}; direction "
            f"{_RULES.get(d['direction_rule'], d['direction_rule'])}")
    _verdict(out, d)
    _frames(out, d)
    _timing(out, d)
    _wkc(out, d)
    _al_status(out, d)
    out.say("Datagrams by command: " + (", ".join(
        f"{k} {v:,}" for k, v in d["datagrams_by_cmd"].items()) or "none"))
    _dc(out, d["dc"])
    _sdo(out, d, show_all)
    write(out.lines)


def _station(address: int) -> str:
    """A station address, never broken across lines."""
    return keep(station(address))


def _verdict(out: _Out, d: dict[str, Any]) -> None:
    from lolacli.cli.verdict import verdict_lines

    note = ", of the part read before the stop" if d.get("interrupted") else ""
    out.lines += verdict_lines(d["verdict"], d["findings"], note, min(out.width, 80))


def _frames(out: _Out, d: dict[str, Any]) -> None:
    rows = [
        ("EtherCAT frames", d["ecat_frames"], "other packets", d["non_ecat_frames"]),
        ("outgoing", d["outgoing_frames"], "returned", d["returned_frames"]),
        ("pairs", d["pairs"], "unmatched out", d["unmatched_outgoing"]),
        ("lost", d["lost_frames"], "late", d["late_frames"]),
        ("in flight at end", d["in_flight_at_end"], "malformed", d["malformed_frames"]),
    ]
    grid = Table("Frames", header=False)
    for right in (False, True, False, True):
        grid.add_column(right=right)
    for a, x, b, y in rows:
        grid.add_row(a, f"{x:,}", b, f"{y:,}")
    out.table(grid)
    out.say(f"A frame unanswered for {number(d['timeout_us'], 'µs', 2)} "
            f"({d['timeout_source']}) is lost, or late when its answer comes later.")


def _timing(out: _Out, d: dict[str, Any]) -> None:
    table = Table(f"Timing (µs), cyclic stream: {d['cyclic_stream']}")
    table.add_column("")
    for col in _STATS:
        table.add_column(col, right=True)
    for label, key in (("round trip", "round_trip_us"), ("cyclic round trip",
                       "round_trip_cyclic_us"), ("cycle period", "cycle_period_us")):
        s = d[key]
        cells = ["—"] * 7 if s is None else [f"{s['count']:,}"] + [
            _us(s[k]) for k in _STATS[1:]]
        table.add_row(label + (" (unusable)" if key in d["unusable_stats"] else ""), *cells)
    out.table(table)
    if d["unusable_stats"]:
        out.say("unusable: built on quantised or backward timestamps (see findings)")
    if d["cycle_jitter_us"] and "cycle_period_us" not in d["unusable_stats"]:
        j = d["cycle_jitter_us"]
        out.say(f"cycle jitter: std {number(j['std'], 'µs', 2)}, max deviation from "
                f"median {number(j['max_deviation'], 'µs', 2)}")


def _us(value: float) -> str:
    """Two decimals below 1 ms, one below 10 ms, none above, thousands grouped as
    everywhere: a row of seven fits 80 columns whatever the cycle (numbers are rounded,
    never cut)."""
    digits = 2 if abs(value) < 1000 else 1 if abs(value) < 10_000 else 0
    return f"{value:,.{digits}f}"


def _datagram(g: dict[str, Any]) -> str:
    """``LRW 0x00010000 780 B``, ``FPRD 0x0130 of 0x03E9 (1001) 2 B``, ``BRD 0x0130 2 B``."""
    if g["logical_address"] is not None:
        where = f"0x{g['logical_address']:08X}"
    elif g["adp"] and g["cmd"] in _CONFIGURED:
        where = f"0x{g['ado']:04X} of {_station(g['adp'])}"
    elif g["adp"]:
        where = f"0x{g['adp']:04X}:0x{g['ado']:04X}"
    else:
        where = f"0x{g['ado']:04X}"
    return f"{g['cmd']} {where} {keep(str(g['length_bytes']) + ' B')}"


def _wkc(out: _Out, d: dict[str, Any]) -> None:
    w = d["wkc"]
    checked = (f"{plural(d['wkc_checked'], 'return')} checked, "
               f"{plural(d['wkc_mismatches'], 'mismatch', 'mismatches')}")
    if not w["datagrams"]:
        out.say(f"WKC (reference: {d['wkc_reference']}; {checked}): no cyclic "
                "datagram came back")
        return
    table = Table(f"WKC per cyclic datagram (reference: {d['wkc_reference']}; {checked})")
    for col, right in (("datagram", False), ("expected", True), ("from", False),
                       ("returns", True), ("bad", True), ("seen (WKC ×count)", False)):
        table.add_column(col, right=right)
    for g in w["datagrams"]:
        seen = ", ".join(f"{o['wkc']}×{o['count']:,}" for o in g["observed"])
        table.add_row(_datagram(g), "?" if g["expected"] is None else str(g["expected"]),
                      g["basis"] or "cannot tell", f"{g['returns']:,}", f"{g['mismatches']:,}",
                      seen)
    out.table(table)


def _al_status(out: _Out, d: dict[str, Any]) -> None:
    reads = d["al_status"]
    if not reads:
        return
    by_state: dict[str, list[str]] = {}
    for r in reads:
        who = "BRD" if r["station"] is None else _station(r["station"])
        by_state.setdefault(r["state"], []).append(who)
    parts = []
    for state, names in by_state.items():
        shown = ", ".join(names[:8]) + (f" and {len(names) - 8} more" if len(names) > 8 else "")
        parts.append(f"{state}: {shown}")
    out.say("AL status, last read per slave — " + "; ".join(parts))


def _dc(out: _Out, dc: dict[str, Any]) -> None:
    reads = dc["system_time_difference_reads"]
    text = (f"DC: {plural(dc['drift_compensation_datagrams'], 'drift-compensation datagram')}"
            f" in {plural(dc['drift_compensation_bursts'], 'burst')}; ")
    if reads:
        text += (f"{plural(reads, 'read')} of the system time difference (0x092C), largest "
                 f"{number(dc['system_time_difference_max_abs_ns'], 'ns')}")
    else:
        text += "no read of the system time difference (0x092C)"
    out.say(text)


def _sdo(out: _Out, d: dict[str, Any], show_all: bool) -> None:
    transactions = d["sdo_transaction_list"]
    aborts = d["sdo_aborts"]
    if not transactions:
        out.say(f"SDO: none ({plural(d['mailbox']['messages'], 'mailbox message')})")
        return
    table = Table(f"SDO transactions ({d['sdo_transactions']}, "
                   f"{plural(len(aborts), 'abort')})")
    for col in ("slave", "object", "kind", "transfer", "bytes", "status", "frames", "µs"):
        table.add_column(col, right=col in ("bytes", "µs"))
    shown = transactions if show_all else transactions[:SDO_ROWS]
    last = None
    for t in shown:
        status = t["status"]  # (an abort's code and text follow the table)
        dur = "" if t["duration_us"] is None else f"{t['duration_us']:.0f}"
        end = "" if t["end_frame"] is None else t["end_frame"]  # (open: no answer yet)
        # the slave once per run of its transactions
        who = "" if t["slave"] == last else _station(t["slave"])
        last = t["slave"]
        table.add_row(who, t["object"], t["kind"], t["transfer"], f"{t['size_bytes']:,}",
                      status, f"{t['start_frame']}–{end}", dur)
    out.table(table)
    if len(shown) < len(transactions):
        out.say(f"… {len(transactions) - len(shown)} more, --all to show")
    for a in aborts:
        out.say(f"SDO abort: slave {_station(a['slave'])} 0x{a['index']:04X}:"
                f"{a['subindex']:02X} {a['code_hex']} {a['text']} (frame {a['frame']})")
