"""What a real-time master asks of the operating system, and what it measured.

:func:`realtime_section` runs a block with the calling thread in ``SCHED_FIFO`` where
the OS allows it (root or CAP_SYS_NICE; elsewhere the thread stays where it was and the
report says why), 1 µs timer slack (Linux rounds sleeps up by 50 µs by default), and the
garbage collector frozen and off (a collection pass over a large heap takes
milliseconds); everything is put back afterwards. :class:`CycleClock` is a transport tap
that times the cyclic frames as they leave: the cycle period, how long after its
scheduled start each cycle's frame left (the software before the send, and any lateness;
more than half a cycle is an overrun), and which cyclic frames came back and when.
"""

from __future__ import annotations

import ctypes
import gc
import os
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from lolacli.timing.stats import summarize_array
from lolacli.wire.commands import LOGICAL
from lolacli.wire.frame import DATAGRAM_HEADER_BYTES, ECAT_HEADER_BYTES, ETH_HEADER_BYTES

PR_SET_TIMERSLACK = 29
PR_GET_TIMERSLACK = 30
TIMER_SLACK_NS = 1000
_FIRST_DATAGRAM = ETH_HEADER_BYTES + ECAT_HEADER_BYTES
_INDEX_AT = _FIRST_DATAGRAM + 1
_CYCLIC_MIN = _FIRST_DATAGRAM + DATAGRAM_HEADER_BYTES  # a frame with a whole datagram header


@dataclass(slots=True)
class Scheduling:
    """What the OS granted (``policy`` "SCHED_FIFO" or "SCHED_OTHER")."""

    policy: str = "SCHED_OTHER"
    priority: int = 0
    requested_priority: int = 0
    error: str | None = None
    timer_slack_ns: int | None = None
    gc_disabled: bool = False
    busy_wait_us: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        return {
            "policy": self.policy,
            "priority": self.priority,
            "requested_priority": self.requested_priority,
            "error": self.error,
            "timer_slack_ns": self.timer_slack_ns,
            "gc_disabled": self.gc_disabled,
            "busy_wait_us": self.busy_wait_us,
        }


@contextmanager
def realtime_section(priority: int, *, busy_wait_us: float = 0.0) -> Iterator[Scheduling]:
    """Run the block as real-time as the OS allows (see the module docstring)."""
    info = Scheduling(requested_priority=priority, busy_wait_us=busy_wait_us)
    old_policy = os.sched_getscheduler(0)
    old_param = os.sched_getparam(0)
    if priority > 0:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
            info.policy, info.priority = "SCHED_FIFO", priority
        except OSError as exc:
            info.error = f"SCHED_FIFO {priority} refused: {exc.strerror or exc}"
    libc, old_slack = _timer_slack(TIMER_SLACK_NS)
    if libc is not None:
        info.timer_slack_ns = TIMER_SLACK_NS
    gc_was_enabled = gc.isenabled()
    gc.collect()
    gc.freeze()
    gc.disable()
    info.gc_disabled = True
    try:
        yield info
    finally:
        if gc_was_enabled:
            gc.enable()
        gc.unfreeze()
        if libc is not None and old_slack:
            libc.prctl(PR_SET_TIMERSLACK, old_slack, 0, 0, 0)
        if info.policy == "SCHED_FIFO":
            os.sched_setscheduler(0, old_policy, old_param)


def _timer_slack(slack_ns: int) -> tuple[Any, int]:
    """Set this thread's timer slack; (libc, the old slack) or (None, 0) if not Linux."""
    if not sys.platform.startswith("linux"):
        return None, 0
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        old = int(libc.prctl(PR_GET_TIMERSLACK, 0, 0, 0, 0))
        if libc.prctl(PR_SET_TIMERSLACK, slack_ns, 0, 0, 0) != 0:
            return None, 0
    except (OSError, AttributeError):
        return None, 0
    return libc, old


def is_cyclic(frame: bytes) -> bool:
    """A frame with a logical datagram (LRW/LRD/LWR): the cyclic stream (docs/architecture.md)."""
    pos, end = _FIRST_DATAGRAM, len(frame)
    while pos + DATAGRAM_HEADER_BYTES <= end:
        if frame[pos] in LOGICAL:
            return True
        length_word = frame[pos + 6] | frame[pos + 7] << 8
        if not length_word & 0x8000:  # the M flag: no datagram follows
            return False
        pos += DATAGRAM_HEADER_BYTES + (length_word & 0x07FF) + 2
    return False


@dataclass(slots=True)
class CycleClock:
    """A transport tap: when every cyclic frame left and whether and when it came back.
    Records only while ``active``."""

    cycle_ns: int
    schedule: Callable[[], int]  # when the cycle now being sent was due
    active: bool = False
    sent_ns: list[int] = field(default_factory=list)
    lateness_ns: list[int] = field(default_factory=list)
    round_trip_ns: list[int] = field(default_factory=list)
    returned: int = 0
    late: int = 0  # came back after one cycle time (the master had stopped waiting)
    _outstanding: dict[int, int] = field(default_factory=dict)  # index -> sent

    def __call__(self, t_ns: int, frame: bytes, returned: bool) -> None:
        if not self.active or len(frame) <= _INDEX_AT:
            return
        index = frame[_INDEX_AT]
        if not returned:
            # is_cyclic, its usual answer (a first datagram LRW/LRD/LWR) without the call
            first_logical = len(frame) >= _CYCLIC_MIN and frame[_FIRST_DATAGRAM] in LOGICAL
            if first_logical or is_cyclic(frame):
                self.sent_ns.append(t_ns)
                self.lateness_ns.append(t_ns - self.schedule())
                self._outstanding[index] = t_ns
            return
        sent = self._outstanding.pop(index, None)
        if sent is None or t_ns < sent:
            return
        self.returned += 1
        self.round_trip_ns.append(t_ns - sent)
        if t_ns - sent > self.cycle_ns:
            self.late += 1

    def report(self, in_flight_ns: int) -> dict[str, Any]:
        """Cycle period, jitter, lateness against the schedule, frames that never came
        back (those sent within ``in_flight_ns`` of the end are in flight, not lost)."""
        import numpy as np

        sent = np.asarray(self.sent_ns, dtype=np.int64)
        periods = np.diff(sent)
        period = summarize_array(periods)
        lateness = np.asarray(self.lateness_ns, dtype=np.int64)
        jitter = period.jitter(divisor=1e3) if period is not None else None
        end = int(sent[-1]) if sent.size else 0
        in_flight = sum(1 for t in self._outstanding.values() if t > end - in_flight_ns)
        offset = summarize_array(lateness)
        return {
            "cycle_period_us": period.to_dict(scale=1e-3) if period is not None else None,
            "cycle_jitter_us": {
                "std": round(jitter["std"], 3),
                "max_deviation_from_median": round(jitter["max_deviation"], 3),
            }
            if jitter is not None
            else None,
            "send_offset_us": offset.to_dict(scale=1e-3) if offset is not None else None,
            "overruns": int((lateness > self.cycle_ns // 2).sum()),
            "cyclic_frames_timed": int(sent.size),
            "late_frames": self.late,
            "never_returned_frames": len(self._outstanding) - in_flight,
        }


def load_now() -> dict[str, Any]:
    """Load averages and CPUs of the host, for the report."""
    try:
        one, five, _fifteen = os.getloadavg()
    except OSError:
        one = five = float("nan")
    return {"cpus": os.cpu_count(), "loadavg_1min": round(one, 2), "loadavg_5min": round(five, 2)}


def process_cpu_s() -> float:
    return time.process_time()


__all__ = [
    "CycleClock",
    "Scheduling",
    "is_cyclic",
    "load_now",
    "process_cpu_s",
    "realtime_section",
]
