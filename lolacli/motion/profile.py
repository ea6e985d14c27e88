"""Minimum-jerk point-to-point motion (pure).

The minimum-jerk profile between two rest points (Flash & Hogan 1985): with
``s = t / T`` in 0..1, ``x(s) = x0 + (x1 - x0) (10 s^3 - 15 s^4 + 6 s^5)``. Velocity and
acceleration are zero at both ends and the jerk stays bounded (its peak is
60 (x1 - x0) / T^3 at the start and the end), so a drive following it in cyclic
synchronous position sees no steps. This is the "simpler smooth profile" of
``lolacli bus simulate``; the seed's jerk-limited S-curve with separate velocity,
acceleration and jerk limits is not this module.
"""

from __future__ import annotations


def min_jerk(t_ns: int, duration_ns: int, start: float, end: float) -> float:
    """Position at ``t_ns`` after the start of a ``duration_ns`` move from ``start`` to
    ``end`` (held at the ends outside it)."""
    if duration_ns <= 0 or t_ns >= duration_ns:
        return end
    if t_ns <= 0:
        return start
    s = t_ns / duration_ns
    return start + (end - start) * s * s * s * (10.0 + s * (-15.0 + 6.0 * s))


def back_and_forth(t_ns: int, period_ns: int, amplitude: float) -> float:
    """0 → ``amplitude`` → 0 by two minimum-jerk moves, repeating every ``period_ns``."""
    half = period_ns // 2
    phase = t_ns % period_ns if period_ns > 0 else 0
    if phase < half:
        return min_jerk(phase, half, 0.0, amplitude)
    return min_jerk(phase - half, period_ns - half, amplitude, 0.0)
