"""The raw-socket server's real-time knobs: SCHED_FIFO on request, a clear error if not;
the CPUs held awake while it serves."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from lolacli.emulator.rawsock import (
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
    with RawSocketServer("lo", chain, realtime_priority=0) as server:
        assert cpu_latency_limit_us() == 0
        assert server.scheduling == "normal, CPU wake-up latency held at 0 µs"
    assert cpu_latency_limit_us() == before
    with RawSocketServer("lo", chain, realtime_priority=0, keep_cpus_awake=False) as server:
        assert cpu_latency_limit_us() == before
        assert server.scheduling == "normal"


@pytest.mark.skipif(os.geteuid() != 0, reason="raw sockets need root")
def test_a_quiet_server_keeps_warm_on_a_chain_of_its_own() -> None:
    """While no frame comes, the server runs the keep-warm work every WARM_EVERY_MS (not
    more often): frames through the scratch chain, never through the chain it serves."""
    eni = load_eni(EXAMPLES / "single_drive.xml")
    chain, scratch = build_chain(eni), build_chain(eni)
    warm = keep_warm_with(scratch)
    calls: list[float] = []

    def counted() -> None:
        calls.append(time.monotonic())
        warm()

    # until five calls (a loaded machine or a garbage collection may delay one), at most 5 s
    deadline = time.monotonic() + 5.0
    with RawSocketServer("lo", chain, realtime_priority=0, keep_warm=counted) as server:
        server.serve(lambda: len(calls) >= 5 or time.monotonic() >= deadline)
    assert len(calls) == 5
    gaps = [b - a for a, b in zip(calls, calls[1:], strict=False)]
    assert min(gaps) >= 0.9 * WARM_EVERY_MS / 1000, gaps
    assert scratch.stats.frames == 3 * len(calls)
    assert chain.stats.frames == 0
