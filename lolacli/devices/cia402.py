"""A CiA 402 servo drive: the power state machine and cyclic synchronous position.

Objects (CiA 402-2): 0x6040 controlword, 0x6041 statusword, 0x6060/0x6061 modes of
operation (display), 0x607A target position, 0x6064 position actual value, 0x606C
velocity actual value, 0x6077 torque actual value, 0x607F max profile velocity (the
rate limit of CSP following), 0x603F error code, 0x1008 a long name (segmented SDO).
"""

from __future__ import annotations

import struct
from enum import IntEnum

from lolacli.devices.base import Device
from lolacli.od import OdEntry
from lolacli.wire.datatypes import DataType

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

MODE_CSP = 8
MODE_CSV = 9


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
STATUS_FOLLOWING = 0x1000


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
    (S.QUICK_STOP_ACTIVE, Command.DISABLE_VOLTAGE): S.SWITCH_ON_DISABLED,
    (S.QUICK_STOP_ACTIVE, Command.ENABLE_OPERATION): S.OPERATION_ENABLED,
    (S.FAULT, Command.FAULT_RESET): S.SWITCH_ON_DISABLED,
}


def next_state(state: Cia402State, command: Command | None) -> Cia402State:
    if state == S.NOT_READY_TO_SWITCH_ON:
        return S.SWITCH_ON_DISABLED  # self-test done
    if state == S.FAULT_REACTION_ACTIVE:
        return S.FAULT
    if command is None:
        return state
    return _TRANSITIONS.get((state, command), state)


class Cia402Drive(Device):
    """A servo drive in CSP/CSV: actual position follows the target while enabled."""

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
        for index, name, dtype, access in (
            (CONTROLWORD, "Controlword", DataType.UNSIGNED16, "rw"),
            (STATUSWORD, "Statusword", DataType.UNSIGNED16, "ro"),
            (MODES, "Modes of operation", DataType.INTEGER8, "rw"),
            (MODES_DISPLAY, "Modes of operation display", DataType.INTEGER8, "ro"),
            (TARGET_POSITION, "Target position", DataType.INTEGER32, "rw"),
            (POSITION_ACTUAL, "Position actual value", DataType.INTEGER32, "ro"),
            (VELOCITY_ACTUAL, "Velocity actual value", DataType.INTEGER32, "ro"),
            (TARGET_VELOCITY, "Target velocity", DataType.INTEGER32, "rw"),
            (TORQUE_ACTUAL, "Torque actual value", DataType.INTEGER16, "ro"),
            (ERROR_CODE, "Error code", DataType.UNSIGNED16, "ro"),
        ):
            if (index, 0) in od:
                entry = od.require(index, 0)
                entry.access, entry.data_type, entry.name = access, dtype, name
            else:
                od.add_var(index, name, dtype, 0, access=access, pdo=True)
        od.add_var(MAX_VELOCITY, "Max profile velocity", DataType.UNSIGNED32, 0)
        od.add_record(
            INTERPOLATION_PERIOD,
            "Interpolation time period",
            [
                ("Interpolation time period value", DataType.UNSIGNED8, 1, "rw"),
                ("Interpolation time index", DataType.INTEGER8, -3, "rw"),
            ],
        )
        od.add_var(0x6502, "Supported drive modes", DataType.UNSIGNED32, 0x0380, access="ro")
        od.set(MODES, 0, MODE_CSP)
        self.power = Cia402State.NOT_READY_TO_SWITCH_ON
        self.previous_cw = 0
        self._cyclic: dict[int, OdEntry] | None = None
        self._update_status()

    def fault(self, error_code: int = 0x5530) -> None:
        """Raise a drive fault (fault injection)."""
        self.od.set(ERROR_CODE, 0, error_code)
        self.power = Cia402State.FAULT_REACTION_ACTIVE
        self._update_status()

    def entries(self) -> dict[int, OdEntry]:
        """The cyclic objects' entries, looked up once (the hot path reads their bytes)."""
        if self._cyclic is None:
            self._cyclic = {
                index: self.od.require(index, 0)
                for index in (
                    CONTROLWORD,
                    STATUSWORD,
                    MODES,
                    MODES_DISPLAY,
                    TARGET_POSITION,
                    POSITION_ACTUAL,
                    VELOCITY_ACTUAL,
                    TARGET_VELOCITY,
                    MAX_VELOCITY,
                    ERROR_CODE,
                )
            }
        return self._cyclic

    def step(self, t_ns: int) -> None:
        e = self.entries()
        cw = int.from_bytes(e[CONTROLWORD].value, "little")
        previous = self.previous_cw
        self.previous_cw = cw
        power = self.power = next_state(self.power, decode_controlword(cw, previous))
        if power == S.SWITCH_ON_DISABLED and e[ERROR_CODE].value != _ZERO2:
            e[ERROR_CODE].value = _ZERO2
        e[MODES_DISPLAY].value = e[MODES].value
        dt_ns = t_ns - self.t_ns if self.t_ns else 0
        self._move(e, int.from_bytes(e[MODES].value, "little", signed=True), dt_ns)
        self._update_status(e)

    def at_rest(self) -> bool:
        """Standing still in a state the same controlword keeps: nothing would change."""
        e = self.entries()
        if self.power in _TRANSIENT:
            return False
        cw = self.previous_cw
        if next_state(self.power, decode_controlword(cw, cw)) != self.power:
            return False
        if e[VELOCITY_ACTUAL].value != _ZERO4:
            return False
        if self.power != S.OPERATION_ENABLED:
            return True
        if int.from_bytes(e[MODES].value, "little", signed=True) == MODE_CSV:
            return e[TARGET_VELOCITY].value == _ZERO4
        return e[POSITION_ACTUAL].value == e[TARGET_POSITION].value

    def _move(self, e: dict[int, OdEntry], mode: int, dt_ns: int) -> None:
        if self.power != S.OPERATION_ENABLED:
            e[VELOCITY_ACTUAL].value = _ZERO4
            return
        actual = int.from_bytes(e[POSITION_ACTUAL].value, "little", signed=True)
        if mode == MODE_CSV:
            velocity = int.from_bytes(e[TARGET_VELOCITY].value, "little", signed=True)
            new = actual + (velocity * dt_ns) // 1_000_000_000
        else:
            new = int.from_bytes(e[TARGET_POSITION].value, "little", signed=True)
            limit = int.from_bytes(e[MAX_VELOCITY].value, "little")
            if limit and dt_ns:
                step = max(1, (limit * dt_ns) // 1_000_000_000)
                new = actual + max(-step, min(step, new - actual))
        velocity = ((new - actual) * 1_000_000_000) // dt_ns if dt_ns > 0 else 0
        e[POSITION_ACTUAL].value = _I32.pack(_int32(new))
        e[VELOCITY_ACTUAL].value = _I32.pack(_int32(velocity))

    def _update_status(self, e: dict[int, OdEntry] | None = None) -> None:
        e = e or self.entries()
        power = self.power
        status = _STATUS_BITS[power]
        if power == S.OPERATION_ENABLED and e[POSITION_ACTUAL].value == e[TARGET_POSITION].value:
            status |= STATUS_TARGET_REACHED
        e[STATUSWORD].value = status.to_bytes(2, "little")


_I32 = struct.Struct("<i")
_ZERO2 = bytes(2)
_ZERO4 = bytes(4)
# states that move on by themselves, whatever the controlword
_TRANSIENT = frozenset({S.NOT_READY_TO_SWITCH_ON, S.FAULT_REACTION_ACTIVE})


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
