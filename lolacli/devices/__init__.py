"""Device models behind the emulated ESCs: CiA 402 drives, IO terminals, a CAN gateway."""

from __future__ import annotations

from lolacli.devices.base import Device
from lolacli.devices.can import lola_sensors
from lolacli.devices.cia402 import Cia402Drive
from lolacli.devices.io import AnalogInput, CanGateway, DigitalIo
from lolacli.eni.model import Slave


def device_for(slave: Slave) -> Device:
    """The device model that fits an ENI slave, by its PDO entries and name."""
    entries = {(e.index, e.subindex) for p in slave.pdos for e in p.entries}
    indexes = {index for index, _ in entries}
    name = slave.name.lower()
    if (0x6040, 0) in entries or (0x6041, 0) in entries:
        return Cia402Drive(slave)
    if "gateway" in name or "can" in name.split() or "imu" in name or "fts" in name:
        # the LOLA gateway's sensors where it maps their values, else sines as before
        if indexes & {s.values_index for s in lola_sensors()}:
            return CanGateway(slave)
        return AnalogInput(slave)
    if any(0x6000 <= i < 0x7000 for i in indexes) and (
        "ai" in name or "analog" in name or name.startswith("el3")
    ):
        return AnalogInput(slave)
    return DigitalIo(slave)


__all__ = ["AnalogInput", "CanGateway", "Cia402Drive", "Device", "DigitalIo", "device_for"]
