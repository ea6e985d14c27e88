"""The one lookup of an entry's type and name, and the one way a value is printed
(lolacli/od/lookup.py), on real dictionaries: the LOLA ENI's PDO entries of drive 5,
the Elmo ESI that describes that drive, the gateway IMU's EDS."""

from __future__ import annotations

import math
import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from lolacli.eni.dictionary import from_eni
from lolacli.od import RECORD, Dictionary, OdEntry, OdObject
from lolacli.od.lookup import TypeLookup, format_real, format_value
from lolacli.sdo.files import esi_dictionary, load_eds
from lolacli.sdo.node import example_eds
from lolacli.wire.datatypes import DataType
from tests.conftest import CORPUS
from tests.live import LOLA

ELMO_ESI = CORPUS / "esi" / "elmo_ethercat_sdk__Elmo_ECAT_00010420_V11.xml"


@pytest.fixture(scope="module")
def drive5() -> tuple[Dictionary, Dictionary | None]:
    """(the ENI's PDO entries of LOLA drive 5, the Elmo ESI device it reports, if here)."""
    from lolacli.files import load_eni, load_esi

    slave = load_eni(LOLA).slaves[4]
    eni = from_eni(slave, str(LOLA))
    assert eni is not None
    esi = esi_dictionary([load_esi(ELMO_ESI)], slave.identity) if ELMO_ESI.is_file() else None
    return eni, esi


def test_the_eni_describes_the_mapped_objects(drive5) -> None:
    eni, _ = drive5
    mode = eni.entry(0x6060, 0)
    assert mode is not None and (mode.name, mode.data_type) == ("Modes of operation", 2)
    assert eni.object(0x607A) is not None and eni.object(0x607A).name == "Target position"
    assert eni.entry(0x1018, 1) is None  # not mapped: not the ENI's to say


def test_the_order_of_the_sources(drive5, corpus) -> None:
    eni, esi = drive5
    assert esi is not None
    both = TypeLookup((esi, eni))
    typed = both.entry_type(0x6060, 0)
    assert (typed.type_label, typed.source, typed.name) == ("INTEGER8", "esi", "Modes of operation")
    typed = TypeLookup((eni,)).entry_type(0x6060, 0)
    assert (typed.type_label, typed.source) == ("INTEGER8", "eni")
    typed = TypeLookup((eni,)).entry_type(0x1018, 2)  # nobody maps it: CiA 301
    assert (typed.type_label, typed.source, typed.name) == ("UNSIGNED32", "cia301", "Product code")
    typed = TypeLookup().entry_type(0x2345, 0)  # a write: no type, no guess
    assert (typed.data_type, typed.source, typed.note) == (None, "", "")
    typed = TypeLookup().entry_type(0x2345, 0, raw=b"\x01\x02\x03\x04")
    assert (typed.type_label, typed.source) == ("UNSIGNED32", "guess")
    assert typed.note.endswith("typed as UNSIGNED32 from its 4 bytes; give --type to choose")
    assert TypeLookup().entry_type(0x2345, 0, raw=b"LOLA-IMU").type_label == "UNSIGNED64"
    assert TypeLookup().entry_type(0x2345, 0, raw=b"LOLA-IMU1").type_label == "VISIBLE_STRING"
    assert TypeLookup().entry_type(0x2345, 0, raw=b"\x00\xff\x01").type_label == "OCTET_STRING"


def test_a_type_given_wins_and_says_when_it_disagrees(drive5) -> None:
    eni, _ = drive5
    typed = TypeLookup((eni,)).entry_type(0x6060, 0, explicit=DataType.UNSIGNED8)
    assert (typed.type_label, typed.source, typed.name) == (
        "UNSIGNED8",
        "--type",
        "Modes of operation",
    )
    assert typed.note == "0x6060:00 is INTEGER8 by eni; taken as UNSIGNED8 as --type says"
    same = TypeLookup((eni,)).entry_type(0x6060, 0, explicit=DataType.INTEGER8)
    assert same.note == ""


def test_a_name_from_a_later_source_when_the_first_has_none() -> None:
    """The type and the name are looked up apart: an entry a dictionary types but does
    not name takes its name from the next source that has one (here CiA 301)."""
    nameless = Dictionary(
        [OdObject.of(0x1018, "", RECORD, [OdEntry(0x1018, 1, "", DataType.UNSIGNED32)])], "eds"
    )
    typed = TypeLookup((nameless,)).entry_type(0x1018, 1)
    assert (typed.source, typed.name) == ("eds", "Vendor ID")


def test_the_gateway_eds() -> None:
    imu = load_eds(example_eds("lola_imu.eds"), 16)
    lookup = TypeLookup((imu,))
    typed = lookup.entry_type(0x2010, 1)
    assert (typed.type_label, typed.source, typed.name) == ("REAL32", "eds", "Gyro bias X")
    found = lookup.object(0x2010)
    assert found is not None and found[1] == "eds" and found[0].name == "Gyro bias"


@pytest.mark.parametrize(
    ("value", "data_type", "printed"),
    [
        (True, DataType.BOOLEAN, "true"),
        (False, DataType.BOOLEAN, "false"),
        (-1000, DataType.INTEGER32, "-1000"),
        (8, DataType.INTEGER8, "8"),
        (154, DataType.UNSIGNED32, "154 (0x0000009A)"),  # the Elmo vendor ID of the LOLA ENI
        (0x00020192, DataType.UNSIGNED32, "131474 (0x00020192)"),
        (8, DataType.UNSIGNED8, "8 (0x08)"),
        (0x1600, DataType.UNSIGNED16, "5632 (0x1600)"),
        (2**64 - 1, DataType.UNSIGNED64, "18446744073709551615 (0xFFFFFFFFFFFFFFFF)"),
        (0x0A, DataType.BYTE, "10 (0x0A)"),
        (0x8000, DataType.WORD, "32768 (0x8000)"),
        (3, DataType.BIT2, "3"),
        (0.0, DataType.REAL32, "0.0"),
        (struct.unpack("<f", struct.pack("<f", 0.1))[0], DataType.REAL32, "0.1"),
        (struct.unpack("<f", struct.pack("<f", 1 / 3))[0], DataType.REAL32, "0.33333334"),
        (1500.0, DataType.REAL32, "1500.0"),
        (0.1, DataType.REAL64, "0.1"),
        (math.nan, DataType.REAL32, "nan"),
        (-math.inf, DataType.REAL64, "-inf"),
        ("LOLA IMU (CAN gateway)", DataType.VISIBLE_STRING, '"LOLA IMU (CAN gateway)"'),
        ('say "hi"\n', DataType.VISIBLE_STRING, '"say \\"hi\\"\\n"'),
        (b"\x01\x02\xff", DataType.OCTET_STRING, "01 02 ff"),
        (b"", DataType.DOMAIN, "(empty)"),
        (42, None, "42"),  # no type known: decimal
    ],
)
def test_one_rule_per_type(value, data_type, printed) -> None:
    assert format_value(value, data_type) == printed


@given(st.floats(width=32, allow_nan=False, allow_infinity=False))
def test_a_real32_prints_as_a_decimal_that_reads_back_the_same(value: float) -> None:
    text = format_real(value, DataType.REAL32)
    assert struct.pack("<f", float(text)) == struct.pack("<f", value)
    assert len(text.lstrip("-").replace(".", "").split("e")[0].strip("0")) <= 9


@given(st.floats(allow_nan=False, allow_infinity=False))
def test_a_real64_prints_as_python_reads_it(value: float) -> None:
    assert float(format_real(value, DataType.REAL64)) == value
