"""`lolacli bus timing`: frame time on the wire, slave and cable delays, round trip, max rate."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

import typer

from lolacli.cli.bus import app
from lolacli.cli.common import FormatOption, OutputFormat, default_eni, emit_json, warn
from lolacli.cli.options import not_nan
from lolacli.errors import InputError, UsageError


class Statistic(StrEnum):
    min = "min"
    median = "median"


@app.command("timing")
def timing_cmd(
    eni: Annotated[
        Path | None,
        typer.Option("--eni", help="ENI file: its first cyclic frame and slave count are used."),
    ] = None,
    frame_bytes: Annotated[
        int | None,
        typer.Option("--frame-bytes", min=1, help="Frame bytes on the wire (instead of --eni)."),
    ] = None,
    slaves: Annotated[
        int | None, typer.Option("--slaves", min=0, help="Number of slaves (with --frame-bytes).")
    ] = None,
    link_mbit: Annotated[
        float, typer.Option("--link-mbit", min=0.001, callback=not_nan, help="Link rate in Mbit/s.")
    ] = 100.0,
    cable_m: Annotated[
        float,
        typer.Option(
            "--cable-m", min=0.0, callback=not_nan, help="Cable length per segment, metres."
        ),
    ] = 1.0,
    per_slave_ns: Annotated[
        int | None,
        typer.Option(
            "--per-slave-ns",
            min=0,
            help="Per-slave delay (out and back) in ns for the prediction. Default: an "
            "assumed 1000 ns (a measured total is calibrated separately).",
        ),
    ] = None,
    host_latency_us: Annotated[
        float,
        typer.Option(
            "--host-latency-us",
            min=0.0, callback=not_nan,
            help="What the master's host adds to a round trip measured at its NIC (stack, "
            "driver, NIC queues, switch): part of the prediction, taken off a measured total "
            "before calibrating.",
        ),
    ] = 0.0,
    measured: Annotated[
        str | None,
        typer.Option(
            "--measured",
            help="Measured round trip: 124.1us, 124.1µs, 0.1241ms, 124100ns, or µs.",
        ),
    ] = None,
    capture: Annotated[
        Path | None,
        typer.Option(
            "--capture",
            help="pcap/pcapng: the measured total is its cyclic round trip (--statistic); "
            "slaves and frame bytes come from it too (BRD working counter, the cyclic "
            "frame) unless --eni, --slaves or --frame-bytes say otherwise.",
        ),
    ] = None,
    statistic: Annotated[
        Statistic,
        typer.Option(
            "--statistic",
            help="Round-trip statistic of --capture: min (closest to the bus alone) or median.",
        ),
    ] = Statistic.min,
    budget_us: Annotated[
        float | None,
        typer.Option(
            "--budget-us",
            min=0.0, callback=not_nan,
            help="Cycle-time budget; exit 1 when the total exceeds it. Default: the ENI's "
            "cycle time.",
        ),
    ] = None,
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Theoretical frame time against measured totals, and the maximum update rate.

    Round trip = wire time (8 x frame bytes / link rate) + slaves x per-slave delay +
    cable (5 ns/m, out and back) + host latency. The prediction uses the assumed (or given)
    per-slave delay; with --measured or --capture the per-slave delay is calibrated apart,
    as (measured - wire - cable - host latency) / slaves, and a warning says when it lies
    outside what ESCs do (0.3-3 µs). The maximum update rate is 1 / round trip (measured if
    given, else predicted): the fastest cycle whose frame is back before the next one
    leaves, without master computing time or acyclic traffic. Without --eni, --frame-bytes
    and --capture the embedded LOLA chain is used.
    """
    from lolacli.timing.model import estimate, parse_duration_ns

    _check_options(eni, frame_bytes, slaves, measured, capture)
    report = None
    measured_ns, measured_from = None, None
    if measured is not None:
        measured_ns, measured_from = parse_duration_ns(measured), "--measured"
    elif capture is not None:
        from lolacli.capture import analyze_file

        report = analyze_file(capture).to_dict()
        measured_ns, measured_from = _capture_round_trip_ns(capture, report, statistic)
    line = _line(eni, frame_bytes, slaves, capture, report)
    budget_ns = (_scaled("--budget-us", budget_us, 1000) if budget_us is not None
                 else line.cycle_ns)
    try:
        result = estimate(
            line.frame_bytes,
            line.slaves,
            link_bit_s=_scaled("--link-mbit", link_mbit, 1_000_000),
            cable_m_per_segment=cable_m,
            per_slave_delay_ns=per_slave_ns,
            measured_total_ns=measured_ns,
            budget_ns=budget_ns,
            host_latency_ns=_scaled("--host-latency-us", host_latency_us, 1000),
        )
    except UsageError as e:
        if capture is None or measured_ns is None:
            raise
        # the capture's own numbers do not fit a round trip (a veth has no wire time)
        raise InputError(f"{e}; from {measured_from}", path=str(capture)) from None
    caution = _calibration_warning(result)
    doc = result.to_dict() | {
        "source": line.source,
        "measured_from": measured_from,
        "sources": {"frame_bytes": line.frame_bytes_from, "slaves": line.slaves_from,
                    "measured": measured_from},
        "calibration_warning": caution,
    }
    if caution:
        warn(caution)
    if fmt is OutputFormat.json:
        emit_json(doc)
    else:
        _render(doc)
    if result.within_budget is False:
        raise typer.Exit(1)


def _check_options(
    eni: Path | None,
    frame_bytes: int | None,
    slaves: int | None,
    measured: str | None,
    capture: Path | None,
) -> None:
    if eni is not None and (frame_bytes is not None or slaves is not None):
        raise UsageError("--eni and --frame-bytes/--slaves contradict each other; give one")
    if capture is None and (frame_bytes is None) != (slaves is None):
        raise UsageError("--frame-bytes and --slaves go together (or come from --capture)")
    if measured is not None and capture is not None:
        raise UsageError("--measured and --capture contradict each other; give one")


def _scaled(option: str, value: float, scale: int) -> int:
    """round(value × scale); a usage error when that is not a finite number (typer lets
    'inf' and '1e999' through its range checks)."""
    import math

    if not math.isfinite(value * scale):
        raise UsageError(f"{option} {value:g}: out of range")
    return round(value * scale)


@dataclass(frozen=True, slots=True)
class _Line:
    """The frame and the line of slaves to time, and where each number came from."""

    frame_bytes: int
    frame_bytes_from: str
    slaves: int
    slaves_from: str
    cycle_ns: int | None
    source: str
    report: dict[str, Any] | None = None


def _line(eni: Path | None, frame_bytes: int | None, slaves: int | None,
          capture: Path | None, report: dict[str, Any] | None) -> _Line:
    if eni is not None or (capture is None and frame_bytes is None):
        n_bytes, n_slaves, cycle_ns, source = _from_eni(eni)
        return _Line(n_bytes, f"{source}: first cyclic frame", n_slaves, f"{source}: slaves",
                     cycle_ns, source, report)
    if capture is None:
        assert frame_bytes is not None and slaves is not None
        return _Line(frame_bytes, "--frame-bytes", slaves, "--slaves", None, "options")
    assert report is not None
    seen = report["bus_seen"]
    if frame_bytes is None:
        if seen["cyclic_frame_bytes"] is None:
            raise UsageError(f"{capture}: no cyclic frame to time; give --frame-bytes or --eni")
        frame_bytes = seen["cyclic_frame_bytes"]
        bytes_from = f"capture: its longest cyclic frame ({report['cyclic_stream']} stream)"
    else:
        bytes_from = "--frame-bytes"
    if slaves is None:
        if seen["slaves"] is None:
            raise UsageError(f"{capture}: no BRD/BWR came back to count the slaves; give "
                             "--slaves or --eni")
        slaves, slaves_from = seen["slaves"], f"capture: {seen['slaves_from']}"
    else:
        slaves_from = "--slaves"
    return _Line(frame_bytes, bytes_from, slaves, slaves_from, None, "capture", report)


def _from_eni(eni: Path | None) -> tuple[int, int, int | None, str]:
    """(frame bytes, slaves, cycle time ns or None, where they came from)."""
    from lolacli.files import load_eni

    path = eni if eni is not None else default_eni()
    model = load_eni(path)
    frames = model.cyclic_frames
    if not frames:
        raise InputError("the ENI has no cyclic frame to time", path=str(path))
    if len(frames) > 1:
        warn(f"{path}: {len(frames)} cyclic frames; timing the first one")
    source = str(eni) if eni is not None else "embedded LOLA chain"
    return frames[0].frame_bytes, len(model.slaves), model.cycle_time_ns, source


def _capture_round_trip_ns(path: Path, report: dict[str, Any],
                           statistic: Statistic) -> tuple[int, str]:
    """The chosen statistic of the capture's cyclic round trips (else of all pairs), ns."""
    for key, what in (("round_trip_cyclic_us", "cyclic round trips"),
                      ("round_trip_us", "round trips of all pairs")):
        stats = report.get(key)
        if not stats:
            continue
        if key in report["unusable_stats"] or float(stats[statistic.value]) <= 0:
            zero = [f for f in report["findings"] if f["kind"] == "timestamps-quantised"]
            why = zero[0]["message"] if zero else "they are not positive"
            raise InputError(f"round trips of 0 µs cannot measure one: {why}", path=str(path))
        value = round(float(stats[statistic.value]) * 1000)
        label = "minimum" if statistic is Statistic.min else "median"
        return value, f"capture: {label} of {stats['count']} {what}"
    raise InputError("no outgoing/returned frame pairs to measure a round trip", path=str(path))


def _calibration_warning(result: Any) -> str | None:
    if result.calibration_plausible is not False:
        return None
    lo, hi = (v / 1000 for v in result.to_dict()["esc_delay_range_ns"])
    return (f"the calibrated per-slave delay ({result.calibrated_per_slave_delay_ns} ns) is "
            f"outside what ESCs do ({lo:g}-{hi:g} µs): the measured round trip holds more than "
            "the slaves (the master's stack and NIC, a switch; see --host-latency-us), or the "
            "slave count is off")


def _render(doc: dict[str, Any]) -> None:
    from lolacli.cli.common import data_table, say, stdout_console

    console = stdout_console()
    what = {"options": "the options given", "capture": "the capture",
            "embedded LOLA chain": "the embedded LOLA chain"}
    say(console, f"Frame timing of {what.get(doc['source'], doc['source'])}")
    table = data_table()
    table.add_column("quantity")
    table.add_column("value", justify="right")
    table.add_column("from")
    for row in _rows(doc):
        table.add_row(*row)
    console.print(table)


def _rows(doc: dict[str, Any]) -> list[tuple[str, str, str]]:
    """(quantity, value with its unit, where it comes from) for each line of the table."""
    from lolacli.text import number, plural

    def source(text: str) -> str:  # "lola.xml: first cyclic frame" -> "ENI: first …"
        if doc["source"] in ("capture", "options"):
            return text
        return text.replace(f"{doc['source']}: ", "ENI: ", 1)

    src, pred = doc["sources"], doc["prediction"]
    rows = [
        ("frame", number(doc["frame_bytes"], "B", 0), source(src["frame_bytes"])),
        ("link rate", number(doc["link_mbit_s"], "Mbit/s"), "--link-mbit"),
        ("wire time", number(doc["wire_time_us"], "µs"), "8 x frame / link rate"),
        ("with preamble and gap", number(doc["wire_time_with_overhead_us"], "µs"),
         "+ 20 B (preamble 8 B, gap 12 B)"),
        ("slaves", plural(doc["slaves"], "slave"), source(src["slaves"])),
        ("cable, out and back", number(doc["cable_delay_ns"], "ns", 0),
         f"{number(doc['cable_m_per_segment'], 'm')} per slave, 5 ns/m"),
        ("host latency", number(doc["host_latency_us"], "µs"), "--host-latency-us"),
        ("per-slave delay", number(pred["per_slave_delay_ns"], "ns", 0),
         f"a priori: {pred['per_slave_delay_source']}"),
        ("predicted round trip", number(doc["predicted_total_us"], "µs"), "model, a priori"),
    ]
    if doc["measured_total_us"] is not None:
        rows.append(("measured round trip", number(doc["measured_total_us"], "µs"),
                     doc["measured_from"]))
        plausible = "" if doc["calibration_plausible"] else "; outside 0.3-3 µs: see warning"
        rows.append(("calibrated per-slave delay",
                     number(doc["calibrated_per_slave_delay_ns"], "ns", 0),
                     f"(measured - wire - cable - host) / slaves{plausible}"))
    rows.append((f"max update rate ({doc['total_source']})",
                 number(doc["max_rate_hz"], "Hz", 0), "1 / round trip"))
    if doc["budget_us"] is not None:
        verdict = "within it" if doc["within_budget"] else "EXCEEDED"
        rows.append(("cycle budget", number(doc["budget_us"], "µs"), verdict))
    return rows
