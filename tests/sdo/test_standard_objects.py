"""CiA 301 / ETG.1000.6 communication objects known without a dictionary: their types
and names (what `sdo read` shows where no EDS/ESI/SDO Information is asked)."""

from __future__ import annotations

import pytest


@pytest.mark.parametrize(
    ("index", "sub", "name"),
    [
        (0x1000, 0, "Device type"),
        (0x1008, 0, "Manufacturer device name"),
        (0x1018, 0, "Number of entries"),
        (0x1018, 3, "Revision number"),
        (0x1601, 2, "Mapped object 2"),
        (0x1010, 2, "Save communication parameters"),
        (0x1281, 3, "Node-ID of the server"),
        (0x1801, 2, "Transmission type"),
        (0x1C12, 1, "Assigned PDO 1"),
        (0x6041, 0, ""),  # a device profile object: not a communication object
        (0x2000, 0, ""),
    ],
)
def test_standard_names_of_the_communication_objects(index: int, sub: int, name: str) -> None:
    from lolacli.od.cia301 import standard_name

    assert standard_name(index, sub) == name


@pytest.mark.parametrize(
    ("index", "name"),
    [
        (0x1600, "RPDO mapping parameter 1"),  # CiA 301 counts PDOs from 1
        (0x1601, "RPDO mapping parameter 2"),
        (0x1A00, "TPDO mapping parameter 1"),
        (0x1800, "TPDO communication parameter 1"),
        (0x1C12, "Sync manager 2 PDO assignment"),
        (0x1018, "Identity object"),
    ],
)
def test_standard_objects_are_named(index: int, name: str) -> None:
    from lolacli.od.cia301 import standard_object

    obj = standard_object(index, 2)
    assert obj is not None and obj.name == name
