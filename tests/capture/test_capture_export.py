"""`capture export --mcap` (lolacli.capture.export) and the channels it shares with
`bus simulate --mcap` (lolacli.capture.mcap_channels): every corpus capture exports and
reads back in the mcap reader (CRCs checked) with the analysis's counts and figures, and
Wireshark's frame count (capinfos); the schemas are JSON Schema documents; the simulation writes the
same topics with the same schemas; bad inputs and Ctrl-C leave nothing behind."""

from __future__ import annotations

import base64
import collections
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import corpus_files, corpus_ids
from mcap.reader import make_reader

from lolacli.capture.analyze import analyze_file
from lolacli.capture.export import SCHEMA, Stopped, export_mcap
from lolacli.capture.mcap_channels import CYCLE, DC, FRAMES, SCHEMAS
from lolacli.capture.reader import CaptureReader

ROOT = Path(__file__).resolve().parents[2]
CAPTURES = corpus_files("pcap")


def run(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "lolacli", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout,
                          env={**os.environ, "COLUMNS": "80"})


def read_mcap(path: Path) -> tuple[dict[str, Any], dict[str, list[Any]]]:
    """(topic -> (schema name, encoding, schema bytes), topic -> [(log_time, message)])."""
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None
        schemas = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
        for c in summary.channels.values():
            assert c.message_encoding == "json"
        messages: dict[str, list[Any]] = collections.defaultdict(list)
        for _, channel, message in reader.iter_messages(log_time_order=False):
            assert message.log_time == message.publish_time
            messages[channel.topic].append((message.log_time, json.loads(message.data)))
        counts = {summary.channels[c].topic: n
                  for c, n in summary.statistics.channel_message_counts.items()}
    for topic, got in messages.items():
        assert counts[topic] == len(got)
    return schemas, messages


def valid_json_schema(data: bytes) -> dict[str, Any]:
    doc = json.loads(data)
    import jsonschema

    jsonschema.validators.validator_for(doc).check_schema(doc)
    return doc


def wireshark_frame_count(path: Path) -> int:
    """The packets of the file by Wireshark's capinfos (its reader, without dissecting)."""
    out = subprocess.run(["capinfos", "-c", "-M", str(path)], capture_output=True,
                         text=True, timeout=60, check=True).stdout
    return int(out.split("Number of packets:")[1].split()[0])


@pytest.mark.parametrize("path", CAPTURES, ids=corpus_ids(CAPTURES))
def test_every_corpus_capture_exports_and_reads_back(path: Path, tmp_path: Path) -> None:
    report = analyze_file(path, keep_series=True)
    out = tmp_path / "out.mcap"
    result = export_mcap(report, out)
    doc = result.to_dict()
    assert doc["schema"] == SCHEMA and doc["mcap"] == str(out)
    assert doc["bytes"] == out.stat().st_size > 0
    assert os.listdir(tmp_path) == ["out.mcap"]  # no temporary file left
    schemas, messages = read_mcap(out)
    assert set(schemas) == {FRAMES, CYCLE, DC}
    for topic, schema in schemas.items():
        assert schema.encoding == "jsonschema" and schema.name == SCHEMAS[topic]["title"]
        assert valid_json_schema(schema.data) == SCHEMAS[topic]
    counts = {c["topic"]: c["messages"] for c in doc["channels"]}
    assert counts == {t: len(messages.get(t, [])) for t in (FRAMES, CYCLE, DC)}

    # /frames: every frame of the file, its bytes and timestamp
    frames = list(CaptureReader(path))
    assert doc["frames"] == len(frames) == counts[FRAMES] == report.counts["frames_total"]
    if shutil.which("capinfos"):
        assert counts[FRAMES] == wireshark_frame_count(path)
    for frame, (at, m) in zip(frames, messages[FRAMES], strict=True):
        assert m["frame"] == frame.number and at == m["t_ns"] == frame.timestamp_ns
        assert base64.b64decode(m["data"]) == frame.data
        assert m["length"] == frame.original_length

    # /cycle: one per answered cyclic frame, the analysis's round trips and periods
    cycles = [m for _, m in messages[CYCLE]]
    assert len(cycles) == report.counts["cyclic_pairs"]
    assert [m["cycle"] for m in cycles] == list(range(len(cycles)))
    stats = report.round_trip_cyclic_stats
    if cycles:
        assert stats is not None
        rts = np.array([m["round_trip_ns"] for m in cycles])
        assert float(np.median(rts)) == stats.median
        assert (int(rts.min()), int(rts.max())) == (stats.min, stats.max)
    else:
        assert stats is None
    periods = sorted(m["period_ns"] for m in cycles[1:])
    assert cycles[0]["period_ns"] is None if cycles else True
    if report.to_dict()["cyclic_unmatched"] == 0:
        assert report.cycle_period_ns is not None
        assert periods == sorted(report.cycle_period_ns.tolist())
    # WKC: the returned frame of each, as the analysis's WKC observations count them
    assert all(m["wkc"] is not None for m in cycles)
    observed: collections.Counter[int] = collections.Counter()
    for d in report.wkc_verdict.datagrams:
        for o in d.observed:
            observed[o.wkc] += o.count
    assert collections.Counter(w for m in cycles for w in m["wkc"]) == observed

    # /dc: every answered read of the system time difference
    dc = report.dc
    errors = [m["error_ns"] for _, m in messages.get(DC, [])]
    assert len(errors) == dc["system_time_difference_reads"]
    if errors:
        assert max(abs(e) for e in errors) == dc["system_time_difference_max_abs_ns"]
        assert errors[-1] == dc["system_time_difference_last_ns"]


def test_simulate_writes_the_same_topics_and_schemas(tmp_path: Path) -> None:
    pcap, mcap = tmp_path / "s.pcapng", tmp_path / "s.mcap"
    sim = run("bus", "simulate", "--cycles", "200", "--pcap", str(pcap), "--mcap", str(mcap),
              "--format", "json")
    assert sim.returncode == 0, sim.stderr
    doc = json.loads(sim.stdout)
    schemas, messages = read_mcap(mcap)
    assert {FRAMES, CYCLE, DC} <= set(schemas)
    for topic, schema in schemas.items():
        assert schema.encoding == "jsonschema"
        assert valid_json_schema(schema.data) == SCHEMAS[topic]
    # one /frames message per frame the pcapng holds, numbered as in it
    frames = list(CaptureReader(pcap))
    assert len(messages[FRAMES]) == len(frames) == doc["pcap"]["frames"]
    for frame, (_, m) in zip(frames, messages[FRAMES], strict=True):
        assert base64.b64decode(m["data"]) == frame.data and m["frame"] == frame.number
    assert doc["mcap"]["messages"] == sum(len(v) for v in messages.values())
    assert doc["mcap"]["channels"] == {t: len(messages.get(t, [])) for t in SCHEMAS}
    # the figures Foxglove plots: round trip and period of each cycle
    cycles = [m for _, m in messages[CYCLE]]
    assert len(cycles) == doc["cycles"] + doc["startup_cycles"]
    periods = [m["period_ns"] for m in cycles[doc["startup_cycles"] + 1:]]
    assert periods and np.median(periods) == pytest.approx(1e9 / doc["rate_hz"], rel=0.01)
    assert all(m["round_trip_ns"] for m in cycles[-doc["cycles"]:])


def test_cli_json_and_human(tmp_path: Path) -> None:
    path = CAPTURES[0] if CAPTURES else pytest.skip("no corpus")
    out = tmp_path / "a.mcap"
    got = run("capture", "export", str(path), "--mcap", str(out), "--format", "json")
    assert got.returncode == 0, got.stderr
    doc = json.loads(got.stdout)
    assert doc["schema"] == SCHEMA and doc["mcap"] == str(out) and doc["verdict"] == "pass"
    assert doc["bytes"] == out.stat().st_size and doc["frames"] > 0
    assert doc["messages"] == sum(c["messages"] for c in doc["channels"])
    human = run("capture", "export", str(path), "--mcap", str(out))
    assert human.returncode == 0, human.stderr
    lines = human.stdout.splitlines()
    size = f"{doc['bytes'] / 1e3:,.1f}".rstrip("0").rstrip(".") + " kB"  # (a small file)
    assert " ".join(human.stdout.split()).startswith(
        f"wrote {out}: {doc['frames']:,} frames, 3 channels, {size} /frames")
    assert all(len(line) <= 80 for line in lines)


def test_a_capture_piped_in_exports_as_the_file_does(tmp_path: Path) -> None:
    """A pipe is read once (the analysis and the export each read the capture): the same
    channels and counts as from the file, named as given."""
    path = CAPTURES[0] if CAPTURES else pytest.skip("no corpus")
    from_file = run("capture", "export", str(path), "--mcap", str(tmp_path / "f.mcap"),
                    "--format", "json")
    with open(path, "rb") as f:
        piped = subprocess.run(
            [sys.executable, "-m", "lolacli", "capture", "export", "/dev/stdin", "--mcap",
             str(tmp_path / "p.mcap"), "--format", "json"],
            cwd=ROOT, stdin=f, capture_output=True, text=True, timeout=120)  # fmt: skip
    assert piped.returncode == 0, piped.stderr
    a, b = json.loads(from_file.stdout), json.loads(piped.stdout)
    assert b["capture"] == "/dev/stdin"
    assert (b["frames"], b["channels"]) == (a["frames"], a["channels"])


def test_a_truncated_capture_exports_what_it_holds_with_the_findings(tmp_path: Path) -> None:
    source = next((p for p in CAPTURES if p.name == "ethercrab__replay-dc.pcapng"), None)
    if source is None:
        pytest.skip("ethercrab__replay-dc.pcapng not in the corpus")
    cut = tmp_path / "cut.pcapng"
    cut.write_bytes(source.read_bytes()[: source.stat().st_size // 2 + 3])
    analyzed = analyze_file(cut).to_dict()  # what `capture analyze` reports
    got = run("capture", "export", str(cut), "--mcap", str(tmp_path / "c.mcap"),
              "--format", "json")
    doc = json.loads(got.stdout)
    assert doc["findings"] == analyzed["findings"]
    assert any(f["kind"] == "cut-short" for f in doc["findings"])
    assert got.returncode == (1 if analyzed["verdict"] == "fail" else 0)
    _, messages = read_mcap(tmp_path / "c.mcap")
    assert len(messages[FRAMES]) == analyzed["frames_total"] == len(list(CaptureReader(cut)))


@pytest.mark.parametrize(
    ("make", "target", "code", "text"),
    [
        (lambda d: d / "x.pcapng", "ok", 3, "No such file"),
        (lambda d: _write(d / "x.pcap", b"not a capture at all\n"), "ok", 3, "not a pcap"),
        (lambda d: _write(d / "x.pcapng", b"\x0a\x0d\x0d\x0a\x1c"), "ok", 3, "truncated"),
        (None, "missing-dir", 3, "cannot write"),
        (None, "a-dir", 2, "is a directory"),
        (None, "under-a-file", 3, "cannot write"),
    ],
)
def test_bad_inputs_one_line_nothing_left(tmp_path: Path, make: Any, target: str, code: int,
                                          text: str) -> None:
    folder = tmp_path / "out"
    folder.mkdir()
    capture = make(tmp_path) if make is not None else CAPTURES[0]
    out = {"ok": folder / "o.mcap", "missing-dir": folder / "no" / "o.mcap",
           "a-dir": folder, "under-a-file": tmp_path / "file" / "o.mcap"}[target]
    (tmp_path / "file").write_text("a file, not a folder\n")
    got = run("capture", "export", str(capture), "--mcap", str(out))
    assert got.returncode == code
    assert got.stderr.count("\n") == 1 and text in got.stderr and "Traceback" not in got.stderr
    assert got.stdout == ""
    assert [p for p in folder.rglob("*") if p.is_file()] == []


@pytest.mark.parametrize(
    ("target", "says"),
    [
        ("in.pcapng", "is the same file as the capture"),
        ("./sub/../in.pcapng", "is the same file as the capture"),
        ("link.pcapng", "is the same file as the capture"),
        ("fifo", "is a FIFO"),
        ("sub", "is a directory"),
        ("", "no file name given"),
    ],
)
def test_an_output_that_is_the_input_or_no_file_is_refused(cli, tmp_path: Path, target: str,
                                                           says: str) -> None:
    """The MCAP is written under a temporary name and renamed over its target: a target
    that is the capture itself (any spelling, a link) or no regular file (a FIFO, a
    folder; a device too, not tried here: without the check, root would replace it) is
    refused, exit 2, one line, before anything is read or written;
    the capture and the FIFO are left as they were."""
    if not CAPTURES:
        pytest.skip("no corpus captures")
    capture = tmp_path / "in.pcapng"
    capture.write_bytes(CAPTURES[0].read_bytes())
    (tmp_path / "link.pcapng").symlink_to("in.pcapng")
    (tmp_path / "sub").mkdir()
    os.mkfifo(tmp_path / "fifo")
    before = capture.read_bytes()
    cwd = Path.cwd()
    os.chdir(tmp_path)
    try:
        code, out, err = cli("capture", "export", "in.pcapng", "--mcap", target)
    finally:
        os.chdir(cwd)
    assert code == 2, err
    assert err.count("\n") == 1 and says in err and "--mcap" in err
    assert out == ""
    assert capture.read_bytes() == before
    assert (tmp_path / "fifo").is_fifo()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fifo", "in.pcapng", "link.pcapng",
                                                          "sub"]
    assert list((tmp_path / "sub").iterdir()) == []


def _write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def test_a_stop_leaves_nothing(tmp_path: Path) -> None:
    """The library: a stop during the export raises Stopped, no file and no temporary
    file left; the target that was there before stays as it was."""
    path = max(CAPTURES, key=lambda p: p.stat().st_size) if CAPTURES else pytest.skip()
    report = analyze_file(path)
    out = tmp_path / "o.mcap"
    out.write_bytes(b"before")
    polls = [0]

    def stop() -> bool:
        polls[0] += 1
        return polls[0] > 2

    with pytest.raises(Stopped):
        export_mcap(report, out, should_stop=stop)
    assert os.listdir(tmp_path) == ["o.mcap"] and out.read_bytes() == b"before"


@pytest.fixture(scope="module")
def large(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A corpus capture repeated until the export takes seconds (timestamps go back at
    each repeat: the export does not mind)."""
    path = max(CAPTURES, key=lambda p: p.stat().st_size) if CAPTURES else pytest.skip()
    from lolacli.capture import writer as w

    blocks = b"".join(w.epb(f.timestamp_ns, f.data) for f in CaptureReader(path))
    out = tmp_path_factory.mktemp("large") / "large.pcapng"
    out.write_bytes(w.shb() + w.idb(tsresol=9) + blocks * 8)
    return out


def test_ctrl_c_exits_130_and_leaves_nothing(large: Path, tmp_path: Path) -> None:
    out = tmp_path / "o.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "lolacli", "capture", "export", str(large),
                             "--mcap", str(out)], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:  # until the export writes its temporary file
        parts = [p for p in tmp_path.iterdir() if p.name.endswith(".part")]
        if parts and parts[0].stat().st_size > 0:
            break
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.01)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=30)
    assert proc.returncode == 130, stderr
    assert "SIGINT" in stderr and "not written" in stderr and "Traceback" not in stderr
    assert list(tmp_path.iterdir()) == []
