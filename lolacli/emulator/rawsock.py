"""Real-time transport: serve a :class:`Chain` on a network interface (Linux AF_PACKET).

The server receives EtherCAT frames (ethertype 0x88A4) on the interface, runs each through
the chain, and sends the returned frame back on the same interface at once (the modelled
bus delay is not waited for: the host is the bottleneck). Frames the socket itself sent
are skipped (``PACKET_OUTGOING``), so on a veth pair only the master's frames are served.

The answer goes first; the work the frame left (device cycles, DC control loops, writes
into the slaves' memories) runs afterwards, once the master had ``grace_s`` to take the
answer (the server watches the socket that long without sleeping, so a frame the master
sends right after the answer, as in any start-up or mailbox exchange, is answered with no
wake-up latency). When the next frame comes first, it is answered first and the
device cycle waits with the outputs it was due (:meth:`Chain.hold_deferred_cycle`).
The slaves' firmware work (AL state requests, mailbox services) runs the same way: after
the answer, a piece at a time while no frame waits, at least one piece per frame.

Scheduling: by default the server asks for SCHED_FIFO (priority :data:`DEFAULT_PRIORITY`)
and keeps normal scheduling where the OS refuses; it blocks on the socket, so it takes a
core only while it answers. While it serves it also holds the CPUs' wake-up latency at 0
(Linux PM QoS, ``/dev/cpu_dma_latency``, as cyclictest does): an idle core then polls
instead of halting, so a frame that arrives after a quiet spell (a start-up's first
frame, a master cycling every 5 ms) does not wait for the core to wake; the hold ends with
the server; and every :data:`WARM_EVERY_MS` it runs its keep-warm work (a few frames through
a chain of its own, giving way to a frame that comes), while no frame comes and after a
frame's work is done, so the first frame after a quiet spell, or a start-up's or mailbox
frame among cyclic ones, finds the answer path in the caches.
:attr:`RawSocketServer.scheduling` says which it got. The collector is off while serving
(the chain makes little cyclic garbage); young objects are collected in idle moments.

:class:`ServerStats` keeps, per frame, the time from the kernel's receive timestamp to the
server holding the frame (``wake``), and from there to the answer sent (``service``).
"""

from __future__ import annotations

import ctypes
import gc
import os
import select
import socket
import struct
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from lolacli.emulator.chain import Chain
from lolacli.errors import TransportError
from lolacli.rawsocket import MAX_FRAME_BYTES, PACKET_OUTGOING, open_socket

DEFAULT_GRACE_S = 100e-6
GRACE_BUSY_NS = 20_000  # the grace's busy part: then blocked, which leaves the core to others
DEFAULT_PRIORITY = 10  # SCHED_FIFO priority asked for by default (1..99)
PR_SET_TIMERSLACK = 29
TIMER_SLACK_NS = 1000
CPU_DMA_LATENCY = "/dev/cpu_dma_latency"  # Linux PM QoS: the CPUs' wake-up latency bound
SO_TIMESTAMPNS = 35  # Linux: receive timestamps as struct timespec (socket module lacks it)
SCM_TIMESTAMPNS = SO_TIMESTAMPNS
_TIMESPEC = struct.Struct("qq")
YIELD_CHECK_NS = 20_000  # deferred device work looks for a waiting frame this often
GC_EVERY_FRAMES = 4096  # a young-generation collection in an idle moment after this many
WARM_EVERY_MS = 10  # a quiet server runs its keep-warm work this often


class LatencyHistogram:
    """Durations in 1 µs bins up to 10 ms (beyond: one overflow bin, and the maximum)."""

    BINS = 10_000

    def __init__(self) -> None:
        self.counts = [0] * (self.BINS + 1)
        self.n = 0
        self.max_ns = 0

    def add(self, ns: int) -> None:
        self.counts[min(max(ns, 0) // 1000, self.BINS)] += 1
        self.n += 1
        if ns > self.max_ns:
            self.max_ns = ns

    def percentile_us(self, p: float) -> float | None:
        """The upper edge of the bin holding the ``p`` quantile (0..1), in µs."""
        if not self.n:
            return None
        rank = max(1, round(p * self.n))
        seen = 0
        for i, c in enumerate(self.counts):
            seen += c
            if seen >= rank:
                return self.max_ns / 1000 if i == self.BINS else float(i + 1)
        return self.max_ns / 1000

    def summary(self) -> dict[str, float | int | None]:
        return {
            "count": self.n,
            "p50_us": self.percentile_us(0.5),
            "p99_us": self.percentile_us(0.99),
            "max_us": self.max_ns / 1000 if self.n else None,
        }


@dataclass(slots=True)
class ServerStats:
    received: int = 0
    answered: int = 0
    lost: int = 0
    started_ns: int = 0
    max_service_ns: int = 0
    #: frames the kernel dropped at this socket (PACKET_STATISTICS), None: not told
    socket_drops: int | None = None
    wake: LatencyHistogram = field(default_factory=LatencyHistogram)  # kernel rx -> server
    service: LatencyHistogram = field(default_factory=LatencyHistogram)  # server -> sent


_SOL_PACKET = 263
_PACKET_STATISTICS = 6


def _socket_drops(sock: socket.socket) -> int | None:
    """Frames the kernel could not queue to this packet socket since it was opened
    (``struct tpacket_stats``: packets, drops); None where the socket does not say."""
    try:
        raw = sock.getsockopt(_SOL_PACKET, _PACKET_STATISTICS, 8)
    except OSError:
        return None
    return struct.unpack("=II", raw)[1] if len(raw) == 8 else None


class RawSocketServer:
    """Answers a real master on ``iface`` with the emulated chain.

    ``realtime_priority``: ``None`` asks for SCHED_FIFO at :data:`DEFAULT_PRIORITY` and
    keeps normal scheduling where that is not permitted; 0 keeps normal scheduling; 1..99
    asks for that priority and fails (TransportError) where it is not permitted.
    ``keep_cpus_awake``: hold the CPUs' wake-up latency at 0 while serving where permitted
    (root); False leaves the CPUs' idle states alone. ``keep_warm``: called every
    :data:`WARM_EVERY_MS` while no frame comes (work that keeps the answer path's code and
    data in the caches; it must not touch the chain served), given ``should_yield``
    (``None``: run it all) to ask between its pieces."""

    def __init__(
        self,
        iface: str,
        chain: Chain,
        *,
        grace_s: float = DEFAULT_GRACE_S,
        realtime_priority: int | None = None,
        keep_cpus_awake: bool = True,
        keep_warm: Callable[[Callable[[], bool] | None], object] | None = None,
    ) -> None:
        self.iface = iface
        self.keep_warm = keep_warm
        self.keep_cpus_awake = keep_cpus_awake
        self._latency_hold: int | None = None
        self.chain = chain
        self.grace_s = grace_s
        self.grace_ns = round(grace_s * 1e9)
        self._next: tuple[bytes, list[tuple[int, int, bytes]]] | None = None
        self._poller = select.poll()
        self._poll_ms = 100
        self._next_check_ns = 0
        self.realtime_priority = realtime_priority
        self.stats = ServerStats()
        self.scheduling = "normal"
        self._sock: socket.socket | None = None
        self._gc_was_enabled = False
        self._since_gc = 0
        self._wait: Callable[[int], bool] | None = None
        self._next_warm_ns = 0  # keep-warm work is due from then on

    def __enter__(self) -> RawSocketServer:
        self._sock = open_socket(self.iface)
        self._wait = readable_within(self._sock.fileno())
        try:
            self._sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
        except OSError:
            pass  # no receive timestamps: the wake-up figures stay empty
        _tight_timers()
        self.scheduling = _scheduling(self.realtime_priority)
        if self.keep_cpus_awake:
            self._latency_hold = hold_cpu_latency(0)
            self.scheduling += (
                ", CPU wake-up latency held at 0 µs"
                if self._latency_hold is not None
                else ", CPU idle states as they are (PM QoS not permitted)"
            )
        gc.collect()
        gc.freeze()  # the chain lives as long as the server: no collector passes over it
        self._gc_was_enabled = gc.isenabled()
        gc.disable()  # no collection in the middle of an answer; see _idle
        return self

    def __exit__(self, *exc: object) -> None:
        if self._gc_was_enabled:
            gc.enable()
        if self._latency_hold is not None:
            os.close(self._latency_hold)  # closing the file ends the request
            self._latency_hold = None
        if self._sock is not None:
            self.stats.socket_drops = _socket_drops(self._sock)
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
        sock.setblocking(False)  # waits go through poll(): a frame already here is taken at once
        self._poller = select.poll()
        self._poller.register(sock, select.POLLIN)
        self._poll_ms = max(1, round(poll_s * 1000))
        self.stats.started_ns = time.monotonic_ns()
        next_status = time.monotonic() + status_interval_s
        while not should_stop():
            self._serve_one(sock)
            if on_status is not None and time.monotonic() >= next_status:
                on_status(self.stats)
                next_status = time.monotonic() + status_interval_s
        return self.stats

    def _serve_one(self, sock: socket.socket) -> None:
        if self._next is None and not self._poll(sock):
            if not self._poller.poll(WARM_EVERY_MS if self.keep_warm else self._poll_ms):
                if self.keep_warm is not None:
                    self.keep_warm(None)
                    self._next_warm_ns = time.monotonic_ns() + WARM_EVERY_MS * 1_000_000
                self.chain.run_deferred_cycles()  # nothing may wait while the master is silent
                self.chain.tick(time.monotonic_ns())  # watchdogs run while it is silent
                gc.collect()
                return
            if not self._poll(sock):
                return  # a frame of our own, or a wake-up for nothing
        received = self._next
        self._next = None
        assert received is not None
        frame, ancillary = received
        t_ns = time.monotonic_ns()
        arrived = _arrival_ns(ancillary)
        if arrived is not None:
            self.stats.wake.add(time.time_ns() - arrived)
        self.stats.received += 1
        reply, _delay_ns = self.chain.process(frame, t_ns, defer_cycles=True)
        if reply is None:
            self.stats.lost += 1
            return
        try:
            sock.send(reply)
        except OSError as exc:
            raise TransportError(f"{self.iface}: send failed: {exc.strerror or exc}") from None
        service_ns = time.monotonic_ns() - t_ns
        self.stats.answered += 1
        self.stats.service.add(service_ns)
        self.stats.max_service_ns = max(self.stats.max_service_ns, service_ns)
        if self._firmware(sock) or self._spin(sock):
            self.chain.hold_deferred_cycle()  # the next frame is here: it is answered first
            return
        # device updates after the answer is on its way, giving way to the next frame
        if self.chain.run_deferred_cycles(should_yield=self._frame_waiting):
            self._idle()

    def _poll(self, sock: socket.socket) -> bool:
        """Take a frame that is already here (kept for the next answer); True if one is."""
        while True:
            try:
                frame, ancillary, _flags, address = sock.recvmsg(
                    MAX_FRAME_BYTES, 64, socket.MSG_DONTWAIT
                )
            except (BlockingIOError, InterruptedError):
                return False  # nothing here
            except OSError as exc:
                raise TransportError(
                    f"{self.iface}: receive failed: {exc.strerror or exc}"
                ) from None
            if len(address) > 2 and address[2] == PACKET_OUTGOING:
                continue
            self._next = frame, ancillary
            return True

    def _frame_waiting(self) -> bool:
        """Whether the master's next frame is here (looked for at most every
        :data:`YIELD_CHECK_NS`, so the check costs little against the work it interrupts)."""
        now = time.monotonic_ns()
        if now < self._next_check_ns or self._sock is None:
            return False
        self._next_check_ns = now + YIELD_CHECK_NS
        return self._poll(self._sock)

    def _spin(self, sock: socket.socket) -> bool:
        """Watch the socket for ``grace_s`` after an answer: the master takes the answer
        meanwhile, and its next frame (in a start-up and a mailbox exchange they come back
        to back) is answered at once. Busy for the first :data:`GRACE_BUSY_NS` (pysoem's
        next frame comes 5-6 µs after the answer), then blocked on the socket for the
        rest (``ppoll``, whose timeout is in ns): a master on this core, which a busy
        real-time loop would hold off for all of the grace, sends meanwhile (KickCAT with
        a CPU hog on the other core sent each of its back-to-back frames 110 µs after the
        last answer when the watch was busy throughout)."""
        now = time.monotonic_ns()
        busy_until = now + GRACE_BUSY_NS
        deadline = now + self.grace_ns
        while True:
            if self._poll(sock):
                return True
            now = time.monotonic_ns()
            if now >= deadline:
                return False
            if now >= busy_until and self._wait is not None:
                self._wait(deadline - now)

    def _firmware(self, sock: socket.socket) -> bool:
        """The slaves' firmware work, a piece at a time while no frame waits (at least
        one piece per frame, so it never starves). True when a frame waits."""
        chain = self.chain
        if not chain.firmware_pending:
            return False
        chain.run_firmware(1)
        while chain.firmware_pending:
            if self._poll(sock):
                return True
            chain.run_firmware(1)
        return False

    def _idle(self) -> None:
        """After a frame's work, while no frame waits: keep-warm work when due (the
        master may be sending only its cyclic frame, whose path stays warm, for long),
        now and then a collection of young objects."""
        if self.keep_warm is not None and time.monotonic_ns() >= self._next_warm_ns:
            if not self.keep_warm(self._frame_waiting):
                return  # a frame waits
            self._next_warm_ns = time.monotonic_ns() + WARM_EVERY_MS * 1_000_000
        self._since_gc += 1
        if self._since_gc >= GC_EVERY_FRAMES:
            self._since_gc = 0
            gc.collect(0)


def _arrival_ns(ancillary: list[tuple[int, int, bytes]]) -> int | None:
    """The kernel's receive timestamp (CLOCK_REALTIME, ns) from SO_TIMESTAMPNS data."""
    for level, kind, data in ancillary:
        if level == socket.SOL_SOCKET and kind == SCM_TIMESTAMPNS and len(data) >= 16:
            sec, nsec = _TIMESPEC.unpack_from(data)
            return int(sec * 1_000_000_000 + nsec)
    return None


def _scheduling(priority: int | None) -> str:
    """Apply the scheduling asked for; what the server got, in words."""
    if priority is None:
        try:
            _realtime(DEFAULT_PRIORITY)
        except TransportError:
            return "normal (SCHED_FIFO not permitted)"
        return f"SCHED_FIFO priority {DEFAULT_PRIORITY}"
    if priority > 0:
        _realtime(priority)
        return f"SCHED_FIFO priority {priority}"
    return "normal"


def _realtime(priority: int) -> None:
    """SCHED_FIFO at ``priority``: the emulator stands in for slave hardware, which does not
    wait for a master process to yield the core. TransportError when not permitted."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError) as exc:
        raise TransportError(
            f"cannot run SCHED_FIFO at priority {priority}: {getattr(exc, 'strerror', exc)}"
        ) from None


def hold_cpu_latency(us: int) -> int | None:
    """Ask Linux to keep every CPU's wake-up latency at or below ``us`` (PM QoS): the
    request holds while the returned descriptor is open (close it to end it). None where
    ``/dev/cpu_dma_latency`` is missing or not writable (it needs root)."""
    try:
        fd = os.open(CPU_DMA_LATENCY, os.O_WRONLY | os.O_CLOEXEC)
    except OSError:
        return None
    try:
        os.write(fd, struct.pack("=i", us))
    except OSError:
        os.close(fd)
        return None
    return fd


def cpu_latency_limit_us() -> int | None:
    """The CPUs' wake-up latency bound in force now (the tightest request), in µs; None
    where it cannot be read."""
    try:
        fd = os.open(CPU_DMA_LATENCY, os.O_RDONLY | os.O_CLOEXEC)
    except OSError:
        return None
    try:
        raw = os.read(fd, 4)
    except OSError:
        return None
    finally:
        os.close(fd)
    return struct.unpack("=i", raw)[0] if len(raw) == 4 else None


class _PollFd(ctypes.Structure):
    _fields_ = [("fd", ctypes.c_int), ("events", ctypes.c_short), ("revents", ctypes.c_short)]


class _Timespec(ctypes.Structure):
    _fields_ = [("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long)]


def readable_within(fd: int) -> Callable[[int], bool] | None:
    """A wait of at most ``ns`` nanoseconds for ``fd`` to become readable, True if it did
    (Linux ``ppoll``: poll() and Python's timeouts round up to whole milliseconds);
    ``None`` where the C library has no ppoll."""
    try:
        ppoll = ctypes.CDLL(None, use_errno=True).ppoll
    except (OSError, AttributeError):
        return None
    ppoll.argtypes = [ctypes.c_void_p, ctypes.c_ulong, ctypes.c_void_p, ctypes.c_void_p]
    ppoll.restype = ctypes.c_int
    pollfd = _PollFd(fd, select.POLLIN, 0)
    timeout = _Timespec(0, 0)
    at_fd, at_timeout = ctypes.addressof(pollfd), ctypes.addressof(timeout)

    def wait(ns: int) -> bool:
        timeout.tv_sec, timeout.tv_nsec = divmod(max(0, ns), 1_000_000_000)
        pollfd.revents = 0
        return bool(ppoll(at_fd, 1, at_timeout, None) > 0)

    return wait


def _tight_timers() -> None:
    """Ask Linux for 1 µs timer slack (default 50 µs; a SCHED_FIFO task has none), so the
    grace's wait ends when asked; elsewhere, or if refused, the waits are just longer."""
    if not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_TIMERSLACK, TIMER_SLACK_NS, 0, 0, 0)
    except (OSError, AttributeError):
        pass
