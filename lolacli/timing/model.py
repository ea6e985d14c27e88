"""Frame-time model of one EtherCAT line: wire time, slave delays, cable, round trip (pure).

Definitions (docs/architecture.md "Definitions"):

* **frame bytes** = 14 + 2 + Σ(10 + data + 2) + 4, padded to 64;
* **wire time** = 8 × frame bytes / link rate (846 B at 100 Mbit/s → 67.68 µs, the LOLA
  seed's equation (3));
* **wire time with overhead** adds preamble + SFD (8 B) and the inter-frame gap (12 B)
  (IEEE 802.3 clause 4/24): 866 B → 69.28 µs.

Round trip (the seed's "minimum bus cycle time (total delay)") is modelled as

    predicted_total = wire time + slaves × per-slave delay + cable delay + host latency

The frame is forwarded cut-through, so its serialisation time counts once; every slave adds
its delay (processing on the way out, forwarding on the way back, PHYs on both), and the
cable is crossed twice (out and back; ~5 ns/m for twisted pair, velocity factor ≈ 0.65).

**Per-slave delay, assumed default: 1000 ns** (our assumption, to be replaced by a
calibration). Reasoning: a 100BASE-TX slave passes the frame through its ESC and two PHYs
(receive and transmit) on the way out and through the forwarding path and two PHYs on the
way back; Beckhoff's ESC documentation (Section I, "Frame Processing") describes this
cut-through path with a fixed delay per port. For E-bus slaves (no PHY) the corpus capture
``ethercrab__replay-dc.pcapng`` (frames 506 and 510: DC receive times, register 0x0900)
shows 600 ns between port 0 and port 1 of the EK1100 with two terminals behind it and
310 ns for one, i.e. about 300 ns per E-bus terminal out and back; PHY slaves are slower.
The LOLA measurement (124.1 µs for 25 slaves and 846 B) calibrates to about 2.25 µs per
slave, which also holds the switch and capture latency the seed calls "conservative". Use
:func:`calibrate_per_slave_delay_ns` with a measured total to replace the assumption.

**Host latency** (default 0): what the master's side adds to a round trip measured where
the frame leaves and re-enters the host — network stack, driver, NIC queues and interrupt
moderation, switch, capture path. The bus alone does not need it; a round trip taken from a
host capture does: for the corpus captures (1-3 slaves, where the bus takes 6-10 µs) the
minimum round trip is 40-1100 µs, almost all of it host (``docs/timing-model.md``,
``tools/timing_model_check.py``). Calibrating a per-slave delay from such a round trip
without this term blames the host on the slaves; give the host latency when it is known.

**Prediction and calibration are kept apart.** ``predicted_total`` always uses the a-priori
per-slave delay (the caller's, else the assumed default), never the one calibrated from the
measurement, so a measured total is never shown as a prediction that agrees with itself.
A calibrated per-slave delay outside what ESCs do (:data:`ESC_DELAY_RANGE_NS`) says the
measurement holds something else (host latency, a switch, more slaves than assumed).

**Maximum update rate** = 1 / total round trip (measured when given, else predicted): the
highest cycle rate at which each cycle's frame is back before the next one leaves, with
no master computing time and no acyclic traffic. It is an upper bound, not a recommended
cycle; LOLA runs at 2 kHz while 124.1 µs allows ~8 kHz (the seed: "> 4 kHz possible").

Integer nanoseconds inside; microseconds only in :meth:`TimingEstimate.to_dict`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from enum import StrEnum
from math import isfinite

from lolacli.errors import UsageError
from lolacli.text import number as _number
from lolacli.wire.frame import MIN_FRAME_BYTES, frame_bytes_on_wire

TIMING_SCHEMA = "lolacli.timing/1"

LINK_100_MBIT_S = 100_000_000
PREAMBLE_SFD_BYTES = 8
INTER_FRAME_GAP_BYTES = 12
DEFAULT_PER_SLAVE_DELAY_NS = 1000
#: per-slave delays (out and back) that ESCs show: ~0.3 µs for E-bus terminals, ~1 µs with
#: two PHYs (see the module docstring), up to a few µs for slow or daisy-chained ports
ESC_DELAY_RANGE_NS = (300, 3000)
CABLE_NS_PER_M = 5.0
DEFAULT_CABLE_M = 1.0  # per segment (master→slave 1, slave 1→slave 2, …)
NS_PER_S = 1_000_000_000
#: Durations, rates and byte counts are bounded to int64 (about 292 years in ns), like the
#: capture timestamps; anything larger is a typo, not a bus.
MAX_INT64 = 2**63 - 1
#: Slaves of one segment are addressed by a 16-bit position (ETG.1000.4, ADP).
MAX_SLAVES = 0xFFFF
#: the longest Ethernet frame, FCS included (no VLAN tag: EtherCAT frames carry none)
MAX_FRAME_BYTES = 1518


#: 100BASE-TX allows 100 m per segment (IEEE 802.3 clause 25); EtherCAT's own limit too
MAX_CABLE_M = 100.0

#: Per-slave delay by the physics of the links a slave passes the frame through, in ns for
#: one link's share (the link in on port 0 and the link out to the next slave; the last
#: slave loops back through its port 0, which counts twice). ENI/ESI name no ESC chip
#: (ET1100, ET1200, an FPGA IP core), but they do name each port's physics, and that is
#: what sets the delay: a 100BASE-TX or 100BASE-FX port adds a PHY's receive and transmit
#: latency to the ESC's own, an E-bus (LVDS) port has no PHY (Beckhoff ESC datasheet
#: Section I, "Frame Processing" and "Physical Layer"). The figures:
#:
#: * ``K`` (E-bus) 150 ns a link, 300 ns a slave: measured, the corpus capture
#:   ``ethercrab__replay-dc.pcapng`` (DC receive times 0x0900, frames 506 and 510: about
#:   300 ns out and back per E-bus terminal, see the module docstring);
#: * ``Y`` / ``F`` (PHY) 500 ns a link, 1000 ns a slave: the model's assumed default
#:   (:data:`DEFAULT_PER_SLAVE_DELAY_NS`), so a line of 100BASE-TX slaves predicts what
#:   ``bus timing`` predicts.
#:
#: A link whose physics is unknown takes the default's share. Sub-100 ns effects (the ESC's
#: receive FIFO, clock phase) are below what a round trip taken at a host resolves and are
#: not modelled.
PHYSICS_LINK_DELAY_NS = {"K": 150, "Y": DEFAULT_PER_SLAVE_DELAY_NS // 2,
                         "F": DEFAULT_PER_SLAVE_DELAY_NS // 2}
PHYSICS_SOURCE = (
    "ENI <Info><Physics> per slave: E-bus link 150 ns (corpus ethercrab__replay-dc.pcapng, "
    "DC receive times), 100BASE-TX/FX link 500 ns (the timing model's assumed 1000 ns a "
    "slave); ESC datasheet Section I: PHY ports add PHY latency, E-bus ports none"
)


def physics_delays_ns(physics: Sequence[str]) -> list[int]:
    """Per-slave delay (out and back, ns) of a line whose slaves have these ENI
    ``<Physics>`` strings (see :data:`PHYSICS_LINK_DELAY_NS`): the share of the link in
    (the slave's port 0 letter) plus the share of the link out (the next slave's port 0
    letter; the last slave's own port 0 again)."""
    default = DEFAULT_PER_SLAVE_DELAY_NS // 2

    def link(p: str) -> int:
        return PHYSICS_LINK_DELAY_NS.get(p[:1], default)

    links = [link(p) for p in physics]
    return [
        links[i] + (links[i + 1] if i + 1 < len(links) else links[i])
        for i in range(len(links))
    ]


@dataclass(frozen=True, slots=True)
class HostLatency:
    """The master host's send-plus-receive latency as a distribution: what a round trip
    measured at the host holds beyond the bus (network stack, driver, NIC queue and
    interrupt moderation; a capture path's switch). ``std_ns`` 0: a constant; else a
    log-normal of that mean and standard deviation (positive, with the long right tail
    host latencies have; a normal would give negative latencies at the seed's 31 ± 10 µs
    once in 1000 frames)."""

    mean_ns: int
    std_ns: int = 0

    def to_dict(self, source: str) -> dict[str, object]:
        return {
            "mean": _us(self.mean_ns),
            "std": _us(self.std_ns),
            "distribution": "lognormal" if self.std_ns else "constant",
            "source": source,
        }


#: a host that answers later than the master's frame timeout loses every frame
MAX_HOST_LATENCY_US = 10_000.0

#: The LOLA seed's host figures, derived: its measured 124.1 ± 10.2 µs round trip (seed
#: §VI-B, 10 s, Wireshark on a switch) less the bus this model predicts for the LOLA ENI
#: (67.68 µs wire + 25 × 1000 ns + 25 × 2 × 5 ns = 92.93 µs) leaves 31.2 µs of host,
#: switch and capture path; the 10.2 µs spread is the seed's, all of it taken as host (the
#: bus's own is tens of ns). A residual, not a second measurement: a simulation with it
#: reproduces the seed's figure by construction.
SEED_HOST_LATENCY_US = (31.2, 10.2)


def parse_host_latency(text: str, what: str = "--host-latency-us") -> HostLatency:
    """``MEAN[:STD]`` in µs (``31.2:10.2``, ``25``) -> :class:`HostLatency`; UsageError
    for anything else: negative, not finite, above :data:`MAX_HOST_LATENCY_US`, or a
    spread without a mean."""
    usage = f"{what} {text!r}: expected MEAN[:STD] in µs, e.g. 31.2:10.2"
    parts = text.strip().split(":")
    if len(parts) > 2:
        raise UsageError(usage)
    values = []
    for part in parts:
        try:
            value = Decimal(part.strip())
        except InvalidOperation:
            raise UsageError(usage) from None
        if not value.is_finite() or value < 0:
            raise UsageError(f"{usage} (finite, >= 0)")
        if value > Decimal(MAX_HOST_LATENCY_US):
            raise UsageError(
                f"{usage} (at most {MAX_HOST_LATENCY_US:,.0f} µs: the master's frame timeout)"
            )
        values.append(int((value * 1000).to_integral_value()))
    mean, std = values[0], values[1] if len(values) > 1 else 0
    if std and not mean:
        raise UsageError(f"{usage} (a spread needs a mean above 0)")
    return HostLatency(mean, std)


def parse_cable_m(items: Sequence[str], segments: int,
                  what: str = "--cable-m") -> tuple[float, ...]:
    """Cable length of every segment (1: master to slave 1, K: slave K-1 to slave K) from
    ``M`` (all segments) and ``K=M`` (segment K) items, later items winning; default
    :data:`DEFAULT_CABLE_M`. UsageError for lengths outside 0..:data:`MAX_CABLE_M` m and
    segments the line does not have."""
    lengths = [DEFAULT_CABLE_M] * segments
    for item in items:
        k_text, eq, m_text = item.strip().rpartition("=")
        try:
            m = float(m_text)
            k = int(k_text) if eq else None
        except ValueError:
            raise UsageError(f"{what} {item!r}: expected M or K=M (metres, segment K)") from None
        if not (isfinite(m) and 0 <= m <= MAX_CABLE_M):
            raise UsageError(
                f"{what} {item!r}: a segment is 0 to {MAX_CABLE_M:g} m (100BASE-TX)"
            )
        if k is None:
            lengths = [m] * segments
        elif 1 <= k <= segments:
            lengths[k - 1] = m
        else:
            raise UsageError(
                f"{what} {item!r}: segment {k} of 1..{segments} (1: master to slave 1)"
            )
    return tuple(lengths)


class DelaySource(StrEnum):
    """Where the per-slave delay of an estimate comes from."""

    ASSUMED = "assumed"  # DEFAULT_PER_SLAVE_DELAY_NS
    GIVEN = "given"  # set by the caller
    CALIBRATED = "calibrated"  # from a measured total


def frame_bytes(datagram_data_lengths: Sequence[int]) -> int:
    """Frame bytes on the wire for datagrams of these data lengths (docs/architecture.md)."""
    return frame_bytes_on_wire(tuple(datagram_data_lengths))


def _div_round(numerator: int, denominator: int) -> int:
    """numerator / denominator rounded half up, integers only."""
    return (2 * numerator + denominator) // (2 * denominator)


def wire_time_ns(n_bytes: int, link_bit_s: int = LINK_100_MBIT_S) -> int:
    """8 × bytes / rate, in ns (846 B at 100 Mbit/s → 67 680 ns)."""
    return _div_round(8 * n_bytes * NS_PER_S, link_bit_s)


def wire_time_with_overhead_ns(n_bytes: int, link_bit_s: int = LINK_100_MBIT_S) -> int:
    """Wire time of the frame plus preamble/SFD (8 B) and inter-frame gap (12 B)."""
    return wire_time_ns(n_bytes + PREAMBLE_SFD_BYTES + INTER_FRAME_GAP_BYTES, link_bit_s)


def cable_delay_ns(segment_lengths_m: Sequence[float], ns_per_m: float = CABLE_NS_PER_M) -> int:
    """Round-trip propagation over the cable segments (each crossed out and back)."""
    return round(2 * sum(segment_lengths_m) * ns_per_m)


def predict_total_ns(
    wire_ns: int, slaves: int, per_slave_delay_ns: int, cable_ns: int, host_latency_ns: int = 0
) -> int:
    """Predicted round trip: wire time + slaves × per-slave delay + cable + host latency."""
    return wire_ns + slaves * per_slave_delay_ns + cable_ns + host_latency_ns


def calibrate_per_slave_delay_ns(
    measured_total_ns: int, wire_ns: int, cable_ns: int, slaves: int, host_latency_ns: int = 0
) -> int:
    """(measured − wire − cable − host latency) / slaves, rounded to whole ns.

    Raises :class:`UsageError` when there are no slaves to share the delay, or when the
    measurement is shorter than the frame's own wire time plus cable and host latency (it
    cannot be a round trip of this frame).
    """
    if slaves <= 0:
        raise UsageError("cannot calibrate a per-slave delay without slaves")
    fixed = wire_ns + cable_ns + host_latency_ns
    rest = measured_total_ns - fixed
    if rest < 0:
        raise UsageError(
            f"measured total {_number(measured_total_ns / 1000, 'µs', 2)} is shorter than the "
            f"wire time plus cable{' and host latency' if host_latency_ns else ''} "
            f"({_number(fixed / 1000, 'µs', 2)}): not a round trip of this frame"
        )
    return _div_round(rest, slaves)


def plausible_per_slave_delay(delay_ns: int) -> bool:
    """Whether a (calibrated) per-slave delay is one that ESCs show."""
    lo, hi = ESC_DELAY_RANGE_NS
    return lo <= delay_ns <= hi


def max_rate_hz(total_ns: int) -> float:
    """1 / total round trip in Hz (see the module docstring for what it means)."""
    if total_ns <= 0:
        raise UsageError("a round trip must be longer than 0 ns")
    return NS_PER_S / total_ns


@dataclass(frozen=True, slots=True)
class TimingEstimate:
    """Timing of one cyclic frame through a line of slaves."""

    frame_bytes: int
    slaves: int
    link_bit_s: int
    wire_time_ns: int
    wire_time_with_overhead_ns: int
    cable_m_per_segment: float
    cable_delay_ns: int
    per_slave_delay_ns: int
    per_slave_delay_source: DelaySource
    predicted_total_ns: int
    measured_total_ns: int | None = None
    calibrated_per_slave_delay_ns: int | None = None
    budget_ns: int | None = None
    #: the delay the prediction uses: the caller's, else the assumed default (never the
    #: calibrated one)
    a_priori_per_slave_delay_ns: int = DEFAULT_PER_SLAVE_DELAY_NS
    a_priori_source: DelaySource = DelaySource.ASSUMED
    host_latency_ns: int = 0

    @property
    def calibration_plausible(self) -> bool | None:
        """None without a calibration; else whether ESCs show such a per-slave delay."""
        if self.calibrated_per_slave_delay_ns is None:
            return None
        return plausible_per_slave_delay(self.calibrated_per_slave_delay_ns)

    @property
    def total_ns(self) -> int:
        """The measured total when there is one, else the predicted one."""
        return (
            self.measured_total_ns
            if self.measured_total_ns is not None
            else self.predicted_total_ns
        )

    @property
    def max_rate_hz(self) -> float:
        return max_rate_hz(self.total_ns)

    @property
    def within_budget(self) -> bool | None:
        """None without a budget; else whether the total round trip fits in it."""
        return None if self.budget_ns is None else self.total_ns <= self.budget_ns

    def to_dict(self) -> dict[str, object]:
        """The ``lolacli.timing/1`` document."""
        us = _us
        return {
            "schema": TIMING_SCHEMA,
            "frame_bytes": self.frame_bytes,
            "wire_time_us": us(self.wire_time_ns),
            "wire_time_with_overhead_us": us(self.wire_time_with_overhead_ns),
            "slaves": self.slaves,
            "link_mbit_s": self.link_bit_s / 1_000_000,
            "cable_m_per_segment": self.cable_m_per_segment,
            "cable_delay_ns": self.cable_delay_ns,
            "per_slave_delay_ns": self.per_slave_delay_ns,
            "per_slave_delay_source": self.per_slave_delay_source.value,
            "calibrated_per_slave_delay_ns": self.calibrated_per_slave_delay_ns,
            "calibration_plausible": self.calibration_plausible,
            "esc_delay_range_ns": list(ESC_DELAY_RANGE_NS),
            "host_latency_us": us(self.host_latency_ns),
            # a priori: model defaults or the caller's numbers, never the calibration
            "predicted_total_us": us(self.predicted_total_ns),
            "prediction": {
                "per_slave_delay_ns": self.a_priori_per_slave_delay_ns,
                "per_slave_delay_source": self.a_priori_source.value,
                "host_latency_us": us(self.host_latency_ns),
                "total_us": us(self.predicted_total_ns),
                "max_rate_hz": round(max_rate_hz(self.predicted_total_ns), 3)
                if self.predicted_total_ns > 0 else None,
            },
            "measured_total_us": None
            if self.measured_total_ns is None
            else us(self.measured_total_ns),
            "total_source": "predicted" if self.measured_total_ns is None else "measured",
            "max_rate_hz": round(self.max_rate_hz, 3),
            "budget_us": None if self.budget_ns is None else us(self.budget_ns),
            "within_budget": self.within_budget,
        }


def _us(ns: int) -> float:
    return round(ns / 1000, 3)


def estimate(
    frame_bytes: int,
    slaves: int,
    *,
    link_bit_s: int = LINK_100_MBIT_S,
    cable_m_per_segment: float = DEFAULT_CABLE_M,
    per_slave_delay_ns: int | None = None,
    measured_total_ns: int | None = None,
    budget_ns: int | None = None,
    host_latency_ns: int = 0,
) -> TimingEstimate:
    """Predict (and, with a measured total, calibrate) the round trip of one frame.

    The prediction uses the caller's per-slave delay, else
    :data:`DEFAULT_PER_SLAVE_DELAY_NS`, plus ``host_latency_ns``; a measured total is
    never fed back into it. ``per_slave_delay_ns`` of the result is the caller's, else the
    one calibrated from the measured total, else the default. One cable segment per slave.
    Frames shorter than the Ethernet minimum are padded to 64 bytes, as on the wire.
    """
    if frame_bytes <= 0 or slaves < 0 or link_bit_s <= 0 or not cable_m_per_segment >= 0:
        raise UsageError("frame bytes and link rate must be positive, slaves and cable >= 0")
    _check_bounds(frame_bytes, slaves, link_bit_s, cable_m_per_segment,
                  per_slave_delay_ns, measured_total_ns, budget_ns, host_latency_ns)
    frame_bytes = max(frame_bytes, MIN_FRAME_BYTES)
    wire = wire_time_ns(frame_bytes, link_bit_s)
    cable = cable_delay_ns([cable_m_per_segment] * slaves)
    calibrated = None
    if measured_total_ns is not None:
        calibrated = calibrate_per_slave_delay_ns(measured_total_ns, wire, cable, slaves,
                                                  host_latency_ns)
    if per_slave_delay_ns is not None:
        prior, prior_source = per_slave_delay_ns, DelaySource.GIVEN
    else:
        prior, prior_source = DEFAULT_PER_SLAVE_DELAY_NS, DelaySource.ASSUMED
    if per_slave_delay_ns is None and calibrated is not None:
        delay, source = calibrated, DelaySource.CALIBRATED
    else:
        delay, source = prior, prior_source
    return TimingEstimate(
        frame_bytes=frame_bytes,
        slaves=slaves,
        link_bit_s=link_bit_s,
        wire_time_ns=wire,
        wire_time_with_overhead_ns=wire_time_with_overhead_ns(frame_bytes, link_bit_s),
        cable_m_per_segment=cable_m_per_segment,
        cable_delay_ns=cable,
        per_slave_delay_ns=delay,
        per_slave_delay_source=source,
        predicted_total_ns=predict_total_ns(wire, slaves, prior, cable, host_latency_ns),
        measured_total_ns=measured_total_ns,
        calibrated_per_slave_delay_ns=calibrated,
        budget_ns=budget_ns,
        a_priori_per_slave_delay_ns=prior,
        a_priori_source=prior_source,
        host_latency_ns=host_latency_ns,
    )


def _check_bounds(
    frame_bytes: int,
    slaves: int,
    link_bit_s: int,
    cable_m_per_segment: float,
    *ns_values: int | None,
) -> None:
    """:class:`UsageError` for values no bus has (and that would overflow a float)."""
    if slaves > MAX_SLAVES:
        raise UsageError(f"{slaves} slaves: a segment has at most {MAX_SLAVES}")
    if frame_bytes > MAX_FRAME_BYTES:
        raise UsageError(
            f"{frame_bytes} frame bytes: one Ethernet frame is at most {MAX_FRAME_BYTES} B "
            "with its FCS (64 at least; shorter frames are padded)"
        )
    if max(frame_bytes, link_bit_s) > MAX_INT64:
        raise UsageError(f"frame bytes and link rate must be below {MAX_INT64}")
    if any(v is not None and not 0 <= v <= MAX_INT64 for v in ns_values):
        raise UsageError(f"delays, measured totals and budgets must be 0..{MAX_INT64} ns")
    if not (isfinite(cable_m_per_segment) and 2 * cable_m_per_segment * CABLE_NS_PER_M
            * max(slaves, 1) <= MAX_INT64):
        raise UsageError(f"cable length {cable_m_per_segment:g} m per segment is out of range")


_UNITS_NS = {
    "ns": Decimal(1),
    "us": Decimal(1000),
    "µs": Decimal(1000),
    "μs": Decimal(1000),  # Greek mu as well as the micro sign
    "ms": Decimal(1_000_000),
    "s": Decimal(1_000_000_000),
}


def parse_duration_ns(text: str, default_unit: str | None = "us", what: str = "") -> int:
    """ "124.1us", "124.1µs", "0.1241ms", "124100ns", "124.1" (bare: ``default_unit``,
    µs unless given) → 124100.

    Raises :class:`UsageError` for anything else (negative, empty, unknown unit), and for
    a bare number when ``default_unit`` is None (where a bare number could mean anything);
    ``what`` (an option's name) starts the message.
    """
    lead = f"{what} " if what else ""
    s = text.strip().replace(" ", "")
    unit = next((u for u in sorted(_UNITS_NS, key=len, reverse=True) if s.endswith(u)), "")
    number = s[: len(s) - len(unit)] if unit else s
    if not unit:
        if default_unit is None:
            raise UsageError(f"{lead}{text!r} has no unit: give one (e.g. 5ms, 800us, 2s)")
        unit = default_unit
    try:
        value = Decimal(number) * _UNITS_NS[unit]
    except (InvalidOperation, KeyError):
        raise UsageError(
            f"{lead}not a duration: {text!r} (use e.g. 124.1us, 0.1241ms, 124100ns)"
        ) from None
    if not value.is_finite() or value < 0:
        raise UsageError(f"{lead}not a duration: {text!r} (must be a finite time >= 0)")
    if value > MAX_INT64:
        raise UsageError(f"{lead}not a duration: {text!r} (longer than {MAX_INT64} ns)")
    return int(value.to_integral_value())


__all__ = [
    "CABLE_NS_PER_M",
    "MAX_CABLE_M",
    "MAX_HOST_LATENCY_US",
    "PHYSICS_LINK_DELAY_NS",
    "PHYSICS_SOURCE",
    "SEED_HOST_LATENCY_US",
    "HostLatency",
    "parse_cable_m",
    "parse_host_latency",
    "physics_delays_ns",
    "DEFAULT_CABLE_M",
    "DEFAULT_PER_SLAVE_DELAY_NS",
    "ESC_DELAY_RANGE_NS",
    "INTER_FRAME_GAP_BYTES",
    "LINK_100_MBIT_S",
    "MAX_INT64",
    "MAX_SLAVES",
    "PREAMBLE_SFD_BYTES",
    "TIMING_SCHEMA",
    "DelaySource",
    "TimingEstimate",
    "cable_delay_ns",
    "calibrate_per_slave_delay_ns",
    "estimate",
    "frame_bytes",
    "max_rate_hz",
    "parse_duration_ns",
    "plausible_per_slave_delay",
    "predict_total_ns",
    "wire_time_ns",
    "wire_time_with_overhead_ns",
]
