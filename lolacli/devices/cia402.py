"""A CiA 402 servo drive as commissioning sees it (CiA 402-2 / IEC 61800-7-201).

The power state machine (0x6040 controlword, 0x6041 statusword; every transition of
Figure 4, fault reset on the rising edge of controlword bit 7, quick stop with its option
code 0x605A, the fault reaction with 0x605E, ramps 0x6084/0x6085), the modes profile
position (1), cyclic synchronous position (8), velocity (9) and torque (10) (0x6060,
0x6061, 0x6502), targets and offsets (0x607A, 0x60FF, 0x6071, 0x60B0, 0x60B1, 0x60B2),
actual values (0x6064, 0x606C, 0x6077, 0x60FC demand, 0x60F4 following error), the
following-error monitor (0x6065 window, 0x6066 timeout: error code 0x8611 in 0x603F),
software position limits (0x607D), max profile velocity 0x607F, max motor speed 0x6080,
max torque 0x6072, motor rated torque 0x6076 (mN·m, what CST's ‰ are of), profile
velocity 0x6081. 0x1008 is a long name (segmented SDO).

Units are the drive's own (increments, increments/s, increments/s², torque in ‰ of rated).
What moves is a *load* (:class:`Load`): the drive hands it the demand of the mode and
gets back position and velocity. The default, :class:`Follower`, is kinematic: it follows
a position demand at most at the velocity limit, integrates a velocity demand, and in
torque mode holds still (it has no inertia for a torque to act on; a joint model behind
the drive gives CST its meaning). Ramps (quick stop, fault reaction) decelerate at the
object's value; 0 stops at once.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum

from lolacli.devices.base import Device
from lolacli.od import OdEntry
from lolacli.wire.datatypes import DataType, encode_value

CONTROLWORD = 0x6040
STATUSWORD = 0x6041
MODES = 0x6060
MODES_DISPLAY = 0x6061
TARGET_POSITION = 0x607A
POSITION_ACTUAL = 0x6064
VELOCITY_ACTUAL = 0x606C
TORQUE_ACTUAL = 0x6077
MAX_VELOCITY = 0x607F
ERROR_CODE = 0x603F
TARGET_VELOCITY = 0x60FF
INTERPOLATION_PERIOD = 0x60C2

TARGET_TORQUE = 0x6071
MAX_TORQUE = 0x6072
RATED_TORQUE = 0x6076
MAX_MOTOR_SPEED = 0x6080
PROFILE_VELOCITY = 0x6081
PROFILE_DECELERATION = 0x6084
QUICK_STOP_DECELERATION = 0x6085
QUICK_STOP_OPTION = 0x605A
FAULT_REACTION_OPTION = 0x605E
FOLLOWING_ERROR_WINDOW = 0x6065
FOLLOWING_ERROR_TIMEOUT = 0x6066
SOFTWARE_LIMITS = 0x607D
POSITION_DEMAND = 0x60FC
FOLLOWING_ERROR_ACTUAL = 0x60F4
POSITION_OFFSET = 0x60B0
VELOCITY_OFFSET = 0x60B1
TORQUE_OFFSET = 0x60B2
SUPPORTED_MODES = 0x6502

MODE_PP = 1
MODE_CSP = 8
MODE_CSV = 9
MODE_CST = 10
#: 0x6502 bits: profile position (bit 0), CSP (7), CSV (8), CST (9)
SUPPORTED_MODES_BITS = 0x0001 | 0x0080 | 0x0100 | 0x0200
#: 0x6065 value that switches the following-error monitor off (CiA 402-2)
WINDOW_OFF = 0xFFFFFFFF
#: 0x603F error code of a following error (CiA 402-2 Annex: "following error")
ERROR_FOLLOWING = 0x8611
#: 0x603F error codes this model raises or a test injects, with their CiA 402 / 301 names
ERROR_NAMES = {0x8611: "following error", 0x8612: "reference limit", 0x7300: "sensor"}
#: default quick stop option code: slow down on the quick-stop ramp, stay in quick stop
#: active (transition 16 back to operation enabled allowed)
QUICK_STOP_DEFAULT = 6


class Cia402State(IntEnum):
    """Power states (CiA 402-2 Figure 4) with their statusword pattern (mask 0x6F)."""

    NOT_READY_TO_SWITCH_ON = 0x0000
    SWITCH_ON_DISABLED = 0x0040
    READY_TO_SWITCH_ON = 0x0021
    SWITCHED_ON = 0x0023
    OPERATION_ENABLED = 0x0027
    QUICK_STOP_ACTIVE = 0x0007
    FAULT_REACTION_ACTIVE = 0x000F
    FAULT = 0x0008


class Command(IntEnum):
    SHUTDOWN = 1
    SWITCH_ON = 2
    ENABLE_OPERATION = 3
    DISABLE_VOLTAGE = 4
    QUICK_STOP = 5
    DISABLE_OPERATION = 6
    FAULT_RESET = 7


STATUS_VOLTAGE_ENABLED = 0x0010
STATUS_REMOTE = 0x0200
STATUS_TARGET_REACHED = 0x0400
STATUS_LIMIT_ACTIVE = 0x0800
STATUS_FOLLOWING = 0x1000  # CSP/CSV/CST: drive follows the command value; PP: set-point ack
STATUS_FOLLOWING_ERROR = 0x2000

CW_NEW_SET_POINT = 0x0010
CW_RELATIVE = 0x0040
CW_HALT = 0x0100


def decode_controlword(cw: int, previous: int) -> Command | None:
    """The state-machine command of a controlword (CiA 402-2 Table 4)."""
    if cw & 0x80 and not previous & 0x80:
        return Command.FAULT_RESET
    if cw & 0x02 == 0:
        return Command.DISABLE_VOLTAGE
    if cw & 0x06 == 0x02:
        return Command.QUICK_STOP
    if cw & 0x07 == 0x06:
        return Command.SHUTDOWN
    if cw & 0x0F == 0x07:
        return Command.SWITCH_ON if previous & 0x0F != 0x0F else Command.DISABLE_OPERATION
    if cw & 0x0F == 0x0F:
        return Command.ENABLE_OPERATION
    return None


S = Cia402State
_TRANSITIONS: dict[tuple[Cia402State, Command], Cia402State] = {
    (S.SWITCH_ON_DISABLED, Command.SHUTDOWN): S.READY_TO_SWITCH_ON,
    (S.READY_TO_SWITCH_ON, Command.SWITCH_ON): S.SWITCHED_ON,
    (S.READY_TO_SWITCH_ON, Command.ENABLE_OPERATION): S.OPERATION_ENABLED,
    (S.READY_TO_SWITCH_ON, Command.DISABLE_VOLTAGE): S.SWITCH_ON_DISABLED,
    (S.READY_TO_SWITCH_ON, Command.QUICK_STOP): S.SWITCH_ON_DISABLED,
    (S.SWITCHED_ON, Command.ENABLE_OPERATION): S.OPERATION_ENABLED,
    (S.SWITCHED_ON, Command.SHUTDOWN): S.READY_TO_SWITCH_ON,
    (S.SWITCHED_ON, Command.DISABLE_VOLTAGE): S.SWITCH_ON_DISABLED,
    (S.SWITCHED_ON, Command.QUICK_STOP): S.SWITCH_ON_DISABLED,
    (S.OPERATION_ENABLED, Command.DISABLE_OPERATION): S.SWITCHED_ON,
    (S.OPERATION_ENABLED, Command.SWITCH_ON): S.SWITCHED_ON,
    (S.OPERATION_ENABLED, Command.SHUTDOWN): S.READY_TO_SWITCH_ON,
    (S.OPERATION_ENABLED, Command.DISABLE_VOLTAGE): S.SWITCH_ON_DISABLED,
    (S.OPERATION_ENABLED, Command.QUICK_STOP): S.QUICK_STOP_ACTIVE,
    (S.FAULT, Command.FAULT_RESET): S.SWITCH_ON_DISABLED,
}


def next_state(
    state: Cia402State,
    command: Command | None,
    option: int = QUICK_STOP_DEFAULT,
    stopped: bool = True,
) -> Cia402State:
    """The state after one step: ``option`` is the quick stop option code (0x605A),
    ``stopped`` whether the ramp of quick stop or fault reaction has come to rest."""
    if state == S.NOT_READY_TO_SWITCH_ON:
        return S.SWITCH_ON_DISABLED  # transition 1: self-test done
    if state == S.FAULT_REACTION_ACTIVE:
        return S.FAULT if stopped else state  # transition 14
    if state == S.QUICK_STOP_ACTIVE:
        if command == Command.DISABLE_VOLTAGE:
            return S.SWITCH_ON_DISABLED  # transition 12
        if 5 <= option <= 8:  # stay in quick stop active
            return S.OPERATION_ENABLED if command == Command.ENABLE_OPERATION else state  # 16
        return S.SWITCH_ON_DISABLED if stopped else state  # transition 12, automatic
    if command is None:
        return state
    return _TRANSITIONS.get((state, command), state)


# what a load is asked to do (see Load)
POSITION, VELOCITY, TORQUE, STOP = "position", "velocity", "torque", "stop"


class Load:
    """What the drive moves: given the mode's demand, the new position and velocity.

    ``follow(kind, demand, position, velocity, limit, dt_ns)``: ``kind`` is
    ``"position"`` (demand in increments, ``limit`` the velocity limit, 0 none),
    ``"velocity"`` (increments/s), ``"torque"`` (‰ of rated torque, ``limit`` the rated
    torque 0x6076 in mN·m, 0 not given) or ``"stop"`` (a
    ramp to rest, ``limit`` its deceleration in increments/s², 0 at once); ``position``
    and ``velocity`` are the actual values, ``dt_ns`` the time since the last step
    (0 on the first). Returns (position, velocity) after ``dt_ns``. A plant model (a
    joint) subclasses this; the default :class:`Follower` is kinematic.
    ``torque_moves``: whether a torque moves it (then a drive in torque is never at rest)."""

    torque_moves = False

    def follow(
        self, kind: str, demand: int, position: int, velocity: int, limit: int, dt_ns: int
    ) -> tuple[int, int]:
        raise NotImplementedError


class Follower(Load):
    """The kinematic default load (and the one the compiled chain core mirrors)."""

    def follow(
        self, kind: str, demand: int, position: int, velocity: int, limit: int, dt_ns: int
    ) -> tuple[int, int]:
        if kind == POSITION:
            new = demand
            if limit and dt_ns:
                step = max(1, (limit * dt_ns) // 1_000_000_000)
                new = position + max(-step, min(step, demand - position))
        elif kind == VELOCITY:
            new = position + (demand * dt_ns) // 1_000_000_000
        elif kind == STOP:
            if not limit or not dt_ns:
                return position, 0
            step = max(1, (limit * dt_ns) // 1_000_000_000)
            speed = max(0, abs(velocity) - step)
            v = speed if velocity > 0 else -speed
            return position + (v * dt_ns) // 1_000_000_000, v
        else:  # torque: no inertia to act on, it holds still
            return position, 0
        return new, ((new - position) * 1_000_000_000) // dt_ns if dt_ns > 0 else 0


_OBJECTS: tuple[tuple[int, str, int, str, int], ...] = (
    # index, name, type, access, default; cyclic ones first (their entries() order)
    (CONTROLWORD, "Controlword", DataType.UNSIGNED16, "rw", 0),
    (STATUSWORD, "Statusword", DataType.UNSIGNED16, "ro", 0),
    (MODES, "Modes of operation", DataType.INTEGER8, "rw", MODE_CSP),
    (MODES_DISPLAY, "Modes of operation display", DataType.INTEGER8, "ro", 0),
    (TARGET_POSITION, "Target position", DataType.INTEGER32, "rw", 0),
    (POSITION_ACTUAL, "Position actual value", DataType.INTEGER32, "ro", 0),
    (VELOCITY_ACTUAL, "Velocity actual value", DataType.INTEGER32, "ro", 0),
    (TARGET_VELOCITY, "Target velocity", DataType.INTEGER32, "rw", 0),
    (MAX_VELOCITY, "Max profile velocity", DataType.UNSIGNED32, "rw", 0),
    (ERROR_CODE, "Error code", DataType.UNSIGNED16, "ro", 0),
    (TARGET_TORQUE, "Target torque", DataType.INTEGER16, "rw", 0),
    (MAX_TORQUE, "Max torque", DataType.UNSIGNED16, "rw", 0),
    (TORQUE_ACTUAL, "Torque actual value", DataType.INTEGER16, "ro", 0),
    (POSITION_DEMAND, "Position demand value", DataType.INTEGER32, "ro", 0),
    (PROFILE_VELOCITY, "Profile velocity", DataType.UNSIGNED32, "rw", 0),
    (FOLLOWING_ERROR_ACTUAL, "Following error actual value", DataType.INTEGER32, "ro", 0),
    (POSITION_OFFSET, "Position offset", DataType.INTEGER32, "rw", 0),
    (VELOCITY_OFFSET, "Velocity offset", DataType.INTEGER32, "rw", 0),
    (TORQUE_OFFSET, "Torque offset", DataType.INTEGER16, "rw", 0),
    # parameters (SDO)
    (QUICK_STOP_OPTION, "Quick stop option code", DataType.INTEGER16, "rw", QUICK_STOP_DEFAULT),
    (FAULT_REACTION_OPTION, "Fault reaction option code", DataType.INTEGER16, "rw", 0),
    (FOLLOWING_ERROR_WINDOW, "Following error window", DataType.UNSIGNED32, "rw", WINDOW_OFF),
    (FOLLOWING_ERROR_TIMEOUT, "Following error time out", DataType.UNSIGNED16, "rw", 0),
    (MAX_MOTOR_SPEED, "Max motor speed", DataType.UNSIGNED32, "rw", 0),
    # mN·m; 0: the load's own (a joint's N k_t I_max)
    (RATED_TORQUE, "Motor rated torque", DataType.UNSIGNED32, "rw", 0),
    (PROFILE_DECELERATION, "Profile deceleration", DataType.UNSIGNED32, "rw", 0),
    (QUICK_STOP_DECELERATION, "Quick stop deceleration", DataType.UNSIGNED32, "rw", 0),
)
_CYCLIC = tuple(o[0] for o in _OBJECTS[:19])
LIMIT_MIN, LIMIT_MAX = -(2**31), 2**31 - 1


class Cia402Drive(Device):
    """A servo drive: power state machine, PP/CSP/CSV/CST, monitors (module docstring)."""

    device_type = 0x00020192  # CiA 402 servo drive profile
    LONG_NAME = (
        "lolacli emulated CiA 402 servo drive, Elmo-Gold-like, for the LOLA joint chain; "
        "this string is long enough to need a segmented SDO upload"
    )

    def define(self) -> None:
        od = self.od
        od.add_var(
            0x1008,
            "Manufacturer device name",
            DataType.VISIBLE_STRING,
            self.LONG_NAME,
            access="const",
        )
        for index, name, dtype, access, default in _OBJECTS:
            if (index, 0) in od:  # the ENI's PDOs made it: the profile's type and access
                entry = od.require(index, 0)
                entry.access, entry.data_type, entry.name = access, dtype, name
                entry.value = encode_value(dtype, default)
            else:
                od.add_var(index, name, dtype, default, access=access, pdo=True)
        od.add_record(
            SOFTWARE_LIMITS,
            "Software position limit",
            [
                ("Min position limit", DataType.INTEGER32, LIMIT_MIN, "rw"),
                ("Max position limit", DataType.INTEGER32, LIMIT_MAX, "rw"),
            ],
        )
        od.add_record(
            INTERPOLATION_PERIOD,
            "Interpolation time period",
            [
                ("Interpolation time period value", DataType.UNSIGNED8, 1, "rw"),
                ("Interpolation time index", DataType.INTEGER8, -3, "rw"),
            ],
        )
        od.add_var(
            SUPPORTED_MODES,
            "Supported drive modes",
            DataType.UNSIGNED32,
            SUPPORTED_MODES_BITS,
            access="ro",
        )
        self.power = Cia402State.NOT_READY_TO_SWITCH_ON
        self.previous_cw = 0
        self.load: Load = Follower()
        self.following_since: int | None = None  # time the following error left its window
        self._cyclic: dict[int, OdEntry] | None = None
        self._config: tuple[int, _Config] | None = None
        self._update_status(self.entries(), 0, 0, False, False)

    def fault(self, error_code: int = 0x5530) -> None:
        """Raise a drive fault (fault injection; transition 13)."""
        self.od.set(ERROR_CODE, 0, error_code)
        self.power = Cia402State.FAULT_REACTION_ACTIVE
        self._update_status(self.entries(), 0, 0, False, False)

    def entries(self) -> dict[int, OdEntry]:
        """The cyclic objects' entries, looked up once (the hot path reads their bytes)."""
        if self._cyclic is None:
            self._cyclic = {index: self.od.require(index, 0) for index in _CYCLIC}
        return self._cyclic

    def config(self) -> _Config:
        """The parameters the step reads (not process data), read again after a write."""
        known = self._config
        if known is not None and known[0] == self.od.writes:
            return known[1]
        g = self.od.get_int
        config = _Config(
            quick_stop=g(QUICK_STOP_OPTION),
            fault_reaction=g(FAULT_REACTION_OPTION),
            window=g(FOLLOWING_ERROR_WINDOW),
            timeout_ns=g(FOLLOWING_ERROR_TIMEOUT) * 1_000_000,
            max_motor_speed=g(MAX_MOTOR_SPEED),
            profile_deceleration=g(PROFILE_DECELERATION),
            quick_stop_deceleration=g(QUICK_STOP_DECELERATION),
            rated_torque=g(RATED_TORQUE),
            limit_min=g(SOFTWARE_LIMITS, 1),
            limit_max=g(SOFTWARE_LIMITS, 2),
        )
        self._config = (self.od.writes, config)
        return config

    def ramp(self, config: _Config, state: Cia402State) -> int:
        """The deceleration of the stop ``state`` runs (0: at once)."""
        option = config.quick_stop if state == S.QUICK_STOP_ACTIVE else config.fault_reaction
        if option in (1, 5):
            return config.profile_deceleration
        if option in (2, 6):
            return config.quick_stop_deceleration
        return 0  # 0: drive function disabled; 3, 4, 7, 8: current/voltage limit

    def core_can_run(self) -> bool:
        """Whether the compiled chain core's mirror of :meth:`step` holds for this drive:
        the kinematic load or a joint (:class:`~lolacli.devices.joint_load.JointLoad`,
        not a subclass), no monitor or limit it lacks."""
        from lolacli.devices.joint_load import JointLoad

        c = self.config()
        return (
            type(self.load) in (Follower, JointLoad)
            and c.window == WINDOW_OFF
            and (c.limit_min, c.limit_max) == (LIMIT_MIN, LIMIT_MAX)
            and c.max_motor_speed == 0
            and self.following_since is None
        )

    def step(self, t_ns: int) -> None:
        e = self.entries()
        c = self.config()
        cw = int.from_bytes(e[CONTROLWORD].value, "little")
        previous = self.previous_cw
        self.previous_cw = cw
        position = _I32.unpack(e[POSITION_ACTUAL].value)[0]
        velocity = _I32.unpack(e[VELOCITY_ACTUAL].value)[0]
        state = self.power
        stopped = velocity == 0 or (state in _STOPPING and self.ramp(c, state) == 0)
        power = self.power = next_state(
            state, decode_controlword(cw, previous), c.quick_stop, stopped
        )
        if power == S.SWITCH_ON_DISABLED and e[ERROR_CODE].value != _ZERO2:
            e[ERROR_CODE].value = _ZERO2
        e[MODES_DISPLAY].value = e[MODES].value
        mode = int.from_bytes(e[MODES].value, "little", signed=True)
        dt_ns = t_ns - self.t_ns if self.t_ns else 0
        load = self.load
        demand = position
        torque = 0
        reached = limited = False
        if power == S.OPERATION_ENABLED:
            limit = _limit(int.from_bytes(e[MAX_VELOCITY].value, "little"), c.max_motor_speed)
            if mode == MODE_CSP or mode == MODE_PP:
                if mode == MODE_CSP:
                    demand = (
                        _I32.unpack(e[TARGET_POSITION].value)[0]
                        + _I32.unpack(e[POSITION_OFFSET].value)[0]
                    )
                else:
                    demand = _I32.unpack(e[POSITION_DEMAND].value)[0]
                    if cw & CW_NEW_SET_POINT and not previous & CW_NEW_SET_POINT:
                        target = _I32.unpack(e[TARGET_POSITION].value)[0]
                        demand = demand + target if cw & CW_RELATIVE else target
                    limit = _limit(int.from_bytes(e[PROFILE_VELOCITY].value, "little"), limit)
                if not c.limit_min <= demand <= c.limit_max:
                    demand = max(c.limit_min, min(c.limit_max, demand))
                    limited = True
                demand = _int32(demand)
                if mode == MODE_PP and cw & CW_HALT:
                    new, v = position, 0
                else:
                    new, v = load.follow(POSITION, demand, position, velocity, limit, dt_ns)
                reached = new == demand or (mode == MODE_PP and bool(cw & CW_HALT))
            else:
                if mode == MODE_CSV:
                    want = (
                        _I32.unpack(e[TARGET_VELOCITY].value)[0]
                        + _I32.unpack(e[VELOCITY_OFFSET].value)[0]
                    )
                    if limit:
                        want = max(-limit, min(limit, want))
                    new, v = load.follow(VELOCITY, want, position, velocity, limit, dt_ns)
                    reached = v == want
                elif mode == MODE_CST:
                    torque = (
                        _I16.unpack(e[TARGET_TORQUE].value)[0]
                        + _I16.unpack(e[TORQUE_OFFSET].value)[0]
                    )
                    most = int.from_bytes(e[MAX_TORQUE].value, "little")
                    if most and not -most <= torque <= most:
                        torque = max(-most, min(most, torque))
                        limited = True
                    torque = _int16(torque)
                    new, v = load.follow(TORQUE, torque, position, velocity, c.rated_torque,
                                         dt_ns)
                    reached = True
                else:  # a mode this drive does not have: no motion
                    new, v = position, 0
                if not c.limit_min <= new <= c.limit_max:
                    new, v, limited = max(c.limit_min, min(c.limit_max, new)), 0, True
                demand = new = _int32(new)
        elif power in _STOPPING:
            new, v = load.follow(STOP, 0, position, velocity, self.ramp(c, power), dt_ns)
            new = demand = _int32(new)
        else:
            new, v = position, 0
        e[POSITION_ACTUAL].value = _I32.pack(new)
        e[VELOCITY_ACTUAL].value = _I32.pack(_int32(v))
        e[TORQUE_ACTUAL].value = _I16.pack(torque)
        e[POSITION_DEMAND].value = _I32.pack(demand)
        error = _int32(demand - new)
        e[FOLLOWING_ERROR_ACTUAL].value = _I32.pack(error)
        over = False
        if c.window != WINDOW_OFF and power == S.OPERATION_ENABLED and mode in (MODE_CSP, MODE_PP):
            over = abs(error) > c.window
        if not over:
            self.following_since = None
        else:
            if self.following_since is None:
                self.following_since = t_ns
            if t_ns - self.following_since >= c.timeout_ns:
                self.following_since = None
                e[ERROR_CODE].value = ERROR_FOLLOWING.to_bytes(2, "little")
                self.power = S.FAULT_REACTION_ACTIVE  # transition 13
        self._update_status(e, mode, cw, reached, limited, over)

    def at_rest(self) -> bool:
        """Standing still in a state the same controlword keeps: nothing would change."""
        e = self.entries()
        power = self.power
        if power in _TRANSIENT or self.following_since is not None:
            return False
        cw = self.previous_cw
        c = self.config()
        if next_state(power, decode_controlword(cw, cw), c.quick_stop, True) != power:
            return False
        if e[VELOCITY_ACTUAL].value != _ZERO4:
            return False
        if power != S.OPERATION_ENABLED:
            return True
        mode = int.from_bytes(e[MODES].value, "little", signed=True)
        if mode == MODE_CSV:
            return e[TARGET_VELOCITY].value == _ZERO4 and e[VELOCITY_OFFSET].value == _ZERO4
        if mode in (MODE_CSP, MODE_PP):
            return e[POSITION_ACTUAL].value == e[POSITION_DEMAND].value and (
                mode == MODE_PP
                or e[POSITION_OFFSET].value == _ZERO4
                and e[POSITION_DEMAND].value == e[TARGET_POSITION].value
            )
        if mode == MODE_CST:
            return not self.load.torque_moves
        return True

    def _update_status(
        self,
        e: dict[int, OdEntry],
        mode: int,
        cw: int,
        reached: bool,
        limited: bool,
        over: bool = False,
    ) -> None:
        power = self.power
        status = _STATUS_BITS[power]
        if power == S.OPERATION_ENABLED:
            if mode == MODE_PP:
                status = (status & ~STATUS_FOLLOWING) | (STATUS_FOLLOWING if cw & 0x10 else 0)
            if reached:
                status |= STATUS_TARGET_REACHED
        if limited:
            status |= STATUS_LIMIT_ACTIVE
        if over:
            status |= STATUS_FOLLOWING_ERROR
        e[STATUSWORD].value = status.to_bytes(2, "little")


@dataclass(frozen=True, slots=True)
class _Config:
    quick_stop: int
    fault_reaction: int
    window: int
    timeout_ns: int
    max_motor_speed: int
    profile_deceleration: int
    quick_stop_deceleration: int
    rated_torque: int
    limit_min: int
    limit_max: int


def _limit(a: int, b: int) -> int:
    """The tighter of two velocity limits (0: none)."""
    return min(a, b) if a and b else a or b


_I32 = struct.Struct("<i")
_I16 = struct.Struct("<h")
_ZERO2 = bytes(2)
_ZERO4 = bytes(4)
# states that move on by themselves, whatever the controlword
_TRANSIENT = frozenset({S.NOT_READY_TO_SWITCH_ON, S.FAULT_REACTION_ACTIVE})
_STOPPING = frozenset({S.QUICK_STOP_ACTIVE, S.FAULT_REACTION_ACTIVE})


def _status_bits(state: Cia402State) -> int:
    status = int(state) | STATUS_REMOTE
    if state in (S.READY_TO_SWITCH_ON, S.SWITCHED_ON, S.OPERATION_ENABLED, S.QUICK_STOP_ACTIVE):
        status |= STATUS_VOLTAGE_ENABLED
    if state == S.OPERATION_ENABLED:
        status |= STATUS_FOLLOWING
    return status


_STATUS_BITS = {state: _status_bits(state) for state in S}


def _int32(value: int) -> int:
    return ((value + 2**31) % 2**32) - 2**31


def _int16(value: int) -> int:
    return ((value + 2**15) % 2**16) - 2**15
