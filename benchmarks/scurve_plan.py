"""µs per S-curve plan (lolacli.motion.scurve.plan, seed 003) against Ruckig's own
calculation of the time-optimal trajectory for the same requests, in the same process.

    PYTHONPATH=$PWD python3 benchmarks/scurve_plan.py [N]

Target: under 100 µs per plan (issue 26). Ruckig (C++ behind pybind11) is the baseline.
"""

from __future__ import annotations

import random
import sys
import time

from lolacli.motion.scurve import plan


def cases(n: int) -> list[tuple[float, ...]]:
    rng = random.Random(26)
    out = []
    for _ in range(n):
        vmax = 10 ** rng.uniform(-1, 2)
        amax = vmax * 10 ** rng.uniform(-0.5, 1)
        jmax = amax * 10 ** rng.uniform(-0.3, 1.5)
        d = vmax * 10 ** rng.uniform(-1.5, 1)
        vs, ve = rng.choice((0.0, rng.uniform(0, vmax))), rng.choice((0.0, rng.uniform(0, vmax)))
        out.append((d, vmax, amax, jmax, vs, ve))
    return out


def per_plan_us(fn, todo: list[tuple[float, ...]]) -> float:  # noqa: ANN001
    best = float("inf")
    for _ in range(3):
        start = time.perf_counter()
        for c in todo:
            fn(c)
        best = min(best, time.perf_counter() - start)
    return best / len(todo) * 1e6


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 2000
    todo = cases(n)
    print(f"{n} random requests, best of 3 runs")
    for label, cycle in (("continuous time", None), ("1 ms cycles", 0.001)):
        us = per_plan_us(lambda c, cycle=cycle: plan(*c, cycle_s=cycle), todo)
        each = []
        for c in todo:
            start = time.perf_counter()
            plan(*c, cycle_s=cycle)
            each.append((time.perf_counter() - start) * 1e6)
        each.sort()
        print(f"lolacli plan, {label:15}: {us:7.1f} µs/plan (median {each[n // 2]:.1f}, "
              f"p95 {each[int(0.95 * n)]:.1f}, max {each[-1]:.0f})")
    try:
        import ruckig
    except ImportError:
        print("ruckig not installed: no baseline (pip install ruckig)")
        return
    otg = ruckig.Ruckig(1)
    inp = ruckig.InputParameter(1)
    traj = ruckig.Trajectory(1)

    def rk(c: tuple[float, ...]) -> None:
        d, vmax, amax, jmax, vs, ve = c
        inp.current_position, inp.current_velocity = [0.0], [vs]
        inp.current_acceleration = [0.0]
        inp.target_position, inp.target_velocity = [d], [ve]
        inp.target_acceleration = [0.0]
        inp.max_velocity, inp.max_acceleration, inp.max_jerk = [vmax], [amax], [jmax]
        otg.calculate(inp, traj)

    print(f"ruckig calculate (baseline)     : {per_plan_us(rk, todo):7.1f} µs/plan")


if __name__ == "__main__":
    main()
