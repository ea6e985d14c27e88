"""The regression gate of ``lolacli report --baseline``: the headline figures of each
measurement (round trip p50/p99, cycle jitter, lost frames, max rate; a simulation's
largest following error, joint track's RMS error per case, joint bode's bandwidth)
against those of an earlier report's JSON; a figure worse by more than the tolerance is a
regression."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from lolacli.errors import InputError, UsageError
from lolacli.files import read_bounded
from lolacli.findings import Finding, Severity
from lolacli.text import number

if TYPE_CHECKING:
    from lolacli.report.model import Report

#: larger baselines are not a report of ours
MAX_BASELINE_BYTES = 64 * 1024 * 1024


def parse_tolerance(text: str) -> float:
    """``10%``, ``10`` or ``2.5 %`` as percent; UsageError otherwise."""
    raw = text.strip().removesuffix("%").strip()
    try:
        value = float(raw)
    except ValueError:
        raise UsageError(f"--tolerance {text}: expected a percentage such as 10%") from None
    if not 0 <= value < 1e6:
        raise UsageError(f"--tolerance {text}: expected 0% or more")
    return value


def load_baseline(path: str | Path) -> dict[str, Any]:
    """An earlier ``lolacli.report/1`` JSON; InputError (exit 3) for anything else."""
    from lolacli.report.model import SCHEMA

    name = str(path)
    raw = read_bounded(path, "a report's JSON", MAX_BASELINE_BYTES)
    try:
        doc = json.loads(raw)
    except (ValueError, UnicodeDecodeError) as exc:
        line = getattr(exc, "lineno", None)
        raise InputError(f"not JSON: {exc}", path=name, line=line) from None
    if not isinstance(doc, dict) or doc.get("schema") != SCHEMA or not isinstance(
        doc.get("headline"), dict
    ):
        raise InputError(f"not a {SCHEMA} report (its JSON, written beside the HTML)",
                         path=name)
    return doc


def apply_gate(
    report: Report, baseline: dict[str, Any], name: str, tolerance_percent: float
) -> None:
    """Compare ``report``'s headline figures with ``baseline``'s (measurements matched by
    label); every regression becomes a failure finding linked to its section."""
    from lolacli.report.model import HEADLINE, HEADLINE_SECTION

    compared: list[dict[str, Any]] = []
    regressions: list[dict[str, Any]] = []
    units: dict[str, str] = {}
    current = report.headlines()
    for label, figures in baseline["headline"].items():
        now = current.get(label)
        if now is None or not isinstance(figures, dict):
            report.notes.append(f"regression gate: the baseline's {label!r} is not measured "
                                "here; not compared")
            continue
        for key, (name, unit, worse_when) in HEADLINE.items():
            old, new = figures.get(key), now.get(key)
            if not isinstance(old, int | float) or new is None:
                continue
            change = None if old == 0 else round(100 * (new - old) / abs(old), 3)
            delta = new - old if worse_when == "higher" else old - new
            worse = delta > abs(old) * tolerance_percent / 100 and delta > 0
            figure = f"{label}: {name}"
            compared.append({"figure": figure, "key": key, "source": label, "unit": unit,
                             "baseline": old, "value": new, "change_percent": change,
                             "worse": worse})
            if worse:
                regressions.append({"figure": figure, "baseline": old, "value": new,
                                    "change_percent": change, "key": key})
            units[figure] = unit
    report.gate = {"baseline": name,
                   "tolerance_percent": tolerance_percent, "compared": compared}
    report.regressions = regressions
    fallback = "comparison" if report.section("comparison") else (
        "bus" if report.section("bus") else "verdict")
    for r in regressions:
        key = r.pop("key")
        section = HEADLINE_SECTION.get(key, fallback)
        section = section if report.section(section) else fallback
        shown = "" if r["change_percent"] is None else f" ({r['change_percent']:+.1f} %)"
        before, after = (number(v, units[r["figure"]], 1 if abs(v) >= 1 else 4)
                         for v in (r["baseline"], r["value"]))
        found = Finding("regression", Severity.FAILURE,
                        f"{r['figure']} got worse: {before} → {after}{shown}, "
                        f"tolerance {tolerance_percent:g} %")
        report.findings.insert(0, {**found.to_dict(), "source": "regression gate",
                                   "section": section})
