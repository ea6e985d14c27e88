"""The seed-003 S-curve planner against Ruckig's time-optimal trajectories, its on-the-fly
use (the seed's 160° example, goals every 0.1 s) and `lolacli traj plan`."""

from __future__ import annotations

import json
import math
import random
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lolacli.errors import UsageError
from lolacli.motion.profile import min_jerk
from lolacli.motion.scurve import bilinear, plan, stream

ruckig = pytest.importorskip("ruckig")


def ruckig_duration(d: float, vmax: float, amax: float, jmax: float, vs: float,
                    ve: float) -> float:
    inp = ruckig.InputParameter(1)
    inp.current_position, inp.current_velocity, inp.current_acceleration = [0.0], [vs], [0.0]
    inp.target_position, inp.target_velocity, inp.target_acceleration = [d], [ve], [0.0]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [vmax], [amax], [jmax]
    traj = ruckig.Trajectory(1)
    assert ruckig.Ruckig(1).calculate(inp, traj) == ruckig.Result.Working
    return float(traj.duration)


def random_cases(n: int, seed: int) -> list[tuple[float, ...]]:
    """(distance, vmax, amax, jmax, v_start, v_end, cycle) drawn over three decades of
    limits; a third with both boundary velocities zero, the rest non-zero (either sign,
    turning round when the distance needs it)."""
    rng = random.Random(seed)
    out = []
    for i in range(n):
        vmax = 10 ** rng.uniform(-1, 2)
        amax = vmax * 10 ** rng.uniform(-0.5, 1)
        jmax = amax * 10 ** rng.uniform(-0.3, 1.5)
        d = vmax * 10 ** rng.uniform(-1.5, 1) * rng.choice((1, 1, -1))
        if i % 3 == 0:
            vs = ve = 0.0
        else:
            vs = rng.uniform(-0.3, 1) * vmax * math.copysign(1, d)
            ve = rng.uniform(-0.3, 1) * vmax * math.copysign(1, d)
        cycle = rng.choice((None, 0.001, 0.0005, 0.002))
        out.append((d, vmax, amax, jmax, vs, ve, cycle))
    return out


CASES = random_cases(300, seed=26)


def check_profile(d, vmax, amax, jmax, vs, ve, cycle):  # noqa: ANN001, ANN201
    p = plan(d, vmax, amax, jmax, vs, ve, cycle)
    s = p.sample()
    tol = 1e-9
    assert np.abs(s["velocity"]).max() <= vmax * (1 + tol)
    assert np.abs(s["acceleration"]).max() <= amax * (1 + tol)
    assert np.abs(s["jerk"]).max() <= jmax * (1 + tol)
    # the closed form between the grid points too (a phase's extreme is at its ends or
    # where a = 0, which the grid may miss by a fraction of a cycle)
    for t in np.linspace(0, p.duration, 997):
        _, v, a, j = p.at(float(t))
        assert abs(v) <= vmax * (1 + tol) and abs(a) <= amax * (1 + tol)
        assert abs(j) <= jmax * (1 + tol)
    scale = max(abs(d), vmax * p.duration, 1e-300)
    assert abs(s["position"][-1] - d) <= 1e-9 * scale
    # (the sampled end is the stated one: where the phases themselves end is checked too)
    assert abs(integrated_end(p) - d) <= 1e-9 * scale
    assert abs(s["velocity"][-1] - ve) <= 1e-9 * vmax
    # and approached, not jumped to: the last cycle before the end lands next to it
    if cycle is not None and len(s["t"]) > 2:
        assert abs(s["position"][-2] - d) <= vmax * cycle * (1 + tol)
        assert p.duration / cycle == pytest.approx(round(p.duration / cycle), abs=1e-6)
    return p


def tiny_ramp(case: tuple[float, ...]) -> bool:
    """Whether a ramp of the continuous optimum changes the velocity by under 1 % of vmax:
    too little to take up what rounding the other phases to whole cycles moves, so the
    family with whole-cycle phases needs a longer detour (the cases it cannot reach)."""
    d, vmax, amax, jmax, vs, ve, cycle = case
    if cycle is None:
        return False
    p = plan(d, vmax, amax, jmax, vs, ve)
    return min(abs(p.v_peak - vs), abs(p.v_peak - ve)) < 0.01 * vmax


def duration_ratios() -> tuple[list[float], list[float]]:
    """(ratios where the family reaches the optimum, ratios of the tiny-ramp cases)."""
    reach, tiny = [], []
    for case in CASES:
        p = check_profile(*case)
        d, vmax, amax, jmax, vs, ve, cycle = case
        ratio = p.duration / ruckig_duration(d, vmax, amax, jmax, vs, ve)
        (tiny if tiny_ramp(case) else reach).append(ratio)
    return sorted(reach), sorted(tiny)


def test_random_cases_keep_limits_hit_the_end_and_are_near_time_optimal() -> None:
    reach, tiny = duration_ratios()
    assert reach[0] >= 1 - 1e-6  # never faster than the optimum: the limits hold
    assert reach[-1] <= 1.05, reach[-10:]
    assert reach[len(reach) // 2] < 1.01
    assert len(tiny) < 0.1 * len(CASES)


def test_continuous_time_matches_ruckig_where_the_optimum_is_in_the_family() -> None:
    """Without a cycle (no rounding) the family's fastest profile is Ruckig's duration:
    with zero boundary accelerations the time-optimal profile is two acceleration-free-
    at-the-ends ramps around a cruise, which is this family."""
    for case in CASES[:120]:
        d, vmax, amax, jmax, vs, ve, _ = case
        p = check_profile(d, vmax, amax, jmax, vs, ve, None)
        assert p.duration == pytest.approx(ruckig_duration(d, vmax, amax, jmax, vs, ve),
                                           rel=1e-6, abs=1e-9)


def test_short_move_reduces_the_peak_by_eq_14() -> None:
    """T4 <= 0 with both ramps at their plateaus: the peak is the seed's eq. 14 root."""
    d, vmax, amax, dmax, jmax, vs, ve = 10.0, 10.0, 2.0, 3.0, 20.0, 1.0, 0.5
    p = plan(d, vmax, amax, jmax, vs, ve, dmax=dmax)
    alpha, beta = 1 / amax + 1 / dmax, amax / jmax + dmax / jmax
    gamma = amax * vs / jmax + dmax * ve / jmax - vs**2 / amax - ve**2 / dmax - 2 * d
    vadj = (-beta + math.sqrt(beta**2 - 4 * alpha * gamma)) / (2 * alpha)
    assert vadj < vmax and not p.cruise_limited
    assert p.v_peak == pytest.approx(vadj, rel=1e-12)
    assert p.durations[3] == 0.0
    assert p.accel == pytest.approx(amax) and p.decel == pytest.approx(-dmax)


def test_whole_cycles_round_up_so_limits_hold() -> None:
    p = plan(160.0, 90.0, 400.0, 4000.0, cycle_s=0.001)
    assert all(abs(t / 0.001 - round(t / 0.001)) < 1e-9 for t in p.durations)
    assert abs(p.v_peak) <= 90.0 and abs(p.accel) <= 400.0
    assert p.end_position == 160.0


def test_bilinear_integration_converges_to_the_closed_form() -> None:
    """Eqs. 15-17 drift from the closed form at the jerk steps; halving the cycle about
    halves the end error (first order), the closed form's is zero."""
    errors = []
    for cycle in (0.002, 0.001, 0.0005):
        p = plan(160.0, 90.0, 400.0, 4000.0, cycle_s=cycle)
        q = bilinear(p)
        assert p.sample()["position"][-1] == 160.0
        errors.append(abs(q["position"][-1] - 160.0))
    assert errors[0] > errors[1] > errors[2] > 0
    assert 1.5 < errors[0] / errors[1] < 4.5 and 1.5 < errors[1] / errors[2] < 4.5


def test_refuses_what_it_cannot_plan() -> None:
    for kwargs in ({"v_start": 3.0}, {"jmax": 0.0}, {"amax": -1.0}, {"vmax": float("nan")},
                   {"distance": float("inf")}, {"distance": 1e300}, {"cycle_s": 0.0}):
        args = {"distance": 1.0, "vmax": 2.0, "amax": 1.0, "jmax": 1.0, **kwargs}
        with pytest.raises(UsageError):
            plan(**args)
    with pytest.raises(UsageError, match="without reversing"):
        plan(1.0, 2.0, 1.0, 1.0, 0.0, 2.0, allow_reverse=False)
    # with reversing allowed it backs up first, then leaves at v_end
    p = plan(1.0, 2.0, 1.0, 1.0, 0.0, 2.0)
    assert p.v_peak < 0 and p.sample()["position"][-1] == pytest.approx(1.0, abs=1e-12)


# --------------------------------------------------------------------- on the fly (seed §4)


def seed_example() -> tuple[list[tuple[float, float]], dict, list]:
    """160° along a MoveIt-like path (minimum jerk over 3.5 s, peak 85.7°/s) sampled as
    goals every 0.1 s; the kernel at 1 ms with 90°/s, 400°/s², 4000°/s³."""
    goals = [(k * 0.1, min_jerk(k * 100_000_000, 3_500_000_000, 0.0, 160.0))
             for k in range(36)]
    series, switches = stream(goals, 4.5, 90.0, 400.0, 4000.0, 0.001)
    return goals, series, switches


def test_seed_example_velocity_within_90_and_continuous_at_every_replan() -> None:
    goals, s, switches = seed_example()
    assert len(switches) == len(goals)
    v, p, a = s["velocity"], s["position"], s["acceleration"]
    assert np.abs(v).max() <= 90.0 * (1 + 1e-12)
    assert np.abs(v).max() > 80.0  # it does move near the limit
    assert p[-1] == pytest.approx(160.0, abs=1e-9) and v[-1] == 0.0
    # continuity: from one cycle to the next, velocity moves by at most amax * Ts and
    # position by at most vmax * Ts, at the switches as everywhere
    assert np.abs(np.diff(v)).max() <= 400.0 * 0.001 * (1 + 1e-9)
    assert np.abs(np.diff(p)).max() <= 90.0 * 0.001 * (1 + 1e-9)
    # the state a new profile starts from is the old one's at that cycle
    for sw in switches:
        k = round(sw.t / 0.001)
        assert (sw.position, sw.velocity) == (p[k], v[k])
    # the acceleration is not continuous (the family starts at a = 0): it steps
    steps = [abs(sw.accel_before - sw.accel_after) for sw in switches]
    assert max(steps) > 0 and np.abs(a).max() <= 400.0 * (1 + 1e-12)


def test_seed_example_plots(tmp_path: Path) -> None:
    from lolacli.cli.traj import write_plot

    goals, s, _ = seed_example()
    out = write_plot(s, tmp_path / "fig6_7.png", "deg", "160°, goals every 0.1 s", goals)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# --------------------------------------------------------------------- lolacli traj plan


ARGS = ("traj", "plan", "--distance", "160", "--vmax", "90", "--amax", "400",
        "--jmax", "4000")


def test_cli_json(cli) -> None:
    code, out, err = cli(*ARGS, "--v-end", "10", "--cycle", "1ms", "--unit", "deg",
                         "-f", "json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["schema"] == "lolacli.traj/1" and doc["unit"] == "deg"
    p = plan(160, 90, 400, 4000, 0, 10, 0.001)
    assert doc["duration_s"] == pytest.approx(p.duration)
    assert doc["end_position"] == 160.0 and doc["end_velocity"] == 10.0
    assert doc["max_velocity"] <= 90 and doc["max_acceleration"] <= 400
    assert doc["max_jerk"] <= 4000 and doc["cycles"] == round(p.duration / 0.001)


def test_cli_human_fits_80_columns_with_units(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from lolacli.cli.main import app

    png = tmp_path / "s.png"
    result = CliRunner().invoke(app, [*ARGS, "--cycle", "1ms", "--unit", "deg",
                                      "--plot", str(png)], env={"COLUMNS": "80"})
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert all(len(line) <= 80 for line in lines if line != f"Plot: {png}")
    assert "deg/s" in result.stdout and "deg/s³" in result.stdout and " ms" in result.stdout
    assert png.read_bytes()[:4] == b"\x89PNG"


@pytest.mark.parametrize(
    ("extra", "said"),
    [
        (("--v-start", "100"), "above vmax"),
        (("--jmax", "0"), "jmax must be greater than 0"),
        (("--amax", "-5"), "amax must be greater than 0"),
        (("--vmax", "nan"), "--vmax: "),
        (("--distance", "1e300"), "out of range"),
        (("--distance", "inf"), "finite"),
        (("--jmax", "1e-300"), "at least 1e-12"),
        (("--distance", "1e12", "--vmax", "1e-6", "--cycle", "1ms"), "cycles in the profile"),
        (("--cycle", "0s"), "a cycle lasts more than 0 s"),
        (("--distance", "1", "--v-end", "90"), "without reversing"),
        (("--v-start", "-1"), "--v-start: "),
    ],
)
def test_cli_bad_input_is_one_line_exit_2(cli, extra: tuple[str, ...], said: str) -> None:
    args = list(ARGS)
    for name, value in zip(extra[::2], extra[1::2], strict=True):
        if name in args:
            args[args.index(name) + 1] = value
        else:
            args += [name, value]
    code, out, err = cli(*args)
    assert (code, out) == (2, "")
    assert err.count("\n") == 1 and "Traceback" not in err
    assert said in err, err


def test_growth_search_skips_hopeless_candidates(monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 26's slow request: the whole-cycle search used to try ~2000 ramp lengths one
    by one (18-27 ms); the bound skips runs of them that cannot fit, same result."""
    import lolacli.motion.scurve as scurve

    calls = []
    real = scurve._cruise_cycles

    def counted(*args):  # noqa: ANN002, ANN202
        calls.append(args)
        return real(*args)

    monkeypatch.setattr(scurve, "_cruise_cycles", counted)
    case = (1.902982866011191, 5.27274686259056, 11.797667985002446, 6.462940400002711,
            2.7161942478785157, 1.3415017171851702, 0.001)
    check_profile(*case)
    assert len(calls) < 500


# --------------------------------------------------------------------- tiny distances


def integrated_end(p) -> float:  # noqa: ANN001
    """Where the profile's own phases end (the last phase integrated from its start), not
    the end position the plan states."""
    d, v, a, j = p.durations[6], p.v0[6], p.a0[6], p.jerks[6]
    return p.p0[6] + d * (v + d * (a / 2.0 + d * j / 6.0))


tiny = st.floats(1e-300, 1e-3)
limit = st.floats(1e-3, 1e3)


@settings(max_examples=200, deadline=None)
@given(tiny, st.floats(2.0, 1e6), limit, limit, limit)
def test_a_tiny_distance_is_planned_as_such(d: float, k: float, vmax: float, amax: float,
                                            jmax: float) -> None:
    """The peak velocity of a tiny move is many decades below vmax (~d^(2/3)): the profile
    still covers exactly the distance, and its duration shrinks with it (~d^(1/3))."""
    d *= vmax
    p, longer = plan(d, vmax, amax, jmax), plan(d * k, vmax, amax, jmax)
    assert p.end_position == d
    assert integrated_end(p) == pytest.approx(d, rel=1e-9, abs=0)
    assert integrated_end(longer) == pytest.approx(d * k, rel=1e-9, abs=0)
    assert 0.0 < p.duration < longer.duration


def test_cli_tiny_distance(cli) -> None:
    """1e-200 m at 1 m/s, 1 m/s², 1 m/s³: a triangular profile of 4 (1e-200 / 2)^(1/3) s,
    not a ~0.7 m move labelled 1e-200."""
    code, out, err = cli("traj", "plan", "--distance", "1e-200", "--vmax", "1", "--amax",
                         "1", "--jmax", "1", "-f", "json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["duration_s"] == pytest.approx(4 * (0.5e-200) ** (1 / 3), rel=1e-9, abs=0)
    assert doc["end_position"] == 1e-200
    assert doc["peak_velocity"] == pytest.approx((0.5e-200) ** (2 / 3), rel=1e-9, abs=0)
