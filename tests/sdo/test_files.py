"""Object dictionaries from files: every corpus EDS/DCF and ESI loads (``sdo list`` exit 0),
broken ones are exit 3 with one line naming the file."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from lolacli.sdo.files import load_eds
from tests.conftest import CORPUS, corpus_files, corpus_ids

EDS = corpus_files("eds")
ESI = corpus_files("esi", "*.xml")


@pytest.mark.parametrize("path", EDS, ids=corpus_ids(EDS))
def test_every_corpus_eds_lists(cli, path: Path, corpus) -> None:
    code, out, err = cli("sdo", "list", "5", "--eds", str(path), "-f", "json")
    assert code == 0, err
    doc = json.loads(out)
    dictionary = load_eds(path, 5)
    assert len(doc["objects"]) == len(dictionary) >= 40
    entries = [e for o in doc["objects"] for e in o["entries"]]
    assert all(e["data_type"] for e in entries)  # every EDS entry has a basic type
    code, out, _ = cli("sdo", "list", "5", "--eds", str(path))
    assert code == 0 and out.startswith(f"slave 5: {len(dictionary)} objects from eds")


@pytest.mark.parametrize("path", ESI, ids=corpus_ids(ESI))
def test_every_corpus_esi_lists_or_says_why(cli, path: Path, corpus) -> None:
    from lolacli.files import load_esi

    esi = load_esi(path)
    with_od = [d for d in esi.devices if d.dictionary is not None]
    code, out, err = cli("sdo", "list", "1", "--esi", str(path), "-f", "json")
    if len(with_od) == 1:
        assert code == 0, err
        doc = json.loads(out)
        assert len(doc["objects"]) == len(with_od[0].dictionary.objects)
        assert doc["slave"] == f"{with_od[0].name} (ESI, no bus)"  # not "slave 1" of a bus
    elif not with_od:  # nothing to list: bad input, naming the file
        assert code == 3 and path.name in err and "no device in it has an object dictionary" in err
    else:  # several devices to choose from: a usage error naming them and the way out
        assert code == 2 and f"describes {len(with_od)} devices with a dictionary" in err
        assert with_od[0].name[:40] in err and "give --eni FILE" in err
    assert len(err.strip().splitlines()) <= 1


def test_esi_device_picked_by_the_eni_slave(cli, corpus) -> None:
    esi = CORPUS / "esi" / "elmo_ethercat_sdk__Elmo_ECAT_00010420_V11.xml"
    eni = CORPUS / "eni" / "rocos-ethercat__eni.xml"  # one Elmo Gold, rev 0x10420
    code, out, err = cli("sdo", "list", "1", "--esi", str(esi), "--eni", str(eni), "-f", "json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["source"] == "esi" and len(doc["objects"]) == 166
    device_type = next(o for o in doc["objects"] if o["index"] == 0x1000)["entries"][0]
    assert device_type["default"] == 0x00020192  # <DefaultData>92010200</DefaultData>
    assert device_type["data_type"] == "UNSIGNED32"


@pytest.mark.parametrize(
    ("name", "content", "reason"),
    [
        ("not-ini.eds", b"just some words\n", "not a valid EDS/DCF"),
        ("empty.eds", b"", "no objects"),
        ("binary.eds", b"\x00\x01\x02PK\x03\x04", "binary data"),
        ("no-type.eds", b"[1000]\nParameterName=x\nObjectType=0x7\n", "not a valid EDS/DCF"),
        (
            "bad-number.eds",
            b"[1000]\nParameterName=x\nObjectType=0x7\nDataType=0xZZ\nAccessType=ro\n",
            "not a valid EDS/DCF",
        ),
        (
            "duplicate.eds",
            b"[1000]\nParameterName=x\n[1000]\nParameterName=y\n",
            "not a valid EDS/DCF",
        ),
    ],
)
def test_broken_eds_is_exit_3(cli, tmp_path: Path, name: str, content: bytes, reason: str) -> None:
    path = tmp_path / name
    path.write_bytes(content)
    code, out, err = cli("sdo", "list", "1", "--eds", str(path))
    assert code == 3 and out == ""
    assert err.count("\n") == 1 and name in err and reason in err


def test_missing_and_directory_eds(cli, tmp_path: Path) -> None:
    code, _out, err = cli("sdo", "list", "1", "--eds", str(tmp_path / "nope.eds"))
    assert code == 3 and "no such file" in err
    code, _out, err = cli("sdo", "list", "1", "--eds", str(tmp_path))
    assert code == 3 and "is a directory" in err


def test_bad_eds_fails_before_the_bus(cli, tmp_path: Path) -> None:
    """Exit 3 for the file, not 4 for a bus that was never needed."""
    path = tmp_path / "bad.eds"
    path.write_text("nonsense\n")
    code, _out, err = cli(
        "sdo", "read", "1", "0x1000", "--can", "x", "--interface", "virtual", "--eds", str(path)
    )
    assert code == 3 and "bad.eds" in err
