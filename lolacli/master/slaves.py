"""Device abstraction classes (seed 000 §IV-C): a slave as application code sees it.

:class:`BusSlave` is the base the application subclasses (the seed's "BusSlave" class):
it declares its Bus Variables as class attributes with :func:`bus_field`, named relative
to the slave (``"Inputs.Statusword"``); constructing it for an ENI slave name links them
(``"Joint04 L Knee.Inputs.Statusword"``). Where ENIs spell a name differently
(``Status word`` / ``Statusword``) a field lists the spellings it takes; the last part
of the name is then matched under the slave, and last the object (index, subindex) the
slave's assigned PDOs map (``obj=(0x6064, 0)``: "Actual motor position" in one ENI). The
master calls :meth:`BusSlave.process` every cycle after the inputs came in (the seed's
procData).

The first users: :class:`Cia402Drive` (the seed's Elmo drive class: a power state machine
and get/set of actual and target position), and the CAN gateway's :class:`Imu` and
:class:`ForceTorqueSensor`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from lolacli.devices.cia402 import (
    CONTROLWORD,
    MODE_CSP,
    MODES,
    MODES_DISPLAY,
    POSITION_ACTUAL,
    STATUSWORD,
    TARGET_POSITION,
    Cia402State,
)
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
    obj: tuple[int, int] | None = None  # the object (index, subindex) a PDO maps


def bus_field(
    kind: type[BusVariable],
    direction: Direction,
    *names: str,
    optional: bool = False,
    obj: tuple[int, int] | None = None,
) -> Any:
    """A Bus Variable of a device class: found by one of ``names`` under the slave, else by
    the last part of a name, else by the object ``obj`` its ENI PDO entry maps (ENIs name
    entries as the vendor likes: "Actual motor position" is 0x6064:00)."""
    return BusField(kind, direction, names, optional, obj)


class BusSlave:
    """Base of the device abstraction classes (see the module docstring)."""

    def __init__(self, image: ProcessImage | Master, slave: str | int) -> None:
        target = image if isinstance(image, ProcessImage) else image.image
        slave = target.slave_name(slave)
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
    if spec.obj is not None:
        mapped = image.objects.get((slave, *spec.obj, spec.direction))
        if mapped is not None:
            return mapped
    return None


def has_field(image: ProcessImage, slave: str, spec: BusField) -> bool:
    """Whether ``slave`` has the Bus Variable a device class declares as ``spec``."""
    return _resolve(image, slave, spec) is not None


_IN, _OUT = Direction.INPUT, Direction.OUTPUT
CONTROLWORD_DISABLE_VOLTAGE = 0x0000
CONTROLWORD_QUICK_STOP = 0x0002
CONTROLWORD_SHUTDOWN = 0x0006
CONTROLWORD_SWITCH_ON = 0x0007
CONTROLWORD_ENABLE_OPERATION = 0x000F
CONTROLWORD_FAULT_RESET = 0x0080
_STATE_MASK = 0x006F


def _state_of(word: int) -> Cia402State | int:
    """The power state a statusword shows (CiA 402-2 Table 30: bits 0-3, 5, 6)."""
    for state, mask in _PATTERNS:
        if word & mask == state:
            return state
    return word & _STATE_MASK


_PATTERNS = (
    (Cia402State.NOT_READY_TO_SWITCH_ON, 0x4F),
    (Cia402State.SWITCH_ON_DISABLED, 0x4F),
    (Cia402State.READY_TO_SWITCH_ON, 0x6F),
    (Cia402State.SWITCHED_ON, 0x6F),
    (Cia402State.OPERATION_ENABLED, 0x6F),
    (Cia402State.QUICK_STOP_ACTIVE, 0x6F),
    (Cia402State.FAULT_REACTION_ACTIVE, 0x4F),
    (Cia402State.FAULT, 0x4F),
)
#: masked statusword -> state, for every value the mask leaves
_STATE_TABLE = {w: _state_of(w) for w in range(0x80) if w & ~_STATE_MASK == 0}
#: the controlword that leads from a state towards operation enabled (transitions 2, 3,
#: 4; 16 from quick stop active, which drives whose quick stop option code is 5-8 take);
#: fault is handled apart (a reset needs a rising edge of bit 7)
_TOWARDS_ENABLED = {
    Cia402State.SWITCH_ON_DISABLED: CONTROLWORD_SHUTDOWN,
    Cia402State.NOT_READY_TO_SWITCH_ON: CONTROLWORD_SHUTDOWN,
    Cia402State.READY_TO_SWITCH_ON: CONTROLWORD_SWITCH_ON,
}
_FAULTED = (Cia402State.FAULT, Cia402State.FAULT_REACTION_ACTIVE)


class Cia402Drive(BusSlave):
    """A CiA 402 servo drive in cyclic synchronous position (the seed's Elmo drive class).

    :meth:`enable` asks for *operation enabled*; every cycle :meth:`process` reads the
    statusword and writes the controlword that leads there (CiA 402-2 Figure 4: shutdown,
    switch on, enable operation; from *fault* a fault reset, whose rising edge of bit 7
    comes after a controlword without it: none is sent while the fault reaction runs, so
    the edge lands in *fault*). :meth:`disable` leads back to *ready to switch on* (from
    *quick stop active*, which takes no shutdown, by disable voltage). :meth:`quick_stop`
    sends quick stop until released. ``reset_faults=False`` leaves a fault standing (the
    application reads 0x603F and decides); :attr:`faults` counts the faults seen.
    :attr:`actual_position` and :attr:`target_position` are the get/set of the seed; while
    not enabled the target follows the actual position, so enabling never jumps.
    """

    statusword = bus_field(
        BusUInt16, _IN, "Inputs.Statusword", "Inputs.Status word", obj=(STATUSWORD, 0)
    )
    position_actual = bus_field(
        BusInt32, _IN, "Inputs.Position actual value", obj=(POSITION_ACTUAL, 0)
    )
    mode_display = bus_field(
        BusInt8, _IN, "Inputs.Modes of operation display", optional=True, obj=(MODES_DISPLAY, 0)
    )
    controlword = bus_field(
        BusUInt16, _OUT, "Outputs.Controlword", "Outputs.Control word", obj=(CONTROLWORD, 0)
    )
    target = bus_field(
        BusInt32, _OUT, "Outputs.Target position", optional=True, obj=(TARGET_POSITION, 0)
    )
    mode = bus_field(BusInt8, _OUT, "Outputs.Modes of operation", optional=True, obj=(MODES, 0))

    def __init__(self, image: ProcessImage | Master, slave: str | int) -> None:
        super().__init__(image, slave)
        self.want_enabled = False
        self.want_quick_stop = False
        self.reset_faults = True
        self.faults = 0
        self.state: Cia402State | int = Cia402State.NOT_READY_TO_SWITCH_ON
        self._target: int | None = None
        self._controlword = -1
        if self.mode is not None:
            self.mode.value = MODE_CSP

    @property
    def enabled(self) -> bool:
        """The drive showed *operation enabled* in the last cycle's statusword."""
        return self.state is Cia402State.OPERATION_ENABLED

    @property
    def actual_position(self) -> int:
        return int(self.position_actual.value)

    @property
    def target_position(self) -> int:
        return self._target if self._target is not None else self.actual_position

    @target_position.setter
    def target_position(self, value: int) -> None:
        """The next set-point; it goes out in this cycle's frame when the drive is enabled
        (set between procData and copyTXData, as the seed's updateDes)."""
        self._target = value
        if self.state is Cia402State.OPERATION_ENABLED and self.target is not None:
            self.target.value = value

    def enable(self) -> None:
        self.want_enabled = True

    def disable(self) -> None:
        self.want_enabled = False

    def quick_stop(self, on: bool = True) -> None:
        """Quick stop (transition 11) while ``on``; released, :meth:`enable` goes on."""
        self.want_quick_stop = on

    @property
    def faulted(self) -> bool:
        return self.state in _FAULTED

    def process(self) -> None:
        before = self.state
        state = self.state = _STATE_TABLE[self.statusword.value & _STATE_MASK]
        if state in _FAULTED:
            if before not in _FAULTED:
                self.faults += 1
            reset = state is Cia402State.FAULT and self.want_enabled and self.reset_faults
            cw = CONTROLWORD_FAULT_RESET if reset else CONTROLWORD_DISABLE_VOLTAGE
        elif self.want_quick_stop:
            cw = CONTROLWORD_QUICK_STOP
        elif not self.want_enabled:
            quick = state is Cia402State.QUICK_STOP_ACTIVE
            cw = CONTROLWORD_DISABLE_VOLTAGE if quick else CONTROLWORD_SHUTDOWN
        else:
            cw = _TOWARDS_ENABLED.get(state, CONTROLWORD_ENABLE_OPERATION)  # type: ignore[call-overload]
        if cw != self._controlword:
            self.controlword.value = self._controlword = cw
        if state is not Cia402State.OPERATION_ENABLED and self.target is not None:
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

    def __init__(self, image: ProcessImage | Master, slave: str | int, side: str) -> None:
        target = image if isinstance(image, ProcessImage) else image.image
        slave = target.slave_name(slave)
        self.axes = {
            axis: target.link(f"{slave}.FTS {side}.{axis}", BusReal32.input())
            for axis in ("Force X", "Force Y", "Force Z", "Torque X", "Torque Y", "Torque Z")
        }
        super().__init__(image, slave)

    @property
    def force(self) -> tuple[float, float, float]:
        snap = self.image.snapshot
        return tuple(snap[self.axes[f"Force {a}"]] for a in "XYZ")

    @property
    def torque(self) -> tuple[float, float, float]:
        snap = self.image.snapshot
        return tuple(snap[self.axes[f"Torque {a}"]] for a in "XYZ")
