"""`bus simulate` at the edges: rates the bus cannot hold end in bounded time and memory
with a verdict that names the rate the bus holds; Ctrl-C and SIGTERM stop it within a
second with the report of the cycles run; options no bus can have are refused in one
line. Each run is a process of its own, as a user runs it (the CLI at its defaults)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
#: the LOLA chain's round trip in the emulator (25 slaves, 846 B): 92.93 µs
LOLA_MAX_RATE = "10,761 Hz"
DURATION_S = 2.0
#: a run's start-up (imports, ENI, bring-up) on a loaded 2-core CI host, generously
STARTUP_S = 6.0
MAX_RSS_KB = 200 * 1024


#: runs ARGV and writes its peak RSS (KiB) to the file named first. A process forked from
#: the test's own (large) one keeps that one's peak as its own across exec, so the
#: command is started by this small process instead.
_PEAK = (
    "import os, subprocess, sys\n"
    "proc = subprocess.Popen(sys.argv[2:])\n"
    "_pid, status, usage = os.wait4(proc.pid, 0)\n"
    "open(sys.argv[1], 'w').write(str(usage.ru_maxrss))\n"
    "sys.exit(os.waitstatus_to_exitcode(status))\n"
)


def _run(*args: str) -> tuple[int, dict, str, float, int]:
    """Exit code, JSON, stderr, wall seconds and peak RSS (KiB) of one CLI process."""
    with tempfile.TemporaryDirectory() as tmp:
        peak = Path(tmp) / "peak"
        argv = [sys.executable, "-c", _PEAK, str(peak), sys.executable, "-m", "lolacli",
                "bus", "simulate", *args, "-q", "-f", "json"]
        t0 = time.monotonic()
        done = subprocess.run(argv, cwd=ROOT, capture_output=True, timeout=120)
        wall = time.monotonic() - t0
        rss = int(peak.read_text())
    return done.returncode, json.loads(done.stdout or b"{}"), done.stderr.decode(), wall, rss


@pytest.mark.slow
@pytest.mark.parametrize(
    ("rate", "extra", "holds"),
    [
        ("2000", (), True),
        ("8000", (), True),
        ("20000", (), False),
        ("100000", (), False),
        ("20000", ("--drop-p", "0.05"), False),
        ("100000", ("--link-down", "12@0.5s"), False),
        ("2000", ("--drop-p", "1"), None),  # nothing ever comes back: exit 4 at once
    ],
)
def test_every_rate_ends_in_bounded_time_and_memory(rate: str, extra: tuple[str, ...],
                                                    holds: bool | None) -> None:
    code, doc, err, wall, rss = _run("--rate", rate, "--duration", f"{DURATION_S}s", *extra)
    assert wall < 2 * DURATION_S + STARTUP_S, (rate, extra, wall)
    assert rss < MAX_RSS_KB, (rate, extra, rss)
    if holds is None:
        assert code == 4 and err.count("\n") == 1 and "no answer" in err, err
        return
    assert doc["schema"] == "lolacli.simulate/1"
    kinds = {f["kind"] for f in doc["findings"] if f["severity"] == "failure"}
    if holds:
        assert (code, doc["verdict"]) == (0, "pass"), doc["findings"]
        assert doc["skipped_cycles"] == 0 and doc["late_frames"] == 0
        return
    assert (code, doc["verdict"]) == (1, "fail")
    assert "overrun" in kinds and "late" in kinds, doc["findings"]
    overrun = next(f for f in doc["findings"] if f["kind"] == "overrun")
    # the rate the whole line holds; a line cut after slave 12 answers sooner
    holds_at = LOLA_MAX_RATE if "--link-down" not in extra else "this bus holds at most"
    assert holds_at in overrun["message"], overrun
    assert overrun["cycles"] and overrun["count"] > 0
    # the slots of the whole duration were scheduled: run plus skipped
    slots = doc["cycles"] + doc["skipped_cycles"]
    assert abs(slots - float(rate) * DURATION_S) <= 1, (slots, rate)
    # every cyclic frame is accounted for: on time, late or never back
    if not extra:
        assert doc["lost_frames"] == 0 and doc["late_frames"] > 0


def _stop_after(sig: int, tmp: Path, *args: str) -> tuple[int, dict, str, float]:
    """Start a run, send ``sig`` once it cycles (its recording has grown past 1 MB), and
    return exit code, JSON, stderr and the seconds from the signal to the exit."""
    pcap = tmp / "run.pcapng"
    argv = [sys.executable, "-m", "lolacli", "bus", "simulate", *args, "--pcap", str(pcap),
            "-q", "-f", "json"]
    proc = subprocess.Popen(argv, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 60
    while not (pcap.exists() and pcap.stat().st_size > 1_000_000):
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.05)
    t0 = time.monotonic()
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=30)
    return proc.returncode, json.loads(out or b"{}"), err.decode(), time.monotonic() - t0


@pytest.mark.slow
@pytest.mark.parametrize(("sig", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_stops_a_run_the_bus_cannot_hold_within_a_second(
    sig: int, code: int, tmp_path: Path
) -> None:
    got, doc, err, took = _stop_after(sig, tmp_path, "--rate", "20000", "--duration", "600s")
    assert got == code, err
    assert took < 1.0, took
    assert doc["interrupted"] is True and doc["verdict"] == "fail"
    stopped = next(f for f in doc["findings"] if f["kind"] == "interrupted")
    assert ("SIGTERM" if sig == signal.SIGTERM else "SIGINT") in stopped["message"]
    assert 0 < doc["cycles"] < 20000 * 600
    assert doc["pcap"]["frames"] > 0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--cycles", "0"), "--cycles"),
        (("--duration", "0.1ms"), "--cycles 0: expected 1 to 20,000,000 cycles"),
        (("--duration", "-3s"), "--duration"),
        (("--rate", "0"), "--rate 0: expected 1 to 100000 Hz"),
        (("--rate", "200000"), "--rate 200000: expected 1 to 100000 Hz"),
        (("--drift-ppb", "100000000000"), "--drift-ppb 100000000000: expected -1,000,000"),
        (("--link-down", "3@20s"), "--link-down 3@20s: after the run ends (10 s of cycles)"),
        (("--link-down", "99"), "--link-down 99: expected 0 (at the master) to 25"),
        (("--stuck-safeop", "26"), "--stuck-safeop 26: expected a slave position 1 to 25"),
        (("--drop-p", "1.5"), "--drop-p"),
        (("--cycles", "30000000"), "expected 1 to 20,000,000 cycles"),
    ],
)
def test_values_no_bus_can_have_are_refused_in_one_line(args: tuple[str, ...],
                                                        message: str) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "lolacli", "bus", "simulate", *args],
        cwd=ROOT, capture_output=True, text=True, timeout=60,
    )
    assert done.returncode == 2, done.stderr
    assert message in done.stderr and done.stderr.count("\n") == 1, done.stderr
    assert "Traceback" not in done.stderr and done.stdout == ""


def test_debug_shows_the_traceback_and_keeps_the_exit_code() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "lolacli", "bus", "simulate", "--rate", "0"],
        cwd=ROOT, capture_output=True, text=True, timeout=60,
        env={**os.environ, "LOLACLI_DEBUG": "1"},
    )
    assert done.returncode == 2
    assert "Traceback" in done.stderr and "UsageError" in done.stderr
