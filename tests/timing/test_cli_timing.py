"""`lolacli bus timing` through the CLI: JSON contract, LOLA numbers, exit codes."""

from __future__ import annotations

import json

import pytest

from tests.conftest import corpus_files

CONTRACT_KEYS = {
    "schema", "frame_bytes", "wire_time_us", "wire_time_with_overhead_us", "slaves",
    "link_mbit_s", "per_slave_delay_ns", "predicted_total_us", "measured_total_us",
    "max_rate_hz",
}  # fmt: skip


def run_json(cli, *args):
    code, out, err = cli("bus", "timing", "--format", "json", *args)
    return code, json.loads(out) if out.strip() else None, err


def test_lola_default_reproduces_the_seed(cli):
    code, doc, _ = run_json(cli, "--measured", "124.1us")
    assert code == 0
    assert CONTRACT_KEYS <= set(doc)
    assert doc["schema"] == "lolacli.timing/1"
    assert doc["source"] == "embedded LOLA chain"
    assert (doc["frame_bytes"], doc["slaves"]) == (846, 25)
    assert doc["wire_time_us"] == 67.68
    assert doc["wire_time_with_overhead_us"] == 69.28
    assert doc["measured_total_us"] == 124.1
    assert doc["per_slave_delay_source"] == "calibrated"
    # (124.1 - 67.68 - 25 x 2 x 1 m x 5 ns/m) / 25 = 2.2468 us
    assert doc["per_slave_delay_ns"] == 2247
    assert doc["max_rate_hz"] == pytest.approx(1e6 / 124.1, abs=1e-3)
    assert doc["max_rate_hz"] > 4000  # seed: "> 4 kHz are possible"
    assert doc["budget_us"] == 500.0 and doc["within_budget"] is True


@pytest.mark.parametrize("text", ["124.1us", "124.1µs", "0.1241ms", "124100ns", "124.1"])
def test_measured_spellings(cli, text):
    code, doc, _ = run_json(cli, "--measured", text, "--cable-m", "0")
    assert code == 0 and doc["measured_total_us"] == 124.1 and doc["per_slave_delay_ns"] == 2257


def test_frame_bytes_and_slaves_without_eni(cli):
    code, doc, _ = run_json(cli, "--frame-bytes", "846", "--slaves", "25", "--per-slave-ns", "1000",
                            "--cable-m", "2", "--link-mbit", "100")  # fmt: skip
    assert code == 0
    assert doc["per_slave_delay_source"] == "given"
    assert doc["cable_delay_ns"] == 500
    assert doc["predicted_total_us"] == 67.68 + 25 + 0.5
    assert doc["measured_total_us"] is None and doc["budget_us"] is None


def test_explicit_eni(cli, tmp_path):
    from lolacli.cli.common import default_eni

    code, doc, _ = run_json(cli, "--eni", str(default_eni().with_name("single_drive.xml")))
    assert code == 0
    assert (doc["frame_bytes"], doc["slaves"], doc["budget_us"]) == (64, 1, 1000.0)


def test_budget_exceeded_exits_1(cli):
    code, doc, _ = run_json(cli, "--measured", "124.1us", "--budget-us", "100")
    assert code == 1 and doc["within_budget"] is False


def test_human_output(cli):
    code, out, _ = cli("bus", "timing", "--measured", "124.1us")
    assert code == 0
    assert "67.68 µs" in out and "69.28 µs" in out and "calibrated" in out
    rows = {line[:28].strip(): line[28:].strip().split(None, 2) for line in out.splitlines()[3:]}
    assert rows["frame"][:2] == ["846", "B"] and rows["slaves"][:2] == ["25", "slaves"]
    assert rows["per-slave delay"][:2] == ["1,000", "ns"]
    assert rows["calibrated per-slave delay"][:2] == ["2,247", "ns"]
    assert rows["max update rate (measured)"][:2] == ["8,058", "Hz"]
    assert rows["cycle budget"] == ["500", "µs", "within it"]


@pytest.mark.parametrize(
    "args",
    [
        ("--eni", "x.xml", "--frame-bytes", "846"),
        ("--frame-bytes", "846"),
        ("--slaves", "3"),
        ("--measured", "124.1us", "--capture", "x.pcapng"),
        ("--measured", "soon"),
        ("--measured", "10us"),  # shorter than the wire time: not a round trip
        ("--frame-bytes", "0", "--slaves", "3"),
        ("--link-mbit", "-5"),
    ],
)
def test_bad_arguments_exit_2(cli, args):
    code, out, err = cli("bus", "timing", *args)
    assert code == 2, (out, err)
    assert "Traceback" not in err


def test_bad_eni_exits_3(cli, tmp_path):
    bad = tmp_path / "broken.xml"
    bad.write_text("<EtherCATConfig><Config>")
    code, _, err = cli("bus", "timing", "--eni", str(bad))
    assert code == 3 and err.count("\n") == 1
    code, _, _ = cli("bus", "timing", "--eni", str(tmp_path / "missing.xml"))
    assert code == 3


CYCLIC = [p for p in corpus_files("pcap", "ethercrab__replay-issue-255.pcapng")]


@pytest.mark.parametrize("capture", CYCLIC, ids=[p.name for p in CYCLIC])
def test_capture_gives_the_measured_total(cli, capture):
    from lolacli.capture import analyze_file

    stats = analyze_file(capture).to_dict()["round_trip_cyclic_us"]
    code, doc, _ = run_json(cli, "--capture", str(capture), "--frame-bytes", "64", "--slaves", "3")
    assert code == 0
    assert doc["measured_from"] == f"capture: minimum of {stats['count']} cyclic round trips"
    assert doc["measured_total_us"] == pytest.approx(stats["min"], abs=1e-3)
    code, doc, _ = run_json(cli, "--capture", str(capture), "--statistic", "median")
    assert doc["measured_total_us"] == pytest.approx(stats["median"], abs=1e-3)


def test_capture_without_pairs_exits_3(cli, corpus):
    path = corpus / "pcap" / "ethercrab__soem-sdinfo-no-slaves.pcapng"
    code, _, err = cli("bus", "timing", "--capture", str(path))
    assert code == 3 and "round trip" in err


def test_capture_gives_slaves_and_frame_bytes_with_their_sources(cli, corpus):
    """3 slaves (BRD WKC) and a 77-byte cyclic frame (LRW 3 B + 3 FPRD 2 B) from the
    capture itself; the a-priori prediction keeps the assumed 1000 ns per slave, and the
    calibrated delay (30.7 us: host latency, not slaves) comes with a warning."""
    path = corpus / "pcap" / "ethercrab__replay-issue-255.pcapng"
    code, doc, err = run_json(cli, "--capture", str(path))
    assert code == 0
    assert (doc["slaves"], doc["frame_bytes"]) == (3, 77)
    assert doc["sources"]["slaves"] == "capture: the highest WKC of a BRD/BWR"
    assert doc["sources"]["frame_bytes"].startswith("capture: its longest cyclic frame")
    assert doc["prediction"]["per_slave_delay_ns"] == 1000
    assert doc["predicted_total_us"] == doc["prediction"]["total_us"] == 9.19
    assert doc["measured_total_us"] == 98.233  # the minimum cyclic round trip
    assert doc["calibrated_per_slave_delay_ns"] == 30681
    assert doc["calibration_plausible"] is False and "outside what ESCs do" in err
    assert doc["calibration_warning"] in " ".join(err.split())
    # with the host latency of that host, the slaves get a plausible delay
    code, doc, err = run_json(cli, "--capture", str(path), "--host-latency-us", "88")
    assert doc["calibration_plausible"] is True and doc["calibration_warning"] is None
    assert doc["predicted_total_us"] == 9.19 + 88 and "outside" not in err


def test_measured_total_is_never_shown_as_a_prediction(cli):
    code, doc, _ = run_json(cli, "--measured", "124.1us")
    assert doc["predicted_total_us"] == 92.93  # 67.68 + 25 x 1 us + 0.25 us cable
    assert doc["measured_total_us"] == 124.1 and doc["per_slave_delay_ns"] == 2247
    code, out, _ = cli("bus", "timing", "--measured", "124.1us")
    assert "92.93 µs" in out and "model, a priori" in out


def test_capture_round_trips_shorter_than_the_wire_time_are_bad_input(cli, tmp_path):
    """A veth has no wire time: a 1026-byte LRW 'returns' in 30 us."""
    from lolacli.capture import writer as w
    from lolacli.wire.commands import Command
    from lolacli.wire.frame import Datagram, encode_frame, make_frame

    recs = []
    for i in range(10):
        for ret in (False, True):
            d = Datagram.logical(Command.LRW, 0, 1026, index=i, wkc=3 if ret else 0)
            brd = Datagram.physical(Command.BRD, 1 if ret else 0, 0x130, 2, index=i,
                                    wkc=1 if ret else 0)
            f = encode_frame(make_frame([d, brd], src=b"\x02" * 6 if ret else b"\x00" * 6))
            recs.append(w.pcap_record(10**18 + i * 10**6 + (30_000 if ret else 0), f, ns=True))
    path = tmp_path / "veth.pcap"
    path.write_bytes(w.pcap_header(ns=True) + b"".join(recs))
    code, _, err = cli("bus", "timing", "--capture", str(path))
    assert code == 3 and "shorter than the wire time" in err and "Traceback" not in err
