"""`bus simulate --iface`: our master in real time against `bus emulate` over a veth pair
(separate processes). CI runs a short run with generous thresholds (a loaded 2-core
host); the 20,000-cycle measurement is benchmarks/simulate_realtime.py. Needs root."""

from __future__ import annotations

import gc
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from lolacli.files import load_eni
from lolacli.simulate import SimulateOptions, simulate
from tests.live import LOLA, ROOT, inside, run, run_json, start_emulator, stop_emulator

pytestmark = [pytest.mark.root, pytest.mark.slow]
CYCLE_US = 500.0


def test_holds_2khz_against_bus_emulate(bus, tmp_path: Path) -> None:
    pcap = tmp_path / "live.pcapng"
    proc = start_emulator(bus)
    try:
        code, doc, err = run_json(
            "bus",
            "simulate",
            "--iface",
            bus.master,
            "--rate",
            "2000",
            "--cycles",
            "2000",
            "--max-lost",
            "200",
            "--max-wkc-mismatches",
            "200",
            "--max-overruns",
            "200",
            "--pcap",
            str(pcap),
            bus=bus,
        )
    finally:
        stop_emulator(proc)
    assert code == 0, err
    # --cycles 2000 are 2000 slots of the schedule: a slot a late cycle ran past is
    # skipped (a loaded host), not made up for
    assert (doc["mode"], doc["iface"]) == ("realtime", bus.master)
    assert doc["cycles"] + doc["skipped_cycles"] == 2000 and doc["skipped_cycles"] <= 200
    assert doc["kernel_timestamps"] is True
    period = doc["cycle_period_us"]
    assert period["count"] == doc["cyclic_frames_timed"] - 1 >= 1999 - doc["skipped_cycles"]
    assert abs(period["median"] - CYCLE_US) < 25
    assert abs(period["mean"] - CYCLE_US) < 0.05 * CYCLE_US
    assert doc["round_trip_us"]["median"] < CYCLE_US
    assert doc["lost_frames"] <= 200 and doc["wkc_mismatches"] <= 200
    assert doc["refusals"] == [] and set(doc["states"].values()) == {"OP"}, doc["states"]
    assert doc["drives"] == 21 and doc["drives_enabled"] >= 18
    sched = doc["scheduling"]
    assert sched["policy"] == "SCHED_FIFO" and sched["priority"] == 80, sched
    assert sched["busy_wait_us"] == 200 and sched["gc_disabled"] is True
    assert doc["load"]["before"]["cpus"] == os.cpu_count()
    assert 0 < doc["master_cpu_percent"] <= 110
    assert doc["wakeup_lateness_us"]["median"] < 50  # busy-waited: on time to the µs
    # capture analyze reads the live recording back to the same cycle period
    ana = run("capture", "analyze", str(pcap), "--eni", str(LOLA), "--format", "json")
    assert ana.returncode in (0, 1), ana.stderr
    analyzed = json.loads(ana.stdout)
    assert analyzed["malformed_frames"] == 0
    assert abs(analyzed["cycle_period_us"]["median"] - period["median"]) < 5
    assert analyzed["pairs"] >= doc["cycles"] - doc["lost_frames"]
    # a frame capture analyze never saw return is one our master counted lost too
    assert analyzed["lost_frames"] <= doc["lost_frames"]


def test_scheduling_and_gc_are_put_back_after_a_run(bus) -> None:
    """The library call in this very process: SCHED_FIFO and the disabled collector
    last only as long as the run."""
    before = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority, gc.isenabled())
    proc = start_emulator(bus)
    try:
        with inside(bus):
            options = SimulateOptions(
                iface=bus.master, cycles=200, realtime_priority=10, max_lost=200
            )
            result = simulate(load_eni(LOLA), options)
    finally:
        stop_emulator(proc)
    assert result.doc["scheduling"]["policy"] == "SCHED_FIFO"
    assert result.doc["scheduling"]["priority"] == 10
    assert result.doc["cycles"] + result.doc["skipped_cycles"] == 200  # 200 slots
    assert (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority, gc.isenabled()) == before


def test_the_emulators_faults_are_refused_on_a_live_bus() -> None:
    for extra, message in (
        (("--drop-p", "0.1"), "--drop-p: faults of the emulated chain"),
        (("--stuck-safeop", "3", "--link-down", "4"), "--stuck-safeop, --link-down: faults"),
        (("--busy-wait-us", "600"), "--busy-wait-us 600: expected 0 to one cycle time"),
        (("--pace",), "--pace: a live bus runs in real time anyway"),
    ):
        done = run("bus", "simulate", "--iface", "lo", "--cycles", "10", *extra)
        assert done.returncode == 2, (extra, done.stderr)
        assert message in done.stderr and done.stderr.count("\n") == 1


def test_no_bus_behind_the_interface_is_exit_4(bus) -> None:
    done = run("bus", "simulate", "--iface", bus.master, "--cycles", "10", bus=bus)
    assert done.returncode == 4
    assert done.stderr.startswith("lolacli: error: no answer to ")
    assert done.stderr.count("\n") == 1


def test_a_rate_the_bus_cannot_hold_ends_in_time_with_a_verdict(bus) -> None:
    """20 kHz over veth: frames come back late or not at all; the run still ends after
    its duration, and the verdict names the cycles not kept."""
    proc = start_emulator(bus)
    try:
        t0 = time.monotonic()
        code, doc, err = run_json(
            "bus", "simulate", "--iface", bus.master, "--rate", "20000", "--duration", "2s",
            bus=bus, timeout=60,
        )
        wall = time.monotonic() - t0
    finally:
        stop_emulator(proc)
    assert wall < 2 * 2.0 + 6.0, wall  # twice the duration plus start-up
    assert (code, doc["verdict"]) == (1, "fail"), err
    assert doc["cycles"] + doc["skipped_cycles"] == 40000
    overrun = next(f for f in doc["findings"] if f["kind"] == "overrun")
    assert "holds at most" in overrun["message"] and overrun["severity"] == "failure"


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_stops_a_live_run_within_a_second(
    bus, sig: int, code: int, tmp_path: Path
) -> None:
    proc = start_emulator(bus)
    pcap = tmp_path / "live.pcapng"
    try:
        run_proc = subprocess.Popen(
            bus.command(sys.executable, "-m", "lolacli", "bus", "simulate", "--iface",
                        bus.master, "--duration", "600s", "--pcap", str(pcap), "-f", "json"),
            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )
        deadline = time.monotonic() + 60
        while not (pcap.exists() and pcap.stat().st_size > 1_000_000):  # up and cycling
            assert run_proc.poll() is None and time.monotonic() < deadline, (
                run_proc.communicate()
            )
            time.sleep(0.05)
        t0 = time.monotonic()
        run_proc.send_signal(sig)
        out, err = run_proc.communicate(timeout=30)
        took = time.monotonic() - t0
    finally:
        stop_emulator(proc)
    assert run_proc.returncode == code, err
    assert took < 1.0, took
    doc = json.loads(out)
    assert doc["interrupted"] is True and doc["cycles"] > 0 and doc["mode"] == "realtime"
    assert any(f["kind"] == "interrupted" for f in doc["findings"])


def test_a_signal_stops_a_slow_live_rate_within_a_second(bus) -> None:
    """At 1 Hz a cycle waits a whole second: the wait itself ends at a stop."""
    proc = start_emulator(bus)
    try:
        run_proc = subprocess.Popen(
            bus.command(sys.executable, "-m", "lolacli", "bus", "simulate", "--iface",
                        bus.master, "--rate", "1", "--duration", "600s", "-f", "json"),
            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )
        time.sleep(4.0)  # in the bring-up or the cyclic run: either stops at once
        assert run_proc.poll() is None, run_proc.communicate()
        t0 = time.monotonic()
        run_proc.send_signal(signal.SIGINT)
        _out, err = run_proc.communicate(timeout=30)
        took = time.monotonic() - t0
    finally:
        stop_emulator(proc)
    assert run_proc.returncode == 130, err
    assert took < 1.0, took
