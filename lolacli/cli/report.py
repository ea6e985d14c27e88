"""`lolacli report`: one timing report (HTML, or Markdown with PNGs) and its JSON from an
ENI, captures and a simulation (:mod:`lolacli.report`)."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

import typer

from lolacli.cli.bus_simulate import CableM, Duration, Forwarding, HostLatencyUs, Rate
from lolacli.cli.options import DriftOption, DropOption, SeedOption, StuckSafeopOption
from lolacli.errors import UsageError


class PageFormat(StrEnum):
    html = "html"
    md = "md"


EniOption = Annotated[
    Path | None,
    typer.Option(
        "--eni",
        help="ENI of the chain: the network and the timing model, what captures are "
        "checked against, the chain simulated (default for --simulate: the embedded LOLA "
        "chain).",
    ),
]
CaptureOption = Annotated[
    list[Path] | None,
    typer.Option("--capture", help="pcap/pcapng to analyse; repeat to compare side by side."),
]
SimulateFlag = Annotated[
    bool, typer.Option("--simulate", help="Simulate the chain (bus simulate) and report it.")
]
OutputOption = Annotated[
    Path,
    typer.Option("--output", "-o", help="The page to write; its JSON (lolacli.report/1) "
                 "goes beside it with the suffix .json.", show_default=False),
]
PageFormatOption = Annotated[
    PageFormat,
    typer.Option("--format", "-f", help="html: one self-contained page; md: Markdown with "
                 "PNGs beside it."),
]
BaselineOption = Annotated[
    Path | None,
    typer.Option("--baseline", help="An earlier report's JSON: exit 1 naming each headline "
                 "figure that got worse beyond --tolerance."),
]
ToleranceOption = Annotated[
    str, typer.Option("--tolerance", help="How much worse a headline figure may get.")
]


def report_cmd(
    output: OutputOption,
    eni: EniOption = None,
    capture: CaptureOption = None,
    simulate: SimulateFlag = False,
    rate: Rate = 2000.0,
    duration: Duration = None,
    drop_p: DropOption = 0.0,
    stuck_safeop: StuckSafeopOption = None,
    drift_ppb: DriftOption = 0,
    seed: SeedOption = 0,
    host_latency_us: HostLatencyUs = None,
    forwarding: Forwarding = "model",
    cable_m: CableM = None,
    fmt: PageFormatOption = PageFormat.html,
    baseline: BaselineOption = None,
    tolerance: ToleranceOption = "10%",
) -> None:
    """A timing report of an ENI, captures and/or a simulation: verdict with every
    finding, network, timing model against the measured round trip, bus measurements
    (round trip histogram, CDF and over time, cycle jitter, lost frames, WKC, AL states),
    distributed clocks, software cycle, captures side by side. Exit 1 when the verdict
    fails (a failure of a capture or the simulation, or a regression against
    --baseline), 2 for bad options, 3 for bad input or an output that cannot be
    written, 130/143 when stopped (nothing is written)."""
    from lolacli.report import build_report, check_output, load_baseline, parse_tolerance

    captures = capture or []
    if eni is None and not captures and not simulate:
        raise UsageError("nothing to report: give --eni, --capture or --simulate")
    simulation_only = {"--rate": rate != 2000.0, "--duration": duration is not None,
                       "--drop-p": drop_p != 0.0, "--stuck-safeop": bool(stuck_safeop),
                       "--drift-ppb": drift_ppb != 0, "--seed": seed != 0,
                       "--host-latency-us": host_latency_us is not None,
                       "--forwarding": forwarding != "model", "--cable-m": bool(cable_m)}
    if not simulate and any(simulation_only.values()):
        given = ", ".join(k for k, v in simulation_only.items() if v)
        raise UsageError(f"{given}: options of the simulation; add --simulate")
    check_output(output)  # before any work
    tolerance_percent = parse_tolerance(tolerance)
    base = load_baseline(baseline) if baseline is not None else None
    model = _eni(eni, simulate)
    analyses = [_analyze(path, model) for path in captures]
    simulation = None
    if simulate:
        from lolacli.simulate import options_from_cli
        from lolacli.simulate import simulate as run_simulation

        options = options_from_cli(
            rate_hz=rate, duration=duration, stuck_safeop=stuck_safeop or (),
            drop_probability=drop_p, drift_ppb=drift_ppb, seed=seed,
            host_latency_us=host_latency_us, forwarding=forwarding,
            cable_m=cable_m or ())  # fmt: skip
        assert model is not None
        simulation = run_simulation(model, options)
    report = build_report(eni=model, captures=analyses, simulation=simulation, baseline=base,
                          baseline_name=str(baseline), tolerance_percent=tolerance_percent)
    _write(report, output, fmt)
    if report.verdict == "fail":
        raise typer.Exit(1)


def _eni(path: Path | None, simulate: bool) -> Any:
    from lolacli.cli.common import default_eni
    from lolacli.files import load_eni

    if path is None and not simulate:
        return None
    return load_eni(path if path is not None else default_eni())


def _analyze(path: Path, eni: Any) -> Any:
    from lolacli.capture.analyze import analyze_file

    return analyze_file(path, eni=eni, keep_series=True)


def _write(report: Any, output: Path, fmt: PageFormat) -> None:
    from lolacli.cli.common import say, stdout_console
    from lolacli.cli.verdict import render_verdict
    from lolacli.report import write_report
    from lolacli.text import number

    written = write_report(report, output, fmt.value)
    console = stdout_console()
    findings = report.findings
    if len(report.sources) > 1:  # say whose finding each is
        findings = [{**f, "message": f"{f['source']}: {f['message']}"}
                    if not f["message"].startswith(f["source"]) else f for f in findings]
    render_verdict(console, report.verdict, findings)
    for note in report.notes:
        say(console, f"note: {note}")
    for path in written:
        say(console, f"wrote {path} ({number(path.stat().st_size / 1000, 'kB', 1)})")
