"""Where `bus emulate` runs: on the CPU the master's frames arrive on (``--cpu follow``, the
default), off it again when the master keeps that CPU, or where it is told. A real
emulator process over a veth pair, the master a raw socket in this process."""

from __future__ import annotations

import os
import re
import socket
import statistics
import struct
import time
from collections.abc import Callable, Iterator

import pytest

from lolacli.emulator.rawsock import (
    FOLLOW_BACKOFF_NS,
    FOLLOW_BOUNCE_NS,
    FOLLOW_LATE_FRAMES,
    SO_TIMESTAMPNS,
)
from lolacli.rawsocket import PACKET_OUTGOING, open_socket
from lolacli.wire.commands import Command
from lolacli.wire.frame import Datagram, encode_frame, make_frame
from tests.live import (
    EXAMPLES,
    LiveBus,
    inside,
    make_bus,
    on_cpu,
    remove_bus,
    start_emulator,
    stop_emulator,
)

pytestmark = [
    pytest.mark.skipif(os.geteuid() != 0, reason="a veth pair needs root"),
    pytest.mark.skipif(
        not {0, 1} <= os.sched_getaffinity(0), reason="needs CPUs 0 and 1 to move between"
    ),
]

SINGLE = EXAMPLES / "single_drive.xml"
FRAME = encode_frame(make_frame([Datagram.physical(Command.BRD, 0, 0x0130, 2)]), pad=True)


@pytest.fixture
def bus() -> Iterator[LiveBus]:
    live = make_bus("p")
    try:
        yield live
    finally:
        remove_bus(live)


def _answer(sock: socket.socket) -> int:
    """Wait for the emulator's answer; the kernel's receive time of it (CLOCK_REALTIME)."""
    while True:
        data, ancillary, _flags, address = sock.recvmsg(2048, 64)
        if address[2] != PACKET_OUTGOING and data[6] & 0x02:  # its datagram came back
            for level, kind, raw in ancillary:
                if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS:
                    sec, nsec = struct.unpack_from("qq", raw)
                    return sec * 1_000_000_000 + nsec
            return time.time_ns()


def _master_socket(bus: LiveBus) -> socket.socket:
    with inside(bus):
        sock = open_socket(bus.master)
    sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    sock.settimeout(2.0)
    return sock


def _placement_counts(stderr: str) -> tuple[int, int]:
    """(moves, backoffs) from the emulator's stop lines (0, 0 when it did not say)."""
    found = re.search(r"placement: moved .*? (\d+) times, left it to the OS (\d+)", stderr)
    return (int(found[1]), int(found[2])) if found else (0, 0)


def _exchange_for(
    bus: LiveBus, duration_ns: int, before_each: Callable[[int], None] | None = None
) -> tuple[int, str]:
    """A frame a millisecond to a fresh emulator for ``duration_ns``, each answered
    (``before_each(k)`` before the k-th); how many, and the emulator's stderr."""
    proc = start_emulator(bus, eni=SINGLE)
    sock = _master_socket(bus)
    frames = 0
    try:
        until = time.monotonic_ns() + duration_ns
        while time.monotonic_ns() < until:
            if before_each is not None:
                before_each(frames)
            sock.send(FRAME)
            _answer(sock)
            frames += 1
            time.sleep(0.001)
    finally:
        sock.close()
        err = stop_emulator(proc)
    return frames, err


def test_the_emulator_runs_on_the_cpu_of_the_masters_frames(bus: LiveBus) -> None:
    """The master on CPU 0, then 1, then 0 again, each for twice FOLLOW_BOUNCE_NS: each
    time the emulator is on the master's CPU after its first frames from there, and says it
    moved."""
    proc = start_emulator(bus, eni=SINGLE)
    sock = _master_socket(bus)
    seen = []
    try:
        for cpu in (0, 1, 0):
            with on_cpu(cpu):
                until = time.monotonic_ns() + 2 * FOLLOW_BOUNCE_NS
                while time.monotonic_ns() < until:
                    sock.send(FRAME)
                    _answer(sock)
                    time.sleep(0.001)
            seen.append(os.sched_getaffinity(proc.pid))
    finally:
        sock.close()
        err = stop_emulator(proc)
    assert "on the CPU of the master's frames" in " ".join(err.split()), err
    assert seen == [{0}, {1}, {0}], err
    moves, _backoffs = _placement_counts(err)
    assert moves >= 3, err


def test_the_emulator_leaves_a_cpu_the_master_keeps(bus: LiveBus) -> None:
    """A master at SCHED_FIFO 50 (above the emulator's 10) that spins 2 ms after each frame
    keeps its CPU: the emulator, following it there, can answer only when the spin ends.
    After FOLLOW_LATE_FRAMES frames held that long it leaves the placement to the OS, which
    runs it on the other CPU: the answers come while the master still spins."""
    proc = start_emulator(bus, eni=SINGLE)
    sock = _master_socket(bus)
    latency_us = []
    try:
        with on_cpu(0, priority=50):
            for _ in range(FOLLOW_LATE_FRAMES + 20):
                sent = time.time_ns()
                sock.send(FRAME)
                spin_until = time.monotonic_ns() + 2_000_000
                while time.monotonic_ns() < spin_until:
                    pass
                latency_us.append((_answer(sock) - sent) / 1000)
                time.sleep(0.001)
    finally:
        sock.close()
        err = stop_emulator(proc)
    _moves, backoffs = _placement_counts(err)
    assert backoffs >= 1, (err, latency_us)
    assert statistics.median(latency_us[-10:]) < 1000, latency_us  # not held by the spin


def test_the_emulator_does_not_chase_a_master_that_moves_away(bus: LiveBus) -> None:
    """A master whose frames come from the other CPU right after the emulator came to its
    own (here it changes CPU every frame; a real-time master below the emulator's priority
    is pushed off the CPU where the emulator preempts it): the emulator leaves the placement
    to the OS after the first such bounce instead of moving on every frame."""

    def on_the_other_cpu(frame: int) -> None:
        os.sched_setaffinity(0, {frame % 2})

    with on_cpu(0):
        frames, err = _exchange_for(bus, FOLLOW_BACKOFF_NS // 2, on_the_other_cpu)
    moves, backoffs = _placement_counts(err)
    assert frames > 100
    assert (moves, backoffs) == (1, 1), err


def test_a_real_time_master_below_the_emulator_keeps_it_in_place(bus: LiveBus) -> None:
    """A master at SCHED_FIFO 5, free to run on either CPU, sending a frame a millisecond
    for a second: the emulator (SCHED_FIFO 10) moves to it a few times at most, not on
    every frame (the kernel pushes the preempted master to the other CPU)."""
    with on_cpu(0, priority=5):
        os.sched_setaffinity(0, {0, 1})
        frames, err = _exchange_for(bus, 1_000_000_000)
    moves, _backoffs = _placement_counts(err)
    assert frames > 300
    assert moves <= 5, err


def test_any_and_a_pinned_cpu(bus: LiveBus) -> None:
    """``--cpu any`` stays where the OS puts it (a master on CPU 0 does not move it);
    ``--cpu 1`` pins it to CPU 1 (and says so)."""
    for extra, expected in ((("--cpu", "any"), None), (("--cpu", "1"), {1})):
        proc = start_emulator(bus, *extra, eni=SINGLE)
        before = os.sched_getaffinity(proc.pid)
        sock = _master_socket(bus)
        try:
            with on_cpu(0):
                for _ in range(20):
                    sock.send(FRAME)
                    _answer(sock)
            after = os.sched_getaffinity(proc.pid)
        finally:
            sock.close()
            err = stop_emulator(proc)
        assert after == (expected or before), (extra, err)
        assert _placement_counts(err) == (0, 0), err
        if expected:
            assert "on CPU 1" in " ".join(err.split()), err


def test_a_cpu_it_may_not_run_on_is_a_usage_error() -> None:
    """``--cpu`` naming a CPU outside the process's set, or not a CPU at all: one line,
    exit 2, before any socket is opened."""
    import subprocess
    import sys

    for value, message in (
        ("999", "--cpu 999: not a CPU this process may run on"),
        ("x", "expected follow, any or a CPU number"),
    ):
        done = subprocess.run(
            [sys.executable, "-m", "lolacli", "bus", "emulate", "--iface", "lo", "--cpu", value],
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert done.returncode == 2, done.stderr
        assert message in done.stderr and "Traceback" not in done.stderr, done.stderr
