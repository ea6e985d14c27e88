"""The chain's C core gives the same bytes and the same state as the Python reference.

Two chains of one ENI get the same frames at the same times: one runs its planned frames,
their deferred work, the watchdogs and the device cycles in the C core (engine ``c``), the
other the Python reference (engine ``python``); both answer through frame plans. The
replies are compared frame by frame, and every slave's memory, DC clock, counters, outputs
state and device state (every object-dictionary value, CiA 402 power state and last
controlword, device time, last analog sample) every few dozen frames and at the end.

The script covers bring-up through the ENI's InitCmds, the CiA 402 state machine (enable,
CSP following with and without the 0x607F rate limit, CSV, disable operation, quick stop,
fault and fault reset, random controlwords), AL state changes (one slave to SAFEOP and back,
waiting for outputs), SM watchdog expiry (AL 0x001B) and recovery, SDO traffic and a PDO
remap, held cycles, link loss, dropped and damaged frames, time gaps and times the core
does not take; on the examples and on every corpus ENI, with the ENI's own cyclic frame
(mostly the general path) and with its plannable part (the C core's path).
"""

from __future__ import annotations

import ctypes
import os
import random
import shutil
import struct
import subprocess
import sys
import sysconfig
import tempfile
import warnings
from collections.abc import Callable
from pathlib import Path

import pytest

from lolacli.devices.cia402 import Cia402Drive
from lolacli.devices.flat import VALUE_LIMIT
from lolacli.emulator import core as core_module
from lolacli.emulator.chain import Chain, Faults, chain_engine
from lolacli.emulator.core import ChainCore, CompiledPlan, SlaveTable, core_available
from lolacli.emulator.esc import Esc
from lolacli.emulator.line import ChainTiming
from lolacli.emulator.plan import layout_key
from lolacli.emulator.registers import AlState
from lolacli.emulator.run import state_summary
from lolacli.emulator.slave import build_chain, device_of
from lolacli.eni.model import Eni
from lolacli.errors import UsageError, WireError
from lolacli.files import load_eni
from lolacli.timing.model import physics_delays_ns
from lolacli.wire.commands import Command as C
from lolacli.wire.frame import Datagram, decode_frame, encode_frame, make_frame
from lolacli.wire.mailbox import MailboxType, encode_mailbox, make_mailbox
from lolacli.wire.registers import AlStatusCode
from lolacli.wire.sdo import SdoUploadRequest, encode_sdo
from tests.emulator.bus import EXAMPLES, Bus
from tests.emulator.test_general_path import (
    _dc_frame,
    _single_slave_frame,
    count_register_frames,
)
from tests.emulator.test_general_path import _random_frame as _register_frame
from tests.emulator.test_plan import _random_frame

ROOT = Path(__file__).resolve().parents[2]
CORPUS = Path(os.environ.get("LOLACLI_CORPUS", Path(__file__).parents[3] / "shared" / "corpus"))
CORPUS_ENIS = sorted((CORPUS / "eni").glob("*.xml")) if (CORPUS / "eni").is_dir() else []
PERIOD_NS = 500_000
PLANNABLE = {C.LRD, C.LWR, C.LRW, C.BRD, C.ARMW}
# corpus ENIs whose plannable cyclic frame the C core runs (the others read the mailbox
# state through a bit-wise FMMU, which the frame plan leaves to the ESC's own code)
COMPILED_CORPUS = {
    "rocos-ethercat__bcr_eni.xml",
    "rocos-ethercat__eni.xml",
    "rocos-ethercat__eni1.xml",
    "rocos-ethercat__eni4.xml",
    "rocos-ethercat__eni7.xml",
    "rocos-ethercat__eni_tech6.xml",
}

needs_core = pytest.mark.skipif(not core_available(), reason="C core not built")
pytestmark = needs_core


class Twin:
    """Looks like a chain to :class:`Bus`; every frame goes through both engines."""

    def __init__(
        self,
        eni: Eni,
        *,
        seed: int = 7,
        drift_ppb: int = 20,
        clock_spread_ns: int | None = None,
        faults: dict[str, float] | None = None,
        compare_every: int = 29,
        python_devices: tuple[int, ...] = (),
        timing: ChainTiming | None = None,
    ) -> None:
        def chain(engine: str) -> Chain:
            f = Faults(seed=seed, **(faults or {}))
            made = build_chain(eni, drift_ppb=drift_ppb, engine=engine, faults=f, timing=timing)
            for position in python_devices:  # a step of their own: cycled in Python
                made._slaves[position].app.device.__class__ = OwnStep  # type: ignore[union-attr]
            return made

        self.c = chain("c")
        self.py = chain("python")
        # where a cycle may give way in both engines: around the slaves Python cycles
        n = len(eni.slaves)
        self.boundaries = sorted({b for p in python_devices for b in (p, p + 1) if 0 < b < n})
        self.gave_way = 0  # cycles both engines interrupted at the same slave
        self.firmware_pieces = 0  # firmware work run a piece at a time between frames
        if clock_spread_ns is not None:  # clocks close enough for the loop's fine steps
            spread = random.Random(seed)
            for a, b in zip(self.c._slaves, self.py._slaves, strict=True):
                start = spread.randrange(-clock_spread_ns, clock_spread_ns)
                a.clock.start_ns = b.clock.start_ns = start
        self.timing = self.c.timing
        self.compare_every = compare_every  # frames between state comparisons (0: never)
        self.rng = random.Random(seed)
        self.frames = 0
        self.compared = 0
        self.held_cycles = 0  # most device cycles the core held at once
        self.compiled_frames = 0  # frames the C core answered

    def process(self, frame: bytes, t_ns: int, *, defer_cycles: bool = False):  # type: ignore[no-untyped-def]
        """Like a real-time server half of the time: answers first, runs the deferred work
        now and then, or holds the cycle because the next frame is already there."""
        defer = defer_cycles or self.rng.random() < 0.5
        replies = [ch.process(frame, t_ns, defer_cycles=defer) for ch in (self.c, self.py)]
        assert replies[0] == replies[1], f"frame {self.frames}: {frame.hex()}"
        self._note_held()
        key = layout_key(frame)
        plan = self.c.planner.plans.get(key) if key is not None else None
        if plan is not None and isinstance(plan.compiled, CompiledPlan):
            self.compiled_frames += 1
        if defer:  # as the raw-socket server: firmware a piece at a time, then the cycle
            if self.c.firmware_pending and self.rng.random() < 0.5:
                self.firmware_pieces += 1
                self.both(lambda ch: ch.run_firmware(1))
            roll = self.rng.random()
            if roll < 0.3:
                self._run_deferred()
            elif roll < 0.45:
                self.both(lambda ch: ch.hold_deferred_cycle())
        self.frames += 1
        if self.compare_every and self.frames % self.compare_every == 0:
            self.same_state()
        return replies[0]

    def _run_deferred(self) -> None:
        """The work after the answer, the cycle giving way at a position where both
        engines can (a frame came): the rest is held and goes on from there later."""
        t_ns = self.c._deferred_t_ns
        if not self.boundaries or t_ns is None or not -VALUE_LIMIT < t_ns < VALUE_LIMIT:
            self.both(lambda ch: ch.run_deferred_cycles())
            return
        target = self.rng.choice(self.boundaries)
        done = [
            ch.run_deferred_cycles(should_yield=GiveWay(ch, target)) for ch in (self.c, self.py)
        ]
        assert done[0] == done[1]
        self.gave_way += not done[0]

    def both(self, action: Callable[[Chain], object]) -> None:
        results = [action(ch) for ch in (self.c, self.py)]
        assert results[0] == results[1]

    def _note_held(self) -> None:
        core = self.c._core
        assert core is not None
        self.held_cycles = max(self.held_cycles, len(core.held_devices()))

    def same_state(self) -> None:
        self.both(lambda ch: ch.run_deferred_cycles())
        self.compared += 1
        for i, (a, b) in enumerate(zip(self.c.slaves, self.py.slaves, strict=True)):
            assert_same_slave(a, b, f"frame {self.frames}, slave {i + 1}")
        assert self.c.stats == self.py.stats
        assert self.c.firmware_pending == self.py.firmware_pending == 0


class OwnStep(Cia402Drive):
    """A drive with a step of its own (the same behaviour): the core leaves it to Python."""

    def step(self, t_ns: int) -> None:
        super().step(t_ns)


class GiveWay:
    """``should_yield`` for one chain's application cycle: yes once the slaves before
    position ``target`` have run. The Python engine asks after every slave, the C core
    after each run of slaves it holds and each slave Python cycles (its pieces)."""

    def __init__(self, chain: Chain, target: int) -> None:
        self.chain, self.target, self.asked = chain, target, 0

    def __call__(self) -> bool:
        n = len(self.chain._active)
        core = self.chain._core
        if core is None:
            position = self.asked + 1
        else:
            position = [hi for _lo, hi, _esc in core._pieces[n] if hi < n][self.asked]
        self.asked += 1
        return position == self.target


def assert_same_slave(a: Esc, b: Esc, where: str) -> None:
    if a.mem != b.mem:
        differ = [f"0x{k:04X}" for k in range(len(a.mem)) if a.mem[k] != b.mem[k]]
        raise AssertionError(f"{where}: memories differ at {differ[:8]}")
    assert a.clock == b.clock, where
    assert a.counters == b.counters, where
    fields = ("outputs_valid", "pending_op", "last_outputs_ns", "now_ns", "al_state")
    fields += ("_mailbox_pending", "_mailbox_write_counter", "_last_mailbox_in")
    assert [getattr(a, f) for f in fields] == [getattr(b, f) for f in fields], where
    da, db = device_of(a), device_of(b)
    assert (da is None) == (db is None)
    if da is None or db is None:
        return
    values_a = [(e.index, e.subindex, e.value) for o in da.od for e in o.entries.values()]
    values_b = [(e.index, e.subindex, e.value) for o in db.od for e in o.entries.values()]
    if values_a != values_b:
        differ = [(x, y) for x, y in zip(values_a, values_b, strict=True) if x != y]
        raise AssertionError(f"{where}: object dictionaries differ: {differ[:4]}")
    for name in ("t_ns", "state", "power", "previous_cw", "last_sample"):
        assert getattr(da, name, None) == getattr(db, name, None), f"{where}: {name}"
    assert da.od.version == db.od.version and da.od.writes == db.od.writes, where
    assert da.od.al_state == db.od.al_state, where


# ---------------------------------------------------------------- the master's side
def _key(name: str) -> str:
    return name.lower().replace(" ", "").rsplit(".", 1)[-1]


class Outputs:
    """The ENI's output process image, written by variable name suffix."""

    SUFFIXES = {
        "controlword": ("controlword",),
        "mode": ("modesofoperation", "modeofoperation"),
        "target_position": ("targetposition", "profiletargetposition"),
        "target_velocity": ("targetvelocity",),
    }
    FORMATS = {"controlword": "<H", "mode": "<b", "target_position": "<i", "target_velocity": "<i"}

    def __init__(self, eni: Eni) -> None:
        out = [v for v in eni.process_image.variables if v.direction.value == "output"]
        size = max([(v.bit_offset + v.bit_size + 7) // 8 for v in out] + [1])
        self.image = bytearray(max(size, eni.process_image.outputs_bytes))
        self.at: dict[str, list[int]] = {name: [] for name in self.SUFFIXES}
        for v in out:
            for name, suffixes in self.SUFFIXES.items():
                width = struct.calcsize(self.FORMATS[name]) * 8
                if _key(v.name) in suffixes and v.bit_offset % 8 == 0 and v.bit_size == width:
                    self.at[name].append(v.bit_offset // 8)

    def set(self, name: str, value: int | Callable[[int], int]) -> None:
        for k, at in enumerate(self.at[name]):
            number = value(k) if callable(value) else value
            struct.pack_into(self.FORMATS[name], self.image, at, number)


def cyclic_frame(eni: Eni, outputs: Outputs, *, plannable_only: bool) -> bytes:
    datagrams = []
    for c in eni.cyclic_frames[0].commands:
        if plannable_only and c.cmd not in PLANNABLE:
            continue
        if c.logical_address is not None:
            start = c.output_offset_bytes or 0
            data = bytes(outputs.image[start : start + c.data_length_bytes])
            datagrams.append(
                Datagram.logical(c.cmd, c.logical_address, data.ljust(c.data_length_bytes, b"\0"))
            )
        else:
            datagrams.append(Datagram.physical(c.cmd, c.adp or 0, c.ado or 0, c.data_length_bytes))
    return encode_frame(make_frame(datagrams), pad=True)


def bring_up(
    bus: Bus,
    eni: Eni,
    outputs: Outputs,
    *,
    plannable_only: bool,
    first_cycle_ns: int | None = None,
) -> None:
    """INIT -> OP through the ENI's InitCmds; a refused step is not the test's business
    (both engines get the same frames either way). ``first_cycle_ns``: when the first
    application cycle runs (the clock jumps there). The cyclic frame comes from PREOP on,
    as many masters send it, so the first cycle in SAFEOP already has its plan."""
    frame = cyclic_frame(eni, outputs, plannable_only=plannable_only)
    for name in ("IP", "PS"):
        if name == "PS":
            for _ in range(3):
                bus.t_ns += PERIOD_NS
                bus.chain.process(frame, bus.t_ns)
        try:
            bus.transition(eni, name)
        except AssertionError:
            pass
    bus.t_ns = bus.t_ns + PERIOD_NS if first_cycle_ns is None else first_cycle_ns
    bus.chain.process(cyclic_frame(eni, outputs, plannable_only=plannable_only), bus.t_ns)
    try:
        bus.transition(eni, "SO")
    except AssertionError:
        pass


class Script:
    """The master's side of a run: cyclic frames with CiA 402 sequences, mixed with SDO,
    AL state changes, faults and odd times."""

    def __init__(
        self,
        eni: Eni,
        twin: Twin,
        *,
        plannable_only: bool,
        seed: int = 1,
        first_cycle_ns: int | None = None,
    ) -> None:
        self.eni, self.twin = eni, twin
        self.bus = Bus(twin)  # type: ignore[arg-type]
        self.first_cycle_ns = first_cycle_ns
        self.outputs = Outputs(eni)
        self.plannable_only = plannable_only
        self.rng = random.Random(seed)
        self.targets = [self.rng.randrange(-50_000, 50_000) for _ in range(64)]

    def cycle(self, step_ns: int = PERIOD_NS) -> None:
        self.bus.t_ns += step_ns
        frame = cyclic_frame(self.eni, self.outputs, plannable_only=self.plannable_only)
        self.twin.process(frame, self.bus.t_ns)

    def move(self, n: int, *, controlword: int = 0x0F, mode: int = 8) -> None:
        out = self.outputs
        for _ in range(n):
            self.targets = [t + self.rng.randrange(-900, 900) for t in self.targets]
            out.set("controlword", controlword)
            out.set("mode", mode)
            out.set("target_position", lambda k: self.targets[k])
            out.set("target_velocity", lambda k: 20_000 * (k + 1) * (-1) ** k)
            self.cycle()

    def sdo_write(self, position: int, index: int, sub: int, data: bytes) -> None:
        slave = self.eni.slaves[position - 1]
        mb = slave.mailbox
        if mb is None or not mb.out_length_bytes:
            return
        mbx = ((mb.out_start, mb.out_length_bytes), (mb.in_start, mb.in_length_bytes))
        try:
            self.bus.sdo_download(slave.station_address, index, sub, data, mbx)
        except (AssertionError, WireError):
            pass  # no answer, or an emergency first in the mailbox: the same in both

    def al_request(self, position: int, state: int) -> None:
        station = self.eni.slaves[position - 1].station_address
        self.bus.t_ns += 20_000
        self.bus.one(C.FPWR, station, 0x0120, struct.pack("<H", state))

    def run(self) -> None:
        bring_up(
            self.bus,
            self.eni,
            self.outputs,
            plannable_only=self.plannable_only,
            first_cycle_ns=self.first_cycle_ns,
        )
        out, twin, rng = self.outputs, self.twin, self.rng
        out.set("controlword", 0)
        self.move(4, controlword=0x00)
        for cw in (0x06, 0x07, 0x0F):  # shutdown, switch on, enable operation
            self.move(1, controlword=cw)
        self.move(60)  # CSP, no rate limit: actual jumps to target
        for position in range(1, min(len(self.eni.slaves), 4) + 1):
            self.sdo_write(position, 0x607F, 0, struct.pack("<I", 400_000 * position))
        self.move(60)  # CSP with the 0x607F rate limit
        self.sdo_write(1, 0x60FF, 0, struct.pack("<i", -123_456))
        self.move(30, mode=9)  # CSV
        self.move(3, controlword=0x07)  # disable operation
        self.move(5)
        self.move(4, controlword=0x02)  # quick stop
        self.move(3)  # enable from quick stop active
        twin.both(lambda ch: ch.drive_fault(1) if _is_drive(ch, 1) else None)
        self.move(5)
        self.move(2, controlword=0x8F)  # fault reset on the rising edge of bit 7
        for cw in (0x06, 0x07, 0x0F):
            self.move(1, controlword=cw)
        self.move(20)
        # profile position: a set-point, a relative one, a halt; then cyclic torque
        for cw in (0x0F, 0x1F, 0x0F, 0x5F, 0x15F, 0x0F):
            self.move(1, controlword=cw, mode=1)
        self.move(2, controlword=0x0F, mode=10)
        for _ in range(40):  # random controlwords and modes
            self.move(1, controlword=rng.randrange(0x10000), mode=rng.choice([8, 9, 1, 10, -3]))
        for cw in (0x00, 0x06, 0x07, 0x0F):
            self.move(1, controlword=cw)
        self.al_changes()
        self.watchdog()
        self.odd_times()
        self.remap()
        self.mailbox_repeats()
        self.mixed_traffic()
        self.register_traffic()
        twin.same_state()

    def al_changes(self) -> None:
        last = len(self.eni.slaves)
        self.al_request(last, AlState.SAFEOP)
        self.move(10)
        self.al_request(last, AlState.OP)  # waits for outputs: pending until the next frame
        self.move(20)
        self.al_request(1, AlState.PREOP)
        self.move(5)
        self.al_request(1, AlState.SAFEOP)
        self.al_request(1, AlState.OP)
        self.move(20)

    def watchdog(self) -> None:
        """No frames for 150 ms: every slave with an SM watchdog falls back to SAFEOP
        with 0x001B; then the error is acknowledged and OP requested again."""
        self.bus.t_ns += 150_000_000
        self.twin.both(lambda ch: ch.tick(self.bus.t_ns))
        expired = [
            esc.al_status_code == AlStatusCode.SYNC_MANAGER_WATCHDOG for esc in self.twin.c.slaves
        ]
        self.move(3)
        for position, hit in enumerate(expired, start=1):
            if hit:
                self.al_request(position, AlState.SAFEOP | 0x10)  # acknowledge
                self.al_request(position, AlState.OP)
        self.move(20)
        self.twin.same_state()
        # and watchdogs that expire in the middle of cyclic traffic: 120 ms of frames that
        # only read (LRD instead of LRW/LWR), so no slave gets outputs
        for _ in range(240):
            self.bus.t_ns += PERIOD_NS
            frame = cyclic_frame(self.eni, self.outputs, plannable_only=self.plannable_only)
            self.twin.process(_reads_only(frame), self.bus.t_ns)
        self.al_recover()
        self.move(5)

    def odd_times(self) -> None:
        self.move(5)
        self.cycle(step_ns=-3 * PERIOD_NS)  # time goes back
        self.cycle(step_ns=0)
        self.move(3)
        self.cycle(step_ns=9_000_000_000)  # a 9 s gap (with the watchdogs: a reason to tick)
        self.move(3)
        self.al_recover()
        saved = self.bus.t_ns
        self.bus.t_ns = (1 << 62) + 17  # beyond what the core takes: the reference runs
        self.move(3)
        self.bus.t_ns = saved + 10 * PERIOD_NS
        self.al_recover()
        self.move(10)

    def al_recover(self) -> None:
        for position, esc in enumerate(self.twin.c.slaves, start=1):
            if esc.al_state != AlState.OP:
                self.al_request(position, AlState.SAFEOP | 0x10)
                self.al_request(position, AlState.OP)
        self.move(2)

    def remap(self) -> None:
        """TxPDO assignment of the first slave cut to one PDO and back (od.version): in
        PREOP, where the PDO configuration is writable; in OP the write is refused, and
        so is one into an input object (object access by state and direction)."""
        self.sdo_write(1, 0x1C13, 0, b"\x00")  # OP: abort 0x08000022
        self.sdo_write(1, 0x6064, 0, b"\x01\x00\x00\x00")  # an input: read-only
        self.move(3)
        self.al_request(1, AlState.PREOP)
        self.move(3)
        self.sdo_write(1, 0x1C13, 0, b"\x00")
        self.move(5)
        self.sdo_write(1, 0x1C13, 0, b"\x01")
        self.al_request(1, AlState.SAFEOP)
        self.move(3)
        self.al_request(1, AlState.OP)
        self.move(5)

    def mailbox_repeats(self) -> None:
        """A master that re-sends mailbox writes while the cyclic frames run (the core
        holds the slaves between them): a write into the full mailbox (WKC 0), the
        identical write again after the firmware took the first (dropped by its counter),
        the repeat request toggle, and INIT forgetting the counter is left to test_mailbox."""
        slave = self.eni.slaves[0]
        mb = slave.mailbox
        if mb is None or not mb.out_length_bytes or not mb.in_length_bytes:
            return
        station = slave.station_address
        bus = self.bus
        for counter in (1, 1, 2, 2, 3):
            box = encode_mailbox(
                make_mailbox(
                    MailboxType.CoE, encode_sdo(SdoUploadRequest(0x1018, 1)), counter=counter
                ),
                buffer_bytes=mb.out_length_bytes,
            )
            for _ in range(2):  # the write and its repeat
                bus.t_ns += 20_000
                bus.one(C.FPWR, station, mb.out_start, box)
                self.move(1)
            for _ in range(self.rng.randrange(3)):
                bus.one(C.FPRD, station, 0x080D, 1)  # the master polls SM1's status
                self.move(1)
            bus.one(C.FPRD, station, mb.in_start, mb.in_length_bytes)
            if counter == 2:  # the answer came back damaged: toggle the repeat request
                activate = bus.one(C.FPRD, station, 0x080E, 2).data
                bus.one(C.FPWR, station, 0x080E, bytes([activate[0] ^ 0x02, activate[1]]))
                self.move(2)
                bus.one(C.FPRD, station, 0x080F, 1)
                bus.one(C.FPRD, station, mb.in_start, mb.in_length_bytes)
            self.move(1)

    def register_traffic(self) -> None:
        """Random register frames of every addressing (APxx, FPxx, BRD/BWR/BRW through
        their fast paths, ARMW/FRMW) between cyclic frames the core answers: the general
        path gives back what the core holds of exactly the slaves each datagram reaches;
        a third of them single-slave register datagrams only, which the core's register
        path answers with the slaves held."""
        stations = [s.station_address for s in self.eni.slaves]
        for k in range(300):
            self.bus.t_ns += self.rng.randrange(1, 300_000)
            # a third of them for the core's register path, DC set-ups among them
            make = _register_frame if k % 3 else (_single_slave_frame, _dc_frame)[k % 2]
            frame = make(self.rng, len(self.eni.slaves), stations)
            self.twin.process(frame, self.bus.t_ns)
            if k % 2 == 0:
                self.move(1)

    def mixed_traffic(self) -> None:
        logical = self.eni.cyclic_frames[0].commands[0].data_length_bytes
        for _ in range(4):  # a BRD that brings data along: the slaves OR theirs into it
            data = self.rng.randbytes(2)
            frame = encode_frame(make_frame([Datagram.physical(C.BRD, 0, 0x0130, data)]))
            self.bus.t_ns += 10_000
            self.twin.process(frame, self.bus.t_ns)
        for k in range(150):
            self.bus.t_ns += self.rng.randrange(1, 300_000)
            self.twin.process(_random_frame(self.rng, len(self.eni.slaves), logical), self.bus.t_ns)
            if k % 3 == 0:
                self.move(1)
            if k % 40 == 0:
                self.twin.both(lambda ch: ch.tick(self.bus.t_ns))


def _reads_only(frame: bytes) -> bytes:
    """The frame with its LRW/LWR datagrams turned into LRD."""
    decoded = decode_frame(frame)
    datagrams = []
    for d in decoded.datagrams:
        if d.cmd in (C.LRW, C.LWR):
            datagrams.append(Datagram.logical(C.LRD, d.adp | d.ado << 16, bytes(len(d.data))))
        else:
            datagrams.append(Datagram.physical(d.cmd, d.adp, d.ado, bytes(d.data)))
    return encode_frame(make_frame(datagrams), pad=True)


def _is_drive(chain: Chain, position: int) -> bool:
    return hasattr(device_of(chain._slaves[position - 1]), "fault")


# ------------------------------------------------------------------------ tests
@pytest.mark.parametrize("name", ["lola.xml", "single_drive.xml", "ek1100_io.xml"])
@pytest.mark.parametrize(
    ("drift_ppb", "spread_ns", "compare_every"), [(20, None, 29), (-13, 5_000, 0)]
)
def test_c_core_matches_the_reference_on_the_examples(
    name: str, drift_ppb: int, spread_ns: int | None, compare_every: int
) -> None:
    """``compare_every`` 0: no state comparison (which gives the state back to Python)
    between the script's own, so the core holds it for long stretches."""
    eni = load_eni(EXAMPLES / name)
    twin = Twin(eni, drift_ppb=drift_ppb, clock_spread_ns=spread_ns, compare_every=compare_every)
    Script(eni, twin, plannable_only=False).run()
    assert twin.c.stats.planned_frames > 250
    assert twin.compiled_frames > 250  # answered by the C core
    assert twin.held_cycles == len(eni.slaves)  # every device's cycle ran in C


def test_c_core_matches_the_reference_with_cycles_that_give_way() -> None:
    """Two LOLA drives with a step of their own (cycled in Python): the application cycle
    after an answer gives way at the slaves around them in both engines (the C core runs
    the others in one call per run), the rest held and run later; firmware a piece at a
    time between frames. Replies and state stay the same bit for bit."""
    eni = load_eni(EXAMPLES / "lola.xml")
    twin = Twin(eni, python_devices=(4, 13))
    Script(eni, twin, plannable_only=False).run()
    assert twin.gave_way > 50
    assert twin.firmware_pieces > 10
    assert twin.compiled_frames > 250


@pytest.mark.parametrize("name", ["lola.xml", "ek1100_io.xml"])
def test_c_core_matches_the_reference_on_a_line_of_its_own_delays(name: str) -> None:
    """Per-slave delays from the ENI's port physics and cable segments of their own
    (``bus simulate --forwarding physics --cable-m``): the C core takes the line's port
    times from Python (``set_line``), so both engines see the frame at the same times at
    every slave (DC receive times 0x0900, system time delays) and answer alike."""
    eni = load_eni(EXAMPLES / name)
    n = len(eni.slaves)
    timing = ChainTiming(
        slave_delays_ns=tuple(physics_delays_ns([s.physics for s in eni.slaves])),
        cable_ns_per_segment=tuple(5 * (1 + 7 * i) for i in range(n)),
    )
    assert timing.port_times(0, n) != ChainTiming().port_times(0, n)  # a line of its own
    twin = Twin(eni, timing=timing)
    assert twin.c._port_offsets == twin.py._port_offsets == timing.port_times(0, n)
    Script(eni, twin, plannable_only=False).run()
    assert twin.compiled_frames > 250


@pytest.mark.parametrize("name", ["single_drive.xml", "ek1100_io.xml"])
def test_c_core_matches_the_reference_from_time_zero(name: str) -> None:
    """The first application cycle within the first analog sample period after t = 0."""
    eni = load_eni(EXAMPLES / name)
    twin = Twin(eni)
    Script(eni, twin, plannable_only=False, first_cycle_ns=400_000).run()
    assert twin.compiled_frames > 250


@pytest.mark.parametrize("path", CORPUS_ENIS, ids=[p.name for p in CORPUS_ENIS])
@pytest.mark.parametrize("plannable_only", [True, False], ids=["planned", "eni-frame"])
def test_c_core_matches_the_reference_on_corpus_enis(path: Path, plannable_only: bool) -> None:
    eni = load_eni(path)
    twin = Twin(eni, seed=len(path.name))
    Script(eni, twin, plannable_only=plannable_only).run()
    assert twin.compared > 5
    if plannable_only and path.name in COMPILED_CORPUS:
        assert twin.compiled_frames > 250


def test_c_core_matches_with_dropped_and_damaged_frames_and_link_loss() -> None:
    eni = load_eni(EXAMPLES / "lola.xml")
    twin = Twin(eni, faults={"drop_probability": 0.05, "corrupt_probability": 0.05})
    script = Script(eni, twin, plannable_only=False)
    bring_up(script.bus, eni, script.outputs, plannable_only=False)
    twin.c.faults.drop_probability = twin.py.faults.drop_probability = 0.0
    twin.c.faults.corrupt_probability = twin.py.faults.corrupt_probability = 0.0
    for cw in (0x06, 0x07, 0x0F):
        script.move(1, controlword=cw)
    for p in (0.05, 0.0):
        twin.c.faults.drop_probability = twin.py.faults.drop_probability = p
        twin.c.faults.corrupt_probability = twin.py.faults.corrupt_probability = p
        script.move(80)
    twin.both(lambda ch: ch.break_link(12))
    script.move(20)
    twin.both(lambda ch: ch.restore_link())
    script.move(20)
    twin.both(lambda ch: ch.schedule_link_loss(20, script.bus.t_ns + 10 * PERIOD_NS))
    script.move(20)
    twin.same_state()
    assert twin.c.stats.dropped > 0 and twin.c.stats.corrupted > 0 and twin.c.stats.links_lost == 1


def test_watchdogs_expire_per_slave_when_only_some_outputs_come() -> None:
    """Outputs for all drives, then for drives 11-21 only, then for drives 1-3 only: the
    drives 4-10 expire first (0x001B), 11-21 later; the Python checks the core hands over
    to see each slave's own last outputs (no comparison in between gives the state back
    to Python early)."""
    eni = load_eni(EXAMPLES / "lola.xml")
    twin = Twin(eni, compare_every=0)
    script = Script(eni, twin, plannable_only=False)
    bring_up(script.bus, eni, script.outputs, plannable_only=False)
    for cw in (0x06, 0x07, 0x0F):
        script.move(1, controlword=cw)
    drive_bytes = 11  # controlword, mode, target position, velocity offset

    def writes(first: int, last: int, ms: float) -> None:
        start = (first - 1) * drive_bytes
        data = bytes(script.outputs.image[start : last * drive_bytes])
        frame = encode_frame(make_frame([Datagram.logical(C.LWR, 0x10000 + start, data)]))
        for _ in range(round(2 * ms)):
            script.bus.t_ns += PERIOD_NS
            twin.process(frame, script.bus.t_ns)

    writes(11, 21, 1)  # both layouts get their plans now, so later frames keep the core
    writes(1, 3, 1)
    script.move(10)
    twin.same_state()  # everything back in Python once, then the core takes it again
    script.move(10)
    writes(11, 21, 80)
    writes(1, 3, 40)
    codes = [esc.al_status_code for esc in twin.c.slaves]
    assert codes[3:10] == [AlStatusCode.SYNC_MANAGER_WATCHDOG] * 7
    assert codes[10:21] == [AlStatusCode.NO_ERROR] * 11
    writes(1, 3, 70)
    codes = [esc.al_status_code for esc in twin.c.slaves]
    assert codes[:3] == [AlStatusCode.NO_ERROR] * 3
    assert codes[10:21] == [AlStatusCode.SYNC_MANAGER_WATCHDOG] * 11
    twin.same_state()


def _lola_moving() -> tuple[Eni, Twin, Script]:
    """The twin LOLA chains in OP, every drive enabled and 10 cycles on, the state left
    with the core (no comparison in between)."""
    eni = load_eni(EXAMPLES / "lola.xml")
    twin = Twin(eni, compare_every=0)
    script = Script(eni, twin, plannable_only=False)
    bring_up(script.bus, eni, script.outputs, plannable_only=False)
    for cw in (0x06, 0x07, 0x0F):
        script.move(1, controlword=cw)
    script.move(10)
    return eni, twin, script


def test_answer_work_and_cycle_in_one_call_as_the_reference(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The cyclic frame's answer, its deferred work and the slaves' cycle in one kernel
    call (CompiledPlan.answer_cycles) while nothing else waits: taken, and the state the
    same as the reference's (the watchdogs that expire meanwhile: the test above)."""
    outcomes: list[bool] = []  # whether the work and the cycle ran in the call
    answer_cycles = CompiledPlan.answer_cycles

    def counted(self: CompiledPlan, *args: object) -> object:
        answer, cycled = answer_cycles(self, *args)  # type: ignore[arg-type]
        outcomes.append(cycled)
        return answer, cycled

    monkeypatch.setattr(CompiledPlan, "answer_cycles", counted)
    eni, twin, script = _lola_moving()
    script.move(20)
    assert sum(outcomes) >= 10
    twin.same_state()


def test_a_watchdog_switched_off_in_op_by_the_register_path_stays_off() -> None:
    """A master clears the watchdog enable of drive 5's output SM in OP, one FPWR that the
    core's register path takes with the slaves held: the core gives that slave back (its
    watchdog time changes with the SM), so without outputs drive 5 stays in OP while the
    drives beside it expire, in both engines."""
    eni, twin, script = _lola_moving()
    core = twin.c._core
    assert core is not None and not core.released  # the core holds every slave
    taken = count_register_frames(twin.c)
    station = eni.slaves[4].station_address
    control = 0x0800 + 8 * twin.c._slaves[4].layout.outputs_sm + 4
    value = script.bus.fprd(station, control, 1)[0]
    assert value & 0x40  # SM_CONTROL_WATCHDOG
    script.bus.fpwr(station, control, bytes([value & ~0x40]))
    assert taken[0] == 2 and core.released == {4}
    frame = encode_frame(make_frame([Datagram.logical(C.LRD, 0x10000, 8)]))
    for _ in range(300):  # 150 ms of reads only
        script.bus.t_ns += PERIOD_NS
        twin.process(frame, script.bus.t_ns)
    codes = [esc.al_status_code for esc in twin.c.slaves]
    assert codes[3:6] == [
        AlStatusCode.SYNC_MANAGER_WATCHDOG,
        AlStatusCode.NO_ERROR,
        AlStatusCode.SYNC_MANAGER_WATCHDOG,
    ]
    twin.same_state()


def test_sync_managers_moved_in_op_move_the_process_data() -> None:
    """A master rewrites a slave's input SM start in OP (a register write, which the
    core's register path takes and gives the slave back): the next cycles put the inputs
    where the SM now is."""
    eni, twin, script = _lola_moving()
    station = eni.slaves[4].station_address
    for sm in range(2, 4):  # the process data SMs, wherever they are: 0x20 bytes on
        start = struct.unpack("<H", script.bus.fprd(station, 0x0800 + 8 * sm, 2))[0]
        script.bus.fpwr(station, 0x0800 + 8 * sm, struct.pack("<H", start + 0x20))
    script.move(10)
    twin.same_state()


def test_the_core_holds_the_state_and_chain_slaves_gives_it_back() -> None:
    eni = load_eni(EXAMPLES / "single_drive.xml")
    chain = build_chain(eni, engine="c")
    bus = Bus(chain)
    bus.bring_up(eni)
    size = eni.cyclic_frames[0].commands[0].data_length_bytes
    for cw in (0x06, 0x07, 0x0F, 0x0F, 0x0F):
        bus.cycle(eni, struct.pack("<Hbi", cw, 8, 777).ljust(size, b"\0"))
    core = chain._core
    assert core is not None and core.held_devices() == [0]
    drive = device_of(chain._slaves[0])
    assert drive is not None
    assert drive.od.get_int(0x6064) != 777  # the Python object lags while the core holds it
    assert device_of(chain.slaves[0]).od.get_int(0x6064) == 777  # read through Chain.slaves
    assert core.held_devices() == []
    bus.cycle(eni, struct.pack("<Hbi", 0x0F, 8, 778).ljust(size, b"\0"))
    assert core.held_devices() == [0]


def test_the_core_takes_the_devices_in_when_they_reach_safeop_not_in_a_cycle() -> None:
    """The devices' tables are built and loaded by the firmware that enters SAFEOP (after
    that frame's answer), so the first application cycle, which a real-time server may
    have to run in a later frame's answer path, finds them held (KickCAT's first LWR on
    LOLA took 1.5 ms while it built 25 of them)."""
    from lolacli.master.core import Master, MasterOptions
    from lolacli.master.transport import ChainTransport
    from lolacli.wire.registers import AlState as Al

    eni = load_eni(EXAMPLES / "lola.xml")
    chain = build_chain(eni, engine="c")
    core = chain._core
    assert core is not None
    master = Master(eni, ChainTransport(chain), options=MasterOptions(dc_drift_frames=50))
    master.bring_up(Al.PREOP)
    assert core.held_devices() == []
    master.bring_up(Al.SAFEOP)
    with_device = [i for i, esc in enumerate(chain._slaves) if device_of(esc) is not None]
    assert len(with_device) == 25 and core.held_devices() == with_device


def test_the_devices_are_tables_before_any_master_and_safeop_only_loads_them() -> None:
    """The chain flattens its devices when it is built, before a master connects, so the
    take-in at SAFEOP only loads the tables while the dictionary is unchanged (a master
    that reads the PDO assignment, as SOEM and KickCAT do): firmware time a frame arriving
    meanwhile would wait for (a single drive's PREOP -> SAFEOP piece ~450 -> ~210 µs
    here). A dictionary written in PREOP (the ENI's CoE InitCmds) is flattened again."""
    import dataclasses

    from lolacli.master.core import Master, MasterOptions
    from lolacli.master.transport import ChainTransport
    from lolacli.wire.registers import AlState as Al

    with_writes = load_eni(EXAMPLES / "single_drive.xml")
    slave = with_writes.slaves[0]
    assert slave.mailbox is not None and slave.mailbox.coe_init_cmds
    reads_only = dataclasses.replace(
        with_writes,
        slaves=(
            dataclasses.replace(
                slave, mailbox=dataclasses.replace(slave.mailbox, coe_init_cmds=())
            ),
        ),
    )
    for eni, kept in ((reads_only, True), (with_writes, False)):
        chain = build_chain(with_writes, engine="c")
        core = chain._core
        assert core is not None
        built = core._flat[0]
        assert built is not None and built.device is device_of(chain._slaves[0])
        master = Master(eni, ChainTransport(chain), options=MasterOptions(dc_drift_frames=50))
        master.bring_up(Al.SAFEOP)
        assert core.held_devices() == [0]
        assert (core._flat[0] is built) is kept


def test_firmware_work_runs_on_the_state_the_core_gave_back() -> None:
    """Work a slave's firmware does after the answer (queued while compiled frames ran
    and the core took every slave's ESC state) finds that state in its Esc object."""
    eni = load_eni(EXAMPLES / "lola.xml")
    chain = build_chain(eni, engine="c")
    bus = Bus(chain)
    bus.bring_up(eni)
    for _ in range(3):
        bus.cycle(eni)
    core = chain._core
    assert core is not None and not core.released  # the core holds every slave's scalars
    esc = chain._slaves[3]
    seen: list[tuple[bool, int]] = []

    class Firmware:  # stands for a bound method of the slave's Esc
        __self__ = esc

        def __call__(self) -> None:
            seen.append((esc.outputs_valid, esc.last_outputs_ns))

    esc.hand_to_firmware(Firmware())
    chain.run_firmware()
    assert core.released == {3}
    assert seen == [(True, bus.t_ns - 50_000 + chain._port_offsets[3].port0_ns)]


def test_the_status_line_leaves_the_core_its_state() -> None:
    """``bus emulate`` prints the slaves' states every second from the shared memories:
    the core keeps what it holds (giving all back and taking it again costs ~60 µs in the
    middle of serving)."""
    eni = load_eni(EXAMPLES / "lola.xml")
    chain = build_chain(eni, engine="c")
    bus = Bus(chain)
    bus.bring_up(eni)
    for _ in range(3):
        bus.cycle(eni)
    chain.stuck_in_safeop(2)
    bus.fpwr(eni.slaves[1].station_address, 0x0120, b"\x04\x00")
    bus.fpwr(eni.slaves[1].station_address, 0x0120, b"\x08\x00")
    for _ in range(3):
        bus.cycle(eni)
    core = chain._core
    assert core is not None and not core.released and core.held_devices()
    assert state_summary(chain) == "OP×1 SAFEOP!×1 OP×23"
    assert not core.released and core.held_devices()


def test_a_broadcast_of_registers_leaves_the_core_its_slaves() -> None:
    """A BRD of AL status or a BWR of AL control in OP (a master's state poll, the INIT
    request that ends its session) changes nothing the core holds but each slave's time:
    the core keeps every slave (giving 25 back took ~60 µs in the answer's path) and
    matches the reference; a BWR of a register it does hold (the watchdog divider) gives
    them all back first."""
    eni = load_eni(EXAMPLES / "lola.xml")
    twin = Twin(eni, compare_every=0)
    twin.rng = random.Random(0)  # no random deferring: the frames below defer by hand
    twin.rng.random = lambda: 1.0  # type: ignore[method-assign]
    bus = Bus(twin)  # type: ignore[arg-type]
    bus.bring_up(eni)
    core = twin.c._core
    assert core is not None

    def broadcast(cmd: int, ado: int, data: bytes | int) -> None:
        for _ in range(4):
            bus.cycle(eni)  # planned: the core holds every slave again
        assert not core.released
        bus.t_ns += 100_000
        frame = encode_frame(make_frame([Datagram.physical(cmd, 0, ado, data)]), pad=True)
        replies = [ch.process(frame, bus.t_ns, defer_cycles=True) for ch in (twin.c, twin.py)]
        assert replies[0] == replies[1]

    for cmd, ado, data in ((C.BRD, 0x0130, 2), (C.BWR, 0x0120, b"\x08\x00")):
        broadcast(cmd, ado, data)
        assert not core.released, hex(ado)  # the firmware (AL control) gives back its slave
        twin.same_state()
    broadcast(C.BWR, 0x0400, b"\xc2\x09")  # the watchdog divider: the watchdog time changes
    assert len(core.released) == len(eni.slaves)
    twin.same_state()
    broadcast(C.BWR, 0x0120, b"\x01\x00")  # INIT
    assert not core.released and twin.c.firmware_pending == len(eni.slaves)
    twin.both(lambda ch: ch.run_firmware(2))  # slave 1's check and entry into INIT
    assert core.released == {0}
    twin.same_state()
    assert all(esc.al_state == AlState.INIT for esc in twin.c.slaves)


def test_a_slave_that_starts_waiting_for_op_invalidates_the_plans() -> None:
    """A compiled plan sets outputs valid without the AL state machine: no plan may
    outlive a slave starting to wait for OP (its outputs event then goes through Python,
    and OP is entered by its firmware after the frame)."""
    eni = load_eni(EXAMPLES / "single_drive.xml")
    chain = build_chain(eni, engine="c")
    Bus(chain).bring_up(eni)
    esc = chain.slaves[0]
    esc.request_state(AlState.PREOP)
    chain.run_firmware()  # a checked request is entered by a piece of firmware of its own
    esc.request_state(AlState.SAFEOP)
    chain.run_firmware()
    epoch = chain.planner.epoch
    esc.request_state(AlState.OP)
    assert esc.pending_op and esc.al_state == AlState.SAFEOP
    assert chain.planner.epoch != epoch


def test_engine_choice() -> None:
    assert chain_engine("python") == "python"
    assert chain_engine(None) == "c"
    with pytest.raises(UsageError, match="expected one of"):
        chain_engine("numba")
    chain = build_chain(load_eni(EXAMPLES / "single_drive.xml"), engine="python")
    assert chain.engine == "python" and chain._core is None


def test_engine_choice_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("LOLACLI_CHAIN_ENGINE", "python")
    assert build_chain(load_eni(EXAMPLES / "single_drive.xml")).engine == "python"
    monkeypatch.setattr(core_module, "_library", lambda: None)
    monkeypatch.setenv("LOLACLI_CHAIN_ENGINE", "c")
    with pytest.raises(UsageError, match="not built"):
        chain_engine()
    monkeypatch.delenv("LOLACLI_CHAIN_ENGINE")
    assert chain_engine() == "python"  # no C core: the reference, silently


# ------------------------------------------------------------- the kernel's checks
def _lola_plan() -> tuple[Chain, CompiledPlan]:
    eni = load_eni(EXAMPLES / "lola.xml")
    chain = build_chain(eni, engine="c")
    bus = Bus(chain)
    bus.bring_up(eni)
    for _ in range(3):
        bus.cycle(eni)
    plans = [p for p in chain.planner.plans.values() if p is not None and p.logical]
    compiled = plans[0].compiled
    assert isinstance(compiled, CompiledPlan)
    return chain, compiled


def test_kernel_refuses_programs_that_reach_outside_their_buffers() -> None:
    """Every single-word change of a valid program is either refused by the check or
    still within bounds; those that pass run (under a sanitizer build: without a fault)."""
    chain, compiled = _lola_plan()
    lib = compiled.lib
    program = ctypes.cast(compiled.table.prog, ctypes.POINTER(ctypes.c_int64))
    words = compiled.table.prog_len
    rng = random.Random(5)
    refused = 0
    frame = bytes(compiled.buf)
    for _ in range(3000):
        k = rng.randrange(words)
        saved = program[k]
        program[k] = rng.choice(
            [saved + 1, saved - 1, -1, 1 << 40, 65536, len(frame), saved + rng.randrange(-64, 64)]
        )
        if lib.lolacli_core_check_plan(compiled.address):
            refused += 1
        else:
            compiled.pend[0] = 0
            lib.lolacli_core_answer(compiled.address, frame, len(frame), 10**12)
            lib.lolacli_core_finish(compiled.address)
        program[k] = saved
    assert lib.lolacli_core_check_plan(compiled.address) == 0
    assert refused > 1000


def test_the_per_frame_calls_skip_ctypes_and_answer_as_through_it() -> None:
    """The built module's own per-frame functions replace the ctypes ones (a sanitizer
    build loaded from a path keeps ctypes) and answer the cyclic frame as the ctypes
    declaration of the same function does; a wrong argument is a TypeError."""
    chain, compiled = _lola_plan()
    lib = compiled.lib
    via_ctypes = core_module.load_library(lib._name)
    assert via_ctypes is not None
    assert isinstance(via_ctypes.lolacli_core_answer, ctypes._CFuncPtr)
    assert not isinstance(lib.lolacli_core_answer, ctypes._CFuncPtr)
    frame = bytes(compiled.buf)
    answers = []
    for answer, finish in [
        (lib.lolacli_core_answer, lib.lolacli_core_finish),
        (via_ctypes.lolacli_core_answer, via_ctypes.lolacli_core_finish),
    ]:
        compiled.pend[0] = 0
        code = answer(compiled.address, frame, len(frame), 10**12)
        answers.append((code, bytes(compiled.buf)))
        finish(compiled.address)
    assert answers[0] == answers[1]
    with pytest.raises(TypeError):
        lib.lolacli_core_answer(compiled.address, bytearray(frame), len(frame), 10**12)
    with pytest.raises(TypeError):
        lib.lolacli_core_cycles(compiled.core.address, 1)
    with pytest.raises(OverflowError):
        lib.lolacli_core_cycles(compiled.core.address, 1, 1 << 70)


def test_kernel_refuses_slave_tables_out_of_bounds() -> None:
    """Offsets, sizes and state values outside what the kernel can run are refused (the
    row counts and buffer lengths are the wrapper's, which sets them from the arrays)."""
    chain, _compiled = _lola_plan()
    core = chain._core
    assert core is not None
    lib = core.lib
    row = SlaveTable.from_address(core.address)  # the first drive's table
    assert lib.lolacli_core_check_slave(core.address) == 0
    for name, bad in [
        ("out_start", 65530),
        ("in_bytes", 1 << 20),
        ("vals_len", 2),
        ("out_bytes", 1),
        ("kind", 99),
        ("clk_corr", 1 << 62),
        ("power", 0x1234),
        ("prev_cw", 0x10000),
    ]:
        saved = getattr(row, name)
        setattr(row, name, bad)
        assert lib.lolacli_core_check_slave(core.address) != 0, name
        setattr(row, name, saved)
    assert lib.lolacli_core_check_slave(core.address) == 0


def test_kernel_refuses_register_tables_out_of_bounds() -> None:
    """The register path's line: more active slaves than tables, a line shorter than
    them, another classes table, a small answer buffer or out array, a port time or a
    sync manager count beyond range, counter groups beyond the registers or not pairs."""
    chain, _compiled = _lola_plan()
    core = chain._core
    assert core is not None and core._regs is not None
    lib, table = core.lib, core._regs
    address = ctypes.addressof(table)
    assert lib.lolacli_core_check_registers(address) == 0
    for name, bad in [
        ("n_active", len(chain._slaves) + 1),
        ("line_len", core_module.LINE_WORDS * len(chain._slaves) - 1),
        ("classes_len", 0x0F00),
        ("buf_len", 15),
        ("out_len", core_module.out_words(len(chain._slaves)) - 1),
        ("groups_len", len(core._groups) - 1),
    ]:
        saved = getattr(table, name)
        setattr(table, name, bad)
        assert lib.lolacli_core_check_registers(address) != 0, name
        setattr(table, name, saved)
    for word, bad in [(0, 1 << 62), (3, 17), (3, -1), (5, -1), (6, 2)]:
        saved = core._line[word]
        core._line[word] = bad
        assert lib.lolacli_core_check_registers(address) != 0, word
        core._line[word] = saved
    for word, bad in [(0, -1), (1, 0x1001), (1, core._groups[0])]:
        saved = core._groups[word]
        core._groups[word] = bad
        assert lib.lolacli_core_check_registers(address) != 0, word
        core._groups[word] = saved
    assert lib.lolacli_core_check_registers(address) == 0
    assert not core.set_line([1 << 62])  # refused: the path is off, frames go to Python
    assert core.register_frame(bytes(60), 0) is None


def test_wrapper_gives_the_reference_what_the_core_cannot_hold() -> None:
    """A clock value beyond the core's arithmetic: the frames go through Python, with
    the same answers."""
    eni = load_eni(EXAMPLES / "lola.xml")
    twin = Twin(eni)
    script = Script(eni, twin, plannable_only=False)
    bring_up(script.bus, eni, script.outputs, plannable_only=False)
    script.move(10)
    twin.both(lambda ch: setattr(ch.slaves[3].clock, "correction_ns", 1 << 63))
    script.move(10)
    core = twin.c._core
    assert core is not None and len(core.released) == len(eni.slaves)
    assert core.held_devices()  # the devices' cycles need no ESC scalar: still in C
    twin.both(lambda ch: setattr(ch.slaves[3].clock, "correction_ns", 0))
    script.move(10)
    assert len(core.released) == 0
    twin.same_state()


def test_a_subclassed_device_runs_in_python_beside_the_core() -> None:
    from lolacli.devices.cia402 import Cia402Drive

    class Slower(Cia402Drive):
        def step(self, t_ns: int) -> None:
            super().step(t_ns)
            self.od.entry(0x6064, 0).value = bytes(4)

    eni = load_eni(EXAMPLES / "lola.xml")
    twin = Twin(eni)
    for chain in (twin.c, twin.py):
        app = chain._slaves[2].app
        app.device.__class__ = Slower  # type: ignore[union-attr]
    script = Script(eni, twin, plannable_only=False)
    bring_up(script.bus, eni, script.outputs, plannable_only=False)
    for cw in (0x06, 0x07, 0x0F):
        script.move(1, controlword=cw)
    script.move(30)
    core = twin.c._core
    assert core is not None and 2 not in core.held_devices() and 3 in core.held_devices()
    twin.same_state()


def test_held_flag_for_every_example_device() -> None:
    """Every device of the examples and of the corpus the core can describe runs in C."""
    for path in [EXAMPLES / "lola.xml", EXAMPLES / "ek1100_io.xml", *CORPUS_ENIS]:
        eni = load_eni(path)
        chain = build_chain(eni, engine="c")
        core = chain._core
        assert isinstance(core, ChainCore)
        core.cycles(len(eni.slaves), 1_000_000)  # takes every device it can describe
        assert core.held_devices() == list(range(len(eni.slaves))), path.name
        core.release_all()


# ------------------------------------------------------------------ sanitizers
SANITIZED_TESTS = (
    "(examples or give_way or refuses or moved or per_slave or corpus_enis and planned"
    " or joints_in_the_core) and not sanitizers"
)


def _runtime(name: str) -> str | None:
    out = subprocess.run(["gcc", f"-print-file-name={name}"], capture_output=True, text=True)
    path = out.stdout.strip()
    return path if out.returncode == 0 and os.path.isabs(path) else None


@pytest.mark.slow
def test_kernel_under_address_and_undefined_behaviour_sanitizers() -> None:
    """The differential tests again with the kernel built with ASan and UBSan (any
    out-of-bounds access, overflow or other undefined behaviour aborts the run). In a
    folder of its own: pytest's basetemp is rotated by every other session of the user."""
    if os.environ.get("LOLACLI_SANITIZED_RUN"):
        pytest.skip("already the sanitized run")
    if shutil.which("gcc") is None:
        pytest.skip("no gcc")
    runtimes = [_runtime("libasan.so"), _runtime("libubsan.so")]
    if None in runtimes:
        pytest.skip("gcc without the sanitizer runtimes")
    root = Path(__file__).resolve().parents[2]
    with tempfile.TemporaryDirectory(prefix="lolacli-sanitized-") as folder:
        work = Path(folder)
        library = work / "_ccore_sanitized.so"
        include = sysconfig.get_paths()["include"]
        subprocess.run(
            ["gcc", "-O1", "-g", "-fno-omit-frame-pointer", "-fsanitize=address,undefined",
             "-fno-sanitize-recover=all", "-std=c11", "-ffp-contract=off", "-fPIC", "-shared",
             f"-I{include}", str(root / "lolacli/emulator/_ccore.c"), "-o", str(library),
             "-lm"],
            check=True,
        )  # fmt: skip
        arguments = ["-q", "-x", "-p", "no:cacheprovider", "--capture=sys"]  # reports on fd 2
        arguments += ["--basetemp", str(work / "tmp")]
        arguments += ["tests/emulator/test_core.py", "tests/emulator/test_core_joints.py"]
        arguments += ["-k", SANITIZED_TESTS]
        driver = work / "run.py"
        driver.write_text(
            "import sys\n"
            f"sys.path.insert(0, {str(root)!r})\n"
            "import pytest\n"
            "from lolacli.emulator import core\n"
            f"lib = core.load_library({str(library)!r})\n"
            "assert lib is not None\n"
            "core._library = lambda: lib\n"
            f"sys.exit(pytest.main({arguments!r}))\n"
        )
        env = dict(os.environ)
        env["LD_PRELOAD"] = " ".join(str(r) for r in runtimes)
        env["ASAN_OPTIONS"] = "detect_leaks=0"
        env["UBSAN_OPTIONS"] = "print_stacktrace=1:halt_on_error=1"
        env["LOLACLI_SANITIZED_RUN"] = "1"
        env["PYTHONMALLOC"] = "malloc"  # every Python buffer from malloc, which ASan watches
        run = subprocess.run(
            [sys.executable, str(driver)], cwd=root, env=env, capture_output=True, text=True
        )
    assert run.returncode == 0, (run.stdout + run.stderr)[-3000:]
    assert " passed" in run.stdout


def test_without_the_c_core_the_fallback_is_said_once(monkeypatch: pytest.MonkeyPatch) -> None:
    """No C core built: the default engine is the Python reference, and the first chain
    says so on stderr (a SlowFallbackWarning), the next ones do not."""
    monkeypatch.delenv("LOLACLI_CHAIN_ENGINE", raising=False)
    monkeypatch.setattr(core_module, "core_available", lambda: False)
    monkeypatch.setattr(core_module, "_fallback_said", False)
    with pytest.warns(core_module.SlowFallbackWarning, match="Python reference"):
        assert chain_engine() == "python"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert chain_engine() == "python"
    script = (
        "import lolacli.emulator.core as c\n"
        "c.core_available = lambda: False\n"
        "c.chain_engine(); c.chain_engine()\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "LOLACLI_CHAIN_ENGINE"}
    env["PYTHONPATH"] = str(ROOT)
    done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True)
    assert done.returncode == 0
    assert done.stderr.count("is not built") == 1
