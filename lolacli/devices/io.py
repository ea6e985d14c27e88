"""IO terminals and the CAN gateway: devices whose inputs are signals of time.

* :class:`DigitalIo` — digital outputs are stored; digital inputs echo the outputs of the
  same width where there are any, else a walking bit pattern changing every 10 ms.
* :class:`AnalogInput` — every input entry carries a sine (period 1 s) scaled to its type.
* :class:`CanGateway` — a placeholder for the CAN gateway of the LOLA chain: its inputs
  (IMU rates and accelerations, foot force/torque sensors) are deterministic sines of time
  with distinct phases, so a master sees plausible, changing values.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable

from lolacli.devices.base import Device
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
_UNSIGNED = frozenset({DataType.UNSIGNED8, DataType.UNSIGNED16, DataType.UNSIGNED32})


class CanGateway(AnalogInput):
    """IMU and force/torque sensor values behind a CAN gateway (placeholder)."""

    scale = 100.0

    def values(self) -> dict[str, Value]:
        return {
            self.od.require(index, sub).name: self.od.get(index, sub)
            for index, sub, _ in _inputs(self)
        }
