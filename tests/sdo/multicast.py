"""Separate processes on python-can's udp_multicast bus, inside a private network namespace.

udp_multicast sends to a multicast group through the host's default route: on a host with
a network card that is the card (TTL 1: the local link). Tests must not send anything off
this machine, so they run both ends in a fresh network namespace whose only interface is
its loopback, with multicast switched on and a route for 224.0.0.0/4 (IPv4: python-can's
IPv6 default group gets no loopback delivery there). Needs root and ``ip``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from lolacli.sdo.canopen_client import UDP_MULTICAST_IPV4
from tests.live import ip, need_root

ROOT = Path(__file__).resolve().parents[2]
PREFIX = os.environ.get("LOLACLI_TEST_NETNS_PREFIX", "lcn")
CAN = ["--can", UDP_MULTICAST_IPV4, "--interface", "udp_multicast"]


@contextmanager
def namespace() -> Iterator[str]:
    """A network namespace with only ``lo``, multicast on, removed afterwards."""
    need_root("a private network namespace (udp_multicast stays on it)")
    name = f"{PREFIX}{os.getpid() % 100000}x{time.monotonic_ns() % 1000}"
    ip("netns", "add", name)
    try:
        ip("-n", name, "link", "set", "lo", "up")
        ip("-n", name, "link", "set", "lo", "multicast", "on")
        ip("-n", name, "route", "add", "224.0.0.0/4", "dev", "lo")
        yield name
    finally:
        subprocess.run(["ip", "netns", "del", name], capture_output=True, check=False)


def command(ns: str, *args: str) -> list[str]:
    return ["ip", "netns", "exec", ns, sys.executable, "-m", "lolacli", *args]


def run(ns: str, *args: str, timeout: float = 60) -> tuple[int, str, str]:
    """``lolacli ARGS`` in the namespace: (exit code, stdout, stderr)."""
    p = subprocess.run(
        command(ns, *args), cwd=ROOT, capture_output=True, text=True, timeout=timeout
    )
    return p.returncode, p.stdout, p.stderr


@contextmanager
def serving(ns: str, *args: str) -> Iterator[subprocess.Popen[str]]:
    """``lolacli sdo serve ARGS`` in the namespace, until the block ends: then Ctrl-C
    (SIGINT) stops it, a server's normal end, with exit 130."""
    proc = subprocess.Popen(
        command(ns, "sdo", "serve", *CAN, *args),
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stderr is not None
        line = proc.stderr.readline()  # "serving CANopen nodes …" once the bus is open
        assert "serving" in line, line + proc.stderr.read()
        yield proc
    finally:
        proc.send_signal(2)
        try:
            _out, err = proc.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            raise
        assert proc.returncode == 130, err
