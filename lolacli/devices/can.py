"""The CAN side of the LOLA CAN gateway: sensor nodes sampling at their own rates, their
frames on one CAN bus, and the sample each sensor's values come from at a given time.

Seed 000 §III: an IMU sending at 200 Hz and two foot force/torque sensors (FTS), CANopen
nodes behind a commercial CAN gateway of 1 Mbit/s that maps their data into the EtherCAT
process data. The seed gives no FTS rate; 1 kHz here (the rate the seed's control loop
asks of "sensor and target data", §IV), an option of ``bus simulate``.

The model is deterministic, in virtual time (nanoseconds):

* sensor ``s`` takes sample ``k`` (0, 1, ...) at ``phase + k * period``; its values are
  the sines of :func:`sensor_value` at that instant (the same the ``sdo serve --gateway``
  nodes answer, :mod:`lolacli.sdo.node`);
* a sample is sent as TPDOs of at most 8 bytes (the sensor's REAL32 values in order:
  the IMU's 9 in 5 frames, an FTS's 6 in 3); each frame lasts :func:`frame_bits` bits at
  the bitrate (a standard 11-bit frame with its interframe space and worst-case bit
  stuffing: 135 bits for 8 data bytes, 135 µs at 1 Mbit/s);
* one bus, frame by frame, never pre-empted; when it is free the pending frame of the
  highest priority wins arbitration: the lowest COB-ID, here each node's TPDOs in a block
  of its own in the order of the nodes (the IMU's first: the lowest node ID), so a
  sample's frames follow each other unless a node of higher priority has one waiting;
* a sample reaches the gateway when its last frame ends (its latency), and from then on
  the gateway's process data hold it until the next one arrives (sample and hold).

:class:`CanBus` advances this to any time and tells which sample each sensor holds.
"""

from __future__ import annotations

import math
import struct
import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

from lolacli.errors import UsageError

CAN_BITRATE = 1_000_000  # the LOLA gateway's CAN (seed 000 §III)
IMU_RATE_HZ = 200.0  # the iMAR iVRU's output rate (seed 000 §III)
FTS_RATE_HZ = 1000.0  # not in the seed: the 1 kHz its control loop needs (§IV)
MAX_RATE_HZ = 100_000.0
IMU_NODE, FTS_LEFT_NODE, FTS_RIGHT_NODE = 0x10, 0x11, 0x12
VALUE_BYTES = 4  # REAL32
NEVER_NS = 1 << 126  # later than any time (the emulator's reach beyond 2^62 included)


def frame_bits(data_bytes: int, *, stuffing: bool = True) -> int:
    """Bits one standard (11-bit identifier) CAN data frame of ``data_bytes`` occupies the
    bus, its 3-bit interframe space included: 47 + 8n, plus with ``stuffing`` the
    worst-case stuff bits over the 34 + 8n stuffed bits (SOF to CRC): (33 + 8n) // 4.
    8 data bytes: 111 bits, 135 with worst-case stuffing."""
    if not 0 <= data_bytes <= 8:
        raise ValueError(f"a CAN frame carries 0 to 8 data bytes, not {data_bytes}")
    bits = 47 + 8 * data_bytes
    return bits + (33 + 8 * data_bytes) // 4 if stuffing else bits


def channel_phase(subindex: int, node_id: int) -> float:
    """The phase of a sensor node's channel ``subindex`` (1-based): 0.7 sub + 0.3 node."""
    return 0.7 * subindex + 0.3 * node_id


def sensor_value(scale: float, subindex: int, node_id: int, t_s: float) -> float:
    """The value a sensor node measures at ``t_s`` seconds on its channel ``subindex``
    (1-based): ``scale * sin(2 pi t + phase)`` with :func:`channel_phase` (the C core's
    twin of the gateway computes the same doubles: the phase first, then the sum)."""
    return scale * math.sin(2 * math.pi * t_s + channel_phase(subindex, node_id))


def sample_seconds(sample_ns: int) -> float:
    """A sample's instant as the sines take it: its place in its second (they repeat
    each second), so that a value does not depend on how long the run has been going."""
    return (sample_ns % 1_000_000_000) / 1e9


@dataclass(frozen=True)
class CanSensor:
    """One sensor node: its name as the gateway's PDOs name it ("IMU", "FTS left"), its
    node ID, rate, first sample's instant, the gateway object holding its values and how
    many REAL32 values it sends; ``scale`` of its sines."""

    name: str
    node_id: int
    rate_hz: float
    values_index: int
    channels: int
    scale: float
    phase_ns: int = 0

    @property
    def period_ns(self) -> int:
        return round(1e9 / self.rate_hz)

    def frames(self) -> list[int]:
        """Data bytes of each of its frames, in TPDO order."""
        total = self.channels * VALUE_BYTES
        return [min(8, total - at) for at in range(0, total, 8)]

    def sample_ns(self, k: int) -> int:
        """The instant of sample ``k`` (0-based)."""
        return self.phase_ns + k * self.period_ns


def lola_sensors(
    imu_rate_hz: float = IMU_RATE_HZ, fts_rate_hz: float = FTS_RATE_HZ
) -> tuple[CanSensor, ...]:
    """The LOLA gateway's three nodes (the ENI's objects 0x6010, 0x6020, 0x6030). The
    right FTS samples half a period after the left one (the feet's boards run
    unsynchronised; apart, their frames do not queue behind each other every time)."""
    fts_period = round(1e9 / fts_rate_hz) if fts_rate_hz > 0 else 0
    return (
        CanSensor("IMU", IMU_NODE, imu_rate_hz, 0x6010, 9, 10.0),
        CanSensor("FTS left", FTS_LEFT_NODE, fts_rate_hz, 0x6020, 6, 100.0),
        CanSensor("FTS right", FTS_RIGHT_NODE, fts_rate_hz, 0x6030, 6, 100.0, fts_period // 2),
    )


@dataclass(frozen=True)
class CanConfig:
    """The gateway's CAN bus: bitrate and sensors (:func:`lola_sensors` by default)."""

    bitrate: int = CAN_BITRATE
    sensors: tuple[CanSensor, ...] = field(default_factory=lola_sensors)

    def frame_ns(self, data_bytes: int) -> int:
        return round(frame_bits(data_bytes) * 1e9 / self.bitrate)

    def load(self) -> float:
        """The share of the bus the sensors' frames take (1.0: saturated)."""
        return sum(
            s.rate_hz * sum(self.frame_ns(n) for n in s.frames()) / 1e9 for s in self.sensors
        )

    def check(self) -> None:
        """UsageError (one line) for a configuration the bus cannot carry."""
        if not 10_000 <= self.bitrate <= 1_000_000:
            raise UsageError(f"--can-bitrate {self.bitrate}: give 10000 to 1000000 bit/s")
        self.check_rates()
        load = self.load()
        if load >= 1.0:
            raise UsageError(
                f"the sensors need {100 * load:.0f} % of the {self.bitrate} bit/s CAN bus: "
                "lower a rate or raise --can-bitrate"
            )

    def check_rates(self) -> None:
        """UsageError (one line) for a sensor rate that is not above 0 and up to
        :data:`MAX_RATE_HZ` (the bus's load aside: a bus without a bitrate, python-can's
        ``virtual`` or ``udp_multicast``, takes any)."""
        for s in self.sensors:
            if not (math.isfinite(s.rate_hz) and 0 < s.rate_hz <= MAX_RATE_HZ):
                raise UsageError(
                    f"{s.name} rate {s.rate_hz:g} Hz: give a rate above 0 and up to "
                    f"{MAX_RATE_HZ:g} Hz"
                )


class CanBus:
    """The gateway's CAN bus in virtual time (see the module): :meth:`advance` to a time,
    then :attr:`held` gives per sensor the sample its values come from (``-1``: none
    arrived yet) and :attr:`received` how many samples arrived."""

    def __init__(self, config: CanConfig, start_ns: int = 0) -> None:
        self.config = config
        sensors = config.sensors
        self.frame_ns = [[config.frame_ns(n) for n in s.frames()] for s in sensors]
        self.held = [-1] * len(sensors)
        self.received = [0] * len(sensors)
        self.latency_ns: list[list[int]] = [[] for _ in sensors]  # per arrived sample
        self.log: list[tuple[int, int, int]] = []  # (arrival, sensor, sample) as they come
        # the next sample to take: the first at or after ``start_ns`` (the bus idle then)
        self._next = [max(0, -(-(start_ns - s.phase_ns) // s.period_ns)) for s in sensors]
        self._next_ns = [s.sample_ns(k) for s, k in zip(sensors, self._next, strict=True)]
        self._free_ns = start_ns
        self._pending: list[deque[list[int]]] = [deque() for _ in sensors]  # [k, t, frame]
        self._busy: tuple[int, int, int] | None = None  # (end, sensor, frame)
        self.now_ns = -1
        # the next time anything happens (a sample taken, a frame ending)
        self.next_event_ns = min(self._next_ns) if sensors else NEVER_NS

    def advance(self, t_ns: int) -> bool:
        """Run the bus up to ``t_ns`` (frames ending at ``t_ns`` have arrived); True when
        a sample arrived."""
        self.now_ns = t_ns
        if t_ns < self.next_event_ns:
            return False
        arrived = False
        pending, next_ns, n = self._pending, self._next_ns, len(self._pending)
        while True:
            first = min(range(n), key=next_ns.__getitem__)
            busy = self._busy
            if busy is None:
                ready = -1  # the sensor whose frame wins the idle bus (priority: order)
                start = NEVER_NS
                for i in range(n):
                    if pending[i]:
                        at = max(self._free_ns, pending[i][0][1])
                        if at < start:
                            ready, start = i, at
                if ready >= 0 and next_ns[first] > start:
                    if start > t_ns:
                        self.next_event_ns = start
                        return arrived
                    frame = pending[ready][0][2]
                    self._busy = (start + self.frame_ns[ready][frame], ready, frame)
                    continue
                if next_ns[first] > t_ns:
                    self.next_event_ns = next_ns[first]
                    return arrived
                self._take(first)  # a sample taken before the bus frees contends too
                continue
            end, i, frame = busy
            if next_ns[first] < end:
                if next_ns[first] > t_ns:
                    self.next_event_ns = next_ns[first]
                    return arrived
                self._take(first)
                continue
            if end > t_ns:
                self.next_event_ns = end
                return arrived
            self._busy, self._free_ns = None, end
            head = pending[i][0]
            if frame + 1 < len(self.frame_ns[i]):
                head[2] = frame + 1
            else:
                pending[i].popleft()
                self.held[i] = head[0]
                self.received[i] += 1
                self.latency_ns[i].append(end - head[1])
                self.log.append((end, i, head[0]))
                arrived = True

    def _take(self, i: int) -> None:
        k = self._next[i]
        self._pending[i].append([k, self._next_ns[i], 0])
        self._next[i] = k + 1
        self._next_ns[i] = self.config.sensors[i].sample_ns(k + 1)


Arrival = tuple[int, int, int]  # (instant it arrived, sensor, sample)

#: the longest hyperperiod and the most arrivals in three of them a schedule is made for
MAX_HYPERPERIOD_NS = 1_000_000_000
HORIZON_EVENTS = 200_000


@dataclass(frozen=True)
class CanSchedule:
    """The bus's arrivals when they repeat: with H the sensors' hyperperiod (the least
    common multiple of their periods), the arrivals of [H, 2H) recur shifted by H for
    ever (sensor ``i``'s sample numbers by ``shifts[i]``), checked against [2H, 3H).
    ``log``: every arrival of [0, 3H), in time order (ties: sensor order); the bus
    settles from its idle start by H. :func:`schedule` makes one."""

    hyper_ns: int
    shifts: tuple[int, ...]
    log: tuple[Arrival, ...]

    def template(self) -> list[Arrival]:
        h = self.hyper_ns
        return [a for a in self.log if h <= a[0] < 2 * h]

    def held_rows(self) -> list[tuple[int, tuple[int, ...]]]:
        """After each arrival of :attr:`log`: its instant and the sample every sensor
        holds then (``-1``: none yet), the table the C core looks a time up in."""
        held = [-1] * len(self.shifts)
        rows = []
        for t_a, i, k in self.log:
            held[i] = k
            rows.append((t_a, tuple(held)))
        return rows

    def held_at(self, t_ns: int) -> list[int]:
        """The sample each sensor holds at ``t_ns`` (arrivals at ``t_ns`` included):
        from :attr:`log` up to 3H, beyond it from [2H, 3H) shifted by whole H."""
        h = self.hyper_ns
        q = t_ns // h - 2 if t_ns >= 3 * h else 0
        local = t_ns - q * h
        held = [-1] * len(self.shifts)
        for t_a, i, k in self.log:
            if t_a > local:
                break
            held[i] = k
        return [k + q * s if k >= 0 else -1 for k, s in zip(held, self.shifts, strict=True)]


def schedule(config: CanConfig, *, horizon_events: int = HORIZON_EVENTS) -> CanSchedule | None:
    """The bus's :class:`CanSchedule`, or ``None`` when it does not repeat within reach
    (a hyperperiod over :data:`MAX_HYPERPERIOD_NS`, more than ``horizon_events``
    arrivals in three, or a bus not settled by H)."""
    sensors = config.sensors
    if not sensors:
        return None
    periods = [s.period_ns for s in sensors]
    hyper = math.lcm(*periods)
    per_h = sum(hyper // p for p in periods)
    if hyper > MAX_HYPERPERIOD_NS or 3 * per_h > horizon_events:
        return None
    bus = CanBus(config)
    bus.advance(3 * hyper)
    seen = bus.log
    template = [a for a in seen if hyper <= a[0] < 2 * hyper]
    third = [a for a in seen if 2 * hyper <= a[0] < 3 * hyper]
    shifts = [hyper // p for p in periods]
    if {i for _, i, _ in template} != set(range(len(sensors))) or third != [
        (t + hyper, i, k + shifts[i]) for t, i, k in template
    ]:
        return None
    return CanSchedule(hyper, tuple(shifts), tuple(seen))


_UNKNOWN = object()


def arrivals(config: CanConfig, from_ns: int = 0, *, horizon_events: int = HORIZON_EVENTS,
             periodic: CanSchedule | None | object = _UNKNOWN) -> Iterator[Arrival]:
    """The samples' arrivals at the gateway in time order, without end (ties: sensor
    order), from about ``from_ns`` on (at least the hyperperiod H before it, so that what
    each sensor holds at ``from_ns`` is among them). With a :func:`schedule`, its
    template repeats for ever; otherwise :class:`CanBus` runs from ``from_ns`` less a
    second, its bus idle then. ``periodic``: the config's :func:`schedule` when the
    caller has it."""
    if periodic is _UNKNOWN:
        periodic = schedule(config, horizon_events=horizon_events)
    if isinstance(periodic, CanSchedule):
        hyper, shifts = periodic.hyper_ns, periodic.shifts
        template = periodic.template()
        m = max(0, (from_ns - hyper) // hyper - 1)
        if m == 0:
            yield from (a for a in periodic.log if a[0] < hyper)
        while True:
            for t_a, i, k in template:
                yield (t_a + m * hyper, i, k + m * shifts[i])
            m += 1
    if not config.sensors:
        return
    bus = CanBus(config, max(0, from_ns - 1_000_000_000))
    while True:
        bus.advance(bus.next_event_ns)
        yield from bus.log
        bus.log.clear()


# ---------------------------------------------------------------- the live bus's frames

#: the sensors' TPDOs: COB-IDs in CANopen's TPDO1 range (0x181-0x1FF, so a CAN tool reads
#: them as PDOs), a block of :data:`TPDO_COB_BLOCK` per sensor in the configuration's
#: order and its frames in order within it; the lower COB-ID wins arbitration, so the
#: priorities are the model's (:class:`CanBus`). CiA 301 lets a node's TPDO
#: communication parameter (0x1800 + n, sub 1) give any; the predefined connection
#: set's 0x180 + node ID would interleave the nodes' frames.
TPDO_COB_BASE = 0x181
TPDO_COB_BLOCK = 8  # frames a sensor may send a sample in: 16 REAL32 values
_REAL32_LE = struct.Struct("<f")


def tpdo_cob_id(sensor: int, frame: int) -> int:
    """The COB-ID of the ``frame``-th TPDO (0-based) of the configuration's ``sensor``-th
    sensor (0-based)."""
    return TPDO_COB_BASE + TPDO_COB_BLOCK * sensor + frame


def sample_values(sensor: CanSensor, sample_ns: int) -> list[float]:
    """The values of ``sensor``'s sample taken at ``sample_ns`` (its channels in order):
    :func:`sensor_value` at :func:`sample_seconds`, as the gateway's model holds them."""
    t_s = sample_seconds(sample_ns)
    return [
        sensor_value(sensor.scale, sub, sensor.node_id, t_s)
        for sub in range(1, sensor.channels + 1)
    ]


def sample_frames(config: CanConfig, sensor: int, values: list[float]) -> list[tuple[int, bytes]]:
    """A sample of the configuration's ``sensor``-th sensor as its TPDOs: (COB-ID, data),
    its REAL32 values little-endian in order, at most 8 bytes a frame
    (:meth:`CanSensor.frames`)."""
    data = b"".join(_REAL32_LE.pack(v) for v in values)
    out, at = [], 0
    for f, size in enumerate(config.sensors[sensor].frames()):
        out.append((tpdo_cob_id(sensor, f), data[at : at + size]))
        at += size
    return out


@dataclass
class AgeStats:
    """The ages (ns) of the samples the master's frames read: count, sum, min, max."""

    count: int = 0
    total: int = 0
    low: int = 0
    high: int = 0

    def add(self, age_ns: int) -> None:
        if self.count == 0 or age_ns < self.low:
            self.low = age_ns
        if self.count == 0 or age_ns > self.high:
            self.high = age_ns
        self.count += 1
        self.total += age_ns

    def summary_us(self) -> dict[str, float] | None:
        """``{"mean", "min", "max"}`` in µs (3 decimals), None before a read."""
        if not self.count:
            return None
        return {
            "mean": round(self.total / self.count / 1e3, 3),
            "min": round(self.low / 1e3, 3),
            "max": round(self.high / 1e3, 3),
        }


Held = tuple[int, tuple[float, ...], int]  # (samples received so far, values, arrival ns)


class LiveSamples:
    """The samples of a live CAN bus as the gateway receives them (sample and hold):
    :meth:`frame` takes each frame as it arrives (one receiving thread) and, when the
    last TPDO of a sample completes it, makes it the sensor's :attr:`latest`; the
    gateway's cycle (another thread) takes the latest in (:meth:`CanGateway.bridge
    <lolacli.devices.io.CanGateway.bridge>`) and adds the age of what the master's
    frame read to :attr:`ages`. No IO here: the bus is the caller's.

    A frame whose COB-ID is no sensor's TPDO (another node, SDO, NMT, an extended
    identifier) is :attr:`ignored`; a TPDO of the wrong length or out of order (a frame
    of the sample lost) drops the sample being assembled (:attr:`incomplete`).
    ``latest[i]`` is replaced whole, so a reader sees one sample's values or the next's,
    never a mix."""

    def __init__(self, config: CanConfig, clock: Callable[[], int] = time.monotonic_ns) -> None:
        if len(config.sensors) * TPDO_COB_BLOCK > 0x200 - TPDO_COB_BASE or any(
            len(s.frames()) > TPDO_COB_BLOCK for s in config.sensors
        ):
            raise ValueError("more sensors or values than the TPDO1 range's COB-IDs carry")
        self.config = config
        self.clock = clock  # the arrivals' clock (ns), the emulator's frames' too
        n = len(config.sensors)
        self._frames = {
            tpdo_cob_id(i, f): (i, f, size)
            for i, s in enumerate(config.sensors)
            for f, size in enumerate(s.frames())
        }
        self._last = [len(s.frames()) - 1 for s in config.sensors]
        self._parts: list[list[bytes]] = [[] for _ in range(n)]
        self._lost = [False] * n  # the sample in flight is counted incomplete already
        self.latest: list[Held | None] = [None] * n
        self.received = [0] * n
        self.first_ns: list[int | None] = [None] * n  # arrival of the first sample
        self.ignored = 0
        self.incomplete = 0
        self.ages = [AgeStats() for _ in range(n)]
        self.read = [0] * n  # distinct samples the master's frames read

    def frame(self, cob_id: int, data: bytes, arrival_ns: int, *, extended: bool = False) -> bool:
        """One frame off the bus at ``arrival_ns`` (monotonic); True when it completed a
        sample."""
        where = None if extended else self._frames.get(cob_id)
        if where is None:
            self.ignored += 1
            return False
        i, f, size = where
        parts = self._parts[i]
        fits = len(data) == size
        if f == 0:
            self._lost[i] = False  # a new sample begins (whole or not)
        if not (fits and f == len(parts)):
            if parts or not self._lost[i]:
                self.incomplete += 1  # the sample in flight lost a frame: once a sample
            parts.clear()
            self._lost[i] = True
            if not (fits and f == 0):
                return False  # the rest of a lost sample, up to the next one's first
            self._lost[i] = False
        parts.append(bytes(data))
        if f < self._last[i]:
            return False
        raw = b"".join(parts)
        parts.clear()
        values = tuple(v for (v,) in _REAL32_LE.iter_unpack(raw))
        self.received[i] += 1
        if self.first_ns[i] is None:
            self.first_ns[i] = arrival_ns
        self.latest[i] = (self.received[i], values, arrival_ns)
        return True

    def report(self) -> dict[str, Any]:
        """Per sensor the samples received, the rate they came at (Hz, first to last),
        the distinct samples the master read and their age at it (µs: mean, min, max,
        from the sample's arrival at the gateway to the master's frame); the frames
        ignored and samples left incomplete."""
        sensors = []
        for i, s in enumerate(self.config.sensors):
            latest, first = self.latest[i], self.first_ns[i]
            rate = None
            if latest is not None and first is not None and latest[0] > 1:
                span = latest[2] - first
                rate = round((latest[0] - 1) * 1e9 / span, 1) if span > 0 else None
            sensors.append({
                "name": s.name,
                "node_id": s.node_id,
                "cob_ids": [tpdo_cob_id(i, f) for f in range(len(s.frames()))],
                "samples_received": self.received[i],
                "rate_hz": rate,
                "samples_read": self.read[i],
                "age_us": self.ages[i].summary_us(),
            })
        return {"sensors": sensors, "frames_ignored": self.ignored,
                "samples_incomplete": self.incomplete}


__all__ = [
    "CAN_BITRATE",
    "TPDO_COB_BASE",
    "AgeStats",
    "LiveSamples",
    "FTS_RATE_HZ",
    "NEVER_NS",
    "IMU_RATE_HZ",
    "CanBus",
    "CanConfig",
    "CanSchedule",
    "CanSensor",
    "Held",
    "arrivals",
    "channel_phase",
    "frame_bits",
    "lola_sensors",
    "sample_frames",
    "sample_seconds",
    "sample_values",
    "schedule",
    "sensor_value",
    "tpdo_cob_id",
]
