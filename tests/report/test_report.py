"""`lolacli report`: sections present exactly for their inputs, every corpus capture (with
its matching ENI where there is one, and without), a simulation with faults, the
regression gate, bad inputs and a stop leave nothing half-written."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from lolacli.capture.analyze import analyze_file
from lolacli.files import load_eni
from lolacli.report import build_report, write_report
from lolacli.simulate import SimulateOptions, simulate
from tests.conftest import CORPUS, corpus_files, corpus_ids
from tests.test_cli_width import human, overlong

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "lolacli" / "eni_examples"
CAPTURES = corpus_files("pcap")
#: the corpus captures whose chain an ENI of ours describes (EK1100 + digital inputs)
MATCHING_ENI = {
    "ethercrab__twincat-run-ek1100-el1004.pcapng": EXAMPLES / "ek1100_io.xml",
    "DERIVED__ethercrab__twincat-run-ek1100-el1004.classic.pcap": EXAMPLES / "ek1100_io.xml",
    "ethercrab__twincat-scan-boxes.pcapng": EXAMPLES / "ek1100_io.xml",
}
#: a corpus capture with distributed-clock traffic and one without
DC_CAPTURE = CORPUS / "pcap" / "ethercrab__replay-dc.pcapng"
NO_DC_CAPTURE = CORPUS / "pcap" / "ethercrab__replay-issue-255.pcapng"
ALL_SECTIONS = {"verdict", "network", "timing", "bus", "dc", "software", "comparison"}


def needs_corpus() -> None:
    if not CORPUS.is_dir():
        pytest.skip(f"corpus not found at {CORPUS}")


@pytest.fixture(scope="module")
def lola():
    return load_eni()


@pytest.fixture(scope="module")
def simulation(lola):
    return simulate(lola, SimulateOptions(cycles=400))


def ids(report) -> set[str]:
    return {s.id for s in report.sections}


def page_sections(text: str) -> set[str]:
    return set(re.findall(r'<section id="([a-z]+)">', text))


# ---------------------------------------------------------------- sections per input


def test_eni_alone_network_and_model(lola, tmp_path):
    report = build_report(eni=lola)
    assert ids(report) == {"verdict", "network", "timing"}
    timing = report.section("timing")
    rows = {r[0]: r for r in timing.tables[0].rows}
    # the seed's chain: 846 B on the wire take 67.68 µs at 100 Mbit/s
    assert rows["frame"][1] == "846 B" and rows["wire time"][1] == "67.68 µs"
    assert "measured round trip" not in rows
    out = tmp_path / "eni.html"
    write_report(report, out)
    text = out.read_text()
    assert page_sections(text) == {"verdict", "network", "timing"}
    assert "<svg" not in text  # no measurement: no figure
    doc = json.loads((tmp_path / "eni.json").read_text())
    assert doc["schema"] == "lolacli.report/1" and doc["sections"][0] == "verdict"
    assert doc["data"]["network"]["slave_count"] == len(lola.slaves) == 25


def test_simulation_has_every_section_but_comparison(lola, simulation, tmp_path):
    report = build_report(eni=lola, simulation=simulation)
    assert ids(report) == ALL_SECTIONS - {"comparison"}
    rows = {r[0]: r for r in report.section("timing").tables[0].rows}
    doc = simulation.doc
    # the measured total and the rates are the simulation's own, not recomputed
    assert rows["measured round trip"][2] == f"{doc['round_trip_us']['median']:g} µs"
    assert rows["max rate with software"][2] == f"{doc['max_rate_with_software_hz']:,} Hz"
    software = report.section("software").data
    assert software["sections_us"] == doc["sections_us"]
    out = tmp_path / "sim.html"
    write_report(report, out)
    text = out.read_text()
    assert page_sections(text) == ALL_SECTIONS - {"comparison"}
    # round trip histogram, CDF, over time; cycle period; DC; software
    assert text.count("<svg") == 6


def test_untimed_simulation_has_no_software_section(lola):
    untimed = simulate(lola, SimulateOptions(cycles=200, time_sections=False))
    assert "software" not in ids(build_report(eni=lola, simulation=untimed))


def test_dc_section_only_with_dc_traffic():
    needs_corpus()
    with_dc = build_report(captures=[analyze_file(DC_CAPTURE, keep_series=True)])
    without = build_report(captures=[analyze_file(NO_DC_CAPTURE, keep_series=True)])
    assert ids(with_dc) == {"verdict", "timing", "bus", "dc"}
    assert ids(without) == {"verdict", "timing", "bus"}
    dc = analyze_file(DC_CAPTURE).to_dict()["dc"]
    assert with_dc.section("dc").data[DC_CAPTURE.name] == dc


def test_two_captures_side_by_side(tmp_path, cli):
    needs_corpus()
    out = tmp_path / "two.html"
    code, _, err = cli("report", "--capture", DC_CAPTURE, "--capture", NO_DC_CAPTURE,
                       "-o", out)
    assert code == 0, err
    doc = json.loads(out.with_suffix(".json").read_text())
    assert doc["sections"] == ["verdict", "timing", "bus", "dc", "comparison"]
    table = doc["data"]["comparison"]
    for path in (DC_CAPTURE, NO_DC_CAPTURE):
        p50 = analyze_file(path).to_dict()["round_trip_cyclic_us"]["median"]
        assert table[path.name]["round_trip_p50_us"] == p50
    text = out.read_text()
    head = re.search(r'<section id="comparison">.*?<tr>(.*?)</tr>', text, re.S).group(1)
    assert DC_CAPTURE.name in head and NO_DC_CAPTURE.name in head  # one column each


# ---------------------------------------------------------------- every corpus capture


@pytest.mark.parametrize("path", CAPTURES, ids=corpus_ids(CAPTURES))
def test_every_corpus_capture(path, tmp_path, cli):
    eni = MATCHING_ENI.get(path.name)
    runs = [("plain", ())] + ([("eni", ("--eni", eni))] if eni else [])
    for name, extra in runs:
        out = tmp_path / f"{name}.html"
        code, stdout, err = cli("report", "--capture", path, *extra, "-o", out)
        analysis = analyze_file(path, eni=load_eni(eni) if extra else None).to_dict()
        assert code == (1 if analysis["verdict"] == "fail" else 0), err
        doc = json.loads(out.with_suffix(".json").read_text())
        assert doc["verdict"] == analysis["verdict"]
        mine = [{k: v for k, v in f.items() if k not in ("source", "section")}
                for f in doc["findings"] if f["source"] == path.name]
        assert mine == analysis["findings"]
        expected = {"verdict", "bus"} | ({"network"} if extra else set())
        assert expected <= set(doc["sections"]) <= ALL_SECTIONS - {"software", "comparison"}
        text = out.read_text()
        assert page_sections(text) == set(doc["sections"])
        assert out.stat().st_size < 3_000_000
        assert not re.search(r'(src|href)="(?!#|data:)', text)  # nothing to fetch


@pytest.mark.parametrize("name", ["ethercrab__replay-dc.pcapng",
                                  "ethercrab__twincat-run-ek1100-el1004.pcapng"])
def test_markdown_with_pngs_beside(name, tmp_path, cli):
    needs_corpus()
    out = tmp_path / "r.md"
    code, _, err = cli("report", "--capture", CORPUS / "pcap" / name, "-o", out,
                       "--format", "md")
    assert code == 0, err
    text = out.read_text()
    images = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    assert images and all((tmp_path / i).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
                          for i in images)
    doc = json.loads((tmp_path / "r.json").read_text())
    for section in doc["sections"]:
        assert f'<a id="{section}"></a>' in text


# ---------------------------------------------------------------- faults, width


def test_faults_show_in_verdict_and_findings(tmp_path):
    out = tmp_path / "faults.html"
    code, stdout = human("report", "--simulate", "--duration", "0.5s", "--drop-p", "0.02",
                         "--stuck-safeop", "3", "-o", out)
    assert code == 1
    doc = json.loads(out.with_suffix(".json").read_text())
    assert doc["verdict"] == "fail"
    kinds = {f["kind"]: f for f in doc["findings"]}
    assert kinds["refused"]["slave"] == 3 and kinds["refused"]["severity"] == "failure"
    assert kinds["lost"]["count"] == doc["headline"]["simulation"]["lost_frames"] > 0
    assert {kinds["lost"]["section"], kinds["refused"]["section"]} == {"bus"}
    text = out.read_text()
    verdict = re.search(r'<section id="verdict">(.*?)</section>', text, re.S).group(1)
    assert "FAIL" in verdict and "refused SAFEOP to OP" in verdict
    assert 'href="#bus"' in verdict
    assert "refused" in stdout and "lost" in stdout
    assert not overlong(stdout)


# ---------------------------------------------------------------- the regression gate


def test_gate_names_the_figures_that_got_worse(tmp_path, cli):
    base = tmp_path / "base.html"
    assert cli("report", "--simulate", "--duration", "1s", "-o", base)[0] == 0
    baseline = base.with_suffix(".json")
    again = tmp_path / "again.html"
    code, _, err = cli("report", "--simulate", "--duration", "1s", "-o", again,
                       "--baseline", baseline)
    assert code == 0, err
    doc = json.loads(again.with_suffix(".json").read_text())
    assert doc["regressions"] == [] and doc["gate"]["compared"]
    worse = tmp_path / "worse.html"
    code, out, _ = cli("report", "--simulate", "--duration", "1s", "--drop-p", "0.02",
                       "-o", worse, "--baseline", baseline, "--tolerance", "10%")
    assert code == 1
    doc = json.loads(worse.with_suffix(".json").read_text())
    assert [r["figure"] for r in doc["regressions"]] == ["simulation: lost frames"]
    assert doc["regressions"][0]["baseline"] == 0 and doc["regressions"][0]["value"] > 0
    assert "simulation: lost frames got worse" in out


def test_gate_names_a_slower_host(tmp_path, cli):
    """The seed's host latency as the baseline, then a host twice as slow: the round trip
    figures are named, the frame counts are not; the same host again passes."""
    base = tmp_path / "base.html"
    seed_host = ("--host-latency-us", "31.2:10.2")
    assert cli("report", "--simulate", "--duration", "1s", *seed_host, "-o", base)[0] == 0
    baseline = base.with_suffix(".json")
    again = tmp_path / "again.html"
    code, _, err = cli("report", "--simulate", "--duration", "1s", *seed_host, "-o", again,
                       "--baseline", baseline)
    assert code == 0, err
    worse = tmp_path / "worse.html"
    code, out, _ = cli("report", "--simulate", "--duration", "1s", "--host-latency-us",
                       "62.4:10.2", "-o", worse, "--baseline", baseline)
    assert code == 1
    named = {r["figure"] for r in json.loads(worse.with_suffix(".json").read_text())[
        "regressions"]}
    assert {"simulation: round trip p50", "simulation: round trip p99"} <= named
    assert "simulation: lost frames" not in named
    assert "simulation: round trip p50 got worse" in " ".join(out.split())


def test_gate_direction_and_tolerance(lola, simulation):
    now = build_report(eni=lola, simulation=simulation).to_dict()["headline"]["simulation"]
    base = {"schema": "lolacli.report/1", "headline": {"simulation": dict(now)}}
    fig = base["headline"]["simulation"]
    fig["round_trip_p99_us"] = now["round_trip_p99_us"] / 1.2  # now 20 % slower: worse
    fig["round_trip_p50_us"] = now["round_trip_p50_us"] / 1.05  # 5 %: within 10 %
    fig["max_rate_hz"] = now["max_rate_hz"] * 1.5  # the rate fell: worse
    fig["cycle_jitter_us"] = 1000.0  # jitter fell: better, never a regression
    report = build_report(eni=lola, simulation=simulation, baseline=base,
                          tolerance_percent=10.0)
    assert {r["figure"] for r in report.regressions} == {
        "simulation: round trip p99", "simulation: max rate, round trip only"}
    assert report.verdict == "fail"
    loose = build_report(eni=lola, simulation=simulation, baseline=base,
                         tolerance_percent=60.0)
    assert loose.regressions == [] and loose.verdict == "pass"


# ---------------------------------------------------------------- bad inputs


def _left_behind(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def test_bad_inputs_one_line_nothing_written(tmp_path, cli):
    not_capture = tmp_path / "in" / "notes.pcap"
    not_capture.parent.mkdir()
    not_capture.write_text("not a capture\n")
    bad_eni = tmp_path / "in" / "bad.xml"
    bad_eni.write_text("<EtherCATConfig><Config>\n")
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    out = out_dir / "r.html"
    cases = [
        (("--capture", not_capture), out, 3, "not a pcap/pcapng capture"),
        (("--eni", bad_eni), out, 3, "bad.xml"),
        (("--simulate", "--duration", "10ms"), tmp_path / "missing" / "r.html", 3,
         "no such folder"),
        (("--simulate", "--duration", "10ms"), not_capture / "r.html", 3, "no such folder"),
        (("--simulate", "--duration", "10ms"), out_dir, 2, "is a directory"),
        (("--simulate", "--duration", "10ms", "--baseline", bad_eni), out, 3, "not JSON"),
        (("--simulate", "--duration", "10ms", "--tolerance", "ten"), out, 2, "--tolerance"),
        ((), out, 2, "nothing to report"),
    ]
    for args, target, expected, says in cases:
        code, _, err = cli("report", *args, "-o", target)
        assert code == expected, (args, err)
        assert len(err.strip().splitlines()) == 1 and says in err, (args, err)
        assert "Traceback" not in err
        assert _left_behind(out_dir) == [], args


def test_an_output_over_an_input_is_refused(tmp_path, cli, corpus):
    """The page or its JSON would replace an input (a capture, an earlier report's JSON
    given as --baseline) or a FIFO: exit 2, one line, before any work; nothing changed."""
    capture = tmp_path / "c.pcapng"
    capture.write_bytes((corpus / "pcap" / "ethercrab__replay-issue-49.pcapng").read_bytes())
    baseline = tmp_path / "r.json"
    baseline.write_text("{}\n")
    os.mkfifo(tmp_path / "fifo")
    cases = [
        (("--capture", capture), tmp_path / "c.pcapng", "-o", "same file as --capture"),
        (("--capture", capture, "--baseline", baseline), tmp_path / "r.html",
         "-o (its JSON)", "same file as --baseline"),
        (("--capture", capture), tmp_path / "fifo", "-o", "is a FIFO"),
    ]
    for args, target, option, says in cases:
        code, out, err = cli("report", *args, "-o", target)
        assert code == 2, (args, err)
        assert len(err.strip().splitlines()) == 1 and option in err and says in err, err
        assert capture.read_bytes()[:4] == b"\x0a\x0d\x0d\x0a" and baseline.read_text() == "{}\n"
        assert _left_behind(tmp_path) == ["c.pcapng", "fifo", "r.json"], args


@pytest.mark.parametrize("fmt", ["html", "md"])
def test_a_page_named_as_its_json_is_refused(tmp_path, cli, corpus, fmt):
    """-o x.json: the page and its JSON would be one file (the JSON written over the
    page, "wrote x.json" said twice): exit 2, one line naming -o, nothing written."""
    capture = corpus / "pcap" / "ethercrab__replay-issue-49.pcapng"
    code, out, err = cli("report", "--capture", capture, "-f", fmt, "-o", tmp_path / "x.json")
    assert code == 2, err
    assert len(err.strip().splitlines()) == 1 and "-o" in err and ".html" in err
    assert "wrote" not in out and _left_behind(tmp_path) == []


def test_the_library_refuses_a_page_named_as_its_json(tmp_path):
    from lolacli.errors import UsageError
    from lolacli.report import check_output

    with pytest.raises(UsageError, match="same file"):
        check_output(tmp_path / "x.json")
    check_output(tmp_path / "x.html")


def test_unwritable_output_leaves_nothing(tmp_path):
    """A folder the report cannot be written into (read-only for a user; /proc even for
    root): exit 3 after the work, and no temporary file left."""
    code, _ = human("report", "--simulate", "--duration", "10ms", "-o", "/proc/r.html")
    assert code == 3
    assert not [p for p in Path("/proc").glob(".r.*")]


def test_stop_exits_130_and_writes_nothing(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT), "COLUMNS": "80"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "lolacli", "report", "--simulate", "--duration", "120s",
         "-o", str(tmp_path / "r.html")], env=env, stderr=subprocess.PIPE, text=True)
    time.sleep(2.0)  # inside the simulation
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert _left_behind(tmp_path) == []


def test_the_page_of_a_10_s_simulation_stays_under_3_mb(lola, tmp_path):
    """The page of `report --simulate` at its defaults (10 s at 2 kHz): under 3 MB. What it
    costs against the simulation alone is measured by benchmarks/report_cost.py."""
    result = simulate(lola, SimulateOptions(rate_hz=2000.0, cycles=20_000))
    written = write_report(build_report(eni=lola, simulation=result), tmp_path / "r.html")
    assert written[0].stat().st_size < 3_000_000
