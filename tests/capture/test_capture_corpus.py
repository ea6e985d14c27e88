"""Every corpus capture against tshark (the decoding oracle) and an independent pairing."""

from __future__ import annotations

import statistics

import pytest
from capture_oracle import (
    cyclic_periods,
    datagrams_by_cmd,
    pair,
    percentile,
    tshark_available,
    tshark_frames,
)
from conftest import corpus_files, corpus_ids

from lolacli.capture.analyze import analyze_file

CAPTURES = corpus_files("pcap")
needs_tshark = pytest.mark.skipif(not tshark_available(), reason="tshark not installed")


@pytest.fixture(scope="module")
def reports() -> dict:
    return {}


def _report(path, cache={}):  # noqa: B006  (module-level memo)
    if path not in cache:
        cache[path] = analyze_file(path).to_dict()
    return cache[path]


@needs_tshark
@pytest.mark.parametrize("path", CAPTURES, ids=corpus_ids(CAPTURES))
def test_counts_equal_tshark(path):
    frames = tshark_frames(path)
    rep = _report(path)
    assert rep["schema"] == "lolacli.capture/1"
    assert rep["ecat_frames"] == len(frames)
    assert rep["outgoing_frames"] == sum(1 for f in frames if not f.returned)
    assert rep["returned_frames"] == sum(1 for f in frames if f.returned)
    assert rep["datagrams_by_cmd"] == datagrams_by_cmd(frames)
    assert rep["datagrams_total"] == sum(len(f.datagrams) for f in frames)
    total = rep["ecat_frames"] + rep["non_ecat_frames"] + rep["malformed_frames"]
    assert rep["frames_total"] == total


@needs_tshark
@pytest.mark.parametrize("path", CAPTURES, ids=corpus_ids(CAPTURES))
def test_pairing_equals_independent_pairing(path):
    frames = tshark_frames(path)
    rts = pair(frames)
    rep = _report(path)
    assert rep["pairs"] == len(rts)
    assert rep["unmatched_outgoing"] == rep["outgoing_frames"] - len(rts)
    rt = rep["round_trip_us"]
    if not rts:
        assert rt is None
        return
    us = [v / 1000.0 for v in rts]
    assert rt["count"] == len(us)
    assert rt["min"] == min(us) and rt["max"] == max(us)
    assert rt["mean"] == pytest.approx(statistics.fmean(us), rel=1e-9)
    assert rt["median"] == pytest.approx(statistics.median(us), rel=1e-9)
    assert rt["std"] == pytest.approx(statistics.pstdev(us), rel=1e-6, abs=1e-9)
    assert rt["p99"] == pytest.approx(percentile(us, 99), rel=1e-9)


@needs_tshark
@pytest.mark.parametrize("path", CAPTURES, ids=corpus_ids(CAPTURES))
def test_cycle_period_of_logical_stream(path):
    frames = tshark_frames(path)
    periods = cyclic_periods(frames)
    rep = _report(path)
    if rep["cyclic_stream"] != "logical":
        assert not periods
        return
    cp = rep["cycle_period_us"]
    assert cp["count"] == len(periods)
    assert cp["median"] == pytest.approx(statistics.median(periods) / 1000.0, rel=1e-9)


def test_sdo_abort_is_reported(corpus):
    rep = analyze_file(corpus / "pcap" / "ethercrab__replay-sdo-error.pcapng").to_dict()
    aborts = rep["sdo_aborts"]
    assert [a["code"] for a in aborts] == [0x06020000]
    assert aborts[0]["code_hex"] == "0x06020000"
    assert "not exist" in aborts[0]["text"].lower()
    assert rep["sdo_transactions"] >= 1


def test_segmented_upload_is_reported(corpus):
    # ethercrab's "segmented upload" of 0x1008 (device name) from an EK1914: a normal
    # (not expedited) transfer, size and the 6 bytes "EK1914" in the initiate response
    # (frames 955/956 request, 964 response, per tshark).
    rep = analyze_file(
        corpus / "pcap" / "ethercrab__replay-ek1914-segmented-upload.pcapng"
    ).to_dict()
    uploads = [t for t in rep["sdo_transaction_list"] if t["kind"] == "upload"]
    assert len(uploads) == 1, rep["sdo_transaction_list"]
    txn = uploads[0]
    assert (txn["index"], txn["subindex"]) == (0x1008, 0)
    assert txn["transfer"] == "normal"
    assert txn["status"] == "ok"
    assert txn["size_bytes"] == 6
    assert bytes.fromhex(txn["data_hex"]) == b"EK1914"
    assert (txn["start_frame"], txn["end_frame"]) == (956, 964)
    # named, typed and printed as `sdo read` does (CiA 301 knows 0x1008)
    assert (txn["name"], txn["data_type"], txn["type_source"]) == (
        "Manufacturer device name",
        "VISIBLE_STRING",
        "cia301",
    )
    assert (txn["value"], txn["value_text"]) == ("EK1914", '"EK1914"')


def test_no_slaves_gives_zero_pairs(corpus):
    rep = analyze_file(corpus / "pcap" / "ethercrab__soem-sdinfo-no-slaves.pcapng").to_dict()
    assert rep["pairs"] == 0
    assert rep["returned_frames"] == 0
    assert rep["unmatched_outgoing"] == rep["outgoing_frames"] > 0
    assert rep["round_trip_us"] is None


def test_classic_pcap_equals_pcapng_twin(corpus):
    a = analyze_file(corpus / "pcap" / "DERIVED__ethercrab__twincat-run-ek1100-el1004.classic.pcap")
    b = analyze_file(corpus / "pcap" / "ethercrab__twincat-run-ek1100-el1004.pcapng")
    da, db = a.to_dict(), b.to_dict()
    for d in (da, db):
        d.pop("file"), d.pop("format"), d.pop("other")  # pcapng also has an ISB
    assert da == db
    assert a.format == "pcap" and b.format == "pcapng"


@pytest.mark.parametrize("path", CAPTURES, ids=corpus_ids(CAPTURES))
def test_compiled_and_python_engines_agree(path, fast):
    got = analyze_file(path, engine=fast).to_dict()
    slow = analyze_file(path, engine="python", chunk_bytes=1 << 16).to_dict()
    assert got.pop("engine") == fast and slow.pop("engine") == "python"
    assert got == slow
