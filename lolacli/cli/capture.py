"""`lolacli capture …` commands: analyze, list.

The library (``lolacli.capture``: numpy, numba) and rich/matplotlib are imported inside
the commands.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Annotated, Any

import typer

from lolacli.cli.common import FormatOption, OutputFormat, emit_json, silence_stdout

app = typer.Typer(no_args_is_help=True, help="Analyse and list pcap/pcapng captures.")

CaptureArgument = Annotated[
    Path, typer.Argument(help="Capture file (pcap or pcapng).", show_default=False)
]


@app.command("analyze")
def analyze_cmd(
    file: CaptureArgument,
    eni: Annotated[
        Path | None,
        typer.Option("--eni", help="ENI whose <Cnt> values are the expected WKCs."),
    ] = None,
    fmt: FormatOption = OutputFormat.human,
    plot: Annotated[
        Path | None,
        typer.Option("--plot", help="Write PNG plots (cycle period, round trip) here."),
    ] = None,
    max_lost: Annotated[
        int, typer.Option("--max-lost", min=0, help="Lost frames allowed before exit 1.")
    ] = 0,
    max_wkc: Annotated[
        int,
        typer.Option(
            "--max-wkc-mismatches", min=0, help="WKC mismatches allowed before exit 1."
        ),
    ] = 0,
    engine: Annotated[
        str, typer.Option("--engine", help="auto | c | numba | python", hidden=True)
    ] = "auto",
) -> None:
    """Out/return pairing, round trip, cycle period and jitter, lost frames, WKC errors,
    SDO transactions and DC diagnostics of a capture. Exit 1 when lost frames or WKC
    mismatches exceed the thresholds."""
    from lolacli.capture.analyze import analyze_file

    if plot is not None:
        from lolacli.capture.plots import plot_folder

        plot_folder(plot)  # a bad folder fails before the report is written
    model = None
    if eni is not None:
        from lolacli.files import load_eni

        model = load_eni(eni)
    with _Progress(file, quiet=False) as progress:
        report = analyze_file(
            file, eni=model, progress=progress, engine=engine, keep_series=plot is not None,
            max_lost=max_lost, max_wkc_mismatches=max_wkc,
        )
    data = report.to_dict()
    if fmt is OutputFormat.json:
        emit_json(data)
    else:
        _render_analysis(data)
    if plot is not None:
        from lolacli.capture.plots import write_plots

        for written in write_plots(report, plot):
            sys.stderr.write(f"lolacli: wrote {written}\n")
    if report.failed:
        raise typer.Exit(1)


class _Progress:
    """A rich progress bar on stderr, shown only once a scan has run for a second."""

    def __init__(self, path: Path, quiet: bool) -> None:
        self.start = time.monotonic()
        self.bar: Any = None
        self.task: Any = None
        self.quiet = quiet or not sys.stderr.isatty()
        self.path = path

    def __enter__(self) -> _Progress:
        return self

    def __call__(self, done: int, total: int) -> None:
        if self.quiet or time.monotonic() - self.start < 1.0:
            return
        if self.bar is None:
            from rich.progress import Progress

            from lolacli.cli.common import stderr_console

            self.bar = Progress(console=stderr_console(), transient=True)
            self.bar.start()
            self.task = self.bar.add_task(f"reading {self.path.name}", total=total)
        self.bar.update(self.task, completed=done)

    def __exit__(self, *exc: object) -> None:
        if self.bar is not None:
            self.bar.stop()


def _fmt_stats(s: dict[str, Any] | None) -> list[str]:
    if s is None:
        return ["—"] * 7
    return [str(s["count"])] + [f"{s[k]:.2f}" for k in ("min", "mean", "median", "std",
                                                        "p99", "max")]


def _render_analysis(d: dict[str, Any]) -> None:
    from rich.table import Table

    from lolacli.cli.common import stdout_console

    console = stdout_console()
    console.print(
        f"{d['file']}  ({d['format']}, {d['time_span_us'] / 1e6:.3f} s, engine {d['engine']})"
    )
    frames = Table(title="Frames", title_justify="left")
    for col in ("total", "EtherCAT", "other", "malformed", "out", "returned", "pairs",
                "unmatched out", "lost", "WKC mismatches"):
        frames.add_column(col, justify="right")
    frames.add_row(*(str(d[k]) for k in (
        "frames_total", "ecat_frames", "non_ecat_frames", "malformed_frames",
        "outgoing_frames", "returned_frames", "pairs", "unmatched_outgoing", "lost_frames",
        "wkc_mismatches")))
    console.print(frames)
    times = Table(title=f"Timing (µs) — cyclic stream: {d['cyclic_stream']}",
                  title_justify="left")
    times.add_column("")
    for col in ("count", "min", "mean", "median", "std", "p99", "max"):
        times.add_column(col, justify="right")
    times.add_row("round trip", *_fmt_stats(d["round_trip_us"]))
    times.add_row("round trip (cyclic)", *_fmt_stats(d["round_trip_cyclic_us"]))
    times.add_row("cycle period", *_fmt_stats(d["cycle_period_us"]))
    console.print(times)
    if d["cycle_jitter_us"]:
        j = d["cycle_jitter_us"]
        console.print(f"cycle jitter: std {j['std']:.2f} µs, max deviation from median "
                      f"{j['max_deviation']:.2f} µs")
    cmds = Table(title="Datagrams by command", title_justify="left")
    for name in d["datagrams_by_cmd"]:
        cmds.add_column(name, justify="right")
    cmds.add_row(*(str(v) for v in d["datagrams_by_cmd"].values()))
    console.print(cmds)
    _render_sdo_dc(console, d)


def _render_sdo_dc(console: Any, d: dict[str, Any]) -> None:
    from rich.table import Table

    dc = d["dc"]
    console.print(
        f"DC: {dc['drift_compensation_datagrams']} drift-compensation datagrams in "
        f"{dc['drift_compensation_bursts']} bursts; {dc['system_time_difference_reads']} "
        f"reads of 0x092C, max |diff| {dc['system_time_difference_max_abs_ns']} ns"
    )
    console.print(f"WKC reference: {d['wkc']['reference']}, "
                  f"{d['wkc']['checked_datagrams']} datagrams checked")
    if not d["sdo_transaction_list"]:
        console.print(f"SDO: none (mailbox messages: {d['mailbox']['messages']})")
        return
    sdo = Table(title=f"SDO transactions ({d['sdo_transactions']})", title_justify="left")
    for col in ("slave", "object", "kind", "transfer", "bytes", "status", "frames", "µs"):
        sdo.add_column(col)
    for t in d["sdo_transaction_list"][:50]:
        status = t["status"] if t["abort_code"] is None else (
            f"abort {t['abort_code']} {t['abort_text']}")
        dur = "" if t["duration_us"] is None else f"{t['duration_us']:.0f}"
        sdo.add_row(f"0x{t['slave']:04X}", t["object"], t["kind"], t["transfer"],
                    str(t["size_bytes"]), status, f"{t['start_frame']}–{t['end_frame']}", dur)
    console.print(sdo)


@app.command("list")
def list_cmd(
    file: CaptureArgument,
    count: Annotated[
        int | None, typer.Option("-c", "--count", min=0, help="List at most N frames.")
    ] = None,
    expr: Annotated[
        str | None,
        typer.Option(
            "--filter",
            help="Terms (all must hold): mnemonics (LRW, fprd|fpwr), adp=N, ado=N, lad=N, "
            "idx=N, wkc=N, wkc!=N, mailbox, coe, sdo, out, ret.",
        ),
    ] = None,
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """One line per EtherCAT frame and datagram (number, time, direction, command, index,
    address, length, WKC), mailbox/CoE/SDO decoded."""
    from lolacli.capture.listing import format_line, list_frames

    frames = list_frames(file, count=count, expr=expr)
    if fmt is OutputFormat.json:
        emit_json({"schema": "lolacli.capture-list/1", "file": str(file),
                   "frames": [f.to_dict() for f in frames]})
        return
    out = sys.stdout
    try:
        for frame in frames:
            for i, d in enumerate(frame.datagrams):
                out.write(format_line(frame, d, i == 0) + "\n")
        out.flush()
    except BrokenPipeError:  # `lolacli capture list F | head`
        silence_stdout()
