"""`lolacli capture analyze|list` through the CLI."""

from __future__ import annotations

import json

import pytest
from capture_oracle import tshark_available, tshark_frames
from conftest import CORPUS

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
    assert "CoE SDO upload req 0x1C00:00" in out
    assert "SDO abort 0x1001:00 code 0x06020000" in out
    assert all("CoE SDO" in line for line in out.splitlines())
    code, out, _ = cli("capture", "list", path, "-c", "2", "--filter", "brd|bwr ret")
    lines = out.splitlines()
    assert len(lines) == 2 and all(" ret " in x for x in lines)
    code, out, _ = cli("capture", "list", path, "--filter", "fprd ado=0x1100 wkc!=0", "-c", "3")
    assert len(out.splitlines()) == 3 and all("ado=0x1100" in x for x in out.splitlines())


def test_list_bad_filter_is_usage_error(cli, corpus):
    code, _, err = cli("capture", "list", PCAP / "ethercrab__replay-sdo-error.pcapng",
                       "--filter", "bogus")
    assert code == 2 and "bogus" in err


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


def test_plot_without_matplotlib_is_one_line(cli, faulty, tmp_path, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib raises
    code, _, err = cli("capture", "analyze", faulty, "--plot", tmp_path)
    assert code == 2 and "needs matplotlib" in err and "Traceback" not in err


@pytest.mark.parametrize("path", sorted(PCAP.glob("*")) if PCAP.is_dir() else [],
                         ids=lambda p: p.name)
def test_human_output_reads_at_80_columns(cli, path):
    """Piped output is 80 columns wide (cli/common.py); names wrap, numbers are rounded to
    fit, never cut (no ellipsis anywhere)."""
    code, out, _ = cli("capture", "analyze", path)
    lines = out.splitlines()
    assert lines[0] == str(path) and lines[2].startswith("Verdict: ")
    # lines of text stay whole (for grep); every table line fits
    text = (str(path), "Datagrams by command:", "DC:", "AL status", "SDO abort:",
            "A frame unanswered", "Verdict:", "unusable:", "cycle jitter:", "WKC ")
    table = [x for x in lines[1:] if not x.startswith(text)]
    assert max(len(line.rstrip()) for line in table) <= 80
    assert "…" not in "".join(x for x in lines if not x.startswith("… "))


def test_sdo_table_says_how_many_more_and_all_shows_them(cli, corpus):
    path = PCAP / "ethercrab__replay-ek1914-no-complete-access.pcapng"
    code, out, _ = cli("capture", "analyze", path)
    assert "… 34 more, --all to show" in out
    rows = [x for x in out.splitlines() if x.strip().startswith("0x100")]
    assert len(rows) == 50
    code, out, _ = cli("capture", "analyze", path, "--all")
    assert "more, --all" not in out
    assert len([x for x in out.splitlines() if x.strip().startswith("0x100")]) == 84


def test_every_abort_has_its_own_line(cli, corpus):
    code, out, _ = cli("capture", "analyze", PCAP / "ethercrab__replay-sdo-error.pcapng")
    assert ("SDO abort: slave 0x1000 0x1001:00 0x06020000 Object does not exist in the object"
            in out.replace("\n", " "))
