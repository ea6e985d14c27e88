"""The CAN gateway's sensors as the master sees them: each one's age at the master.

Seed 000 §III: the IMU (200 Hz) and the foot force/torque sensors reach the EtherCAT
process data through a CAN gateway, so the master at 2 kHz reads a sample several times
(sample and hold) and late (the CAN bus's latency, then the EtherCAT side's). Every
cycle of the run :class:`SensorAges` keeps what the master's application read of the
gateway's ``Sensor status`` counters (the sample's number plus one, mod 65536:
:class:`~lolacli.devices.io.CanGateway`) and when; the sample's instant follows from its
number and the sensor's rate and phase (:meth:`~lolacli.devices.can.CanSensor.sample_ns`),
which a virtual run knows (the emulated gateway is configured with them). A sample's age
at the master is the time from that instant to the cycle whose application read it.
"""

from __future__ import annotations

from typing import Any

from lolacli.devices.can import CanConfig, CanSensor
from lolacli.master.variables import ProcessImage


class SensorAges:
    """The per-cycle reads of the gateway ``slave``'s counters (those of ``config``'s
    sensors the process image has, byte-aligned UINT16) while :attr:`active`."""

    def __init__(self, image: ProcessImage, slave: str, config: CanConfig) -> None:
        self.config = config
        self.sensors: list[tuple[CanSensor, int]] = []  # sensor, counter's byte offset
        for sensor in config.sensors:
            v = image.variables.get(f"{slave}.Sensor status.{sensor.name} counter")
            if v is not None and v.bit_offset % 8 == 0 and v.bit_size == 16:
                self.sensors.append((sensor, v.bit_offset // 8))
        at = [offset for _, offset in self.sensors]
        self.lo, self.hi = (min(at), max(at) + 2) if at else (0, 0)
        self.active = False
        self.times: list[int] = []  # the cycle's time (ns) when its application read
        self.reads: list[bytes] = []  # the counters' bytes it read

    def hook(self, master: Any) -> None:
        """A control hook: this cycle's counters as the application reads them."""
        if self.active:
            self.times.append(master.transport.now_ns())
            self.reads.append(master.image.snapshot.data[self.lo : self.hi])

    def report(self) -> dict[str, Any] | None:
        """``can_gateway`` of the report: the bus (bitrate, load) and per sensor its
        rate, the samples the master read and their age at it (µs: mean, min, max) over
        the cycles after the first sample reached it; None without a sensor to read."""
        if not self.sensors:
            return None
        import numpy as np

        times = np.asarray(self.times, dtype=np.int64)
        raw = np.frombuffer(b"".join(self.reads), dtype=np.uint8).reshape(
            len(self.reads), self.hi - self.lo
        )
        out = []
        for sensor, offset in self.sensors:
            at = offset - self.lo
            counter = raw[:, at].astype(np.int64) | (raw[:, at + 1].astype(np.int64) << 8)
            row: dict[str, Any] = {
                "name": sensor.name,
                "node_id": sensor.node_id,
                "rate_hz": sensor.rate_hz,
                "samples_read": 0,
                "age_us": None,
            }
            seen = np.flatnonzero(counter)  # 0: no sample yet
            if seen.size:
                first = seen[0]
                c = counter[first:]
                # unwrap mod 65536 (a counter never goes back; far less than 65536 a cycle)
                number = c[0] - 1 + np.concatenate(([0], np.cumsum(np.diff(c) % 65536)))
                instant = sensor.phase_ns + number * sensor.period_ns
                age = (times[first:] - instant) / 1e3
                row["samples_read"] = int(np.unique(number).size)
                row["age_us"] = {
                    "mean": round(float(age.mean()), 3),
                    "min": round(float(age.min()), 3),
                    "max": round(float(age.max()), 3),
                }
            out.append(row)
        return {
            "bitrate": self.config.bitrate,
            "load": round(self.config.load(), 4),
            "sensors": out,
        }


__all__ = ["SensorAges"]
