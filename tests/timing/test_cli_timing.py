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
