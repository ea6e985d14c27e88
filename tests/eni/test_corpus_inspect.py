"""`eni inspect --format json` on every real ENI of the corpus, checked number by number
against an independent reading of the XML with the standard library's ElementTree."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from tests.conftest import corpus_files, corpus_ids

ENIS = corpus_files("eni", "*.xml")

pytestmark = pytest.mark.skipif(not ENIS, reason="corpus not found (LOLACLI_CORPUS)")


def num(text: str | None) -> int | None:
    """The oracle's own number reader (decimal or #x hex), deliberately independent."""
    if text is None:
        return None
    t = text.strip()
    if t.lower().startswith(("#x", "0x")):
        return int(t[2:], 16)
    return int(t)


def logical(cmd: int) -> bool:
    return cmd in (10, 11, 12)  # LRD, LWR, LRW (ETG.1000.4 Table 13)


MNEMONIC = {
    0: "NOP",
    1: "APRD",
    2: "APWR",
    4: "FPRD",
    5: "FPWR",
    7: "BRD",
    8: "BWR",
    10: "LRD",
    11: "LWR",
    12: "LRW",
    13: "ARMW",
    14: "FRMW",
}


def pdo_entries(config) -> dict[tuple[str, str], list[tuple[str, str, int]]]:
    """(direction, "<slave>.<PDO>.<entry>") -> [(PDO index, "index:subindex", bits)] of the
    PDOs each slave assigns to a sync manager (an Sm attribute, or listed in <SmN><Pdo>)."""
    out: dict[tuple[str, str], list[tuple[str, str, int]]] = {}
    for s in config.findall("Slave"):
        pd = s.find("ProcessData")
        if pd is None:
            continue
        listed = {num(p.text) for sm in pd if sm.tag.startswith("Sm") for p in sm.findall("Pdo")}
        for tag, direction in (("RxPdo", "output"), ("TxPdo", "input")):
            for pdo in pd.findall(tag):
                index = num(pdo.findtext("Index"))
                if pdo.get("Sm") is None and index not in listed:
                    continue
                for e in pdo.findall("Entry"):
                    if not num(e.findtext("Index")):
                        continue  # padding
                    name = f"{s.findtext('Info/Name')}.{pdo.findtext('Name').strip()}."
                    name += e.findtext("Name").strip()
                    sub = num(e.findtext("SubIndex") or "0")
                    entry = f"0x{num(e.findtext('Index')):04X}:{sub:02X}"
                    out.setdefault((direction, name), []).append(
                        (f"0x{index:04X}", entry, num(e.findtext("BitLen")))
                    )
    return out


def oracle(path: Path) -> dict:
    root = ET.parse(path).getroot()
    config = root.find("Config")
    slaves = []
    for i, s in enumerate(config.findall("Slave"), 1):
        pd = s.find("ProcessData")
        send = pd.findall("Send") if pd is not None else []
        recv = pd.findall("Recv") if pd is not None else []
        slaves.append(
            {
                "position": i,
                "name": s.findtext("Info/Name"),
                "vendor_id": num(s.findtext("Info/VendorId")),
                "product_code": num(s.findtext("Info/ProductCode")),
                "revision": num(s.findtext("Info/RevisionNo")),
                "station_address": num(s.findtext("Info/PhysAddr")),
                "auto_inc_address": num(s.findtext("Info/AutoIncAddr")),
                "inputs_bits": sum(num(r.findtext("BitLength")) for r in recv),
                "outputs_bits": sum(num(r.findtext("BitLength")) for r in send),
            }
        )
    frames = []
    cycle = None
    for task in config.findall("Cyclic"):
        if cycle is None and task.findtext("CycleTime") is not None:
            cycle = float(task.findtext("CycleTime"))
        for frame in task.findall("Frame"):
            datagrams = []
            for c in frame.findall("Cmd"):
                cmd = num(c.findtext("Cmd"))
                datagrams.append(
                    {
                        "cmd": MNEMONIC[cmd],
                        "adp": None if logical(cmd) else num(c.findtext("Adp")),
                        "ado": None if logical(cmd) else num(c.findtext("Ado")),
                        "logical_address": num(c.findtext("Addr")) if logical(cmd) else None,
                        "length_bytes": num(c.findtext("DataLength")),
                        "expected_wkc": num(c.findtext("Cnt")),
                    }
                )
            wire = 14 + 2 + sum(10 + d["length_bytes"] + 2 for d in datagrams) + 4
            frames.append({"datagrams": datagrams, "frame_bytes": max(64, wire)})
    pi = config.find("ProcessImage")
    entries = pdo_entries(config)
    variables = []
    for section, direction in (("Inputs", "input"), ("Outputs", "output")):
        for v in pi.findall(f"{section}/Variable"):
            bits = num(v.findtext("BitSize"))
            candidates = entries.get((direction, v.findtext("Name")), [])
            found = {e[:2] for e in candidates if e[2] == bits}
            pdo, entry = found.pop() if len(found) == 1 else (None, None)
            variables.append(
                {
                    "name": v.findtext("Name"),
                    "direction": direction,
                    "bit_offset": num(v.findtext("BitOffs")),
                    "bit_size": bits,
                    "data_type": v.findtext("DataType"),
                    "pdo_index": pdo,
                    "pdo_entry": entry,
                }
            )
    return {
        "cycle_time_us": cycle,
        "slaves": slaves,
        "frames": frames,
        "inputs_bytes": num(pi.findtext("Inputs/ByteSize")),
        "outputs_bytes": num(pi.findtext("Outputs/ByteSize")),
        "variables": variables,
    }


@pytest.fixture(params=ENIS, ids=corpus_ids(ENIS))
def eni_path(request) -> Path:
    return request.param


def inspect_json(cli, path: Path) -> dict:
    code, out, err = cli("eni", "inspect", str(path), "--format", "json")
    assert code == 0, err
    assert err == ""
    data = json.loads(out)
    assert data["schema"] == "lolacli.eni/1"
    return data


def test_slaves_match_the_file(cli, eni_path):
    data, want = inspect_json(cli, eni_path), oracle(eni_path)
    assert len(data["slaves"]) == len(want["slaves"]) >= 1
    keys = list(want["slaves"][0])
    assert [{k: s[k] for k in keys} for s in data["slaves"]] == want["slaves"]


def test_cyclic_frames_match_the_file(cli, eni_path):
    data, want = inspect_json(cli, eni_path), oracle(eni_path)
    assert data["cycle_time_us"] == want["cycle_time_us"]
    assert len(data["cyclic_frames"]) == len(want["frames"]) >= 1
    for got, exp in zip(data["cyclic_frames"], want["frames"], strict=True):
        keys = list(exp["datagrams"][0])
        assert [{k: d[k] for k in keys} for d in got["datagrams"]] == exp["datagrams"]
        assert got["frame_bytes"] == exp["frame_bytes"]
        assert got["wire_time_us"] == round(exp["frame_bytes"] * 8 / 100e6 * 1e6, 2)
        overhead = exp["frame_bytes"] + 8 + 12
        assert got["wire_time_with_overhead_us"] == round(overhead * 8 / 100e6 * 1e6, 2)


def test_process_image_matches_the_file(cli, eni_path):
    data, want = inspect_json(cli, eni_path), oracle(eni_path)
    pi = data["process_image"]
    assert pi["inputs_bytes"] == want["inputs_bytes"]
    assert pi["outputs_bytes"] == want["outputs_bytes"]
    assert pi["variables"] == want["variables"]
    assert pi["variables"], "every corpus ENI has process-image variables"


def test_vars_json_matches_inspect(cli, eni_path):
    data = inspect_json(cli, eni_path)
    code, out, err = cli("eni", "vars", str(eni_path), "--format", "json")
    assert code == 0, err
    listing = json.loads(out)
    assert listing["schema"] == "lolacli.eni-vars/1"
    assert listing["count"] == len(data["process_image"]["variables"])
    assert [v["name"] for v in listing["variables"]] == [
        v["name"] for v in data["process_image"]["variables"]
    ]


def test_human_inspect_renders(cli, eni_path):
    code, out, err = cli("eni", "inspect", str(eni_path))
    assert code == 0, err
    want = oracle(eni_path)
    n = len(want["slaves"])
    assert f"{n} slave{'s' if n != 1 else ''}, cycle time" in out
    assert f"Cyclic frame 1: {want['frames'][0]['frame_bytes']:,} B," in out


def test_corpus_validates_without_errors(cli, eni_path):
    """Investigated: no corpus ENI has a real defect; murrelektronik's FMMU InitCmd data is
    scrambled (its root is EncryptedEtherCATConfig) and is reported as a warning only."""
    code, out, err = cli("eni", "validate", str(eni_path), "--format", "json")
    report = json.loads(out)
    assert report["schema"] == "lolacli.eni-validate/2"
    assert report["errors"] == 0, report["findings"]
    assert code == 0
    if eni_path.name.startswith("murrelektronik"):
        assert [f["code"] for f in report["findings"]] == ["fmmu-undecodable"]
    else:
        assert report["findings"] == []


def test_corpus_facts_from_sources_md(cli):
    """Facts stated in corpus/SOURCES.md, independent of any XML reading."""
    by_name = {p.name: p for p in ENIS}
    facts = {  # file: (slaves, LRW length, LRW Cnt, cycle µs)
        "kpierczy-ethercat-lib__test_eni.xml": (5, 56, 12, 10000.0),
        "murrelektronik-variox__eni.xml": (2, 172, 3, 1000.0),
        "rocos-ethercat__eni.xml": (1, 14, 3, 1000.0),
        "rocos-ethercat__bcr_eni.xml": (3, 42, 9, 1000.0),
        "rocos-ethercat__eni4.xml": (4, 56, 12, 1000.0),
        "rocos-ethercat__eni7.xml": (7, 154, 21, 1000.0),
        "rocos-ethercat__eni_tech6.xml": (6, 96, 18, 1000.0),
    }
    for name, (n, lrw_len, cnt, cycle) in facts.items():
        data = inspect_json(cli, by_name[name])
        assert len(data["slaves"]) == n
        lrw = [d for f in data["cyclic_frames"] for d in f["datagrams"] if d["cmd"] == "LRW"]
        assert [(d["length_bytes"], d["expected_wkc"]) for d in lrw] == [(lrw_len, cnt)]
        assert data["cycle_time_us"] == cycle
    elmo = inspect_json(cli, by_name["rocos-ethercat__eni1.xml"])
    assert elmo["cycle_time_us"] is None
    cmds = [(d["cmd"], d["length_bytes"]) for d in elmo["cyclic_frames"][0]["datagrams"]]
    assert cmds == [("LRD", 14), ("LWR", 16)]
    tech6 = inspect_json(cli, by_name["rocos-ethercat__eni_tech6.xml"])
    assert all("\n" in s["name"] and s["vendor_id"] == 0xAB for s in tech6["slaves"])
