"""Frame plans give the same bytes as the general path: replies, ESC memories, clocks.

Two chains of the same ENI get the same frames at the same times: one answers through
frame plans wherever it can (``planner.plan_after = 1``), the other never (``0``).
Bring-up through the ENI's InitCmds, cyclic frames with changing outputs, SDO traffic,
a drive fault with its emergency, and random frames built from the plannable commands
(random logical windows, registers, DC addressing) mixed with others.
"""

from __future__ import annotations

import random
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lolacli.devices.cia402 import Cia402Drive
from lolacli.emulator.chain import Chain
from lolacli.emulator.core import core_available
from lolacli.emulator.plan import layout_check, layout_key
from lolacli.emulator.slave import build_chain
from lolacli.eni.model import Eni
from lolacli.files import load_eni
from lolacli.wire.commands import Command as C
from lolacli.wire.frame import Datagram, decode_frame, encode_frame, make_frame
from tests.emulator.bus import EXAMPLES, Bus

ENGINES = [
    "python",
    pytest.param("c", marks=pytest.mark.skipif(not core_available(), reason="C core not built")),
]


class Twin:
    """Looks like a chain to :class:`Bus`; runs every frame through both chains."""

    def __init__(self, eni: Eni, engine: str | None = None) -> None:
        self.fast = build_chain(eni, drift_ppb=20, engine=engine)
        self.fast.planner.plan_after = self.fast.planner.register_plan_after = 1
        self.slow = build_chain(eni, drift_ppb=20, engine=engine)
        self.slow.planner.plan_after = 0
        self.slaves = self.fast.slaves
        self.timing = self.fast.timing
        self.frames = 0
        self.rng = random.Random(7)

    def process(self, frame: bytes, t_ns: int, *, defer_cycles: bool = False):  # type: ignore[no-untyped-def]
        """Like a real-time server half of the time: answers first, and runs the work
        left for afterwards (deferred DC loops, device cycles) only now and then, so the
        next frame often comes before it ran."""
        defer = defer_cycles or self.rng.random() < 0.5
        fast = self.fast.process(frame, t_ns, defer_cycles=defer)
        slow = self.slow.process(frame, t_ns, defer_cycles=defer)
        assert fast == slow, f"frame {self.frames}: {frame.hex()}"
        roll = self.rng.random()
        if defer and roll < 0.5:
            self.fast.run_deferred_cycles()
            self.slow.run_deferred_cycles()
        elif defer and roll < 0.75:  # one piece of a plan being made: frames come between
            self.fast.planner.work(lambda: True)
        self.frames += 1
        if self.frames % 50 == 0:
            self.same_state()
        return fast

    def same_state(self) -> None:
        self.fast.run_deferred_cycles()
        self.slow.run_deferred_cycles()
        for i, (a, b) in enumerate(zip(self.fast.slaves, self.slow.slaves, strict=True)):
            assert a.mem == b.mem, f"slave {i}: memories differ"
            assert a.clock == b.clock, f"slave {i}"
            assert a.counters == b.counters, f"slave {i}"
            assert (a.outputs_valid, a.pending_op, a.last_outputs_ns) == (
                b.outputs_valid,
                b.pending_op,
                b.last_outputs_ns,
            ), f"slave {i}"
        assert self.fast.stats.replies == self.slow.stats.replies


def _cyclic(bus: Bus, eni: Eni, rng: random.Random, n: int) -> None:
    size = eni.cyclic_frames[0].commands[0].data_length_bytes
    image = bytearray(size)
    for k in range(n):
        for drive in range(0, min(size - 6, 21 * 13), 13):  # controlword, mode, target
            cw = (0x06, 0x07, 0x0F)[min(k, 2)]
            struct.pack_into("<Hbi", image, drive, cw, 8, rng.randrange(-5000, 5000))
        bus.cycle(eni, bytes(image[:size]))


def _random_frame(rng: random.Random, slaves: int, logical_bytes: int) -> bytes:
    datagrams = []
    for _ in range(rng.randrange(1, 5)):
        kind = rng.randrange(6)
        if kind <= 1:
            cmd = rng.choice([C.LRD, C.LWR, C.LRW])
            start = 0x10000 + rng.randrange(-16, logical_bytes)
            datagrams.append(Datagram.logical(cmd, start, rng.randbytes(rng.randrange(1, 64))))
        elif kind == 2:
            ado = rng.choice([0x0130, 0x0110, 0x0000, 0x0900, 0x0910, 0x092C, 0x0F00, 0x0FFE])
            datagrams.append(Datagram.physical(C.BRD, 0, ado, rng.randrange(1, 9)))
        elif kind == 3:
            adp = (-rng.randrange(0, slaves + 2)) & 0xFFFF
            datagrams.append(Datagram.physical(C.ARMW, adp, 0x0910, rng.choice([4, 8])))
        elif kind == 4:
            station = 0x03E9 + rng.randrange(0, slaves + 1)
            datagrams.append(
                Datagram.physical(C.FRMW, station, 0x0910, rng.randbytes(rng.choice([4, 8, 2])))
            )
        else:  # reads only: writes may take the slaves out of OP, which is tested above
            ado = rng.choice([0x0130, 0x0910, 0x1000, 0x0F00])
            datagrams.append(Datagram.physical(C.APRD, (-rng.randrange(slaves)) & 0xFFFF, ado, 4))
    return encode_frame(make_frame(datagrams), pad=rng.random() < 0.5)


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("name", ["lola.xml", "single_drive.xml", "ek1100_io.xml"])
def test_plans_answer_like_the_general_path(name: str, engine: str) -> None:
    eni = load_eni(EXAMPLES / name)
    twin = Twin(eni, engine)
    bus = Bus(twin)  # type: ignore[arg-type]
    rng = random.Random(name)
    bus.bring_up(eni)
    _cyclic(bus, eni, rng, 60)
    mb = eni.slaves[0].mailbox
    if mb is not None:
        mbx = ((mb.out_start, mb.out_length_bytes), (mb.in_start, mb.in_length_bytes))
        station = eni.slaves[0].station_address
        assert bus.sdo_upload(station, 0x1008, 0, mbx)
        _cyclic(bus, eni, rng, 5)
        if name != "ek1100_io.xml":
            twin.fast.drive_fault(1)
            twin.slow.drive_fault(1)
            _cyclic(bus, eni, rng, 5)
            assert bus.fprd(station, mb.in_start, mb.in_length_bytes)  # the emergency
            assert bus.sdo_upload(station, 0x603F, 0, mbx) == b"\x30\x55"
    logical = eni.cyclic_frames[0].commands[0].data_length_bytes
    for _ in range(800):
        bus.t_ns += rng.randrange(1, 300_000)
        twin.process(_random_frame(rng, len(eni.slaves), logical), bus.t_ns)
        if rng.random() < 0.3:
            _cyclic(bus, eni, rng, 1)
    twin.same_state()
    assert twin.fast.stats.planned_frames > 150
    assert twin.slow.stats.planned_frames == 0


def test_a_cyclic_frame_keeps_its_plan_from_cycle_to_cycle() -> None:
    eni = load_eni(EXAMPLES / "lola.xml")
    chain = build_chain(eni)
    bus = Bus(chain)
    bus.bring_up(eni)
    planned = chain.stats.planned_frames
    for _ in range(10):
        bus.cycle(eni)
    assert chain.stats.planned_frames == planned + 10  # the plan survived all ten cycles
    chain.stuck_in_safeop(3)
    replies, _ = bus.cycle(eni)
    expected = [c.expected_wkc for c in eni.cyclic_frames[0].commands]
    assert [d.wkc for d in replies] == expected


def _cyclic_frame(eni: Eni) -> bytes:
    return encode_frame(
        make_frame(
            [
                Datagram.logical(c.cmd, c.logical_address, c.data_length_bytes)
                if c.logical_address is not None
                else Datagram.physical(c.cmd, c.adp or 0, c.ado or 0, c.data_length_bytes)
                for c in eni.cyclic_frames[0].commands
            ]
        ),
        pad=True,
    )


@pytest.mark.parametrize("engine", ENGINES)
def test_a_plan_is_made_in_pieces_between_frames(engine: str) -> None:
    """A server makes a frame's plan after the answer a piece at a time and answers a
    frame that comes meanwhile first (pysoem's AL status poll waited ~360 µs on the wire
    for LOLA's cyclic plan, made whole); the plan is used once its last piece has run,
    and a plan begun before a register write is dropped, not used in the new epoch, and
    begun again for it."""
    eni = load_eni(EXAMPLES / "lola.xml")
    chain = build_chain(eni, engine=engine)
    bus = Bus(chain)
    bus.bring_up(eni)
    cyclic = _cyclic_frame(eni)
    poll = encode_frame(make_frame([Datagram.physical(C.BRD, 0, 0x0130, 2)]), pad=True)
    t = [bus.t_ns]
    station = eni.slaves[0].station_address
    fmmu0 = bus.fprd(station, 0x0600, 16)

    def new_epoch() -> None:  # a register write, changing nothing: FMMU 0 as it is
        assert bus.fpwr(station, 0x0600, fmmu0) == 1

    def send(frame: bytes) -> tuple[Datagram, ...]:
        t[0] += 200_000
        reply, _ = chain.process(frame, t[0], defer_cycles=True)
        assert reply is not None
        return decode_frame(reply).datagrams

    def planned_after(frame: bytes) -> bool:
        before = chain.stats.planned_frames
        send(frame)
        return chain.stats.planned_frames > before

    def making() -> bool:  # the cycle runs whole, the plan's first piece then gives way
        return chain.planner.making is not None

    new_epoch()  # the bring-up's plans are of the last epoch
    assert not planned_after(cyclic)  # a layout seen before: its plan is asked for ...
    assert chain.run_deferred_cycles(should_yield=making) is False  # ... one piece made
    assert chain.planner.making is not None
    pieces = 1
    while chain.planner.making is not None:  # a poll between every two pieces
        assert send(poll)[0].wkc == len(eni.slaves)
        chain.run_deferred_cycles(should_yield=lambda: True)
        pieces += 1
    assert pieces > len(eni.slaves)  # a slave a piece, at least
    assert planned_after(cyclic)
    # begun, then a register write: dropped, and begun again for the new epoch
    new_epoch()
    assert not planned_after(cyclic)
    assert chain.run_deferred_cycles(should_yield=making) is False
    assert chain.planner.making is not None
    begun = chain.planner.making
    new_epoch()
    assert chain.run_deferred_cycles(should_yield=making) is False
    assert chain.planner.making is not None and chain.planner.making == chain.planner.epoch != begun
    assert not chain.planner.plans
    chain.run_deferred_cycles()  # made whole, before the layout's next frame
    assert planned_after(cyclic)
    assert chain.run_deferred_cycles() is True and chain.planner.making is None  # nothing left


class _Lola:
    """LOLA brought up; LRD, LWR and LRW of its whole first logical window."""

    def __init__(self, engine: str | None = None) -> None:
        self.eni = eni = load_eni(EXAMPLES / "lola.xml")
        self.chain = build_chain(eni, engine=engine)
        self.bus = Bus(self.chain)
        self.bus.bring_up(eni)
        c = eni.cyclic_frames[0].commands[0]
        start, size = c.logical_address or 0, c.data_length_bytes
        self.lrd, self.lwr, self.lrw = (
            encode_frame(make_frame([Datagram.logical(cmd, start, size)]), pad=True)
            for cmd in (C.LRD, C.LWR, C.LRW)
        )
        self.station = eni.slaves[0].station_address
        self.fmmu0 = self.bus.fprd(self.station, 0x0600, 16)

    def planned_after(self, frame: bytes) -> bool:
        """Send ``frame`` as a server does (its work after the answer left); whether
        a plan answered it."""
        self.bus.t_ns += 500_000
        before = self.chain.stats.planned_frames
        assert self.chain.process(frame, self.bus.t_ns, defer_cycles=True)[0] is not None
        return self.chain.stats.planned_frames > before

    def new_epoch(self) -> None:
        """A register write that changes nothing: FMMU 0 as it is."""
        assert self.bus.fpwr(self.station, 0x0600, self.fmmu0) == 1


@pytest.mark.parametrize("engine", ENGINES)
def test_cyclic_layouts_are_planned_again_before_their_next_frame(engine: str) -> None:
    """When a register write (or a slave's step to OP) ends the epoch of the cyclic
    frames' plans, the server's work after the answer plans those layouts again before
    their next frame comes: KickCAT's LRD and LWR after its request for OP each took
    the general path once more (200-550 µs each for LOLA, against ~15 planned)."""
    lola = _Lola(engine)
    chain, frames = lola.chain, (lola.lrd, lola.lwr)
    assert [lola.planned_after(f) for f in frames] == [False, False]  # first seen
    chain.run_deferred_cycles()
    assert [lola.planned_after(f) for f in frames] == [True, True]
    lola.new_epoch()
    for _ in frames:  # a layout a call: the next is asked for in the next idle moment
        chain.run_deferred_cycles()
    assert [lola.planned_after(f) for f in frames] == [True, True]
    assert chain.run_deferred_cycles() is True  # nothing left: no plan made again
    assert chain.planner.making is None


def test_plans_stay_pending_until_every_cyclic_layout_is_planned_again() -> None:
    """The server makes plans only while ``plans_pending`` says some are left: after a
    frame came between two layouts' plans, or an AL status poll came first in the new
    epoch, the layouts not yet planned again are still pending (review)."""
    lola = _Lola()
    chain, planned_after = lola.chain, lola.planned_after
    poll = encode_frame(make_frame([Datagram.physical(C.BRD, 0, 0x0130, 2)]), pad=True)
    planned_after(lola.lrd), planned_after(lola.lwr)
    chain.planner.work()
    assert planned_after(lola.lrd) and planned_after(lola.lwr)
    lola.new_epoch()
    assert chain.planner.pending
    planned_after(poll)  # a frame first, which sees the new epoch
    assert chain.planner.pending
    assert chain.planner.work(lambda: chain.planner.making is None) is False  # a frame came
    assert chain.planner.pending  # the other layout is left
    assert chain.planner.work() is True and not chain.planner.pending
    assert planned_after(lola.lrd) and planned_after(lola.lwr)


def test_a_layout_no_longer_sent_is_planned_again_once_then_forgotten() -> None:
    """A logical frame sent once gets a plan; once its epoch ends it is planned again one
    time, and as that plan is never used, no more: the layouts the master still sends
    are planned again every epoch, first (review: 40 plans in 10 epochs, not 20)."""
    lola = _Lola()
    chain, planned_after = lola.chain, lola.planned_after
    planned_after(lola.lrw)  # once only
    planned_after(lola.lrd), planned_after(lola.lwr)
    chain.planner.work()
    made: list[object] = []
    pieces = chain.planner._pieces

    def spy(key, asked):  # type: ignore[no-untyped-def]
        made.append(key)
        return (yield from pieces(key, asked))

    chain.planner._pieces = spy  # type: ignore[method-assign]
    for _ in range(10):
        lola.new_epoch()
        while not chain.planner.work():
            pass
        assert planned_after(lola.lrd) and planned_after(lola.lwr)
    assert made.count(layout_key(lola.lrw)) == 1
    assert made.count(layout_key(lola.lrd)) == made.count(layout_key(lola.lwr)) == 10
    assert len(made) == 21


def test_a_register_write_makes_the_next_frame_replan() -> None:
    eni = load_eni(EXAMPLES / "single_drive.xml")
    chain = build_chain(eni)
    bus = Bus(chain)
    bus.bring_up(eni)
    bus.cycle(eni)
    bus.cycle(eni)
    station = eni.slaves[0].station_address
    assert bus.fpwr(station, 0x0120, b"\x02\x00") == 1  # back to PREOP: SM buffers close
    replies, _ = bus.cycle(eni)
    assert replies[0].wkc == 0


def test_layout_key_rejects_what_the_general_path_rejects() -> None:
    good = encode_frame(make_frame([Datagram.physical(C.BRD, 0, 0x0130, 2)]), pad=True)
    assert layout_key(good) is not None
    assert layout_key(good[:20]) is None
    assert layout_key(good[:12] + b"\x81\x00" + good[12:]) is None  # VLAN: general path
    bad_length = bytearray(good)
    bad_length[14] = 0xFF
    assert layout_key(bytes(bad_length)) is None
    chain: Chain = build_chain(load_eni(EXAMPLES / "single_drive.xml"))
    assert decode_frame(chain.process(good, 0)[0] or b"").datagrams[0].wkc == 1


def test_held_cycles_let_frames_answer_first_and_lose_no_outputs() -> None:
    """A server that answers back-to-back frames first holds each device cycle; every
    frame's outputs still reach the drive, in order, one cycle late."""
    eni = load_eni(EXAMPLES / "single_drive.xml")
    chain = build_chain(eni)
    bus = Bus(chain)
    bus.bring_up(eni)
    for _ in range(3):
        bus.cycle(eni)  # the cyclic frame gets its plan
    size = eni.cyclic_frames[0].commands[0].data_length_bytes
    statuses = []
    for cw in (0x06, 0x07, 0x0F, 0x0F, 0x0F):
        image = struct.pack("<Hbi", cw, 8, 4242).ljust(size, b"\0")
        frame = encode_frame(
            make_frame(
                [
                    Datagram.logical(c.cmd, c.logical_address, image)
                    if c.logical_address is not None
                    else Datagram.physical(c.cmd, c.adp or 0, c.ado or 0, c.data_length_bytes)
                    for c in eni.cyclic_frames[0].commands
                ]
            ),
            pad=True,
        )
        bus.t_ns += 100_000
        planned = chain.stats.planned_frames
        reply, _ = chain.process(frame, bus.t_ns, defer_cycles=True)
        assert reply is not None and chain.stats.planned_frames == planned + 1
        statuses.append(struct.unpack_from("<H", decode_frame(reply).datagrams[0].data)[0])
        chain.hold_deferred_cycle()  # the next frame is already here
    chain.run_deferred_cycles()
    # each answer shows the drive before the previous frame's cycle: one cycle late
    assert [s & 0x6F for s in statuses] == [0x40, 0x40, 0x21, 0x23, 0x27]
    replies, inputs = bus.cycle(eni, struct.pack("<Hbi", 0x0F, 8, 4242).ljust(size, b"\0"))
    status, _mode, actual = struct.unpack_from("<Hbi", inputs, 0)
    assert status & 0x6F == 0x27 and actual == 4242


_KINDS = [C.LRW, C.LRD, C.BRD, C.ARMW, C.FPRD]


@settings(max_examples=300, deadline=None)
@given(
    a=st.lists(st.tuples(st.sampled_from(_KINDS), st.integers(0, 40)), min_size=1, max_size=4),
    b=st.lists(st.tuples(st.sampled_from(_KINDS), st.integers(0, 40)), min_size=1, max_size=4),
    noise=st.binary(min_size=0, max_size=4),
    pad=st.booleans(),
)
def test_layout_check_agrees_with_layout_key(a, b, noise, pad) -> None:  # type: ignore[no-untyped-def]
    """A plan recognises its frames without working out their key; the test it uses
    says yes exactly when the keys are equal (also for cut, tagged or noisy frames)."""

    def frame(spec: list[tuple[int, int]]) -> bytes:
        datagrams = [
            Datagram.logical(cmd, 0x10000, bytes(n))
            if cmd in (C.LRW, C.LRD)
            else Datagram.physical(cmd, 0x1001, 0x0130, bytes(n))
            for cmd, n in spec
        ]
        return encode_frame(make_frame(datagrams), pad=pad)

    first = frame(a)
    key = layout_key(first)
    assert key is not None
    check = layout_check(key)
    assert check(first)
    for other in (frame(b), frame(b) + noise, frame(b)[: len(frame(b)) - len(noise)], first[:-1]):
        assert check(other) == (layout_key(other) == key)


class _OwnStep(Cia402Drive):
    """A drive with a step of its own: the C core leaves its cycle to Python."""

    def step(self, t_ns: int) -> None:
        super().step(t_ns)


@pytest.mark.parametrize("engine", ENGINES)
def test_a_deferred_cycle_that_gives_way_goes_on_where_it_stopped(engine: str) -> None:
    """A server runs the application cycle slave by slave and stops when the next frame
    waits; the rest runs before anything touches those slaves. After the same frames,
    every slave ends where it ends when the cycles always run whole (in the reference).
    The C core runs the devices it holds in one call per run of consecutive slaves, so it
    gives way only around the slaves Python cycles (here two drives with a step of their
    own); the Python engine between any two slaves."""
    eni = load_eni(EXAMPLES / "lola.xml")
    whole, parts = build_chain(eni, engine="python"), build_chain(eni, engine=engine)
    for chain in (whole, parts):
        for position in (5, 12):
            chain._slaves[position].app.device.__class__ = _OwnStep  # type: ignore[union-attr]
    buses = [Bus(whole), Bus(parts)]
    for bus in buses:
        bus.bring_up(eni)
    rng = random.Random(5)
    size = eni.cyclic_frames[0].commands[0].data_length_bytes
    stopped = 0
    asked = 30 if engine == "python" else 5  # questions per cycle: 24, or 4 (5 pieces)
    for k in range(40):
        image = bytearray(size)
        for drive in range(0, min(size - 6, 21 * 13), 13):
            struct.pack_into("<Hbi", image, drive, (0x06, 0x07, 0x0F)[min(k, 2)], 8, 100 * k)
        frame = encode_frame(
            make_frame(
                [
                    Datagram.logical(c.cmd, c.logical_address, bytes(image[:size]))
                    if c.logical_address is not None
                    else Datagram.physical(c.cmd, c.adp or 0, c.ado or 0, c.data_length_bytes)
                    for c in eni.cyclic_frames[0].commands
                ]
            ),
            pad=True,
        )
        t_ns = buses[0].t_ns + (k + 1) * 1_000_000
        whole.process(frame, t_ns, defer_cycles=True)
        whole.run_deferred_cycles()
        parts.process(frame, t_ns, defer_cycles=True)
        after = rng.randrange(1, asked)
        calls = iter(range(after, -1, -1))
        if not parts.run_deferred_cycles(should_yield=lambda c=calls: next(c, 0) == 0):
            stopped += 1
    parts.run_deferred_cycles()
    assert stopped > 10  # most cycles gave way somewhere in the line
    if engine == "c":  # the other drives' cycles ran in the core
        core = parts._core
        assert core is not None
        assert core.held_devices() == [i for i in range(len(eni.slaves)) if i not in (5, 12)]
    for i, (a, b) in enumerate(zip(whole.slaves, parts.slaves, strict=True)):
        assert a.mem == b.mem, f"slave {i}"
        assert a.counters == b.counters, f"slave {i}"


def test_a_register_poll_is_planned_only_after_many_repeats_in_one_epoch() -> None:
    """A start-up's register polls (AL status by BRD between writes) stay on the general
    path: making their plan costs more than it saves before the next write (a new epoch)
    drops it, and a master's next frame may wait for it. Cyclic frames are still planned
    from their second time on (above)."""
    eni = load_eni(EXAMPLES / "lola.xml")
    chain = build_chain(eni)
    bus = Bus(chain)
    bus.bring_up(eni)
    n = chain.planner.register_plan_after
    planned = chain.stats.planned_frames
    for _ in range(n - 1):
        assert bus.one(C.BRD, 0, 0x0130, 2).wkc == 25
    assert chain.stats.planned_frames == planned
    assert bus.fpwr(eni.slaves[0].station_address, 0x0120, b"\x08\x00") == 1  # a new epoch
    for _ in range(n - 1):
        bus.one(C.BRD, 0, 0x0130, 2)
    assert chain.stats.planned_frames == planned  # counted again from the write on
    for _ in range(3):
        bus.one(C.BRD, 0, 0x0130, 2)
    assert chain.stats.planned_frames == planned + 3  # the 64th and on
