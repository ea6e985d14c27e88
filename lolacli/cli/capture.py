"""`lolacli capture …` commands: analyze, export, list.

The library (``lolacli.capture``: numpy) and rich/matplotlib are imported inside
the commands.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Annotated, Any

import typer

from lolacli.cli.common import FormatOption, OutputFormat, emit_json, json_text, silence_stdout
from lolacli.cli.options import CaptureArgument, EniCheckOption, MaxLostOption, MaxWkcOption
from lolacli.errors import UsageError

app = typer.Typer(no_args_is_help=True, help="Analyse and list pcap/pcapng captures.")



PlotOption = Annotated[
    Path | None,
    typer.Option("--plot", metavar="FOLDER", help="Write PNG plots (cycle period, round "
                 "trip) into this folder (created if missing, not its parent)."),
]
TimeoutOption = Annotated[
    str | None,
    typer.Option(
        "--timeout",
        help="A frame unanswered for this long is lost, or late when its answer comes "
        "later (5ms, 800us). Default: 10 x the median round trip, at least 1 ms.",
    ),
]
AllOption = Annotated[
    bool, typer.Option("--all", help="Show every SDO transaction, not the first 50.")
]
EngineOption = Annotated[
    str, typer.Option("--engine", help="auto | c | python", hidden=True)
]


CapturesArgument = Annotated[
    list[Path],
    typer.Argument(help="Capture files (pcap or pcapng), or folders of them. One file: one "
                   "report. Several, or a folder: a row, or a JSON line "
                   "(lolacli.capture-batch/1), per file.", show_default=False),
]
JobsOption = Annotated[
    int | None,
    typer.Option("--jobs", "-j", min=1,
                 help="Captures analysed at once (several files). Default: the CPUs."),
]


@app.command("analyze")
def analyze_cmd(
    files: CapturesArgument,
    eni: EniCheckOption = None,
    fmt: FormatOption = OutputFormat.human,
    plot: PlotOption = None,
    max_lost: MaxLostOption = 0,
    max_wkc: MaxWkcOption = 0,
    timeout: TimeoutOption = None,
    show_all: AllOption = False,
    engine: EngineOption = "auto",
    jobs: JobsOption = None,
) -> None:
    """Out/return pairing, round trip, cycle period and jitter, lost and late frames, WKC
    verdict, AL states, SDO transactions and DC diagnostics of a capture, with findings.
    Exit 1 when a finding is a failure (lost frames or WKC mismatches over the thresholds,
    a bus that never answered, no EtherCAT traffic, slaves not in OP after the master asked
    for OP, nothing checked against the --eni); frames still in flight when the capture
    ends are not lost. Several captures or a folder: a row (JSON: a line) per file, the
    exit code the worst file's."""
    from lolacli.capture.analyze import analyze_file
    from lolacli.interrupt import stop_signals

    timeout_ns = _timeout_ns(timeout)
    if len(files) != 1 or (file := files[0]).is_dir():
        return _analyze_many(files, eni, fmt, plot, engine, timeout_ns, max_lost, max_wkc, jobs)
    if plot is not None:
        from lolacli.capture.plots import plot_folder

        plot_folder(plot)  # a bad folder fails before the report is written
    model = _eni_model(eni)
    # Ctrl-C or SIGTERM during the scan: the report of the frames read so far, then 130/143
    with stop_signals() as stop, stop.polled(), _Progress(file, quiet=False) as progress:
        report = analyze_file(
            file, eni=model, progress=progress, engine=engine, keep_series=plot is not None,
            timeout_ns=timeout_ns, max_lost=max_lost, max_wkc_mismatches=max_wkc,
            should_stop=stop,
        )
    from lolacli.capture.fast import fallback_note

    if (note := fallback_note()) is not None:
        sys.stderr.write(note + "\n")
    data = report.to_dict()
    if fmt is OutputFormat.json:
        emit_json(data)
    else:
        from lolacli.cli.capture_render import render_analysis

        render_analysis(data, show_all=show_all)
    if stop():
        _stopped(report, stop.exit_code, plots=plot is not None)
    if plot is not None:
        from lolacli.capture.plots import write_plots

        for written in write_plots(report, plot):
            sys.stderr.write(f"lolacli: wrote {written}\n")
    if report.failed:
        raise typer.Exit(1)


McapOption = Annotated[
    Path,
    typer.Option("--mcap", help="Write MCAP here: /frames (every frame), /cycle (round "
                 "trip, period, WKC), /dc (system time difference), JSON for Foxglove."),
]


@app.command("export")
def export_cmd(
    file: CaptureArgument,
    mcap: McapOption,
    fmt: FormatOption = OutputFormat.human,
    engine: EngineOption = "auto",
) -> None:
    """Export a capture as MCAP: every frame (its bytes base64) and per-cycle figures
    (round trip, cycle period, WKC, DC system time difference) as JSON-schema channels
    that Foxglove plots, the channels `bus simulate --mcap` writes. The file is written
    whole or not at all (a temporary file renamed at the end). The findings are those of
    `capture analyze` (exit 1 when one is a failure, the file written anyway)."""
    from lolacli.capture.analyze import analyze_file, spool_stream
    from lolacli.capture.export import Stopped, check_target, export_mcap
    from lolacli.files import check_output_file
    from lolacli.interrupt import stop_signals

    check_output_file(mcap, "--mcap", [("the capture", file)])
    check_target(mcap)  # an unwritable path fails before the capture is read
    result = None
    spool = spool_stream(file)  # a pipe is read twice (analysis, export): copied once
    source = Path(spool.name) if spool is not None else file
    with stop_signals() as stop, stop.polled(), _Progress(file, quiet=False) as progress:
        try:
            report = analyze_file(source, progress=progress, engine=engine, should_stop=stop)
            if not stop():
                result = export_mcap(report, mcap, engine=engine, should_stop=stop)
                result.capture = str(file)
        except Stopped:
            pass
        finally:
            if spool is not None:
                spool.close()
    if stop() or result is None:
        sys.stderr.write(f"lolacli: stopped by {_signal_name(stop.exit_code)}; {mcap} "
                         "not written\n")
        raise typer.Exit(stop.exit_code)
    from lolacli.findings import verdict as verdict_of

    data = result.to_dict()
    data["verdict"] = verdict_of(report.findings)
    data["findings"] = [f.to_dict() for f in report.findings]
    if fmt is OutputFormat.json:
        emit_json(data)
    else:
        _render_export(data)
    if report.failed:
        raise typer.Exit(1)


def _size(n: int) -> str:
    from lolacli.text import number

    return number(n / 1e6, "MB", 1) if n >= 1e6 else number(n / 1e3, "kB", 1)


def _render_export(data: dict[str, Any]) -> None:
    from lolacli.cli.common import say, stdout_console
    from lolacli.text import number

    def count(n: int, noun: str) -> str:
        return number(n, noun if n == 1 else noun + "s", 0)

    console = stdout_console()
    say(console, f"wrote {data['mcap']}: {count(data['frames'], 'frame')}, "
        f"{count(len(data['channels']), 'channel')}, {_size(data['bytes'])}")
    for c in data["channels"]:
        say(console, f"  {c['topic']:<8} {count(c['messages'], 'message')} ({c['schema']})")
    findings = data["findings"]
    if findings:
        say(console, f"verdict {data['verdict']}: {count(len(findings), 'finding')} "
            "(as capture analyze gives them)")
        for f in findings:
            say(console, f"  {f['severity']}: {f['message']}", hang=4)


def _analyze_many(files: list[Path], eni: Path | None, fmt: OutputFormat, plot: Path | None,
                  engine: str, timeout_ns: int | None, max_lost: int, max_wkc: int,
                  jobs: int | None) -> None:
    """``capture analyze`` of several captures or a folder (lolacli.cli.capture_batch)."""
    from lolacli.cli.capture_batch import analyze_batch

    if plot is not None:
        raise UsageError("--plot takes one capture, not several")
    model = _eni_model(eni)
    code = analyze_batch(files, json_lines=fmt is OutputFormat.json, eni=model, engine=engine,
                         timeout_ns=timeout_ns, max_lost=max_lost, max_wkc=max_wkc, jobs=jobs)
    if code:
        raise typer.Exit(code)


def _eni_model(eni: Path | None) -> Any:
    """The --eni's model, None without one."""
    if eni is None:
        return None
    from lolacli.files import load_eni

    return load_eni(eni)


def _timeout_ns(timeout: str | None) -> int | None:
    """--timeout in ns (None: the analysis's default)."""
    if timeout is None:
        return None
    from lolacli.timing.model import parse_duration_ns

    timeout_ns = parse_duration_ns(timeout, None, "--timeout")
    if timeout_ns <= 0:
        raise UsageError(f"--timeout {timeout}: must be longer than 0")
    return timeout_ns


def _stopped(report: Any, code: int, *, plots: bool) -> None:
    """Say how much of the file the analysis of a stopped scan covers; exit with ``code``."""
    from lolacli.text import number

    read = "the whole file" if report.read_bytes is None else (
        f"the first {number(report.read_bytes / 1e6, 'MB', 1)}")
    sys.stderr.write(f"lolacli: stopped by {_signal_name(code)}; the analysis "
                     f"covers {read}" + ("; no plots written" if plots else "") + "\n")
    raise typer.Exit(code)


def _signal_name(code: int) -> str:
    import signal

    return signal.Signals(code - 128).name


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
            help="Terms, all of which must hold: commands (LRW; several, as fprd|fpwr or "
            "fprd fpwr: any of them), adp=N, ado=N (0..0xFFFF), lad=N (0..0xFFFFFFFF), "
            "idx=N (0..0xFF), wkc=N, wkc!=N (0..0xFFFF), mailbox, coe, sdo, and one "
            "direction: out or ret.",
        ),
    ] = None,
    fmt: FormatOption = OutputFormat.human,
) -> None:
    """One line per EtherCAT frame and datagram (number, time, direction, command, index,
    address, length, WKC), mailbox/CoE/SDO decoded."""
    import shutil

    from lolacli.capture.listing import format_lines, list_frames
    from lolacli.interrupt import stop_signals

    frames = list_frames(file, count=count, expr=expr)
    head = {"schema": "lolacli.capture-list/1", "file": str(file)}
    width = shutil.get_terminal_size((80, 24)).columns  # $COLUMNS, the terminal, or 80
    json_out = _JsonFrames(head) if fmt is OutputFormat.json else None
    out = sys.stdout
    # Ctrl-C or SIGTERM: the frames listed so far stay listed (JSON: a whole document, so
    # frames are written as they are listed), then 130/143
    with stop_signals() as stop, stop.polled():
        try:
            for frame in frames:
                if json_out is not None:
                    json_out.add(frame.to_dict())
                else:
                    for i, d in enumerate(frame.datagrams):
                        for line in format_lines(frame, d, i == 0, width):
                            out.write(line + "\n")
                if stop():
                    break
            if json_out is not None:
                json_out.end(interrupted=stop())
            out.flush()
        except BrokenPipeError:  # `lolacli capture list F | head`
            silence_stdout()
    if stop():
        sys.stderr.write(f"lolacli: stopped by {_signal_name(stop.exit_code)}; the list "
                         "ends there\n")
        raise typer.Exit(stop.exit_code)


class _JsonFrames:
    """``lolacli.capture-list/1`` written frame by frame (the document ``emit_json`` would
    write, with ``interrupted`` last): a stop, or a long list, costs no time nor memory."""

    def __init__(self, head: dict[str, Any]) -> None:
        self.n = 0
        text = json_text(head)
        sys.stdout.write(text[:-2] + ',\n  "frames": [')

    def add(self, frame: dict[str, Any]) -> None:
        body = json_text(frame).replace("\n", "\n    ")
        sys.stdout.write(("," if self.n else "") + "\n    " + body)
        self.n += 1

    def end(self, interrupted: bool) -> None:
        close = "\n  ]" if self.n else "]"
        sys.stdout.write(f'{close},\n  "interrupted": {json.dumps(interrupted)}\n}}\n')
