"""Fixtures of the master tests: a veth pair for a live bus (see tests/master/live.py)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.master.live import make_veth, remove_veth


@pytest.fixture
def veth() -> Iterator[tuple[str, str]]:
    """A fresh veth pair (master end, emulator end), removed afterwards."""
    master, emulator = make_veth()
    try:
        yield master, emulator
    finally:
        remove_veth(master)
