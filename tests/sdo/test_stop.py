"""Ctrl-C and SIGTERM during ``sdo`` commands that wait on a bus: they stop within a
second with exit 130/143, ``sdo check`` with the results of the items done so far, and
``sdo serve`` (a server: stopping is how it ends) closes its nodes and exits the same
way (DESIGN's exit-code table).

The waits are real: a CANopen node ID nobody answers on python-can's virtual bus
(tests/sdo/blocking.py runs the nodes and the command in one process), with a timeout
of 30 s. The live-bus equivalents (a veth pair with nothing at the other end) are in
test_live_bus.py.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from lolacli.cli.main import app

ROOT = Path(__file__).resolve().parents[2]
#: node 16 answers (the gateway IMU's EDS); node 99 does not
CHECK = """\
slave: 16
reads:
  - {object: "0x1000", expect: 0x0000019A}
  - {object: "0x1008", expect: "LOLA IMU (CAN gateway)"}
  - {slave: 99, object: "0x1000", expect: 1}
  - {object: "0x1018:01", expect: 0xE0000001}
"""


def _spawn(*args: str) -> subprocess.Popen[str]:
    env = dict(os.environ, PYTHONPATH=str(ROOT), COLUMNS="80")
    return subprocess.Popen(
        [sys.executable, "-m", "tests.sdo.blocking", *args],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _stop(proc: subprocess.Popen[str], signum: int) -> tuple[float, str, str]:
    """Send ``signum``; (seconds until the process ended, the rest of stdout, stderr)."""
    start = time.monotonic()
    proc.send_signal(signum)
    try:
        out, err = proc.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        raise AssertionError(f"still running 20 s after {signum}: {err}") from None
    return time.monotonic() - start, out, err


@pytest.mark.parametrize(("signum", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_check_waiting_on_a_node_stops_with_its_results(tmp_path, signum, code) -> None:
    path = tmp_path / "gateway.yaml"
    path.write_text(CHECK)
    channel = f"lolacli-stop-{os.getpid()}-{signum}"
    can = ["--can", channel, "--interface", "virtual", "--timeout", "30"]
    proc = _spawn(channel, "sdo", "check", str(path), *can)
    assert proc.stdout is not None
    done = [proc.stdout.readline() for _ in range(2)]  # each result as it is made
    assert [line.split()[:4] for line in done] == [
        ["ok", "read", "16", "0x1000:00"],
        ["ok", "read", "16", "0x1008:00"],
    ], done
    time.sleep(0.3)  # now waiting for node 99 (30 s)
    took, out, err = _stop(proc, signum)
    name = signal.Signals(signum).name
    assert proc.returncode == code, err
    assert took < 1.0, f"{took:.2f} s to stop"
    assert out == f"stopped by {name} after 2 checks of 4: 2 passed, 0 failed\n"
    assert "Traceback" not in err


def test_a_stopped_check_writes_its_json(tmp_path) -> None:
    """In process: a real SIGINT to this process while the check waits for node 99; the
    JSON document has the results so far and says what stopped it."""
    from lolacli.sdo.node import IMU_NODE, NodeServer, NodeSpec, example_eds

    path = tmp_path / "gateway.yaml"
    path.write_text(CHECK)
    channel = f"lolacli-stop-json-{os.getpid()}"
    can = ["--can", channel, "--interface", "virtual", "--timeout", "30"]
    timer = threading.Timer(1.5, os.kill, (os.getpid(), signal.SIGINT))
    with NodeServer(
        channel, [NodeSpec(example_eds("lola_imu.eds"), IMU_NODE)], interface="virtual"
    ):
        timer.start()
        start = time.monotonic()
        try:
            result = CliRunner().invoke(app, ["sdo", "check", str(path), *can, "-f", "json"])
        finally:
            timer.cancel()
    assert time.monotonic() - start < 2.5
    assert result.exit_code == 130, result.stderr
    doc = json.loads(result.stdout)
    assert (doc["stopped_by"], doc["items"], doc["checks"], doc["failed"]) == ("SIGINT", 4, 2, 0)
    assert [r["object"] for r in doc["results"]] == ["0x1000:00", "0x1008:00"]


@pytest.mark.parametrize(("signum", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_read_waiting_on_a_node_stops(signum, code) -> None:
    channel = f"lolacli-stop-read-{os.getpid()}-{signum}"
    can = ["--can", channel, "--interface", "virtual", "--timeout", "30"]
    proc = _spawn(channel, "sdo", "read", "99", "0x1000", *can)
    time.sleep(2.0)  # started and waiting (an answer would take 30 s)
    assert proc.poll() is None
    took, out, err = _stop(proc, signum)
    assert proc.returncode == code and took < 1.0, (took, err)
    assert out == "" and err == f"lolacli: stopped by {signal.Signals(signum).name}\n"


@pytest.mark.parametrize(("signum", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_serve_stops_with_the_signal_s_code(signum, code) -> None:
    """A server ends by a signal: its nodes closed, exit 130/143 (not 0)."""
    channel = f"lolacli-serve-{os.getpid()}-{signum}"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "lolacli",
            "sdo",
            "serve",
            "--can",
            channel,
            "--interface",
            "virtual",
            "--gateway",
        ],
        cwd=ROOT,
        env=dict(os.environ, PYTHONPATH=str(ROOT), COLUMNS="80"),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stderr is not None
    line = proc.stderr.readline()
    assert line.startswith("serving CANopen nodes 16 (lola_imu.eds)"), line
    took, _out, err = _stop(proc, signum)
    assert proc.returncode == code and took < 1.0, (took, err)
    assert err.endswith(f"lolacli: stopped by {signal.Signals(signum).name}: nodes closed\n"), err


def test_serve_for_a_duration_ends_with_0() -> None:
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "lolacli",
            "sdo",
            "serve",
            "--can",
            f"lolacli-d-{os.getpid()}",
            "--interface",
            "virtual",
            "--gateway",
            "--duration",
            "0.3",
        ],
        cwd=ROOT,
        env=dict(os.environ, PYTHONPATH=str(ROOT)),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
