"""A live bus for tests: a veth pair, `lolacli bus emulate` on one end in its own process
(its own GIL, as a real slave chain has its own silicon), our master or pysoem on the
other. Needs root and iproute2; tests using it skip cleanly otherwise.

Interface names start with ``f11`` and carry the pid, so runs in parallel (other
engineers' tests on the same host) never touch each other's pairs.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "lolacli" / "eni_examples"
LOLA = EXAMPLES / "lola.xml"
PREFIX = "f11"


def need_root() -> None:
    if os.geteuid() != 0:
        pytest.skip("needs root for a veth pair")
    if shutil.which("ip") is None:
        pytest.skip("needs iproute2 (ip)")


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True)


def make_veth() -> tuple[str, str]:
    """A fresh veth pair (master end, emulator end), up, without IPv6 chatter."""
    need_root()
    tag = f"{os.getpid() % 100000:05d}{time.monotonic_ns() % 100:02d}"
    master, emulator = f"{PREFIX}m{tag}", f"{PREFIX}e{tag}"
    _ip("link", "add", master, "type", "veth", "peer", "name", emulator)
    try:
        for name in (master, emulator):
            subprocess.run(
                ["sysctl", "-qw", f"net.ipv6.conf.{name}.disable_ipv6=1"],
                capture_output=True,
                check=False,
            )
            _ip("link", "set", name, "up")
    except BaseException:
        remove_veth(master)
        raise
    return master, emulator


def remove_veth(master: str) -> None:
    subprocess.run(["ip", "link", "del", master], capture_output=True, check=False)


def start_emulator(iface: str, *extra: str, eni: Path = LOLA) -> subprocess.Popen[str]:
    """`lolacli bus emulate` serving ``eni`` on ``iface`` (returns once it answers)."""
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "lolacli",
            "bus",
            "emulate",
            "--iface",
            iface,
            "--eni",
            str(eni),
            "--quiet",
            *extra,
        ],
        cwd=ROOT,
        stderr=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stderr is not None
    line = proc.stderr.readline()  # "emulating N slaves of …" once the socket is open
    if "emulating" not in line:
        proc.kill()
        raise AssertionError(line + proc.stderr.read())
    time.sleep(0.2)
    return proc


def stop_emulator(proc: subprocess.Popen[str]) -> None:
    proc.send_signal(2)  # SIGINT: stops cleanly
    try:
        _out, err = proc.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        raise
    assert proc.returncode == 0, err


def run(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    """``python -m lolacli ARGS`` from the worktree."""
    return subprocess.run(
        [sys.executable, "-m", "lolacli", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def run_json(*args: str, timeout: float = 120) -> tuple[int, dict[str, Any], str]:
    """Exit code, the JSON document on stdout, stderr."""
    done = run(*args, "--format", "json", timeout=timeout)
    doc = json.loads(done.stdout) if done.stdout.strip() else {}
    return done.returncode, doc, done.stderr
