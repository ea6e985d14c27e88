"""INDEX[:SUB] and SLAVE resolution over the ENI model (pure)."""

from __future__ import annotations

import pytest

from lolacli.errors import UsageError
from lolacli.files import load_eni
from lolacli.sdo.address import ObjectAddress, parse_node_id, parse_object, resolve_slave
from tests.emulator.bus import EXAMPLES


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("0x6041", (0x6041, 0)),
        ("6041", (0x6041, 0)),
        ("#x1018:01", (0x1018, 1)),
        ("0x1018:0x0A", (0x1018, 10)),
        ("1A00:10", (0x1A00, 16)),  # hexadecimal, as listings (ours too) write it
        (" 0x1c12:1 ", (0x1C12, 1)),
    ],
)
def test_parse_object(text: str, expected: tuple[int, int]) -> None:
    assert parse_object(text) == ObjectAddress(*expected)
    assert str(parse_object(text)) == f"0x{expected[0]:04X}:{expected[1]:02X}"


@pytest.mark.parametrize("text", ["", "zz", "0x10000", "0x1000:100", "0x1000:", ":1", "0x1000:1:2"])
def test_bad_objects_are_usage_errors(text: str) -> None:
    with pytest.raises(UsageError):
        parse_object(text)


def test_resolve_slave_over_the_lola_eni() -> None:
    eni = load_eni(EXAMPLES / "lola.xml")
    assert resolve_slave("5", eni).position == 5
    gateway = resolve_slave("@1022", eni)
    assert gateway.position == 22 and gateway.name == "CAN Gateway (IMU, FTS)"
    assert resolve_slave("@0x3FE", eni) == gateway
    assert resolve_slave("CAN Gateway (IMU, FTS)", eni) == gateway  # exact
    assert resolve_slave("can gateway (imu, fts)", eni) == gateway  # case-insensitive
    assert resolve_slave("gateway", eni) == gateway  # a unique part
    with pytest.raises(UsageError, match="ambiguous"):
        resolve_slave("Joint", eni)
    with pytest.raises(UsageError, match="position 26 .*positions 1 to 25"):
        resolve_slave("26", eni)
    with pytest.raises(UsageError, match=r"station address 0x1001 \(4097\)"):
        resolve_slave("@0x1001", eni)
    with pytest.raises(UsageError, match="no slave named"):
        resolve_slave("nobody", eni)


def test_node_ids() -> None:
    assert parse_node_id("0x10") == 16
    for bad in ("0", "128", "x"):
        with pytest.raises(UsageError):
            parse_node_id(bad)


def test_abort_table_covers_cia_301() -> None:
    """One table (wire/sdo.py): every code canopen knows (CiA 301 Table 22) has a text,
    every named code too; unknown codes still read as a line."""
    from canopen.sdo.exceptions import SdoAbortedError

    from lolacli.wire.sdo import SdoAbortCode, abort_text

    for code in [*SdoAbortedError.CODES, *SdoAbortCode]:
        assert abort_text(code) != "unknown abort code", hex(code)
    assert abort_text(0x12345678) == "unknown abort code"
