"""`lolacli bus timing`: frame time on the wire, slave and cable delays, round trip, max rate."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from lolacli.cli.bus import app
from lolacli.cli.common import FormatOption, OutputFormat, default_eni, emit_json, warn
from lolacli.errors import InputError, UsageError


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
        float, typer.Option("--link-mbit", min=0.001, help="Link rate in Mbit/s.")
    ] = 100.0,
    cable_m: Annotated[
        float, typer.Option("--cable-m", min=0.0, help="Cable length per segment, metres.")
    ] = 1.0,
    per_slave_ns: Annotated[
        int | None,
        typer.Option(
            "--per-slave-ns",
            min=0,
            help="Per-slave delay (out and back) in ns. Default: calibrated from the "
            "measured total when there is one, else an assumed 1000 ns.",
        ),
    ] = None,
    measured: Annotated[
        str | None,
        typer.Option(
            "--measured",
            help="Measured round trip: 124.1us, 124.1µs, 0.1241ms, 124100ns, or µs.",
        ),
    ] = None,
    capture: Annotated[
        Path | None,
        typer.Option("--capture", help="pcap/pcapng: the measured total is its mean round trip."),
    ] = None,
    budget_us: Annotated[
        float | None,
        typer.Option(
            "--budget-us",
            min=0.0,
            help="Cycle-time budget; exit 1 when the total exceeds it. Default: the ENI's "
            "cycle time.",
        ),
    ] = None,
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """Theoretical frame time against measured totals, and the maximum update rate.

    Round trip = wire time (8 x frame bytes / link rate) + slaves x per-slave delay +
    cable (5 ns/m, out and back). With --measured or --capture, the per-slave delay is
    calibrated as (measured - wire - cable) / slaves. The maximum update rate is
    1 / round trip (measured if given, else predicted): the fastest cycle whose frame is
    back before the next one leaves, without master computing time or acyclic traffic.
    Without --eni and --frame-bytes the embedded LOLA chain is used.
    """
    from lolacli.timing.model import estimate, parse_duration_ns

    _check_options(eni, frame_bytes, slaves, measured, capture)
    n_bytes, n_slaves, cycle_ns, source = _frame_and_slaves(eni, frame_bytes, slaves)
    measured_ns, measured_from = None, None
    if measured is not None:
        measured_ns, measured_from = parse_duration_ns(measured), "option"
    elif capture is not None:
        measured_ns, measured_from = _capture_round_trip_ns(capture)
    budget_ns = _scaled("--budget-us", budget_us, 1000) if budget_us is not None else cycle_ns
    result = estimate(
        n_bytes,
        n_slaves,
        link_bit_s=_scaled("--link-mbit", link_mbit, 1_000_000),
        cable_m_per_segment=cable_m,
        per_slave_delay_ns=per_slave_ns,
        measured_total_ns=measured_ns,
        budget_ns=budget_ns,
    )
    doc = result.to_dict() | {"source": source, "measured_from": measured_from}
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
    if (frame_bytes is None) != (slaves is None):
        raise UsageError("--frame-bytes and --slaves go together")
    if measured is not None and capture is not None:
        raise UsageError("--measured and --capture contradict each other; give one")


def _scaled(option: str, value: float, scale: int) -> int:
    """round(value × scale); a usage error when that is not a finite number (typer lets
    'inf' and '1e999' through its range checks)."""
    import math

    if not math.isfinite(value * scale):
        raise UsageError(f"{option} {value:g}: out of range")
    return round(value * scale)


def _frame_and_slaves(
    eni: Path | None, frame_bytes: int | None, slaves: int | None
) -> tuple[int, int, int | None, str]:
    """(frame bytes, slaves, cycle time ns or None, where they came from)."""
    if frame_bytes is not None and slaves is not None:
        return frame_bytes, slaves, None, "options"
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


def _capture_round_trip_ns(path: Path) -> tuple[int, str]:
    """Mean round trip of the capture's cyclic stream (or of all pairs), in ns."""
    from lolacli.capture import analyze_file

    report = analyze_file(path).to_dict()
    for key in ("round_trip_cyclic_us", "round_trip_us"):
        stats = report.get(key)
        if stats and float(stats["max"]) > 0:
            return round(float(stats["mean"]) * 1000), f"capture:{key}.mean"
    if report.get("round_trip_us"):
        raise InputError(
            "every round trip in the capture is 0 us: its timestamps cannot measure one",
            path=str(path),
        )
    raise InputError("no outgoing/returned frame pairs to measure a round trip", path=str(path))


def _render(doc: dict[str, Any]) -> None:
    from rich.table import Table

    from lolacli.cli.common import stdout_console

    table = Table(title=f"Frame timing ({doc['source']})", show_header=False, title_justify="left")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    rows = [
        ("frame", f"{doc['frame_bytes']} B at {doc['link_mbit_s']:g} Mbit/s"),
        ("wire time", f"{doc['wire_time_us']:g} µs"),
        ("wire time incl. preamble + IFG", f"{doc['wire_time_with_overhead_us']:g} µs"),
        ("slaves", str(doc["slaves"])),
        (
            "per-slave delay",
            f"{doc['per_slave_delay_ns']} ns ({doc['per_slave_delay_source']})",
        ),
        ("cable (out and back)", f"{doc['cable_delay_ns']} ns"),
        ("predicted round trip", f"{doc['predicted_total_us']:g} µs"),
    ]
    if doc["measured_total_us"] is not None:
        rows.append(("measured round trip", f"{doc['measured_total_us']:g} µs"))
        rows.append(("calibrated per-slave delay", f"{doc['calibrated_per_slave_delay_ns']} ns"))
    rows.append((f"max update rate ({doc['total_source']})", f"{doc['max_rate_hz']:,.0f} Hz"))
    if doc["budget_us"] is not None:
        verdict = "ok" if doc["within_budget"] else "EXCEEDED"
        rows.append(("cycle budget", f"{doc['budget_us']:g} µs: {verdict}"))
    for name, value in rows:
        table.add_row(name, value)
    stdout_console().print(table)
