"""`lolacli capture analyze|list` through the CLI."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from capture_oracle import tshark_available, tshark_frames
from conftest import CORPUS
from rich.cells import cell_len

from lolacli.capture import writer as w
from lolacli.wire.commands import Command
from lolacli.wire.frame import Datagram, encode_frame, make_frame

PCAP = CORPUS / "pcap"
OUT_MAC = b"\x10\x10\x10\x10\x10\x10"
RET_MAC = b"\x12\x10\x10\x10\x10\x10"


def _frame(idx: int, wkc: int, ret: bool) -> bytes:
    d = Datagram.logical(Command.LRW, 0, 4, index=idx, wkc=wkc)
    return encode_frame(make_frame([d], src=RET_MAC if ret else OUT_MAC), pad=True)


@pytest.fixture
def faulty(tmp_path):
    """10 LRW cycles: cycle 4 never returns (lost), cycle 7 returns WKC 2 instead of 3."""
    body = w.pcap_header(ns=True)
    t = 10**18
    for i in range(10):
        body += w.pcap_record(t + i * 1_000_000, _frame(i, 0, False), ns=True)
        if i != 4:
            body += w.pcap_record(t + i * 1_000_000 + 50_000, _frame(i, 2 if i == 7 else 3, True),
                                  ns=True)
    path = tmp_path / "faulty.pcap"
    path.write_bytes(body)
    return path


def test_analyze_json_contract(cli, corpus):
    code, out, err = cli("capture", "analyze", PCAP / "ethercrab__replay-issue-255.pcapng",
                         "--format", "json")
    rep = json.loads(out)
    assert rep["wkc"]["reference"] == "inferred" == rep["wkc_reference"]
    assert rep["wkc"]["checked_datagrams"] == rep["wkc_checked"] > 0
    assert rep["wkc_mismatches"] == 0 and rep["lost_frames"] == 0
    assert code == 0, err
    for key in ("schema", "frames_total", "ecat_frames", "non_ecat_frames", "malformed_frames",
                "datagrams_total", "datagrams_by_cmd", "outgoing_frames", "returned_frames",
                "pairs", "unmatched_outgoing", "round_trip_us", "cycle_period_us",
                "wkc_mismatches", "lost_frames", "sdo_transactions", "sdo_aborts"):
        assert key in rep
    assert rep["schema"] == "lolacli.capture/1"
    assert set(rep["round_trip_us"]) == {"count", "min", "mean", "median", "std", "p99", "max"}
    assert rep["cyclic_stream"] == "logical"
    assert rep["cycle_period_us"]["median"] == pytest.approx(1925, rel=0.02)


def test_thresholds_set_exit_code(cli, faulty):
    code, out, _ = cli("capture", "analyze", faulty, "--format", "json")
    rep = json.loads(out)
    assert code == 1
    assert rep["lost_frames"] == 1 and rep["wkc_mismatches"] == 1
    assert rep["wkc"]["first_mismatches"][0]["received"] == 2
    code, _, _ = cli("capture", "analyze", faulty, "--max-lost", "1", "--max-wkc-mismatches", "1",
                     "--format", "json")
    assert code == 0
    code, _, _ = cli("capture", "analyze", faulty, "--max-lost", "1", "--format", "json")
    assert code == 1


def test_human_output_and_plots(cli, faulty, tmp_path):
    code, out, err = cli("capture", "analyze", faulty, "--plot", tmp_path / "plots",
                         "--max-lost", "5", "--max-wkc-mismatches", "5")
    assert code == 0, err
    assert "round trip" in out and "Frames" in out
    pngs = sorted(p.name for p in (tmp_path / "plots").glob("*.png"))
    assert pngs == ["faulty-cycle-period.png", "faulty-round-trip-cdf.png", "faulty-round-trip.png"]
    for p in (tmp_path / "plots").glob("*.png"):
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_analyze_with_eni_expected_wkc(cli, tmp_path, faulty):
    """With --eni the reference is the ENI's <Cnt>: a chain whose LRW expects 2 makes
    every WKC 3 a mismatch except the one that returned 2."""
    eni = tmp_path / "eni.xml"
    eni.write_text(
        """<?xml version="1.0"?>
<EtherCATConfig><Config>
 <Master><Info><Name>m</Name></Info></Master>
 <Cyclic><CycleTime>1000</CycleTime><Frame>
  <Cmd><State>OP</State><Cmd>12</Cmd><Addr>0</Addr><DataLength>4</DataLength><Cnt>2</Cnt></Cmd>
 </Frame></Cyclic>
</Config></EtherCATConfig>
""")
    code, out, err = cli("capture", "analyze", faulty, "--eni", eni, "--format", "json",
                         "--max-lost", "9")
    if code == 3:
        pytest.skip(f"ENI parser rejects the minimal ENI: {err.strip()}")
    rep = json.loads(out)
    assert rep["wkc"]["reference"] == "eni"
    assert rep["wkc_mismatches"] == 8 and code == 1


@pytest.mark.skipif(not tshark_available(), reason="tshark not installed")
def test_list_matches_tshark_frame_numbers(cli, corpus):
    path = PCAP / "ethercrab__replay-sdo-error.pcapng"
    code, out, _ = cli("capture", "list", path, "--format", "json")
    assert code == 0
    frames = json.loads(out)["frames"]
    oracle = tshark_frames(path)
    assert [f["number"] for f in frames] == [f.number for f in oracle]
    assert [[d["wkc"] for d in f["datagrams"]] for f in frames] == [list(f.wkcs) for f in oracle]


def test_list_filters_and_sdo_text(cli, corpus):
    path = PCAP / "ethercrab__replay-sdo-error.pcapng"
    code, out, _ = cli("capture", "list", path, "--filter", "sdo")
    assert code == 0
    # one datagram per entry: its line, and the mailbox summary on it or below it
    entries = re.split(r"\n(?=\s*\d+ )", out.strip())
    listed = json.loads(cli("capture", "list", path, "--filter", "sdo", "-f", "json")[1])
    assert len(entries) == sum(len(f["datagrams"]) for f in listed["frames"]) > 10
    assert all("CoE SDO" in e for e in entries)
    assert "CoE SDO upload req 0x1C00:00" in out
    assert "SDO abort 0x1001:00 code 0x06020000" in out
    code, out, _ = cli("capture", "list", path, "-c", "2", "--filter", "brd|bwr ret")
    lines = out.splitlines()
    assert len(lines) == 2 and all(" ret " in x for x in lines)
    code, out, _ = cli("capture", "list", path, "--filter", "fprd ado=0x1100 wkc!=0", "-c", "3")
    lines = [x for x in out.splitlines() if not x.startswith(" " * 24)]  # (not summaries)
    assert len(lines) == 3 and all("ado=0x1100" in x for x in lines)


def test_list_bad_filter_is_usage_error(cli, corpus):
    code, _, err = cli("capture", "list", PCAP / "ethercrab__replay-sdo-error.pcapng",
                       "--filter", "bogus")
    assert code == 2 and "bogus" in err


@pytest.mark.parametrize(
    ("expr", "said"),
    [
        ("adp=-1", "adp is 0..0xFFFF"),
        ("adp=0x10000", "adp is 0..0xFFFF"),
        ("ado=65536", "ado is 0..0xFFFF"),
        ("idx=999999999999999999999", "idx is 0..0xFF"),
        ("idx=0x100", "idx is 0..0xFF"),
        ("lad=0x100000000", "lad is 0..0xFFFFFFFF"),
        ("wkc!=-1", "wkc is 0..0xFFFF"),
        ("out ret", "out and ret contradict"),
        ("fprd, ret out", "ret and out contradict"),
    ],
)
def test_list_filter_out_of_range_or_contradicting_is_usage_error(cli, corpus, expr, said):
    code, out, err = cli("capture", "list", PCAP / "ethercrab__replay-sdo-error.pcapng",
                         "--filter", expr)
    assert (code, out) == (2, "") and err.count("\n") == 1 and said in err, err


def test_list_filter_commands_are_any_of_them_the_rest_all(cli, corpus):
    """Several commands, joined by | or as terms of their own, list a datagram of any of
    them; every other term must hold as well (the help says so)."""
    path = PCAP / "ethercrab__replay-sdo-error.pcapng"

    def listed(expr: str) -> list[tuple[int, str, str]]:
        code, out, err = cli("capture", "list", path, "--filter", expr, "-f", "json")
        assert code == 0, err
        return [(f["number"], f["direction"], d["cmd"])
                for f in json.loads(out)["frames"] for d in f["datagrams"]]

    one, other = listed("brd"), listed("fprd")
    assert one and other
    assert sorted(listed("brd fprd")) == sorted(listed("brd|fprd")) == sorted(one + other)
    assert listed("brd fprd ret") == [x for x in listed("brd fprd") if x[1] == "ret"]
    assert listed("ret ret") == listed("ret")
    code, out, _ = cli("capture", "list", "--help")
    assert "any of them" in " ".join(out.split()) and "one direction" in " ".join(out.split())


@pytest.mark.parametrize("name", ["ethercrab__twincat-scan-boxes.pcapng",
                                  "ethercrab__soem-sdinfo-no-slaves.pcapng",
                                  "ethercrab__replay-issue-255.pcapng"])
def test_plot_never_a_traceback(cli, corpus, tmp_path, name):
    """Quantised and backward timestamps (scan-boxes), nothing to plot (no-slaves), a
    healthy stream: plots or a clean skip, never a traceback."""
    code, _, err = cli("capture", "analyze", PCAP / name, "--plot", tmp_path, "-f", "json")
    assert "Traceback" not in err and code in (0, 1)
    written = sorted(p.name for p in tmp_path.glob("*.png"))
    stem = name.removesuffix(".pcapng")
    if name.startswith("ethercrab__soem-sdinfo-no-slaves"):
        assert written == [f"{stem}-cycle-period.png"]  # periods, but no round trip at all
    else:
        assert written == sorted(f"{stem}-{k}.png" for k in ("cycle-period", "round-trip",
                                                           "round-trip-cdf"))


@pytest.mark.parametrize(
    ("plot", "says"),
    [
        ("p.png", "--plot takes a folder"),
        ("missing/x.png", "--plot takes a folder"),
        ("missing/plots", "cannot create the folder: missing does not exist"),
    ],
)
def test_plot_is_a_folder_whose_parent_exists(cli, corpus, tmp_path, monkeypatch, plot, says):
    """--plot names a folder: a PNG's name or a folder under a missing one is refused,
    exit 2, one line, and no folder is made; the last folder itself is made."""
    capture = PCAP / "ethercrab__replay-issue-49.pcapng"
    monkeypatch.chdir(tmp_path)
    code, out, err = cli("capture", "analyze", capture, "--plot", plot)
    assert code == 2 and says in err and err.count("\n") == 1, err
    assert out == "" and list(tmp_path.iterdir()) == []
    code, _, err = cli("capture", "analyze", capture, "--plot", "plots", "-f", "json")
    assert code in (0, 1) and len(list((tmp_path / "plots").glob("*.png"))) == 3, err


def test_plot_without_matplotlib_is_one_line(cli, faulty, tmp_path, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib raises
    code, _, err = cli("capture", "analyze", faulty, "--plot", tmp_path)
    assert code == 2 and "needs matplotlib" in err and "Traceback" not in err


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """The LOLA chain's bring-up and 600 cycles (25 slaves: long station lists, 450 SDO
    transactions), some frames lost, written by the simulator's pcapng recorder."""
    from lolacli.cli.common import default_eni
    from lolacli.files import load_eni
    from lolacli.simulate import SimulateOptions, simulate

    path = tmp_path_factory.mktemp("sim") / "lola-600.pcapng"
    simulate(load_eni(default_eni()),
             SimulateOptions(cycles=600, pcap=path, drop_probability=0.002, seed=2))
    return path


CAPTURES = sorted(PCAP.glob("*")) if PCAP.is_dir() else []
#: a count of 1 with a plural noun ("1 frames"), or a None (a value missing in words)
_BAD_WORDS = re.compile(r"(?<![\d.,x])1 (frames|packets|bursts|aborts|returns|mismatches|reads"
                        r"|datagrams|warnings|failures|slaves|messages|transactions)\b|\bNone\b")


def _check_80_columns(out: str, path: Path) -> list[str]:
    lines = out.splitlines()
    assert lines[0] == str(path)  # the path alone may be longer
    wide = [x for x in lines[1:] if cell_len(x) > 80]
    assert not wide, wide
    assert not _BAD_WORDS.search(out), _BAD_WORDS.search(out)
    return lines


@pytest.mark.parametrize("path", [*CAPTURES, "simulated"], ids=lambda p: getattr(p, "name", p))
def test_human_output_reads_at_80_columns(cli, request, monkeypatch, path):
    """With COLUMNS=80 every line fits: prose wraps between words, tables wrap names and
    headers; numbers are rounded, never cut (no ellipsis)."""
    if path == "simulated":
        path = request.getfixturevalue("simulated")
    monkeypatch.setenv("COLUMNS", "80")
    code, out, _ = cli("capture", "analyze", path)
    lines = _check_80_columns(out, path)
    assert lines[2].startswith("Verdict: ")
    assert "…" not in "".join(x for x in lines if not x.startswith("… "))


@pytest.mark.parametrize("path", [*CAPTURES, "simulated"], ids=lambda p: getattr(p, "name", p))
def test_list_reads_at_80_columns(cli, request, monkeypatch, path):
    """Each datagram on one line of at most 80 columns; a mailbox summary that does not
    fit after it goes below it, wrapped between words."""
    if path == "simulated":
        path = request.getfixturevalue("simulated")
    monkeypatch.setenv("COLUMNS", "80")
    code, out, _ = cli("capture", "list", path)
    assert code == 0
    _check_80_columns(str(path) + "\n" + out, path)
    monkeypatch.setenv("COLUMNS", "200")  # a wide terminal: one line per datagram
    code, wide, _ = cli("capture", "list", path)
    assert all(cell_len(x) <= 200 for x in wide.splitlines())
    assert " ".join(out.split()) == " ".join(wide.split())  # the same words


def test_stations_and_units_in_words(cli, corpus, monkeypatch):
    monkeypatch.setenv("COLUMNS", "80")
    path = PCAP / "ethercrab__replay-sdo-error.pcapng"
    code, out, _ = cli("capture", "analyze", path)
    text = " ".join(out.split())
    assert "of slave 0x1000 (4096)" in text and "PREOP: 0x1000 (4096), BRD" in text
    assert "FRMW 0x0910 of" in text and "0x1000 (4096) 8 B" in text  # (a table cell)
    assert "in 1 burst;" in text and "no read of the system time difference" in text
    assert "A frame unanswered for 2,384.73 µs" in text
    code, out, _ = cli("capture", "list", path, "-c", "1")
    assert out.split()[:3] == ["1", "0.000000", "s"]
    code, out, _ = cli("capture", "list", path, "--filter", "fprd ado=0x1100", "-c", "1")
    assert "adp=0x1000 (4096) ado=0x1100  256 B wkc=" in out


_SDO_ROW = re.compile(r"0x[0-9A-F]{4}:[0-9A-F]{2}\s+(upload|download)\s")


def test_sdo_table_says_how_many_more_and_all_shows_them(cli, corpus):
    path = PCAP / "ethercrab__replay-ek1914-no-complete-access.pcapng"
    code, out, _ = cli("capture", "analyze", path, "-f", "json")
    total = json.loads(out)["sdo_transactions"]
    code, out, _ = cli("capture", "analyze", path)
    assert f"… {total - 50} more, --all to show" in out
    assert len([x for x in out.splitlines() if _SDO_ROW.search(x)]) == 50
    code, out, _ = cli("capture", "analyze", path, "--all")
    assert "more, --all" not in out
    assert len([x for x in out.splitlines() if _SDO_ROW.search(x)]) == total > 50


def test_every_abort_has_its_own_line(cli, corpus):
    code, out, _ = cli("capture", "analyze", PCAP / "ethercrab__replay-sdo-error.pcapng")
    assert ("SDO abort: slave 0x1000 (4096) 0x1001:00 0x06020000 object does not exist "
            "(frame 544)" in " ".join(out.split()))
