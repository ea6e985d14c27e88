"""The real-time helpers without a bus: which frames are cyclic, what the cycle clock
makes of a timeline of sends and returns, scheduling put back after a section."""

from __future__ import annotations

import gc
import os

from lolacli.files import load_eni
from lolacli.master.cyclic import plan_frame
from lolacli.master.realtime import CycleClock, is_cyclic, realtime_section
from lolacli.wire.commands import Command
from lolacli.wire.frame import Datagram, encode_frame, make_frame
from tests.live import LOLA


def test_the_lola_cyclic_frame_is_cyclic_and_mailbox_reads_are_not() -> None:
    eni = load_eni(LOLA)
    plan = plan_frame(
        eni.cyclic_frames[0],
        "OP",
        inputs_bytes=eni.process_image.inputs_bytes,
        outputs_bytes=eni.process_image.outputs_bytes,
        source_mac=b"\x01" * 6,
        destination_mac=b"\xff" * 6,
    )
    assert plan is not None
    assert is_cyclic(plan.build(1, bytearray(eni.process_image.outputs_bytes)))
    reads = [Datagram.physical(Command.FPRD, 0x1001 + k, 0x092C, 4) for k in range(3)]
    assert not is_cyclic(encode_frame(make_frame(reads), pad=True))
    lrd_last = [*reads, Datagram.logical(Command.LRD, 0x10000, 4)]
    assert is_cyclic(encode_frame(make_frame(lrd_last), pad=True))
    assert not is_cyclic(b"\x00" * 20)  # too short for a datagram: not cyclic, no error


def _cyclic(index: int) -> bytes:
    return encode_frame(make_frame([Datagram.logical(Command.LRW, 0, 8, index=index)]), pad=True)


def test_cycle_clock_of_a_timeline() -> None:
    """Cycles due every 500 us, sent 70 us after; one answer 600 us late, one never."""
    due = {"t": 0}
    clock = CycleClock(500_000, lambda: due["t"], active=True)
    for k in range(10):
        due["t"] = k * 500_000
        sent = due["t"] + 70_000 + (300_000 if k == 4 else 0)
        clock(sent, _cyclic(k), False)
        if k == 7:
            continue  # never comes back
        back = sent + (600_000 if k == 2 else 60_000)
        clock(back, _cyclic(k), True)
    report = clock.report(in_flight_ns=0)
    assert report["cyclic_frames_timed"] == 10
    assert report["cycle_period_us"]["count"] == 9
    assert report["send_offset_us"]["median"] == 70.0
    assert report["send_offset_us"]["max"] == 370.0
    assert report["overruns"] == 1  # cycle 4 left more than half a cycle late
    assert (report["late_frames"], report["never_returned_frames"]) == (1, 1)
    assert report["cycle_jitter_us"]["max_deviation_from_median"] == 300.0
    assert clock.returned == 9


def test_a_frame_sent_just_before_the_end_is_in_flight_not_lost() -> None:
    clock = CycleClock(500_000, lambda: 0, active=True)
    clock(0, _cyclic(1), False)
    clock(100_000, _cyclic(1), True)
    clock(500_000, _cyclic(2), False)
    assert clock.report(in_flight_ns=500_000)["never_returned_frames"] == 0
    assert clock.report(in_flight_ns=0)["never_returned_frames"] == 1


def test_scheduling_and_collector_come_back_after_a_section() -> None:
    before = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority, gc.isenabled())
    with realtime_section(7, busy_wait_us=100) as info:
        assert not gc.isenabled()
        if info.policy == "SCHED_FIFO":
            assert os.sched_getscheduler(0) == os.SCHED_FIFO
        else:  # not permitted here: said why
            assert info.error and "SCHED_FIFO 7 refused" in info.error
    assert (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority, gc.isenabled()) == before
    assert info.to_dict()["busy_wait_us"] == 100
