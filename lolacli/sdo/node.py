"""CANopen nodes served from an EDS: canopen's LocalNode on a python-can bus.

For tests and for users without hardware: ``lolacli sdo serve --can CH --interface
udp_multicast --eds F --node N`` answers SDO requests from any other process on the host
(``virtual`` within one process). ``--gateway`` serves the LOLA CAN gateway's sensors:
the IMU (node 0x10) and the left and right foot force/torque sensors (0x11, 0x12), from
``lolacli/eds_examples``; their measured values (0x6010, 0x6020) are sines of time with
distinct phases, as the EtherCAT side of the gateway shows them (devices/io.py); with
``--pdo`` they also send their samples as TPDOs at their own rates
(:mod:`lolacli.sdo.can_bridge`), which ``bus emulate --can`` bridges into the emulated
gateway's process data.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path
from typing import Any

from lolacli.devices.can import CanConfig, sensor_value
from lolacli.sdo.can_bridge import SensorTransmitter
from lolacli.sdo.canopen_client import NOTIFIER_CYCLE_S, open_bus, quiet_canopen
from lolacli.sdo.files import load_eds_od

IMU_NODE, FTS_LEFT_NODE, FTS_RIGHT_NODE = 0x10, 0x11, 0x12
IMU_VALUES, FTS_VALUES = 0x6010, 0x6020
SENSOR_SCALE = {IMU_VALUES: 10.0, FTS_VALUES: 100.0}
COUNTER = 0x6001


def example_eds(name: str) -> Path:
    """A packaged EDS: ``lola_imu.eds`` or ``lola_fts.eds``."""
    return Path(str(files("lolacli.eds_examples").joinpath(name)))


@dataclass(frozen=True)
class NodeSpec:
    eds: Path
    node_id: int
    sensor: bool = False  # measured values from a clock (the gateway's sensors)


def gateway_nodes() -> list[NodeSpec]:
    return [
        NodeSpec(example_eds("lola_imu.eds"), IMU_NODE, True),
        NodeSpec(example_eds("lola_fts.eds"), FTS_LEFT_NODE, True),
        NodeSpec(example_eds("lola_fts.eds"), FTS_RIGHT_NODE, True),
    ]


def node_specs(
    eds: list[Path], node_ids: list[int], *, gateway: bool = False
) -> list[NodeSpec]:
    """The nodes ``sdo serve`` serves: each EDS with its node ID, in order, then the LOLA
    gateway's sensors; UsageError when the counts differ, nothing is left to serve or a
    node ID is given twice."""
    from lolacli.errors import UsageError

    if len(eds) != len(node_ids):
        raise UsageError(f"{len(eds)} --eds but {len(node_ids)} --node: give one node ID per EDS")
    specs = [NodeSpec(f, n) for f, n in zip(eds, node_ids, strict=True)]
    if gateway:
        specs += gateway_nodes()
    if not specs:
        raise UsageError("nothing to serve: give --eds FILE --node N, or --gateway")
    taken = [s.node_id for s in specs]
    if len(set(taken)) != len(taken):
        raise UsageError(f"node IDs given twice: {taken}")
    return specs


def sensor_callback(node_id: int, clock: Callable[[], float]) -> Callable[..., Any]:
    """A LocalNode read callback: sines for 0x6010/0x6020 entries, a 1 kHz sample counter."""

    def read(index: int, subindex: int, od: Any) -> Any:
        if index in SENSOR_SCALE and subindex > 0:
            return sensor_value(SENSOR_SCALE[index], subindex, node_id, clock())
        if index == COUNTER:
            return int(clock() * 1000) & 0xFFFF
        return None  # the stored or default value

    return read


class NodeServer:
    """LocalNodes on one bus until :meth:`close`. With ``pdo`` (a
    :class:`~lolacli.devices.can.CanConfig` of the gateway's sensors) the sensors also
    send their samples as TPDOs at their rates (:class:`~lolacli.sdo.can_bridge.
    SensorTransmitter`), their instants counted from :attr:`epoch_ns`, the instant the
    SDO values' clock starts at (monotonic ns)."""

    def __init__(
        self,
        channel: str,
        nodes: list[NodeSpec],
        *,
        interface: str | None = None,
        bus: Any = None,
        clock: Callable[[], float] | None = None,
        pdo: CanConfig | None = None,
        **bus_options: Any,
    ) -> None:
        import canopen

        quiet_canopen()
        self.epoch_ns = time.monotonic_ns()  # again once the nodes are on the bus
        self.clock = clock or (lambda: (time.monotonic_ns() - self.epoch_ns) / 1e9)
        self.transmitter: SensorTransmitter | None = None
        if pdo is not None:
            pdo.check_rates()  # exit 2 before the bus
        dictionaries = [load_eds_od(n.eds, n.node_id) for n in nodes]  # exit 3 before the bus
        self.bus = bus if bus is not None else open_bus(channel, interface, **bus_options)
        self.network = canopen.Network(self.bus)
        self.network.NOTIFIER_CYCLE = NOTIFIER_CYCLE_S
        self.nodes = []
        for spec, od in zip(nodes, dictionaries, strict=True):
            node = canopen.LocalNode(spec.node_id, od)
            if spec.sensor:
                node.add_read_callback(sensor_callback(spec.node_id, self.clock))  # type: ignore[no-untyped-call]
            self.network.add_node(node)
            self.nodes.append(node)
        self.network.connect()
        self.epoch_ns = time.monotonic_ns()
        if pdo is not None:
            self.transmitter = SensorTransmitter(
                self.network.send_message, pdo, self.epoch_ns
            ).start()

    def close(self) -> None:
        if self.transmitter is not None:
            self.transmitter.close()  # before the bus goes
        try:
            self.network.disconnect()
        except Exception:  # the bus went away first
            pass

    def __enter__(self) -> NodeServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


__all__ = [
    "FTS_LEFT_NODE",
    "FTS_RIGHT_NODE",
    "IMU_NODE",
    "NodeServer",
    "NodeSpec",
    "example_eds",
    "gateway_nodes",
    "sensor_callback",
]
