"""`lolacli bus timing`: frame time on the wire, slave and cable delays, round trip, max rate
(:class:`lolacli.timing.bus.TimingRequest`)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from lolacli.cli.bus import app
from lolacli.cli.common import FormatOption, OutputFormat, default_eni, emit_json, warn
from lolacli.cli.options import not_nan
from lolacli.timing.bus import Statistic

EniOption = Annotated[
    Path | None,
    typer.Option("--eni", help="ENI file: its first cyclic frame and slave count are used."),
]
FrameBytesOption = Annotated[
    int | None,
    typer.Option("--frame-bytes", min=1, help="Frame bytes on the wire (instead of --eni)."),
]
SlavesOption = Annotated[
    int | None, typer.Option("--slaves", min=0, help="Number of slaves (with --frame-bytes).")
]
LinkOption = Annotated[
    float, typer.Option("--link-mbit", min=0.001, callback=not_nan, help="Link rate in Mbit/s.")
]
CableOption = Annotated[
    float,
    typer.Option("--cable-m", min=0.0, callback=not_nan, help="Cable length per segment, metres."),
]
PerSlaveOption = Annotated[
    int | None,
    typer.Option(
        "--per-slave-ns",
        min=0,
        help="Per-slave delay (out and back) in ns for the prediction. Default: an "
        "assumed 1000 ns (a measured total is calibrated separately).",
    ),
]
HostLatencyOption = Annotated[
    float,
    typer.Option(
        "--host-latency-us",
        min=0.0,
        callback=not_nan,
        help="What the master's host adds to a round trip measured at its NIC (stack, "
        "driver, NIC queues, switch): part of the prediction, taken off a measured total "
        "before calibrating.",
    ),
]
MeasuredOption = Annotated[
    str | None,
    typer.Option(
        "--measured",
        help="Measured round trip: 124.1us, 124.1µs, 0.1241ms, 124100ns, or µs.",
    ),
]
CaptureOption = Annotated[
    Path | None,
    typer.Option(
        "--capture",
        help="pcap/pcapng: the measured total is its cyclic round trip (--statistic); "
        "slaves and frame bytes come from it too (BRD working counter, the cyclic "
        "frame) unless --eni, --slaves or --frame-bytes say otherwise.",
    ),
]
StatisticOption = Annotated[
    Statistic,
    typer.Option(
        "--statistic",
        help="Round-trip statistic of --capture: min (closest to the bus alone) or median.",
    ),
]
BudgetOption = Annotated[
    float | None,
    typer.Option(
        "--budget-us",
        min=0.0,
        callback=not_nan,
        help="Cycle-time budget; exit 1 when the total exceeds it. Default: the ENI's "
        "cycle time.",
    ),
]


@app.command("timing")
def timing_cmd(
    eni: EniOption = None,
    frame_bytes: FrameBytesOption = None,
    slaves: SlavesOption = None,
    link_mbit: LinkOption = 100.0,
    cable_m: CableOption = 1.0,
    per_slave_ns: PerSlaveOption = None,
    host_latency_us: HostLatencyOption = 0.0,
    measured: MeasuredOption = None,
    capture: CaptureOption = None,
    statistic: StatisticOption = Statistic.min,
    budget_us: BudgetOption = None,
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
    from lolacli.files import load_eni
    from lolacli.timing.bus import TimingRequest

    request = TimingRequest(
        None if eni is None else str(eni), frame_bytes, slaves, link_mbit, cable_m,
        per_slave_ns, host_latency_us, measured, None if capture is None else str(capture),
        statistic, budget_us,
    )
    report = None
    if capture is not None:  # request.reads_capture
        from lolacli.capture import analyze_file
        from lolacli.capture.fast import fallback_note

        report = analyze_file(capture).to_dict()
        if (note := fallback_note()) is not None:  # the C scanner is not built
            sys.stderr.write(note + "\n")
    timing = request.run(lambda: load_eni(eni if eni is not None else default_eni()),
                         report, warn)
    if fmt is OutputFormat.json:
        emit_json(timing.doc)
    else:
        _render(timing.doc)
    if timing.within_budget is False:
        raise typer.Exit(1)


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
