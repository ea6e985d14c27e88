"""`lolacli report`: one timing report (HTML, or Markdown with PNGs) and its JSON from an
ENI, captures and a simulation (:mod:`lolacli.report`)."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

import typer

from lolacli.cli.bus_simulate import (
    CableM,
    Duration,
    Forwarding,
    HostLatencyUs,
    Move,
    Rate,
    Trajectory,
)
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
JointTrackOption = Annotated[
    Path | None,
    typer.Option("--joint-track", metavar="FILE", help="joint track --format json's "
                 "document: the Joint tracking section (Table III; its error over time with "
                 "joint track --series)."),
]
JointBodeOption = Annotated[
    Path | None,
    typer.Option("--joint-bode", metavar="FILE", help="joint bode --format json's "
                 "document: the Bandwidth section (gain and phase, the -3 dB bandwidth)."),
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
    move: Move = None,
    trajectory: Trajectory = None,
    joint_track: JointTrackOption = None,
    joint_bode: JointBodeOption = None,
    fmt: PageFormatOption = PageFormat.html,
    baseline: BaselineOption = None,
    tolerance: ToleranceOption = "10%",
) -> None:
    """A timing report of an ENI, captures, a simulation and/or a joint's tracking and
    bandwidth: verdict with every finding, network, timing model against the measured
    round trip, bus measurements (round trip histogram, CDF and over time, cycle jitter,
    lost frames, WKC, AL states), distributed clocks, software cycle, captures side by
    side, the simulation's moved joints (--move/--trajectory), joint tracking
    (--joint-track) and bandwidth (--joint-bode). Exit 1 when the verdict fails (a
    failure of a capture or the simulation, or a regression against --baseline), 2 for
    bad options, 3 for bad input or an output that cannot be written, 130/143 when
    stopped (nothing is written)."""
    from lolacli.report import build_report, check_output, load_baseline, parse_tolerance

    captures = capture or []
    if eni is None and not captures and not simulate and not (joint_track or joint_bode):
        raise UsageError("nothing to report: give --eni, --capture, --simulate, "
                         "--joint-track or --joint-bode")
    sim_args = {"rate_hz": rate, "duration": duration, "stuck_safeop": stuck_safeop or (),
                "drop_probability": drop_p, "drift_ppb": drift_ppb, "seed": seed,
                "host_latency_us": host_latency_us, "forwarding": forwarding,
                "cable_m": cable_m or (), "moves": move or (), "trajectory": trajectory}
    _simulation_only(simulate, sim_args)
    _check_outputs(output, [("--eni", eni), *(("--capture", c) for c in captures),
                            ("--baseline", baseline), ("--joint-track", joint_track),
                            ("--joint-bode", joint_bode), ("--trajectory", trajectory)])
    check_output(output)  # before any work
    tolerance_percent = parse_tolerance(tolerance)
    base = load_baseline(baseline) if baseline is not None else None
    track, bode = _joint_docs(joint_track, joint_bode)
    model = _eni(eni, simulate)
    analyses = [_analyze(path, model) for path in captures]
    simulation = _simulate(model, sim_args) if simulate else None
    report = build_report(eni=model, captures=analyses, simulation=simulation, baseline=base,
                          baseline_name=str(baseline), tolerance_percent=tolerance_percent,
                          joint_track=track, joint_bode=bode)
    _write(report, output, fmt)
    if report.verdict == "fail":
        raise typer.Exit(1)


def _check_outputs(output: Path, inputs: list[tuple[str, Path | None]]) -> None:
    """UsageError (exit 2) when the page or its JSON would replace an input or is no
    regular file (lolacli.files.check_output_file)."""
    from lolacli.files import check_output_file
    from lolacli.report import json_path

    check_output_file(output, "-o", inputs)
    if json_path(output) == output:
        raise UsageError(f"-o {output}: the page's JSON is written beside it as "
                         f"{json_path(output).name}; give -o the page's name (.html, .md)")
    check_output_file(json_path(output), "-o (its JSON)", inputs)


#: the simulation's options (their options_from_cli names), flags and defaults
_SIMULATION_ONLY = (("rate_hz", "--rate", 2000.0), ("duration", "--duration", None),
                    ("drop_probability", "--drop-p", 0.0), ("stuck_safeop", "--stuck-safeop", ()),
                    ("drift_ppb", "--drift-ppb", 0), ("seed", "--seed", 0),
                    ("host_latency_us", "--host-latency-us", None),
                    ("forwarding", "--forwarding", "model"), ("cable_m", "--cable-m", ()),
                    ("moves", "--move", ()), ("trajectory", "--trajectory", None))


def _simulation_only(simulate: bool, args: dict[str, Any]) -> None:
    """UsageError for an option of the simulation given without --simulate."""
    given = [flag for key, flag, default in _SIMULATION_ONLY if args[key] != default]
    if not simulate and given:
        raise UsageError(f"{', '.join(given)}: options of the simulation; add --simulate")


def _joint_docs(track: Path | None, bode: Path | None) -> tuple[Any, Any]:
    from lolacli.report import load_joint_bode, load_joint_track

    return (load_joint_track(track) if track is not None else None,
            load_joint_bode(bode) if bode is not None else None)


def _simulate(model: Any, args: dict[str, Any]) -> Any:
    from lolacli.simulate import options_from_cli, simulate

    assert model is not None
    return simulate(model, options_from_cli(**args))


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
