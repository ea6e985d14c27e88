"""One way to type and print a value: ``sdo read``, ``sdo write``, ``sdo check`` and ``sdo
list`` say the same data type, name and value of an entry (lolacli/od/lookup.py).

The same objects go through all four commands, in process: on the emulated LOLA chain
(identity, a PDO mapping entry, the drive's INTEGER8 mode and INTEGER32 target position,
a segmented VISIBLE_STRING, the gateway's REAL32), and on python-can's virtual bus
against canopen LocalNodes serving the gateway IMU's EDS and, for a BOOLEAN, the corpus's
python-canopen sample EDS; and on a drive whose ENI types an INTEGER24, a non-ASCII
VISIBLE_STRING, a REAL32 and a BOOLEAN, also against the drive's own SDO Information.
Each command's JSON gives the same ``data_type`` and ``name``;
each human line says ``NAME  TYPE = VALUE`` in the same words, and ``sdo list`` gives the
value the node starts with as its default in the same form.
"""

from __future__ import annotations

import itertools
import json
import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from lolacli.cli.main import app
from lolacli.sdo.node import NodeServer, NodeSpec, example_eds
from tests.conftest import CORPUS

_channels = itertools.count()
SAMPLE_EDS = CORPUS / "eds" / "python-canopen__sample.eds"


def _run(*args: str, width: int = 1000) -> tuple[int, str, str]:
    """The CLI in process, output as wide as ``width`` (one line per entry here)."""
    result = CliRunner().invoke(app, [str(a) for a in args], env={"COLUMNS": str(width)})
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception
    return result.exit_code, result.stdout, result.stderr


def _phrase(line: str, address: str) -> str:
    """What a human line says of the entry: everything after its address."""
    found = re.search(re.escape(address) + r"  (.*)$", line)
    assert found is not None, (address, line)
    return found.group(1)


class Bus:
    """One transport's options and what each command adds to them."""

    def __init__(self, options: list[str], list_options: list[str] | None = None) -> None:
        self.options = options
        self.list_options = options if list_options is None else list_options

    def read(self, slave: str, obj: str) -> tuple[dict, str]:
        code, out, err = _run("sdo", "read", slave, obj, *self.options, "-f", "json")
        assert code == 0, err
        doc = json.loads(out)
        code, human, err = _run("sdo", "read", slave, obj, *self.options)
        assert code == 0, err
        return doc, _phrase(human.strip(), doc["object"])

    def write(self, slave: str, obj: str, value: str) -> tuple[dict, str]:
        code, out, err = _run("sdo", "write", slave, obj, value, *self.options, "-f", "json")
        assert code == 0, err
        doc = json.loads(out)
        code, human, err = _run("sdo", "write", slave, obj, value, *self.options)
        assert code == 0, err
        return doc, _phrase(human.strip(), doc["object"])

    def check(self, tmp: Path, checks: dict) -> tuple[list[dict], list[str]]:
        path = tmp / f"check{next(_channels)}.json"
        path.write_text(json.dumps(checks))
        code, out, err = _run("sdo", "check", str(path), *self.options, "-f", "json")
        assert code == 0, (err, out)
        results = json.loads(out)["results"]
        code, human, err = _run("sdo", "check", str(path), *self.options)
        assert code == 0, err
        lines = human.strip().splitlines()[:-1]  # the last: "N checks: …"
        assert len(lines) == len(results)
        return results, [_phrase(line, r["object"]) for line, r in zip(lines, results, strict=True)]

    def listed(self, slave: str) -> tuple[dict[str, dict], dict[str, str]]:
        code, out, err = _run("sdo", "list", slave, *self.list_options, "-f", "json")
        assert code == 0, err
        entries = {e["object"]: e for o in json.loads(out)["objects"] for e in o["entries"]}
        code, human, err = _run("sdo", "list", slave, *self.list_options)
        assert code == 0, err
        rows = {line.split()[0]: line for line in human.splitlines()[2:] if line[:2] == "0x"}
        return entries, rows


def _same_everywhere(bus: Bus, tmp: Path, slave: str, reads: list[str], writes: dict) -> None:
    """Each object: read, checked, listed (and written, checked after the write) with the
    same type and name in every JSON and the same words in every human line."""
    entries, rows = bus.listed(slave)
    before = {obj: bus.read(slave, obj) for obj in reads}
    results, phrases = bus.check(
        tmp,
        {"slave": slave, "reads": [{"object": o, "expect": before[o][0]["value"]} for o in reads]},
    )
    for obj, result, phrase in zip(reads, results, phrases, strict=True):
        doc, said = before[obj]
        assert doc["name"], obj  # every sample has a name in some source
        assert (result["data_type"], result["name"]) == (doc["data_type"], doc["name"]), obj
        assert result["type_source"] == doc["type_source"], obj
        assert phrase == said, obj
        entry = entries[doc["object"]]
        assert (entry["data_type"], entry["name"]) == (doc["data_type"], doc["name"]), obj
        row = rows[doc["object"]]
        assert doc["name"] in row and f"  {doc['data_type']}  " in row, (obj, row)
        if entry["default"] is not None:  # a served EDS: the node starts with its default
            assert row.rstrip().endswith(said.split(" = ", 1)[1]), (obj, row, said)
    for obj, value in writes.items():
        doc, said = bus.write(slave, obj, value)
        results, phrases = bus.check(
            tmp,
            {
                "slave": slave,
                "writes": [{"object": obj, "value": value}],
                "reads": [{"object": obj, "expect": doc["value"]}],
            },
        )
        for result, phrase in zip(results, phrases, strict=True):
            assert (result["data_type"], result["name"]) == (doc["data_type"], doc["name"]), obj
            assert phrase == said, (obj, phrase, said)
        read, _ = before.get(obj) or bus.read(slave, obj)
        assert (read["data_type"], read["name"]) == (doc["data_type"], doc["name"]), obj


LOLA_READS = [
    "0x1018:01",
    "0x1018:02",
    "0x1018:03",
    "0x1018:04",
    "0x1000",
    "0x6060",
    "0x607A",
    "0x1600:01",
    "0x1008",
]


def test_the_lola_drive(tmp_path) -> None:
    bus = Bus([])
    _same_everywhere(bus, tmp_path, "5", LOLA_READS, {"0x6060": "8", "0x607A": "-1000"})
    mode, said = bus.read("5", "0x6060")
    assert (mode["data_type"], mode["type_source"], mode["name"]) == (
        "INTEGER8",
        "eni",
        "Modes of operation",
    )
    position, said = bus.write("5", "0x607A", "-1000")
    assert said == "Target position  INTEGER32 = -1000" and position["value"] == -1000
    ident, said = bus.read("5", "0x1018:01")
    assert said == "Vendor ID  UNSIGNED32 = 154 (0x0000009A)"


def test_the_lola_gateway_real32(tmp_path) -> None:
    bus = Bus([])
    _same_everywhere(bus, tmp_path, "22", ["0x6010:01", "0x1008"], {})
    rate, said = bus.read("22", "0x6010:01")
    assert (rate["data_type"], rate["name"]) == ("REAL32", "Angular rate X")
    assert said == "Angular rate X  REAL32 = 0.0"


@pytest.fixture
def can_nodes():
    """The gateway IMU (16) and, where the corpus is, the python-canopen sample (5)."""
    channel = f"lolacli-typing-{next(_channels)}"
    specs = [NodeSpec(example_eds("lola_imu.eds"), 16)]
    if SAMPLE_EDS.is_file():
        specs.append(NodeSpec(SAMPLE_EDS, 5))
    with NodeServer(channel, specs, interface="virtual"):
        yield ["--can", channel, "--interface", "virtual", "--timeout", "0.5"]


def test_the_gateway_imu_over_canopen(can_nodes, tmp_path) -> None:
    eds = ["--eds", str(example_eds("lola_imu.eds"))]
    bus = Bus([*can_nodes, *eds], eds)
    reads = ["0x1018:01", "0x1008", "0x2000", "0x2010:01", "0x1A00:01", "0x1000"]
    _same_everywhere(bus, tmp_path, "16", reads, {"0x2000": "500", "0x2010:01": "0.1"})
    bias, said = bus.read("16", "0x2010:01")  # written 0.1 just now: REAL32's own 0.1
    assert said == "Gyro bias X  REAL32 = 0.1" and bias["type_source"] == "eds"
    assert abs(bias["value"] - 0.1) < 1e-7


def test_a_boolean_over_canopen(can_nodes, tmp_path, corpus) -> None:
    eds = ["--eds", str(SAMPLE_EDS)]
    bus = Bus([*can_nodes, *eds], eds)
    # canopen's LocalNode has no value for 0x2005 until one is written
    _same_everywhere(bus, tmp_path, "5", ["0x1008"], {"0x2005": "true"})
    flag, said = bus.read("5", "0x2005")
    assert said == "BOOLEAN value  BOOLEAN = true" and flag["value"] is True


def test_without_a_dictionary_the_guess_is_said_once(can_nodes) -> None:
    """No --eds: CiA 301 types the identity; an object nobody describes is a guess from its
    bytes, said on stderr once, and the value is printed by the guessed type's rule."""
    code, out, err = _run("sdo", "read", "16", "0x1018:02", *can_nodes)
    assert code == 0 and out == "16 0x1018:02  Product code  UNSIGNED32 = 3089 (0x00000C11)\n"
    assert err == ""
    code, out, err = _run("sdo", "read", "16", "0x2000", *can_nodes, width=80)
    assert code == 0 and out == "16 0x2000:00  UNSIGNED16 = 1000 (0x03E8)\n"
    said = " ".join(err.split())
    assert err.count("lolacli: note:") == 1 and all(len(line) <= 80 for line in err.splitlines())
    assert "typed as UNSIGNED16 from its 2 bytes; give --type to choose" in said
    code, out, _ = _run("sdo", "read", "16", "0x2000", *can_nodes, "-f", "json")
    assert json.loads(out)["type_source"] == "guess" and json.loads(out)["name"] is None


def test_a_type_given_wins_and_a_disagreement_is_said(can_nodes) -> None:
    eds = ["--eds", str(example_eds("lola_imu.eds"))]
    code, out, err = _run(
        "sdo", "read", "16", "0x2000", *can_nodes, *eds, "-t", "i16", "-f", "json"
    )
    doc = json.loads(out)
    assert code == 0 and (doc["data_type"], doc["type_source"]) == ("INTEGER16", "--type")
    assert doc["name"] == "Sample rate"  # the name still from the EDS
    assert "0x2000:00 is UNSIGNED16 by eds; taken as INTEGER16 as --type says" in err


#: an RxPDO the ENI lists but assigns to no sync manager: objects of the drive typed by it
#: (INTEGER24, VISIBLE_STRING, REAL32, BOOLEAN), the process image unchanged
_TYPED_PDO = """
				<RxPdo Fixed="false" Mandatory="false">
					<Index>#x1601</Index>
					<Name>Typed samples</Name>
					<Entry><Index>#x2000</Index><SubIndex>1</SubIndex><BitLen>24</BitLen>
						<Name>Offset 24</Name><DataType>INT24</DataType></Entry>
					<Entry><Index>#x2000</Index><SubIndex>2</SubIndex><BitLen>48</BitLen>
						<Name>Label</Name><DataType>STRING(6)</DataType></Entry>
					<Entry><Index>#x2000</Index><SubIndex>3</SubIndex><BitLen>32</BitLen>
						<Name>Gain</Name><DataType>REAL</DataType></Entry>
					<Entry><Index>#x2000</Index><SubIndex>4</SubIndex><BitLen>1</BitLen>
						<Name>Enable</Name><DataType>BOOL</DataType></Entry>
				</RxPdo>"""
#: object, value written, type, value as printed, bytes on the wire
_TYPED = [
    ("0x2000:01", "-70000", "INTEGER24", "-70000", (-70000).to_bytes(3, "little", signed=True)),
    ("0x2000:02", "Maß 1°", "VISIBLE_STRING", '"Maß 1°"', "Maß 1°".encode("latin-1")),
    ("0x2000:03", "0.1", "REAL32", "0.1", bytes.fromhex("cdcccc3d")),
    ("0x2000:04", "true", "BOOLEAN", "true", b"\x01"),
]


def _typed_eni(tmp: Path) -> Path:
    from tests.live import EXAMPLES

    text = (EXAMPLES / "single_drive.xml").read_text()
    end = text.index("</RxPdo>") + len("</RxPdo>")
    path = tmp / "typed.xml"
    path.write_text(text[:end] + _TYPED_PDO + text[end:])
    return path


def test_one_entry_typed_alike_by_every_command_and_the_drives_sdo_information(tmp_path) -> None:
    """An INTEGER24, a VISIBLE_STRING with non-ASCII characters (latin-1 bytes on the wire),
    a REAL32 and a BOOLEAN of the emulated drive: sdo read, write, check and list say the
    same type, name and printed value; the drive's own SDO Information describes each with
    the same type, and a value typed by it alone prints the same."""
    from lolacli.od import access_text
    from lolacli.od.lookup import TypeLookup, describe
    from lolacli.sdo.client import read, write
    from lolacli.sdo.session import TransportOptions, open_session
    from lolacli.wire.datatypes import DataType

    eni = _typed_eni(tmp_path)
    bus = Bus(["--eni", str(eni)])
    objects = [obj for obj, *_ in _TYPED]
    _same_everywhere(bus, tmp_path, "1", objects, {obj: value for obj, value, *_ in _TYPED})
    for obj, value, kind, printed, _raw in _TYPED:
        code, out, err = _run("sdo", "check", _check_file(tmp_path, obj, value), "--eni", eni)
        assert code == 0, (err, out)
        assert f"{obj}  " in out and f"{kind} = {printed}" in out, out
    with open_session(TransportOptions(eni=eni)) as session:
        target = session.target("1")
        info = target.client.dictionary()  # the drive's SDO Information, read whole
        assert info is not None and info.source == "sdo-info"
        only_info = TypeLookup((info,))
        for obj, value, kind, printed, raw in _TYPED:
            index, sub = (int(part, 16) for part in obj.split(":"))
            described = info.entry(index, sub)
            assert described is not None and described.data_type == DataType[kind], obj
            assert access_text(0x3F) == described.access  # an output: rw in every state
            written = write(target.client, index, sub, value, lookup=target.lookup)
            assert written.raw == raw, obj
            by_info = read(target.client, index, sub, lookup=only_info)
            by_all = read(target.client, index, sub, lookup=target.lookup)
            assert (by_info.type_source, by_all.type_source) == ("sdo-info", "eni")
            assert by_info.data_type == by_all.data_type == kind, obj
            assert by_info.text == by_all.text == printed, obj
            said = describe(by_info.name, kind, by_info.text)
            assert said == f"{by_all.name}  {kind} = {printed}", obj


def _check_file(tmp: Path, obj: str, value: str) -> str:
    path = tmp / f"one{next(_channels)}.json"
    checks = {
        "slave": "1",
        "writes": [{"object": obj, "value": value}],
        "reads": [{"object": obj, "expect": value}],
    }
    path.write_text(json.dumps(checks, ensure_ascii=False), encoding="utf-8")
    return str(path)


@pytest.mark.parametrize(
    ("obj", "given", "said"),
    [
        ("0x1008", "u8", "UNSIGNED8 is 1 byte, not 137"),  # the drive's 137-byte name
        ("0x6061", "u16", "UNSIGNED16 is 2 bytes, not 1"),  # the INTEGER8 mode display
        ("0x6061", "unicode_string", "UNICODE_STRING of 1 byte (not a whole number"),
    ],
)
def test_a_type_that_does_not_fit_says_its_byte_counts(obj, given, said) -> None:
    """Bytes read that do not fit ``--type`` are shown as octets, the note counting the
    bytes in agreement with their number ("1 byte", never "1 bytes")."""
    code, out, err = _run("sdo", "read", "1", obj, "-t", given)
    assert code == 0 and "OCTET_STRING = " in out
    assert said in " ".join(err.split()) and "1 bytes" not in err


def test_a_guess_from_one_byte_says_one_byte() -> None:
    from lolacli.od.lookup import guess_note
    from lolacli.wire.datatypes import DataType

    note = guess_note(0x2000, 0, DataType.UNSIGNED8, b"\x05")
    assert "typed as UNSIGNED8 from its 1 byte;" in note
