"""`eni validate`: our small valid ENI is clean; each planted defect is found with its code."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from lolacli.eni.parser import parse_eni
from lolacli.eni.validate import expected_wkc, validate_eni

FIXTURES = Path(__file__).resolve().parent.parent / "fixtures" / "eni"
VALID = (FIXTURES / "eni-small-valid.xml").read_text()

# InitCmd data of the fixture (ETG.1000.4 Table 56 FMMU, Table 58 SM).
EL1809_FMMU_READ = "08000100020000070010000101000000"  # 0x00010008+2, read
DRIVE_SM2 = "0011060064000100"  # 0x1100, 6 bytes


def planted(old: str, new: str, count: int = 1) -> str:
    assert VALID.count(old) == count, old
    return VALID.replace(old, new)


def codes(xml: str) -> list[str]:
    return [f.kind for f in validate_eni(parse_eni(xml.encode(), "t.xml"))]


def test_small_valid_eni_is_clean(cli):
    code, out, err = cli("eni", "validate", str(FIXTURES / "eni-small-valid.xml"), "-f", "json")
    assert code == 0, out
    report = json.loads(out)
    assert report == {
        "schema": "lolacli.eni-validate/2",
        "source": str(FIXTURES / "eni-small-valid.xml"),
        "errors": 0,
        "warnings": 0,
        "verdict": "pass",
        "findings": [],
    }


def test_expected_wkc_of_the_fixture():
    eni = parse_eni(VALID.encode())
    lrw, brd = eni.cyclic_frames[0].commands
    assert expected_wkc(eni, lrw) == 4  # drive reads+writes (3) + input terminal reads (1)
    assert expected_wkc(eni, brd) == 3  # broadcast read: one per slave


DEFECTS = {
    "duplicate-station-address": planted("<PhysAddr>1003</PhysAddr>", "<PhysAddr>1002</PhysAddr>"),
    "wkc-mismatch": planted("<Cnt>4</Cnt>", "<Cnt>5</Cnt>"),
    "fmmu-write-overlap": planted(
        EL1809_FMMU_READ,
        "02000100020000070010000201000000",  # write at 0x00010002: drive's outputs
    ),
    "fmmu-overlap": planted(
        EL1809_FMMU_READ,
        "04000100020000070010000101000000",  # read at 0x00010004: drive's inputs
    ),
    "pdo-overruns-sm": planted(DRIVE_SM2, "0011040064000100"),  # SM2 4 bytes < 6 bytes of PDOs
    "cyclic-logical-overlap": planted(
        "<Cmd>7</Cmd>\n          <Adp>0</Adp>\n          <Ado>#x130</Ado>",
        "<Cmd>10</Cmd>\n          <Addr>#x00010004</Addr>",
    ),
    "missing-station-address": planted("<PhysAddr>1003</PhysAddr>", "<PhysAddr>0</PhysAddr>"),
    "unknown-previous-port": planted(
        "<Port>B</Port>\n        <PhysAddr>1002</PhysAddr>",
        "<Port>B</Port>\n        <PhysAddr>1234</PhysAddr>",
    ),
}


@pytest.mark.parametrize("code", sorted(DEFECTS))
def test_planted_defect_is_found(cli, tmp_path, code):
    path = tmp_path / f"eni-{code}.xml"
    path.write_text(DEFECTS[code])
    exit_code, out, err = cli("eni", "validate", str(path), "--format", "json")
    report = json.loads(out)
    assert code in [f["code"] for f in report["findings"]], report
    assert exit_code == 1
    assert report["errors"] >= 1
    finding = next(f for f in report["findings"] if f["code"] == code)
    assert finding["severity"] == "failure" and finding["message"]


def test_variable_outside_the_image_is_found_in_a_model():
    """A file with one is refused by the parser (tests/eni/test_validate_ranges.py); a model
    built in code is checked by validate."""
    from dataclasses import replace

    eni = parse_eni(VALID.encode(), "t.xml")
    pi = eni.process_image
    moved = replace(pi.variables[0], bit_offset=pi.inputs_bytes * 8)
    eni = replace(eni, process_image=replace(pi, variables=(moved, *pi.variables[1:])))
    (finding,) = [f for f in validate_eni(eni) if f.kind == "variable-outside-image"]
    assert finding.severity.value == "failure" and moved.name in finding.message


def test_an_eni_without_slaves_fails_validation(cli, tmp_path):
    path = tmp_path / "eni-no-slaves.xml"
    path.write_text(
        "<EtherCATConfig><Config><Master><Info><Name>m</Name></Info></Master>"
        "<Cyclic><CycleTime>1000</CycleTime></Cyclic></Config></EtherCATConfig>"
    )
    code, out, _err = cli("eni", "validate", str(path), "--format", "json")
    report = json.loads(out)
    assert code == 1 and report["verdict"] == "fail"
    assert [(f["kind"], f["severity"]) for f in report["findings"]] == [("no-slaves", "failure")]


def test_wrong_cnt_is_the_only_finding():
    assert codes(DEFECTS["wkc-mismatch"]) == ["wkc-mismatch"]


def test_write_overlap_also_breaks_the_lrw_count():
    """The terminal now writes into the LRW range: Cnt 4 no longer matches (1+2 … )."""
    found = codes(DEFECTS["fmmu-write-overlap"])
    assert "fmmu-write-overlap" in found and "wkc-mismatch" in found


def test_lrw_counts_one_for_inputs_only_and_two_for_outputs_only():
    only_outputs = planted(
        EL1809_FMMU_READ,
        "08000100020000070010000201000000",  # terminal now writes (type 2)
    )
    eni = parse_eni(only_outputs.encode())
    assert expected_wkc(eni, eni.cyclic_frames[0].commands[0]) == 3 + 2
    assert codes(only_outputs) == ["wkc-mismatch"]


def test_auto_inc_address_out_of_order_is_a_warning(cli, tmp_path):
    path = tmp_path / "eni-auto-inc.xml"
    path.write_text(planted("<AutoIncAddr>65534</AutoIncAddr>", "<AutoIncAddr>65533</AutoIncAddr>"))
    code, out, _ = cli("eni", "validate", str(path), "--format", "json")
    report = json.loads(out)
    assert [f["code"] for f in report["findings"]] == ["auto-inc-address"]
    assert report["findings"][0]["slave"] == 3
    assert code == 0  # warnings alone pass ...
    code, _, _ = cli("eni", "validate", str(path), "--strict")
    assert code == 1  # ... unless --strict


def test_human_output_names_code_and_slave(cli, tmp_path):
    path = tmp_path / "eni-dup.xml"
    path.write_text(DEFECTS["duplicate-station-address"])
    code, out, _ = cli("eni", "validate", str(path))
    assert code == 1
    assert "duplicate-station-address at 0x03EA (1002): slave 2 (Drive 1)" in out
    assert "2 errors, 0 warnings" in out


def test_fmmu_outside_any_cyclic_command():
    moved = planted(EL1809_FMMU_READ, "00000200020000070010000101000000")  # 0x00020000
    found = codes(moved)
    assert "fmmu-not-in-cyclic" in found
    assert "wkc-mismatch" in found  # the LRW no longer reaches the terminal: 3, not 4


def test_fmmu_pointing_outside_the_sync_managers():
    moved = planted(EL1809_FMMU_READ, "08000100020000070014000101000000")  # physical 0x1400
    assert codes(moved) == ["fmmu-sm-mismatch"]
