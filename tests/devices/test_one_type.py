"""One data type per ENI type name: what the ``sdo`` commands read from an ENI's PDO
entries (lolacli/eni/dictionary.py), the emulated device's own dictionary (served by its
SDO Information) and the PDO entries of the emulated SII all say the same CoE type code,
on the embedded LOLA chain and every corpus ENI."""

from __future__ import annotations

import pytest

from lolacli.devices import device_for
from lolacli.emulator.sii import sii_from_slave
from lolacli.eni.dictionary import from_eni
from lolacli.files import load_eni
from lolacli.wire.datatypes import DataType
from lolacli.wire.sii import SiiCategory, decode_sii_pdos, sii_categories
from tests.conftest import corpus_files, corpus_ids
from tests.live import EXAMPLES

ENIS = [EXAMPLES / "lola.xml", *corpus_files("eni", "*.xml")]


@pytest.mark.parametrize("path", ENIS, ids=corpus_ids(ENIS))
def test_eni_device_and_sii_type_alike(path) -> None:
    eni = load_eni(path)
    typed = described_any = 0
    for slave in eni.slaves:
        described = from_eni(slave)
        if described is None:
            continue
        described_any += 1
        device = device_for(slave)
        image = sii_categories(sii_from_slave(slave))
        sii = {
            (e.index, e.subindex): e.data_type
            for kind in (SiiCategory.TXPDO, SiiCategory.RXPDO)
            for pdo in decode_sii_pdos(image.get(kind, b""))
            for e in pdo.entries
        }
        for entry in described.entries():
            assert entry.data_type is not None, (slave.name, entry)  # every name a type
            key = (entry.index, entry.subindex)
            served = device.od.entry(*key)
            assert served is not None, (slave.name, key)
            assert served.data_type == entry.data_type, (slave.name, key)
            assert sii.get(key) == entry.data_type, (slave.name, key)
            typed += 1
    assert typed > 0 or not described_any  # an ENI with no PDO entries types none


def test_names_the_corpus_uses() -> None:
    """The type names of the corpus's ENI entries, typed as ETG.1000.6 says."""
    from lolacli.wire.datatypes import data_type_from_name as typed

    assert typed("BIT") == typed("BOOL") == DataType.BOOLEAN
    assert typed("USINT") == DataType.UNSIGNED8 and typed("BYTE") == DataType.BYTE
    assert typed("ARRAY [0..7] OF BYTE") == DataType.OCTET_STRING
    assert typed("STRING(6)") == DataType.VISIBLE_STRING and typed("INT24") == DataType.INTEGER24
