"""The raw-socket server's real-time knobs: SCHED_FIFO on request, a clear error if not;
the CPUs held awake while it serves."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from lolacli.emulator.rawsock import (
    ANY,
    CPU_DMA_LATENCY,
    WARM_EVERY_MS,
    RawSocketServer,
    _realtime,
    cpu_latency_limit_us,
)
from lolacli.emulator.run import keep_warm_with
from lolacli.emulator.slave import build_chain
from lolacli.errors import TransportError
from lolacli.files import load_eni

EXAMPLES = Path(__file__).resolve().parents[2] / "lolacli" / "eni_examples"


def test_an_impossible_priority_is_one_transport_error() -> None:
    with pytest.raises(TransportError, match="cannot run SCHED_FIFO at priority 1000"):
        _realtime(1000)  # SCHED_FIFO priorities are 1..99


@pytest.mark.skipif(os.geteuid() != 0, reason="SCHED_FIFO needs root or CAP_SYS_NICE")
def test_realtime_priority_is_applied_in_a_child() -> None:
    pid = os.fork()
    if pid == 0:  # keep the test process itself in its scheduling class
        _realtime(3)
        ok = os.sched_getscheduler(0) == os.SCHED_FIFO and os.sched_getparam(0).sched_priority == 3
        os._exit(0 if ok else 1)
    _, status = os.waitpid(pid, 0)
    assert os.waitstatus_to_exitcode(status) == 0


@pytest.mark.skipif(
    not os.access(CPU_DMA_LATENCY, os.W_OK), reason="PM QoS requests need root"
)
def test_the_server_holds_the_cpus_awake_while_it_serves_and_lets_go_after() -> None:
    chain = build_chain(load_eni(EXAMPLES / "single_drive.xml"))
    before = cpu_latency_limit_us()
    assert before is not None and before > 0  # nothing else holds it during the tests
    with RawSocketServer("lo", chain, realtime_priority=0, cpu=ANY) as server:
        assert cpu_latency_limit_us() == 0
        assert server.scheduling == "normal, CPU wake-up latency held at 0 µs"
    assert cpu_latency_limit_us() == before
    with RawSocketServer(
        "lo", chain, realtime_priority=0, keep_cpus_awake=False, cpu=ANY
    ) as server:
        assert cpu_latency_limit_us() == before
        assert server.scheduling == "normal"


@pytest.mark.skipif(os.geteuid() != 0, reason="raw sockets need root")
def test_a_quiet_server_keeps_warm_on_a_chain_of_its_own() -> None:
    """While no frame comes, the server runs the keep-warm work every WARM_EVERY_MS (not
    more often): frames through the scratch chain, never through the chain it serves, whose
    memories it only reads."""
    eni = load_eni(EXAMPLES / "single_drive.xml")
    chain, scratch = build_chain(eni), build_chain(eni)
    before = [bytes(esc.mem) for esc in chain.slaves]
    warm = keep_warm_with(scratch, chain)
    calls: list[float] = []

    def counted(should_yield: Callable[[], bool] | None) -> bool:
        calls.append(time.monotonic())
        return warm(should_yield)

    # until five calls (a loaded machine or a garbage collection may delay one), at most 5 s
    deadline = time.monotonic() + 5.0
    with RawSocketServer("lo", chain, realtime_priority=0, keep_warm=counted) as server:
        server.serve(lambda: len(calls) >= 5 or time.monotonic() >= deadline)
    assert len(calls) == 5
    gaps = [b - a for a, b in zip(calls, calls[1:], strict=False)]
    assert min(gaps) >= 0.9 * WARM_EVERY_MS / 1000, gaps
    assert scratch.stats.frames == 3 * len(calls)
    assert chain.stats.frames == 0
    assert [bytes(esc.mem) for esc in chain.slaves] == before


@pytest.mark.skipif(os.geteuid() != 0, reason="a veth pair needs root")
def test_the_server_keeps_warm_between_cyclic_frames() -> None:
    """A master that sends a frame every millisecond never leaves the server quiet for
    WARM_EVERY_MS: the keep-warm work then runs after a frame's work, as often as when
    quiet and no more, and every frame is answered (pysoem's closing BWR after 10,000
    LOLA cycles: 80 µs in process without, 33 with)."""
    from lolacli.rawsocket import PACKET_OUTGOING, open_socket
    from lolacli.wire.commands import Command
    from lolacli.wire.frame import Datagram, encode_frame, make_frame
    from tests.live import inside, make_bus, remove_bus

    eni = load_eni(EXAMPLES / "single_drive.xml")
    chain, scratch = build_chain(eni), build_chain(eni)
    warm = keep_warm_with(scratch, chain)
    calls: list[float] = []

    def counted(should_yield: Callable[[], bool] | None) -> bool:
        began = time.monotonic()
        done = warm(should_yield)
        if done:  # one that gave way to a frame runs again after that frame's work
            calls.append(began)
        return done

    frame = encode_frame(make_frame([Datagram.physical(Command.BRD, 0, 0x0130, 2)]), pad=True)
    bus = make_bus("w")
    ready, stop = threading.Event(), threading.Event()

    def server() -> None:
        with inside(bus), RawSocketServer(
            bus.emulator, chain, realtime_priority=0, keep_cpus_awake=False, keep_warm=counted
        ) as served:
            ready.set()
            served.serve(stop.is_set)

    thread = threading.Thread(target=server)
    thread.start()
    try:
        assert ready.wait(10)
        with inside(bus):
            sock = open_socket(bus.master)
        sock.settimeout(1.0)
        answered = 0
        start = time.monotonic()
        calls.clear()  # from the first frame on
        next_t = start
        while time.monotonic() - start < 0.3:
            sock.send(frame)
            while True:
                data, address = sock.recvfrom(2048)
                if address[2] != PACKET_OUTGOING and data[6] & 0x02:
                    answered += 1
                    break
            next_t += 0.001
            time.sleep(max(0.0, next_t - time.monotonic()))
        sock.close()
    finally:
        stop.set()
        thread.join(10)
        remove_bus(bus)
    assert answered >= 200
    during = [t for t in calls if t < start + 0.3]
    assert len(during) >= 10, f"{len(during)} keep-warm runs in 300 ms of frames"
    gaps = [b - a for a, b in zip(during, during[1:], strict=False)]
    assert min(gaps) >= 0.9 * WARM_EVERY_MS / 1000, gaps


@pytest.mark.skipif(os.geteuid() != 0, reason="a veth pair and SCHED_FIFO need root")
def test_a_master_on_the_servers_core_sends_during_the_grace() -> None:
    """After an answer the server watches for the master's next frame (the grace), busy
    only at first, then blocked on the socket: a master at normal priority on the core of
    the SCHED_FIFO server takes the answer and sends again meanwhile. A watch busy for all
    of the grace held it off: every exchange took the whole grace or more (median 127 µs
    here against 63; 19 with the master on the other core either way)."""
    from lolacli.rawsocket import PACKET_OUTGOING, open_socket
    from lolacli.wire.commands import Command
    from lolacli.wire.frame import Datagram, encode_frame, make_frame
    from tests.live import inside, make_bus, remove_bus

    eni = load_eni(EXAMPLES / "single_drive.xml")
    frame = encode_frame(make_frame([Datagram.physical(Command.BRD, 0, 0x0130, 2)]), pad=True)
    bus = make_bus("g")
    affinity = os.sched_getaffinity(0)
    pid = -1
    try:
        with inside(bus):
            pid = os.fork()
            if pid == 0:  # the server, on core 0 at SCHED_FIFO 10
                try:
                    os.sched_setaffinity(0, {0})
                    with RawSocketServer(bus.emulator, build_chain(eni)) as server:
                        server.serve(lambda: os.getppid() == 1)
                finally:
                    os._exit(0)
            os.sched_setaffinity(0, {0})  # the master, on the same core
            sock = open_socket(bus.master)

            def exchange() -> int:
                t0 = time.perf_counter_ns()
                sock.send(frame)
                while True:
                    data, address = sock.recvfrom(2048)
                    if address[2] != PACKET_OUTGOING and data[6] & 0x02:
                        return time.perf_counter_ns() - t0

            sock.settimeout(0.2)
            deadline = time.monotonic() + 20
            while True:  # until the server answers (it builds its chain first)
                try:
                    exchange()
                    break
                except TimeoutError:
                    assert time.monotonic() < deadline, "the server never answered"
            sock.settimeout(2.0)
            times = [exchange() for _ in range(300)]
            sock.close()
    finally:
        os.sched_setaffinity(0, affinity)
        if pid > 0:
            os.kill(pid, 9)
            os.waitpid(pid, 0)
        remove_bus(bus)
    times.sort()
    median_us = times[len(times) // 2] / 1000
    assert median_us < 100, f"median exchange {median_us:.0f} µs"
