"""Hostile and broken ENI files through the CLI: exit 3, one stderr line naming the file
(and the line where known), no traceback, nothing resolved, each within 2 s."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from lolacli.eni.parser import parse_eni
from lolacli.errors import EniError

FIXTURES = Path(__file__).resolve().parent.parent / "fixtures" / "eni"
SECRET = "lolacli-secret-7f3a9c"

#: fixture -> (line expected in the message or None, words expected in the message)
BROKEN = {
    "eni-billion-laughs.xml": (2, "DOCTYPE"),
    "eni-quadratic-blowup.xml": (2, "DOCTYPE"),
    "eni-xxe-http.xml": (2, "DOCTYPE"),
    "eni-external-dtd.xml": (2, "DOCTYPE"),
    "eni-truncated.xml": (7, "not well-formed"),
    "eni-mismatched-tag.xml": (5, "not well-formed"),
    "eni-wrong-root.xml": (2, "not an ENI"),
    "eni-missing-physaddr.xml": (5, "PhysAddr"),
    "eni-bad-number.xml": (8, "not a number"),
    "eni-not-xml.bin": (1, "not well-formed"),
}


def run_timed(cli, *args: str) -> tuple[int, str, str, float]:
    start = time.perf_counter()
    code, out, err = cli(*args)
    return code, out, err, time.perf_counter() - start


def assert_one_line_error(code: int, out: str, err: str, path: Path, line: int | None) -> str:
    assert code == 3, (code, out, err)
    assert "Traceback" not in err and "Traceback" not in out
    lines = err.splitlines()
    assert len(lines) == 1, err
    message = lines[0]
    assert message.startswith("lolacli: error: ")
    where = f"{path}:{line}:" if line is not None else f"{path}:"
    assert where in message, message
    assert out == ""
    return message


@pytest.mark.parametrize("name", sorted(BROKEN))
@pytest.mark.parametrize("command", ["inspect", "vars", "validate"])
def test_broken_file_exits_3_with_one_line(cli, name, command):
    path = FIXTURES / name
    line, words = BROKEN[name]
    code, out, err, seconds = run_timed(cli, "eni", command, str(path))
    message = assert_one_line_error(code, out, err, path, line)
    assert words in message
    assert seconds < 2.0


def test_diff_with_a_broken_side_exits_3(cli):
    good, bad = FIXTURES / "eni-small-valid.xml", FIXTURES / "eni-truncated.xml"
    code, out, err = cli("eni", "diff", str(good), str(bad))
    assert_one_line_error(code, out, err, bad, 7)


def xxe_document(secret_file: Path) -> str:
    return (
        '<?xml version="1.0"?>\n'
        f'<!DOCTYPE EtherCATConfig [ <!ENTITY xxe SYSTEM "file://{secret_file}"> ]>\n'
        "<EtherCATConfig><Config><Master><Info><Name>&xxe;</Name></Info></Master>"
        "</Config></EtherCATConfig>\n"
    )


def test_xxe_file_entity_is_not_resolved(cli, tmp_path):
    secret = tmp_path / "secret.txt"
    secret.write_text(SECRET)
    eni = tmp_path / "eni-xxe-file.xml"
    eni.write_text(xxe_document(secret))
    for command in ("inspect", "vars", "validate"):
        code, out, err, seconds = run_timed(cli, "eni", command, str(eni), "--format", "json")
        assert_one_line_error(code, out, err, eni, 2)
        assert SECRET not in out + err
        assert seconds < 2.0


def test_xxe_in_utf16_is_refused_by_the_defused_gate(tmp_path):
    """UTF-16 hides the DOCTYPE from the byte scan; defusedxml's expat gate still stops it."""
    secret = tmp_path / "secret.txt"
    secret.write_text(SECRET)
    doc = xxe_document(secret).replace(
        '<?xml version="1.0"?>', '<?xml version="1.0" encoding="UTF-16"?>'
    )
    with pytest.raises(EniError) as info:
        parse_eni(doc.encode("utf-16"), "utf16.xml")
    assert info.value.path == "utf16.xml" and info.value.line == 2
    assert "DTDForbidden" in str(info.value)
    assert SECRET not in str(info.value)


def test_lxml_layer_alone_resolves_nothing(tmp_path):
    """Defence in depth: even past the gate, the lxml parser loads no DTD and no entity."""
    from lolacli.eni import parser as eni_parser

    secret = tmp_path / "secret.txt"
    secret.write_text(SECRET)
    with pytest.raises(EniError) as info:
        eni_parser._lxml_root(xxe_document(secret).encode(), "x.xml")
    assert "DOCTYPE" in str(info.value)


def test_library_error_carries_path_and_line():
    with pytest.raises(EniError) as info:
        parse_eni((FIXTURES / "eni-missing-physaddr.xml").read_bytes(), "m.xml")
    assert (info.value.path, info.value.line, info.value.exit_code) == ("m.xml", 5, 3)


@pytest.mark.parametrize(
    "data, words",
    [
        (b"", "empty"),
        (b"   \n", "empty"),
        (b"<EtherCATConfig/>", "no <Config>"),
        (b"<EtherCATConfig>&undefined;</EtherCATConfig>", "not well-formed"),
        (b"<a><b></a>", "not well-formed"),
        (b"\xff\xfe\x00garbage", "not well-formed"),
    ],
)
def test_small_broken_inputs(data, words):
    with pytest.raises(EniError) as info:
        parse_eni(data, "s.xml")
    assert words in str(info.value)


def test_missing_file_exits_3(cli, tmp_path):
    missing = tmp_path / "nope.xml"
    code, out, err = cli("eni", "inspect", str(missing))
    message = assert_one_line_error(code, out, err, missing, None)
    assert "no such file" in message


def test_directory_exits_3(cli, tmp_path):
    code, out, err = cli("eni", "validate", str(tmp_path))
    assert_one_line_error(code, out, err, tmp_path, None)


def test_deep_nesting_is_refused_quickly(tmp_path):
    deep = b"<EtherCATConfig>" + b"<a>" * 100_000 + b"</a>" * 100_000 + b"</EtherCATConfig>"
    start = time.perf_counter()
    with pytest.raises(EniError):
        parse_eni(deep, "deep.xml")
    assert time.perf_counter() - start < 2.0


# --------------------------------------------------------------------------- not an ENI at all


def _corpus_file(kind: str, name: str) -> Path:
    from tests.conftest import CORPUS

    path = CORPUS / kind / name
    if not path.is_file():
        pytest.skip(f"corpus file {path} not found")
    return path


@pytest.mark.parametrize(
    ("name", "kind"),
    [
        ("ethercrab__twincat-run-ek1100-el1004.pcapng", "pcapng"),
        ("DERIVED__ethercrab__twincat-run-ek1100-el1004.classic.pcap", "pcap"),
    ],
)
@pytest.mark.parametrize(
    "command", [("eni", "inspect"), ("eni", "validate"), ("bus", "timing", "--eni")]
)
def test_a_capture_given_as_an_eni_is_named_as_one(cli, name, kind, command):
    path = _corpus_file("pcap", name)
    code, out, err = cli(*command, str(path))
    message = assert_one_line_error(code, out, err, path, None)
    assert message == (
        f"lolacli: error: {path}: this is a {kind} capture, not an ENI "
        f"(read it with: lolacli capture analyze {path})"
    )


def test_an_eds_given_as_an_eni_is_named_as_one(cli):
    path = _corpus_file("eds", "ros_canopen__prbt_0_1.dcf")
    code, out, err = cli("eni", "vars", str(path))
    message = assert_one_line_error(code, out, err, path, None)
    assert "this is a CANopen EDS/DCF, not an ENI" in message and "--eds" in message


def test_an_esi_given_as_an_eni_is_named_as_one(cli):
    path = _corpus_file("esi", "soes__EasyCAT_V2_0.xml")
    code, out, err = cli("eni", "inspect", str(path))
    message = assert_one_line_error(code, out, err, path, 2)
    assert "this is an ESI device description (<EtherCATInfo>), not an ENI" in message
    assert "--esi" in message


def test_an_eni_given_as_an_esi_is_named_as_one():
    from lolacli.files import load_esi

    path = FIXTURES / "eni-small-valid.xml"
    with pytest.raises(EniError) as info:
        load_esi(path)
    assert info.value.path == str(path) and info.value.line is not None
    assert "this is an ENI (<EtherCATConfig>), not an ESI" in str(info.value)
    assert f"lolacli eni inspect {path}" in str(info.value)


def test_a_capture_given_as_an_esi_is_named_as_one():
    from lolacli.files import load_esi

    path = _corpus_file("pcap", "ethercrab__twincat-run-ek1100-el1004.pcapng")
    with pytest.raises(EniError, match="this is a pcapng capture, not an ESI"):
        load_esi(path)


# --------------------------------------------------------------------------- no slaves

NO_SLAVES = (
    "<EtherCATConfig><Config><Master><Info><Name>m</Name></Info></Master>"
    "<Cyclic><CycleTime>1000</CycleTime><Frame><Cmd><Cmd>7</Cmd><Adp>0</Adp><Ado>#x130</Ado>"
    "<DataLength>2</DataLength></Cmd></Frame></Cyclic></Config></EtherCATConfig>"
)


@pytest.mark.parametrize(
    "command",
    [
        ("bus", "simulate", "--cycles", "3", "--eni"),
        ("bus", "emulate", "-i", "nosuchif0", "--duration", "0.1", "--eni"),
        ("sdo", "read", "1", "0x1018:01", "--eni"),
    ],
    ids=["simulate", "emulate", "sdo-read"],
)
def test_an_eni_without_slaves_cannot_be_run(cli, tmp_path, command):
    """`eni validate` fails it (no-slaves); the commands that need a chain say so."""
    path = tmp_path / "no-slaves.xml"
    path.write_text(NO_SLAVES)
    code, out, err = cli(*command, str(path))
    message = assert_one_line_error(code, out, err, path, None)
    assert "the ENI has no <Slave>" in message
