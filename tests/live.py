"""A live bus for tests (the master's, the SDO tests'): a veth pair, `lolacli bus emulate`
on one end in its own process (its own GIL, as a real slave chain has its own silicon), our
master, the CLI under test or pysoem on the other. Needs root and iproute2; tests using it
skip cleanly otherwise.

Each pair lives in a network namespace of its own, named from
``LOLACLI_TEST_NETNS_PREFIX`` (default ``lct``) and the pid (``lctn…``; interfaces
``lctm…`` and ``lcte…``), so runs in parallel on the same host never see each other's
frames; the emulator and the CLI run inside it through ``ip netns exec``, in-process
users open their sockets inside it with :func:`inside`.
"""

from __future__ import annotations

import ctypes
import json
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: the CPUs the test run may use, taken at import (a test may pin its master to one of them)
ALL_CPUS = frozenset(os.sched_getaffinity(0))


def on_all_cpus() -> None:
    """A child's CPUs as the run's (``preexec_fn``: not the one core a test's master is
    pinned to; the emulator places itself)."""
    os.sched_setaffinity(0, ALL_CPUS)


@contextmanager
def on_cpu(cpu: int, priority: int = 0) -> Iterator[None]:
    """This thread on ``cpu`` (at SCHED_FIFO ``priority`` if not 0) for the block; its
    CPUs and normal scheduling again afterwards."""
    affinity = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {cpu})
    try:
        if priority:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        yield
    finally:
        if priority:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        os.sched_setaffinity(0, affinity)
EXAMPLES = ROOT / "lolacli" / "eni_examples"
LOLA = EXAMPLES / "lola.xml"
PREFIX = os.environ.get("LOLACLI_TEST_NETNS_PREFIX", "lct")


def need_root(what: str = "a veth pair") -> None:
    if os.geteuid() != 0:
        pytest.skip(f"needs root for {what}")
    if shutil.which("ip") is None:
        pytest.skip("needs iproute2 (ip)")


def ip(*args: str) -> None:
    """``ip ARGS`` (iproute2), failing on error."""
    subprocess.run(["ip", *args], check=True, capture_output=True)


@dataclass(frozen=True, slots=True)
class LiveBus:
    """A veth pair inside its own network namespace: no other process on the host can
    open these interfaces or send on them (on a shared host one did: another master's
    frames turned up on a pair of ours)."""

    netns: str
    master: str  # our master's end
    emulator: str  # `bus emulate`'s end

    def command(self, *argv: str) -> list[str]:
        """``argv`` run inside the namespace."""
        return ["ip", "netns", "exec", self.netns, *argv]

    def ip(self, *args: str) -> None:
        ip("-n", self.netns, *args)


def make_bus(tag: str = "") -> LiveBus:
    """A fresh namespace with a veth pair, up, without IPv6 chatter (``tag``: a letter or
    two that tell the test's pairs apart)."""
    need_root()
    tag += f"{os.getpid() % 100000:05d}{time.monotonic_ns() % 100:02d}"
    bus = LiveBus(f"{PREFIX}n{tag}", f"{PREFIX}m{tag}", f"{PREFIX}e{tag}")
    ip("netns", "add", bus.netns)
    try:
        bus.ip("link", "add", bus.master, "type", "veth", "peer", "name", bus.emulator)
        for name in (bus.master, bus.emulator):
            subprocess.run(
                bus.command("sysctl", "-qw", f"net.ipv6.conf.{name}.disable_ipv6=1"),
                capture_output=True,
                check=False,
            )
            bus.ip("link", "set", name, "up")
    except BaseException:
        remove_bus(bus)
        raise
    return bus


def remove_bus(bus: LiveBus) -> None:
    """Delete the namespace (and the pair in it)."""
    subprocess.run(["ip", "netns", "del", bus.netns], capture_output=True, check=False)


_CLONE_NEWNET = 0x40000000


@contextmanager
def inside(bus: LiveBus) -> Iterator[None]:
    """This thread in the bus's namespace for the block: sockets opened here (our
    transport's, pysoem's) stay in it afterwards."""
    libc = ctypes.CDLL(None, use_errno=True)
    home = os.open("/proc/thread-self/ns/net", os.O_RDONLY)
    target = os.open(f"/run/netns/{bus.netns}", os.O_RDONLY)
    try:
        if libc.setns(target, _CLONE_NEWNET) != 0:
            raise OSError(ctypes.get_errno(), f"setns into {bus.netns} failed")
        try:
            yield
        finally:
            if libc.setns(home, _CLONE_NEWNET) != 0:
                raise OSError(ctypes.get_errno(), "setns back failed")
    finally:
        os.close(home)
        os.close(target)


def emulate_argv(iface: str, eni: Path, *extra: str) -> list[str]:
    """The command line of `lolacli bus emulate` serving ``eni`` on ``iface``."""
    argv = [sys.executable, "-m", "lolacli", "bus", "emulate", "--iface", iface]
    return [*argv, "--eni", str(eni), "--quiet", *extra]


def spawn_emulator(argv: list[str]) -> subprocess.Popen[bytes]:
    """Start `bus emulate` (``argv``) and return once it answers: its first stderr line
    ("emulating N slaves of …", kept as ``first_line``) says the socket is open. Read byte
    by byte, so nothing after it is buffered here and lost to :func:`stop_emulator`."""
    proc = subprocess.Popen(
        argv,
        cwd=ROOT,
        stderr=subprocess.PIPE,
        stdout=subprocess.PIPE,
        bufsize=0,
        preexec_fn=on_all_cpus,
    )
    assert proc.stderr is not None
    line = b""
    while not line.endswith(b"\n"):
        byte = proc.stderr.read(1)
        if not byte:
            break
        line += byte
    if b"emulating" not in line:
        proc.kill()
        raise AssertionError((line + proc.stderr.read()).decode())
    proc.first_line = line.decode()  # type: ignore[attr-defined]
    time.sleep(0.2)
    return proc


def start_emulator(
    bus: LiveBus, *extra: str, eni: Path = LOLA, priority: int | None = None
) -> subprocess.Popen[bytes]:
    """`lolacli bus emulate` serving ``eni`` on the bus (returns once it answers), with the
    product's scheduling (SCHED_FIFO 10 as root) unless ``priority`` is given (0: normal
    scheduling). Real time stands in for slave hardware, which does not stall when the
    host is busy (with a CPU hog and a load of 8 on 2 cores, a plain emulator process
    answered mailboxes too late for SOEM and tripped its own process-data watchdogs)."""
    if priority is not None:
        extra = ("--realtime-priority", str(priority), *extra)
    return spawn_emulator(bus.command(*emulate_argv(bus.emulator, eni, *extra)))


def stop_emulator(proc: subprocess.Popen[bytes]) -> str:
    """Stop it with SIGINT (a clean stop, exit 130); its whole stderr (status and stop
    lines)."""
    proc.send_signal(2)
    try:
        _out, err = proc.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        raise
    text = getattr(proc, "first_line", "") + err.decode()
    assert proc.returncode == 130, text
    return text


def run(
    *args: str, bus: LiveBus | None = None, timeout: float = 120
) -> subprocess.CompletedProcess[str]:
    """``python -m lolacli ARGS`` from the worktree (inside the bus's namespace)."""
    argv = [sys.executable, "-m", "lolacli", *args]
    return subprocess.run(
        bus.command(*argv) if bus is not None else argv,
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def json_of(out: str) -> dict[str, Any]:
    """The JSON document a command wrote (empty when it wrote none)."""
    return json.loads(out) if out.strip() else {}


def run_json(
    *args: str, bus: LiveBus | None = None, timeout: float = 120
) -> tuple[int, dict[str, Any], str]:
    """Exit code, the JSON document on stdout, stderr."""
    done = run(*args, "--format", "json", bus=bus, timeout=timeout)
    return done.returncode, json_of(done.stdout), done.stderr
