"""The report's content (``lolacli.report/1``): sections built from the results the other
commands produce — the ENI (``eni inspect``'s document), ``bus timing``'s estimate,
``capture analyze``'s :class:`~lolacli.capture.analyze.CaptureReport` and ``bus
simulate``'s :class:`~lolacli.simulate.SimulationResult`. Nothing here measures or models
anything again: every number is one of theirs, placed in a table with where it comes from.

A section is present when its input is, and absent (not empty) when it is not:
``verdict`` always; ``network`` with an ENI; ``timing`` with an ENI or a capture whose
line the timing model can read; ``bus`` with a capture or a simulation; ``dc`` when a
capture or the simulation has distributed-clock figures; ``software`` with a simulation
that timed its sections; ``comparison`` with two or more measurements; ``joints`` with a
simulation that moved joints (``--move``/``--trajectory``); ``tracking`` with ``joint
track``'s document and ``bandwidth`` with ``joint bode``'s (:mod:`lolacli.report.joints`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from lolacli.errors import LolaError
from lolacli.findings import Finding, Severity
from lolacli.text import number, plural, station

if TYPE_CHECKING:
    import numpy as np

    from lolacli.capture.analyze import CaptureReport
    from lolacli.eni.model import Eni
    from lolacli.report.joints import JointDoc
    from lolacli.simulate import SimulationResult

SCHEMA = "lolacli.report/1"

#: section ids in page order, and their titles
TITLES = {
    "verdict": "Verdict",
    "network": "Network",
    "timing": "Timing model",
    "bus": "Bus measurements",
    "dc": "Distributed clocks",
    "software": "Software cycle",
    "comparison": "Measurements side by side",
    "joints": "Joints",
    "tracking": "Joint tracking",
    "bandwidth": "Bandwidth",
}

#: the figures the regression gate compares, with their unit and which way is worse
HEADLINE = {
    "round_trip_p50_us": ("round trip p50", "µs", "higher"),
    "round_trip_p99_us": ("round trip p99", "µs", "higher"),
    "cycle_jitter_us": ("cycle jitter (std)", "µs", "higher"),
    "lost_frames": ("lost frames", "", "higher"),
    "max_rate_hz": ("max rate, round trip only", "Hz", "lower"),
    # the joints: a simulation's moves, joint track's cases, joint bode's response
    "following_error_rms": ("largest following error RMS", "increments", "higher"),
    "tracking_rms_error_mrad": ("RMS tracking error", "mrad", "higher"),
    "bandwidth_hz": ("-3 dB bandwidth", "Hz", "lower"),
}
#: the section a headline figure's regression links to (the others: comparison or bus)
HEADLINE_SECTION = {"following_error_rms": "joints", "tracking_rms_error_mrad": "tracking",
                    "bandwidth_hz": "bandwidth"}


@dataclass(slots=True)
class Table:
    """Text cells, ready for any renderer: a header row and data rows."""

    columns: list[str]
    rows: list[list[str]]
    caption: str = ""


@dataclass(slots=True)
class Section:
    id: str
    title: str
    intro: str = ""
    tables: list[Table] = field(default_factory=list)
    data: dict[str, Any] = field(default_factory=dict)  # the JSON of the section


@dataclass(slots=True)
class Source:
    """One measurement: a capture's analysis or the simulation, with its series (µs, s)."""

    label: str
    kind: str  # "capture" | "simulation"
    doc: dict[str, Any]
    round_trip_us: np.ndarray | None = None
    round_trip_t_s: np.ndarray | None = None  # x of "over time" (None: the pair's number)
    period_us: np.ndarray | None = None  # cycle periods of the cyclic stream
    dc_t_s: np.ndarray | None = None  # seconds since the cyclic run started
    dc_error_ns: np.ndarray | None = None
    timing: dict[str, Any] | None = None  # bus timing's document with this measured total
    #: --move/--trajectory: each moved joint's (s, following error in increments)
    following_error: dict[str, tuple[Any, Any]] = field(default_factory=dict)

    @property
    def headline(self) -> dict[str, float | None]:
        d = self.doc
        unusable = set(d.get("unusable_stats") or ())  # a capture's quantised timestamps
        rt_key = "round_trip_cyclic_us" if d.get("round_trip_cyclic_us") else "round_trip_us"
        rt = (d.get(rt_key) if rt_key not in unusable else None) or {}
        jitter = (d.get("cycle_jitter_us") if "cycle_period_us" not in unusable else None) or {}
        if self.kind == "simulation":
            rate = d.get("max_rate_hz")
        else:
            rate = self.timing["max_rate_hz"] if self.timing else None
        out = {
            "round_trip_p50_us": rt.get("median"),
            "round_trip_p99_us": rt.get("p99"),
            "cycle_jitter_us": jitter.get("std"),
            "lost_frames": d.get("lost_frames"),
            "max_rate_hz": round(rate, 3) if rate is not None else None,
        }
        if d.get("moves"):  # a simulation that moved joints
            from lolacli.report.joints import joints_data

            out["following_error_rms"] = joints_data(d["moves"])["largest_following_error_rms"]
        return out


@dataclass(slots=True)
class Report:
    verdict: str
    findings: list[dict[str, Any]]
    sections: list[Section]
    sources: list[Source]
    inputs: dict[str, Any]
    regressions: list[dict[str, Any]] = field(default_factory=list)
    gate: dict[str, Any] | None = None
    notes: list[str] = field(default_factory=list)
    joint_track: JointDoc | None = None
    joint_bode: JointDoc | None = None

    def headlines(self) -> dict[str, dict[str, float | None]]:
        """The headline figures by measurement: each source's, then joint track's cases
        ("joint track: <case>") and joint bode's bandwidth ("joint bode")."""
        out = {s.label: s.headline for s in self.sources}
        if self.joint_track is not None:
            for c in self.joint_track.doc["cases"]:
                out[f"joint track: {c['name']}"] = {
                    "tracking_rms_error_mrad": round(c["rms_error_rad"] * 1e3, 9)}
        if self.joint_bode is not None:
            out["joint bode"] = {"bandwidth_hz": self.joint_bode.doc.get("bandwidth_hz")}
        return out

    def section(self, id: str) -> Section | None:
        return next((s for s in self.sections if s.id == id), None)

    def to_dict(self) -> dict[str, Any]:
        return {
            "schema": SCHEMA,
            "verdict": self.verdict,
            "findings": self.findings,
            "sections": [s.id for s in self.sections],
            "regressions": self.regressions,
            "gate": self.gate,
            "headline": self.headlines(),
            "inputs": self.inputs,
            "notes": self.notes,
            "data": {s.id: s.data for s in self.sections if s.data},
        }


def build_report(
    *,
    eni: Eni | None = None,
    captures: Sequence[CaptureReport] = (),
    simulation: SimulationResult | None = None,
    baseline: dict[str, Any] | None = None,
    baseline_name: str = "baseline",
    tolerance_percent: float = 10.0,
    joint_track: JointDoc | None = None,
    joint_bode: JointDoc | None = None,
) -> Report:
    """The report over what was given (see the module docstring). ``captures`` analysed
    with ``keep_series=True`` get their plots; ``joint_track``/``joint_bode`` are ``joint
    track``'s and ``joint bode``'s documents (:func:`lolacli.report.joints.load_track`,
    ``load_bode``); ``baseline`` (an earlier report's JSON) turns on the regression gate:
    each headline figure worse than the baseline's by more than ``tolerance_percent`` is a
    regression and a failure."""
    sources = _sources(captures, simulation)
    notes: list[str] = []
    timing = _timing(eni, sources, notes)
    sections: list[Section] = []
    if eni is not None:
        sections.append(_network(eni))
    if timing is not None:
        sections.append(timing)
    if sources:
        sections.append(_bus(sources))
    if (dc := _dc(sources)) is not None:
        sections.append(dc)
    if simulation is not None and simulation.doc.get("sections_us"):
        sections.append(_software(simulation.doc))
    if len(sources) > 1:
        sections.append(_comparison(sources))
    sim = next((s for s in sources if s.kind == "simulation"), None)
    if sim is not None and sim.doc.get("moves"):
        sections.append(_joints(sim))
    if joint_track is not None:
        sections.append(_tracking(joint_track))
    if joint_bode is not None:
        sections.append(_bandwidth(joint_bode))
    present = {s.id for s in sections}
    findings = _findings(sources, timing, present) + _joint_findings(joint_track, joint_bode)
    inputs = _inputs(eni, sources) | {
        "joint_track": joint_track.path if joint_track is not None else None,
        "joint_bode": joint_bode.path if joint_bode is not None else None}
    report = Report("pass", _by_severity(findings), sections, sources, inputs, notes=notes,
                    joint_track=joint_track, joint_bode=joint_bode)
    if baseline is not None:
        from lolacli.report.gate import apply_gate

        apply_gate(report, baseline, baseline_name, tolerance_percent)
    failed = any(f["severity"] == Severity.FAILURE.value for f in report.findings)
    report.verdict = "fail" if failed else "pass"
    report.sections.insert(0, _verdict(report))
    return report


# ---------------------------------------------------------------- sources


def _sources(captures: Sequence[CaptureReport], simulation: SimulationResult | None
             ) -> list[Source]:
    import numpy as np

    out: list[Source] = []
    seen: set[str] = set()
    for c in captures:
        label = Path(c.path).name
        n = 2
        while label in seen:
            label, n = f"{Path(c.path).name} ({n})", n + 1
        seen.add(label)
        rt = c.round_trip_ns / 1000.0 if c.round_trip_ns is not None else None
        at = c.round_trip_at_ns
        t = (at - at[0]) / 1e9 if at is not None and rt is not None and at.size == rt.size \
            and at.size else None
        period = c.cycle_period_ns / 1000.0 if c.cycle_period_ns is not None else None
        out.append(Source(label, "capture", c.to_dict(), rt, t, period))
    if simulation is not None:
        s = simulation.series
        src = Source("simulation", "simulation", simulation.doc)
        if s is not None:
            src.round_trip_us = np.asarray(s.round_trip_ns, dtype=np.float64) / 1000.0
            src.period_us = np.diff(np.asarray(s.sent_ns, dtype=np.int64)) / 1000.0
            if s.dc_error_ns:
                dc = np.asarray(s.dc_error_ns, dtype=np.int64)
                src.dc_t_s = (dc[:, 0] - s.start_ns) / 1e9
                src.dc_error_ns = dc[:, 1]
            src.following_error = dict(s.following_error)
        out.append(src)
    return out


def _inputs(eni: Eni | None, sources: list[Source]) -> dict[str, Any]:
    sim = next((s.doc for s in sources if s.kind == "simulation"), None)
    inputs: dict[str, Any] = {
        "eni": eni.source if eni is not None else None,
        "captures": [s.doc["file"] for s in sources if s.kind == "capture"],
        "simulation": None,
    }
    if sim is not None:
        inputs["simulation"] = {
            k: sim.get(k) for k in ("rate_hz", "cycles", "simulated_s", "faults", "mode")
        } | {k: v for k, v in sim.items() if "host_latency" in k or k in ("pcap", "mcap")}
    return inputs


# ---------------------------------------------------------------- network


def _network(eni: Eni) -> Section:
    from lolacli.eni.report import datagram_where, inspect_report

    doc = inspect_report(eni)
    pi = doc["process_image"]
    frames = doc["cyclic_frames"]
    overview = Table(["", ""], [
        ["ENI", str(doc["source"])],
        ["slaves", str(doc["slave_count"])],
        ["cycle time", _opt(doc["cycle_time_us"], "µs")],
        ["process image", f"{number(pi['inputs_bytes'], 'B', 0)} in, "
                          f"{number(pi['outputs_bytes'], 'B', 0)} out, "
                          f"{plural(pi['variable_count'], 'variable')}"],
        ["cyclic frames", ", ".join(f"{number(f['frame_bytes'], 'B', 0)} "
                                    f"({number(f['wire_time_us'], 'µs')} on the wire)"
                                    for f in frames) or "none"],
    ])
    datagrams = Table(["frame", "datagram", "address", "length", "expected WKC"], [
        [str(i + 1), d["cmd"], datagram_where(c), number(d["length_bytes"], "B", 0),
         str(d["expected_wkc"]) if d["expected_wkc"] is not None else "not given"]
        for i, frame in enumerate(eni.cyclic_frames)
        for d, c in zip(frames[i]["datagrams"], frame.commands, strict=True)
    ], "Cyclic datagrams")
    slaves = Table(["#", "name", "station", "in", "out"], [
        [str(s["position"]), s["name"], station(s["station_address"]),
         number(s["inputs_bits"], "bit", 0), number(s["outputs_bits"], "bit", 0)]
        for s in doc["slaves"]
    ], "Slaves")
    data = {k: doc[k] for k in ("source", "slave_count", "cycle_time_us", "frames_bytes_total")}
    data["process_image"] = {k: pi[k] for k in ("inputs_bytes", "outputs_bytes",
                                               "variable_count")}
    data["cyclic_frames"] = frames
    data["slaves"] = [{k: s[k] for k in ("position", "name", "station_address", "inputs_bits",
                                         "outputs_bits")} for s in doc["slaves"]]
    return Section("network", TITLES["network"], "", [overview, datagrams, slaves], data)


def _opt(value: float | None, unit: str) -> str:
    return "not given" if value is None else number(value, unit)


# ---------------------------------------------------------------- timing model


def _timing(eni: Eni | None, sources: list[Source], notes: list[str]) -> Section | None:
    """``bus timing`` for each measurement (the a-priori model alone without one)."""
    from lolacli.timing.bus import Statistic, TimingRequest

    def read() -> Eni:
        assert eni is not None
        return eni

    warnings: list[str] = []
    eni_name = eni.source if eni is not None else None
    columns: list[tuple[str, dict[str, Any]]] = []
    for s in sources:
        def warn(message: str, label: str = s.label) -> None:
            warnings.append(f"{label}: {message}")

        try:
            if s.kind == "simulation":
                rt = s.doc.get("round_trip_us")
                if eni is None or not rt:
                    continue
                host = (s.doc.get("host_latency_us") or {}).get("mean", 0.0)
                request = TimingRequest(eni=eni_name, measured=f"{rt['median']}us",
                                        host_latency_us=host)
                doc = request.run(read, None, warn).doc
                doc["measured_from"] = "simulation: median round trip"
            else:
                request = TimingRequest(eni=eni_name, capture=s.doc["file"],
                                        statistic=Statistic.median)
                doc = request.run(read if eni is not None else None, s.doc, warn).doc
        except LolaError as exc:
            notes.append(f"timing model for {s.label}: {exc}")
            continue
        s.timing = doc
        columns.append((s.label, doc))
    if not columns:
        if eni is None:
            return None
        columns.append(("", TimingRequest(eni=eni_name).run(read, None, warnings.append).doc))
    sim = next((s.doc for s in sources if s.kind == "simulation"), None)
    section = Section("timing", TITLES["timing"], (
        "Round trip = wire time + slaves × per-slave delay + cable + host latency (the "
        "model of `bus timing`); the per-slave delay is calibrated from each measured "
        "total, and the maximum update rate is 1 / round trip, then with the software's "
        "time per cycle."), [_timing_table(columns, sim)])
    section.data = {"estimates": {label or "model": doc for label, doc in columns},
                    "warnings": warnings}
    return section


def _timing_table(columns: list[tuple[str, dict[str, Any]]], sim: dict[str, Any] | None
                  ) -> Table:
    first = columns[0][1]
    measured = [(label, doc) for label, doc in columns if doc["measured_total_us"] is not None]
    pred = first["prediction"]
    src = first["sources"]
    model_rows = [
        ("frame", number(first["frame_bytes"], "B", 0), src["frame_bytes"]),
        ("wire time", number(first["wire_time_us"], "µs"), "8 × frame / link rate"),
        ("with preamble and gap", number(first["wire_time_with_overhead_us"], "µs"),
         "+ 20 B (preamble 8 B, gap 12 B)"),
        ("slaves", str(first["slaves"]), src["slaves"]),
        ("cable, out and back", number(first["cable_delay_ns"], "ns", 0),
         f"{number(first['cable_m_per_segment'], 'm')} per slave, 5 ns/m"),
        ("host latency", number(first["host_latency_us"], "µs"), _host_source(sim)),
        ("per-slave delay", number(pred["per_slave_delay_ns"], "ns", 0),
         f"a priori: {pred['per_slave_delay_source']}"),
        ("predicted round trip", number(first["predicted_total_us"], "µs"), "model"),
        ("max rate, predicted", number(pred["max_rate_hz"], "Hz", 0), "1 / predicted"),
    ]
    head = ["quantity", "model"] + [label for label, _ in measured] + ["from"]
    blank = [""] * len(measured)
    rows = [[q, v, *blank, f] for q, v, f in model_rows]

    def per(key: str, unit: str, digits: int = 3) -> list[str]:
        return [number(doc[key], unit, digits) if doc.get(key) is not None else "–"
                for _, doc in measured]

    if measured:
        rows.append(["measured round trip", "", *per("measured_total_us", "µs"),
                     "; ".join(sorted({str(doc["measured_from"]) for _, doc in measured}))])
        rows.append(["calibrated per-slave delay", "",
                     *per("calibrated_per_slave_delay_ns", "ns", 0),
                     "(measured - wire - cable - host) / slaves"])
        rows.append(["max rate, round trip only", "", *per("max_rate_hz", "Hz", 0),
                     "1 / measured round trip"])
    if sim is not None and sim.get("software_us_per_cycle") is not None:
        cells = [number(sim["software_us_per_cycle"], "µs") if label == "simulation" else "–"
                 for label, _ in measured]
        rows.append(["software per cycle", "", *cells, "simulation: mean of its sections"])
        cells = [number(sim["max_rate_with_software_hz"], "Hz", 0) if label == "simulation"
                 else "–" for label, _ in measured]
        rows.append(["max rate with software", "", *cells,
                     "simulation: 1 / (round trip + software)"])
    return Table(head, rows)


def _host_source(sim: dict[str, Any] | None) -> str:
    """Where the model's host latency comes from: the simulation's draw, or none."""
    host = (sim or {}).get("host_latency_us")
    if not host:
        return "model input (none given)"
    return (f"simulation: --host-latency-us {host['mean']:g}:{host['std']:g} "
            f"({host.get('distribution', 'drawn')} mean)")


# ---------------------------------------------------------------- bus measurements


def _stat(d: dict[str, Any] | None, key: str, unit: str = "µs") -> str:
    if not d or d.get(key) is None:
        return "–"
    return number(float(d[key]), unit)


def _bus(sources: list[Source]) -> Section:
    head = ["figure", *[s.label for s in sources]]
    rows: list[list[str]] = []

    def row(name: str, cells: list[str]) -> None:
        rows.append([name, *cells])

    rts = [s.doc.get("round_trip_cyclic_us") or s.doc.get("round_trip_us") for s in sources]
    for key, name in (("median", "round trip p50"), ("p99", "round trip p99"),
                      ("mean", "round trip mean"), ("std", "round trip std"),
                      ("max", "round trip max")):
        row(name, [_stat(rt, key) for rt in rts])
    row("round trips", [str(rt["count"]) if rt else "none" for rt in rts])
    periods = [s.doc.get("cycle_period_us") for s in sources]
    row("cycle period mean", [_stat(p, "mean") for p in periods])
    jitters = [s.doc.get("cycle_jitter_us") for s in sources]
    row("cycle jitter (std)", [_stat(j, "std") for j in jitters])
    row("largest deviation from median",
        [_stat({"v": (j or {}).get("max_deviation", (j or {}).get(
            "max_deviation_from_median"))}, "v") for j in jitters])
    row("lost frames", [str(s.doc.get("lost_frames", "–")) for s in sources])
    row("late frames", [str(s.doc.get("late_frames") or 0) for s in sources])
    row("in flight at the end", [str(s.doc.get("in_flight_at_end", "–")) for s in sources])
    row("WKC mismatches", [f"{s.doc.get('wkc_mismatches', 0):,} of "
                           f"{s.doc.get('wkc_checked', 0):,} checked" for s in sources])
    unusable = [", ".join(s.doc.get("unusable_stats") or ()) or "none" for s in sources]
    if any(u != "none" for u in unusable):
        row("unusable (quantised or backward timestamps)", unusable)
    tables = [Table(head, rows, "Round trip, cycle and frames")]
    for s in sources:
        if s.kind == "capture":
            tables.extend(_capture_tables(s))
        else:
            states = s.doc.get("states") or {}
            tables.append(Table(["slave", "AL state at the end"],
                                [[name, state] for name, state in states.items()],
                                f"AL states: {s.label}"))
    data = {s.label: {k: s.doc.get(k) for k in (
        "round_trip_us", "round_trip_cyclic_us", "cycle_period_us", "cycle_jitter_us",
        "lost_frames", "late_frames", "in_flight_at_end", "wkc_mismatches", "wkc_checked")}
        for s in sources}
    return Section("bus", TITLES["bus"], (
        "What the capture or the simulation measured: round trip of each cyclic frame "
        "(histogram, CDF, over time), the cycle period and its jitter, frames lost, late "
        "or in flight, working counters per datagram and AL states."), tables, data)


def _capture_tables(s: Source) -> list[Table]:
    wkc = s.doc["wkc"]
    rows = []
    for d in wkc["datagrams"][:40]:
        where = (f"0x{d['logical_address']:08X}" if d["logical_address"] is not None
                 else f"{d['adp']}:0x{d['ado']:04X}" if d["adp"] is not None else "")
        observed = ", ".join(f"{o['wkc']}×{o['count']}" for o in d["observed"])
        rows.append([d["cmd"], where, str(d["expected"]), observed, str(d["mismatches"])])
    out = []
    if rows:
        more = len(wkc["datagrams"]) - len(rows)
        caption = f"WKC per datagram: {s.label} (reference: {wkc['reference']})" + (
            f"; {more} more in the JSON of capture analyze" if more > 0 else "")
        out.append(Table(["datagram", "address", "expected", "seen (WKC×n)", "mismatches"],
                         rows, caption))
    al = s.doc["al_status"]
    if al:
        out.append(Table(["station", "state", "last frame"], [
            [station(r["station"]) if r["station"] is not None else "broadcast", r["state"],
             str(r["last_frame"])] for r in al[:40]], f"AL states read: {s.label}"))
    return out


# ---------------------------------------------------------------- distributed clocks


def _dc(sources: list[Source]) -> Section | None:
    tables, data = [], {}
    for s in sources:
        d = s.doc
        if s.kind == "capture":
            dc = d["dc"]
            if not dc["drift_compensation_datagrams"] and not dc["system_time_difference_reads"]:
                continue
            data[s.label] = dc
            tables.append(Table(["", ""], [
                ["drift compensation datagrams", f"{dc['drift_compensation_datagrams']:,} in "
                 f"{dc['drift_compensation_bursts']:,} bursts"],
                ["system time difference reads", f"{dc['system_time_difference_reads']:,}"],
                ["largest |difference|", _opt(dc["system_time_difference_max_abs_ns"], "ns")],
                ["last difference", _opt(dc["system_time_difference_last_ns"], "ns")],
            ], s.label))
        elif d.get("dc_slaves") and s.dc_error_ns is not None and s.dc_t_s is not None:
            start = s.dc_error_ns[s.dc_t_s < 0]
            run = s.dc_error_ns[s.dc_t_s >= 0]
            data[s.label] = {"dc_slaves": d["dc_slaves"], "dc_reference": d["dc_reference"],
                             "dc_max_error_ns": d["dc_max_error_ns"]}
            tables.append(Table(["", ""], [
                ["DC slaves", f"{d['dc_slaves']} (reference: {d['dc_reference']})"],
                ["drift along the line", number(d["faults"]["drift_ppb"], "ppb", 0)],
                ["largest |error| at start-up",
                 number(int(start.max()), "ns", 0) if start.size else "not read"],
                ["largest |error| in operation", _opt(d["dc_max_error_ns"], "ns")],
                ["reads", f"{start.size:,} at start-up, {run.size:,} in operation"],
            ], s.label))
    if not tables:
        return None
    return Section("dc", TITLES["dc"], (
        "Offset of the slaves' clocks from the reference clock (register 0x092C, the "
        "system time difference) at start-up and in operation."), tables, data)


# ---------------------------------------------------------------- software cycle


def _software(doc: dict[str, Any]) -> Section:
    sections = doc["sections_us"]
    rows = [[name, s["thread"], number(s["mean"], "µs"), number(s["p99"], "µs"),
             number(s["max"], "µs")] for name, s in sections.items()]
    rows.append(["total (means)", "", number(doc["software_us_per_cycle"], "µs"), "", ""])
    table = Table(["section", "thread", "mean", "p99", "max"], rows)
    data = {"sections_us": sections, "software_us_per_cycle": doc["software_us_per_cycle"],
            "max_rate_with_software_hz": doc["max_rate_with_software_hz"],
            "bus_emulation_us": doc.get("bus_emulation_us")}
    return Section("software", TITLES["software"], (
        "Time the master spends in each section of a cycle (seed Fig. 7, Tables I–II), "
        "measured on this host."), [table], data)


# ---------------------------------------------------------------- side by side


def _comparison(sources: list[Source]) -> Section:
    base = sources[0].headline
    head = ["figure", *[s.label for s in sources]]
    rows = []
    for key, (name, unit, _worse) in HEADLINE.items():
        if not any(key in s.headline for s in sources):  # e.g. no simulation moved joints
            continue
        cells = []
        for i, s in enumerate(sources):
            v = s.headline.get(key)
            text = "–" if v is None else number(v, unit)
            b = base.get(key)
            if i and v is not None and b:
                text += f" ({100 * (v - b) / b:+.1f} %)"
            cells.append(text)
        rows.append([name, *cells])
    return Section("comparison", TITLES["comparison"], (
        f"The headline figures, one column per measurement; in brackets the change from "
        f"the first ({sources[0].label})."), [Table(head, rows)],
        {s.label: s.headline for s in sources})


# ---------------------------------------------------------------- joints


def _joints(sim: Source) -> Section:
    from lolacli.report.joints import joints_data, moves_rows

    moves = sim.doc["moves"]
    unit = moves[0]["unit"]
    table = Table(["slave", "joint", "distance", "duration", "error RMS", "error max"],
                  moves_rows(moves), f"Moves (inc: {unit}; error: set-point sent - actual "
                  "received)")
    return Section("joints", TITLES["joints"], (
        "The joints the simulation moved (--move/--trajectory): jerk-limited S-curves "
        "streamed in cyclic synchronous position, one set-point a cycle. Following error: "
        "the set-point the master sent minus the actual position it received in the same "
        "cycle (the bus's delay included), over each joint's motion; in the drive's "
        "increments (no encoder resolution is modelled, so no radians)."), [table],
        joints_data(moves))


def _tracking(track: JointDoc) -> Section:
    from lolacli.report.joints import tracking_data, tracking_rows

    d = track.doc
    t = d.get("trajectory") or {}
    walk = (f"a walking hip, {number(t['step_s'], 's')} steps, {t['steps']} measured"
            if {"step_s", "steps"} <= set(t) else "its trajectory")
    table = Table(["case", "control rate", "bus rate", "k_e", "RMS error", "max error",
                   "RMS change vs the first"], tracking_rows(d["cases"]),
                  f"Tracking error θd − θ of {d['joint']} (seed 000 Table III)")
    series = "" if all("error_series" in c for c in d["cases"]) else (
        " The document has no error series (joint track --series), so no figure.")
    return Section("tracking", TITLES["tracking"], (
        f"joint track ({track.path}): {d['joint']} on {walk}, with the standard velocity "
        "feed-forward at the control rate, with the learned k_e (k_vel,ff = 1 + k_e), and "
        "with a faster bus extrapolating the targets between control updates. Errors after "
        f"settling, every 0.1 ms drive period.{series}"), [table], tracking_data(track))


def _bandwidth(bode: JointDoc) -> Section:
    from lolacli.report.joints import bandwidth_data, bandwidth_rows

    return Section("bandwidth", TITLES["bandwidth"], (
        f"joint bode ({bode.path}): the closed loop's response from the central control's "
        "target to the joint angle, from a small-amplitude chirp through the bus (seed 000 "
        "Fig. 10); the bandwidth is where the gain falls for good below -3 dB."),
        [Table(["", ""], bandwidth_rows(bode))], bandwidth_data(bode))


# ---------------------------------------------------------------- findings and verdict


def _section_of(kind: str, present: set[str]) -> str:
    if kind.startswith("dc") and "dc" in present:
        return "dc"
    if kind.startswith(("move", "drive-fault")) and "joints" in present:
        return "joints"
    if kind.startswith("calibration") and "timing" in present:
        return "timing"
    return "bus" if "bus" in present else "verdict"


def _findings(sources: list[Source], timing: Section | None, present: set[str]
              ) -> list[dict[str, Any]]:
    out = []
    for s in sources:
        for f in s.doc.get("findings", []):
            out.append({**f, "source": s.label, "section": _section_of(f["kind"], present)})
    if timing is not None:
        for w in timing.data["warnings"]:
            out.append({**Finding("calibration", Severity.WARNING, w).to_dict(),
                        "source": "timing model", "section": "timing"})
    return out


def _joint_findings(track: JointDoc | None, bode: JointDoc | None) -> list[dict[str, Any]]:
    from lolacli.report.joints import bandwidth_findings, tracking_findings

    out = []
    if track is not None:
        out += [{**f.to_dict(), "source": "joint track", "section": "tracking"}
                for f in tracking_findings(track)]
    if bode is not None:
        out += [{**f.to_dict(), "source": "joint bode", "section": "bandwidth"}
                for f in bandwidth_findings(bode)]
    return out


def _by_severity(findings: list[dict[str, Any]]) -> list[dict[str, Any]]:
    order = {"failure": 0, "warning": 1, "info": 2}
    return sorted(findings, key=lambda f: order.get(f["severity"], 3))


def _verdict(report: Report) -> Section:
    counts = {k: sum(1 for f in report.findings if f["severity"] == k)
              for k in ("failure", "warning", "info")}
    intro = (f"{report.verdict.upper()}: {plural(counts['failure'], 'failure')}, "
             f"{plural(counts['warning'], 'warning')}, {counts['info']} info.")
    tables = []
    if report.findings:
        tables.append(Table(["severity", "source", "finding", "section"], [
            [f["severity"], f["source"], f["message"], f["section"]]
            for f in report.findings]))
    if report.gate is not None:
        tables.append(Table(["figure", "baseline", "now", "change", ""], [
            [c["figure"], _num(c["baseline"]), _num(c["value"]),
             "–" if c["change_percent"] is None else f"{c['change_percent']:+.1f} %",
             "WORSE" if c["worse"] else "ok"] for c in report.gate["compared"]],
            f"Regression gate against {report.gate['baseline']} "
            f"(tolerance {report.gate['tolerance_percent']:g} %)"))
    data = {"counts": counts, "notes": report.notes}
    return Section("verdict", TITLES["verdict"], intro, tables, data)


def _num(v: float | None) -> str:
    return "–" if v is None else f"{v:,.6g}"
