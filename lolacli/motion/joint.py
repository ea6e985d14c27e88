"""A joint behind a drive (pure): motor, gear, link, and the seed's P-PI-PI cascade.

Seed 000 §V, Fig. 5: each LOLA joint's drive closes a position P loop and a velocity PI
loop every 0.1 ms and a current PI loop every 50 µs, on the motor's own encoder and
current sensor. Its inputs, from the central control through the bus, are the target
position θd, the target velocity θ̇d (multiplied by k_vel,ff = 1 + k_e, eq. 2) and a
current feed-forward Id from the robot's inverse dynamics.

Everything here is on the link side of the gear (angle θ in rad, torque in N·m), the
motor's inertia reflected through the gear as N² J_m and its torque as N k_t I:

* electrical:  L dI/dt = V − R I − k_t N ω     (k_t in N·m/A = back-EMF in V·s/rad)
* mechanical:  J dω/dt = N k_t I − b ω − τ_c(ω) − G sin θ,   J = J_load + N² J_m

with τ_c(ω) = F_c tanh(ω / ω_s) Coulomb friction (smoothed over ω_s =
:data:`COULOMB_SMOOTHING_RAD_S` so that it is a function) and G the peak gravity torque
of the link the joint carries (θ = 0 hanging).

Integration. The current PI's output voltage is held over its 50 µs period (the PWM
average), so the linear part (I, θ, ω) is advanced by its exact zero-order-hold
discretisation (matrix exponential); only the friction and gravity torques are held
over a plant step of ``current period / substeps``. Halving that step changes the RMS
tracking error of the walking trajectory by far under 1 % (tests/motion/test_joint.py).

Velocity and position are sampled exactly at each 0.1 ms control instant (an encoder of
unlimited resolution); the current at each 50 µs instant.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import MISSING, dataclass, fields
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

#: ω_s of the smoothed Coulomb friction F_c tanh(ω/ω_s), rad/s
COULOMB_SMOOTHING_RAD_S = 0.01

#: the seed's sampling times (Fig. 5): position and velocity 0.1 ms, current 50 µs
POSITION_PERIOD_NS = 100_000
CURRENT_PERIOD_NS = 50_000

#: the motor encoder's increments per motor turn when a joints file does not say: a 19-bit
#: single-turn absolute encoder (BiSS/EnDat class), the usual one on servo motors of this
#: size; the drive counts motor-side, so a link radian is 2^19 × N / 2π increments
#: (8.3 M at N = 100: 0.12 µrad a count, ±256 rad of link in the int32 position)
DEFAULT_ENCODER_INCREMENTS_PER_REV = 524_288.0


@dataclass(frozen=True)
class JointParams:
    """One joint: its motor, gear, link and drive gains. Units are in the names; the
    packaged values and their sources are in ``joints.toml`` beside this module."""

    name: str
    # motor (motor side)
    motor_inertia_kgm2: float
    torque_constant_nm_per_a: float
    resistance_ohm: float
    inductance_h: float
    supply_v: float
    max_current_a: float
    # gear
    gear_ratio: float
    # link (link side)
    load_inertia_kgm2: float
    viscous_nm_s_per_rad: float
    coulomb_nm: float
    gravity_nm: float
    # drive gains (link side)
    position_kp_per_s: float
    velocity_kp_a_s_per_rad: float
    velocity_ki_per_s: float
    current_kp_v_per_a: float
    current_ki_per_s: float
    # the drive's position unit (optional in a joints file)
    encoder_increments_per_rev: float = DEFAULT_ENCODER_INCREMENTS_PER_REV

    @property
    def increments_per_rad(self) -> float:
        """The drive's position unit: encoder increments (motor side) per radian of the
        link, ``encoder_increments_per_rev`` × N / 2π."""
        return self.encoder_increments_per_rev * self.gear_ratio / (2.0 * math.pi)

    @property
    def inertia_kgm2(self) -> float:
        """J: the link's inertia plus the motor's reflected through the gear (N² J_m)."""
        return self.load_inertia_kgm2 + self.gear_ratio**2 * self.motor_inertia_kgm2

    @property
    def link_torque_per_a(self) -> float:
        """N k_t: link torque per ampere of motor current, N·m/A."""
        return self.gear_ratio * self.torque_constant_nm_per_a

    def check(self) -> list[str]:
        """What makes these parameters unusable (empty when they are fine)."""
        problems = []
        positive = ("motor_inertia_kgm2", "torque_constant_nm_per_a", "resistance_ohm",
                    "inductance_h", "supply_v", "max_current_a", "gear_ratio",
                    "position_kp_per_s", "velocity_kp_a_s_per_rad", "current_kp_v_per_a",
                    "encoder_increments_per_rev")
        for f in fields(self):
            if f.name == "name":
                continue
            value = getattr(self, f.name)
            if not isinstance(value, float) or not math.isfinite(value):
                problems.append(f"{f.name} is not a finite number")
            elif f.name in positive and value <= 0:
                problems.append(f"{f.name} must be > 0")
            elif value < 0:
                problems.append(f"{f.name} must be >= 0")
        return problems

    def current_feedforward(self, accel: Any, position: Any) -> Any:
        """Id from the inverse dynamics the central control knows: inertia and gravity
        (J θ̈d + G sin θd) / (N k_t), in A. Friction is not in the robot's model; the
        loops, and the learned k_e, take it up. Works on floats and numpy arrays."""
        import numpy as np

        return (self.inertia_kgm2 * accel + self.gravity_nm * np.sin(position)) / (
            self.link_torque_per_a
        )


def _expm(m: np.ndarray) -> np.ndarray:
    """Matrix exponential by scaling and squaring a Taylor series (small matrices)."""
    import numpy as np

    norm = float(np.abs(m).sum(axis=1).max())
    squarings = max(0, math.ceil(math.log2(norm / 0.25))) if norm > 0.25 else 0
    a = m / (2.0**squarings)
    result = np.eye(len(m))
    term = np.eye(len(m))
    for k in range(1, 20):
        term = term @ a / k
        result = result + term
    for _ in range(squarings):
        result = result @ result
    return result


def discretize(p: JointParams, step_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(Φ, Γ) of the plant's linear part over ``step_s`` with inputs held (zero-order
    hold): x⁺ = Φ x + Γ [V, τ] for x = [I, θ, ω] and τ the friction and gravity torque."""
    import numpy as np

    j = p.inertia_kgm2
    nkt = p.link_torque_per_a
    a = np.array([
        [-p.resistance_ohm / p.inductance_h, 0.0, -nkt / p.inductance_h],
        [0.0, 0.0, 1.0],
        [nkt / j, 0.0, -p.viscous_nm_s_per_rad / j],
    ])
    b = np.array([[1.0 / p.inductance_h, 0.0], [0.0, 0.0], [0.0, -1.0 / j]])
    m = np.zeros((5, 5))
    m[:3, :3] = a
    m[:3, 3:] = b
    e = _expm(m * step_s)
    return e[:3, :3], e[:3, 3:]


@dataclass(frozen=True)
class DriveInput:
    """What the drive holds during each 0.1 ms control period (one entry per period):
    target position (rad), target velocity (rad/s), current feed-forward (A)."""

    position: Any  # numpy arrays of equal length
    velocity: Any
    current: Any


class Cascade:
    """The drive's P-PI-PI cascade and the joint it moves, one 0.1 ms control period at a
    time: the one implementation behind :func:`run_cascade` (whole trajectories) and the
    emulated drives' joint load (:class:`lolacli.devices.joint_load.JointLoad`, a bus
    cycle's periods at a time).

    State: the motor current :attr:`current` (A), the joint angle :attr:`theta` (rad) and
    velocity :attr:`omega` (rad/s), the velocity PI's integral part :attr:`vint` (A) and
    the current PI's :attr:`iint` (V). ``kvel_ff`` multiplies the target velocity
    (1 + k_e; 0 for none); ``substeps`` plant steps per 50 µs current period."""

    __slots__ = ("p", "kvel_ff", "substeps", "_c", "current", "theta", "omega", "vint",
                 "iint")

    def __init__(self, p: JointParams, *, kvel_ff: float, substeps: int = 1,
                 initial: tuple[float, float] = (0.0, 0.0)) -> None:
        if substeps < 1:
            raise ValueError("substeps must be >= 1")
        self.p, self.kvel_ff, self.substeps = p, kvel_ff, substeps
        tp = POSITION_PERIOD_NS * 1e-9
        tc = CURRENT_PERIOD_NS * 1e-9
        phi, gam = discretize(p, tc / substeps)
        kv, kpc = p.velocity_kp_a_s_per_rad, p.current_kp_v_per_a
        # the loop's constants, unpacked into locals by run()
        self._c = (*phi.ravel().tolist(), *gam.ravel().tolist(),
                   p.position_kp_per_s, kv, kpc, p.max_current_a, p.supply_v,
                   p.coulomb_nm, COULOMB_SMOOTHING_RAD_S, p.gravity_nm,
                   kv * p.velocity_ki_per_s * tp, kpc * p.current_ki_per_s * tc)
        self.current = self.theta = self.omega = self.vint = self.iint = 0.0
        self.reset(*initial)

    @property
    def constants(self) -> tuple[float, ...]:
        """The loop's constants as :meth:`run` uses them: Φ (row by row), Γ (row by row),
        the P, PI and PI gains, the current and voltage limits, F_c, ω_s, G, and the two
        integral gains times their periods (the compiled chain core's copy of a joint)."""
        return self._c

    def reset(self, theta: float, omega: float = 0.0) -> None:
        """Start again at (θ, ω): no current, the integrators at their steady values for
        that motion with no load (the current PI's holds the back-EMF)."""
        self.theta, self.omega = theta, omega
        self.current = 0.0
        self.vint = 0.0
        self.iint = self.p.torque_constant_nm_per_a * self.p.gear_ratio * omega

    def run(self, position: Sequence[float], velocity: Sequence[float],
            current: Sequence[float], out: list[float] | None = None, *,
            current_only: bool = False) -> None:
        """One control period per entry of the targets (position rad, velocity rad/s
        before ``kvel_ff``, current feed-forward A, held over the period); ``out`` gets θ
        at the start of each period, before its control update. ``current_only``: the
        position and velocity loops are bypassed, the current entry is the current
        command itself (clamped at the current limit; a drive in cyclic synchronous
        torque), the current PI runs as ever."""
        (p00, p01, p02, p10, p11, p12, p20, p21, p22, g0v, g0t, g1v, g1t, g2v, g2t,
         kp, kv, kpc, imax, vmax, fc, ws, grav, kvi_tp, kci_tc) = self._c
        kvel_ff = self.kvel_ff
        tanh, sin = math.tanh, math.sin
        cur, th, w, vint, iint = self.current, self.theta, self.omega, self.vint, self.iint
        inner = range(POSITION_PERIOD_NS // CURRENT_PERIOD_NS)
        sub = range(self.substeps)
        record = out.append if out is not None else None
        for target, vel, ff in zip(position, velocity, current, strict=True):
            if record is not None:
                record(th)
            if current_only:
                icmd = ff
                if icmd > imax:
                    icmd = imax
                elif icmd < -imax:
                    icmd = -imax
            else:
                ev = kp * (target - th) + kvel_ff * vel - w
                icmd = kv * ev + vint + ff
                if icmd > imax:
                    icmd = imax
                elif icmd < -imax:
                    icmd = -imax
                else:
                    vint += kvi_tp * ev  # integrate only when not saturated (anti-windup)
            for _ in inner:
                ei = icmd - cur
                volts = kpc * ei + iint
                if volts > vmax:
                    volts = vmax
                elif volts < -vmax:
                    volts = -vmax
                else:
                    iint += kci_tc * ei
                for _ in sub:
                    tau = fc * tanh(w / ws) + grav * sin(th)
                    cur, th, w = (p00 * cur + p01 * th + p02 * w + g0v * volts + g0t * tau,
                                  p10 * cur + p11 * th + p12 * w + g1v * volts + g1t * tau,
                                  p20 * cur + p21 * th + p22 * w + g2v * volts + g2t * tau)
        self.current, self.theta, self.omega, self.vint, self.iint = cur, th, w, vint, iint


def run_cascade(
    p: JointParams,
    drive: DriveInput,
    *,
    kvel_ff: float,
    substeps: int = 1,
    initial: tuple[float, float] = (0.0, 0.0),
    should_stop: Callable[[], bool] | None = None,
) -> np.ndarray:
    """Run the cascade (:class:`Cascade`) over the drive's targets; the joint angle θ
    (rad) at the start of each 0.1 ms period, before its control update (numpy array,
    one per period).

    ``kvel_ff`` multiplies the target velocity (1 + k_e; 0 for none). ``initial`` is
    (θ, ω) at t = 0, the current and the integrators start at their steady values for
    that motion with no load. ``should_stop`` is polled every 1000 periods (0.1 s); when
    it says stop, the run ends there and the array is shorter.
    """
    import numpy as np

    cascade = Cascade(p, kvel_ff=kvel_ff, substeps=substeps, initial=initial)
    tt, vt, it = (np.asarray(a, dtype=float).tolist() for a in (drive.position,
                                                                  drive.velocity,
                                                                  drive.current))
    out: list[float] = []
    for n in range(0, len(tt), 1000):
        if should_stop is not None and n and should_stop():
            break
        cascade.run(tt[n:n + 1000], vt[n:n + 1000], it[n:n + 1000], out)
    return np.array(out)


#: the joint the ``joint`` commands use unless told: the hip flexion of seed 000's tables
DEFAULT_JOINT = "Joint03 L Hip Pitch"


def parse_joints(text: str, source: str) -> dict[str, JointParams]:
    """The joints of a joints file (TOML: ``[class.NAME]`` tables of every
    :class:`JointParams` field, ``[joints]`` slave name = class name; the packaged
    ``joints.toml`` documents them). Raises :class:`~lolacli.errors.InputError` naming
    ``source`` (and the line, when TOML knows it)."""
    import re
    import tomllib

    from lolacli.errors import InputError

    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        where = re.search(r"at line (\d+)", str(exc))
        raise InputError(str(exc), path=source,
                         line=int(where.group(1)) if where else None) from None
    classes, joints = doc.get("class"), doc.get("joints")
    if not isinstance(classes, dict) or not isinstance(joints, dict) or not joints:
        raise InputError("needs [class.NAME] tables and a [joints] table", path=source)
    keys = [f.name for f in fields(JointParams) if f.name != "name"]
    optional = {f.name for f in fields(JointParams) if f.default is not MISSING}
    out = {}
    for joint, cls in joints.items():
        table = classes.get(cls) if isinstance(cls, str) else None
        if not isinstance(table, dict):
            raise InputError(f"joint {joint!r}: no class {cls!r}", path=source)
        missing = [k for k in keys if k not in table and k not in optional]
        unknown = [k for k in table if k not in keys]
        if missing or unknown:
            what = f"missing {', '.join(missing)}" if missing else f"unknown {', '.join(unknown)}"
            raise InputError(f"class {cls!r}: {what}", path=source)
        values = {}
        for k in keys:
            if k not in table:
                continue  # optional: its default
            v = table[k]
            if isinstance(v, bool) or not isinstance(v, int | float):
                raise InputError(f"class {cls!r}: {k} is not a number", path=source)
            values[k] = float(v)
        params = JointParams(name=str(joint), **values)
        if problems := params.check():
            raise InputError(f"class {cls!r}: {problems[0]}", path=source)
        out[str(joint)] = params
    return out


def find_joint(joints: dict[str, JointParams], name: str) -> JointParams | None:
    """The joint called ``name``: its full slave name, or (ignoring case and spaces) the
    name without its number ("L Hip Pitch") or the number alone ("Joint03")."""

    def key(text: str) -> str:
        return "".join(text.lower().split())

    wanted = key(name)
    for full, params in joints.items():
        number, _, rest = full.partition(" ")
        if wanted in (key(full), key(rest), key(number)):
            return params
    return None


__all__ = [
    "COULOMB_SMOOTHING_RAD_S",
    "Cascade",
    "DEFAULT_ENCODER_INCREMENTS_PER_REV",
    "DEFAULT_JOINT",
    "CURRENT_PERIOD_NS",
    "POSITION_PERIOD_NS",
    "DriveInput",
    "JointParams",
    "discretize",
    "find_joint",
    "parse_joints",
    "run_cascade",
]
