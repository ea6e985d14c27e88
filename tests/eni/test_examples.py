"""The packaged example ENIs: the LOLA chain numbers of DESIGN.md, and all validate clean."""

from __future__ import annotations

import json
from importlib.resources import files
from pathlib import Path

import pytest

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
