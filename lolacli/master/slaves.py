"""Device abstraction classes (seed 000 §IV-C): a slave as application code sees it.

:class:`BusSlave` is the base the application subclasses (the seed's "BusSlave" class):
it declares its Bus Variables as class attributes with :func:`bus_field`, named relative
to the slave (``"Inputs.Statusword"``); constructing it for an ENI slave name links them
(``"Joint04 L Knee.Inputs.Statusword"``). Where ENIs spell a name differently
(``Status word`` / ``Statusword``) a field lists the spellings it takes; the last part
of the name is then matched under the slave. The master calls :meth:`BusSlave.process`
every cycle after the inputs came in (the seed's procData).

The first users: :class:`Cia402Drive` (the seed's Elmo drive class: a power state machine
and get/set of actual and target position), and the CAN gateway's :class:`Imu` and
:class:`ForceTorqueSensor`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from lolacli.devices.cia402 import MODE_CSP, Cia402State
from lolacli.eni.model import Direction
from lolacli.errors import LinkError
from lolacli.master.variables import (
    BusInt8,
    BusInt32,
    BusReal32,
    BusUInt16,
    BusVariable,
    ProcessImage,
)

if TYPE_CHECKING:
    from lolacli.master.core import Master


@dataclass(frozen=True, slots=True)
class BusField:
    """A Bus Variable a device class declares: type, direction, accepted names."""

    kind: type[BusVariable]
    direction: Direction
    names: tuple[str, ...]
    optional: bool = False


def bus_field(
    kind: type[BusVariable], direction: Direction, *names: str, optional: bool = False
) -> Any:
    return BusField(kind, direction, names, optional)


class BusSlave:
    """Base of the device abstraction classes (see the module docstring)."""

    def __init__(self, image: ProcessImage | Master, slave: str) -> None:
        target = image if isinstance(image, ProcessImage) else image.image
        self.slave = slave
        self.image = target
        for attr, spec in _fields(type(self)):
            variable = spec.kind(spec.direction)
            name = _resolve(target, slave, spec)
            if name is None:
                if spec.optional:
                    setattr(self, attr, None)
                    continue
                raise LinkError(
                    f"{slave}.{spec.names[0]}", "no such variable in the ENI's process image"
                )
            target.link(name, variable)
            setattr(self, attr, variable)
        if not isinstance(image, ProcessImage):
            image.devices.append(self)

    def process(self) -> None:
        """Called every cycle after the inputs came in (procData); the default does nothing."""


def _fields(cls: type) -> list[tuple[str, BusField]]:
    out: dict[str, BusField] = {}
    for klass in reversed(cls.__mro__):
        for attr, value in vars(klass).items():
            if isinstance(value, BusField):
                out[attr] = value
    return list(out.items())


def _resolve(image: ProcessImage, slave: str, spec: BusField) -> str | None:
    for name in spec.names:
        if f"{slave}.{name}" in image.variables:
            return f"{slave}.{name}"
    prefix = f"{slave}."
    for name in spec.names:
        last = name.rsplit(".", 1)[-1].lower()
        hits = [
            n
            for n, v in image.variables.items()
            if n.startswith(prefix)
            and n.rsplit(".", 1)[-1].lower() == last
            and v.direction == spec.direction
        ]
        if len(hits) == 1:
            return hits[0]
    return None


_IN, _OUT = Direction.INPUT, Direction.OUTPUT
CONTROLWORD_SHUTDOWN = 0x0006
CONTROLWORD_SWITCH_ON = 0x0007
CONTROLWORD_ENABLE_OPERATION = 0x000F
CONTROLWORD_FAULT_RESET = 0x0080
_STATE_MASK = 0x006F


class Cia402Drive(BusSlave):
    """A CiA 402 servo drive in cyclic synchronous position (the seed's Elmo drive class).

    :meth:`enable` asks for *operation enabled*; every cycle :meth:`process` reads the
    statusword and writes the controlword that leads there (fault reset, shutdown, switch
    on, enable operation: CiA 402-2 Figure 4). :attr:`actual_position` and
    :attr:`target_position` are the get/set of the seed; while not enabled the target
    follows the actual position, so enabling never jumps.
    """

    statusword = bus_field(BusUInt16, _IN, "Inputs.Statusword", "Inputs.Status word")
    position_actual = bus_field(BusInt32, _IN, "Inputs.Position actual value")
    mode_display = bus_field(BusInt8, _IN, "Inputs.Modes of operation display", optional=True)
    controlword = bus_field(BusUInt16, _OUT, "Outputs.Controlword", "Outputs.Control word")
    target = bus_field(BusInt32, _OUT, "Outputs.Target position", optional=True)
    mode = bus_field(BusInt8, _OUT, "Outputs.Modes of operation", optional=True)

    def __init__(self, image: ProcessImage | Master, slave: str) -> None:
        super().__init__(image, slave)
        self.want_enabled = False
        self._target: int | None = None

    @property
    def state(self) -> Cia402State | int:
        word = self.statusword.value & _STATE_MASK
        if word & 0x4F == Cia402State.SWITCH_ON_DISABLED:
            return Cia402State.SWITCH_ON_DISABLED
        if word & 0x4F in (
            Cia402State.NOT_READY_TO_SWITCH_ON,
            Cia402State.FAULT,
            Cia402State.FAULT_REACTION_ACTIVE,
        ):
            return Cia402State(word & 0x4F)
        try:
            return Cia402State(word)
        except ValueError:
            return word

    @property
    def enabled(self) -> bool:
        return self.state == Cia402State.OPERATION_ENABLED

    @property
    def actual_position(self) -> int:
        return int(self.position_actual.value)

    @property
    def target_position(self) -> int:
        return self._target if self._target is not None else self.actual_position

    @target_position.setter
    def target_position(self, value: int) -> None:
        self._target = int(value)

    def enable(self) -> None:
        self.want_enabled = True

    def disable(self) -> None:
        self.want_enabled = False

    def process(self) -> None:
        state = self.state
        if self.mode is not None:
            self.mode.value = MODE_CSP
        if not self.want_enabled:
            self.controlword.value = CONTROLWORD_SHUTDOWN if state != Cia402State.FAULT else 0
        elif state in (Cia402State.FAULT, Cia402State.FAULT_REACTION_ACTIVE):
            self.controlword.value = CONTROLWORD_FAULT_RESET
        elif state == Cia402State.SWITCH_ON_DISABLED:
            self.controlword.value = CONTROLWORD_SHUTDOWN
        elif state == Cia402State.READY_TO_SWITCH_ON:
            self.controlword.value = CONTROLWORD_SWITCH_ON
        else:
            self.controlword.value = CONTROLWORD_ENABLE_OPERATION
        if self.target is not None:
            if state != Cia402State.OPERATION_ENABLED or self._target is None:
                self._target = self.actual_position  # follow: enabling never jumps
            self.target.value = self._target


class Imu(BusSlave):
    """The CAN gateway's inertial measurement unit: rates, accelerations, orientation."""

    rate_x = bus_field(BusReal32, _IN, "IMU.Angular rate X")
    rate_y = bus_field(BusReal32, _IN, "IMU.Angular rate Y")
    rate_z = bus_field(BusReal32, _IN, "IMU.Angular rate Z")
    acceleration_x = bus_field(BusReal32, _IN, "IMU.Acceleration X")
    acceleration_y = bus_field(BusReal32, _IN, "IMU.Acceleration Y")
    acceleration_z = bus_field(BusReal32, _IN, "IMU.Acceleration Z")
    roll = bus_field(BusReal32, _IN, "IMU.Roll")
    pitch = bus_field(BusReal32, _IN, "IMU.Pitch")
    yaw = bus_field(BusReal32, _IN, "IMU.Yaw")

    @property
    def angular_rate(self) -> tuple[float, float, float]:
        snap = self.image.snapshot
        return (snap[self.rate_x], snap[self.rate_y], snap[self.rate_z])

    @property
    def acceleration(self) -> tuple[float, float, float]:
        snap = self.image.snapshot
        return (snap[self.acceleration_x], snap[self.acceleration_y], snap[self.acceleration_z])


class ForceTorqueSensor(BusSlave):
    """One foot's 6-axis force/torque sensor behind the CAN gateway (``side``: "left"
    or "right", the ENI's "FTS left"/"FTS right")."""

    def __init__(self, image: ProcessImage | Master, slave: str, side: str) -> None:
        target = image if isinstance(image, ProcessImage) else image.image
        self.axes = {
            axis: target.link(f"{slave}.FTS {side}.{axis}", BusReal32.input())
            for axis in ("Force X", "Force Y", "Force Z", "Torque X", "Torque Y", "Torque Z")
        }
        super().__init__(image, slave)

    @property
    def force(self) -> tuple[float, float, float]:
        snap = self.image.snapshot
        return tuple(snap[self.axes[f"Force {a}"]] for a in "XYZ")  # type: ignore[return-value]

    @property
    def torque(self) -> tuple[float, float, float]:
        snap = self.image.snapshot
        return tuple(snap[self.axes[f"Torque {a}"]] for a in "XYZ")  # type: ignore[return-value]


def cia402_slaves(image: ProcessImage) -> list[str]:
    """ENI slave names that have a statusword and a target position: the CiA 402 drives."""
    names: list[str] = []
    for name in image.variables:
        slave, _, rest = name.partition(".")
        last = rest.rsplit(".", 1)[-1].lower()
        if last in ("statusword", "status word") and slave not in names:
            names.append(slave)
    return names
