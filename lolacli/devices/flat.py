"""A device's cyclic state as flat tables, for the compiled chain core.

The device classes (:mod:`~lolacli.devices.base`, :mod:`~lolacli.devices.cia402`,
:mod:`~lolacli.devices.io`) are the reference. :func:`flatten` describes one device as the
tables the C core (``lolacli/emulator/_ccore.c``) runs its cycle on:

* ``vals``: one block of bytes holding the value of every object-dictionary entry the
  cycle reads or writes (its slots);
* the PDO mappings (``Device.pdo_layout``) as rows ``(image bit, bits, value offset, value
  bytes)``, outputs and inputs, with the semantics of ``unpack_outputs``/``pack_inputs``
  (an output entry takes ``ceil(bits / 8)`` bytes, at least one; an input contributes its
  value's low ``bits`` bits, zero beyond its bytes);
* the step's own rows: the CiA 402 drive's cyclic entries (and with a
  :class:`~lolacli.devices.joint_load.JointLoad` behind it, ``joint``: the cascade's
  constants and the load's state as doubles, ``J_*`` below, and ``rest_out``: the outputs
  of its rest cache), the digital IO channels, the
  analog channels with their phases, the CAN gateway's sensor channels with their phases
  and scales and ``aux``: its sensors and the bus's schedule
  (:class:`~lolacli.devices.can.CanSchedule`: every arrival of three hyperperiods and
  what each sensor holds after it), the sample each sensor's values are of last.

``None`` when the core does not follow the device: a class with its own step or mapping
code, a drive whose configuration needs what the core's mirror of its step lacks
(``Cia402Drive.core_can_run``: a load other than the kinematic follower or a joint, the
following-error monitor, software position limits, max motor speed), a CAN gateway
bridged to a live CAN bus (``CanGateway.bridge``), or a use the tables cannot hold
without changing it (a value whose length the cycle would change, more than 64 bits
where the core computes in 64). Python runs those.

While the core holds a device's state, the entries' values and the device's scalars
(time of the last cycle, CiA 402 power state and last controlword, last analog sample,
the gateway's held samples, a joint's state and the drive's rest cache) live in the
tables; :meth:`FlatDevice.store` gives them back to the objects. The drive's configuration
the step reads (quick stop option, ramps, rated torque) goes in with every load.
"""

from __future__ import annotations

from array import array
from dataclasses import dataclass, field

from lolacli.devices.base import Device
from lolacli.devices.can import channel_phase
from lolacli.devices.cia402 import Cia402Drive, Cia402State
from lolacli.devices.io import FLOAT_PACK, AnalogInput, CanGateway, DigitalIo
from lolacli.devices.joint_load import JointLoad
from lolacli.eni.model import Direction
from lolacli.errors import LolaError
from lolacli.motion.joint import CURRENT_PERIOD_NS, POSITION_PERIOD_NS
from lolacli.od import OdEntry
from lolacli.wire.datatypes import DataType

KIND_GENERIC = 2
KIND_CIA402 = 3
KIND_DIGITAL_IO = 4
KIND_ANALOG = 5
KIND_CAN_GATEWAY = 6

#: the gateway's tables (_ccore.c): aux header words, per sensor, rows of its channels
CAN_HEADER_WORDS = 4  # sensors, hyperperiod, schedule rows, spare
CAN_SENSOR_WORDS = 8  # status at, bytes, counter at, bytes, shift, period, phase, held
#: the most schedule rows a gateway's table holds (beyond, Python runs it)
CAN_MAX_ROWS = 30_000

#: bytes of the CiA 402 cyclic entries, in ``Cia402Drive._entries`` order
CYCLIC_BYTES = (2, 2, 1, 1, 4, 4, 4, 4, 4, 2, 2, 2, 2, 4, 4, 4, 4, 4, 2)
#: the core's arithmetic takes any state value below this in magnitude
VALUE_LIMIT = 1 << 62

#: a joint's doubles (``J_*`` of _ccore.c): the 25 constants of ``Cascade.constants``,
#: then k_vel,ff, the increments per rad, J/(N k_t), G/(N k_t), k_t N (the back-EMF a reset
#: starts the current PI's integral at), N k_t and the rated torque (mN·m) when 0x6076 is 0;
#: then the state: current, θ, ω, the two integrals, the targets (position, velocity,
#: current), the time carried on (ns), whether there is a last value given back, its
#: position and velocity, whether the targets held are a torque's
JOINT_CONSTANTS = 25
JOINT_STATE = JOINT_CONSTANTS + 7
JOINT_WORDS = JOINT_STATE + 13

_STEPS = {
    Device.step: KIND_GENERIC,
    Cia402Drive.step: KIND_CIA402,
    DigitalIo.step: KIND_DIGITAL_IO,
    AnalogInput.step: KIND_ANALOG,
    CanGateway.step: KIND_CAN_GATEWAY,
}
_BASE_METHODS = (
    "cycle",
    "unpack_outputs",
    "pack_inputs",
    "process_data_bytes",
    "mapping",
    "pdo_layout",
    "byte_layout_of",
)
_KIND_METHODS = {
    KIND_CIA402: ("entries", "config", "ramp", "core_can_run", "at_rest", "_update_status"),
    KIND_DIGITAL_IO: ("channels",),
    KIND_ANALOG: ("channels",),
    KIND_CAN_GATEWAY: ("cycle", "configure", "resume", "_pull", "_write"),
}
#: base methods a kind's class overrides with the same semantics (the gateway's cycle is
#: Device.cycle with a cache of its inputs)
_KIND_OVERRIDES = {KIND_CAN_GATEWAY: frozenset({"cycle"})}
_KIND_CLASS: dict[int, type[Device]] = {
    KIND_CIA402: Cia402Drive,
    KIND_DIGITAL_IO: DigitalIo,
    KIND_ANALOG: AnalogInput,
    KIND_CAN_GATEWAY: CanGateway,
}
_POWER_STATES = frozenset(int(s) for s in Cia402State)
_MASK64 = (1 << 64) - 1


@dataclass(slots=True)
class DeviceScalars:
    """The device's own state besides its entries (what the C table keeps per slave)."""

    t_ns: int = 0
    power: int = 0
    previous_cw: int = 0
    last_sample: int = 0
    has_last: bool = False
    # CiA 402: the configuration its step reads (loaded, not given back), and the rest
    # cache of a drive with a joint (1: at rest, with ``rest_n`` bytes of outputs)
    quick_stop: int = 0
    quick_stop_ramp: int = 0
    fault_ramp: int = 0
    rated_torque: int = 0
    rest: int = 0
    rest_n: int = 0


@dataclass(slots=True)
class FlatDevice:
    """One device as tables (see the module docstring); ``rows`` per kind."""

    device: Device
    kind: int
    version: int  # the od.version the tables were made for
    slots: tuple[tuple[OdEntry, int, int], ...]  # entry, offset in vals, bytes
    vals: bytearray
    out_map: array[int]  # rows of 4
    in_map: array[int]
    channels: array[int]  # digital IO rows of 6, analog rows of 6, CAN rows of 6
    phases: array[float]  # analog, one per channel; CAN gateway, phase and scale each
    cyclic: tuple[int, ...]  # CiA 402: offsets of the cyclic entries in vals
    out_bytes: int
    in_bytes: int
    period_ns: int = 0
    scale: float = 0.0
    aux: array[int] = field(default_factory=lambda: array("q"))  # CAN gateway (module)
    drive_load: object = None  # CiA 402: the load the tables were made for
    joint: array[float] = field(default_factory=lambda: array("d"))  # its JointLoad (module)
    rest_out: bytearray = field(default_factory=bytearray)  # the rest cache's outputs

    def load(self) -> DeviceScalars | None:
        """The entries' values into ``vals`` and the device's scalars; ``None`` when the
        tables no longer fit the device (its mapping or a value's length changed)."""
        device = self.device
        if device.od.version != self.version:
            return None
        vals = self.vals
        for entry, offset, size in self.slots:
            value = entry.value
            if len(value) != size:
                return None
            vals[offset : offset + size] = value
        scalars = DeviceScalars(t_ns=device.t_ns)
        if isinstance(device, Cia402Drive):
            if device.load is not self.drive_load or not device.core_can_run():
                return None  # another load, or configured since (an SDO write)
            scalars.power = int(device.power)
            scalars.previous_cw = device.previous_cw
            if scalars.power not in _POWER_STATES or not 0 <= scalars.previous_cw <= 0xFFFF:
                return None
            c = device.config()
            scalars.quick_stop, scalars.rated_torque = c.quick_stop, c.rated_torque
            scalars.quick_stop_ramp = device.ramp(c, Cia402State.QUICK_STOP_ACTIVE)
            scalars.fault_ramp = device.ramp(c, Cia402State.FAULT_REACTION_ACTIVE)
            if self.joint and not self._load_joint(device, scalars):
                return None
        elif isinstance(device, AnalogInput):
            last = getattr(device, "last_sample", None)
            if last is not None:
                scalars.last_sample, scalars.has_last = last, True
        elif isinstance(device, CanGateway):
            held = device.held
            if device.live is not None:
                return None  # bridged to a live CAN bus since it was flattened
            if len(held) != self.aux[0] or not all(_bounded(k) for k in held):
                return None
            for i, k in enumerate(held):
                self.aux[CAN_HEADER_WORDS + i * CAN_SENSOR_WORDS + 7] = k
        if not all(_bounded(v) for v in (scalars.t_ns, scalars.last_sample)):
            return None
        return scalars

    def store(self, scalars: DeviceScalars) -> None:
        """Give the values and scalars back to the device (the Python objects hold the
        state again)."""
        device = self.device
        data = bytes(self.vals)
        for entry, offset, size in self.slots:
            entry.value = data[offset : offset + size]
        device.t_ns = scalars.t_ns
        device.rest_cache = None  # its inputs cache was made before the core's cycles
        if isinstance(device, Cia402Drive):
            device.power = Cia402State(scalars.power)
            device.previous_cw = scalars.previous_cw
            if self.joint:
                self._store_joint(device, scalars)
        elif isinstance(device, AnalogInput) and scalars.has_last:
            device.last_sample = scalars.last_sample
        elif isinstance(device, CanGateway):
            aux = self.aux
            device.held = [
                aux[CAN_HEADER_WORDS + i * CAN_SENSOR_WORDS + 7] for i in range(aux[0])
            ]
            device.resume(scalars.t_ns)

    def _load_joint(self, device: Cia402Drive, scalars: DeviceScalars) -> bool:
        """The JointLoad's constants and state into ``joint``, the drive's rest cache into
        ``rest_out``; False when a value is not one the tables hold exactly."""
        load = device.load
        assert isinstance(load, JointLoad)
        cascade, last = load.cascade, load.last
        has_last = last is not None
        position, velocity = last if last is not None else (0, 0)
        if not (0 <= load.pending_ns < POSITION_PERIOD_NS and type(load.pending_ns) is int
                and all(type(x) is int and float(x) == x for x in (position, velocity))
                and type(load.rated_torque_mnm) is int and 0 <= load.rated_torque_mnm < 1 << 32
                and cascade.substeps == 1):
            return False
        p = load.params
        values = (*cascade.constants, cascade.kvel_ff, load.scale, load.inertia_per_a,
                  load.gravity_per_a, p.torque_constant_nm_per_a * p.gear_ratio,
                  p.link_torque_per_a, load.rated_torque_mnm,
                  cascade.current, cascade.theta, cascade.omega, cascade.vint, cascade.iint,
                  load.ref, load.ref_v, load.ff, load.pending_ns, has_last, position, velocity,
                  load.torque)
        try:
            made = array("d", values)
        except (TypeError, OverflowError):
            return False
        if len(made) != len(self.joint):
            return False
        self.joint[:] = made  # in place: the core has its address
        rest = device.rest_cache
        if rest is not None and rest[1] == device.od.writes and len(rest[0]) <= len(
            self.rest_out
        ):
            scalars.rest, scalars.rest_n = 1, len(rest[0])
            self.rest_out[: len(rest[0])] = rest[0]
        return True

    def _store_joint(self, device: Cia402Drive, scalars: DeviceScalars) -> None:
        """The JointLoad's state and the drive's rest cache back from the tables."""
        load = device.load
        assert isinstance(load, JointLoad)
        cascade = load.cascade
        (cascade.current, cascade.theta, cascade.omega, cascade.vint, cascade.iint,
         load.ref, load.ref_v, load.ff, pending, has_last, position, velocity,
         torque) = self.joint[JOINT_STATE:]
        load.pending_ns = int(pending)
        load.last = (int(position), int(velocity)) if has_last else None
        load.torque = bool(torque)
        if scalars.rest:
            device.rest_cache = (bytes(self.rest_out[: scalars.rest_n]), device.od.writes,
                                 device.pack_inputs())


def flatten(device: Device) -> FlatDevice | None:
    """The device as tables, or ``None`` when only Python runs it (see the module)."""
    kind = _kind(device)
    if kind is None:
        return None
    try:
        return _Builder(device, kind).build()
    except (_NotFlat, LolaError):
        return None


class _NotFlat(Exception):
    """The core cannot hold this device's cycle."""


def _kind(device: Device) -> int | None:
    cls = type(device)
    kind = _STEPS.get(getattr(cls, "step", None))  # type: ignore[arg-type]
    own = _KIND_OVERRIDES.get(kind, frozenset()) if kind is not None else frozenset()
    if kind is None or any(
        getattr(cls, m) is not getattr(Device, m) for m in _BASE_METHODS if m not in own
    ):
        return None
    reference = _KIND_CLASS.get(kind)
    if reference is not None:
        for name in _KIND_METHODS[kind]:
            if getattr(cls, name) is not getattr(reference, name):
                return None
    return kind


class _Builder:
    def __init__(self, device: Device, kind: int) -> None:
        self.device = device
        self.kind = kind
        self.slots: dict[int, tuple[OdEntry, int, int]] = {}
        self.size = 0

    def slot(self, entry: OdEntry, size: int | None = None) -> int:
        """The entry's offset in vals (one slot per entry); ``size``: the length the
        cycle writes, which must be the value's."""
        if type(entry.value) not in (bytes, bytearray):
            raise _NotFlat
        if size is not None and len(entry.value) != size:
            raise _NotFlat  # the cycle would change the value's length
        known = self.slots.get(id(entry))
        if known is None:
            known = (entry, self.size, len(entry.value))
            self.slots[id(entry)] = known
            self.size += known[2]
        return known[1]

    def build(self) -> FlatDevice:
        device = self.device
        out_bytes, in_bytes = device.process_data_bytes()
        out_map = self._map(Direction.OUTPUT, writes=True)
        in_map = self._map(Direction.INPUT, writes=False)
        channels, phases = array("q"), array("d")
        cyclic: tuple[int, ...] = ()
        period_ns, scale = 0, 0.0
        aux = array("q")
        joint, rest_out = array("d"), bytearray()
        if self.kind == KIND_CIA402:
            assert isinstance(device, Cia402Drive)
            if not device.core_can_run():
                raise _NotFlat  # a load, monitor or limit the core lacks
            if isinstance(device.load, JointLoad):
                if POSITION_PERIOD_NS != 2 * CURRENT_PERIOD_NS:
                    raise _NotFlat  # the core runs the current loop twice a period
                joint, rest_out = array("d", bytes(8 * JOINT_WORDS)), bytearray(out_bytes)
            entries = device.entries()
            cyclic = tuple(
                self.slot(entry, size)
                for entry, size in zip(entries.values(), CYCLIC_BYTES, strict=True)
            )
        elif self.kind == KIND_DIGITAL_IO:
            assert isinstance(device, DigitalIo)
            channels = self._digital_channels(device)
        elif self.kind == KIND_ANALOG:
            assert isinstance(device, AnalogInput)
            channels, phases = self._analog_channels(device)
            period_ns, scale = device.sample_period_ns, float(device.scale)
            if type(period_ns) is not int or not 0 < period_ns < VALUE_LIMIT:
                raise _NotFlat
        elif self.kind == KIND_CAN_GATEWAY:
            assert isinstance(device, CanGateway)
            channels, phases, aux = self._gateway(device)
        slots = tuple(sorted(self.slots.values(), key=lambda s: s[1]))
        return FlatDevice(
            device=device,
            kind=self.kind,
            version=device.od.version,
            slots=slots,
            vals=bytearray(self.size),
            out_map=out_map,
            in_map=in_map,
            channels=channels,
            phases=phases,
            cyclic=cyclic,
            out_bytes=out_bytes,
            in_bytes=in_bytes,
            period_ns=period_ns,
            scale=scale,
            aux=aux,
            drive_load=device.load if isinstance(device, Cia402Drive) else None,
            joint=joint,
            rest_out=rest_out,
        )

    def _map(self, direction: Direction, *, writes: bool) -> array[int]:
        """Rows of the mapping; the byte path of base.py is the bit path when every
        entry's value has the mapped length, which is checked here."""
        device = self.device
        byte_layout = device.byte_layout_of(direction)
        if byte_layout is not None:
            for entry, _offset, size in byte_layout:
                if entry is not None and len(entry.value) != size:
                    raise _NotFlat
        rows = array("q")
        bit = 0
        for _index, _sub, bits, entry in device.pdo_layout(direction):
            if entry is not None:
                written = max(1, (bits + 7) // 8) if writes else None
                rows.extend((bit, bits, self.slot(entry, written), len(entry.value)))
            bit += bits
        return rows

    def _digital_channels(self, device: DigitalIo) -> array[int]:
        rows = array("q")
        for i, entry, source, bits in device.channels():
            if bits > 64:
                raise _NotFlat
            size = max(1, (bits + 7) // 8)
            at = self.slot(entry, size)
            if source is None:
                rows.extend((i, at, size, bits, -1, 0))
            else:
                rows.extend((i, at, size, bits, self.slot(source), len(source.value)))
        return rows

    def _analog_channels(self, device: AnalogInput) -> tuple[array[int], array[float]]:
        rows, phases = array("q"), array("d")
        f32, f64 = FLOAT_PACK[DataType.REAL32], FLOAT_PACK[DataType.REAL64]
        for entry, phase, pack, full, offset, mask, size in device.channels():
            if pack is None:
                kind = 0
                if mask > _MASK64 or size > 8:
                    raise _NotFlat
            else:
                kind, size = (1, 4) if pack is f32 else (2, 8) if pack is f64 else (-1, 0)
                if kind < 0:
                    raise _NotFlat
            at = self.slot(entry, size)
            signed_mask = mask - (1 << 64) if mask >= 1 << 63 else mask
            rows.extend((at, size, kind, full, offset, signed_mask))
            phases.append(phase)
        return rows, phases


    def _gateway(self, device: CanGateway) -> tuple[array[int], array[float], array[int]]:
        """The gateway's channel rows (sensor, value at, 4, 1 (REAL32), 0, 0) with their
        phases and scales, and its aux table (see the module)."""
        plan = device.schedule
        sensors = device.config.sensors
        if device.live is not None:
            raise _NotFlat  # its samples come from a live CAN bus (CanGateway.bridge)
        if plan is None or len(plan.log) > CAN_MAX_ROWS or not plan.hyper_ns < VALUE_LIMIT:
            raise _NotFlat  # a bus whose arrivals do not repeat soon enough: Python
        rows, phases = array("q"), array("d")
        aux = array("q", (len(sensors), plan.hyper_ns, len(plan.log), 0))
        for i, (sensor, (status, count, entries)) in enumerate(
            zip(sensors, device.sensor_entries, strict=True)
        ):
            words = []
            for entry, sizes in ((status, (1, 8)), (count, (2, 8))):
                if entry is None:
                    words += [-1, 0]
                    continue
                size = len(entry.value)
                if not sizes[0] <= size <= sizes[1]:
                    raise _NotFlat
                words += [self.slot(entry), size]
            words += [plan.shifts[i], sensor.period_ns, sensor.phase_ns, -1]
            aux.extend(words)
            for sub, entry in enumerate(entries, start=1):
                if entry is None:
                    continue
                rows.extend((i, self.slot(entry, 4), 4, 1, 0, 0))
                phases.extend((channel_phase(sub, sensor.node_id), float(sensor.scale)))
        for t_a, held in plan.held_rows():
            aux.append(t_a)
            aux.extend(held)
        if not all(_bounded(x) for x in aux):
            raise _NotFlat
        return rows, phases, aux


def _bounded(value: int) -> bool:
    return -VALUE_LIMIT < value < VALUE_LIMIT


__all__ = [
    "KIND_ANALOG",
    "KIND_CAN_GATEWAY",
    "KIND_CIA402",
    "KIND_DIGITAL_IO",
    "KIND_GENERIC",
    "DeviceScalars",
    "FlatDevice",
    "flatten",
]
