"""``capture analyze A B …`` and folders: one process, a JSON line or a row per file."""

from __future__ import annotations

import json
import shutil

from conftest import corpus_files

from lolacli.capture.analyze import analyze_file

CAPTURES = corpus_files("pcap")


def _lines(out: str) -> list[dict]:
    return [json.loads(line) for line in out.splitlines()]


def test_several_files_give_one_json_line_each_in_order(cli, corpus, tmp_path):
    files = CAPTURES[:4]
    bad = tmp_path / "bad.pcap"
    bad.write_bytes(b"not a capture at all")
    code, out, _err = cli("capture", "analyze", *map(str, files), str(bad), "--format", "json")
    docs = _lines(out)
    assert [d["file"] for d in docs] == [*map(str, files), str(bad)]
    assert {d["schema"] for d in docs} == {"lolacli.capture-batch/1"}
    for path, d in zip(files, docs, strict=False):
        alone = analyze_file(path).to_dict()
        assert d["report"] == alone and d["error"] is None
        assert d["exit_code"] == (1 if alone["verdict"] == "fail" else 0)
    assert docs[-1]["report"] is None and docs[-1]["exit_code"] == 3
    assert "not a pcap/pcapng capture" in docs[-1]["error"]
    assert code == 3  # the worst file's


def test_exit_code_is_the_worst_files(cli, corpus):
    docs = {p: analyze_file(p).to_dict()["verdict"] for p in CAPTURES}
    passing = [str(p) for p, v in docs.items() if v != "fail"][:2]
    failing = [str(p) for p, v in docs.items() if v == "fail"][:1]
    assert cli("capture", "analyze", *passing, "--format", "json")[0] == 0
    assert cli("capture", "analyze", *passing, *failing, "--format", "json")[0] == 1


def test_a_folder_stands_for_its_captures(cli, corpus, tmp_path):
    for p in CAPTURES[:3]:
        shutil.copy(p, tmp_path / p.name)
    (tmp_path / "notes.txt").write_text("not a capture")
    _code, out, _ = cli("capture", "analyze", str(tmp_path), "--format", "json")
    assert [d["file"] for d in _lines(out)] == [str(tmp_path / p.name) for p in CAPTURES[:3]]
    empty = tmp_path / "empty"
    empty.mkdir()
    code, _out, err = cli("capture", "analyze", str(empty))
    assert code == 2 and "no .pcap" in err


def test_one_file_keeps_the_single_document(cli, corpus):
    code, out, _ = cli("capture", "analyze", str(CAPTURES[1]), "--format", "json")
    doc = json.loads(out)
    assert doc["schema"] == "lolacli.capture/1" and doc == analyze_file(CAPTURES[1]).to_dict()


def test_human_table_has_a_row_per_file_within_80_columns(cli, corpus, tmp_path):
    bad = tmp_path / "bad.pcap"
    bad.write_bytes(b"junk")
    code, out, err = cli("capture", "analyze", *map(str, CAPTURES[:3]), str(bad))
    assert code == 3 and "bad.pcap" in err
    assert max(len(line) for line in out.splitlines()) <= 80
    assert "4 captures" in out and out.count(" pass ") + out.count(" fail ") >= 3


def test_plot_with_several_files_is_a_usage_error(cli, corpus, tmp_path):
    code, _out, err = cli("capture", "analyze", *map(str, CAPTURES[:2]), "--plot",
                          str(tmp_path))
    assert code == 2 and "--plot" in err


def test_parallel_jobs_give_what_one_at_a_time_gives(cli, corpus):
    """Threads (the C scan releases the GIL) do not change any figure nor the order."""
    args = ("capture", "analyze", *map(str, CAPTURES), "--format", "json")
    code1, one, _ = cli(*args, "--jobs", "1")
    code4, four, _ = cli(*args, "--jobs", "4")
    assert (code1, one) == (code4, four)
    assert len(_lines(one)) == len(CAPTURES)


def test_a_stopped_batch_prints_what_it_did_and_exits_130(tmp_path):
    """SIGINT after the first file: its line is whole, the file being read comes out with
    its partial report (interrupted), the rest is left out; exit 130."""
    import os
    import signal
    import subprocess
    import sys
    from pathlib import Path

    from lolacli.capture import writer as w
    from lolacli.wire.commands import Command
    from lolacli.wire.frame import Datagram, encode_frame, make_frame

    def frame(ret: bool) -> bytes:
        d = Datagram.logical(Command.LRW, 0x10000, 800, index=1, wkc=3 if ret else 0)
        return encode_frame(make_frame([d], src=b"\x02" * 6 if ret else b"\x00" * 6), pad=True)

    pairs = b"".join(w.pcap_record(t * 500_000, frame(False))
                     + w.pcap_record(t * 500_000 + 40_000, frame(True)) for t in range(4000))
    files = []
    for k in range(3):
        f = tmp_path / f"{k}.pcap"
        f.write_bytes(w.pcap_header() + pairs)
        files.append(str(f))
    root = Path(__file__).resolve().parents[2]
    proc = subprocess.Popen(
        [sys.executable, "-m", "lolacli", "capture", "analyze", *files, "--format", "json",
         "--jobs", "1", "--engine", "python"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        env=dict(os.environ, PYTHONPATH=str(root)))
    try:
        first = proc.stdout.readline()  # the first file is done
        proc.send_signal(signal.SIGINT)
        rest, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    docs = _lines(first + rest)
    assert proc.returncode == 130, err
    assert docs[0]["report"]["interrupted"] is False and docs[0]["file"] == files[0]
    assert 1 <= len(docs) <= 2
    if len(docs) == 2:
        assert docs[1]["file"] == files[1] and docs[1]["report"]["interrupted"] is True
    assert "stopped" in err


def test_the_table_marks_unusable_medians_and_has_no_blank_padding(cli, corpus):
    """A round trip built on quantised timestamps (TwinCAT's 0 µs) is "unusable" in the
    table, as in the file's own report, not a measurement of 0 µs; the table starts
    with its header, and no line ends in spaces."""
    quantised = corpus / "pcap" / "DERIVED__ethercrab__twincat-run-ek1100-el1004.classic.pcap"
    doc = analyze_file(quantised).to_dict()
    assert "round_trip_us" in doc["unusable_stats"]
    code, out, _ = cli("capture", "analyze", str(quantised), str(CAPTURES[1]))
    lines = out.splitlines()
    assert code == 0 and lines[0].split()[:2] == ["File", "Frames"]
    row = next(line for line in lines if line.startswith(" DERIVED"))
    assert "unusable" in row and " 0 µs" not in row
    assert all(line == line.rstrip() for line in lines)
