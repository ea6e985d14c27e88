"""Fixtures of the master tests: a live bus in a namespace of its own (tests/live.py)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.live import LiveBus, make_bus, remove_bus


@pytest.fixture
def bus() -> Iterator[LiveBus]:
    """A fresh veth pair in a fresh network namespace, removed afterwards."""
    live = make_bus()
    try:
        yield live
    finally:
        remove_bus(live)
