"""Human output of ``capture analyze``: the verdict and its findings first, then the numbers
behind them, in tables and lines that read at 80 columns (the width rule of
:mod:`lolacli.cli.common`; lines of prose wrap between words). Renders the
``lolacli.capture/1`` document, so it shows exactly what the JSON says."""

from __future__ import annotations

from typing import Any

from lolacli.text import number, plural, station

SDO_ROWS = 50
_SEVERITY = {"failure": "FAIL", "warning": "WARN", "info": "info"}
_STATS = ("count", "min", "mean", "median", "std", "p99", "max")
_RULES = {"mac": "by the source MAC", "packet_type": "by packet type (Linux cooked)",
          "packet_type+mac": "by packet type and source MAC", "inferred": "inferred"}
_CONFIGURED = ("FPRD", "FPWR", "FPRW", "FRMW")  # adp is a station address


def _table(**kwargs: Any) -> Any:
    from rich import box
    from rich.table import Table

    return Table(box=box.SIMPLE_HEAD, title_justify="left", **kwargs)


def _grid() -> Any:
    from rich.table import Table

    return Table.grid(padding=(0, 1))


def _text(text: str) -> Any:
    """Plain text for rich: no markup (a message may hold brackets)."""
    from rich.text import Text

    return Text(text)


def _say(console: Any, text: str) -> None:
    """A line of prose, wrapped between words at the console's width."""
    console.print(_text(text), soft_wrap=False)


def render_analysis(d: dict[str, Any], show_all: bool = False) -> None:
    from lolacli.cli.common import stdout_console

    console = stdout_console()
    console.print(_text(d["file"]))  # whole, however long (soft wrap)
    _say(console,
         f"{d['format']}, {number(d['time_span_us'] / 1e6, 's')}, "
         f"{plural(d['frames_total'], 'packet')}, engine {d['engine']}; direction "
         f"{_RULES.get(d['direction_rule'], d['direction_rule'])}")
    _verdict(console, d)
    _frames(console, d)
    _timing(console, d)
    _wkc(console, d)
    _al_status(console, d)
    _say(console, "Datagrams by command: " + (", ".join(
        f"{k} {v}" for k, v in d["datagrams_by_cmd"].items()) or "none"))
    _dc(console, d["dc"])
    _sdo(console, d, show_all)


def _verdict(console: Any, d: dict[str, Any]) -> None:
    from lolacli.cli.verdict import render_verdict

    note = ", of the part read before the stop" if d.get("interrupted") else ""
    render_verdict(console, d["verdict"], d["findings"], note)


def _frames(console: Any, d: dict[str, Any]) -> None:
    rows = [
        ("EtherCAT frames", d["ecat_frames"], "other packets", d["non_ecat_frames"]),
        ("outgoing", d["outgoing_frames"], "returned", d["returned_frames"]),
        ("pairs", d["pairs"], "unmatched out", d["unmatched_outgoing"]),
        ("lost", d["lost_frames"], "late", d["late_frames"]),
        ("in flight at end", d["in_flight_at_end"], "malformed", d["malformed_frames"]),
    ]
    grid = _table(title="Frames", show_header=False)
    for justify in ("left", "right", "left", "right"):
        grid.add_column(justify=justify)
    for a, x, b, y in rows:
        grid.add_row(a, str(x), b, str(y))
    console.print(grid)
    _say(console, f"A frame unanswered for {number(d['timeout_us'], 'µs', 2)} "
                  f"({d['timeout_source']}) is lost, or late when its answer comes later.")


def _timing(console: Any, d: dict[str, Any]) -> None:
    table = _table(title=f"Timing (µs), cyclic stream: {d['cyclic_stream']}")
    table.add_column("")
    for col in _STATS:
        table.add_column(col, justify="right")
    for label, key in (("round trip", "round_trip_us"), ("cyclic round trip",
                       "round_trip_cyclic_us"), ("cycle period", "cycle_period_us")):
        s = d[key]
        cells = ["—"] * 7 if s is None else [str(s["count"])] + [
            _us(s[k]) for k in _STATS[1:]]
        table.add_row(label + (" (unusable)" if key in d["unusable_stats"] else ""), *cells)
    console.print(table)
    if d["unusable_stats"]:
        _say(console, "unusable: built on quantised or backward timestamps (see findings)")
    if d["cycle_jitter_us"] and "cycle_period_us" not in d["unusable_stats"]:
        j = d["cycle_jitter_us"]
        _say(console, f"cycle jitter: std {j['std']:.2f} µs, max deviation from median "
                      f"{j['max_deviation']:.2f} µs")


def _us(value: float) -> str:
    """Two decimals below 1 ms, one below 10 ms, none above: a row of seven fits 80
    columns whatever the cycle (numbers are rounded, never cut)."""
    digits = 2 if abs(value) < 1000 else 1 if abs(value) < 10_000 else 0
    return f"{value:.{digits}f}"


def _datagram(g: dict[str, Any]) -> str:
    """``LRW 0x00010000 780 B``, ``FPRD 0x0130 of 0x03E9 (1001) 2 B``, ``BRD 0x0130 2 B``."""
    if g["logical_address"] is not None:
        where = f"0x{g['logical_address']:08X}"
    elif g["adp"] and g["cmd"] in _CONFIGURED:
        where = f"0x{g['ado']:04X} of {station(g['adp'])}"
    elif g["adp"]:
        where = f"0x{g['adp']:04X}:0x{g['ado']:04X}"
    else:
        where = f"0x{g['ado']:04X}"
    return f"{g['cmd']} {where} {g['length_bytes']} B"


def _wkc(console: Any, d: dict[str, Any]) -> None:
    w = d["wkc"]
    checked = (f"{plural(d['wkc_checked'], 'return')} checked, "
               f"{plural(d['wkc_mismatches'], 'mismatch', 'mismatches')}")
    if not w["datagrams"]:
        _say(console, f"WKC (reference: {d['wkc_reference']}; {checked}): no cyclic "
                      "datagram came back")
        return
    table = _table(title=f"WKC per cyclic datagram (reference: {d['wkc_reference']}; "
                         f"{checked})")
    for col, justify in (("datagram", "left"), ("expected", "right"), ("from", "left"),
                         ("returns", "right"), ("bad", "right"), ("seen (WKC ×count)", "left")):
        table.add_column(col, justify=justify)
    for g in w["datagrams"]:
        seen = ", ".join(f"{o['wkc']}×{o['count']}" for o in g["observed"])
        table.add_row(_datagram(g), "?" if g["expected"] is None else str(g["expected"]),
                      g["basis"] or "cannot tell", str(g["returns"]), str(g["mismatches"]), seen)
    console.print(table)


def _al_status(console: Any, d: dict[str, Any]) -> None:
    reads = d["al_status"]
    if not reads:
        return
    by_state: dict[str, list[str]] = {}
    for r in reads:
        who = "BRD" if r["station"] is None else station(r["station"])
        by_state.setdefault(r["state"], []).append(who)
    parts = []
    for state, names in by_state.items():
        shown = ", ".join(names[:8]) + (f" and {len(names) - 8} more" if len(names) > 8 else "")
        parts.append(f"{state}: {shown}")
    _say(console, "AL status, last read per slave — " + "; ".join(parts))


def _dc(console: Any, dc: dict[str, Any]) -> None:
    reads = dc["system_time_difference_reads"]
    text = (f"DC: {plural(dc['drift_compensation_datagrams'], 'drift-compensation datagram')}"
            f" in {plural(dc['drift_compensation_bursts'], 'burst')}; ")
    if reads:
        text += (f"{plural(reads, 'read')} of the system time difference (0x092C), largest "
                 f"{number(dc['system_time_difference_max_abs_ns'], 'ns')}")
    else:
        text += "no read of the system time difference (0x092C)"
    _say(console, text)


def _sdo(console: Any, d: dict[str, Any], show_all: bool) -> None:
    transactions = d["sdo_transaction_list"]
    aborts = d["sdo_aborts"]
    if not transactions:
        _say(console, f"SDO: none ({plural(d['mailbox']['messages'], 'mailbox message')})")
        return
    table = _table(title=f"SDO transactions ({d['sdo_transactions']}, "
                         f"{plural(len(aborts), 'abort')})", collapse_padding=True)
    for col in ("slave", "object", "kind", "transfer", "bytes", "status", "frames", "µs"):
        table.add_column(col, justify="right" if col in ("bytes", "µs") else "left")
    shown = transactions if show_all else transactions[:SDO_ROWS]
    last = None
    for t in shown:
        status = t["status"]  # (an abort's code and text follow the table)
        dur = "" if t["duration_us"] is None else f"{t['duration_us']:.0f}"
        end = "" if t["end_frame"] is None else t["end_frame"]  # (open: no answer yet)
        # the slave once per run of its transactions
        who = "" if t["slave"] == last else station(t["slave"])
        last = t["slave"]
        table.add_row(who, t["object"], t["kind"], t["transfer"], str(t["size_bytes"]),
                      status, f"{t['start_frame']}–{end}", dur)
    console.print(table)
    if len(shown) < len(transactions):
        _say(console, f"… {len(transactions) - len(shown)} more, --all to show")
    for a in aborts:
        _say(console, f"SDO abort: slave {station(a['slave'])} 0x{a['index']:04X}:"
                      f"{a['subindex']:02X} {a['code_hex']} {a['text']} (frame {a['frame']})")
