"""IO terminals and the CAN gateway: devices whose inputs are signals of time.

* :class:`DigitalIo` — digital outputs are stored; digital inputs echo the outputs of the
  same width where there are any, else a walking bit pattern changing every 10 ms.
* :class:`AnalogInput` — every input entry carries a sine (period 1 s) scaled to its type.
* :class:`CanGateway` — the CAN gateway of the LOLA chain: its IMU and foot force/torque
  sensors sample at their own rates behind a CAN bus (:mod:`lolacli.devices.can`), the
  process data hold each one's last sample to arrive.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable

from lolacli.devices.base import Device
from lolacli.devices.can import (
    NEVER_NS,
    Arrival,
    CanConfig,
    Held,
    LiveSamples,
    arrivals,
    sample_seconds,
    schedule,
    sensor_value,
)
from lolacli.eni.model import Direction
from lolacli.od import OdEntry
from lolacli.wire.datatypes import DataType, Value


def _inputs(device: Device) -> list[tuple[int, int, int]]:
    return [m for m in device.mapping(Direction.INPUT) if m[0]]


_Echo = tuple[int, OdEntry, OdEntry | None, int]
_Channel = tuple[OdEntry, float, Callable[[float], bytes] | None, int, int, int, int]


class DigitalIo(Device):
    device_type = 0x00000000
    _channel_cache: tuple[int, list[_Echo]] | None = None

    def step(self, t_ns: int) -> None:
        pattern = 1 << ((t_ns // 10_000_000) % 8)
        for i, entry, source, bits in self.channels():
            if source is not None:
                value = int.from_bytes(source.value, "little")
            else:
                value = (pattern >> (i % 8)) & 1 if bits == 1 else pattern
            entry.value = (value & ((1 << bits) - 1)).to_bytes(max(1, (bits + 7) // 8), "little")

    def at_rest(self) -> bool:
        """Inputs that only echo outputs stand still with them; the walking bits do not."""
        return all(source is not None for _, _, source, _ in self.channels())

    def channels(self) -> list[_Echo]:
        """(position, input entry, output entry it echoes or None, bits), once per mapping."""
        key = self.od.version
        cached = self._channel_cache
        if cached is not None and cached[0] == key:
            return cached[1]
        outputs = [m for m in self.mapping(Direction.OUTPUT) if m[0]]
        out = []
        for i, (index, sub, bits) in enumerate(_inputs(self)):
            source = self.od.require(*outputs[i][:2]) if i < len(outputs) else None
            out.append((i, self.od.require(index, sub), source, bits))
        self._channel_cache = (key, out)
        return out


class AnalogInput(Device):
    """Inputs are sines; they are sampled every ``sample_period_ns`` (1 kHz, like the
    sensors behind a real terminal or gateway), not on every bus cycle."""

    device_type = 0x00000000
    scale = 10.0
    sample_period_ns = 1_000_000
    _channel_cache: tuple[int, list[_Channel]] | None = None

    def step(self, t_ns: int) -> None:
        sample = t_ns // self.sample_period_ns
        if sample == getattr(self, "last_sample", None):
            return
        self.last_sample = sample
        angle = 2 * math.pi * (t_ns / 1e9)
        sin = math.sin
        for entry, phase, pack, full, offset, mask, size in self.channels():
            s = sin(angle + phase)
            if pack is not None:
                entry.value = pack(s * self.scale)
            else:
                entry.value = ((int(round(s * full * 0.5)) + offset) & mask).to_bytes(
                    size, "little"
                )

    def channels(self) -> list[_Channel]:
        """Per input entry what its sine needs, worked out once per mapping."""
        key = self.od.version
        cached = self._channel_cache
        if cached is not None and cached[0] == key:
            return cached[1]
        out = []
        for i, (index, sub, bits) in enumerate(_inputs(self)):
            entry = self.od.require(index, sub)
            dtype = entry.data_type or 0
            pack = FLOAT_PACK.get(dtype)
            full = (1 << (bits - 1)) - 1 if bits > 1 else 1
            offset = full if dtype in _UNSIGNED else 0
            out.append(
                (entry, 0.7 * i, pack, full, offset, (1 << bits) - 1, max(1, (bits + 7) // 8))
            )
        self._channel_cache = (key, out)
        return out


FLOAT_PACK: dict[int, Callable[[float], bytes]] = {
    DataType.REAL32: struct.Struct("<f").pack,
    DataType.REAL64: struct.Struct("<d").pack,
}
_REAL32 = FLOAT_PACK[DataType.REAL32]
_UNSIGNED = frozenset({DataType.UNSIGNED8, DataType.UNSIGNED16, DataType.UNSIGNED32})


class CanGateway(Device):
    """The LOLA CAN gateway: the IMU and foot force/torque sensors behind it are CANopen
    nodes sampling at their own rates (:mod:`lolacli.devices.can`); each cycle the
    gateway's process data hold the last sample that has crossed the CAN bus, so a bus
    faster than a sensor sees the same values for several cycles, a sample's latency
    after it was taken. ``Sensor status`` gives per sensor its status (1 once a sample
    arrived) and counter (the sample's number plus one, mod 65536): a master tells a
    sample's instant from its counter (:meth:`CanSensor.sample_ns` of ``counter - 1``).
    A sample's values are :func:`~lolacli.devices.can.sensor_value` at its
    :func:`~lolacli.devices.can.sample_seconds`.

    :meth:`configure` sets the CAN side (rates, bitrate) before the run. This class is
    the reference; the C core runs the same cycle from the bus's
    :class:`~lolacli.devices.can.CanSchedule` (:mod:`lolacli.devices.flat`)."""

    device_type = 0x00000000
    STATUS = 0x6000
    live: LiveSamples | None = None  # the samples of a live CAN bus (bridge)

    def define(self) -> None:
        self.configure(CanConfig())

    def configure(self, config: CanConfig) -> None:
        """The CAN side: sensors the ENI maps (their values object in the inputs) on a
        bus of ``config``'s bitrate, from time 0 (UsageError for a bus that cannot carry
        them)."""
        config.check()
        mapped = {e.index for p in self.slave.pdos for e in p.entries}
        places = [j for j, s in enumerate(config.sensors) if s.values_index in mapped]
        sensors = tuple(config.sensors[j] for j in places)
        self.config = CanConfig(config.bitrate, sensors)
        self.schedule = schedule(self.config)
        self.held = [-1] * len(sensors)  # the sample each sensor's values are of
        # per sensor its status and counter (0x6000, two subindexes a sensor, in the
        # configuration's order) and its values
        self.sensor_entries = [
            (
                self.od.entry(self.STATUS, 2 * j + 1),
                self.od.entry(self.STATUS, 2 * j + 2),
                [self.od.entry(s.values_index, sub) for sub in range(1, s.channels + 1)],
            )
            for j, s in zip(places, sensors, strict=True)
        ]
        self._cached: tuple[bytes, int, int, bytes] | None = None  # outputs, writes, version
        self._samples: dict[tuple[int, int], list[bytes]] = {}  # packed values by instant
        self._image = bytearray()  # the inputs, kept up to date by _write (byte layouts)
        self._offsets: dict[int, int] = {}  # id(entry) -> its offset in the inputs
        self._blocks: dict[int, int] = {}  # sensor -> offset of its contiguous values
        self.rest_cache = None
        self.resume(0)

    def resume(self, t_ns: int) -> None:
        """Take the arrivals up again from about ``t_ns`` (after a jump in time, or after
        the C core ran the gateway's cycles)."""
        self._arrivals = arrivals(self.config, t_ns, periodic=self.schedule)
        self._pull()
        self._applied_ns = -(1 << 63)  # the last arrival taken in
        self._cached = None

    def bridge(self, live: LiveSamples) -> None:
        """From now on the sensors' samples come from a live CAN bus (``live``, fed by a
        receiving thread) instead of the model: each cycle takes every sensor's latest
        sample in (its counter: the samples received, mod 65536) and first adds to
        ``live.ages`` the age of the sample the master's frame of this cycle read (the
        cycle runs after the frame, at its time ``t_ns``: the frame read what the cycles
        that ran before ``t_ns`` took in, on ``live.clock``, the arrivals' clock; a cycle
        the emulator held back while a frame was answered takes in after it). Only Python
        runs a bridged gateway (:func:`~lolacli.devices.flat.flatten` gives ``None``). A
        sensor of this gateway's configuration ``live`` does not have (by node ID) holds
        no sample."""
        by_node = {s.node_id: j for j, s in enumerate(live.config.sensors)}
        n = len(self.config.sensors)
        self.live = live
        self.live_index = [by_node.get(s.node_id) for s in self.config.sensors]
        # per sensor the samples in the process data: now and before, each with the time
        # a cycle took it in
        self.live_held: list[tuple[Held, int] | None] = [None] * n
        self.live_before: list[tuple[Held, int] | None] = [None] * n
        self.live_read = [0] * n  # the last sample counted read
        self.held = [-1] * n
        self._cached = None

    def cycle(self, outputs: bytes, t_ns: int) -> bytes:
        """As :meth:`Device.cycle`; the inputs are packed again only when a sample arrived
        or the dictionary changed (the gateway's cycle at 2 kHz mostly holds)."""
        self.t_ns = t_ns
        od, cached = self.od, self._cached
        if (
            cached is not None
            and self.live is None
            and self._applied_ns <= t_ns < self.next_arrival_ns
            and cached[1] == od.writes
            and cached[2] == od.version
            and cached[0] == outputs
        ):
            return cached[3]
        if outputs and (cached is None or cached[0] != outputs):
            self.unpack_outputs(outputs)
        if cached is None or cached[1] != od.writes or cached[2] != od.version:
            self._image = bytearray(self.pack_inputs())  # the dictionary changed: all
            self._offsets = {
                id(e): at for e, at, _ in self.byte_layout_of(Direction.INPUT) or () if e
            }
            self._blocks = self._contiguous()
        self.step(t_ns)
        inputs = bytes(self._image) if self._offsets else self.pack_inputs()
        self._cached = (outputs, od.writes, od.version, inputs)
        return inputs

    def _contiguous(self) -> dict[int, int]:
        """Sensors whose values lie one after the other in the inputs: their offset."""
        out = {}
        for i, (_, _, entries) in enumerate(self.sensor_entries):
            at = [self._offsets.get(id(e)) if e is not None else None for e in entries]
            if at and at[0] is not None and at == [at[0] + 4 * j for j in range(len(at))]:
                out[i] = at[0]
        return out

    def _pull(self) -> None:
        self._next: Arrival | None = next(self._arrivals, None)
        self.next_arrival_ns = self._next[0] if self._next is not None else NEVER_NS

    def step(self, t_ns: int) -> None:
        if self.live is not None:
            self._step_live(self.live, t_ns)
            return
        sensors, cache = self.config.sensors, self._samples
        if t_ns < self._applied_ns or (
            self._next is not None and t_ns - self._next[0] > 2_000_000_000
        ):
            self.resume(t_ns)  # a jump in time, back or forward: seek
        while self._next is not None and self._next[0] <= t_ns:
            self._applied_ns, i, k = self._next
            sensor = sensors[i]
            key = (i, sensor.sample_ns(k) % 1_000_000_000)  # the sines repeat each second
            packed = cache.get(key)
            if packed is None:
                t_s = sample_seconds(sensor.sample_ns(k))
                scale, node = sensor.scale, sensor.node_id
                packed = [
                    _REAL32(sensor_value(scale, sub, node, t_s))
                    for sub in range(1, sensor.channels + 1)
                ]
                if len(cache) < 100_000:
                    cache[key] = packed
            self._write(i, k, packed)
            self._pull()

    def _step_live(self, live: LiveSamples, t_ns: int) -> None:
        """The cycle of a bridged gateway (:meth:`bridge`)."""
        held, before = self.live_held, self.live_before
        now_ns = live.clock()
        for i, j in enumerate(self.live_index):
            if j is None:
                continue
            now = held[i]
            read = now if now is not None and now[1] <= t_ns else before[i]
            if read is not None and read[1] <= t_ns:
                sample = read[0]
                live.ages[j].add(t_ns - sample[2])  # what this cycle's frame read
                if sample[0] != self.live_read[i]:
                    self.live_read[i] = sample[0]
                    live.read[j] += 1
            latest = live.latest[j]
            if latest is not None and (now is None or latest is not now[0]):
                before[i], held[i] = now, (latest, now_ns)
                self._write(i, latest[0] - 1, [_REAL32(v) for v in latest[1]])

    def _write(self, i: int, k: int, packed: list[bytes]) -> None:
        """Sensor ``i``'s sample ``k`` (its values ``packed``) into the process data."""
        self.held[i] = k
        status, count, entries = self.sensor_entries[i]
        image, offsets = self._image, self._offsets
        if status is not None and status.value[0] != 1:
            status.value = (1).to_bytes(len(status.value), "little")
            at = offsets.get(id(status))
            if at is not None:
                image[at : at + len(status.value)] = status.value
        if count is not None:
            size = len(count.value)
            count.value = data = ((k + 1) & 0xFFFF & ((1 << 8 * size) - 1)).to_bytes(
                size, "little"
            )
            at = offsets.get(id(count))
            if at is not None:
                image[at : at + len(data)] = data
        block = self._blocks.get(i)
        for entry, data in zip(entries, packed, strict=False):
            if entry is not None:
                entry.value = data
        if block is not None:
            image[block : block + 4 * len(packed)] = b"".join(packed)
        else:
            for entry, data in zip(entries, packed, strict=False):
                at = offsets.get(id(entry)) if entry is not None else None
                if at is not None:
                    image[at : at + 4] = data

    def values(self) -> dict[str, Value]:
        return {
            self.od.require(index, sub).name: self.od.get(index, sub)
            for index, sub, _ in _inputs(self)
        }
