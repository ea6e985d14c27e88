"""How well a joint tracks, and the seed's k_e learning (pure).

Seed 000 §V: the velocity feed-forward gain is k_vel,ff = 1 + k_e (eq. 2). k_e starts at
0 (the standard velocity feed-forward) and grows by 0.1 as long as the cost, the RMS
tracking error over two steps of walking, falls (:func:`learn_ke`). Seed 000 §VI-C,
Table III: the hip's RMS error with k_e = 0 at a 1 kHz bus, with the learned k_e, and
with the learned k_e at a 2 kHz bus with extrapolated targets (:func:`table_iii`).

The tracking error is the central control's trajectory θd(t) minus the joint angle θ(t),
both at the start of each 0.1 ms drive period, after a settling time from rest on the
trajectory (the current and the integrators start at the no-load values).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from lolacli.motion.joint import JointParams, run_cascade
from lolacli.motion.targets import BusTiming, Trajectory, drive_input, period_times

if TYPE_CHECKING:
    import numpy as np

#: what the error is measured after, s (the start transient has died out by then)
SETTLE_S = 0.3
#: the step of the k_e learning (seed 000 §V)
KE_STEP = 0.1


class Stopped(Exception):
    """A run was asked to stop (``should_stop``) before it finished."""


@dataclass(frozen=True)
class Tracking:
    """The error of one run over its measuring window: times (s, from the window's
    start) and θd − θ (rad) per 0.1 ms, and their RMS and largest magnitude."""

    times_s: np.ndarray
    error_rad: np.ndarray

    @property
    def rms_rad(self) -> float:
        import numpy as np

        return float(np.sqrt(np.mean(self.error_rad**2)))

    @property
    def max_rad(self) -> float:
        import numpy as np

        return float(np.abs(self.error_rad).max())


def track(
    joint: JointParams,
    trajectory: Trajectory,
    timing: BusTiming,
    *,
    k_e: float,
    window_s: float,
    velocity_ff: bool = True,
    current_ff: bool = True,
    substeps: int = 1,
    should_stop: Callable[[], bool] | None = None,
) -> Tracking:
    """Run the joint on ``trajectory`` for :data:`SETTLE_S` + ``window_s`` and measure the
    tracking error over the window. Raises :class:`Stopped` when ``should_stop`` says so."""
    duration = SETTLE_S + window_s
    t = period_times(duration)
    pos, vel, _ = trajectory(t)
    drive = drive_input(joint, trajectory, timing, duration, current_ff=current_ff)
    theta = run_cascade(
        joint, drive, kvel_ff=(1.0 + k_e) if velocity_ff else 0.0, substeps=substeps,
        initial=(float(pos[0]), float(vel[0])), should_stop=should_stop,
    )
    if len(theta) < len(t):
        raise Stopped
    keep = t >= SETTLE_S - 1e-12
    return Tracking(t[keep] - SETTLE_S, (pos - theta)[keep])


@dataclass(frozen=True)
class Learning:
    """The k_e learning: each step's (k_e, RMS error in rad), and the k_e kept."""

    steps: list[tuple[float, float]]
    k_e: float


def learn_ke(
    cost: Callable[[float], float],
    *,
    start: float = 0.0,
    step: float = KE_STEP,
    max_steps: int = 100,
) -> Learning:
    """Seed 000 §V's policy: from ``start``, raise k_e by ``step`` as long as ``cost``
    (the RMS error of two steps) falls; keep the last k_e before it rose (or stayed).
    Stops after ``max_steps`` evaluations at the latest."""
    k_e = start
    best = cost(k_e)
    steps = [(k_e, best)]
    while len(steps) < max_steps:
        trial = round(k_e + step, 10)
        value = cost(trial)
        steps.append((trial, value))
        if not value < best:
            break
        k_e, best = trial, value
    return Learning(steps, k_e)


def learning_cost(
    joint: JointParams,
    trajectory: Trajectory,
    timing: BusTiming,
    step_s: float,
    should_stop: Callable[[], bool] | None = None,
) -> Callable[[float], float]:
    """The seed's cost: k_e → RMS tracking error (rad) over two steps of ``step_s``."""

    def cost(k_e: float) -> float:
        return track(joint, trajectory, timing, k_e=k_e, window_s=2 * step_s,
                     should_stop=should_stop).rms_rad

    return cost


@dataclass(frozen=True)
class Case:
    """One column of Table III."""

    name: str
    timing: BusTiming
    learned: bool
    k_e: float
    tracking: Tracking

    def to_dict(self) -> dict[str, object]:
        return {
            "name": self.name,
            "control_hz": round(1e9 / self.timing.control_period_ns, 6),
            "bus_hz": round(1e9 / self.timing.bus_period_ns, 6),
            "feedforward": "learned" if self.learned else "standard",
            "extrapolation": self.timing.extrapolate,
            "k_e": self.k_e,
            "rms_error_rad": self.tracking.rms_rad,
            "max_error_rad": self.tracking.max_rad,
        }


def table_iii(
    joint: JointParams,
    trajectory: Trajectory,
    *,
    step_s: float,
    window_s: float,
    control_period_ns: int = 1_000_000,
    fast_bus_period_ns: int = 500_000,
    should_stop: Callable[[], bool] | None = None,
) -> tuple[list[Case], dict[str, Learning]]:
    """The three columns of Table III: k_e = 0 with bus = control rate ("1 kHz ref"); the
    k_e learned there ("1 kHz w/ff"); the k_e learned with the faster bus and extrapolated
    targets ("2 kHz w/ff"). Each learning, as the seed's, runs in the setting it is used in."""
    slow = BusTiming(control_period_ns, control_period_ns, False)
    fast = BusTiming(control_period_ns, fast_bus_period_ns, True)
    learnt = {}
    cases = []
    for timing, learned in ((slow, False), (slow, True), (fast, True)):
        name = f"{_rate(timing.bus_period_ns)} {'w/ff' if learned else 'ref'}"
        k_e = 0.0
        if learned:
            key = "slow" if timing is slow else "fast"
            if key not in learnt:
                learnt[key] = learn_ke(learning_cost(joint, trajectory, timing, step_s,
                                                     should_stop))
            k_e = learnt[key].k_e
        result = track(joint, trajectory, timing, k_e=k_e, window_s=window_s,
                       should_stop=should_stop)
        cases.append(Case(name, timing, learned, k_e, result))
    return cases, learnt


def _rate(period_ns: int) -> str:
    """A bus rate as Table III names it: "1 kHz", "2 kHz", "500 Hz"."""
    hz = 1e9 / period_ns
    return f"{hz / 1000:g} kHz" if hz >= 1000 else f"{hz:g} Hz"


def fine_minimiser(cost: Callable[[float], float], low: float, high: float,
                   step: float) -> tuple[float, float]:
    """(k_e, cost) of the smallest cost on a grid from ``low`` to ``high`` by ``step``."""
    n = int(math.floor((high - low) / step + 1e-9)) + 1
    grid = [round(low + i * step, 10) for i in range(n)]
    values = [cost(k) for k in grid]
    i = min(range(n), key=values.__getitem__)
    return grid[i], values[i]


__all__ = [
    "KE_STEP",
    "SETTLE_S",
    "Case",
    "Learning",
    "Stopped",
    "Tracking",
    "fine_minimiser",
    "learn_ke",
    "learning_cost",
    "table_iii",
    "track",
]
