"""The ENI's cyclic frames as prebuilt byte templates: outputs in, inputs out, WKC checked.

A :class:`CyclicFrame` of the ENI becomes a :class:`FramePlan`: the frame's bytes built
once, and three short lists of byte ranges — process-image outputs to copy into the frame
(``<OutputOffs>``), returned data to copy into the inputs image (``<InputOffs>``), and the
working counters to compare with ``<Cnt>``. A cycle then costs a few slice copies, not an
encode and a decode. Commands whose ``<State>`` list leaves out the master's state are not
sent in that state (ETG.2100 §"Cyclic").
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from operator import itemgetter
from typing import Any

from lolacli.eni.model import CyclicFrame
from lolacli.wire.commands import LOGICAL, Command
from lolacli.wire.frame import (
    DATAGRAM_HEADER_BYTES,
    ECAT_HEADER_BYTES,
    ETH_HEADER_BYTES,
    Datagram,
    encode_frame,
    make_frame,
)
from lolacli.wire.registers import Register

_U16 = struct.Struct("<H")
#: where each datagram's index byte is, relative to its header
_INDEX_OFFSET = 1
_SYSTEM_TIME_WRITES = frozenset({Command.APWR, Command.FPWR, Command.BWR})


@dataclass(frozen=True, slots=True)
class WkcCheck:
    datagram: int  # position in the frame
    offset: int  # of the WKC in the frame
    expected: int
    cmd: int


@dataclass(slots=True)
class FramePlan:
    """One cyclic frame for one master state (see the module docstring)."""

    template: bytearray
    index_offsets: tuple[int, ...]
    outputs: tuple[tuple[int, int, int], ...]  # (frame offset, image offset, length)
    inputs: tuple[tuple[int, int, int], ...]  # (frame offset, image offset, length)
    wkc: tuple[WkcCheck, ...]
    system_time: tuple[tuple[int, int], ...]  # (frame offset, length): master time written
    datagram_count: int
    logical: bool
    # the WKC bytes of a reply in one call, and what they are when every WKC is as
    # expected (take's usual case, without a loop over the checks)
    _wkc_bytes: Callable[[bytes], Any] = field(init=False, repr=False, compare=False)
    _wkc_expected: Any = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        places = [at for check in self.wkc for at in (check.offset, check.offset + 1)]
        self._wkc_bytes = itemgetter(*places) if places else (lambda reply: ())
        if all(0 <= check.expected <= 0xFFFF for check in self.wkc):
            self._wkc_expected = tuple(b for c in self.wkc for b in _U16.pack(c.expected))
        else:
            self._wkc_expected = None  # a WKC no reply can have: the loop counts it

    def build(self, index: int, outputs: bytearray, system_time_ns: int = 0) -> bytes:
        """The frame bytes for this cycle: ``index`` in every datagram, ``outputs`` copied."""
        buf = self.template
        for at in self.index_offsets:
            buf[at] = index
        for frame_at, image_at, n in self.outputs:
            buf[frame_at : frame_at + n] = outputs[image_at : image_at + n]
        for at, n in self.system_time:
            buf[at : at + n] = (system_time_ns & 0xFFFFFFFFFFFFFFFF).to_bytes(8, "little")[:n]
        return bytes(buf)

    def take(self, reply: bytes, inputs: bytearray) -> int:
        """Copy the returned inputs into ``inputs``; the number of WKC mismatches."""
        for frame_at, image_at, n in self.inputs:
            inputs[image_at : image_at + n] = reply[frame_at : frame_at + n]
        if self._wkc_bytes(reply) == self._wkc_expected:
            return 0
        bad = 0
        for check in self.wkc:
            if reply[check.offset] | reply[check.offset + 1] << 8 != check.expected:
                bad += 1
        return bad


def plan_frame(
    frame: CyclicFrame,
    state: str,
    *,
    inputs_bytes: int,
    outputs_bytes: int,
    source_mac: bytes,
    destination_mac: bytes,
) -> FramePlan | None:
    """The plan of ``frame`` in master state ``state`` ("SAFEOP", "OP", ...); ``None`` when
    no command of it is sent in that state."""
    commands = [c for c in frame.commands if not c.states or state in c.states]
    if not commands:
        return None
    datagrams: list[Datagram] = []
    for c in commands:
        if c.logical_address is not None:
            datagrams.append(Datagram.logical(c.cmd, c.logical_address, c.data_length_bytes))
        else:
            datagrams.append(Datagram.physical(c.cmd, c.adp or 0, c.ado or 0, c.data_length_bytes))
    raw = encode_frame(make_frame(datagrams, src=source_mac, dst=destination_mac), pad=True)
    pos = ETH_HEADER_BYTES + ECAT_HEADER_BYTES
    index_offsets, outs, ins, checks, times = [], [], [], [], []
    for i, c in enumerate(commands):
        data_at = pos + DATAGRAM_HEADER_BYTES
        n = c.data_length_bytes
        index_offsets.append(pos + _INDEX_OFFSET)
        writes = c.cmd in (Command.LRW, Command.LWR)
        reads = c.cmd in (Command.LRW, Command.LRD)
        if writes and c.output_offset_bytes is not None:
            outs.append(_span(data_at, c.output_offset_bytes, n, outputs_bytes))
        if reads and c.input_offset_bytes is not None:
            ins.append(_span(data_at, c.input_offset_bytes, n, inputs_bytes))
        if c.expected_wkc is not None:
            checks.append(WkcCheck(i, data_at + n, c.expected_wkc, c.cmd))
        if c.cmd in _SYSTEM_TIME_WRITES and c.ado == Register.DC_SYSTEM_TIME:
            times.append((data_at, min(n, 8)))
        pos = data_at + n + 2
    return FramePlan(
        bytearray(raw),
        tuple(index_offsets),
        tuple(s for s in outs if s[2] > 0),
        tuple(s for s in ins if s[2] > 0),
        tuple(checks),
        tuple(times),
        len(commands),
        any(c.cmd in LOGICAL for c in commands),
    )


def _span(frame_at: int, image_at: int, n: int, image_bytes: int) -> tuple[int, int, int]:
    """The part of a datagram's data that lies inside an image of ``image_bytes``."""
    return frame_at, image_at, max(0, min(n, image_bytes - image_at))


def image_sizes(
    frames: Sequence[CyclicFrame], inputs_bytes: int, outputs_bytes: int
) -> tuple[int, int]:
    """Image sizes that hold the ENI's process image and every cyclic command's range."""
    for frame in frames:
        for c in frame.commands:
            if c.input_offset_bytes is not None and c.cmd in (Command.LRW, Command.LRD):
                inputs_bytes = max(inputs_bytes, c.input_offset_bytes + c.data_length_bytes)
            if c.output_offset_bytes is not None and c.cmd in (Command.LRW, Command.LWR):
                outputs_bytes = max(outputs_bytes, c.output_offset_bytes + c.data_length_bytes)
    return inputs_bytes, outputs_bytes
