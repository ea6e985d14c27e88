"""A live EtherCAT bus for the SDO tests: a veth pair in a network namespace of its own,
``lolacli bus emulate`` on one end (its own process), the CLI under test on the other.

Namespace and interfaces are named from ``LOLACLI_TEST_NETNS_PREFIX`` (default ``lcs``)
and the pid, so parallel runs on one host never see each other's frames; everything runs
inside the namespace through ``ip netns exec``. Needs root and iproute2 (tests skip
otherwise).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "lolacli" / "eni_examples"
LOLA = EXAMPLES / "lola.xml"
PREFIX = os.environ.get("LOLACLI_TEST_NETNS_PREFIX", "lcs")


def _ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True)


@dataclass(frozen=True, slots=True)
class LiveBus:
    netns: str
    master: str  # the CLI's end
    emulator: str  # bus emulate's end

    def command(self, *argv: str) -> list[str]:
        return ["ip", "netns", "exec", self.netns, *argv]


def make_bus(tag: str = "") -> LiveBus:
    """A fresh namespace with a veth pair, both ends up, no IPv6 chatter."""
    if os.geteuid() != 0 or shutil.which("ip") is None:
        pytest.skip("needs root and iproute2 for a veth pair")
    tag = tag + f"{os.getpid() % 100000:05d}{time.monotonic_ns() % 100:02d}"
    bus = LiveBus(f"{PREFIX}n{tag}", f"{PREFIX}m{tag}", f"{PREFIX}e{tag}")
    _ip("netns", "add", bus.netns)
    try:
        _ip(
            "-n", bus.netns, "link", "add", bus.master, "type", "veth", "peer", "name", bus.emulator
        )
        for name in (bus.master, bus.emulator):
            subprocess.run(
                bus.command("sysctl", "-qw", f"net.ipv6.conf.{name}.disable_ipv6=1"),
                capture_output=True,
                check=False,
            )
            _ip("-n", bus.netns, "link", "set", name, "up")
    except BaseException:
        remove_bus(bus)
        raise
    return bus


def remove_bus(bus: LiveBus) -> None:
    subprocess.run(["ip", "netns", "del", bus.netns], capture_output=True, check=False)


def start_emulator(bus: LiveBus, *extra: str, eni: Path = LOLA) -> subprocess.Popen[str]:
    """``lolacli bus emulate`` serving ``eni`` on the bus; returns once it serves."""
    proc = subprocess.Popen(
        bus.command(
            sys.executable,
            "-m",
            "lolacli",
            "bus",
            "emulate",
            "--iface",
            bus.emulator,
            "--eni",
            str(eni),
            "--quiet",
            *extra,
        ),
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stderr is not None
    line = proc.stderr.readline()
    if "emulating" not in line:
        proc.kill()
        raise AssertionError(line + proc.stderr.read())
    return proc


def stop_emulator(proc: subprocess.Popen[str]) -> None:
    proc.send_signal(2)
    try:
        proc.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()


def lolacli(bus: LiveBus | None, *args: str, timeout: float = 120) -> tuple[int, str, str]:
    """``python -m lolacli ARGS`` from the worktree, inside the bus's namespace if any."""
    argv = [sys.executable, "-m", "lolacli", *args]
    done = subprocess.run(
        bus.command(*argv) if bus is not None else argv,
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    return done.returncode, done.stdout, done.stderr


def json_of(out: str) -> dict[str, Any]:
    return json.loads(out) if out.strip() else {}
