"""lolacli.emulator.run: the library under ``bus emulate`` (serving itself is tested on a
veth pair in test_masters.py and test_placement.py)."""

from __future__ import annotations

import time

import pytest

from lolacli.emulator.rawsock import ServerStats
from lolacli.emulator.run import EmulateOptions, Emulation, parse_cpu
from lolacli.errors import UsageError
from lolacli.files import load_eni, lola_path
from lolacli.wire.commands import Command
from lolacli.wire.frame import Datagram, encode_frame, make_frame


@pytest.mark.parametrize(("text", "where"), [("follow", "follow"), ("any", "any"), ("3", 3)])
def test_parse_cpu(text: str, where: int | str) -> None:
    assert parse_cpu(text) == where


@pytest.mark.parametrize("text", ["x", "-1", "1.5", ""])
def test_parse_cpu_refuses(text: str) -> None:
    with pytest.raises(UsageError, match="expected follow, any or a CPU number"):
        parse_cpu(text)


def test_bad_options_fail_before_anything_is_served() -> None:
    with pytest.raises(UsageError, match="--stuck-safeop 99"):
        Emulation(load_eni(lola_path()), EmulateOptions(stuck_safeop=(99,)))


def test_status_counts_what_the_chain_did() -> None:
    emulation = Emulation(load_eni(lola_path()), EmulateOptions())
    n = len(emulation.chain.slaves)
    brd = encode_frame(make_frame([Datagram.physical(Command.BRD, 0, 0x0130, 2)]), pad=True)
    for i in range(3):
        emulation.chain.process(brd, i * 1000)
    stats = ServerStats(started_ns=time.monotonic_ns() - 2_000_000_000)
    status = emulation.status(stats)
    assert (status.frames, status.lost, status.damaged) == (3, 0, 0)
    assert 1.0 < status.frames_per_s <= 1.5  # 3 frames in a little over 2 s
    assert status.states == f"INIT×{n}"
    assert emulation.esi == ()
