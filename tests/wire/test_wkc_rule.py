"""The working-counter rule (ETG.1000.4 §5.2, Table 13), the one every layer uses."""

from __future__ import annotations

import pytest

from lolacli.wire.commands import Command, addressed_wkc, wkc_increment

C = Command


@pytest.mark.parametrize(
    ("cmd", "read_only", "write_only", "both"),
    [
        (C.APRD, 1, 0, 1), (C.FPRD, 1, 0, 1), (C.BRD, 1, 0, 1), (C.LRD, 1, 0, 1),
        (C.APWR, 0, 1, 1), (C.FPWR, 0, 1, 1), (C.BWR, 0, 1, 1), (C.LWR, 0, 1, 1),
        (C.APRW, 1, 2, 3), (C.FPRW, 1, 2, 3), (C.BRW, 1, 2, 3), (C.LRW, 1, 2, 3),
        (C.ARMW, 1, 1, 1), (C.FRMW, 1, 1, 1), (C.NOP, 0, 0, 0),
    ],
)
def test_one_slave(cmd: Command, read_only: int, write_only: int, both: int) -> None:
    assert wkc_increment(cmd, read=True, write=False) == read_only
    assert wkc_increment(cmd, read=False, write=True) == write_only
    assert wkc_increment(cmd) == both
    assert wkc_increment(cmd, read=False, write=False) == 0


def test_addressed_commands_on_a_chain() -> None:
    # LOLA's 25 slaves: a BRD of AL status counts 25, the DC system time ARMW 25 (ENI <Cnt>)
    assert addressed_wkc(C.BRD, 25) == 25
    assert addressed_wkc(C.ARMW, 25) == 25
    assert addressed_wkc(C.BRW, 25) == 75
    assert addressed_wkc(C.FPRW, 25) == 3
    assert addressed_wkc(C.APRD, 25) == 1
    assert addressed_wkc(C.NOP, 25) == 0
    assert addressed_wkc(C.LRW, 25) is None
    assert wkc_increment(0xEE) == 0  # unknown command byte
