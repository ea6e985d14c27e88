"""The master's one seam to a bus: send a frame, receive the returned frame with its times.

Modelled on python-can's ``BusABC``: a :class:`Transport` has :meth:`~Transport.send`
and :meth:`~Transport.recv`, a clock (:meth:`~Transport.now_ns`, :meth:`~Transport.wait_until`)
and taps that see every frame in time order (recorders). Two implementations:

* :class:`ChainTransport` — an in-process frame processor (the emulated chain's
  ``process(frame, t_ns) -> (reply | None, delay_ns)``) in *virtual time*: the clock jumps
  to whatever the master waits for, the reply comes back ``delay_ns`` after the frame left
  (the chain's delay model), a lost frame never does. Frames leave back to back: one
  starts when the previous one has left the master's port (wire time + preamble/IFG).
* :class:`RawSocketTransport` — a raw socket on a network interface in real time
  (``time.monotonic_ns``), any NIC, veth or TAP.

The master knows nothing else of what is behind the transport.
"""

from __future__ import annotations

import heapq
import select
import socket
import struct
import time
from collections import deque
from collections.abc import Callable
from typing import NamedTuple, Protocol

from lolacli.errors import TransportError
from lolacli.rawsocket import SO_TIMESTAMPNS
from lolacli.timing.model import INTER_FRAME_GAP_BYTES, LINK_100_MBIT_S, PREAMBLE_SFD_BYTES
from lolacli.wire.frame import FCS_BYTES, MIN_FRAME_BYTES

#: A tap sees every frame on the master's port: (time ns, frame bytes, returned?).
Tap = Callable[[int, bytes, bool], None]


class Received(NamedTuple):
    """A frame as it came back: its bytes and when it left and returned (ns). A named
    tuple: one is made for every frame (a frozen dataclass's ``__init__`` costs ~0.5 µs
    more, some 2% of a simulated LOLA cycle)."""

    frame: bytes
    sent_ns: int
    received_ns: int


class Transport(Protocol):
    """What the master needs of a bus (python-can's ``BusABC`` is the model)."""

    taps: list[Tap]

    def now_ns(self) -> int:
        """The transport's clock (virtual or monotonic), integer nanoseconds."""
        ...

    def send(self, frame: bytes) -> int:
        """Put ``frame`` on the wire; returns when it left (ns)."""
        ...

    def recv(self, timeout_ns: int) -> Received | None:
        """The next returned frame, waiting at most ``timeout_ns``; ``None`` if none."""
        ...

    def wait_until(self, t_ns: int) -> None:
        """Let the clock reach ``t_ns`` (sleep in real time, jump in virtual time)."""
        ...

    def close(self) -> None: ...


class FrameProcessor(Protocol):
    """Anything that answers a frame at a time: the emulated chain's interface."""

    def process(self, frame: bytes, t_ns: int) -> tuple[bytes | None, int]: ...


def frame_time_on_wire_ns(frame_length: int, link_bit_s: int = LINK_100_MBIT_S) -> int:
    """How long a frame of ``frame_length`` bytes (without FCS) occupies the master's
    port: FCS, padding to 64, preamble/SFD and the inter-frame gap (docs/architecture.md)."""
    on_wire = max(frame_length + FCS_BYTES, MIN_FRAME_BYTES)
    return (on_wire + PREAMBLE_SFD_BYTES + INTER_FRAME_GAP_BYTES) * 8 * 1_000_000_000 // link_bit_s


#: the longest sleep of a real-time wait between two looks at a stop request
_SLICE_NS = 100_000_000


class ChainTransport:
    """A frame processor in virtual time (see the module docstring)."""

    def __init__(
        self,
        processor: FrameProcessor,
        *,
        start_ns: int = 1_000_000_000,
        link_bit_s: int = LINK_100_MBIT_S,
    ) -> None:
        self.processor = processor
        self.taps: list[Tap] = []
        self.link_bit_s = link_bit_s
        self._now = start_ns
        self._port_free_ns = start_ns  # when the last frame has left the master's port
        self._in_flight: list[tuple[int, int, int, bytes]] = []  # (received, seq, sent, frame)
        self._seq = 0
        self._inbox: deque[Received] = deque()
        self.frames_sent = 0
        self.frames_lost = 0
        self.processing_ns = 0  # CPU time spent in the processor (the emulated bus itself)

    @property
    def link_bit_s(self) -> int:
        """The master's link speed (bit/s): how long a frame occupies its port."""
        return self._link_bit_s

    @link_bit_s.setter
    def link_bit_s(self, bit_s: int) -> None:
        self._link_bit_s = bit_s
        self._on_wire_ns: dict[int, int] = {}  # frame_time_on_wire_ns by frame length

    def now_ns(self) -> int:
        return self._now

    def send(self, frame: bytes) -> int:
        t = self._now if self._now > self._port_free_ns else self._port_free_ns
        heap = self._in_flight
        if heap and heap[0][0] <= t:  # (_deliver's own test: no call when nothing is due)
            self._deliver(t)
        for tap in self.taps:
            tap(t, frame, False)
        self.frames_sent += 1
        on_wire = self._on_wire_ns.get(len(frame))
        if on_wire is None:
            on_wire = frame_time_on_wire_ns(len(frame), self._link_bit_s)
            self._on_wire_ns[len(frame)] = on_wire
        self._port_free_ns = t + on_wire
        clock = time.perf_counter_ns
        c0 = clock()
        reply, delay_ns = self.processor.process(frame, t)
        self.processing_ns += clock() - c0
        if reply is None:
            self.frames_lost += 1
        else:
            self._seq += 1
            heapq.heappush(self._in_flight, (t + delay_ns, self._seq, t, reply))
        return t

    def recv(self, timeout_ns: int) -> Received | None:
        if not self._inbox:
            deadline = self._now + max(0, timeout_ns)
            if self._in_flight and self._in_flight[0][0] <= deadline:
                self._now = max(self._now, self._in_flight[0][0])
            else:
                self._now = deadline
            self._deliver(self._now)
        return self._inbox.popleft() if self._inbox else None

    def wait_until(self, t_ns: int) -> None:
        if t_ns > self._now:
            self._now = t_ns
        heap = self._in_flight
        if heap and heap[0][0] <= self._now:
            self._deliver(self._now)

    def _deliver(self, t_ns: int) -> None:
        """Frames that have returned by ``t_ns`` go to the inbox (and the taps), in order."""
        heap = self._in_flight
        while heap and heap[0][0] <= t_ns:
            received, _seq, sent, reply = heapq.heappop(heap)
            for tap in self.taps:
                tap(received, reply, True)
            self._inbox.append(Received(reply, sent, received))

    def close(self) -> None:
        self._deliver(self._now)


class RawSocketTransport:
    """A raw EtherCAT socket on ``iface``, real time (see the module docstring).

    Frames this host sent (``PACKET_OUTGOING``) are not returned frames and are skipped,
    and so are frames whose source MAC is not the one this transport sends with (the
    first ESC sets the locally administered bit, nothing else): another master's frames
    on a shared segment, counted in :attr:`foreign_frames`.
    A returned frame's time is the kernel's receive stamp (``SO_TIMESTAMPNS``, taken to
    the monotonic clock), not the time :meth:`recv` got round to reading it: a master that
    collects the last cycle's frames at the start of the next one still measures their
    round trip. ``spin_ns``: :meth:`wait_until` sleeps until that long before the time
    and busy-waits the rest (a sleep wakes up late by tens of µs, more under load); with
    :attr:`wake_lateness_ns` set to a list it records how late each wait ended.
    """

    def __init__(self, iface: str, *, spin_ns: int = 0) -> None:
        from lolacli.rawsocket import open_socket

        self.iface = iface
        self.taps: list[Tap] = []
        self.spin_ns = spin_ns
        self.wake_lateness_ns: list[int] | None = None  # a list: record how late waits end
        self.stop: Callable[[], bool] | None = None  # ends a long wait when it says so
        self._sock = open_socket(iface)
        self._sock.setblocking(False)
        self._sent: deque[int] = deque(maxlen=256)
        self._source: bytes | None = None  # our source MAC, locally administered bit set
        self.foreign_frames = 0  # EtherCAT frames of another master, ignored
        self._realtime_offset = time.time_ns() - time.monotonic_ns()
        self.kernel_timestamps = _enable_timestamps(self._sock)

    def now_ns(self) -> int:
        return time.monotonic_ns()

    def send(self, frame: bytes) -> int:
        t = time.monotonic_ns()
        self._realtime_offset = time.time_ns() - t
        if len(frame) >= 12:
            self._source = bytes((frame[6] | 0x02,)) + frame[7:12]
        try:
            self._sock.send(frame)
        except OSError as exc:
            raise TransportError(f"{self.iface}: send failed: {exc.strerror or exc}") from None
        for tap in self.taps:
            tap(t, frame, False)
        self._sent.append(t)
        return t

    def recv(self, timeout_ns: int) -> Received | None:
        from lolacli.rawsocket import MAX_FRAME_BYTES, PACKET_OUTGOING

        deadline = time.monotonic_ns() + max(0, timeout_ns)
        while True:
            try:
                frame, ancillary, _flags, address = self._sock.recvmsg(
                    MAX_FRAME_BYTES, _ANCILLARY_BYTES
                )
            except BlockingIOError:
                left = deadline - time.monotonic_ns()
                if left <= 0:
                    return None
                select.select([self._sock], [], [], left / 1e9)
                continue
            except InterruptedError:
                continue
            except OSError as exc:
                raise TransportError(
                    f"{self.iface}: receive failed: {exc.strerror or exc}"
                ) from None
            if len(address) > 2 and address[2] == PACKET_OUTGOING:
                continue
            source = self._source
            if source is not None and (frame[6] | 0x02 != source[0] or frame[7:12] != source[1:]):
                self.foreign_frames += 1  # another master on this segment: not ours
                continue
            now = time.monotonic_ns()
            t = min(now, _stamp(ancillary, self._realtime_offset) or now)
            for tap in self.taps:
                tap(t, frame, True)
            sent = self._sent[-1] if self._sent else t
            return Received(frame, sent, t)

    def wait_until(self, t_ns: int) -> None:
        clock = time.monotonic_ns
        left = t_ns - clock()
        while left > self.spin_ns:
            # a long wait (a slow cycle rate) in slices, so that a stop asked for meanwhile
            # (``stop``) ends it within a second
            time.sleep(min(left - self.spin_ns, _SLICE_NS) / 1e9)
            if self.stop is not None and self.stop():
                return
            left = t_ns - clock()
        now = clock()
        while now < t_ns:
            now = clock()
        if self.wake_lateness_ns is not None:
            self.wake_lateness_ns.append(now - t_ns)

    def close(self) -> None:
        self._sock.close()


_TIMESPEC = struct.Struct("qq")
_ANCILLARY_BYTES = 64


def _enable_timestamps(sock: socket.socket) -> bool:
    try:
        sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    except OSError:
        return False
    return True


def _stamp(ancillary: list[tuple[int, int, bytes]], realtime_offset: int) -> int | None:
    """The kernel's receive stamp in the monotonic clock, if the frame carries one."""
    for level, kind, data in ancillary:
        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(data) >= 16:
            seconds, nanoseconds = _TIMESPEC.unpack_from(data)
            return int(seconds) * 1_000_000_000 + int(nanoseconds) - realtime_offset
    return None
