"""A device as flat tables: what the compiled cycle gets, and when it gets nothing."""

from __future__ import annotations

import struct

import pytest

from lolacli.devices import AnalogInput, Cia402Drive, DigitalIo, device_for
from lolacli.devices.flat import (
    CYCLIC_BYTES,
    KIND_ANALOG,
    KIND_CIA402,
    KIND_DIGITAL_IO,
    DeviceScalars,
    flatten,
)
from lolacli.eni.model import Direction
from lolacli.files import load_eni
from tests.emulator.bus import EXAMPLES

LOLA = load_eni(EXAMPLES / "lola.xml")


def _device(name: str):  # type: ignore[no-untyped-def]
    return device_for(next(s for s in LOLA.slaves if s.name == name))


def test_a_drive_flattens_to_its_mapping_and_cyclic_entries() -> None:
    drive = _device("Joint04 L Knee")
    assert isinstance(drive, Cia402Drive)
    flat = flatten(drive)
    assert flat is not None and flat.kind == KIND_CIA402
    assert (flat.out_bytes, flat.in_bytes) == drive.process_data_bytes() == (11, 11)
    rows = [tuple(flat.out_map[k : k + 4]) for k in range(0, len(flat.out_map), 4)]
    # controlword, mode, target position, velocity offset: bit offset and bits as mapped
    assert [(bit, bits) for bit, bits, _, _ in rows] == [(0, 16), (16, 8), (24, 32), (56, 32)]
    sizes = {offset: size for _entry, offset, size in flat.slots}
    assert [sizes[offset] for offset in flat.cyclic] == list(CYCLIC_BYTES)


def test_load_and_store_carry_values_and_scalars() -> None:
    drive = _device("Joint01 L Hip Yaw")
    assert isinstance(drive, Cia402Drive)
    drive.od.set(0x607A, 0, -12345)
    flat = flatten(drive)
    assert flat is not None
    scalars = flat.load()
    assert scalars is not None and scalars.power == int(drive.power)
    target = flat.cyclic[4]
    assert struct.unpack_from("<i", flat.vals, target)[0] == -12345
    struct.pack_into("<i", flat.vals, target, 777)  # as the kernel would change it
    flat.store(DeviceScalars(t_ns=5_000, power=0x27, previous_cw=0x0F))
    assert drive.od.get_int(0x607A) == 777
    assert (drive.t_ns, int(drive.power), drive.previous_cw) == (5_000, 0x27, 0x0F)


def test_bit_mapped_io_and_analog_channels() -> None:
    gpio = _device("GPIO 8DI 8DO")
    assert isinstance(gpio, DigitalIo)
    flat = flatten(gpio)
    assert flat is not None and flat.kind == KIND_DIGITAL_IO
    assert len(flat.channels) // 6 == 8  # eight 1-bit inputs echoing eight outputs
    assert all(flat.channels[k + 3] == 1 for k in range(0, len(flat.channels), 6))
    # the gateway's inputs as a plain analog device (the gateway itself samples at its
    # sensors' rates behind a CAN bus: tests/devices/test_can_gateway.py)
    gateway = AnalogInput(next(s for s in LOLA.slaves if s.name == "CAN Gateway (IMU, FTS)"))
    flat = flatten(gateway)
    assert flat is not None and flat.kind == KIND_ANALOG
    assert len(flat.phases) == len(flat.channels) // 6 > 100
    assert flat.period_ns == gateway.sample_period_ns and flat.scale == gateway.scale


def test_a_class_with_its_own_step_stays_in_python() -> None:
    class Own(Cia402Drive):
        def step(self, t_ns: int) -> None:
            super().step(t_ns)

    drive = _device("Joint01 L Hip Yaw")
    drive.__class__ = Own
    assert flatten(drive) is None


def test_a_value_the_cycle_would_resize_stays_in_python() -> None:
    """0x6060 as an ENI might map it: 16 bits onto an INTEGER8 object. The cycle would
    give the entry 2 bytes, then the step 1: the tables cannot hold that."""
    drive = _device("Joint01 L Hip Yaw")
    entry = drive.od.entry(0x6060, 0)
    entry.value = b"\x08\x00"
    assert flatten(drive) is None


def test_tables_made_for_another_mapping_refuse_to_load() -> None:
    drive = _device("Joint01 L Hip Yaw")
    flat = flatten(drive)
    assert flat is not None and flat.load() is not None
    drive.od.write(0x1A00, 0, b"\x01")  # TxPDO mapping cut to one entry: a new version
    assert drive.process_data_bytes()[1] == 2
    assert flat.load() is None
    fresh = flatten(drive)
    assert fresh is not None and fresh.in_bytes == 2


@pytest.mark.parametrize("name", ["lola.xml", "single_drive.xml", "ek1100_io.xml"])
def test_every_example_device_flattens(name: str) -> None:
    for slave in load_eni(EXAMPLES / name).slaves:
        device = device_for(slave)
        flat = flatten(device)
        assert flat is not None, slave.name
        assert (flat.out_bytes, flat.in_bytes) == device.process_data_bytes()
        assert len(flat.in_map) // 4 == len(device.mapping(Direction.INPUT)) - sum(
            1 for index, _, _ in device.mapping(Direction.INPUT) if index == 0
        )
