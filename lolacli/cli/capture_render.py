"""Human output of ``capture analyze``: the verdict and its findings first, then the numbers
behind them, in tables that read at 80 columns (the width rule of :mod:`lolacli.cli.common`).
Renders the ``lolacli.capture/1`` document, so it shows exactly what the JSON says."""

from __future__ import annotations

from typing import Any

SDO_ROWS = 50
_SEVERITY = {"failure": "FAIL", "warning": "WARN", "info": "info"}
_STATS = ("count", "min", "mean", "median", "std", "p99", "max")
_RULES = {"mac": "by the source MAC", "packet_type": "by packet type (Linux cooked)",
          "packet_type+mac": "by packet type and source MAC", "inferred": "inferred"}


def _table(**kwargs: Any) -> Any:
    from rich import box
    from rich.table import Table

    return Table(box=box.SIMPLE_HEAD, title_justify="left", **kwargs)


def _grid() -> Any:
    from rich.table import Table

    return Table.grid(padding=(0, 1))


def render_analysis(d: dict[str, Any], show_all: bool = False) -> None:
    from lolacli.cli.common import stdout_console

    console = stdout_console()
    console.print(d["file"])
    console.print(
        f"{d['format']}, {d['time_span_us'] / 1e6:.3f} s, {d['frames_total']} packets, "
        f"engine {d['engine']}; direction {_RULES.get(d['direction_rule'], d['direction_rule'])}"
    )
    _verdict(console, d)
    _frames(console, d)
    _timing(console, d)
    _wkc(console, d)
    _al_status(console, d)
    console.print("Datagrams by command: " + (", ".join(
        f"{k} {v}" for k, v in d["datagrams_by_cmd"].items()) or "none"))
    dc = d["dc"]
    console.print(
        f"DC: {dc['drift_compensation_datagrams']} drift-compensation datagrams in "
        f"{dc['drift_compensation_bursts']} bursts; {dc['system_time_difference_reads']} "
        f"reads of 0x092C, max |diff| {dc['system_time_difference_max_abs_ns']} ns"
    )
    _sdo(console, d, show_all)


def _verdict(console: Any, d: dict[str, Any]) -> None:
    findings = d["findings"]
    counts = {s: sum(1 for f in findings if f["severity"] == s) for s in _SEVERITY}
    parts = [f"{n} {s}{'s' if n != 1 else ''}" for s, n in counts.items() if n]
    console.print(f"Verdict: {d['verdict'].upper()}" + (f" ({', '.join(parts)})" if parts else ""))
    if not findings:
        return
    grid = _grid()
    grid.add_column(no_wrap=True)
    grid.add_column()
    for f in findings:
        text = f"{f['kind']}: {f['message']}"
        if f["frames"]:
            listed = ", ".join(str(n) for n in f["frames"])
            if f["count"] > len(f["frames"]):
                text += f"\nfirst frames {listed} (of {f['count']})"
            else:
                text += f"\nframe{'s' if len(f['frames']) > 1 else ''} {listed}"
        grid.add_row(_SEVERITY.get(f["severity"], f["severity"]), text)
    console.print(grid)


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
    console.print(f"A frame unanswered for {d['timeout_us']:g} µs ({d['timeout_source']}) is "
                  "lost, or late when its answer comes later.")


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
        console.print("unusable: built on quantised or backward timestamps (see findings)")
    if d["cycle_jitter_us"] and "cycle_period_us" not in d["unusable_stats"]:
        j = d["cycle_jitter_us"]
        console.print(f"cycle jitter: std {j['std']:.2f} µs, max deviation from median "
                      f"{j['max_deviation']:.2f} µs")


def _us(value: float) -> str:
    """Two decimals below 1 ms, one below 10 ms, none above: a row of seven fits 80
    columns whatever the cycle (numbers are rounded, never cut)."""
    digits = 2 if abs(value) < 1000 else 1 if abs(value) < 10_000 else 0
    return f"{value:.{digits}f}"


def _wkc(console: Any, d: dict[str, Any]) -> None:
    w = d["wkc"]
    title = (f"WKC per cyclic datagram (reference: {d['wkc_reference']}; "
             f"{d['wkc_checked']} returns checked, {d['wkc_mismatches']} mismatches)")
    if not w["datagrams"]:
        console.print(title.replace("per cyclic datagram ", "") + ": no cyclic datagram "
                      "came back")
        return
    table = _table(title=title)
    for col, justify in (("datagram", "left"), ("expected", "right"), ("from", "left"),
                         ("returns", "right"), ("bad", "right"), ("seen (WKC ×count)", "left")):
        table.add_column(col, justify=justify)
    for g in w["datagrams"]:
        if g["logical_address"] is not None:
            where = f"0x{g['logical_address']:08X}"
        elif g["adp"]:
            where = f"0x{g['adp']:04X}:0x{g['ado']:04X}"
        else:
            where = f"0x{g['ado']:04X}"
        seen = ", ".join(f"{o['wkc']}×{o['count']}" for o in g["observed"])
        table.add_row(f"{g['cmd']} {where} {g['length_bytes']} B",
                      "?" if g["expected"] is None else str(g["expected"]),
                      g["basis"] or "cannot tell", str(g["returns"]), str(g["mismatches"]), seen)
    console.print(table)


def _al_status(console: Any, d: dict[str, Any]) -> None:
    reads = d["al_status"]
    if not reads:
        return
    by_state: dict[str, list[str]] = {}
    for r in reads:
        who = "BRD" if r["station"] is None else f"0x{r['station']:04X}"
        by_state.setdefault(r["state"], []).append(who)
    parts = []
    for state, names in by_state.items():
        shown = ", ".join(names[:8]) + (f" and {len(names) - 8} more" if len(names) > 8 else "")
        parts.append(f"{state}: {shown}")
    console.print("AL status, last read per slave — " + "; ".join(parts))


def _sdo(console: Any, d: dict[str, Any], show_all: bool) -> None:
    transactions = d["sdo_transaction_list"]
    aborts = d["sdo_aborts"]
    if not transactions:
        console.print(f"SDO: none (mailbox messages: {d['mailbox']['messages']})")
        return
    table = _table(title=f"SDO transactions ({d['sdo_transactions']}, {len(aborts)} aborts)")
    for col in ("slave", "object", "kind", "transfer", "bytes", "status", "frames", "µs"):
        table.add_column(col, justify="right" if col in ("bytes", "µs") else "left")
    shown = transactions if show_all else transactions[:SDO_ROWS]
    for t in shown:
        status = t["status"] if t["abort_code"] is None else f"abort {t['abort_code']}"
        dur = "" if t["duration_us"] is None else f"{t['duration_us']:.0f}"
        table.add_row(f"0x{t['slave']:04X}", t["object"], t["kind"], t["transfer"],
                      str(t["size_bytes"]), status, f"{t['start_frame']}–{t['end_frame']}", dur)
    console.print(table)
    if len(shown) < len(transactions):
        console.print(f"… {len(transactions) - len(shown)} more, --all to show")
    for a in aborts:
        console.print(f"SDO abort: slave 0x{a['slave']:04X} 0x{a['index']:04X}:"
                      f"{a['subindex']:02X} {a['code_hex']} {a['text']} (frame {a['frame']})")
