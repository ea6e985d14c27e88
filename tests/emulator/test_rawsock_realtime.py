"""The raw-socket server's real-time knobs: SCHED_FIFO on request, a clear error if not."""

from __future__ import annotations

import os

import pytest

from lolacli.emulator.rawsock import _realtime
from lolacli.errors import TransportError


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
