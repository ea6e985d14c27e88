"""The CAN gateway bridged live (seed 000 §III): the sensor nodes (``sdo serve --gateway
--pdo``'s NodeServer) send their samples as TPDOs at their own rates on python-can's
``virtual`` bus, the emulated chain's gateway (``bus emulate --can``'s bridge) holds the
last one to arrive in its process data, and frames at 2 kHz in real time read it: the
values are the sensors' at one of their sample instants, the 200 Hz IMU's change every
tenth frame, and each sensor's age at the master is what its rate allows.

Also the frames' assembly (pure: a lost, short or foreign frame), the gateway leaving
the C core when bridged, and ``bus emulate --can``'s one-line errors.
"""

from __future__ import annotations

import itertools
import statistics
import struct
import time

from lolacli.devices import device_for
from lolacli.devices.can import (
    CanConfig,
    LiveSamples,
    lola_sensors,
    sample_frames,
    sample_values,
    tpdo_cob_id,
)
from lolacli.devices.flat import KIND_CAN_GATEWAY, flatten
from lolacli.devices.io import CanGateway
from lolacli.emulator.run import Emulation
from lolacli.emulator.slave import device_of
from lolacli.files import load_eni, lola_path
from lolacli.sdo.can_bridge import SensorBridge
from lolacli.sdo.canopen_client import CanopenNetwork
from lolacli.sdo.node import IMU_NODE, NodeServer, gateway_nodes
from tests.emulator.bus import Bus

GATEWAY = "CAN Gateway (IMU, FTS)"
CYCLE_NS = 500_000  # 2 kHz
_channels = itertools.count()


def _f32(values: list[float]) -> tuple[float, ...]:
    """Values as REAL32 carries them."""
    return struct.unpack(f"<{len(values)}f", struct.pack(f"<{len(values)}f", *values))


# ---------------------------------------------------------------- the frames, pure


def test_a_sample_is_its_tpdos_in_priority_order() -> None:
    config = CanConfig()
    imu = config.sensors[0]
    values = sample_values(imu, 1_234_000)
    frames = sample_frames(config, 0, values)
    assert [c for c, _ in frames] == [0x181, 0x182, 0x183, 0x184, 0x185]
    assert [len(d) for _, d in frames] == imu.frames() == [8, 8, 8, 8, 4]
    assert b"".join(d for _, d in frames) == struct.pack("<9f", *values)
    # every sensor's block below the next one's: the model's arbitration order
    ids = [tpdo_cob_id(i, f) for i, s in enumerate(config.sensors) for f in range(len(s.frames()))]
    assert ids == sorted(ids) and ids[-1] == 0x193 and len(set(ids)) == 11


def test_live_samples_complete_a_sample_at_its_last_frame_only() -> None:
    config = CanConfig()
    live = LiveSamples(config)
    fts = config.sensors[1]
    first = sample_frames(config, 1, sample_values(fts, 0))
    for n, (cob, data) in enumerate(first):
        assert live.latest[1] is None
        assert live.frame(cob, data, 1000 + n) is (n == len(first) - 1)
    held = live.latest[1]
    assert held is not None and held[0] == 1 and held[2] == 1002
    assert held[1] == _f32(sample_values(fts, 0))
    # the next sample loses its middle frame: it never completes, the first stays held
    second = sample_frames(config, 1, sample_values(fts, 1_000_000))
    live.frame(*second[0], 2000)
    live.frame(*second[2], 2002)
    assert live.latest[1] is held and live.incomplete == 1
    # a sample with a short first frame: incomplete; then a whole one
    live.frame(second[0][0], second[0][1][:4], 3000)
    live.frame(*second[1], 3001)
    live.frame(*second[2], 3002)
    assert live.latest[1] is held and live.incomplete == 2
    for cob, data in second:
        live.frame(cob, data, 4000)
    assert live.latest[1][0] == 2 and live.latest[1][1] == _f32(sample_values(fts, 1_000_000))
    # one whose first frame was lost, one whose first frame came twice (the second
    # starts it again and completes it)
    live.frame(*second[1], 5001)
    live.frame(*second[2], 5002)
    assert live.incomplete == 3 and live.latest[1][0] == 2
    live.frame(*second[0], 5003)
    for cob, data in second:
        live.frame(cob, data, 5004)
    assert live.incomplete == 4 and live.latest[1][0] == 3
    # other nodes' frames, an extended identifier of a TPDO's number: ignored, counted
    live.frame(0x701, b"\x05", 6000)
    live.frame(0x591, bytes(8), 6001)
    live.frame(0x189, bytes(8), 6002, extended=True)
    assert (live.ignored, live.incomplete, live.received) == (3, 4, [0, 3, 0])


# ---------------------------------------------------------------- the gateway


def test_a_bridged_gateway_leaves_the_c_core_and_says_so_in_its_summary() -> None:
    emulation = Emulation(load_eni(lola_path()))
    gateway = next(d for d in map(device_of, emulation.chain.slaves) if isinstance(d, CanGateway))
    flat = flatten(gateway)
    assert flat is not None and flat.kind == KIND_CAN_GATEWAY  # the model runs in C
    live = emulation.bridge_gateway()
    assert flatten(gateway) is None and flat.load() is None  # live samples: Python
    assert emulation.live is live and gateway.live is live
    report = live.report()
    assert [s["name"] for s in report["sensors"]] == ["IMU", "FTS left", "FTS right"]
    assert all(s["samples_received"] == 0 and s["age_us"] is None for s in report["sensors"])


def test_a_frame_reads_what_the_cycles_before_it_took_in() -> None:
    """A frame's age is of the sample in the process data when it came: a cycle the
    emulator held back while the next frame was answered takes its sample in after
    that frame (clock in ns, the arrivals' and the frames')."""
    now = [0]
    config = CanConfig()
    live = LiveSamples(config, clock=lambda: now[0])
    gateway = device_for(next(s for s in load_eni(lola_path()).slaves if s.name == GATEWAY))
    assert isinstance(gateway, CanGateway)
    gateway.bridge(live)
    imu = config.sensors[0]

    def arrive(k: int, at: int) -> None:
        for cob, data in sample_frames(config, 0, sample_values(imu, imu.sample_ns(k))):
            live.frame(cob, data, at)

    def cycle(t: int, runs_at: int) -> None:
        now[0] = runs_at
        gateway.cycle(b"", t)

    arrive(0, 100)
    cycle(1000, 1050)  # the frame at 1000 read nothing yet; sample 0 taken in
    cycle(1500, 1550)  # read sample 0: 1400 old
    arrive(1, 1700)
    cycle(2000, 2600)  # held back past the frame at 2500: read sample 0 (1900), takes 1
    cycle(2500, 2700)  # the frame at 2500 read sample 0 still: 2400
    cycle(3000, 3050)  # read sample 1: 1300
    assert live.ages[0].count == 4 and live.ages[0].total == 1400 + 1900 + 2400 + 1300
    assert (live.ages[0].low, live.ages[0].high, live.read[0]) == (1300, 2400, 2)
    assert gateway.od.get(0x6000, 2) == 2 and gateway.held[0] == 1  # counter: samples
    values = tuple(struct.unpack("<f", gateway.od.entry(0x6010, sub).value)[0]
                   for sub in range(1, 10))
    assert values == _f32(sample_values(imu, imu.sample_ns(1)))
    assert live.ages[1].count == 0  # no FTS sample came


class RealTimeBus(Bus):
    """The test master of tests/emulator/bus.py on the monotonic clock (the gateway's
    arrivals are on it): each frame at the time it is sent."""

    def frame(self, *datagrams):  # type: ignore[no-untyped-def]
        self.t_ns = time.monotonic_ns()
        return super().frame(*datagrams)


def _offsets(eni) -> dict[str, int]:  # type: ignore[no-untyped-def]
    """Byte offsets in the cyclic LRW's data (inputs and outputs from 0) of the
    gateway's variables, by their name after the slave's."""
    prefix = f"{GATEWAY}."
    return {
        v.name[len(prefix):]: v.bit_offset // 8
        for v in eni.process_image.variables
        if v.name.startswith(prefix) and v.direction.name == "INPUT"
    }


def _sample_at(sensor, epoch_ns: int, read_ns: int, values: tuple[float, ...]) -> int | None:  # type: ignore[no-untyped-def]
    """The sample instant (monotonic ns) within a second before ``read_ns`` whose values
    (REAL32) these are, the latest first."""
    k = (read_ns - epoch_ns - sensor.phase_ns) // sensor.period_ns
    for j in range(k, max(-1, k - round(1e9 / sensor.period_ns)), -1):
        if _f32(sample_values(sensor, sensor.sample_ns(j))) == values:
            return epoch_ns + sensor.sample_ns(j)
    return None


def test_the_master_reads_live_samples_held_at_2_khz() -> None:
    """Two seconds of frames at 2 kHz against TPDOs at 200 Hz (IMU) and 1 kHz (FTS)."""
    eni = load_eni(lola_path())
    emulation = Emulation(eni)
    live = emulation.bridge_gateway()
    at = _offsets(eni)
    imu_at = [at[f"IMU.{n}"] for n in ("Angular rate X", "Angular rate Y", "Angular rate Z",
                                       "Acceleration X", "Acceleration Y", "Acceleration Z",
                                       "Roll", "Pitch", "Yaw")]
    fts_at = [at[f"FTS left.{n}"] for n in ("Force X", "Force Y", "Force Z",
                                            "Torque X", "Torque Y", "Torque Z")]
    imu_counter, imu_status = at["Sensor status.IMU counter"], at["Sensor status.IMU status"]
    channel = f"lolacli-bridge-{next(_channels)}"
    config = CanConfig(sensors=lola_sensors(200.0, 1000.0))
    imu, fts = config.sensors[0], config.sensors[1]
    rows = []
    with (
        SensorBridge(channel, live, interface="virtual") as bridge,
        NodeServer(channel, gateway_nodes(), interface="virtual", pdo=config) as server,
        CanopenNetwork(channel, interface="virtual", timeout_s=1.0) as sdo,
    ):
        bus = RealTimeBus(emulation.chain)
        bus.bring_up(eni)
        # an SDO exchange on the same bus meanwhile: two frames of no sensor
        assert len(sdo.client(IMU_NODE).upload(0x1000, 0)) == 4
        due = time.monotonic_ns()
        for _ in range(4000):
            due += CYCLE_NS
            time.sleep(max(0, due - time.monotonic_ns()) / 1e9)  # the GIL free meanwhile
            _, data = bus.cycle(eni)
            rows.append((
                bus.t_ns - 50_000,  # the frame's time (Bus steps its clock after it)
                struct.unpack_from("<HH", data, imu_status),
                struct.unpack_from("<H", data, imu_counter)[0],
                tuple(struct.unpack_from("<f", data, a)[0] for a in imu_at),
                tuple(struct.unpack_from("<f", data, a)[0] for a in fts_at),
            ))
        epoch = server.epoch_ns
    sent = server.transmitter.report()  # all it sent: it stopped before the bridge
    assert bridge.error is None
    report = live.report()
    by_name = {s["name"]: s for s in report["sensors"]}
    assert report["frames_ignored"] == 2 and report["samples_incomplete"] == 0

    read = [r for r in rows if r[1][0] == 1]  # status: a sample arrived
    assert len(read) > 3500  # the first IMU sample within 250 ms of the nodes starting
    # every value the master read is the sensor's at one of its sample instants, taken
    # before the frame read it
    for t, _status, counter, imu_values, fts_values in read[::7]:
        taken = _sample_at(imu, epoch, t, imu_values)
        assert taken is not None and taken <= t, (t, counter, imu_values)
        taken = _sample_at(fts, epoch, t, fts_values)
        assert taken is not None and taken <= t, (t, fts_values)
    # sample and hold: the IMU's values change with its counter only, every 5 ms (every
    # 10th frame while the loop keeps its 2 kHz; a loaded host delays some frames and
    # sends the late ones back to back, so the gaps are timed by the frames' clock)
    changes = [n for n in range(1, len(read)) if read[n][2] != read[n - 1][2]]
    assert all(read[n][3] == read[n - 1][3] for n in range(1, len(read)) if n not in changes)
    gaps_ms = [(read[b][0] - read[a][0]) / 1e6 for a, b in itertools.pairwise(changes)]
    assert 4.5 <= statistics.median(gaps_ms) <= 5.5, gaps_ms
    assert 4.5 <= statistics.mean(gaps_ms) <= 7.0, gaps_ms  # (a late sender skips samples)
    assert read[-1][2] == by_name["IMU"]["samples_received"] or (
        read[-1][2] == by_name["IMU"]["samples_received"] - 1  # one arrived after the last
    )
    # ages at the master: the IMU's held up to its 5 ms period, on average half of it;
    # an FTS's up to its 1 ms plus a frame's 0.5 ms (a loaded host's stalls add to both)
    imu_age, fts_age = by_name["IMU"]["age_us"], by_name["FTS left"]["age_us"]
    assert 0 < imu_age["min"] < 1000 and 1500 < imu_age["mean"] < 6000, imu_age
    assert 0 < fts_age["min"] < 500 and 250 < fts_age["mean"] < 3000, fts_age
    assert imu_age["max"] < 100_000 and fts_age["max"] < 100_000  # a stall of the host
    # at their rates (a sample the sender was too late for is skipped: a loaded host)
    assert 150 < by_name["IMU"]["rate_hz"] < 220 and 600 < by_name["FTS left"]["rate_hz"] < 1100
    for row, done in zip(report["sensors"], sent, strict=True):
        assert 0.95 * done["samples_sent"] <= row["samples_received"] <= done["samples_sent"]
    # each one the master saw (one or two more in the bring-up's frames)
    assert len(changes) + 1 <= by_name["IMU"]["samples_read"] <= len(changes) + 3


# ---------------------------------------------------------------- bus emulate --can


def test_bus_emulate_can_that_does_not_open_is_one_line_and_exit_4(cli) -> None:
    code, out, err = cli("bus", "emulate", "-i", "lo", "--can", "nosuchcan0",
                         "--interface", "socketcan")
    assert (code, out) == (4, "") and err.count("\n") == 1, err
    assert "cannot open CAN bus socketcan nosuchcan0" in err


def test_bus_emulate_can_without_a_gateway_is_a_usage_error(cli, corpus) -> None:
    eni = corpus / "eni" / "murrelektronik-variox__eni.xml"
    code, out, err = cli("bus", "emulate", "-i", "lo", "--eni", eni, "--can", "x",
                         "--interface", "virtual")
    assert (code, out) == (2, "") and err.count("\n") == 1, err
    assert "the ENI has no CAN gateway" in err


def test_sdo_serve_pdo_needs_the_gateway(cli) -> None:
    code, out, err = cli("sdo", "serve", "--can", "x", "--interface", "virtual", "--pdo")
    assert (code, out) == (2, "") and "--pdo" in err and err.count("\n") == 1
