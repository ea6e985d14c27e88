"""Timing model: numbers computed by hand from DESIGN.md and the LOLA seed."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lolacli.errors import UsageError
from lolacli.timing.model import (
    DEFAULT_PER_SLAVE_DELAY_NS,
    DelaySource,
    cable_delay_ns,
    calibrate_per_slave_delay_ns,
    estimate,
    frame_bytes,
    max_rate_hz,
    parse_duration_ns,
    predict_total_ns,
    wire_time_ns,
    wire_time_with_overhead_ns,
)


def test_seed_equation_3_846_bytes_is_67_68_us():
    # 8 bit/byte * 846 B / 100 Mbit/s = 67.68 us (the seed rounds to 67.7 us)
    assert wire_time_ns(846) == 67_680


def test_overhead_adds_preamble_sfd_and_gap():
    # (846 + 8 + 12) * 80 ns = 69.28 us
    assert wire_time_with_overhead_ns(846) == 69_280


def test_other_link_rates():
    assert wire_time_ns(846, 1_000_000_000) == 6_768
    assert wire_time_ns(64, 10_000_000) == 51_200
    assert wire_time_ns(1, 3) == 2_666_666_667  # rounded half up


def test_frame_bytes_lola_frame():
    # LRW 780 + ARMW 8 + BRD 2: 14 + 2 + (12+780) + (12+8) + (12+2) + 4 = 846
    assert frame_bytes([780, 8, 2]) == 846
    assert frame_bytes([2]) == 64  # padded to the Ethernet minimum


def test_cable_is_crossed_twice():
    assert cable_delay_ns([1.0] * 25) == 250
    assert cable_delay_ns([10.0, 0.5], ns_per_m=5.0) == 105
    assert cable_delay_ns([]) == 0


def test_calibration_from_the_lola_measurement():
    # (124100 - 67680 - 0) / 25 = 2256.8 -> 2257 ns
    assert calibrate_per_slave_delay_ns(124_100, 67_680, 0, 25) == 2257
    # with 1 m per segment: (124100 - 67680 - 250) / 25 = 2246.8 -> 2247 ns
    assert calibrate_per_slave_delay_ns(124_100, 67_680, 250, 25) == 2247


def test_calibration_refuses_impossible_measurements():
    with pytest.raises(UsageError):
        calibrate_per_slave_delay_ns(60_000, 67_680, 0, 25)
    with pytest.raises(UsageError):
        calibrate_per_slave_delay_ns(124_100, 67_680, 0, 0)


def test_predicted_total_and_rate():
    assert predict_total_ns(67_680, 25, 1000, 250) == 92_930
    assert max_rate_hz(124_100) == pytest.approx(8058.018, abs=1e-3)
    assert max_rate_hz(250_000) > 4000 - 1e-9  # seed: "> 4 kHz" is possible


def test_estimate_lola_with_measurement():
    est = estimate(846, 25, cable_m_per_segment=0.0, measured_total_ns=124_100, budget_ns=500_000)
    assert est.wire_time_ns == 67_680
    assert est.wire_time_with_overhead_ns == 69_280
    assert est.per_slave_delay_source is DelaySource.CALIBRATED
    assert est.per_slave_delay_ns == 2257
    # the prediction stays a priori: never the calibration fed back into itself
    assert est.predicted_total_ns == 67_680 + 25 * DEFAULT_PER_SLAVE_DELAY_NS
    assert est.a_priori_source is DelaySource.ASSUMED
    assert est.calibration_plausible is True  # 2.26 us is within 0.3-3 us
    assert est.total_ns == 124_100
    assert est.within_budget is True
    doc = est.to_dict()
    assert doc["schema"] == "lolacli.timing/1"
    assert doc["wire_time_us"] == 67.68
    assert doc["measured_total_us"] == 124.1
    assert doc["max_rate_hz"] == pytest.approx(8058.018, abs=1e-3)


def test_estimate_without_measurement_uses_the_assumed_delay():
    est = estimate(846, 25)
    assert est.per_slave_delay_source is DelaySource.ASSUMED
    assert est.per_slave_delay_ns == DEFAULT_PER_SLAVE_DELAY_NS
    assert est.measured_total_ns is None and est.calibrated_per_slave_delay_ns is None
    assert est.to_dict()["measured_total_us"] is None
    assert est.within_budget is None


def test_given_delay_wins_but_calibration_is_still_reported():
    est = estimate(
        846, 25, cable_m_per_segment=0, per_slave_delay_ns=500, measured_total_ns=124_100
    )
    assert est.per_slave_delay_source is DelaySource.GIVEN
    assert est.predicted_total_ns == 67_680 + 12_500
    assert est.calibrated_per_slave_delay_ns == 2257


def test_host_latency_is_part_of_the_prediction_and_of_the_calibration():
    # 3 slaves, 64 B (5.12 us on the wire), the minimum round trip of
    # ethercrab__replay-ek1100-el2828-el2889.pcapng (88.647 us): without the host latency
    # the slaves get 27.8 us each, which no ESC does; with 80 us of host latency 1.18 us
    est = estimate(64, 3, cable_m_per_segment=0, measured_total_ns=88_647)
    assert est.calibrated_per_slave_delay_ns == 27_842 and est.calibration_plausible is False
    est = estimate(64, 3, cable_m_per_segment=0, measured_total_ns=88_647,
                   host_latency_ns=80_000)
    assert est.calibrated_per_slave_delay_ns == 1_176 and est.calibration_plausible is True
    assert est.predicted_total_ns == 5_120 + 3 * 1000 + 80_000
    with pytest.raises(UsageError):
        estimate(64, 3, measured_total_ns=50_000, host_latency_ns=80_000)


def test_budget_exceeded():
    assert estimate(846, 25, budget_ns=80_000).within_budget is False


def test_short_frames_are_padded():
    assert estimate(40, 1).frame_bytes == 64


@pytest.mark.parametrize(
    ("text", "ns"),
    [
        ("124.1us", 124_100),
        ("124.1µs", 124_100),
        ("124.1μs", 124_100),
        ("0.1241ms", 124_100),
        ("124100ns", 124_100),
        ("124.1", 124_100),
        (" 124.1 us ", 124_100),
        ("1s", 1_000_000_000),
    ],
)
def test_parse_duration(text, ns):
    assert parse_duration_ns(text) == ns


@pytest.mark.parametrize("text", ["", "us", "fast", "-3us", "12 parsecs", "nan", "inf"])
def test_parse_duration_rejects(text):
    with pytest.raises(UsageError):
        parse_duration_ns(text)


def test_parse_duration_without_a_default_unit_wants_one():
    assert parse_duration_ns("30ms", None) == 30_000_000
    with pytest.raises(UsageError, match="^--timeout '30' has no unit"):
        parse_duration_ns("30", None, "--timeout")


@settings(max_examples=200, deadline=None)
@given(
    n_bytes=st.integers(64, 1514),
    slaves=st.integers(1, 500),
    delay=st.integers(0, 10_000),
    cable_m=st.floats(0, 100),
)
def test_calibration_inverts_prediction(n_bytes, slaves, delay, cable_m):
    est = estimate(n_bytes, slaves, per_slave_delay_ns=delay, cable_m_per_segment=cable_m)
    back = calibrate_per_slave_delay_ns(
        est.predicted_total_ns, est.wire_time_ns, est.cable_delay_ns, slaves
    )
    assert back == delay


# --------------------------------------------------------------------------- bus timing


def test_timing_request_from_numbers_needs_no_file() -> None:
    from lolacli.timing.bus import TimingRequest

    request = TimingRequest(frame_bytes=100, slaves=5)
    assert not request.reads_eni and not request.reads_capture
    timing = request.run()  # no ENI reader, no report: none is asked for
    assert timing.doc["sources"] == {"frame_bytes": "--frame-bytes", "slaves": "--slaves",
                                     "measured": None}
    assert timing.doc["slaves"] == 5 and timing.within_budget is None


def test_timing_request_contradictions_are_usage_errors() -> None:
    from lolacli.timing.bus import TimingRequest

    for options in ({"eni": "a.xml", "slaves": 3}, {"frame_bytes": 100},
                  {"measured": "1us", "capture": "x.pcap"}):
        with pytest.raises(UsageError):
            TimingRequest(**options)  # type: ignore[arg-type]


def test_timing_request_reads_the_eni_after_checking_the_measured_total() -> None:
    from lolacli.timing.bus import TimingRequest

    read: list[str] = []

    def reader():  # type: ignore[no-untyped-def]
        read.append("eni")
        raise AssertionError("not to be read")

    with pytest.raises(UsageError):
        TimingRequest(eni="a.xml", measured="soon").run(reader)
    assert read == []
