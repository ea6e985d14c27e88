"""The LOLA CAN gateway at its sensors' rates (seed 000 §III): sample and hold at the
bus's 2 kHz, the CAN bus's latency, the C core's twin against the Python reference, and
each sensor's age at the master in ``bus simulate``."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import pytest

import lolacli
from lolacli.devices import device_for
from lolacli.devices.can import CanBus, CanConfig, lola_sensors, schedule
from lolacli.devices.flat import KIND_CAN_GATEWAY, flatten
from lolacli.devices.io import CanGateway
from lolacli.emulator.core import core_available
from lolacli.emulator.slave import device_of
from lolacli.files import load_eni
from lolacli.simulate import SimulateOptions, Simulation
from tests.emulator.test_core import Script, Twin

LOLA = load_eni(Path(lolacli.__file__).parent / "eni_examples" / "lola.xml")
GATEWAY = next(s for s in LOLA.slaves if s.name == "CAN Gateway (IMU, FTS)")
CYCLE_NS = 500_000  # 2 kHz


def _values(device: CanGateway, index: int) -> tuple[float, ...]:
    return tuple(
        struct.unpack("<f", device.od.entry(index, sub).value)[0] for sub in range(1, 10)
        if device.od.entry(index, sub) is not None
    )


def test_a_200_hz_imu_holds_its_sample_for_ten_cycles_at_2_khz() -> None:
    gateway = device_for(GATEWAY)
    assert isinstance(gateway, CanGateway)
    imu = gateway.config.sensors[0]
    assert imu.name == "IMU" and imu.period_ns == 10 * CYCLE_NS
    seen, counters, changes = [], [], []
    for n in range(400):  # 200 ms
        gateway.cycle(b"", n * CYCLE_NS)
        values = _values(gateway, 0x6010)
        counters.append(gateway.od.get(0x6000, 2))
        if seen and values != seen[-1]:
            changes.append(n)
        seen.append(values)
    gaps = {b - a for a, b in zip(changes, changes[1:], strict=False)}
    assert gaps == {10}  # a new IMU sample every 10 bus cycles, held in between
    assert len(set(counters)) == len(changes) + 1  # one counter a sample
    assert gateway.od.get(0x6000, 1) == 1  # status: samples arrive
    # each FTS at 1 kHz changes every 2 cycles at most, and its counter says which sample
    fts = gateway.config.sensors[1]
    k = gateway.od.get(0x6000, 4) - 1
    assert gateway.held[1] == k and fts.sample_ns(k) <= 399 * CYCLE_NS


def test_the_imu_sample_arrives_after_its_frames_cross_the_can_bus() -> None:
    """The IMU's 9 REAL32 values are 5 frames (4 of 8 bytes, 1 of 4) at 1 Mbit/s with
    worst-case stuffing: its first sample, alone on the bus, arrives that much later."""
    config = CanConfig()
    imu = config.sensors[0]
    expect = sum(config.frame_ns(n) for n in imu.frames())
    assert imu.frames() == [8, 8, 8, 8, 4]
    bus = CanBus(config)
    bus.advance(imu.period_ns)
    assert bus.log[0] == (expect, 0, 0) and bus.latency_ns[0][0] == expect
    gateway = device_for(GATEWAY)
    gateway.cycle(b"", expect - 1)
    assert gateway.held[0] == -1 and gateway.od.get(0x6000, 2) == 0
    gateway.cycle(b"", expect)
    assert gateway.held[0] == 0 and gateway.od.get(0x6000, 2) == 1


def test_the_schedule_repeats_the_bus_and_the_reference_follows_it() -> None:
    config = CanConfig()
    plan = schedule(config)
    assert plan is not None and plan.hyper_ns == 5_000_000  # lcm of 5 ms and 1 ms
    bus = CanBus(config)
    gateway = device_for(GATEWAY)
    for t in range(0, 60_000_000, 137_000):  # off the cycle grid, 12 hyperperiods
        bus.advance(t)
        gateway.cycle(b"", t)
        assert plan.held_at(t) == bus.held == gateway.held, t
    gateway.cycle(b"", 3_000_000_000_123)  # a jump forward, then back: the same lookup
    assert gateway.held == plan.held_at(3_000_000_000_123)
    gateway.cycle(b"", 7_000_000)
    assert gateway.held == plan.held_at(7_000_000)


@pytest.mark.skipif(not core_available(), reason="C core not built")
@pytest.mark.parametrize("rates", [(200.0, 1000.0), (250.0, 500.0), (333.0, 250.0)])
def test_c_core_gateway_matches_the_reference(rates: tuple[float, float]) -> None:
    """Both engines, every frame of the scripted run, byte for byte (replies and state),
    at the defaults and at rates whose schedule is long or does not repeat soon."""
    config = CanConfig(1_000_000, lola_sensors(*rates))
    twin = Twin(LOLA, compare_every=29)
    for chain in (twin.c, twin.py):
        for esc in chain.slaves:
            device = device_of(esc)
            if isinstance(device, CanGateway):
                device.configure(config)
    Script(LOLA, twin, plannable_only=False).run()
    gateway = next(d for d in map(device_of, twin.c.slaves) if isinstance(d, CanGateway))
    flat = flatten(gateway)
    if schedule(gateway.config) is not None and len(schedule(gateway.config).log) < 30_000:
        assert flat is not None and flat.kind == KIND_CAN_GATEWAY
        assert twin.held_cycles == len(LOLA.slaves)  # the gateway's cycle ran in C
    else:
        assert flat is None  # Python runs a bus that does not repeat soon enough


def _ages(options: SimulateOptions) -> dict:  # type: ignore[type-arg]
    return Simulation(LOLA, options).run().doc["can_gateway"]


@pytest.mark.parametrize("rates", [(200.0, 1000.0), (100.0, 400.0)])
def test_bus_simulate_reports_each_sensors_age_at_the_master(rates: tuple[float, float]) -> None:
    """Ages computed from the model: at least the sample's CAN latency plus the EtherCAT
    side's (the gateway's next cycle, the frame after it, the master's cycle after that:
    one to three bus cycles), at most the longest latency plus a period and three bus
    cycles; their mean half a period above the mean latency, give or take those cycles."""
    imu_hz, fts_hz = rates
    seconds = 1.0
    options = SimulateOptions(2000.0, round(2000 * seconds), imu_rate_hz=imu_hz,
                              fts_rate_hz=fts_hz)
    doc = _ages(options)
    config = options.can_config()
    bus = CanBus(config)
    bus.advance(2_000_000_000)
    assert doc["bitrate"] == 1_000_000 and doc["load"] == pytest.approx(config.load(), abs=1e-4)
    for i, (sensor, row) in enumerate(zip(config.sensors, doc["sensors"], strict=True)):
        latencies = bus.latency_ns[i][5:]
        low, high = min(latencies) / 1e3, max(latencies) / 1e3
        mean = sum(latencies) / len(latencies) / 1e3
        period, cycle = sensor.period_ns / 1e3, CYCLE_NS / 1e3
        age = row["age_us"]
        assert row["name"] == sensor.name and row["rate_hz"] == sensor.rate_hz
        assert low + cycle <= age["min"] and age["max"] <= high + period + 3 * cycle
        assert abs(age["mean"] - (mean + period / 2 + 2 * cycle)) <= 1.5 * cycle
        # a sample the next one does not follow within a bus cycle is read at least
        # once; samples that arrive closer (queued behind others) may be overtaken
        expected = sensor.rate_hz * seconds
        arrived = [t for t, j, _ in bus.log if j == i]
        gap = min(b - a for a, b in zip(arrived[5:], arrived[6:], strict=False))
        assert row["samples_read"] <= expected + 1
        if gap > CYCLE_NS:
            assert row["samples_read"] >= expected - 3
        else:
            assert row["samples_read"] >= expected / 2
    human = doc["sensors"][0]
    assert human["age_us"]["max"] - human["age_us"]["min"] == pytest.approx(
        1e6 / imu_hz - CYCLE_NS / 1e3, abs=1.0
    )  # the IMU's sample held for a period, seen each bus cycle


def test_the_cli_prints_and_checks_the_sensor_options(cli, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    monkeypatch.setenv("COLUMNS", "80")
    code, out, _ = cli("bus", "simulate", "--duration", "200ms", "-q", "--imu-rate", "100",
                       "--format", "json")
    doc = json.loads(out)
    assert doc["can_gateway"]["sensors"][0]["rate_hz"] == 100.0
    code, out, _ = cli("bus", "simulate", "--duration", "200ms", "-q")
    lines = [line for line in out.splitlines() if " age " in line]
    assert [line.split()[0:2] for line in lines] == [["IMU", "age"], ["FTS", "left"],
                                                      ["FTS", "right"]]
    assert all(len(line.rstrip()) <= 80 and "µs" in line and "Hz" in line for line in lines)
    code, _, err = cli("bus", "simulate", "--duration", "10ms", "-q", "--can-bitrate", "125000")
    assert code == 2 and err.count("\n") == 1 and "--can-bitrate" in err
    code, _, err = cli("bus", "simulate", "--duration", "10ms", "-q", "--fts-rate", "-5")
    assert code == 2 and err == "lolacli: error: --fts-rate -5: expected above 0 to 100000 Hz\n"
