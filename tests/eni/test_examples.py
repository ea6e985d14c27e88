"""The packaged example ENIs: the LOLA chain numbers of DESIGN.md, and all validate clean."""

from __future__ import annotations

import csv
import io
import json
from importlib.resources import files
from pathlib import Path

import pytest

from lolacli.eni.report import VARS_FIELDS
from tests.conftest import corpus_files

EXAMPLES = Path(str(files("lolacli.eni_examples")))
NAMES = ["lola.xml", "single_drive.xml", "ek1100_io.xml"]


def lola_numbers(report: dict) -> tuple:
    pi = report["process_image"]
    frames = [(f["frame_bytes"], f["wire_time_us"]) for f in report["cyclic_frames"]]
    total = pi["inputs_bytes"] + pi["outputs_bytes"]
    return len(report["slaves"]), len(pi["variables"]), total, frames, report["cycle_time_us"]


def test_lola_chain_numbers(cli):
    code, out, err = cli("eni", "inspect", str(EXAMPLES / "lola.xml"), "--format", "json")
    assert code == 0, err
    assert lola_numbers(json.loads(out)) == (25, 294, 1026, [(846, 67.68)], 500.0)


def test_inspect_without_file_uses_the_lola_chain(cli):
    code, out, err = cli("eni", "inspect", "--format", "json")
    assert code == 0, err
    report = json.loads(out)
    assert report["source"].endswith("lola.xml")
    assert lola_numbers(report)[0] == 25


@pytest.mark.parametrize("name", NAMES)
def test_example_validates_clean(cli, name):
    code, out, err = cli("eni", "validate", str(EXAMPLES / name), "--format", "json")
    report = json.loads(out)
    assert report["findings"] == [], report
    assert code == 0, err


def test_vars_filter_is_a_case_insensitive_glob(cli):
    code, out, _ = cli("eni", "vars", "--filter", "*STATUSWORD*", "--format", "json")
    assert code == 0
    report = json.loads(out)
    names = [v["name"] for v in report["variables"]]
    assert report["filter"] == "*STATUSWORD*" and report["count"] == len(names) > 0
    assert all("statusword" in n.lower() for n in names)
    code, out, _ = cli("eni", "vars", "--format", "json")
    everything = json.loads(out)["variables"]
    assert len(names) == sum("statusword" in v["name"].lower() for v in everything)


CSV_ENIS = [EXAMPLES / n for n in NAMES] + corpus_files("eni", "*.xml")


@pytest.mark.parametrize("path", CSV_ENIS, ids=[p.name for p in CSV_ENIS])
def test_vars_csv_reads_back_as_the_json(cli, path):
    """--format csv: a header row with the JSON's keys, then one row per variable that
    csv.DictReader gives back as the JSON variable (numbers as text, null as empty)."""
    code, out, _ = cli("eni", "vars", str(path), "--format", "json")
    assert code == 0
    variables = json.loads(out)["variables"]
    code, text, _ = cli("eni", "vars", str(path), "--format", "csv")
    assert code == 0
    rows = list(csv.DictReader(io.StringIO(text)))
    assert text.splitlines()[0].split(",") == list(VARS_FIELDS) == list(variables[0])
    assert rows == [
        {k: "" if v is None else str(v) for k, v in variable.items()} for variable in variables
    ]


def test_vars_help_names_the_csv_columns(cli):
    code, out, _ = cli("eni", "vars", "--help")
    assert code == 0
    said = " ".join(out.split())
    assert all(field in said for field in VARS_FIELDS)


#: CiA 402 objects by the names drives give them in their PDOs (CiA 402-2, 6040h-60FFh)
CIA402 = {
    "statusword": "0x6041:00",
    "status word": "0x6041:00",
    "controlword": "0x6040:00",
    "control word": "0x6040:00",
    "modes of operation display": "0x6061:00",
    "position actual value": "0x6064:00",
    "velocity actual value": "0x606C:00",
    "torque actual value": "0x6077:00",
    "target position": "0x607A:00",
    "target velocity": "0x60FF:00",
}


def test_pdo_entries_of_drives_are_the_cia402_objects(cli):
    """The PDO entry found for a drive's variable is the CiA 402 object of that name, in
    every ENI that has drives; TwinCAT's WcState and frame-state variables, and an ENI
    without PDOs (rocos eni1), have none."""
    checked = 0
    for path in CSV_ENIS:
        code, out, _ = cli("eni", "vars", str(path), "--format", "json")
        for v in json.loads(out)["variables"]:
            entry = v["name"].rsplit(".", 1)[-1].strip().lower()
            if entry in CIA402 and v["pdo_entry"] is not None:
                assert v["pdo_entry"] == CIA402[entry], (path.name, v)
                checked += 1
            if "WcState" in v["name"] or ".Frm0" in v["name"]:
                assert v["pdo_entry"] is None and v["pdo_index"] is None
            if path.name == "rocos-ethercat__eni1.xml":
                assert v["pdo_entry"] is None
    assert checked >= 25 * 3  # the LOLA joints alone have three each


def human_vars_names(out: str) -> list[str]:
    """The name column of ``eni vars``, row by row, its wrapped lines joined."""
    lines = out.splitlines()
    header = next(i for i, line in enumerate(lines) if line.startswith("dir "))
    column = lines[header].index("name")
    names: list[list[str]] = []
    for line in lines[header + 2 :]:
        if line.split()[0] in ("in", "out"):
            names.append([])
        names[-1].append(line[column:].strip())
    return [" ".join(parts) for parts in names]


@pytest.mark.parametrize("path", CSV_ENIS, ids=[p.name for p in CSV_ENIS])
def test_vars_human_shows_each_name_whole(cli, path):
    """Names are never cut: the name column, its wrapped lines joined, holds each name
    (a name with no room and no space wraps after a dot); the offset, size, type and
    PDO entry are on the variable's first line."""
    code, out, _ = cli("eni", "vars", str(path))
    assert code == 0
    variables = json.loads(cli("eni", "vars", str(path), "--format", "json")[1])["variables"]
    shown = human_vars_names(out)
    assert [n.replace(" ", "") for n in shown] == [
        "".join(v["name"].split()) for v in variables
    ]
    if path.name == "lola.xml":
        first = out.splitlines()[3].split()
        assert first[:6] == ["in", "0.0", "16", "bit", "UINT", "0x6041:00"]
