"""The line between the slaves: its delay model (:class:`ChainTiming`), the faults
injected on it (:class:`Faults`) and what the chain counts (:class:`ChainStats`)."""

from __future__ import annotations

import random
from dataclasses import dataclass, field
from functools import lru_cache

from lolacli.emulator.esc import Esc, PortTimes
from lolacli.timing.model import (
    CABLE_NS_PER_M,
    DEFAULT_CABLE_M,
    DEFAULT_PER_SLAVE_DELAY_NS,
    LINK_100_MBIT_S,
    frame_bytes,
    predict_total_ns,
    wire_time_ns,
)


@dataclass(frozen=True, slots=True)
class ChainTiming:
    """Delay model of a line, the one :mod:`lolacli.timing` predicts with.

    ``processing_ns`` is the delay through an ESC's processing unit on the way out,
    ``forward_ns`` the delay of passing an ESC on the way back (together the timing
    model's per-slave delay, 1000 ns by default), ``cable_ns`` one cable segment one way
    (1 m at 5 ns/m). Round trip = wire time of the frame (DESIGN.md frame bytes) + slaves
    × per-slave delay + every segment out and back.

    ``slave_delays_ns`` and ``cable_ns_per_segment`` (one per slave, in line order; segment
    K leads from slave K-1, the master for K = 1, to slave K) replace the uniform figures
    slave by slave: the per-slave delay of each slave's ESC and ports
    (:func:`lolacli.timing.model.physics_delays_ns`), split between the way out and the way
    back as the default is (60/40), and each cable's length. The round trip sums them over
    the slaves the frame reaches.
    """

    link_bit_s: int = LINK_100_MBIT_S
    processing_ns: int = 600
    forward_ns: int = DEFAULT_PER_SLAVE_DELAY_NS - 600
    cable_ns: int = round(DEFAULT_CABLE_M * CABLE_NS_PER_M)
    slave_delays_ns: tuple[int, ...] | None = None
    cable_ns_per_segment: tuple[int, ...] | None = None

    @property
    def per_slave_delay_ns(self) -> int:
        return self.processing_ns + self.forward_ns

    def wire_time_ns(self, frame_bytes: int) -> int:
        return wire_time_ns(frame_bytes, self.link_bit_s)

    def split_ns(self, i: int) -> tuple[int, int]:
        """(processing, forwarding) of the slave at 0-based ``i``."""
        if self.slave_delays_ns is None or i >= len(self.slave_delays_ns):
            return self.processing_ns, self.forward_ns
        delay = self.slave_delays_ns[i]
        processing = delay * self.processing_ns // max(1, self.per_slave_delay_ns)
        return processing, delay - processing

    def segment_ns(self, i: int) -> int:
        """One way over segment ``i`` (0-based: the one into slave i + 1)."""
        segments = self.cable_ns_per_segment
        return self.cable_ns if segments is None or i >= len(segments) else segments[i]

    def port_times(self, t_ns: int, slaves: int) -> list[PortTimes]:
        """When the frame's head reaches each slave's port 0 (out) and port 1 (back)."""
        if self.slave_delays_ns is None and self.cable_ns_per_segment is None:
            out = [t_ns + (i + 1) * self.cable_ns + i * self.processing_ns
                   for i in range(slaves)]
            back: list[int | None] = [None] * slaves
            if slaves:
                t = out[-1] + self.processing_ns
                for i in range(slaves - 2, -1, -1):
                    t += self.cable_ns
                    back[i] = t
                    t += self.forward_ns
            return [PortTimes(o, b) for o, b in zip(out, back, strict=True)]
        split = [self.split_ns(i) for i in range(slaves)]
        out, t = [], t_ns
        for i in range(slaves):
            t += self.segment_ns(i)
            out.append(t)
            t += split[i][0]
        back = [None] * slaves
        for i in range(slaves - 2, -1, -1):
            t += self.segment_ns(i + 1)
            back[i] = t
            t += split[i][1]
        return [PortTimes(o, b) for o, b in zip(out, back, strict=True)]

    @lru_cache(maxsize=256)  # noqa: B019 - a frozen value object: the cache keeps no chain alive
    def delay_ns(self, lengths: tuple[int, ...], slaves: int) -> int:
        """:meth:`round_trip_ns` kept for the frame layouts a chain sees again."""
        return self.round_trip_ns(list(lengths), slaves)

    def bus_delay_ns(self, slaves: int) -> int:
        """The round trip less the wire time: the first ``slaves`` slaves' delays and
        their cable segments out and back."""
        if self.slave_delays_ns is None and self.cable_ns_per_segment is None:
            return slaves * self.per_slave_delay_ns + 2 * slaves * self.cable_ns
        return sum(sum(self.split_ns(i)) + 2 * self.segment_ns(i) for i in range(slaves))

    def round_trip_ns(self, datagram_lengths: list[int], slaves: int) -> int:
        wire = wire_time_ns(frame_bytes(datagram_lengths), self.link_bit_s)
        if self.slave_delays_ns is None and self.cable_ns_per_segment is None:
            return predict_total_ns(
                wire, slaves, self.per_slave_delay_ns, 2 * slaves * self.cable_ns
            )
        return wire + self.bus_delay_ns(slaves)


@dataclass(slots=True)
class Faults:
    """Faults injected at the chain, drawn per frame from one seeded generator.

    ``drop_probability``: the frame is destroyed on the cable between the master and the
    first slave; nothing comes back, and the first slave counts it on port 0 as hardware
    would for a frame hit by noise (ESC datasheets, register 0x0300: the invalid frame
    counter for the failed FCS, 0x0301 RX error counter for the PHY's symbol errors).

    ``corrupt_probability``: the frame is damaged as it leaves the slave at 1-based
    position ``corrupt_at_slave`` (``None``: a cable segment drawn at random, 0 the
    master's own cable). The next slave sees a bad FCS on port 0 (invalid frame counter
    0x0300), marks the frame and does not process it; every slave further along counts
    the marked frame as a forwarded RX error (0x0308 + port: port 0 on the way out,
    port 1 on the way back). The master still gets the frame back, with the working
    counters of the slaves before the damage only.

    ``bad_link`` (a 1-based position K) with ``bad_link_probability``: a bad cable into
    slave K (from slave K-1, the master for K = 1). A frame it damages is counted as
    ``corrupt`` counts it (slave K's invalid frame counter 0x0300 on port 0, forwarded RX
    errors 0x0308/0x0309 further on), and it reaches the master with the bad FCS the ESCs
    keep marked, so the master's NIC discards it: the master sees a lost frame, as on a
    real line. Only the way out is damaged, so the first counter that rises is always
    slave K's port 0.
    """

    drop_probability: float = 0.0
    seed: int = 0
    rng: random.Random = field(default_factory=random.Random)
    corrupt_probability: float = 0.0
    corrupt_at_slave: int | None = None
    bad_link: int | None = None
    bad_link_probability: float = 0.0

    def __post_init__(self) -> None:
        self.rng.seed(self.seed)

    def drop(self) -> bool:
        return self.drop_probability > 0 and self.rng.random() < self.drop_probability

    def corrupt(self, slaves: int) -> int | None:
        """How many of ``slaves`` process the frame before it is damaged; ``None``: intact."""
        if self.corrupt_probability <= 0 or self.rng.random() >= self.corrupt_probability:
            return None
        if self.corrupt_at_slave is not None:
            return min(self.corrupt_at_slave, slaves)
        return self.rng.randrange(slaves) if slaves else 0

    def bad_link_hit(self, slaves: int) -> int | None:
        """How many of ``slaves`` process a frame before the bad link damages it; ``None``:
        it passes intact (or the bad link is beyond the line's end)."""
        link = self.bad_link
        if link is None or link > slaves or self.bad_link_probability <= 0:
            return None
        return link - 1 if self.rng.random() < self.bad_link_probability else None

    @staticmethod
    def count_lost(active: list[Esc]) -> None:
        """A dropped frame's counters: the first slave counts it on port 0."""
        if active:
            active[0].count_invalid_frame(0)
            active[0].count_rx_error(0)

    @staticmethod
    def count_damaged(active: list[Esc], processed: int) -> None:
        """The counters of a frame damaged after ``processed`` of the ``active`` slaves."""
        if processed >= len(active):  # damaged in the last slave's loop back
            if len(active) >= 2:
                active[-2].count_invalid_frame(1)
            for esc in active[:-2]:
                esc.count_forwarded_error(1)
            return
        active[processed].count_invalid_frame(0)
        for esc in active[processed + 1 :]:
            esc.count_forwarded_error(0)
        for esc in active[:-1]:  # the marked frame passes every open port 1 on the way back
            esc.count_forwarded_error(1)


@dataclass(slots=True)
class ChainStats:
    frames: int = 0
    replies: int = 0
    dropped: int = 0
    corrupted: int = 0
    links_lost: int = 0
    malformed: int = 0
    logical_frames: int = 0
    planned_frames: int = 0  # answered through a frame plan
