"""The ENI writer: every ENI the parser reads comes back the same through write and parse."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from lolacli.eni.model import ConfiguredSyncManager, Direction, Pdo, PdoEntry
from lolacli.eni.parser import parse_eni
from lolacli.eni.writer import write_eni
from lolacli.errors import EniError
from lolacli.wire.registers import SyncManager
from tests.conftest import corpus_files, corpus_ids
from tests.eni.test_examples import EXAMPLES, NAMES

CORPUS_ENIS = corpus_files("eni", "*.xml")


def _round_trip(path: Path) -> None:
    try:
        first = parse_eni(path.read_bytes(), str(path))
    except EniError:
        pytest.skip("the parser refuses this file")
    written = write_eni(first)
    again = parse_eni(written, "written")
    assert again == replace(first, source="written")
    # and a second pass writes the very same bytes
    assert write_eni(again) == written


@pytest.mark.parametrize("name", NAMES)
def test_examples_round_trip(name):
    _round_trip(EXAMPLES / name)


@pytest.mark.parametrize("path", CORPUS_ENIS, ids=corpus_ids(CORPUS_ENIS))
def test_corpus_round_trip(path):
    _round_trip(path)


def test_declared_sync_managers_and_pdo_assignment_survive():
    """What no InitCmd writes (a generated ENI's declared SM, a PDO's Sm) is written too."""
    lola = parse_eni((EXAMPLES / "single_drive.xml").read_bytes(), "x")
    slave = lola.slaves[0]
    sm = ConfiguredSyncManager(5, SyncManager(0x1C00, 6, 0x20, activate=1), kind="Inputs")
    pdo = Pdo(0x1A07, "extra", Direction.INPUT, 5, (PdoEntry(0x6077, 0, 16, "Torque", "INT"),))
    changed = replace(slave, sync_managers=(*slave.sync_managers, sm), pdos=(*slave.pdos, pdo))
    eni = replace(lola, slaves=(changed,))
    back = parse_eni(write_eni(eni), "x")
    assert back.slaves[0].sync_managers[-1] == sm
    assert back.slaves[0].pdos[-1] == pdo
    assert back == eni
