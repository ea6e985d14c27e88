"""Real-time transport: serve a :class:`Chain` on a network interface (Linux AF_PACKET).

The server receives EtherCAT frames (ethertype 0x88A4) on the interface, runs each through
the chain, and sends the returned frame back on the same interface at once (the modelled
bus delay is not waited for: the host is the bottleneck). Frames the socket itself sent
are skipped (``PACKET_OUTGOING``), so on a veth pair only the master's frames are served.

The answer goes first; the work the frame left (device cycles, DC control loops, writes
into the slaves' memories) runs afterwards, once the master had ``grace_s`` to take the
answer (the server sleeps that long, or until the master's next frame comes). On a host
where master and emulator share a core the sleep is what lets the master see the answer
before that work is done. When the next frame comes first, it is answered first and the
device cycle waits with the outputs it was due (:meth:`Chain.hold_deferred_cycle`).
"""

from __future__ import annotations

import ctypes
import gc
import os
import select
import socket
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass

from lolacli.emulator.chain import Chain
from lolacli.errors import TransportError
from lolacli.rawsocket import MAX_FRAME_BYTES, PACKET_OUTGOING, open_socket

DEFAULT_GRACE_S = 100e-6
PR_SET_TIMERSLACK = 29
TIMER_SLACK_NS = 1000


@dataclass(slots=True)
class ServerStats:
    received: int = 0
    answered: int = 0
    lost: int = 0
    started_ns: int = 0
    max_service_ns: int = 0


class RawSocketServer:
    """Answers a real master on ``iface`` with the emulated chain."""

    def __init__(
        self,
        iface: str,
        chain: Chain,
        *,
        grace_s: float = DEFAULT_GRACE_S,
        realtime_priority: int = 0,
    ) -> None:
        self.iface = iface
        self.chain = chain
        self.grace_s = grace_s
        self.realtime_priority = realtime_priority
        self.stats = ServerStats()
        self._sock: socket.socket | None = None

    def __enter__(self) -> RawSocketServer:
        self._sock = open_socket(self.iface)
        _tight_timers()
        if self.realtime_priority > 0:
            _realtime(self.realtime_priority)
        gc.collect()
        gc.freeze()  # the chain lives as long as the server: no collector passes over it
        return self

    def __exit__(self, *exc: object) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def serve(
        self,
        should_stop: Callable[[], bool],
        *,
        on_status: Callable[[ServerStats], None] | None = None,
        status_interval_s: float = 1.0,
        poll_s: float = 0.1,
    ) -> ServerStats:
        """Serve until ``should_stop()``; ``on_status`` every ``status_interval_s``."""
        sock = self._sock
        if sock is None:
            raise TransportError("server not opened (use it as a context manager)")
        sock.settimeout(poll_s)
        self.stats.started_ns = time.monotonic_ns()
        next_status = time.monotonic() + status_interval_s
        while not should_stop():
            self._serve_one(sock)
            if on_status is not None and time.monotonic() >= next_status:
                on_status(self.stats)
                next_status = time.monotonic() + status_interval_s
        return self.stats

    def _serve_one(self, sock: socket.socket) -> None:
        try:
            frame, address = sock.recvfrom(MAX_FRAME_BYTES)
        except TimeoutError:
            self.chain.tick(time.monotonic_ns())  # watchdogs run while the master is silent
            return
        except InterruptedError:
            return
        except OSError as exc:
            raise TransportError(f"{self.iface}: receive failed: {exc.strerror or exc}") from None
        if len(address) > 2 and address[2] == PACKET_OUTGOING:
            return
        t_ns = time.monotonic_ns()
        self.stats.received += 1
        reply, _delay_ns = self.chain.process(frame, t_ns, defer_cycles=True)
        if reply is None:
            self.stats.lost += 1
            return
        try:
            sock.send(reply)
        except OSError as exc:
            raise TransportError(f"{self.iface}: send failed: {exc.strerror or exc}") from None
        self.stats.answered += 1
        self.stats.max_service_ns = max(self.stats.max_service_ns, time.monotonic_ns() - t_ns)
        if self.grace_s > 0 and select.select([sock], [], [], self.grace_s)[0]:
            self.chain.hold_deferred_cycle()  # the next frame is here: it is answered first
            return
        self.chain.run_deferred_cycles()  # device updates after the answer is on its way


def _realtime(priority: int) -> None:
    """SCHED_FIFO at ``priority``: the emulator stands in for slave hardware, which does not
    wait for a master process to yield the core. TransportError when not permitted."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError) as exc:
        raise TransportError(
            f"cannot run SCHED_FIFO at priority {priority}: {getattr(exc, 'strerror', exc)}"
        ) from None


def _tight_timers() -> None:
    """Ask Linux for 1 µs timer slack (default 50 µs), so the grace sleep is as short as
    asked; elsewhere, or if refused, the sleeps are just longer."""
    if not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_TIMERSLACK, TIMER_SLACK_NS, 0, 0, 0)
    except (OSError, AttributeError):
        pass
