"""What the central control asks of a joint, and what reaches the drive over the bus (pure).

Seed 000 §V: the central control computes a target (position, velocity, current
feed-forward) every ∆t_cont; the bus carries one every ∆t_bus = ∆t_cont / n. When the
bus runs faster (n > 1), new trajectory data exists only every n-th bus cycle and the
intermediate cycles carry the last target position linearly extrapolated with the last
target velocity. Here the drive applies the outputs of bus cycle j at the SYNC0 event that
starts cycle j + 1 (one bus cycle after the master computed them) and holds them until the
next; its 0.1 ms control periods see them as :class:`~lolacli.motion.joint.DriveInput`.

Trajectories are functions of time (s, numpy arrays) giving (θ, θ̇, θ̈) in rad, rad/s,
rad/s²: :func:`hip_walk`, a walking-like hip flexion, and :func:`chirp`, a logarithmic
frequency sweep.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from lolacli.motion.joint import POSITION_PERIOD_NS, DriveInput, JointParams

if TYPE_CHECKING:
    import numpy as np

Trajectory = Callable[[Any], tuple[Any, Any, Any]]


@dataclass(frozen=True)
class HipWalk:
    """Hip flexion while walking: a stride (two steps) of ``2 step_s`` seconds, the first
    harmonic of ``amplitude_rad`` and a second harmonic of ``second_rad`` (stance and swing
    are not symmetric) around ``offset_rad``.

    Defaults: LOLA's walk of seed 000 §VI-C (5 m at 2.7 km/h = 0.75 m/s) with steps of
    0.45 m, so 0.6 s a step; a hip flexion range of about 0.6 rad (35°) as in human
    gait at that speed."""

    step_s: float = 0.6
    amplitude_rad: float = 0.3
    second_rad: float = 0.06
    second_phase_rad: float = 0.8
    offset_rad: float = 0.1

    def __call__(self, t: Any) -> tuple[Any, Any, Any]:
        import numpy as np

        w = math.pi / self.step_s
        a1, a2, ph = self.amplitude_rad, self.second_rad, self.second_phase_rad
        s1, c1 = np.sin(w * t), np.cos(w * t)
        s2, c2 = np.sin(2 * w * t + ph), np.cos(2 * w * t + ph)
        pos = self.offset_rad + a1 * s1 + a2 * s2
        vel = a1 * w * c1 + 2 * a2 * w * c2
        acc = -a1 * w * w * s1 - 4 * a2 * w * w * s2
        return pos, vel, acc


@dataclass(frozen=True)
class Chirp:
    """``amplitude_rad`` sin φ(t), the frequency rising exponentially from ``start_hz`` to
    ``stop_hz`` over ``duration_s`` (then held)."""

    start_hz: float
    stop_hz: float
    duration_s: float
    amplitude_rad: float

    def frequency(self, t: Any) -> Any:
        import numpy as np

        rate = math.log(self.stop_hz / self.start_hz) / self.duration_s
        return self.start_hz * np.exp(rate * np.minimum(t, self.duration_s))

    def __call__(self, t: Any) -> tuple[Any, Any, Any]:
        import numpy as np

        rate = math.log(self.stop_hz / self.start_hz) / self.duration_s
        f = self.frequency(t)
        phase = 2 * math.pi * self.start_hz * np.expm1(rate * np.asarray(t)) / rate
        dphase = 2 * math.pi * f
        ddphase = dphase * rate
        a = self.amplitude_rad
        s, c = np.sin(phase), np.cos(phase)
        return a * s, a * c * dphase, a * (c * ddphase - s * dphase * dphase)


@dataclass(frozen=True)
class BusTiming:
    """Rates of the central control and of the bus (integer ns), and whether the
    intermediate bus cycles extrapolate."""

    control_period_ns: int = 1_000_000
    bus_period_ns: int = 1_000_000
    extrapolate: bool = False

    def check(self) -> str | None:
        """Why this timing cannot be simulated (None when it can)."""
        if self.bus_period_ns < POSITION_PERIOD_NS or self.bus_period_ns % POSITION_PERIOD_NS:
            return "the bus period must be a whole multiple of the drive's 0.1 ms"
        if self.control_period_ns < self.bus_period_ns or (
            self.control_period_ns % self.bus_period_ns
        ):
            return "the control period must be a whole multiple of the bus period"
        return None


def period_times(duration_s: float) -> np.ndarray:
    """The start of each 0.1 ms drive period over ``duration_s``, in s."""
    import numpy as np

    n = int(round(duration_s * 1e9 / POSITION_PERIOD_NS))
    return np.arange(n, dtype=np.int64) * POSITION_PERIOD_NS * 1e-9


def drive_input(
    joint: JointParams,
    trajectory: Trajectory,
    timing: BusTiming,
    duration_s: float,
    *,
    current_ff: bool = True,
) -> DriveInput:
    """The targets the drive holds in each 0.1 ms period over ``duration_s``: the central
    control's sample of ``trajectory`` at its last update, carried by the bus (one cycle
    late), extrapolated in the cycles between updates when ``timing.extrapolate``."""
    import numpy as np

    problem = timing.check()
    if problem is not None:
        raise ValueError(problem)
    n = int(round(duration_s * 1e9 / POSITION_PERIOD_NS))
    t_ns = np.arange(n, dtype=np.int64) * POSITION_PERIOD_NS
    bus = timing.bus_period_ns
    cycle = np.maximum(t_ns // bus - 1, 0)  # the bus cycle whose outputs are applied
    sent_ns = cycle * bus
    control_ns = (sent_ns // timing.control_period_ns) * timing.control_period_ns
    pos, vel, acc = trajectory(control_ns * 1e-9)
    target = np.array(pos, dtype=float)
    if timing.extrapolate:
        target = target + vel * ((sent_ns - control_ns) * 1e-9)
    current = joint.current_feedforward(acc, pos) if current_ff else np.zeros(n)
    return DriveInput(target, np.asarray(vel, dtype=float), np.asarray(current, dtype=float))


__all__ = ["BusTiming", "Chirp", "HipWalk", "Trajectory", "drive_input", "period_times"]
