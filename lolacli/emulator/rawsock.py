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
the answer, a piece at a time while no frame waits, at least one piece per frame; and so
do the frame plans the chain has to make (a cyclic layout's, new or of an ended epoch).

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
from lolacli.errors import TransportError, UsageError
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
FOLLOW = "follow"  # placement: on the CPU where the master's frames arrive
ANY = "any"  # placement: where the OS puts it
PACKET_FANOUT = 18  # Linux packet socket option: join a fanout group
PACKET_FANOUT_CPU = 2  # the group's member of the CPU the packet arrived on
FOLLOW_LATE_NS = 500_000  # a frame held this long after it arrived, on the master's CPU...
FOLLOW_LATE_FRAMES = 3  # ...this many times in a row: the master keeps that CPU to itself
FOLLOW_BOUNCE_NS = 50_000_000  # frames from another CPU this soon after a move: a bounce
FOLLOW_BACKOFF_NS = 1_000_000_000  # then the OS places the server for this long


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
                # the bin's upper edge, but never past the largest value seen
                return self.max_ns / 1000 if i == self.BINS else min(
                    float(i + 1), self.max_ns / 1000
                )
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
    #: times the server moved to the CPU of the master's frames (placement "follow")
    moves: int = 0
    #: times it left that CPU because its frames waited there (FOLLOW_LATE_FRAMES)
    backoffs: int = 0
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
    (``None``: run it all) to ask between its pieces.

    ``cpu``: where the server runs. :data:`FOLLOW` (the default): on the CPU the master's
    frames arrive on, which is the master's own on a veth pair (a socket per CPU in a
    ``PACKET_FANOUT_CPU`` group says which; the server moves there after answering the
    first frame from a new CPU, within the CPUs it was allowed at the start). The whole
    exchange then runs on one CPU: the master's send wakes the server on its core, the
    answer is in the master's socket before the master looks, and a CPU the hypervisor
    does not run for a while holds up master and emulator alike, never one waiting for
    the other (KickCAT's single drive, 10,000 cycles with a 500 µs timeout, other core
    idle: 9-122 time-outs a run with the OS's placement, none in 4 runs with both on one
    CPU). A master that keeps that CPU (a real-time priority above the server's and never
    sleeping) holds the frames there: after :data:`FOLLOW_LATE_FRAMES` frames in a row
    held over :data:`FOLLOW_LATE_NS` the OS places the server again for
    :data:`FOLLOW_BACKOFF_NS`; so it does when the master's frames come from another CPU
    within :data:`FOLLOW_BOUNCE_NS` of a move (a real-time master below the server's
    priority, which the kernel pushes to the other CPU when the server preempts it).
    :data:`ANY`: the OS places it. A number: pinned to that CPU."""

    def __init__(
        self,
        iface: str,
        chain: Chain,
        *,
        grace_s: float = DEFAULT_GRACE_S,
        realtime_priority: int | None = None,
        keep_cpus_awake: bool = True,
        keep_warm: Callable[[Callable[[], bool] | None], object] | None = None,
        cpu: int | str = FOLLOW,
    ) -> None:
        if not (cpu in (FOLLOW, ANY) or (isinstance(cpu, int) and cpu >= 0)):
            raise ValueError(f"cpu: expected {FOLLOW!r}, {ANY!r} or a CPU number, not {cpu!r}")
        self.iface = iface
        self.keep_warm = keep_warm
        self.keep_cpus_awake = keep_cpus_awake
        self.cpu = cpu
        self._latency_hold: int | None = None
        self.chain = chain
        self.grace_s = grace_s
        self.grace_ns = round(grace_s * 1e9)
        self._next: tuple[bytes, list[tuple[int, int, bytes]], int] | None = None
        self._poller = select.poll()
        self._poll_ms = 100
        self._next_check_ns = 0
        self.realtime_priority = realtime_priority
        self.stats = ServerStats()
        self.scheduling = "normal"
        self._sock: socket.socket | None = None  # the one the answers go out on
        self._socks: list[socket.socket] = []  # a frame on the i-th arrived on CPU i
        self._gc_was_enabled = False
        self._since_gc = 0
        self._wait: Callable[[int], bool] | None = None
        self._next_warm_ns = 0  # keep-warm work is due from then on
        self._allowed: set[int] = set()  # the CPUs the server may run on
        self._follow = False
        self._on_cpu: int | None = None  # the master's CPU the server is on (FOLLOW)
        self._late = 0  # frames in a row held over FOLLOW_LATE_NS there
        self._backoff_until_ns = 0
        self._moved_ns = 0  # when the server last moved to the master's CPU

    def __enter__(self) -> RawSocketServer:
        try:
            self._open()
        except BaseException:
            self._close_sockets()
            raise
        self._wait = readable_within([s.fileno() for s in self._socks])
        _tight_timers()
        self.scheduling = _scheduling(self.realtime_priority)
        self.scheduling += self._placement()
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

    def _open(self) -> None:
        """The sockets: one, or one per CPU in a fanout group when following the master."""
        self._allowed = _allowed_cpus()
        if isinstance(self.cpu, int) and self._allowed and self.cpu not in self._allowed:
            raise UsageError(
                f"--cpu {self.cpu}: not a CPU this process may run on "
                f"({_cpu_list(self._allowed)})"
            )
        self._socks = [open_socket(self.iface)]
        if self.cpu == FOLLOW and len(self._allowed) > 1:
            count = max(os.cpu_count() or 1, max(self._allowed) + 1)
            self._socks += [open_socket(self.iface) for _ in range(count - 1)]
            group = (os.getpid() ^ id(self)) & 0xFFFF
            try:
                for sock in self._socks:
                    sock.setsockopt(
                        _SOL_PACKET, PACKET_FANOUT, group | (PACKET_FANOUT_CPU << 16)
                    )
                self._follow = True
            except OSError:
                for sock in self._socks[1:]:
                    sock.close()
                # a socket that did join a group has left it only when closed: a fresh one
                self._socks[0].close()
                self._socks = [open_socket(self.iface)]
        for sock in self._socks:
            try:
                sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
            except OSError:
                pass  # no receive timestamps: the wake-up figures stay empty
        self._sock = self._socks[0]

    def _placement(self) -> str:
        """Apply a pinned CPU; the placement in words."""
        if isinstance(self.cpu, int):
            _set_cpus({self.cpu})
            return f", on CPU {self.cpu}"
        if self._follow:
            return ", on the CPU of the master's frames"
        return ""

    def __exit__(self, *exc: object) -> None:
        if self._gc_was_enabled:
            gc.enable()
        if self._latency_hold is not None:
            os.close(self._latency_hold)  # closing the file ends the request
            self._latency_hold = None
        if self._socks:
            drops = [_socket_drops(sock) for sock in self._socks]
            known = [d for d in drops if d is not None]
            self.stats.socket_drops = sum(known) if known else None
        self._close_sockets()
        if self._on_cpu is not None or isinstance(self.cpu, int):
            _set_cpus(self._allowed)  # the library caller's thread as it was
            self._on_cpu = None

    def _close_sockets(self) -> None:
        for sock in self._socks:
            sock.close()
        self._socks = []
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
        if self._sock is None:
            raise TransportError("server not opened (use it as a context manager)")
        self._poller = select.poll()
        for sock in self._socks:
            sock.setblocking(False)  # waits go through poll(): a frame here is taken at once
            self._poller.register(sock, select.POLLIN)
        self._poll_ms = max(1, round(poll_s * 1000))
        self.stats.started_ns = time.monotonic_ns()
        next_status = time.monotonic() + status_interval_s
        while not should_stop():
            self._serve_one(self._sock)
            if on_status is not None and time.monotonic() >= next_status:
                on_status(self.stats)
                next_status = time.monotonic() + status_interval_s
        return self.stats

    def _serve_one(self, sock: socket.socket) -> None:
        if self._next is None and not self._poll():
            if not self._poller.poll(WARM_EVERY_MS if self.keep_warm else self._poll_ms):
                if self.keep_warm is not None:
                    self.keep_warm(None)
                    self._next_warm_ns = time.monotonic_ns() + WARM_EVERY_MS * 1_000_000
                self.chain.run_deferred_cycles()  # nothing may wait while the master is silent
                self.chain.tick(time.monotonic_ns())  # watchdogs run while it is silent
                gc.collect()
                return
            if not self._poll():
                return  # a frame of our own, or a wake-up for nothing
        received = self._next
        self._next = None
        assert received is not None
        frame, ancillary, cpu = received
        t_ns = time.monotonic_ns()
        arrived = _arrival_ns(ancillary)
        held_ns = time.time_ns() - arrived if arrived is not None else None
        if held_ns is not None:
            self.stats.wake.add(held_ns)
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
        if self._follow:
            self._place(cpu, held_ns)
        if self._firmware() or self._plans() or self._spin():
            self.chain.hold_deferred_cycle()  # the next frame is here: it is answered first
            return
        # device updates after the answer is on its way, giving way to the next frame
        if self.chain.run_deferred_cycles(should_yield=self._frame_waiting):
            self._idle()

    def _place(self, cpu: int, held_ns: int | None) -> None:
        """After answering a frame that arrived on ``cpu`` (held ``held_ns`` before the
        server took it): move to that CPU, or leave it to the OS when the master keeps it
        (frames held there) or leaves it when the server comes (a bounce)."""
        now = time.monotonic_ns()
        if cpu == self._on_cpu:
            if held_ns is None or held_ns <= FOLLOW_LATE_NS:
                self._late = 0
                return
            self._late += 1
            if self._late >= FOLLOW_LATE_FRAMES:
                self._back_off(now)
            return
        if self._on_cpu is not None and now - self._moved_ns < FOLLOW_BOUNCE_NS:
            # the master went elsewhere as the server came: a real-time master the
            # kernel pushes off the CPU the server preempts it on, or a busy CPU the load
            # balancer moves it from; chasing it would move both on every frame
            self._back_off(now)
            return
        if cpu not in self._allowed or now < self._backoff_until_ns:
            return
        if _set_cpus({cpu}):
            self._on_cpu = cpu
            self._late = 0
            self._moved_ns = now
            self.stats.moves += 1
        else:
            self._follow = False  # refused (a cpuset changed under us): the OS places it

    def _back_off(self, now: int) -> None:
        """The OS places the server for :data:`FOLLOW_BACKOFF_NS`."""
        self._late = 0
        self._on_cpu = None
        self._backoff_until_ns = now + FOLLOW_BACKOFF_NS
        self.stats.backoffs += 1
        _set_cpus(self._allowed)

    def _poll(self) -> bool:
        """Take a frame that is already here (kept for the next answer); True if one is."""
        for cpu, sock in enumerate(self._socks):
            while True:
                try:
                    frame, ancillary, _flags, address = sock.recvmsg(
                        MAX_FRAME_BYTES, 64, socket.MSG_DONTWAIT
                    )
                except (BlockingIOError, InterruptedError):
                    break  # nothing here
                except OSError as exc:
                    raise TransportError(
                        f"{self.iface}: receive failed: {exc.strerror or exc}"
                    ) from None
                if len(address) > 2 and address[2] == PACKET_OUTGOING:
                    continue
                self._next = frame, ancillary, cpu
                return True
        return False

    def _frame_waiting(self) -> bool:
        """Whether the master's next frame is here (looked for at most every
        :data:`YIELD_CHECK_NS`, so the check costs little against the work it interrupts)."""
        now = time.monotonic_ns()
        if now < self._next_check_ns or self._sock is None:
            return False
        self._next_check_ns = now + YIELD_CHECK_NS
        return self._poll()

    def _spin(self) -> bool:
        """Watch the socket for ``grace_s`` after an answer: the master takes the answer
        meanwhile, and its next frame (in a start-up and a mailbox exchange they come back
        to back) is answered at once. Busy for the first :data:`GRACE_BUSY_NS` (pysoem's
        next frame comes 5-6 µs after the answer), then blocked on the socket for the
        rest (``ppoll``, whose timeout is in ns): a master on this core, which a busy
        real-time loop would hold off for all of the grace, sends meanwhile (KickCAT with
        a CPU hog on the other core sent each of its back-to-back frames 110 µs after the
        last answer when the watch was busy throughout). On the master's own CPU
        (placement :data:`FOLLOW`) the watch is blocked throughout: there the master
        cannot send while the server spins, and its frame wakes the server at once."""
        now = time.monotonic_ns()
        busy_until = now if self._on_cpu is not None else now + GRACE_BUSY_NS
        deadline = now + self.grace_ns
        while True:
            if self._poll():
                return True
            now = time.monotonic_ns()
            if now >= deadline:
                return False
            if now >= busy_until and self._wait is not None:
                self._wait(deadline - now)

    def _firmware(self) -> bool:
        """The slaves' firmware work, a piece at a time while no frame waits (at least
        one piece per frame, so it never starves). True when a frame waits."""
        chain = self.chain
        if not chain.firmware_pending:
            return False
        chain.run_firmware(1)
        while chain.firmware_pending:
            if self._poll():
                return True
            chain.run_firmware(1)
        return False

    def _plans(self) -> bool:
        """The chain's pending frame plans, a piece at a time while no frame waits, before
        the grace: a master polling faster than the grace leaves no idle moment for them
        (:meth:`Planner.work`). True when a frame waits."""
        chain = self.chain
        return chain.planner.pending and not chain.planner.work(self._frame_waiting)

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


def _allowed_cpus() -> set[int]:
    """The CPUs this thread may run on (empty where the OS does not say)."""
    try:
        return set(os.sched_getaffinity(0))
    except (OSError, AttributeError):
        return set()


def _set_cpus(cpus: set[int]) -> bool:
    """Run this thread on ``cpus`` from now on (Linux moves it at once); False if refused."""
    if not cpus:
        return False
    try:
        os.sched_setaffinity(0, cpus)
    except (OSError, AttributeError):
        return False
    return True


def _cpu_list(cpus: set[int]) -> str:
    return ", ".join(str(c) for c in sorted(cpus))


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


def readable_within(fds: list[int]) -> Callable[[int], bool] | None:
    """A wait of at most ``ns`` nanoseconds for one of ``fds`` to become readable, True
    if one did (Linux ``ppoll``: poll() and Python's timeouts round up to whole
    milliseconds); ``None`` where the C library has no ppoll."""
    try:
        ppoll = ctypes.CDLL(None, use_errno=True).ppoll
    except (OSError, AttributeError):
        return None
    ppoll.argtypes = [ctypes.c_void_p, ctypes.c_ulong, ctypes.c_void_p, ctypes.c_void_p]
    ppoll.restype = ctypes.c_int
    pollfds = (_PollFd * len(fds))(*(_PollFd(fd, select.POLLIN, 0) for fd in fds))
    timeout = _Timespec(0, 0)
    at_fds, at_timeout, count = ctypes.addressof(pollfds), ctypes.addressof(timeout), len(fds)

    def wait(ns: int) -> bool:
        timeout.tv_sec, timeout.tv_nsec = divmod(max(0, ns), 1_000_000_000)
        for pollfd in pollfds:
            pollfd.revents = 0
        return bool(ppoll(at_fds, count, at_timeout, None) > 0)

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
