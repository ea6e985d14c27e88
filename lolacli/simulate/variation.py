"""What makes a simulated round trip other than the formula, each from a stated source.

``bus simulate`` at its defaults runs the timing model's line: every slave 1000 ns
(:data:`~lolacli.timing.model.DEFAULT_PER_SLAVE_DELAY_NS`, assumed), every cable segment
1 m at 5 ns/m, no host: LOLA's 846 B frame comes back after exactly 92.93 µs every cycle,
the prediction of ``bus timing``. Three inputs change that:

* ``forwarding="physics"``: each slave's delay from the physics of its ports (ENI
  ``<Info><Physics>``; E-bus terminals 300 ns, 100BASE-TX slaves 1000 ns:
  :func:`~lolacli.timing.model.physics_delays_ns`, sources in
  :data:`~lolacli.timing.model.PHYSICS_SOURCE`);
* ``cable_m``: the length of every segment, or of segment K (``--cable-m 5``,
  ``--cable-m 3=50``), 5 ns/m (:data:`~lolacli.timing.model.CABLE_NS_PER_M`: twisted pair,
  velocity factor about 0.65);
* ``host_latency``: the master host's send-plus-receive latency, drawn for every frame
  from a log-normal of the given mean and standard deviation
  (:class:`~lolacli.timing.model.HostLatency`) by a generator seeded with the run's seed
  (``--seed``): the same seed, the same round trips. The draws are made in blocks with
  numpy, a list index a frame. Frames come back in the order they left, as a NIC queue
  delivers them: a frame whose draw would overtake the one before waits behind it.

The first two are fixed properties of the line (they move the round trip, not its
spread); the host latency is the variation: with the seed's figures
(:data:`~lolacli.timing.model.SEED_HOST_LATENCY_US`, 31.2 ± 10.2 µs) LOLA's round trip
comes out near the seed's 124.1 ± 10.2 µs. The report says which inputs were used
(:func:`timing_sources`).
"""

from __future__ import annotations

from typing import Any

from lolacli.emulator.line import ChainTiming
from lolacli.eni.model import Eni
from lolacli.errors import UsageError
from lolacli.master.transport import FrameProcessor
from lolacli.timing.model import (
    CABLE_NS_PER_M,
    DEFAULT_CABLE_M,
    DEFAULT_PER_SLAVE_DELAY_NS,
    PHYSICS_SOURCE,
    HostLatency,
    parse_cable_m,
    physics_delays_ns,
)

FORWARDING_MODES = ("model", "physics")
MODEL_SOURCE = (
    f"the timing model's assumed {DEFAULT_PER_SLAVE_DELAY_NS} ns a slave "
    "(lolacli.timing.model, DEFAULT_PER_SLAVE_DELAY_NS)"
)
CABLE_SOURCE = (
    f"{CABLE_NS_PER_M:g} ns/m, twisted pair at a velocity factor of about 0.65 "
    "(lolacli.timing.model, CABLE_NS_PER_M)"
)
HOST_SOURCE = "--host-latency-us"
#: draws made at once (numpy), a list index a frame after that
BLOCK = 8192


def check_forwarding(forwarding: str) -> None:
    if forwarding not in FORWARDING_MODES:
        raise UsageError(
            f"--forwarding {forwarding!r}: expected one of {', '.join(FORWARDING_MODES)}"
        )


def line_timing(eni: Eni, forwarding: str, cable_m: tuple[str, ...]) -> ChainTiming | None:
    """The line of ``eni`` with these inputs; None when they are the timing model's
    defaults (the chain's own default line: exactly the formula)."""
    check_forwarding(forwarding)
    n = len(eni.slaves)
    lengths = parse_cable_m(cable_m, n)
    delays = (
        tuple(physics_delays_ns([s.physics for s in eni.slaves]))
        if forwarding == "physics"
        else None
    )
    cable = (
        None
        if all(m == DEFAULT_CABLE_M for m in lengths)
        else tuple(round(m * CABLE_NS_PER_M) for m in lengths)
    )
    if delays is None and cable is None:
        return None
    return ChainTiming(slave_delays_ns=delays, cable_ns_per_segment=cable)


class HostLatencyLine:
    """``processor`` (the emulated chain) seen from the master's host: every frame that
    comes back comes back ``latency`` later, a seeded draw a frame (module docstring)."""

    def __init__(self, processor: FrameProcessor, latency: HostLatency, seed: int) -> None:
        import numpy as np

        self.processor = processor
        self.latency = latency
        self._rng = np.random.default_rng([seed, 0x4C4F4C41])  # its own stream of the seed
        self._draws: list[int] = []
        self._next = 0
        self._last_back: int | None = None

    def _refill(self) -> list[int]:
        import numpy as np

        mean, std = self.latency.mean_ns, self.latency.std_ns
        if std == 0:
            draws = [mean] * BLOCK
        else:
            # log-normal with this mean and standard deviation
            sigma2 = float(np.log1p((std / mean) ** 2))
            mu = float(np.log(mean)) - sigma2 / 2
            draws = np.rint(self._rng.lognormal(mu, sigma2**0.5, BLOCK)).astype(np.int64).tolist()
        self._draws, self._next = draws, 0
        return draws

    def process(self, frame: bytes, t_ns: int) -> tuple[bytes | None, int]:
        reply, delay_ns = self.processor.process(frame, t_ns)
        if reply is None:
            return reply, delay_ns
        draws, i = self._draws, self._next
        if i >= len(draws):
            draws, i = self._refill(), 0
        self._next = i + 1
        back = t_ns + delay_ns + draws[i]
        last = self._last_back
        if last is not None and back < last:
            back = last  # in order: behind the frame before it in the host's queue
        self._last_back = back
        return reply, back - t_ns


def timing_sources(
    eni: Eni,
    timing: ChainTiming | None,
    forwarding: str,
    cable_m: tuple[str, ...],
    host_latency: HostLatency | None,
) -> dict[str, Any]:
    """The ``timing_sources`` block of the report: which inputs made the round trip, each
    with its source, and what the formula predicts from them (bus alone, and with the
    host's mean)."""
    from lolacli.timing.model import wire_time_ns

    line = timing or ChainTiming()
    n = len(eni.slaves)
    delays = [sum(line.split_ns(i)) for i in range(n)]
    lengths = parse_cable_m(cable_m, n)
    lengths_json: Any = lengths[0] if len(set(lengths)) <= 1 else list(lengths)
    wire = wire_time_ns(eni.cyclic_frames[0].frame_bytes, line.link_bit_s)
    bus = wire + line.bus_delay_ns(n)
    host_mean = host_latency.mean_ns if host_latency is not None else 0
    counts: dict[int, int] = {}
    for d in delays:
        counts[d] = counts.get(d, 0) + 1
    return {
        "forwarding": {
            "mode": forwarding,
            "per_slave_delay_ns": delays,
            "slaves_by_delay_ns": {str(d): c for d, c in sorted(counts.items())},
            "physics": [s.physics or None for s in eni.slaves] if forwarding == "physics"
            else None,
            "source": PHYSICS_SOURCE if forwarding == "physics" else MODEL_SOURCE,
        },
        "cable": {
            "m_per_segment": lengths_json,
            "ns_per_m": CABLE_NS_PER_M,
            "delay_ns": 2 * sum(line.segment_ns(i) for i in range(n)),
            "source": ("--cable-m" if cable_m else f"default {DEFAULT_CABLE_M:g} m a segment")
            + "; " + CABLE_SOURCE,
        },
        "host_latency": host_latency.to_dict(HOST_SOURCE) if host_latency is not None
        else None,
        "wire_time_us": round(wire / 1000, 3),
        "formula_bus_round_trip_us": round(bus / 1000, 3),
        "formula_round_trip_us": round((bus + host_mean) / 1000, 3),
    }


__all__ = [
    "FORWARDING_MODES",
    "HostLatencyLine",
    "check_forwarding",
    "line_timing",
    "timing_sources",
]
