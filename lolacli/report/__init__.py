"""Timing reports (``lolacli report``): one page from an ENI, captures and a simulation.

:func:`build_report` takes the results the other commands produce — the ENI model,
``capture analyze``'s :class:`~lolacli.capture.analyze.CaptureReport` (analysed with
``keep_series=True`` for the figures) and ``bus simulate``'s
:class:`~lolacli.simulate.SimulationResult`, ``joint track``'s and ``joint bode``'s JSON
(:func:`load_joint_track`, :func:`load_joint_bode`) — and places their numbers in sections
(``lolacli.report/1``); :func:`write_report` writes it as HTML or Markdown with its JSON
beside it::

    from lolacli.files import load_eni
    from lolacli.report import build_report, write_report
    from lolacli.simulate import SimulateOptions, simulate

    eni = load_eni()
    report = build_report(eni=eni, simulation=simulate(eni, SimulateOptions(cycles=2000)))
    write_report(report, Path("lola.html"))
"""

from lolacli.report.gate import load_baseline, parse_tolerance
from lolacli.report.joints import load_bode as load_joint_bode
from lolacli.report.joints import load_track as load_joint_track
from lolacli.report.model import SCHEMA, Report, build_report
from lolacli.report.write import check_output, json_path, write_report

__all__ = [
    "SCHEMA",
    "Report",
    "build_report",
    "check_output",
    "json_path",
    "load_baseline",
    "load_joint_bode",
    "load_joint_track",
    "parse_tolerance",
    "write_report",
]
