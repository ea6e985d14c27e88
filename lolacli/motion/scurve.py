"""Jerk-limited S-curve point-to-point planning and its on-the-fly use (pure).

The profile of seed 003 (eqs. 1-17): seven phases of constant jerk. T1-T3 change the
velocity from ``v_start`` to the peak (cruise) velocity, T4 cruises, T5-T7 change it to
``v_end``; each change is a *ramp* whose acceleration starts and ends at zero, rises and
falls with the same jerk (T1 = T3, T5 = T7) and has a plateau (T2, T6) when the change
is large enough to reach the acceleration limit. The first ramp is limited by ``amax``
(the seed's Accmax), the second by ``dmax`` (Decmax), both by ``jmax``.

How :func:`plan` finds it:

1. The peak velocity. With the cruise at ``vmax`` when the distance is long enough for it
   (the seed's T4 > 0); otherwise (T4 <= 0) the reduced peak at which the two ramps alone
   cover the distance: the seed's eq. 14 (a quadratic) when both ramps reach their
   acceleration plateaus, else the same equation with the triangular ramps' square roots,
   solved numerically on the bracket where it is monotonic.
2. Phase times rounded to whole cycles (eqs. 7-10), here *up* (``ceil``) rather than to
   the nearest cycle as the seed writes: a time rounded down would need more than
   Accmax/Jacc; rounded up, the re-solved acceleration, deceleration and peak velocity
   (eqs. 11-13) only shrink, so every limit holds exactly on the cycle grid. The cost is at
   most a few cycles of duration.
3. With the times fixed the peak velocity is linear in the distance (eq. 12), so end
   position and end velocity are exact (to floating point), not approximately hit.

The seed's family starts and ends with zero acceleration and keeps the velocity between
the boundary velocities and the peak. Two extensions make it usable for every request
(:func:`plan` ``allow_reverse``): boundary velocities of either sign, and a peak *below*
both boundary velocities (down to ``-vmax``) when the distance is shorter than the direct
ramp from ``v_start`` to ``v_end`` needs; that profile slows (or turns round, overshoots)
and comes back. Without ``allow_reverse`` a profile that would move against the direction
of the distance is refused with the reason (the CLI's rule: the seed's unsigned speeds).

Sampling is in closed form (:meth:`SCurve.at`, :meth:`SCurve.sample`); the seed's
bilinear (trapezoidal) integration, eqs. 15-17, is :func:`bilinear` - it drifts from the
closed form by O(jmax Ts^2) per phase, which is why the grid samples do not use it.

On the fly (:class:`OnTheFly`, seed 003 §4): a new goal interrupts the running profile;
the new one starts, at the cycle of the goal, from the current position and velocity.
Position and velocity are continuous at every switch; the acceleration is *not* (the
family starts at zero acceleration, as the seed's does), so the acceleration steps at a
switch, each side within its limit - the switch records say by how much.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from lolacli.errors import UsageError

#: the largest magnitude accepted for any input (distances, limits): 1e12 in the user's
#: unit keeps every product of the planner (v^2 / a, a^3 / j^2 ...) finite and exact enough
HUGE = 1e12
#: the smallest magnitude accepted for a limit (vmax, amax, jmax): below it the phase
#: times and their products leave the floating-point range
TINY = 1e-12
#: the most cycles a profile is sampled on (5 arrays of 8-byte numbers each)
MAX_SAMPLES = 2_000_000
_EPS = 1e-9  # cycles: a time within this of a whole cycle is that cycle


def _ramp(dv: float, a: float, j: float) -> tuple[float, float]:
    """(T1, T2) of a velocity change of magnitude ``dv`` with limits ``a``, ``j``."""
    if dv * j >= a * a:
        t1 = a / j
        return t1, dv / a - t1
    return math.sqrt(dv / j), 0.0


def _ramp_time(dv: float, a: float, j: float) -> float:
    if dv * j >= a * a:
        return a / j + dv / a
    return 2.0 * math.sqrt(dv / j)


def _reach(v: float, vs: float, ve: float, a: float, d: float, j: float) -> float:
    """Distance of the two ramps vs -> v -> ve with no cruise (the family at T4 = 0)."""
    return 0.5 * ((vs + v) * _ramp_time(abs(v - vs), a, j)
                  + (v + ve) * _ramp_time(abs(v - ve), d, j))


#: regula-falsi steps in a row that may fail to halve the bracket before one bisects it
_SLOW_STEPS = 3


def _order(x: float) -> int:
    """``x`` as an integer in the order of the doubles (0.0 and -0.0 both 0): the midpoint
    of two of these halves the doubles between them, whatever their magnitudes."""
    bits: int = struct.unpack("<q", struct.pack("<d", x))[0]
    return bits if bits >= 0 else -(bits & 0x7FFF_FFFF_FFFF_FFFF)


def _double(k: int) -> float:
    bits = k if k >= 0 else (-k) | -0x8000_0000_0000_0000
    value: float = struct.unpack("<d", struct.pack("<q", bits))[0]
    return value


def _root(target: float, lo: float, hi: float, vs: float, ve: float, a: float, d: float,
          j: float) -> float:
    """v in [lo, hi] with _reach(v) == target, given _reach(lo) <= target <= _reach(hi)
    (Illinois regula falsi: a handful of evaluations, bracketed so it cannot diverge).

    Safeguarded: after a few steps in a row that do not halve the doubles left in the
    bracket, one does (their midpoint in :func:`_order`), so a root many decades below
    the bracket's width (a tiny distance: v ~ distance^(2/3) on [0, vmax]) is found in
    some 70 steps, not left at the bracket's middle, and the bracket is closed relative
    to the root's own magnitude, not the bracket's first width."""
    flo = _reach(lo, vs, ve, a, d, j) - target
    fhi = _reach(hi, vs, ve, a, d, j) - target
    if flo >= 0.0:
        return lo
    if fhi <= 0.0:
        return hi
    side = slow = 0
    left = _order(hi) - _order(lo)  # doubles in the bracket
    for _ in range(400):
        x = (lo * fhi - hi * flo) / (fhi - flo)
        width = _order(hi) - _order(lo)
        if width <= 1:
            break
        slow = slow + 1 if 2 * width > left else 0
        if not lo < x < hi or slow >= _SLOW_STEPS:  # the last steps did not halve it
            x = _double((_order(lo) + _order(hi)) // 2)
            slow = 0
        left = width
        fx = _reach(x, vs, ve, a, d, j) - target
        if fx == 0.0:
            return x
        if fx < 0.0:
            lo, flo = x, fx
            if side == -1:
                fhi *= 0.5
            side = -1
        else:
            hi, fhi = x, fx
            if side == 1:
                flo *= 0.5
            side = 1
        if hi - lo <= 4e-16 * max(abs(lo), abs(hi)):
            break
    return 0.5 * (lo + hi)


def _check(name: str, value: float, *, positive: bool = False) -> float:
    value = float(value)
    if value != value or math.isinf(value):
        raise UsageError(f"{name} must be a finite number, not {value}")
    if abs(value) > HUGE:
        raise UsageError(f"{name} {value:g} is out of range (at most {HUGE:g} in magnitude)")
    if positive and value <= 0.0:
        raise UsageError(f"{name} must be greater than 0, not {value:g}")
    if positive and value < TINY:
        raise UsageError(f"{name} {value:g} is out of range (at least {TINY:g})")
    return value


@dataclass(frozen=True, slots=True)
class SCurve:
    """A planned profile. Signed: position starts at 0 and ends at ``distance``.

    ``durations`` are the seven phase times T1..T7 (s), ``jerks`` their constant jerks;
    ``p0``, ``v0``, ``a0`` the state at the start of each phase (eight entries, the last
    the end). ``v_peak`` is the cruise velocity (the seed's modified Vmax, eq. 12),
    ``accel`` and ``decel`` the ramps' plateau accelerations (eqs. 11, 13; signed:
    ``decel`` is negative when the second ramp slows down) and ``cruise_limited`` says
    whether the cruise runs at ``vmax`` (the seed's T4 > 0 case before rounding)."""

    distance: float
    v_start: float
    v_end: float
    vmax: float
    amax: float
    dmax: float
    jmax: float
    cycle_s: float | None
    durations: tuple[float, ...]
    jerks: tuple[float, ...]
    v_peak: float
    accel: float
    decel: float
    cruise_limited: bool
    p0: tuple[float, ...] = field(repr=False)
    v0: tuple[float, ...] = field(repr=False)
    a0: tuple[float, ...] = field(repr=False)
    starts: tuple[float, ...] = field(repr=False)

    @property
    def duration(self) -> float:
        return self.starts[7]

    @property
    def cycles(self) -> int | None:
        """Whole cycles of the profile (None without a cycle time)."""
        if self.cycle_s is None:
            return None
        return round(self.duration / self.cycle_s)

    @property
    def end_position(self) -> float:
        return self.p0[7]

    @property
    def end_velocity(self) -> float:
        return self.v0[7]

    def at(self, t: float) -> tuple[float, float, float, float]:
        """(position, velocity, acceleration, jerk) at ``t`` seconds; held at the end
        state after the profile (and at the start before it)."""
        if t <= 0.0:
            return self.p0[0], self.v0[0], self.a0[0], self.jerks[0] if self.duration else 0.0
        if t >= self.starts[7]:
            return self.p0[7], self.v0[7], 0.0, 0.0
        i = 0
        while i < 6 and t >= self.starts[i + 1]:
            i += 1
        dt = t - self.starts[i]
        j, a, v = self.jerks[i], self.a0[i], self.v0[i]
        return (self.p0[i] + dt * (v + dt * (a / 2.0 + dt * j / 6.0)),
                v + dt * (a + dt * j / 2.0), a + dt * j, j)

    def sample(self, cycle_s: float | None = None) -> dict[str, Any]:
        """numpy arrays ``t``, ``position``, ``velocity``, ``acceleration``, ``jerk`` on
        the cycle grid (the profile's own cycle, else ``cycle_s``, else 1000 points), the
        last sample exactly at the end. The jerk of a sample is that of the cycle that
        starts there (the value the drive is commanded with during it)."""
        import numpy as np

        step = self.cycle_s or cycle_s
        if step is None:
            step = self.duration / 1000.0 if self.duration > 0 else 1.0
        n = max(1, math.ceil(self.duration / step - _EPS)) if self.duration > 0 else 0
        if n > MAX_SAMPLES:
            raise UsageError(f"{n:.3g} cycles in the profile: at most {MAX_SAMPLES:,}")
        t = np.minimum(np.arange(n + 1) * step, self.duration)
        starts = np.asarray(self.starts)
        i = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, 6)
        if self.cycle_s is not None:  # phase boundaries are whole cycles: index exactly
            bounds = np.rint(starts / self.cycle_s).astype(np.int64)
            i = np.clip(np.searchsorted(bounds, np.arange(n + 1), side="right") - 1, 0, 6)
        dt = t - starts[i]
        jj, a, v, p = (np.asarray(x)[i] for x in (self.jerks, self.a0, self.v0, self.p0))
        pos = p + dt * (v + dt * (a / 2.0 + dt * jj / 6.0))
        vel = v + dt * (a + dt * jj / 2.0)
        acc = a + dt * jj
        jj = jj.copy()
        pos[-1], vel[-1], acc[-1], jj[-1] = self.p0[7], self.v0[7], 0.0, 0.0
        return {"t": t, "position": pos, "velocity": vel, "acceleration": acc, "jerk": jj}

    def to_dict(self) -> dict[str, Any]:
        """The figures of ``lolacli traj plan --format json`` (schema lolacli.traj/1)."""
        s = self.sample()
        return {
            "duration_s": self.duration,
            "cycles": self.cycles,
            "phases_s": list(self.durations),
            "peak_velocity": self.v_peak,
            "cruise_at_vmax": self.cruise_limited,
            "plateau_acceleration": self.accel,
            "plateau_deceleration": self.decel,
            "jerk": [self.jerks[0], self.jerks[4]],
            "max_velocity": float(abs(s["velocity"]).max()),
            "max_acceleration": float(abs(s["acceleration"]).max()),
            "max_jerk": float(max(abs(x) for x in self.jerks)),
            "end_position": self.end_position + 0.0,  # no -0.0
            "end_velocity": self.end_velocity + 0.0,
        }


def plan(distance: float, vmax: float, amax: float, jmax: float, v_start: float = 0.0,
         v_end: float = 0.0, cycle_s: float | None = None, dmax: float | None = None,
         *, allow_reverse: bool = True) -> SCurve:
    """The S-curve over ``distance`` (signed) from ``v_start`` to ``v_end`` (signed, at
    most ``vmax`` in magnitude) with |v| <= vmax, |a| <= amax in the first ramp and
    <= dmax (default amax) in the second, |j| <= jmax; phase times in whole
    ``cycle_s`` when given. Raises :class:`~lolacli.errors.UsageError` with the reason
    for an input it cannot plan."""
    distance = _check("distance", distance)
    vmax = _check("vmax", vmax, positive=True)
    amax = _check("amax", amax, positive=True)
    jmax = _check("jmax", jmax, positive=True)
    dmax = amax if dmax is None else _check("dmax", dmax, positive=True)
    vs, ve = _check("v_start", v_start), _check("v_end", v_end)
    if cycle_s is not None:
        cycle_s = _check("cycle", cycle_s, positive=True)
    for name, v in (("v_start", vs), ("v_end", ve)):
        if abs(v) > vmax * (1.0 + 1e-12):
            raise UsageError(f"|{name}| {abs(v):g} is above vmax {vmax:g}")
    # mirrored so that the distance is >= 0; undone at the end
    sign = -1.0 if distance < 0.0 or (distance == 0.0 and vs + ve < 0.0) else 1.0
    dist, vs, ve = sign * distance, sign * vs, sign * ve
    vp, t4 = _peak(dist, vs, ve, vmax, amax, dmax, jmax)
    if not allow_reverse and (vp < -1e-12 * vmax or vs < 0.0 or ve < 0.0):
        direct = _reach(vs, vs, ve, amax, dmax, jmax) if vs >= ve else _reach(
            ve, vs, ve, amax, dmax, jmax)
        raise UsageError(
            f"distance {abs(distance):g} is shorter than the {direct:g} that the "
            f"jerk-limited change from v_start {abs(vs):g} to v_end {abs(ve):g} needs "
            "without reversing")
    t1, t2 = _ramp(abs(vp - vs), amax, jmax)
    t5, t6 = _ramp(abs(vp - ve), dmax, jmax)
    if cycle_s is None:
        return _build(dist, vs, ve, vp, (t1, t2, t4, t5, t6), sign, distance, vmax, amax,
                      dmax, jmax, None, t4 > 0.0)
    # eqs. 7-8 rounded up: T1 and Ta = T1 + T2 (so T2 = Ta - T1), each ramp >= 1 cycle.
    # Rounded up, the ramps cover a little more distance, which the re-solved peak takes
    # up; when it cannot within the limits (or only with a long slow cruise), the
    # continuous profile of slightly lower limits is rounded instead: its ramps have room.
    ideal = 2 * (t1 + t5) + t2 + t4 + t6
    found = None
    for slack in (0.0, 0.01, 0.03, 0.1, 0.3):
        if slack:
            lim = 1.0 - slack
            vq, _ = _peak(dist, vs, ve, vmax, amax * lim, dmax * lim, jmax * lim)
            t1, t2 = _ramp(abs(vq - vs), amax * lim, jmax * lim)
            t5, t6 = _ramp(abs(vq - ve), dmax * lim, jmax * lim)
        c1 = max(1, math.ceil(t1 / cycle_s - _EPS))
        ca = max(c1, math.ceil((t1 + t2) / cycle_s - _EPS))
        c5 = max(1, math.ceil(t5 / cycle_s - _EPS))
        cd = max(c5, math.ceil((t5 + t6) / cycle_s - _EPS))
        n = _round(dist, vs, ve, c1, ca, c5, cd, cycle_s, vmax, amax, dmax, jmax)
        if n is not None and (found is None or _cycles(n) < _cycles(found)):
            found = n
        if found is not None and _cycles(found) * cycle_s <= 1.02 * ideal + 8 * cycle_s:
            break
    if found is None:
        raise UsageError("the phase times could not be rounded to whole cycles within the "
                         "limits (a cycle far longer than the move?)")
    vp2, _acc, _dec = _resolve(dist, vs, ve, found, cycle_s)
    times = tuple(k * cycle_s for k in found)
    return _build(dist, vs, ve, vp2, times, sign, distance, vmax, amax, dmax, jmax,
                  cycle_s, t4 > 0.0)


def _cycles(n: list[int]) -> int:
    """Whole cycles of a profile of phase cycles [T1, T2, T4, T5, T6]."""
    return 2 * (n[0] + n[3]) + n[1] + n[2] + n[4]


def _round(dist: float, vs: float, ve: float, c1: int, ca: int, c5: int, cd: int,
           ts: float, vmax: float, amax: float, dmax: float, jmax: float) -> list[int] | None:
    """Whole cycles [T1, T2, T4, T5, T6] near the continuous ones (c1, ca = T1 + T2 of
    the first ramp, c5, cd of the second) that keep every limit, the shortest found.

    Rounded up, the ramps cover a little more distance, which the re-solved peak absorbs;
    that is within the other ramp's reach unless it is tiny (a velocity change of the order
    of jmax Ts^2). Then the neighbouring roundings are tried, and after them ever longer
    ramps, the one with the narrower reach first."""
    def fits(n1: int, na: int, n5: int, nd: int) -> list[int] | None:
        n = [n1, na - n1, 0, n5, nd - n5]
        k = _cruise_cycles(dist, vs, ve, n, ts, vmax, amax, dmax, jmax)
        if k is None:
            return None
        n[2] = k
        return n

    if (first := fits(c1, ca, c5, cd)) is not None:
        return first
    best: list[int] | None = None
    for d1 in (-1, 0, 1):
        for da in (-1, 0, 1, 2):
            for d5 in (-1, 0, 1):
                for dd in (-1, 0, 1, 2):
                    n1, na, n5, nd = c1 + d1, ca + da, c5 + d5, cd + dd
                    if n1 < 1 or n5 < 1 or na < n1 or nd < n5:
                        continue
                    n = fits(n1, na, n5, nd)
                    if n is not None and (best is None or _cycles(n) < _cycles(best)):
                        best = n
    return _grow(dist, vs, ve, c1, ca, c5, cd, ts, vmax, amax, dmax, jmax, best, fits)


def _grow(dist: float, vs: float, ve: float, n1: int, na: int, n5: int, nd: int, ts: float,
          vmax: float, amax: float, dmax: float, jmax: float, best: list[int] | None,
          fits: Callable[[int, int, int, int], list[int] | None]) -> list[int] | None:
    """:func:`_round`'s last resort: ever longer ramps, the one with the narrower reach
    first, until one fits (or is longer than ``best``).

    The candidates are tried in that order, one growth step each, but a run of steps is
    skipped without calling ``fits`` when a bound shows that none of them can fit: over
    the next ``m`` steps each ramp grows by at most ``m`` of its own steps, its reach w
    (monotone in its steps) stays within its values at the two ends, and so do the band
    of peaks [lo, hi] the ramps can meet and the peak velocity the distance asks for with
    no cruise (a cruise only moves it towards 0). When the band misses that range by more
    than the rounding, the whole run is skipped, and the next run tried is twice as long;
    else half as long, down to one step, which is tried. The result is the same as trying
    every step, in a few dozen bounds instead of thousands of ``fits``."""
    def own(n: int, nn: int, a: float, steps: int) -> tuple[int, int]:
        """A ramp's (T1, Ta) cycles after ``steps`` of its own growth steps."""
        lim = a / (jmax * ts) if jmax * ts > 0.0 else math.inf
        q = steps if lim > n + steps + 1 else max(0, min(steps, math.ceil(lim) - n - 1))
        while q > 0 and not jmax * (n + q - 1) * ts < a:
            q -= 1  # the closed form's rounding: as the loop compares
        while q < steps and jmax * (n + q) * ts < a:
            q += 1
        return n + q, nn + 2 * q + (steps - q)

    def hopeless(n1: int, na: int, n5: int, nd: int, m: int) -> bool:
        """Whether no candidate of the next ``m`` steps from (n1, na, n5, nd) fits."""
        e1, ea = own(n1, na, amax, m - 1)
        e5, ed = own(n5, nd, dmax, m - 1)
        w1 = min(amax, jmax * e1 * ts) * ea * ts * (1.0 - 1e-13)  # the largest reaches
        w2 = min(dmax, jmax * e5 * ts) * ed * ts * (1.0 - 1e-13)
        lo = max(-vmax, vs - w1, ve - w2)  # the widest band
        hi = min(vmax, vs + w1, ve + w2)
        a0, a1 = 0.5 * (n1 + na) * ts, 0.5 * (e1 + ea) * ts  # eq. 12's terms
        d0, d1 = 0.5 * (n5 + nd) * ts, 0.5 * (e5 + ed) * ts
        top = dist - min(vs * a0, vs * a1) - min(ve * d0, ve * d1)
        bottom = dist - max(vs * a0, vs * a1) - max(ve * d0, ve * d1)
        up = max(0.0, top / (a0 + d0) if top > 0.0 else top / (a1 + d1))
        down = min(0.0, bottom / (a0 + d0) if bottom < 0.0 else bottom / (a1 + d1))
        margin = 1e-9 * (vmax + abs(up) + abs(down))
        return lo > hi + margin or lo > up + margin or hi < down - margin

    steps = 0
    limit = 100_000 if best is None else 2_000
    run = 1
    while steps < limit:
        if run > 1 and not hopeless(*_next(n1, na, n5, nd, ts, amax, dmax, jmax), run):
            run //= 2
            continue
        # ``run`` candidates from here: all hopeless (run > 1), or the one to try
        stop = math.inf if best is None else _cycles(best)
        for _ in range(min(run, limit - steps)):  # _next, inline: the hot loop
            w1 = min(amax, jmax * n1 * ts) * na
            w2 = min(dmax, jmax * n5 * ts) * nd
            if w1 <= w2:
                n1, na = (n1 + 1, na + 2) if jmax * n1 * ts < amax else (n1, na + 1)
            if w2 <= w1:
                n5, nd = (n5 + 1, nd + 2) if jmax * n5 * ts < dmax else (n5, nd + 1)
            steps += 1
            if n1 + na + n5 + nd >= stop:
                return best  # longer than what is found already
        if run == 1:
            if (n := fits(n1, na, n5, nd)) is not None:
                return n if best is None or _cycles(n) < _cycles(best) else best
            run = 2
        else:
            run *= 2
    return best


def _next(n1: int, na: int, n5: int, nd: int, ts: float, amax: float, dmax: float,
          jmax: float) -> tuple[int, int, int, int]:
    """One growth step of :func:`_grow`: a longer ramp widens the band of peaks it can
    meet; the narrower grows (a tiny velocity change cannot absorb the rounding)."""
    w1 = min(amax, jmax * n1 * ts) * na
    w2 = min(dmax, jmax * n5 * ts) * nd
    if w1 <= w2:
        n1, na = (n1 + 1, na + 2) if jmax * n1 * ts < amax else (n1, na + 1)
    if w2 <= w1:
        n5, nd = (n5 + 1, nd + 2) if jmax * n5 * ts < dmax else (n5, nd + 1)
    return n1, na, n5, nd


def _cruise_cycles(dist: float, vs: float, ve: float, n: list[int], ts: float, vmax: float,
                   amax: float, dmax: float, jmax: float) -> int | None:
    """The fewest whole cruise cycles with which, the ramps' cycles ``n`` fixed, the
    re-solved peak velocity (eq. 12) keeps every limit; None when none does."""
    t1, ta, t5, td = n[0] * ts, (n[0] + n[1]) * ts, n[3] * ts, (n[3] + n[4]) * ts
    w1 = min(amax, jmax * t1) * ta * (1.0 - 1e-13)  # reach of the first ramp
    w2 = min(dmax, jmax * t5) * td * (1.0 - 1e-13)
    lo = max(-vmax, vs - w1, ve - w2)
    hi = min(vmax, vs + w1, ve + w2)
    if lo > hi:
        return None
    half = (n[0] + 0.5 * n[1] + n[3] + 0.5 * n[4]) * ts
    numer = dist - vs * (n[0] + 0.5 * n[1]) * ts - ve * (n[3] + 0.5 * n[4]) * ts
    # peak = numer / (half + n4 ts): from numer / half (n4 = 0) towards 0 as n4 grows
    if numer > 0.0:
        if hi <= 0.0:
            return None
        least = numer / hi - half
        most = math.inf if lo <= 0.0 else numer / lo - half
    elif numer < 0.0:
        if lo >= 0.0:
            return None
        least = numer / lo - half
        most = math.inf if hi >= 0.0 else numer / hi - half
    else:
        return 0 if lo <= 0.0 <= hi else None
    k = max(0, math.ceil(least / ts - _EPS))
    if k * ts > most * (1.0 + 1e-12) + 1e-12 * ts:
        return None
    vp = numer / (half + k * ts)
    return k if lo - 1e-12 * vmax <= vp <= hi + 1e-12 * vmax else None


def _peak(dist: float, vs: float, ve: float, vmax: float, amax: float, dmax: float,
          jmax: float) -> tuple[float, float]:
    """(peak velocity, cruise time) of the fastest profile of the family, dist >= 0."""
    v0 = max(vs, ve, 0.0)  # above it _reach grows with v (see the module's notes)
    if dist >= _reach(v0, vs, ve, amax, dmax, jmax):
        full = _reach(vmax, vs, ve, amax, dmax, jmax)
        if dist >= full:  # T4 > 0: cruise at vmax
            return vmax, (dist - full) / vmax
        # T4 <= 0: the seed's eq. 14 when both ramps reach their plateaus
        alpha = 1.0 / amax + 1.0 / dmax
        beta = amax / jmax + dmax / jmax
        gamma = (amax * vs / jmax + dmax * ve / jmax - vs * vs / amax - ve * ve / dmax
                 - 2.0 * dist)
        disc = beta * beta - 4.0 * alpha * gamma
        if disc >= 0.0:
            v = (-beta + math.sqrt(disc)) / (2.0 * alpha)
            if (v - vs) * jmax >= amax * amax and (v - ve) * jmax >= dmax * dmax:
                return v, 0.0
        return _root(dist, v0, vmax, vs, ve, amax, dmax, jmax), 0.0
    # shorter than the direct ramp between the boundary velocities: the peak goes below
    # both (slow down and speed up again; below zero, a turn and an overshoot)
    lo = min(vs, ve, 0.0)  # below it _reach grows with v as well
    least = _reach(-vmax, vs, ve, amax, dmax, jmax)
    if dist <= least:  # cruise backwards at -vmax
        return -vmax, (dist - least) / -vmax
    if dist <= _reach(lo, vs, ve, amax, dmax, jmax):
        return _root(dist, -vmax, lo, vs, ve, amax, dmax, jmax), 0.0
    return _root(dist, lo, min(vs, ve), vs, ve, amax, dmax, jmax), 0.0


def _resolve(dist: float, vs: float, ve: float, n: list[int],
             ts: float) -> tuple[float, float, float]:
    """Eqs. 11-13 with the phase times fixed: (peak velocity, plateau acceleration of the
    first ramp, of the second), exact for ``dist``."""
    ta, td = (n[0] + n[1]) * ts, (n[3] + n[4]) * ts
    tc = (n[0] + 0.5 * n[1] + n[2] + n[3] + 0.5 * n[4]) * ts
    vp = (dist - vs * (n[0] + 0.5 * n[1]) * ts - ve * (n[3] + 0.5 * n[4]) * ts) / tc
    return vp, (vp - vs) / ta, (ve - vp) / td


def _build(dist: float, vs: float, ve: float, vp: float, times: tuple[float, ...],
           sign: float, distance: float, vmax: float, amax: float, dmax: float,
           jmax: float, cycle_s: float | None, limited: bool) -> SCurve:
    t1, t2, t4, t5, t6 = times
    ta, td = t1 + t2, t5 + t6
    acc = (vp - vs) / ta if ta > 0.0 else 0.0
    dec = (ve - vp) / td if td > 0.0 else 0.0
    j1 = acc / t1 if t1 > 0.0 else 0.0
    j2 = dec / t5 if t5 > 0.0 else 0.0
    durations = (t1, t2, t1, t4, t5, t6, t5)
    jerks = (j1, 0.0, -j1, 0.0, j2, 0.0, -j2)
    p, v, a = 0.0, vs, 0.0
    ps, vs_, as_, starts = [p], [v], [a], [0.0]
    t = 0.0
    for d, j in zip(durations, jerks, strict=True):
        p += d * (v + d * (a / 2.0 + d * j / 6.0))
        v += d * (a + d * j / 2.0)
        a += d * j
        t += d
        ps.append(p)
        vs_.append(v)
        as_.append(a)
        starts.append(t)
    # the closed form's sums land on the end state up to rounding: say it exactly
    ps[7], vs_[7], as_[7] = dist, ve, 0.0
    if cycle_s is not None:
        starts = [round(s / cycle_s) * cycle_s for s in starts]
    return SCurve(
        distance=distance, v_start=sign * vs, v_end=sign * ve, vmax=vmax, amax=amax,
        dmax=dmax, jmax=jmax, cycle_s=cycle_s, durations=durations,
        jerks=tuple(sign * j for j in jerks), v_peak=sign * vp, accel=sign * acc,
        decel=sign * dec, cruise_limited=limited,
        p0=tuple(sign * x for x in ps), v0=tuple(sign * x for x in vs_),
        a0=tuple(sign * x for x in as_), starts=tuple(starts),
    )


def bilinear(profile: SCurve, cycle_s: float | None = None) -> dict[str, Any]:
    """The seed's bilinear integration (eqs. 15-17) of the profile's jerk on the cycle
    grid: a[k] = a[k-1] + Ts/2 (j[k] + j[k-1]), then v and q alike, j[k] the commanded
    jerk of cycle k. Returned as :meth:`SCurve.sample` returns the closed form, to compare
    with it (the trapezoid rule is exact for a's and v's ramps only when the jerk is
    continuous, which at the phase boundaries it is not)."""
    import numpy as np

    grid = profile.sample(cycle_s)
    t, jerk = grid["t"], grid["jerk"]
    ts = float(t[1] - t[0]) if len(t) > 1 else 0.0
    a = np.zeros_like(t)
    v = np.zeros_like(t)
    q = np.zeros_like(t)
    v[0] = profile.v_start
    for k in range(1, len(t)):
        a[k] = a[k - 1] + 0.5 * ts * (jerk[k] + jerk[k - 1])
        v[k] = v[k - 1] + 0.5 * ts * (a[k] + a[k - 1])
        q[k] = q[k - 1] + 0.5 * ts * (v[k] + v[k - 1])
    return {"t": t, "position": q, "velocity": v, "acceleration": a, "jerk": jerk}


@dataclass(frozen=True, slots=True)
class Switch:
    """One re-plan: at ``t`` (s) toward ``goal``, from ``position``/``velocity``; the
    acceleration before and after (the step the family leaves)."""

    t: float
    goal: float
    position: float
    velocity: float
    accel_before: float
    accel_after: float


class OnTheFly:
    """A point-to-point motion kernel fed goals at any time (seed 003 §4): each
    :meth:`goal` interrupts the running profile; the new one starts from the current
    position and velocity toward the goal with ``v_end`` (0: stop there, the seed's
    point-to-point moves). :meth:`step` advances one cycle and returns (t, position,
    velocity, acceleration, jerk) of the new cycle's start."""

    def __init__(self, vmax: float, amax: float, jmax: float, cycle_s: float,
                 position: float = 0.0, dmax: float | None = None) -> None:
        self.vmax, self.amax, self.jmax, self.dmax = vmax, amax, jmax, dmax
        self.cycle_s = _check("cycle", cycle_s, positive=True)
        self.k = 0  # cycles since the start
        self._origin = position  # position where the running profile starts
        self._k0 = 0  # its first cycle
        self._profile: SCurve | None = None
        self.switches: list[Switch] = []

    @property
    def t(self) -> float:
        return self.k * self.cycle_s

    def state(self) -> tuple[float, float, float, float]:
        """(position, velocity, acceleration, jerk) at the current cycle."""
        if self._profile is None:
            return self._origin, 0.0, 0.0, 0.0
        p, v, a, j = self._profile.at((self.k - self._k0) * self.cycle_s)
        return self._origin + p, v, a, j

    def goal(self, target: float, v_end: float = 0.0) -> SCurve:
        """Re-plan from the current cycle's position and velocity to ``target``."""
        p, v, a, _ = self.state()
        v = max(-self.vmax, min(self.vmax, v))
        profile = plan(target - p, self.vmax, self.amax, self.jmax, v, v_end, self.cycle_s,
                       self.dmax)
        self._origin, self._k0, self._profile = p, self.k, profile
        self.switches.append(Switch(self.t, target, p, v, a, 0.0))
        return profile

    def step(self) -> tuple[float, float, float, float, float]:
        self.k += 1
        return (self.t, *self.state())


def stream(goals: list[tuple[float, float]], until_s: float, vmax: float, amax: float,
           jmax: float, cycle_s: float, start: float = 0.0,
           dmax: float | None = None) -> tuple[dict[str, Any], list[Switch]]:
    """Run :class:`OnTheFly` on the cycle grid with ``goals`` as (time s, target) pairs,
    each applied at the first cycle at or after its time, until ``until_s``. Returns the
    cycle samples (numpy arrays as :meth:`SCurve.sample`) and the switches."""
    import numpy as np

    kernel = OnTheFly(vmax, amax, jmax, cycle_s, start, dmax)
    todo = sorted(goals)
    n = math.ceil(until_s / cycle_s - _EPS)
    rows = []
    g = 0
    for _ in range(n + 1):
        while g < len(todo) and todo[g][0] <= kernel.t + _EPS * cycle_s:
            kernel.goal(todo[g][1])
            g += 1
        rows.append((kernel.t, *kernel.state()))
        kernel.k += 1
    arr = np.asarray(rows, dtype=float).reshape(-1, 5)
    names = ("t", "position", "velocity", "acceleration", "jerk")
    return {name: arr[:, i] for i, name in enumerate(names)}, kernel.switches
