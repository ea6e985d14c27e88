"""The report of a simulation (``lolacli.simulate/1``, DESIGN.md) and its verdict."""

from __future__ import annotations

from typing import Any

from lolacli.devices.cia402 import ERROR_NAMES
from lolacli.emulator.line import ChainTiming
from lolacli.eni.model import Eni
from lolacli.errors import TransportError
from lolacli.findings import Finding, Findings, Severity, verdict
from lolacli.interrupt import Stop
from lolacli.master.core import SECTIONS, Master
from lolacli.simulate.application import Application
from lolacli.simulate.options import SimulateOptions, SimulationResult
from lolacli.text import plural, transition_text
from lolacli.timing.model import (
    INTER_FRAME_GAP_BYTES,
    LINK_100_MBIT_S,
    PREAMBLE_SFD_BYTES,
    wire_time_ns,
)
from lolacli.timing.stats import summarize_array
from lolacli.wire.commands import Command
from lolacli.wire.frame import Datagram
from lolacli.wire.registers import Register, al_state_name

SCHEMA = "lolacli.simulate/1"


def result(
    doc: dict[str, Any],
    options: SimulateOptions,
    master: Master,
    app: Application,
    interrupted: bool,
    stop: Stop | None,
) -> SimulationResult:
    doc["interrupted"] = interrupted
    found = findings(doc, options, master, app, stop if interrupted else None)
    doc["verdict"] = verdict(found)
    doc["findings"] = [f.to_dict() for f in found]
    return SimulationResult(doc, doc["verdict"] == "fail", interrupted)


def findings(
    doc: dict[str, Any],
    options: SimulateOptions,
    master: Master,
    app: Application,
    stopped: Stop | None,
) -> list[Finding]:
    """The verdict's findings (the one model of :mod:`lolacli.findings`)."""
    out = Findings()
    stats = master.stats
    fail, warn = Severity.FAILURE, Severity.WARNING
    for r in master.refusals:
        code = "" if r.al_status_code is None else f", AL status code 0x{r.al_status_code:04X}"
        out.add(
            "refused",
            fail,
            f"slave {r.position} ({r.slave}) refused "
            f"{transition_text(r.transition)}{code}: {r.text}",
            slave=r.position,
        )
    refused = {r.position for r in master.refusals}
    for slave in master.eni.slaves:
        state = app.final_states.get(slave.position, "no answer")
        if state != "OP" and slave.position not in refused:
            out.add(
                "not-op",
                fail,
                f"slave {slave.position} ({slave.name}) ended in {state}, not OP",
                slave=slave.position,
            )
    _overrun_finding(out, doc, master, options, app)
    lost, late = doc["lost_frames"], doc["late_frames"] or 0
    over = lost + late > options.max_lost
    if lost:
        cyclic = doc["cyclic_lost_frames"]
        out.add(
            "lost",
            fail if over else warn,
            f"{lost:,} frames never came back ({cyclic:,} of them cyclic; threshold "
            f"--max-lost {options.max_lost})",
            cycles=app.run_cycles(master.lost_cycles()),
            count=lost,
        )
    if late:
        out.add(
            "late",
            fail if over else warn,
            f"{late:,} cyclic frames came back after their cycle had ended: those cycles "
            "ran without their inputs",
            cycles=app.run_cycles(stats.late_at),
            count=late,
        )
    if doc["wkc_mismatches"]:
        out.add(
            "wkc-mismatch",
            fail if doc["wkc_mismatches"] > options.max_wkc_mismatches else warn,
            f"{doc['wkc_mismatches']:,} of {doc['wkc_checked']:,} working counters differed"
            f" from the ENI's <Cnt>, in {doc['cycles_with_wkc_mismatch']:,} cycles (threshold "
            f"--max-wkc-mismatches {options.max_wkc_mismatches})",
            cycles=app.run_cycles(stats.mismatch_at),
            count=doc["wkc_mismatches"],
        )
    if doc["drives_enabled"] < doc["drives"]:
        out.add(
            "drives-disabled",
            warn,
            f"{doc['drives'] - doc['drives_enabled']} of {doc['drives']} drives were not "
            "enabled (CiA 402 state machine short of Operation enabled)",
        )
    for fault in doc["drive_faults"]:
        code = fault["error_code"]
        if code is None:
            what = "its error code (0x603F) could not be read"
        else:
            named = ERROR_NAMES.get(code)
            what = f"error code 0x{code:04X}" + (f" ({named})" if named else "") + " in 0x603F"
        out.add(
            "drive-fault",
            fail,
            f"drive at slave {fault['slave']} ({fault['name']}) went to fault "
            f"{plural(fault['faults'], 'time')} (CiA 402): {what}",
            slave=fault["slave"],
            count=fault["faults"],
        )
    for move in doc["moves"] or ():
        if not move["complete"]:
            started = move["duration_s"] is not None
            out.add(
                "move-incomplete",
                warn,
                f"the move of slave {move['slave']} ({move['joint']}) "
                + ("did not end within the run (its profile takes "
                   f"{move['duration_s']:g} s)" if started else
                   "never started: the drives were never all enabled"),
                slave=move["slave"],
            )
    for name, value in doc["watch"].items():
        shown = f"{value:.6g}" if isinstance(value, float) else value
        out.add("watch", Severity.INFO, f"{name} = {shown} (last value)")
    if stopped is not None:
        signame = "SIGTERM" if stopped.exit_code == 143 else "SIGINT"
        out.add(
            "interrupted",
            warn,
            f"stopped by {signame} after {doc['cycles']:,} cycles of {options.cycles:,}: the "
            "figures cover the cycles run",
        )
    return out.ordered()


def _overrun_finding(
    out: Findings,
    doc: dict[str, Any],
    master: Master,
    options: SimulateOptions,
    app: Application,
) -> None:
    """Cycles not kept: the slots skipped and the cycles sent over half a cycle late, and
    why — a bus too slow for the rate (with the rate it holds), or the host."""
    skipped, overruns = doc["skipped_cycles"] or 0, doc["overruns"] or 0
    if not skipped and not overruns:
        return
    cycle_us = master.cycle_time_ns / 1000
    rt = doc["round_trip_us"]
    why = ""
    holds = doc["max_rate_with_software_hz"] or doc["max_rate_hz"]
    if rt is not None and doc["max_rate_hz"]:
        why = (
            f"; a round trip takes {rt['median']:g} µs, so this bus holds at most "
            f"{doc['max_rate_hz']:,} Hz"
        )
        if doc["max_rate_with_software_hz"]:
            why += f" ({doc['max_rate_with_software_hz']:,} Hz with the software)"
        if holds and holds >= doc["rate_hz"]:
            why += ": the cycles were lost to the host (scheduling, load), not to the bus"
    severity = Severity.FAILURE if skipped + overruns > options.max_overruns else Severity.WARNING
    out.add(
        "overrun",
        severity,
        f"the cycle of {cycle_us:g} µs ({doc['rate_hz']:,g} Hz) was not kept: {skipped:,} "
        f"cycle slots skipped, {overruns:,} cycles sent over half a cycle late (threshold "
        f"--max-overruns {options.max_overruns}){why}",
        cycles=app.run_cycles(master.stats.skipped_at),
        count=skipped + overruns,
    )


#: keys only a run on a live bus fills (null in virtual time)
NO_LIVE_KEYS: dict[str, Any] = {
    "mode": "virtual",
    "iface": None,
    "wakeup_lateness_us": None,
    "scheduling": None,
    "load": None,
    "master_cpu_percent": None,
    "kernel_timestamps": None,
}


def timing(master: Master, clock: Any, skipped: int) -> dict[str, Any]:
    """Cycle period, jitter and lateness as the frames left, in both times; frames late
    and never back as the master saw them (a late one came back after it had stopped
    waiting: the cycle ran without its inputs)."""
    stats = master.stats
    doc: dict[str, Any] = clock.report(master.cycle_time_ns)
    doc["late_frames"] = stats.late_frames
    doc["never_returned_frames"] = stats.cyclic_lost
    doc["skipped_cycles"] = skipped
    return doc


def variation(eni: Eni, options: SimulateOptions, line: ChainTiming | None) -> dict[str, Any]:
    """What made the round trip (:mod:`lolacli.simulate.variation`): ``host_latency_us``
    (null: none modelled, the round trip is the bus alone) and ``timing_sources``, each
    input with its source and the formula's round trip from them."""
    from lolacli.simulate.variation import timing_sources

    latency = options.host_latency
    sources = timing_sources(eni, line, options.forwarding, options.cable_m, latency)
    sources["seed"] = options.seed if latency is not None else None
    return {
        "host_latency_us": sources["host_latency"],
        "timing_sources": sources,
    }


#: a live bus measures what the simulation models: no inputs to state
LIVE_VARIATION: dict[str, Any] = {"host_latency_us": None, "timing_sources": None}


def live_states(master: Master) -> dict[int, str]:
    """AL state of every slave at the end of a live run, read in one frame while the
    master still cycles (read after the cycling stops, one frame per slave, a slow host
    takes long enough for the slaves' process-data watchdogs to drop them to SAFEOP)."""
    try:
        got = master.al_states()
    except TransportError:
        return {s.position: "no answer" for s in master.eni.slaves}
    return {
        s.position: al_state_name(status) if status is not None else "no answer"
        for s, (_position, status) in zip(master.eni.slaves, got, strict=True)
    }


def final_states(master: Master) -> dict[int, str]:
    """AL state of every slave at the end (the capture's closing frames): after twice the
    frame timeout, so every earlier frame is older than a capture reader's timeout."""
    master.idle(2 * master.options.frame_timeout_ns)
    out: dict[int, str] = {}
    for s in master.eni.slaves:
        read = Datagram.physical(Command.FPRD, s.station_address, Register.AL_STATUS, 2)
        try:
            got = master.exchange([read], retries=20)[0]
        except TransportError:
            out[s.position] = "no answer"
            continue
        out[s.position] = al_state_name(got.data[0]) if got.wkc == 1 else "no answer"
    return out


def report(
    eni: Eni,
    options: SimulateOptions,
    master: Master,
    app: Application,
    states: dict[int, str],
    wall_s: float,
    start_ns: int,
    recorders: tuple[Any, Any],
) -> dict[str, Any]:
    stats = master.stats
    frame = eni.cyclic_frames[0]
    n_bytes = frame.frame_bytes
    rt = summarize_array(stats.round_trip_ns)
    sections: dict[str, Any] = {}
    software_ns = 0.0
    first = app.first_cycle
    timed_from = first - (stats.cycles - len(master.sections_ns["rx"]))
    planner = app.planner_ns
    for name, thread in SECTIONS:
        values: Any = master.sections_ns[name][timed_from:]
        planned = None
        if name == "control" and planner and len(planner) == len(master.sections_ns[name]):
            # the planner runs in the control hooks: its own section, out of control's
            import numpy as np

            planned = np.asarray(planner[timed_from:], dtype=np.int64)
            values = np.asarray(values, dtype=np.int64) - planned
        s = summarize_array(values)
        if s is not None:
            sections[name] = {"thread": thread, **s.to_dict(scale=1e-3)}
            software_ns += s.mean
        p = summarize_array(planned) if planned is not None else None
        if p is not None:
            sections["planner"] = {"thread": "main", **p.to_dict(scale=1e-3)}
            software_ns += p.mean
    run_cycles = (stats.cycles if app.last_cycle is None else app.last_cycle) - first
    simulated_s = run_cycles * master.cycle_time_ns / 1e9
    emulation = summarize_array(master.bus_emulation_ns[timed_from:])
    # the rate the bus holds in a typical cycle: the median round trip (late frames that
    # waited behind others in a queue would drag a mean far from it)
    rt_typical = rt.median if rt is not None else None
    dc_errors = [e for t, e in stats.dc_errors_ns if t >= start_ns]
    pcap, mcap = recorders
    return {
        "schema": SCHEMA,
        "eni": eni.source,
        "rate_hz": options.rate_hz,
        "cycle_time_us": master.cycle_time_ns / 1000,
        "cycles": run_cycles,
        "startup_cycles": first,
        "slaves": len(eni.slaves),
        "frame_bytes": n_bytes,
        "wire_time_us": wire_time_ns(n_bytes, LINK_100_MBIT_S) / 1000,
        "wire_time_with_overhead_us": wire_time_ns(
            n_bytes + PREAMBLE_SFD_BYTES + INTER_FRAME_GAP_BYTES, LINK_100_MBIT_S
        )
        / 1000,
        "round_trip_us": rt.to_dict(scale=1e-3) if rt is not None else None,
        "wkc_mismatches": stats.wkc_mismatches,
        "wkc_checked": stats.wkc_checked,
        "cycles_with_wkc_mismatch": stats.cycles_with_mismatch,
        "lost_frames": stats.frames_lost,
        "cyclic_lost_frames": stats.cyclic_lost,
        "frames_sent": stats.frames_sent,
        "cyclic_frames": stats.cyclic_frames,
        "acyclic_frames": stats.acyclic_frames,
        "dc_max_error_ns": max(dc_errors) if dc_errors else None,
        "dc_slaves": len(master.dc_slaves),
        "dc_reference": master.dc_reference.name if master.dc_reference else None,
        "sections_us": sections,
        "software_us_per_cycle": round(software_ns / 1000, 3) if sections else None,
        "bus_emulation_us": emulation.to_dict(scale=1e-3) if emulation is not None else None,
        "max_rate_hz": round(1e9 / rt_typical) if rt_typical else None,
        "max_rate_with_software_hz": round(1e9 / (rt_typical + software_ns))
        if rt_typical and sections
        else None,
        "realtime_factor": round(simulated_s / wall_s, 3) if wall_s > 0 else None,
        "simulated_s": simulated_s,
        "wall_s": round(wall_s, 3),
        "refusals": [r.to_dict() for r in master.refusals],
        "states": {s.name: states.get(s.position, "no answer") for s in eni.slaves},
        "drives": len(app.drives),
        "drives_enabled": sum(1 for d in app.drives if d.enabled),
        "drive_faults": app.drive_faults,
        "moves": _moves(master, app, options),
        "joints": _joints(master, app, options),
        "can_gateway": app.sensor_ages.report() if app.sensor_ages is not None else None,
        "watch": {name: _jsonable(v.value) for name, v in app.watch.items()},
        "faults": {
            "drop_p": options.drop_probability,
            "stuck_safeop": list(options.stuck_safeop),
            "link_down": list(options.link_down) if options.link_down else None,
            "drift_ppb": options.drift_ppb,
            "seed": options.seed,
        },
        "pcap": {"path": pcap.path, "frames": pcap.frames} if pcap is not None else None,
        "mcap": {"path": mcap.path, "messages": mcap.messages, "channels": dict(mcap.topics)}
        if mcap is not None else None,
        "shm": options.shm,
    }


def _moves(
    master: Master, app: Application, options: SimulateOptions
) -> list[dict[str, Any]] | None:
    """Each moved joint's move and following error (None without --move/--trajectory),
    with the load behind its drive: ``joint`` (--joint-model) or ``kinematic``."""
    if app.moves is None:
        return None
    positions = {s.name: s.position for s in master.eni.slaves}
    names = [d.slave for d in app.drives]
    moves = app.moves.report(names, [positions[n] for n in names])
    for m in moves:
        m["load"] = "joint" if options.joint(m["joint"]) is not None else "kinematic"
    return moves


def _joints(master: Master, app: Application, options: SimulateOptions) -> dict[str, Any] | None:
    """--joint-model: the file, the drives with a joint behind them and their velocity
    feed-forward's k_e (k_vel,ff = 1 + k_e) (None without)."""
    if not options.joints:
        return None
    names = [d.slave for d in app.drives]
    return {"file": options.joints_source,
            "drives": [n for n in names if options.joint(n) is not None],
            "k_e": options.k_e, "kvel_ff": 1.0 + options.k_e}


def _jsonable(value: Any) -> Any:
    return value.hex() if isinstance(value, bytes) else value
