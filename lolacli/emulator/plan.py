"""Frame plans: a repeated frame's work through the chain, worked out once.

A cyclic frame comes every cycle with the same datagrams (command, address, length);
only its data change. Which slave copies which bytes between the datagram and its memory
depends on registers that change rarely: FMMUs and sync managers (ETG.1000.4 §6.5, §6.7),
AL states (which SM buffers the PDI opens), station address and alias, the line itself.
A :class:`FramePlan` holds that work for one frame layout as slice copies between a
frame buffer and the slaves' memories, the DC time distribution as a list of slaves and
the BRD as an OR over memory views, with the WKC increments known in advance. It is valid
while the chain's epoch (bumped by every ESC on any such change) keeps its value.

Only frames made entirely of plannable datagrams get a plan — logical reads and writes
whose FMMUs write into process RAM or the digital outputs from 0x0F00 (and read from
anywhere), BRD of registers other than the DC system time, ARMW/FRMW of the DC system
time (4 or 8 bytes) — so nothing a plan does can change what a plan assumes, except a
slave entering OP on its first outputs (which keeps its SM buffers open: SAFEOP and OP
open the same ones). Everything else takes the general path, which gives the same bytes
(tests/emulator/test_plan.py compares them).

Datagrams are run one after the other over all slaves (datagram-major), not slave by
slave as the frame passes (slave-major): slaves only meet through the frame's bytes and
each datagram has its own, so the two orders give the same result.
"""

from __future__ import annotations

import operator
import struct
from collections.abc import Callable, Generator
from dataclasses import dataclass, field
from typing import Any

from lolacli.emulator import registers as r
from lolacli.emulator.esc import (
    PLAN_FREE_REGISTERS,
    DcClock,
    Esc,
    PortTimes,
    SmView,
    byte_aligned,
    system_time_loop,
)
from lolacli.wire.commands import Command, wkc_increment
from lolacli.wire.registers import Fmmu

_HEAD = struct.Struct("<BBHHH")  # cmd, index, adp, ado, length word
_U16 = struct.Struct("<H")
ECAT_TYPE_COMMANDS = 1
_MASK64 = (1 << 64) - 1
_LOGICAL = frozenset({Command.LRD, Command.LWR, Command.LRW})
_DC = frozenset({Command.ARMW, Command.FRMW})
PLANNABLE = _LOGICAL | _DC | {Command.BRD}

Key = tuple[int, ...]
NOT_COMPILED = object()  # FramePlan.compiled before the chain's core looked at the plan
#: work done in pieces: the generator yields between pieces and returns the result
Pieces = Generator[None, None, Any]


def finish(pieces: Pieces) -> Any:
    """Run ``pieces`` to the end; what it returns."""
    while True:
        try:
            next(pieces)
        except StopIteration as done:
            return done.value


def layout_key(frame: bytes) -> Key | None:
    """The layout of an untagged EtherCAT command frame: its length, the EtherCAT header
    word and each datagram's command, ADP, ADO and length word. ``None`` when the frame is
    not one (tagged, other types, malformed): the general path deals with those. Frames
    with equal keys are decoded alike, so a plan made from one fits the others."""
    n = len(frame)
    if n < 16 or frame[12] != 0x88 or frame[13] != 0xA4:
        return None
    word = frame[14] | frame[15] << 8
    end = 16 + (word & 0x7FF)
    if word >> 12 != ECAT_TYPE_COMMANDS or end > n:
        return None
    key = [n, word]
    pos = 16
    unpack = _HEAD.unpack_from
    while True:
        if pos + 10 > end:
            return None
        cmd, _index, adp, ado, lenw = unpack(frame, pos)
        pos += 12 + (lenw & 0x7FF)
        if pos > end:
            return None
        key += (cmd, adp, ado, lenw)
        if not lenw & 0x8000:
            return tuple(key)


@dataclass(slots=True)
class _Datagram:
    header: int
    cmd: int
    adp: int
    ado: int
    length: int

    @property
    def data(self) -> int:
        return self.header + 10

    @property
    def wkc(self) -> int:
        return self.header + 10 + self.length


def layout_check(key: Key) -> Callable[[bytes], bool]:
    """A test that a frame has the layout ``key`` (``layout_key(frame) == key``) in one
    C-level pass over the bytes the key comes from: the frame's length, the EtherType and
    EtherCAT header word, and each datagram's command, ADP, ADO and length word."""
    places: list[int | slice] = [slice(12, 16)]
    want: list[int | bytes] = [bytes((0x88, 0xA4)) + _U16.pack(key[1])]
    for i, d in enumerate(_datagrams(key)):
        places += [d.header, slice(d.header + 2, d.header + 8)]
        want += [d.cmd, struct.pack("<HHH", d.adp, d.ado, key[5 + 4 * i])]
    fields = operator.itemgetter(*places)
    n, expected = key[0], tuple(want)

    def check(frame: bytes) -> bool:
        return len(frame) == n and fields(frame) == expected

    return check


def _datagrams(key: Key) -> list[_Datagram]:
    out = []
    pos = 16
    for i in range(2, len(key), 4):
        cmd, adp, ado, lenw = key[i : i + 4]
        out.append(_Datagram(pos, cmd, adp, ado, lenw & 0x7FF))
        pos += 12 + (lenw & 0x7FF)
    return out


class _NotPlannable(Exception):
    """This frame takes the general path."""


DcRow = tuple[bytearray, DcClock, int, int]
Deferred = list[tuple[Callable[..., None], tuple[Any, ...]]]  # work left for after the answer


def plan_pieces(
    key: Key,
    slaves: list[Esc],
    offsets: list[PortTimes],
    epoch: int,
    delay_ns: int,
    deferred: Deferred | None = None,
) -> Pieces:
    """The plan of a frame layout, or ``None`` when the frame takes the general path, made
    in pieces (one slave's part of a datagram each, 5-10 µs for a LOLA drive; ``finish``
    runs them all): a real-time server answers a frame that comes meanwhile between two
    of them instead of after the whole plan (~250 µs for LOLA's cyclic frame). The slaves
    must not change while it runs (the chain drops it when the epoch moves on).

    With ``deferred``, work that changes nothing in the returning frame is appended
    there instead of run, when nothing later in the frame reads what it changes: the DC
    time control loops of the slaves that only take the reference time, and a logical
    datagram's writes into the slaves' memories with their outputs events. The chain
    runs it after the answer is sent, and before anything else touches the slaves."""
    if not slaves or any(key[i] not in PLANNABLE for i in range(2, len(key), 4)):
        return None
    plan = FramePlan.__new__(FramePlan)
    try:
        yield from plan.make_pieces(key, slaves, offsets, epoch, delay_ns, deferred)
    except _NotPlannable:
        return None
    return plan


class FramePlan:
    """The precomputed work of one frame layout for one chain epoch."""

    used = False  #: whether a frame has run it (the chain sets it)

    def __init__(
        self,
        key: Key,
        slaves: list[Esc],
        offsets: list[PortTimes],
        epoch: int,
        delay_ns: int,
        deferred: Deferred | None = None,
    ) -> None:
        finish(self.make_pieces(key, slaves, offsets, epoch, delay_ns, deferred))

    def make_pieces(
        self,
        key: Key,
        slaves: list[Esc],
        offsets: list[PortTimes],
        epoch: int,
        delay_ns: int,
        deferred: Deferred | None,
    ) -> Pieces:
        self.epoch = epoch
        self.delay_ns = delay_ns
        self.deferred = deferred
        self.compiled: Any = NOT_COMPILED  # the chain's C core's program for it, or None
        self.fits = layout_check(key)  # frame -> whether it has this plan's layout
        self.buf = bytearray(key[0])
        view = memoryview(self.buf)
        self.slaves = [(esc, o.port0_ns) for esc, o in zip(slaves, offsets, strict=True)]
        self.escs = list(slaves)
        datagrams = _datagrams(key)
        self.datagrams_per_slave = len(datagrams)
        self.logical = any(d.cmd in _LOGICAL for d in datagrams)
        self.ops: list[Op] = []
        for d in datagrams:
            self.ops.append((yield from _op_pieces(d, view, self.slaves)))
        if deferred is not None:
            for k, op in enumerate(self.ops):
                later = self.ops[k + 1 :]
                if isinstance(op, DcOp) and op.references <= 1:
                    if not any(_reads_dc(o) for o in later):
                        op.deferred = deferred
                elif isinstance(op, LogicalOp) and op.writes_deferrable(later):
                    op.deferred = deferred
        logical = [op for op in self.ops if isinstance(op, LogicalOp)]
        # no write into the slaves' memories before the answer is sent
        self.defers_writes = all(op.deferred is not None or not op.steps_write for op in logical)
        written = {id(s.esc) for op in logical for s in op.steps if s.events}
        # a slave that takes outputs in this frame cannot time out in it: no watchdog check
        self.watchdog_slaves = [esc for esc in slaves if id(esc) not in written]
        n = len(slaves)
        self.adp_fixes = [  # every slave incremented the ADP of these
            (d.header + 2, (d.adp + n) & 0xFFFF)
            for d in datagrams
            if d.cmd in (Command.BRD, Command.ARMW)
        ]

    def run(self, frame: bytes, t_ns: int) -> bytes:
        buf = self.buf
        buf[:] = frame
        # The general path also sets each ESC's frame time, port offsets and "now": the
        # first two serve only the receive-time latch, "now" only outputs events (set
        # there), so all three are left to the code that reads them.
        if self.deferred is not None:
            self.deferred.append((self.count, ()))
        else:
            self.count()
        for op in self.ops:
            added = op.run(t_ns)
            if added:
                at = op.wkc_offset
                _U16.pack_into(buf, at, (_U16.unpack_from(buf, at)[0] + added) & 0xFFFF)
        for at, adp in self.adp_fixes:
            _U16.pack_into(buf, at, adp)
        buf[6] |= 0x02  # SOURCE_MAC_LOCAL_BIT
        return bytes(buf)

    def count(self) -> None:
        k = self.datagrams_per_slave
        for esc in self.escs:
            esc.counters.datagrams += k


class Op:
    wkc_offset: int

    def run(self, t_ns: int) -> int:
        raise NotImplementedError


def _op_pieces(d: _Datagram, view: memoryview, slaves: list[tuple[Esc, int]]) -> Pieces:
    data = view[d.data : d.data + d.length]
    if d.cmd in _LOGICAL:
        op = LogicalOp.__new__(LogicalOp)
        yield from op.make_pieces(d, data, slaves)
        return op
    yield
    if d.cmd == Command.BRD:
        return BrdOp(d, data, [esc for esc, _ in slaves])
    if d.cmd in _DC and d.ado == r.DC_SYSTEM_TIME and d.length in (4, 8):
        return DcOp(d, data, slaves)
    raise _NotPlannable


class BrdOp(Op):
    """BRD of registers: the OR of every slave's bytes into the datagram, WKC +1 each."""

    def __init__(self, d: _Datagram, data: memoryview, slaves: list[Esc]) -> None:
        lo, hi = d.ado, d.ado + d.length
        if hi > r.PROCESS_RAM or (lo < r.DC_SYSTEM_TIME + 8 and r.DC_SYSTEM_TIME < hi):
            raise _NotPlannable  # SM buffers, or a read that latches the system time
        self.wkc_offset = d.wkc
        self.data = data
        self.length = d.length
        self.lo, self.hi = lo, hi
        self.sources = [memoryview(esc.mem)[lo:hi] for esc in slaves]
        # registers that only change with the epoch: their OR holds while it does
        self.epoch_cell = slaves[0].epoch if _within(lo, hi, EPOCH_REGISTERS) else None
        self.cached: tuple[int, int] | None = None  # (epoch, OR of all slaves)

    def run(self, t_ns: int) -> int:
        cell, cached = self.epoch_cell, self.cached
        if cell is not None and cached is not None and cached[0] == cell[0]:
            merged = cached[1]
        else:
            merged = 0
            for source in self.sources:
                merged |= int.from_bytes(source, "little")
            if cell is not None:
                self.cached = (cell[0], merged)
        value = int.from_bytes(self.data, "little") | merged
        self.data[:] = value.to_bytes(self.length, "little")
        return len(self.sources)


class DcOp(Op):
    """ARMW/FRMW of the system time: the reference puts its time in, the others take it
    into their time control loop; WKC +1 from every slave. Runs of slaves between
    references go through :func:`system_time_loop` in one call."""

    def __init__(self, d: _Datagram, data: memoryview, slaves: list[tuple[Esc, int]]) -> None:
        self.wkc_offset = d.wkc
        self.data = data
        self.length = d.length
        self.count = len(slaves)
        # (reference or None, its time offset, the slaves after it up to the next one)
        segments: list[tuple[Esc | None, int, list[tuple[bytearray, DcClock, int, int]]]] = [
            (None, 0, [])
        ]
        for position, (esc, port0_ns) in enumerate(slaves):
            if d.cmd == Command.ARMW:
                hit = (d.adp + position) & 0xFFFF == 0
            else:
                hit = esc.addressed_configured(d.adp)
            if hit:
                segments.append((esc, port0_ns, []))
            else:
                segments[-1][2].append(
                    (esc.mem, esc.clock, port0_ns, esc.dc_offset_minus_delay_ns())
                )
        self.segments = segments
        self.references = len(segments) - 1
        self.deferred: Deferred | None = None  # set: the loops run after the answer

    def run(self, t_ns: int) -> int:
        data, n = self.data, self.length
        width_bits = 8 * n
        value = int.from_bytes(data, "little")
        deferred = self.deferred
        for reference, port0_ns, others in self.segments:
            if reference is not None:
                time_ns = reference.system_time_ns(t_ns + port0_ns)
                data[:] = (time_ns & _MASK64).to_bytes(8, "little")[:n]
                value = int.from_bytes(data, "little")
            if not others:
                continue
            if deferred is not None:
                deferred.append((system_time_loop, (others, value, width_bits, t_ns)))
            else:
                system_time_loop(others, value, width_bits, t_ns)
        return self.count


@dataclass(slots=True)
class SlaveStep:
    """One slave's part of a logical datagram: ``generic`` set -> the ESC's own code."""

    esc: Esc
    port0_ns: int = 0  # when the frame reaches it, relative to the frame's start
    generic: bool = False
    writes: list[tuple[memoryview, memoryview, int, int]] | None = None  # target, source, a, b
    events: int = 0  # output SM buffers completed: outputs_written calls
    reads: list[tuple[memoryview, memoryview, int, int]] | None = None
    read_memory: list[tuple[int, int]] = field(default_factory=list)  # ranges the reads copy
    write_memory: list[tuple[int, int]] = field(default_factory=list)  # and the writes
    wkc: int = 0


class LogicalOp(Op):
    """LRD/LWR/LRW: slice copies through every slave's FMMUs (ETG.1000.4 §6.5).

    Slaves whose FMMUs are not plain byte copies (bit-wise mappings, mailbox buffers) run
    the ESC's own logical processing; then, and when a slave's read lands where a later
    slave's write takes from, the slaves run in line order. Otherwise all writes run
    first, then the outputs events, then all reads."""

    def __init__(self, d: _Datagram, data: memoryview, slaves: list[tuple[Esc, int]]) -> None:
        finish(self.make_pieces(d, data, slaves))

    def make_pieces(self, d: _Datagram, data: memoryview, slaves: list[tuple[Esc, int]]) -> Pieces:
        self.wkc_offset = d.wkc
        self.data = data
        self.cmd = d.cmd
        self.address = d.adp | d.ado << 16
        self.steps: list[SlaveStep] = []
        for esc, port0_ns in slaves:
            self.steps.append(self._slave(esc, port0_ns, d))
            yield
        plain = [s for s in self.steps if not s.generic]
        self.fixed_wkc = sum(s.wkc for s in plain)
        self.steps_write = any(s.generic or s.writes for s in self.steps)
        self.deferred: Deferred | None = None  # set: writes and events run after the answer
        self.snapshot = bytearray(d.length)
        view = memoryview(self.snapshot)
        self.snapshot_writes = [(t, view[a:b]) for s in plain for t, _, a, b in s.writes or ()]
        self.ordered = len(plain) < len(self.steps) or _reads_feed_writes(self.steps)
        self.writes = [(t, src) for s in plain for t, src, _, _ in s.writes or ()]
        self.events = [(s.esc, s.port0_ns, s.events) for s in plain if s.events]
        self.reads = [(t, src) for s in plain for t, src, _, _ in s.reads or ()]

    def _slave(self, esc: Esc, port0_ns: int, d: _Datagram) -> SlaveStep:
        config = esc.configuration()
        lo, hi = self.address, self.address + d.length
        mem = memoryview(esc.mem)
        step = SlaveStep(esc, port0_ns, writes=[], reads=[])
        assert step.writes is not None and step.reads is not None
        wrote = read = False
        if d.cmd != Command.LRD:
            hits = [f for f in config.write_fmmus if _fmmu_hits(f, lo, hi)]
            for f in hits:
                if f.physical_start < PLAN_FREE_REGISTERS:
                    raise _NotPlannable  # writes into registers a plan depends on
                p, q, a, b = _copy_range(f, lo, hi)
                kinds = _sm_last_byte_in(config.active, p, q, r.SM_DIRECTION_WRITE)
                if r.SM_MODE_MAILBOX in kinds or not byte_aligned(f):
                    return SlaveStep(esc, port0_ns, generic=True)
                step.writes.append((mem[p:q], self.data[a:b], a, b))
                step.write_memory.append((p, q))
                step.events += len(kinds)
            wrote = bool(hits)
        if d.cmd != Command.LWR:
            hits = [f for f in config.read_fmmus if _fmmu_hits(f, lo, hi)]
            for f in hits:
                p, q, a, b = _copy_range(f, lo, hi)
                kinds = _sm_last_byte_in(config.active, p, q, r.SM_DIRECTION_READ)
                if r.SM_MODE_MAILBOX in kinds or not byte_aligned(f):
                    return SlaveStep(esc, port0_ns, generic=True)
                step.reads.append((self.data[a:b], mem[p:q], a, b))
                step.read_memory.append((p, q))
            read = bool(hits)
        step.wkc = wkc_increment(d.cmd, read=read, write=wrote)
        return step

    def writes_deferrable(self, later: list[Op]) -> bool:
        """Whether the writes and outputs events may wait until after the answer (taking
        the outputs from a copy of the datagram made before the reads): no read in the
        frame takes from memory they write, no later write writes it again, and no
        outputs event can change the AL state (no slave waits for OP)."""
        if self.ordered or not self.writes:
            return False
        if any(esc.pending_op for esc, _, _ in self.events):
            return False
        written: dict[int, list[tuple[int, int]]] = {}  # per slave: the ranges written
        for s in self.steps:
            if s.write_memory:
                written.setdefault(id(s.esc), []).extend(s.write_memory)
        for op in [self, *later]:
            if not isinstance(op, LogicalOp):
                if isinstance(op, BrdOp) and op.hi > PLAN_FREE_REGISTERS:
                    return False
                continue
            for s in op.steps:
                if s.generic:
                    return False
                ranges = written.get(id(s.esc))
                if not ranges:
                    continue
                later_writes = s.write_memory if op is not self else []
                for p, q in [*s.read_memory, *later_writes]:
                    if any(p < wq and wp < q for wp, wq in ranges):
                        return False
        return True

    def run(self, t_ns: int) -> int:
        if self.ordered:
            return self._run_ordered(t_ns)
        if self.deferred is not None:
            self.snapshot[:] = self.data  # what the writes take, before the reads change it
            self.deferred.append((self.write_later, (t_ns,)))
        else:
            self.write(t_ns)
        for target, source in self.reads:
            target[:] = source
        return self.fixed_wkc

    def write(self, t_ns: int) -> None:
        """The writes into the slaves' memories and their outputs events."""
        for target, source in self.writes:
            target[:] = source
        self._events(t_ns)

    def write_later(self, t_ns: int) -> None:
        """:meth:`write` from the copy of the datagram taken before the reads."""
        for target, source in self.snapshot_writes:
            target[:] = source
        self._events(t_ns)

    def _events(self, t_ns: int) -> None:
        for esc, port0_ns, n in self.events:
            esc.now_ns = t_ns + port0_ns
            if esc.pending_op:
                for _ in range(n):
                    esc.outputs_written()
            else:  # what outputs_written does for a slave not waiting for OP
                esc.outputs_valid = True
                esc.last_outputs_ns = t_ns + port0_ns

    def _run_ordered(self, t_ns: int) -> int:
        added = 0
        for step in self.steps:
            esc = step.esc
            esc.now_ns = t_ns + step.port0_ns
            if step.generic:
                added += esc.logical(self.cmd, self.address, self.data, esc.now_ns)
                continue
            for target, source, _, _ in step.writes or ():
                target[:] = source
            for _ in range(step.events):
                esc.outputs_written()
            for target, source, _, _ in step.reads or ():
                target[:] = source
            added += step.wkc
        return added


_DC_REGISTERS = (r.DC_RECEIVE_TIME_PORT0, r.DC_END)


def _reads_dc(op: Op) -> bool:
    """True when ``op`` may read DC registers or clocks (so the loops before it must run)."""
    lo, hi = _DC_REGISTERS
    if isinstance(op, DcOp):
        return True
    if isinstance(op, BrdOp):
        return op.lo < hi and lo < op.hi
    if isinstance(op, LogicalOp):
        return any(s.generic or any(p < hi and lo < q for p, q in s.read_memory) for s in op.steps)
    return True


# Register ranges every change of which bumps the epoch (DL status: topology; AL status
# and status code: the AL state machine); other writes to them go through register writes, which
# bump it too.
EPOCH_REGISTERS = ((r.DL_STATUS, r.DL_STATUS + 2), (r.AL_STATUS, r.AL_STATUS_CODE + 2))


def _within(lo: int, hi: int, ranges: tuple[tuple[int, int], ...]) -> bool:
    return any(a <= lo and hi <= b for a, b in ranges)


def _fmmu_hits(f: Fmmu, lo: int, hi: int) -> bool:
    return f.logical_start < hi and lo < f.logical_start + f.length_bytes


def _copy_range(f: Fmmu, lo: int, hi: int) -> tuple[int, int, int, int]:
    """(memory start, memory end, data start, data end) of a byte-aligned FMMU's copy."""
    a = max(lo, f.logical_start)
    b = min(hi, f.logical_start + f.length_bytes)
    p = f.physical_start + (a - f.logical_start)
    return p, p + b - a, a - lo, b - lo


def _sm_last_byte_in(active: list[SmView], p: int, q: int, direction: int) -> list[int]:
    """Modes of the SMs of ``direction`` whose last byte lies in [p, q): the buffer events
    of the ESC's sync managers (esc.sm: writes, and reads only past 0x1000)."""
    if direction == r.SM_DIRECTION_READ and q <= r.PROCESS_RAM:
        return []
    return [
        sm.mode for sm in active if sm.direction == direction and p <= sm.start + sm.length - 1 < q
    ]


def _reads_feed_writes(steps: list[SlaveStep]) -> bool:
    """True when a slave's read lands in bytes a later slave's write takes from."""
    for i, step in enumerate(steps):
        for _, _, a, b in step.reads or ():
            for later in steps[i + 1 :]:
                for _, _, c, e in later.writes or ():
                    if a < e and c < b:
                        return True
    return False
