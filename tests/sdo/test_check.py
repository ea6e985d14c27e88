"""``sdo check FILE``: the file's validation (one line, exit 3, line and item named) and runs
against the gateway's sensor nodes on a virtual bus (writes first, expected values, aborts)."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import pytest

from lolacli.errors import InputError
from lolacli.sdo.check import parse_check
from lolacli.sdo.node import NodeServer, example_eds, gateway_nodes

_channels = itertools.count()

GOOD = """\
# the gateway's IMU (node 16) and left foot sensor (node 17)
slave: 16
writes:
  - {object: "0x2001", value: 0x40}
  - {slave: 17, object: 0x2001, value: 150, type: UNSIGNED16}
reads:
  - {object: "0x1000", expect: 0x0000019A}
  - {object: "0x1008", expect: "LOLA IMU (CAN gateway)"}
  - {object: "0x2001", expect: 64}
  - {slave: 17, object: "0x2001", expect: "150"}
  - {slave: 17, object: "0x2020:01", expect: 1.0, type: REAL32}  # --eds is the IMU's
  - {slave: 17, object: "0x6020:01", expect: 0.0, tolerance: 100.0, type: REAL32}
  - {object: "0x2345", expect_abort: 0x06020000}
  - {object: "0x2002", expect_abort: "0x06010001"}
"""


@pytest.fixture
def channel():
    name = f"lolacli-check-{next(_channels)}"
    with NodeServer(name, gateway_nodes(), interface="virtual"):
        yield name


def _run(cli, channel: str, path: Path, *extra: str) -> tuple[int, str, str]:
    return cli(
        "sdo",
        "check",
        str(path),
        "--can",
        channel,
        "--interface",
        "virtual",
        "--timeout",
        "0.5",
        *extra,
    )


def test_all_pass(cli, channel, tmp_path) -> None:
    path = tmp_path / "imu.yaml"
    path.write_text(GOOD)
    eds = str(example_eds("lola_imu.eds"))
    code, out, err = _run(cli, channel, path, "--eds", eds, "-f", "json")
    assert code == 0, err + out
    doc = json.loads(out)
    assert doc["schema"] == "lolacli.sdo-check/1"
    assert (doc["checks"], doc["passed"], doc["failed"]) == (10, 10, 0)
    assert [r["kind"] for r in doc["results"]] == ["write"] * 2 + ["read"] * 8
    assert doc["results"][-2]["abort_code"] == "0x06020000" and doc["results"][-2]["ok"]
    code, out, _ = _run(cli, channel, path, "--eds", eds)
    assert code == 0 and out.endswith("10 checks: 10 passed, 0 failed\n")


def test_a_difference_and_an_unexpected_abort_are_exit_1(cli, channel, tmp_path) -> None:
    path = tmp_path / "bad.json"
    path.write_text(
        json.dumps(
            {
                "slave": 16,
                "reads": [
                    {"object": "0x1000", "expect": "0x19B"},
                    {"object": "0x2345", "expect": 1},
                    {"object": "0x1000", "expect_abort": "0x06020000"},
                    {"object": "0x1018:01", "expect": 3758096385},
                ],
            }
        )
    )
    code, out, _ = _run(cli, channel, path, "-f", "json")
    assert code == 1
    results = json.loads(out)["results"]
    assert [r["ok"] for r in results] == [False, False, False, True]
    assert results[0]["message"] == "expected 411 (0x0000019B), read 410 (0x0000019A)"
    assert (
        results[1]["abort_code"] == "0x06020000"
        and "object does not exist" in results[1]["message"]
    )
    assert "expected abort 0x06020000" in results[2]["message"]
    code, out, _ = _run(cli, channel, path)
    assert code == 1 and "FAIL read  16 0x1000:00" in out and "4 checks: 1 passed, 3 failed" in out


def test_a_bus_that_does_not_answer_is_exit_4(cli, channel, tmp_path) -> None:
    path = tmp_path / "c.yaml"
    path.write_text("slave: 99\nreads:\n  - {object: '0x1000', expect: 1}\n")
    assert _run(cli, channel, path)[0] == 4


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "not empty"),
        ("- 1\n- 2\n", "not a list"),
        ("slave: 1\nreeds: []\n", "unknown key 'reeds' (allowed: slave, writes, reads)"),
        ("slave: 1\n", "no checks"),
        ("reads:\n  - {object: '0x1000', expect: 1}\n", ":2: reads[0]: no slave"),
        (
            "slave: 1\nreads:\n\n  - {object: '0x1000', expct: 1}\n",
            ":4: reads[0]: unknown key 'expct'",
        ),
        ("slave: 1\nreads:\n  - {expect: 1}\n", "reads[0]: no object"),
        ("slave: 1\nreads:\n  - {object: '0x1000'}\n", "reads[0]: no expect"),
        ("slave: 1\nwrites:\n  - {object: '0x1000'}\n", "writes[0]: no value"),
        ("slave: 1\nreads:\n  - {object: 'zz:1', expect: 1}\n", "reads[0]: object:"),
        ("slave: 1\nreads:\n  - {object: '0x1000', expect: 1, type: NOPE}\n", "unknown data type"),
        ("slave: 1\nreads:\n  - {object: '0x1000', expect: [1]}\n", "not a number or a string"),
        ("slave: 1\nreads:\n  - {object: '0x1000', expect: 1, tolerance: -1}\n", "tolerance"),
        ("slave: 1\nreads:\n  - {object: '0x1000', expect_abort: 'x'}\n", "not an abort code"),
        ("slave: 1\nreads: {object: 1}\n", "reads: a list of items"),
        ("slave: 1\nreads:\n  - 5\n", "reads[0]: an item is a mapping"),
        ("slave: [1]\nreads: []\n", "slave: [1]"),
        ("reads: [\n", "not YAML/JSON"),
        ('{"slave": 1, "reads": [{"object": "0x1000", "expect": 1}]', "not YAML/JSON"),
    ],
)
def test_bad_files_name_the_problem(text: str, message: str) -> None:
    with pytest.raises(InputError) as exc:
        parse_check(text, "c.yaml")
    line = str(exc.value)
    assert line.startswith("c.yaml") and "\n" not in line
    if message == "not empty":
        assert "not empty" in line or "empty" in line
    else:
        assert message in line


def test_bad_file_is_exit_3_before_any_bus(cli, tmp_path) -> None:
    path = tmp_path / "c.yaml"
    path.write_text("slave: 1\nreads:\n  - {object: '0x1000'}\n")
    code, out, err = cli("sdo", "check", str(path), "--can", "unused", "--interface", "nosuch")
    assert code == 3 and out == "" and "c.yaml:3: reads[0]: no expect" in err
    code, _out, err = cli("sdo", "check", str(tmp_path / "missing.yaml"), "--can", "x")
    assert code == 3 and "no such file" in err



@pytest.mark.parametrize(
    ("name", "text", "where", "message"),
    [
        (
            "unknown-top-key.yaml",
            "slave: 1\nreads:\n  - {object: '0x1000', expect: 1}\nextra: 2\n",
            4,
            "unknown key 'extra' (allowed: slave, writes, reads)",
        ),
        (
            "value-not-its-type.yaml",
            "slave: 1\nwrites:\n  - object: '0x2000'\n    type: u16\n    value: 70000\n",
            5,
            "writes[0]: value: 70000 is out of range for UNSIGNED16 (0..65535)",
        ),
        (
            "expect-not-its-type.yaml",
            "slave: 1\nreads:\n  - object: '0x1000'\n    expect: abc\n    type: u32\n",
            4,
            "reads[0]: expect: 'abc' is not an integer (UNSIGNED32)",
        ),
        (
            "expect-null.yaml",
            "slave: 1\nreads:\n  - object: '0x1000'\n    expect: null\n",
            4,
            "reads[0]: expect: empty (null)",
        ),
        (
            "bad-key-in-item.yaml",
            "slave: 1\nreads:\n  - object: '0x1000'\n    expect: 1\n    tolerance: -3\n",
            5,
            "reads[0]: tolerance: -3 is not a finite number >= 0",
        ),
        (
            "tolerance-nan.yaml",
            "slave: 1\nreads:\n  - object: '0x1000'\n    expect: 1\n    tolerance: .nan\n",
            5,
            "reads[0]: tolerance: nan is not a finite number >= 0",
        ),
        (
            "tolerance-inf.yaml",
            "slave: 1\nreads:\n  - object: '0x1000'\n    expect: 1\n    tolerance: .inf\n",
            5,
            "reads[0]: tolerance: inf is not a finite number >= 0",
        ),
        (
            "tolerance-nan.json",
            '{"slave": 1, "reads": [{"object": "0x1000", "expect": 1,\n  "tolerance": NaN}]}\n',
            2,
            "reads[0]: tolerance: 'NaN' is not a finite number >= 0",  # YAML: a string
        ),
        (
            "trailing-comma.json",
            '{\n  "slave": 1,\n  "reads": [{"object": "0x1000", "expect": 1},]\n}\n',
            3,
            "not JSON: Expecting value",
        ),
        (
            "unclosed.yaml",
            "slave: 1\nreads:\n  - {object: '0x1000', expect: 1\n",
            4,
            "not YAML/JSON: expected ',' or '}'",
        ),
    ],
)
def test_a_bad_file_names_file_and_line_once(cli, tmp_path, name, text, where, message) -> None:
    path = tmp_path / name
    path.write_text(text)
    code, out, err = cli("sdo", "check", str(path), "--can", "unused", "--interface", "nosuch")
    assert code == 3 and out == "", err
    assert err.count("\n") == 1 and err.count(str(path)) == 1, err
    assert err.startswith(f"lolacli: error: {path}:{where}: {message}"), err


def test_json_indented_with_tabs_is_json(tmp_path) -> None:
    """JSON may be indented with tabs, which YAML refuses: it is still read, its lines kept."""
    text = '{\n\t"slave": 16,\n\t"reads": [\n\t\t{"object": "0x1000", "expct": 1}\n\t]\n}\n'
    with pytest.raises(InputError) as exc:
        parse_check(text, "tabs.json")
    assert str(exc.value).startswith("tabs.json:4: reads[0]: unknown key 'expct'")
    good = parse_check(text.replace("expct", "expect"), "tabs.json")
    assert [(i.slave, i.address.index, i.value) for i in good.items] == [("16", 0x1000, 1)]
