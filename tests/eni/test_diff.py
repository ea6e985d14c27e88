"""`eni diff`: equal files exit 0, each kind of difference is reported and exits 1."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from lolacli.eni.diff import diff_eni
from lolacli.eni.parser import parse_eni
from tests.conftest import corpus_files

FIXTURES = Path(__file__).resolve().parent.parent / "fixtures" / "eni"
VALID_PATH = FIXTURES / "eni-small-valid.xml"
VALID = VALID_PATH.read_text()


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def diff_json(cli, a: Path, b: Path) -> tuple[int, dict]:
    code, out, err = cli("eni", "diff", str(a), str(b), "--format", "json")
    assert err == ""
    report = json.loads(out)
    assert report["schema"] == "lolacli.eni-diff/1"
    return code, report


def test_same_file_is_equal(cli):
    code, report = diff_json(cli, VALID_PATH, VALID_PATH)
    assert code == 0
    assert report["equal"] is True and report["changes"] == []


def test_formatting_only_changes_are_equal(cli, tmp_path):
    """Whitespace, comments and #x vs decimal spelling do not make a difference."""
    other = VALID.replace("<Addr>#x00010000</Addr>", "<Addr>65536</Addr>").replace("\n", "\n  ")
    other = other.replace("<Cyclic>", "<Cyclic><!-- a comment -->")
    code, report = diff_json(cli, VALID_PATH, write(tmp_path, "b.xml", other))
    assert code == 0 and report["equal"]


def test_changed_identity_and_address(cli, tmp_path):
    b = VALID.replace("<RevisionNo>66592</RevisionNo>", "<RevisionNo>66593</RevisionNo>")
    code, report = diff_json(cli, VALID_PATH, write(tmp_path, "b.xml", b))
    assert code == 1
    assert report["changes"] == [
        {
            "kind": "changed",
            "area": "slave",
            "key": "station 1002",
            "before": {"revision": 66592},
            "after": {"revision": 66593},
            "message": "slave 0x03EA (1002): revision 0x00010420 in A, 0x00010421 in B",
        }
    ]


def test_cyclic_and_variable_changes(cli, tmp_path):
    b = VALID.replace("<Cnt>4</Cnt>", "<Cnt>5</Cnt>").replace(
        "<Name>EL1809.Channel 1-16.Input</Name>", "<Name>EL1809.Inputs</Name>"
    )
    code, report = diff_json(cli, VALID_PATH, write(tmp_path, "b.xml", b))
    assert code == 1
    summary = [(c["kind"], c["area"], c["key"]) for c in report["changes"]]
    assert summary == [
        ("changed", "cyclic", "frame 1 cmd 1"),
        ("removed", "variable", "input:EL1809.Channel 1-16.Input"),
        ("added", "variable", "input:EL1809.Inputs"),
    ]
    assert report["changes"][0]["before"] == {"expected_wkc": 4}
    assert report["changes_by_area"]["variable"] == 2


def test_removed_slave_and_cycle_time(cli, tmp_path):
    start = VALID.index("    <Slave>\n      <Info>\n        <Name>EL1809")
    end = VALID.index("    <Cyclic>")
    b = (VALID[:start] + VALID[end:]).replace(
        "<CycleTime>500</CycleTime>", "<CycleTime>1000</CycleTime>"
    )
    eni_a, eni_b = parse_eni(VALID.encode()), parse_eni(b.encode())
    changes = diff_eni(eni_a, eni_b)
    assert ("changed", "cycle_time") == (changes[0].kind, changes[0].area)
    assert changes[0].before == {"cycle_time_ns": 500_000}
    assert changes[0].after == {"cycle_time_ns": 1_000_000}
    removed = [c for c in changes if c.kind == "removed" and c.area == "slave"]
    assert [c.key for c in removed] == ["station 1003"]
    code, out, _ = cli("eni", "diff", str(VALID_PATH), str(write(tmp_path, "b.xml", b)))
    assert code == 1
    name = eni_a.slaves[2].name
    assert f"slave 0x03EB (1003) {name}: only in A" in out.splitlines()
    assert "cycle time: 500 µs in A, 1,000 µs in B" in out.splitlines()
    assert out.splitlines()[-1].startswith(f"{len(changes)} differences: 1 cycle time, 1 slave")


def test_corpus_pair(cli):
    """rocos eni4 (4 drives) against eni7 (7 drives): three slaves added, LRW grown."""
    files = {p.name: p for p in corpus_files("eni", "rocos-ethercat__eni[47].xml")}
    if len(files) < 2:
        pytest.skip("corpus not found")
    code, report = diff_json(
        cli, files["rocos-ethercat__eni4.xml"], files["rocos-ethercat__eni7.xml"]
    )
    assert code == 1
    added = [c["key"] for c in report["changes"] if c["kind"] == "added" and c["area"] == "slave"]
    assert added == ["station 1005", "station 1006", "station 1007"]
    lrw = next(
        c for c in report["changes"] if c["area"] == "cyclic" and "length_bytes" in c["before"]
    )
    assert (lrw["before"]["length_bytes"], lrw["after"]["length_bytes"]) == (56, 154)
    assert (lrw["before"]["expected_wkc"], lrw["after"]["expected_wkc"]) == (12, 21)


def test_diff_help_states_exit_codes(cli):
    code, out, _ = cli("eni", "diff", "--help")
    assert code == 0
    assert "Exit 0 when the two are equal, 1 when they differ" in " ".join(out.split())


def test_each_difference_in_words(cli, tmp_path):
    """The human output says each difference as a sentence: the thing, the field, its
    value in A and in B, with units; no Python values."""
    b = (
        VALID.replace("<RevisionNo>66592</RevisionNo>", "<RevisionNo>66593</RevisionNo>")
        .replace("<Cnt>4</Cnt>", "<Cnt>5</Cnt>")
        .replace("<Name>EL1809.Channel 1-16.Input</Name>", "<Name>EL1809.Inputs</Name>")
    )
    code, out, _ = cli("eni", "diff", str(VALID_PATH), str(write(tmp_path, "b.xml", b)))
    assert code == 1
    lines = out.splitlines()
    assert lines[:2] == [f"A is {VALID_PATH}", f"B is {tmp_path / 'b.xml'}"]
    assert lines[2:] == [
        "slave 0x03EA (1002): revision 0x00010420 in A, 0x00010421 in B",
        "cyclic frame 1, command 1 (LRW): expected WKC 4 in A, 5 in B",
        "input EL1809.Channel 1-16.Input: only in A",
        "input EL1809.Inputs: only in B",
        "4 differences: 1 slave, 1 cyclic command, 2 variables",
    ]


CORPUS_ENIS = corpus_files("eni", "*.xml")
EXAMPLE_ENIS = sorted((VALID_PATH.parents[3] / "lolacli" / "eni_examples").glob("*.xml"))


@pytest.mark.parametrize("other", CORPUS_ENIS + EXAMPLE_ENIS, ids=lambda p: p.name)
def test_no_python_values_in_the_words(cli, other):
    """Against the LOLA chain, every corpus ENI differs in many ways (slaves only in one,
    names, identities, cyclic commands, variables): each line is words and numbers with
    units, and the JSON's messages say the same."""
    lola = EXAMPLE_ENIS[[p.name for p in EXAMPLE_ENIS].index("lola.xml")]
    code, out, _ = cli("eni", "diff", str(lola), str(other))
    assert code == (0 if other == lola else 1)
    for bad in ("{", "}", "None", "': ", "->", "(s)"):
        assert bad not in out, (bad, [line for line in out.splitlines() if bad in line])
    code, report = diff_json(cli, lola, other)
    said = " ".join(out.split())
    assert all(c["message"].split("; ")[0] in said for c in report["changes"])
    assert ("no differences" in out) == (other == lola)


def test_a_changed_slave_says_each_field(tmp_path):
    """Identity, address, sizes: one line each, in the form of every other command."""
    eni_a = parse_eni(VALID.encode())
    b = (
        VALID.replace("<RevisionNo>66592</RevisionNo>", "<RevisionNo>66593</RevisionNo>", 1)
        .replace("<AutoIncAddr>65535</AutoIncAddr>", "<AutoIncAddr>65534</AutoIncAddr>", 1)
    )
    changes = diff_eni(eni_a, parse_eni(b.encode()))
    lines = [line for c in changes for line in c.describe()]
    assert any("revision 0x00010420 in A, 0x00010421 in B" in line for line in lines), lines
    assert any("auto-increment address 0xFFFF in A, 0xFFFE in B" in line for line in lines)


def test_states_are_a_set_in_state_machine_order(cli, tmp_path):
    """The <State>s a cyclic command is sent in are a set: listed in another order they
    are the same ENI; a real difference, and inspect, write them in the state machine's
    order (rocos eni1 lists SAFEOP, PREOP, OP)."""
    files = corpus_files("eni", "rocos-ethercat__eni1.xml")
    if not files:
        pytest.skip("corpus not found")
    a = files[0]
    text = a.read_text()
    listed = "<State>SAFEOP</State>\n\t\t\t\t\t<State>PREOP</State>"
    assert text.count(listed) == 2
    swapped = text.replace(listed, "<State>PREOP</State>\n\t\t\t\t\t<State>SAFEOP</State>")
    code, report = diff_json(cli, a, write(tmp_path, "swapped.xml", swapped))
    assert (code, report["changes"]) == (0, [])

    no_op = text.replace(listed + "\n\t\t\t\t\t<State>OP</State>", listed, 1)
    code, out, _ = cli("eni", "diff", str(a), str(write(tmp_path, "no-op.xml", no_op)))
    assert code == 1
    assert "states PREOP, SAFEOP, OP in A, PREOP, SAFEOP in B" in " ".join(out.split())

    code, out, _ = cli("eni", "inspect", str(a))
    assert code == 0
    rows = [line for line in out.splitlines() if line.startswith(("LRD", "LWR"))]
    assert len(rows) == 2 and all(row.rstrip().endswith("  PREOP, SAFEOP, OP") for row in rows)
    code, out, _ = cli("eni", "inspect", str(a), "-f", "json")
    datagrams = [d for f in json.loads(out)["cyclic_frames"] for d in f["datagrams"]]
    assert [d["states"] for d in datagrams] == [["PREOP", "SAFEOP", "OP"]] * 2
