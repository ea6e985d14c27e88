"""The closed loop's frequency response from a chirp, and its bandwidth (pure).

Seed 000 §VI-C, Fig. 10: the hip is driven with a small-amplitude chirp target (10 Hz to
500 Hz, 0.0002 rad) and the transfer function from target to measured position is
estimated, smoothed in the frequency domain. Here both records (θd and θ, every 0.1 ms)
are tapered at their ends and Fourier transformed once; the response in each band of
1/``bands_per_octave`` octave is the cross spectrum over the input's spectrum summed over
the band's bins (H1 = Σ Y X* / Σ |X|², the smoothing), so bins where the chirp put no
energy weigh nothing. The bandwidth is where the gain falls for good below −3 dB
(|H| = 1/√2), interpolated linearly in dB over log frequency between the two bands around it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from lolacli.motion.joint import POSITION_PERIOD_NS, JointParams, run_cascade
from lolacli.motion.targets import BusTiming, Chirp, drive_input, period_times
from lolacli.motion.tracking import Stopped

if TYPE_CHECKING:
    import numpy as np

MINUS_3DB = -20 * math.log10(math.sqrt(2.0))


@dataclass(frozen=True)
class Point:
    freq_hz: float
    gain_db: float
    phase_deg: float


def frequency_response(
    target: np.ndarray,
    actual: np.ndarray,
    sample_s: float,
    low_hz: float,
    high_hz: float,
    bands_per_octave: int = 24,
) -> list[Point]:
    """H(f) = actual / target in log-spaced bands from ``low_hz`` to ``high_hz``; the
    phase unwrapped from the lowest band."""
    import numpy as np

    n = len(target)
    taper = np.ones(n)
    edge = max(1, n // 50)  # 2 % cosine taper at each end
    ramp = 0.5 - 0.5 * np.cos(np.linspace(0.0, math.pi, edge))
    taper[:edge], taper[-edge:] = ramp, ramp[::-1]
    x = np.fft.rfft((target - np.mean(target)) * taper)
    y = np.fft.rfft((actual - np.mean(actual)) * taper)
    freqs = np.fft.rfftfreq(n, sample_s)
    cross, power = y * np.conj(x), np.abs(x) ** 2
    edges = low_hz * 2.0 ** (np.arange(0, 1 + bands_per_octave * math.log2(high_hz / low_hz))
                             / bands_per_octave)
    points, phases, centres = [], [], []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        band = (freqs >= lo) & (freqs < hi)
        if not band.any() or power[band].sum() == 0:
            continue
        h = cross[band].sum() / power[band].sum()
        centres.append(math.sqrt(lo * hi))
        points.append(abs(h))
        phases.append(math.atan2(h.imag, h.real))
    unwrapped: list[float] = np.degrees(np.unwrap(np.array(phases))).tolist() if phases else []
    return [Point(f, 20 * math.log10(g) if g > 0 else -math.inf, float(ph))
            for f, g, ph in zip(centres, points, unwrapped, strict=True)]


def bandwidth_hz(points: list[Point], level_db: float = MINUS_3DB) -> float | None:
    """The frequency above which the gain stays below ``level_db``: its last fall
    through that level (a dip at low frequency, where friction distorts a small chirp,
    is not the bandwidth). None when the gain never falls below it, or is below it from
    the first point."""
    for i in range(len(points) - 2, -1, -1):
        a, b = points[i], points[i + 1]
        if a.gain_db >= level_db > b.gain_db:
            la, lb = math.log(a.freq_hz), math.log(b.freq_hz)
            frac = (a.gain_db - level_db) / (a.gain_db - b.gain_db)
            return math.exp(la + frac * (lb - la))
        if b.gain_db >= level_db:
            return None  # above the level at the top: not reached
    return None


@dataclass(frozen=True)
class Bode:
    chirp: Chirp
    points: list[Point]
    bandwidth_hz: float | None


def chirp_response(
    joint: JointParams,
    chirp: Chirp,
    timing: BusTiming,
    *,
    k_e: float = 0.0,
    velocity_ff: bool = True,
    current_ff: bool = True,
    bands_per_octave: int = 24,
    should_stop: Callable[[], bool] | None = None,
) -> Bode:
    """Drive the joint with ``chirp`` through the bus and estimate the closed loop's
    response from the central control's target to the joint angle, over the chirp's band
    (its lowest and highest ~6 % left out, where the taper acts)."""
    t = period_times(chirp.duration_s)
    target, vel, _ = chirp(t)
    drive = drive_input(joint, chirp, timing, chirp.duration_s, current_ff=current_ff)
    theta = run_cascade(joint, drive, kvel_ff=(1.0 + k_e) if velocity_ff else 0.0,
                        initial=(float(target[0]), float(vel[0])), should_stop=should_stop)
    if len(theta) < len(t):
        raise Stopped
    margin = (chirp.stop_hz / chirp.start_hz) ** 0.06
    points = frequency_response(target, theta, POSITION_PERIOD_NS * 1e-9,
                                chirp.start_hz * margin, chirp.stop_hz / margin,
                                bands_per_octave)
    return Bode(chirp, points, bandwidth_hz(points))


__all__ = ["MINUS_3DB", "Bode", "Point", "bandwidth_hz", "chirp_response",
           "frequency_response"]
