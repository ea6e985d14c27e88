"""A line of emulated slaves: a frame passes every ESC on the way out and comes back.

``Chain.process(frame_bytes, t_ns) -> (reply_bytes | None, delay_ns)`` is the in-process
transport: the master's frame in, the frame as it returns to the master out, with the
time it spent on the wire and in the slaves. Each ESC processes every datagram of the
frame in the order the frame reaches it (slave-major, as on the wire), and the first ESC
sets the locally administered bit of the source MAC (DESIGN.md "Direction").

A frame layout that repeats (the cyclic frame) is answered through a frame plan
(:mod:`lolacli.emulator.plan`): the same bytes, a fraction of the work. With
``defer_cycles`` the work that does not shape the answer (device cycles, the DC control
loops of the non-reference slaves, a plan's writes into the slaves' memories) waits for
:meth:`Chain.run_deferred_cycles`; it always runs before anything else touches the slaves.

As on hardware, the slaves' firmware (AL control requests, mailbox services, OP entered on
the first valid outputs) works after the frame that asked for it: a frame that writes AL
control and reads AL status sees the old state (:meth:`Chain.run_firmware`).

With the C core (:mod:`lolacli.emulator.core`, engine ``c``) the planned frames, their
deferred work, the watchdogs and the device cycles run in C on state the core holds; the
general path and the firmware give back the ESC state of each slave they touch first,
and a device goes back to Python before Python uses it. Both engines give the same bytes
and states (tests/emulator/test_core.py).
"""

from __future__ import annotations

import os
import random
import struct
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

from lolacli.emulator.core import ChainCore, core_available
from lolacli.emulator.esc import (
    Esc,
    PortTimes,
    broadcast_of_registers,
    broadcast_read,
    broadcast_write,
)
from lolacli.emulator.plan import (
    NOT_COMPILED,
    PLANNABLE,
    Deferred,
    FramePlan,
    Key,
    Pieces,
    finish,
    layout_key,
    plan_pieces,
)
from lolacli.emulator.registers import (
    AL_STATUS,
    FMMU,
    PROCESS_RAM,
    SM,
    SYNC_MANAGER_BYTES,
    AlState,
)
from lolacli.emulator.sii import sii_layout
from lolacli.errors import UsageError, WireError
from lolacli.timing.model import (
    CABLE_NS_PER_M,
    DEFAULT_CABLE_M,
    DEFAULT_PER_SLAVE_DELAY_NS,
    LINK_100_MBIT_S,
    frame_bytes,
    predict_total_ns,
    wire_time_ns,
)
from lolacli.wire.commands import LOGICAL, Command
from lolacli.wire.frame import (
    DATAGRAM_HEADER_BYTES,
    ECAT_HEADER_BYTES,
    ECAT_TYPE_COMMANDS,
    WKC_BYTES,
    decode_ethernet_header,
    decode_frame,
)
from lolacli.wire.registers import AlStatusCode

_U16 = struct.Struct("<H")
_HEAD = struct.Struct("<BBHHH")  # cmd, index, adp, ado, length word
SOURCE_MAC_LOCAL_BIT = 0x02


@dataclass(frozen=True, slots=True)
class ChainTiming:
    """Delay model of a line, the one :mod:`lolacli.timing` predicts with.

    ``processing_ns`` is the delay through an ESC's processing unit on the way out,
    ``forward_ns`` the delay of passing an ESC on the way back (together the timing
    model's per-slave delay, 1000 ns by default), ``cable_ns`` one cable segment one way
    (1 m at 5 ns/m). Round trip = wire time of the frame (DESIGN.md frame bytes) + slaves
    × per-slave delay + every segment out and back.
    """

    link_bit_s: int = LINK_100_MBIT_S
    processing_ns: int = 600
    forward_ns: int = DEFAULT_PER_SLAVE_DELAY_NS - 600
    cable_ns: int = round(DEFAULT_CABLE_M * CABLE_NS_PER_M)

    @property
    def per_slave_delay_ns(self) -> int:
        return self.processing_ns + self.forward_ns

    def wire_time_ns(self, frame_bytes: int) -> int:
        return wire_time_ns(frame_bytes, self.link_bit_s)

    def port_times(self, t_ns: int, slaves: int) -> list[PortTimes]:
        """When the frame's head reaches each slave's port 0 (out) and port 1 (back)."""
        out = [t_ns + (i + 1) * self.cable_ns + i * self.processing_ns for i in range(slaves)]
        back: list[int | None] = [None] * slaves
        if slaves:
            t = out[-1] + self.processing_ns
            for i in range(slaves - 2, -1, -1):
                t += self.cable_ns
                back[i] = t
                t += self.forward_ns
        return [PortTimes(o, b) for o, b in zip(out, back, strict=True)]

    def round_trip_ns(self, datagram_lengths: list[int], slaves: int) -> int:
        wire = wire_time_ns(frame_bytes(datagram_lengths), self.link_bit_s)
        return predict_total_ns(wire, slaves, self.per_slave_delay_ns, 2 * slaves * self.cable_ns)


@dataclass(slots=True)
class Faults:
    """Faults injected at the chain, drawn per frame from one seeded generator.

    ``drop_probability``: the frame is destroyed on the cable between the master and the
    first slave; nothing comes back, and the first slave counts it on port 0 as hardware
    would for a frame hit by noise (ESC datasheets, register 0x0300: the invalid frame
    counter for the failed FCS, 0x0301 RX error counter for the PHY's symbol errors).

    ``corrupt_probability``: the frame is damaged as it leaves the slave at 1-based
    position ``corrupt_at_slave`` (``None``: a cable segment drawn at random, 0 the
    master's own cable). The next slave sees a bad FCS on port 0 (invalid frame counter
    0x0300), marks the frame and does not process it; every slave further along counts
    the marked frame as a forwarded RX error (0x0308 + port: port 0 on the way out,
    port 1 on the way back). The master still gets the frame back, with the working
    counters of the slaves before the damage only.
    """

    drop_probability: float = 0.0
    seed: int = 0
    rng: random.Random = field(default_factory=random.Random)
    corrupt_probability: float = 0.0
    corrupt_at_slave: int | None = None

    def __post_init__(self) -> None:
        self.rng.seed(self.seed)

    def drop(self) -> bool:
        return self.drop_probability > 0 and self.rng.random() < self.drop_probability

    def corrupt(self, slaves: int) -> int | None:
        """How many of ``slaves`` process the frame before it is damaged; ``None``: intact."""
        if self.corrupt_probability <= 0 or self.rng.random() >= self.corrupt_probability:
            return None
        if self.corrupt_at_slave is not None:
            return min(self.corrupt_at_slave, slaves)
        return self.rng.randrange(slaves) if slaves else 0


@dataclass(slots=True)
class ChainStats:
    frames: int = 0
    replies: int = 0
    dropped: int = 0
    corrupted: int = 0
    links_lost: int = 0
    malformed: int = 0
    logical_frames: int = 0
    planned_frames: int = 0  # answered through a frame plan


_READS_ONLY = frozenset({Command.APRD, Command.FPRD, Command.BRD})
_APRD, _FPRD, _BRD, _BWR = int(Command.APRD), int(Command.FPRD), int(Command.BRD), int(Command.BWR)
_APWR, _FPWR = int(Command.APWR), int(Command.FPWR)
_PLANNABLE = frozenset(int(c) for c in PLANNABLE)
_AUTO_INCREMENT_SINGLE = frozenset({Command.APRD, Command.APWR, Command.APRW})
_CONFIGURED_SINGLE = frozenset({Command.FPRD, Command.FPWR, Command.FPRW})


@dataclass(slots=True)
class _Slot:
    """A datagram's place in the frame."""

    header: int  # offset of the datagram header in the frame
    cmd: int
    length: int
    adp: int  # as the next slave sees it
    ado: int


_AL_STATUS = AL_STATUS
_OP = int(AlState.OP)
# FMMU and SM registers: where a device cycle's data go
_SM_AND_FMMU = (FMMU, SM + 16 * SYNC_MANAGER_BYTES)


def _touches_process_data(slots: list[_Slot]) -> bool:
    """Whether a frame may see or change what a held device cycle reads and writes: the
    SM buffers in process RAM (logical datagrams, physical ones from 0x1000) and the
    FMMU/SM registers. Register reads and other register writes may go first, as they
    would on a slave whose application is late (AL control requests wait for the
    firmware anyway)."""
    lo, hi = _SM_AND_FMMU
    for slot in slots:
        cmd = slot.cmd
        if cmd in LOGICAL or slot.ado + slot.length > PROCESS_RAM:
            return True
        if cmd not in _READS_ONLY and slot.ado < hi and lo < slot.ado + slot.length:
            return True
    return False


def _slots(frame: bytes) -> list[_Slot] | None:
    """The datagrams of an untagged EtherCAT command frame; ``None`` for anything else
    (the full decoder then tells a tagged frame from a malformed one). Accepts what
    :func:`lolacli.wire.frame.decode_frame` accepts for such frames."""
    n = len(frame)
    if n < 16 or frame[12] != 0x88 or frame[13] != 0xA4:
        return None
    word = frame[14] | frame[15] << 8
    end = 16 + (word & 0x7FF)
    if word >> 12 != ECAT_TYPE_COMMANDS or end > n:
        return None
    out = []
    pos = 16
    unpack = _HEAD.unpack_from
    while True:
        if pos + DATAGRAM_HEADER_BYTES > end:
            return None
        cmd, _index, adp, ado, lenw = unpack(frame, pos)
        length = lenw & 0x7FF
        out.append(_Slot(pos, cmd, length, adp, ado))
        pos += DATAGRAM_HEADER_BYTES + length + WKC_BYTES
        if pos > end:
            return None
        if not lenw & 0x8000:
            return out


PLAN_CACHE_SIZE = 32
CYCLIC_LAYOUTS = 4  # logical layouts planned again unasked when an epoch ends
ENGINES = ("c", "python")
ENGINE_VARIABLE = "LOLACLI_CHAIN_ENGINE"


def chain_engine(engine: str | None = None) -> str:
    """The engine a chain runs its cyclic work with: ``engine``, else the environment's
    ``LOLACLI_CHAIN_ENGINE``, else ``c`` when the C core is built and ``python`` when not.
    UsageError for an unknown name or ``c`` without the C core."""
    chosen = engine or os.environ.get(ENGINE_VARIABLE) or ""
    if not chosen:
        return "c" if core_available() else "python"
    if chosen not in ENGINES:
        raise UsageError(f"chain engine {chosen!r}: expected one of {', '.join(ENGINES)}")
    if chosen == "c" and not core_available():
        raise UsageError(
            "chain engine 'c': the C core (lolacli.emulator._ccore) is not built; "
            "reinstall with a C compiler, or use 'python'"
        )
    return chosen


class Chain:
    """Slaves in line order; ``process`` runs a frame through all of them.

    A frame layout seen ``plan_after`` times gets a :class:`~lolacli.emulator.plan.FramePlan`
    (0: never), the fast path for cyclic frames; it gives the same bytes as the general
    path.

    ``engine`` (see :func:`chain_engine`): with ``c`` the planned frames, their deferred
    work, the watchdogs and the device cycles run in the C core (:mod:`.core`), which holds
    the slaves' cyclic state between frames and gives it back before Python code touches
    it; ``python`` runs the reference code only."""

    #: a logical layout is planned after its first frame (a server makes the plan after
    #: the answer; in process, without deferred cycles, it is made for the frame itself),
    #: so the cyclic frame's second comes planned: pysoem sends one LRW in SAFEOP before
    #: it asks for OP, which ends that plan's epoch (see _replan_key)
    plan_after = 1
    #: a layout without logical datagrams (a start-up's register polls) is planned only
    #: after this many repeats in one epoch: making a plan takes 40-170 µs after the answer
    #: (LOLA), which the master's next frame may wait for, and any register write starts
    #: a new epoch; such frames take 10-20 µs on the general path
    register_plan_after = 64

    def __init__(
        self,
        slaves: list[Esc],
        *,
        timing: ChainTiming | None = None,
        faults: Faults | None = None,
        engine: str | None = None,
    ) -> None:
        self._slaves = slaves
        self.engine = chain_engine(engine)
        self._core = ChainCore(slaves) if self.engine == "c" else None
        self.timing = timing or ChainTiming()
        self.faults = faults or Faults()
        self.stats = ChainStats()
        self._deferred_t_ns: int | None = None
        self.reachable = len(slaves)
        self._epoch = [0]  # one cell for all slaves: any change invalidates the plans
        self._addressing = [0]  # one cell for all slaves: configured addresses changed
        self._sii_version = [0]  # one cell for all slaves: an SII image or layout replaced
        self._pdi: list[tuple[Callable[..., object], tuple[Any, ...]]] = []  # firmware work
        for esc in slaves:
            esc.epoch = self._epoch
            esc.addressing = self._addressing
            esc.sii_version = self._sii_version
            esc.pdi = self._pdi
        self._stations_at = -1
        self._line_at = -1  # the SII version the C core's line is for (-1: none)
        self._stations_map: dict[int, int] = {}
        self._delays: dict[tuple[tuple[int, ...], int], int] = {}
        self._plans: dict[Key, FramePlan | None] = {}
        self._last_plan: FramePlan | None = None  # the plan the last planned lookup found
        self._plan_epoch = -1
        self._seen: dict[Key, int] = {}  # layouts with logical datagrams: times seen
        self._seen_registers: dict[Key, int] = {}  # the others, in the current epoch
        self._deferred_dc: Deferred = []  # what a plan left for after the answer
        self._held: int | None = None  # a late application cycle's time
        self._held_from = 0  # ... and the position it goes on from
        self._plan_later: dict[Key, None] = {}  # plans to make after the answer, in order
        # ... being made in pieces between frames: its layout, the epoch it is for, the work
        self._plan_job: tuple[Key, int, Pieces] | None = None
        # the layouts of the last logical plans frames asked for, oldest first, planned
        # again unasked in a new epoch: each with its latest plan and whether a frame
        # asked for that one (a plan made unasked and never used ends it there)
        self._cyclic_keys: dict[Key, tuple[FramePlan, bool]] = {}
        self._replanned: set[Key] = set()  # ... those of them planned again in the epoch
        self._replanned_epoch = -1  # ... it is
        self._link_loss: tuple[int, int] | None = None  # (after position, at_ns)
        self._line_changed()

    @property
    def slaves(self) -> list[Esc]:
        """The slaves in line order, their Python state up to date (the C core gives back
        what it holds first; keep no slave or device across frames, read them here)."""
        if self._core is not None:
            self._core.release_all()
        return self._slaves

    def al_statuses(self) -> list[int]:
        """The AL status register (0x0130) of every slave, read from the ESC memories
        (which the C core shares: nothing is given back, so a status line costs no
        frame its held state)."""
        return [esc.mem[AL_STATUS] for esc in self._slaves]

    def use_sii(self, position: int, image: bytes) -> None:
        """Give the slave at 1-based ``position`` another SII image, then power it on again
        (so the ESC's alias and layout come from the new image)."""
        esc = self.slaves[position - 1]
        esc.sii = bytearray(image)
        esc.layout = sii_layout(bytes(image))
        self._sii_version[0] += 1
        esc.reset()

    def _line_changed(self) -> None:
        """Topology and arrival offsets of the slaves the frames reach."""
        self._epoch[0] += 1
        self._addressing[0] += 1
        self._active = self.slaves[: self.reachable]
        # when the frame reaches each slave, relative to its start: fixed for a line
        self._port_offsets = self.timing.port_times(0, len(self._active))
        if self._core is not None:  # the C core's line now, not in a frame's answer
            self._set_core_line(self._core)
        for i, esc in enumerate(self.slaves):
            esc.set_topology(last=i >= self.reachable - 1)

    def break_link(self, after: int) -> None:
        """Fault: the cable after 1-based position ``after`` is cut; the slave there closes
        its port 1 and returns the frames, the slaves behind it see nothing (0: no slave)."""
        if not 0 <= after <= len(self.slaves):
            raise UsageError(
                f"link after slave {after}: the chain has slaves 1..{len(self.slaves)}"
            )
        self.reachable = after
        self._line_changed()

    def schedule_link_loss(self, after: int, at_ns: int) -> None:
        """Fault: the cable after 1-based position ``after`` is cut at ``at_ns`` (the time
        base of :meth:`process` and :meth:`tick`). From then on, the slave
        there shows port 1 closed without link in DL status 0x0110 and its lost link
        counter 0x0311 (port 1) has counted one; the slave behind it (out of reach)
        counts one on port 0 (0x0310)."""
        if not 0 <= after <= len(self.slaves):
            raise UsageError(
                f"link after slave {after}: the chain has slaves 1..{len(self.slaves)}"
            )
        self._link_loss = (after, at_ns)

    def _due_link_loss(self, t_ns: int) -> None:
        if self._link_loss is None or t_ns < self._link_loss[1]:
            return
        after, self._link_loss = self._link_loss[0], None
        if after < self.reachable:
            if after > 0:
                self.slaves[after - 1].count_lost_link(1)
            self.slaves[after].count_lost_link(0)
            self.stats.links_lost += 1
        self.break_link(min(after, self.reachable))

    def restore_link(self) -> None:
        self.reachable = len(self.slaves)
        self._line_changed()

    def stuck_in_safeop(self, position: int, code: int = AlStatusCode.NO_VALID_OUTPUTS) -> None:
        """Fault: the slave at 1-based ``position`` refuses SAFEOP -> OP with ``code``."""
        self.slaves[position - 1].refuse_op_code = code

    def drive_fault(self, position: int, error_code: int = 0x5530) -> None:
        """Fault: the CiA 402 drive at 1-based ``position`` faults (statusword bit 3,
        0x603F) and sends a CoE emergency with ``error_code`` through its mailbox."""
        esc = self.slaves[position - 1]
        fault = getattr(getattr(esc.app, "device", None), "fault", None)
        if fault is None:
            raise UsageError(f"slave {position} is not a CiA 402 drive")
        fault(error_code)
        server = getattr(esc.app, "sdo", None)
        if server is not None:
            esc.post_mailbox(server.emergency(error_code, 0x01))

    def process(
        self, frame: bytes, t_ns: int, *, defer_cycles: bool = False
    ) -> tuple[bytes | None, int]:
        """The frame as it returns to the master, and its delay; ``None`` when lost.

        A frame with logical datagrams also runs one application cycle in every slave
        (outputs to the devices, new inputs for the next frame). ``defer_cycles`` leaves
        that to :meth:`run_deferred_cycles`, so a real-time transport can answer first.
        """
        self.stats.frames += 1
        self._due_link_loss(t_ns)
        if self._pdi and not defer_cycles:
            self._run_pdi()  # in-process: the firmware has kept up
        damaged = self.faults.corrupt(len(self._active))  # a damaged frame never takes a plan
        plan = self._plan(frame, defer_cycles) if self.plan_after and damaged is None else None
        if plan is not None:
            if self._held is not None and not plan.defers_writes:
                self._run_held()  # this frame's outputs would reach memory before it ran
            if self._deferred_dc:
                self._run_deferred_dc()
            return self._run_plan(plan, frame, t_ns, defer_cycles)
        if (
            self._core is not None
            and damaged is None
            and self._held is None
            and self._active
            and self.faults.drop_probability <= 0
        ):
            answered = self._registers_in_core(frame, t_ns, defer_cycles)
            if answered is not None:
                return answered
        slots = _slots(frame)
        if slots is None:
            slots = self._parse(frame)  # tagged, another EtherCAT type, or malformed
        if self._held is not None and (slots is None or _touches_process_data(slots)):
            self._run_held()  # the held cycle reads and writes what this frame touches
        if self._deferred_dc:
            self._run_deferred_dc()
        if slots is None:
            return None, 0
        if self.faults.drop():
            self._lost_on_cable()
            return None, 0
        if not self._active:
            self.stats.dropped += 1  # the link is down at the master: nothing comes back
            return None, 0
        buf = bytearray(frame)
        logical = self._run_slots(buf, slots, t_ns, damaged)
        if damaged is not None:
            self._count_damaged(damaged)
        self.tick(t_ns)
        if logical:
            self._deferred_t_ns = t_ns
            self.stats.logical_frames += 1
            if not defer_cycles:
                self.run_deferred_cycles()
        elif self._pdi and not defer_cycles:
            self._run_pdi()
        buf[6] |= SOURCE_MAC_LOCAL_BIT
        self.stats.replies += 1
        return bytes(buf), self._delay_ns(tuple(slot.length for slot in slots))

    def _registers_in_core(
        self, frame: bytes, t_ns: int, defer_cycles: bool
    ) -> tuple[bytes, int] | None:
        """The general path of a frame of single-slave register reads and writes in the C
        core (``ChainCore.register_frame``): a start-up's SM/FMMU set-up and status polls,
        KickCAT's 15-FPWR frames 5 µs a frame in process against 42 on the Python path,
        its 15-FPRD polls 6 against 21. ``None``: the frame is not one."""
        core = self._core
        assert core is not None
        if self._line_at != self._sii_version[0]:
            self._set_core_line(core)
        if self._deferred_dc:
            self._run_deferred_dc()  # as the general path does before any datagram
        got = core.register_frame(frame, t_ns)
        if got is None:
            return None
        buf, lengths = got
        self.tick(t_ns)
        if self._pdi and not defer_cycles:
            self._run_pdi()
        buf[6] |= SOURCE_MAC_LOCAL_BIT
        self.stats.replies += 1
        return bytes(buf), self._delay_ns(lengths)

    def _set_core_line(self, core: ChainCore) -> None:
        ports = self._port_offsets
        core.set_line([port.port0_ns for port in ports], [port.port1_ns for port in ports])
        self._line_at = self._sii_version[0]

    def _run_slots(
        self, buf: bytearray, slots: list[_Slot], t_ns: int, damaged: int | None
    ) -> bool:
        """Run the datagrams through the slaves (``damaged``: only that many process the
        frame); ADP and WKC fields updated in ``buf``. True when a datagram was logical.

        Datagram by datagram, each through the slaves it reaches, which is the order the
        frame passes them in for every slave (slave-major) as long as slaves meet only
        through the frame's bytes; a single-slave datagram goes straight to its slave.
        With the C core, the ESC state it holds of the slaves a datagram reaches comes
        back to their Esc objects first (one slave for APxx/FPxx, all for the rest)."""
        view = memoryview(buf)
        processing = self._active if damaged is None else self._active[:damaged]
        reached = len(processing)
        offsets = self._port_offsets
        core = self._core
        released = core.released if core is not None else None
        logical = False
        for slot in slots:
            cmd, ado = slot.cmd, slot.ado
            start = slot.header + DATAGRAM_HEADER_BYTES
            data = view[start : start + slot.length]
            added = 0
            if cmd in _AUTO_INCREMENT_SINGLE:
                position = (-slot.adp) & 0xFFFF
                if position < reached:
                    if released is not None and position not in released:
                        core.release((position,))  # type: ignore[union-attr]
                    if cmd == _APRD:
                        esc = processing[position]
                        t = t_ns + offsets[position].port0_ns
                        added = esc.read_addressed(cmd, 0, ado, data, t)
                    else:
                        added = self._one(
                            processing[position], offsets[position], cmd, 0, ado, data, t_ns
                        )
                slot.adp = (slot.adp + reached) & 0xFFFF  # every slave incremented it
            elif cmd in _CONFIGURED_SINGLE:
                position = self._station_position(slot.adp)
                if position < reached:
                    if released is not None and position not in released:
                        core.release((position,))  # type: ignore[union-attr]
                    if cmd == _FPRD:
                        esc = processing[position]
                        t = t_ns + offsets[position].port0_ns
                        added = esc.read_addressed(cmd, slot.adp, ado, data, t)
                    else:
                        added = self._one(
                            processing[position], offsets[position], cmd, slot.adp, ado, data, t_ns
                        )
            else:
                held = core is not None and broadcast_of_registers(cmd, ado, slot.length)
                if core is not None and not held:
                    core.release()  # broadcast, logical, xRMW: every slave takes part
                if (
                    cmd == _BRD
                    and (got := broadcast_read(processing, offsets, ado, data, t_ns)) is not None
                ):
                    added = got
                    slot.adp = (slot.adp + reached) & 0xFFFF
                elif (
                    cmd == _BWR
                    and (got := broadcast_write(processing, offsets, ado, data, t_ns)) is not None
                ):
                    added = got
                    slot.adp = (slot.adp + reached) & 0xFFFF
                else:
                    logical = logical or cmd in LOGICAL
                    adp = slot.adp
                    for esc, port in zip(processing, offsets, strict=False):
                        esc.frame_t_ns = t_ns
                        esc.port_offsets = port
                        adp, wkc = esc.process(cmd, adp, ado, data, t_ns + port.port0_ns)
                        added += wkc
                    slot.adp = adp
                if held:  # registers only: the core keeps the slaves, with their new time
                    core.note_times(reached)  # type: ignore[union-attr]
            data.release()
            _U16.pack_into(buf, slot.header + 2, slot.adp)
            if added:
                at = start + slot.length
                _U16.pack_into(buf, at, (_U16.unpack_from(buf, at)[0] + added) & 0xFFFF)
        view.release()
        return logical

    @staticmethod
    def _one(
        esc: Esc, port: PortTimes, cmd: int, adp: int, ado: int, data: memoryview, t_ns: int
    ) -> int:
        esc.frame_t_ns = t_ns
        esc.port_offsets = port
        if cmd == _APWR or cmd == _FPWR:  # registers stored straight, no dispatch
            return esc.write_addressed(cmd, adp, ado, data, t_ns + port.port0_ns)
        return esc.process(cmd, adp, ado, data, t_ns + port.port0_ns)[1]

    def _station_position(self, address: int) -> int:
        """The first position answering configured ``address`` (station address or
        alias); the number of active slaves when none does."""
        if self._stations_at != self._addressing[0]:
            self._stations_map = self._stations()
            self._stations_at = self._addressing[0]
        return self._stations_map.get(address, len(self._active))

    def keep_warm(self) -> None:
        """Bring what the first frame after a quiet spell reads back into the CPU's caches,
        changing nothing: the slaves' register memories (a byte a cache line) and the wire
        delays of short single-datagram frames, a start-up's first. For a quiet server
        (``keep_warm_with``, run.py): pysoem's first frame to LOLA, caches evicted, 47 ->
        18 µs in process."""
        for esc in self._slaves:
            esc.mem[0:PROCESS_RAM:64]
        for length in (1, 2):
            self._delay_ns((length,))

    def _delay_ns(self, lengths: tuple[int, ...]) -> int:
        key = (lengths, len(self._active))
        delay = self._delays.get(key)
        if delay is None:
            if len(self._delays) >= 256:
                self._delays.clear()
            delay = self._delays[key] = self.timing.round_trip_ns(list(lengths), len(self._active))
        return delay

    def _plan(self, frame: bytes, defer: bool = False) -> FramePlan | None:
        """The frame's plan for the current epoch, made when its layout comes often;
        with ``defer``, made after the answer (this frame takes the general path)."""
        last = self._last_plan
        if last is not None and last.epoch == self._epoch[0] and last.fits(frame):
            return last  # the cyclic frame again: no key to work out
        if len(frame) > 16 and frame[16] not in _PLANNABLE:
            return None  # the first datagram takes the general path: so does the frame
        key = layout_key(frame)
        if key is None or not all(key[i] in _PLANNABLE for i in range(2, len(key), 4)):
            return None  # register frames: the general path, no plan to count towards
        if self._plan_epoch != self._epoch[0]:
            self._plans.clear()
            self._seen_registers.clear()  # register layouts are counted per epoch
            self._plan_epoch = self._epoch[0]
        if key in self._plans:
            plan = self._last_plan = self._plans[key]
            return plan
        logical = any(key[i] in LOGICAL for i in range(2, len(key), 4))
        counts = self._seen if logical else self._seen_registers
        seen = counts.get(key, 0) + 1
        if len(counts) >= 1024:
            counts.clear()
        counts[key] = seen
        if seen < (self.plan_after if logical else max(self.plan_after, self.register_plan_after)):
            return None
        if defer:
            self._plan_later[key] = None  # KickCAT's LRD and LWR come back to back
            return None
        return self._make_plan(key)

    def _make_plan(self, key: Key) -> FramePlan | None:
        """The plan of ``key`` made now, whole, and kept (:meth:`_plan_pieces`)."""
        return finish(self._plan_pieces(key, asked=True))  # type: ignore[no-any-return]

    def _run_plan(
        self, plan: FramePlan, frame: bytes, t_ns: int, defer_cycles: bool
    ) -> tuple[bytes | None, int]:
        if self.faults.drop():
            self._lost_on_cable()
            return None, 0
        plan.used = True
        compiled = plan.compiled
        if compiled is NOT_COMPILED:
            compiled = self._compiled(plan)
        answer = compiled.answer(frame, t_ns, self._deferred_dc) if compiled else None
        expired = True  # the Python checks run: no compiled answer, or a watchdog expires
        if answer is None:
            if self._core is not None:
                self._core.release()
            reply = plan.run(frame, t_ns)
        else:
            reply, expired = answer
            if expired and self._core is not None:
                self._core.release()
        if expired:
            for esc in plan.watchdog_slaves:
                esc.check_watchdog(t_ns)
        if plan.logical:
            self._deferred_t_ns = t_ns
            self.stats.logical_frames += 1
            if not defer_cycles:
                self.run_deferred_cycles()
        elif not defer_cycles and self._deferred_dc:
            self._run_deferred_dc()
        self.stats.replies += 1
        self.stats.planned_frames += 1
        return reply, plan.delay_ns

    def _compiled(self, plan: FramePlan) -> Any:
        """The C core's program for ``plan`` (made on first use), or None."""
        if self._core is None:
            return None
        if plan.compiled is NOT_COMPILED:
            plan.compiled = self._core.compile(plan)
        return plan.compiled

    def _lost_on_cable(self) -> None:
        """A dropped frame: destroyed between the master and the first slave (see Faults)."""
        self.stats.dropped += 1
        if self._active:
            self._active[0].count_invalid_frame(0)
            self._active[0].count_rx_error(0)

    def _count_damaged(self, processed: int) -> None:
        """Counters of a frame damaged after ``processed`` slaves (see Faults)."""
        self.stats.corrupted += 1
        active = self._active
        if processed >= len(active):  # damaged in the last slave's loop back
            if len(active) >= 2:
                active[-2].count_invalid_frame(1)
            for esc in active[:-2]:
                esc.count_forwarded_error(1)
            return
        active[processed].count_invalid_frame(0)
        for esc in active[processed + 1 :]:
            esc.count_forwarded_error(0)
        for esc in active[:-1]:  # the marked frame passes every open port 1 on the way back
            esc.count_forwarded_error(1)

    def tick(self, t_ns: int) -> None:
        """Let time pass in every slave (process-data watchdogs) and in the line (a
        scheduled link loss)."""
        self._due_link_loss(t_ns)
        if self._deferred_dc:
            self._run_deferred_dc()
        if self._core is not None:
            self._core.check_watchdogs(len(self._active), t_ns)
            return
        for esc in self._active:
            if esc.mem[_AL_STATUS] == _OP:  # only a slave in OP has a watchdog to run out
                esc.check_watchdog(t_ns)

    def run_deferred_cycles(self, should_yield: Callable[[], bool] | None = None) -> bool:
        """Run the work left for after the answer, in order: the application cycle held
        back by :meth:`hold_deferred_cycle`, the slaves' firmware work, what the frame
        plans left (DC time control loops, writes into the slaves' memories), the cycle
        the last logical frame asked for.

        ``should_yield`` is asked between the slaves of that cycle: when it says a frame
        waits, the rest of the cycle is held as by :meth:`hold_deferred_cycle` (it goes on
        from the next slave) and the result is False; True when everything ran."""
        if self._held is not None:
            self._run_held()
        if self._pdi:
            self._run_pdi()
        if self._deferred_dc:
            self._run_deferred_dc()
        t_ns = self._deferred_t_ns
        if t_ns is not None:
            self._deferred_t_ns = None
            stopped = self._cycles(t_ns, 0, should_yield)
            if stopped is not None:
                self._held, self._held_from = t_ns, stopped
                return False
        return self._plan_work(should_yield)

    def _plan_work(self, should_yield: Callable[[], bool] | None) -> bool:
        """Make the plans :meth:`_plan` left for after the answer, in the order the
        frames asked, then those of cyclic layouts to plan again (:meth:`_replan_key`),
        a piece at a time while
        ``should_yield`` says no frame waits (at least one piece a call): LOLA's cyclic
        frame takes ~250 µs to plan, which a frame that comes meanwhile (pysoem's AL
        status poll after its first frame in OP) would otherwise wait for. The plan is
        used from the frame after the last piece on; a plan begun in an epoch that has
        ended meanwhile is dropped (the slaves it read may have changed), and a cyclic
        layout's is begun again for the new epoch. True when nothing is left to do."""
        while True:
            if self._plan_job is None:
                nxt = self._next_plan_key()
                if nxt is None:
                    return True
                key, asked = nxt
                if key in self._plans and self._plan_epoch == self._epoch[0]:
                    continue
                self._plan_job = (key, self._epoch[0], self._plan_pieces(key, asked))
            key, epoch, pieces = self._plan_job
            while epoch == self._epoch[0]:
                try:
                    next(pieces)
                except StopIteration:
                    break
                if should_yield is not None and should_yield():
                    return False
            self._plan_job = None  # made, or begun in an epoch that has ended: dropped
            if should_yield is not None and should_yield():
                return False  # the next layout's plan, if any, after that frame

    def _next_plan_key(self) -> tuple[Key, bool] | None:
        """The layout to plan next, and whether a frame asked for it: one a frame asked
        for, else a cyclic one to plan again (:meth:`_replan_key`)."""
        if self._plan_later:
            key = next(iter(self._plan_later))
            del self._plan_later[key]
            return key, True
        again = self._replan_key()
        return None if again is None else (again, False)

    def _replan_key(self) -> Key | None:
        """A cyclic layout to plan again, before its next frame, once the epoch of its
        plan has ended (each once an epoch, the most recent first): any register write
        ends one, and so does each slave's step to OP. Its frames would otherwise take
        the general path until a plan is made after one of them: LOLA's first LRW after
        pysoem asked for OP took 200-550 µs in the general path against ~15 planned, and
        KickCAT's LRD and LWR alike. A layout whose plan was made unasked and never used
        is no longer sent: it is forgotten (a frame of it asks again)."""
        if self._replanned_epoch != self._epoch[0]:
            self._replanned_epoch = self._epoch[0]
            self._replanned.clear()
            for key in [k for k, (p, asked) in self._cyclic_keys.items() if not (asked or p.used)]:
                del self._cyclic_keys[key]
        again = next(self._replan_candidates(), None)
        if again is not None:
            self._replanned.add(again)
        return again

    def _replan_due(self) -> bool:
        """Whether :meth:`_replan_key` has a layout to give (changing nothing)."""
        return next(self._replan_candidates(), None) is not None

    def _replan_candidates(self) -> Iterator[Key]:
        """The cyclic layouts to plan again in this epoch, the most recent first: not
        planned again in it yet, not to be forgotten at its start, their plan not of it."""
        epoch = self._epoch[0]
        started = self._replanned_epoch == epoch  # _replan_key has forgotten the unused
        for key in reversed(self._cyclic_keys):
            plan, asked = self._cyclic_keys[key]
            if started and key in self._replanned:
                continue
            if not started and not (asked or plan.used):
                continue  # forgotten when the epoch's first layout is asked for
            if self._plan_epoch != epoch or key not in self._plans:
                yield key

    def _plan_pieces(self, key: Key, asked: bool) -> Pieces:
        """The plan of ``key`` and its C program in pieces, then both kept; it returns the
        plan (``None``: the layout takes the general path)."""
        lengths = [key[i] & 0x7FF for i in range(5, len(key), 4)]
        delay_ns = self.timing.round_trip_ns(lengths, len(self._active))
        epoch = self._epoch[0]
        plan = yield from plan_pieces(
            key, self._active, self._port_offsets, epoch, delay_ns, self._deferred_dc
        )
        if plan is not None and self._core is not None:
            plan.compiled = yield from self._core.compile_pieces(plan)
        if self._plan_epoch != epoch:
            self._plans.clear()
            self._seen_registers.clear()  # as _plan does at an epoch's first frame
            self._plan_epoch = epoch
        if len(self._plans) >= PLAN_CACHE_SIZE:
            self._plans.clear()
        self._plans[key] = self._last_plan = plan
        cyclic = self._cyclic_keys
        if plan is not None and plan.logical and (asked or key in cyclic):
            if asked:
                cyclic.pop(key, None)  # the most recent last
            cyclic[key] = (plan, asked)  # planned again: it keeps its place
            if len(cyclic) > CYCLIC_LAYOUTS:
                del cyclic[next(iter(cyclic))]
        return plan

    def hold_deferred_cycle(self) -> None:
        """The master's next frame is already here: let it be answered before the pending
        application cycle runs. The cycle still runs before that frame's outputs reach the
        slaves' memories (a plan leaves them for after the answer; any other frame runs
        the held cycle first), so every frame's outputs reach the devices, in order; the
        answer shows the inputs as they are, as a slave whose application is late would."""
        if self._held is not None:
            self._run_held()  # one held at a time: the older one runs now
        if self._deferred_dc:
            self._run_deferred_dc()
        self._held, self._deferred_t_ns = self._deferred_t_ns, None
        self._held_from = 0

    def _run_held(self) -> None:
        t_ns, self._held = self._held, None
        start, self._held_from = self._held_from, 0
        if t_ns is not None:
            self._cycles(t_ns, start)

    def _cycles(
        self, t_ns: int, start: int = 0, should_yield: Callable[[], bool] | None = None
    ) -> int | None:
        """The application cycle of the slaves the frames reach, from position ``start``
        on, in line order; ``should_yield`` is asked between slaves (with the C core:
        between the runs of slaves it cycles in one call and the slaves Python cycles).
        The position to go on from when it said yes, else ``None``."""
        if self._core is not None:
            return self._core.cycles(len(self._active), t_ns, start, should_yield)
        active = self._active
        last = len(active) - 1
        for i in range(start, len(active)):
            active[i].cycle(t_ns)
            if should_yield is not None and i < last and should_yield():
                return i + 1
        return None

    @property
    def plans_pending(self) -> bool:
        """Whether frame plans are to be made (:meth:`make_plans`): asked for by a frame,
        begun, or of cyclic layouts whose plans' epoch has ended."""
        return self._plan_job is not None or bool(self._plan_later) or self._replan_due()

    def make_plans(self, should_yield: Callable[[], bool] | None = None) -> bool:
        """Make the pending frame plans a piece at a time, before the work
        :meth:`run_deferred_cycles` does, while ``should_yield`` says no frame waits
        (at least one piece); True when none is left. A server calls it after the
        answer when the master sends its frames too close together for the deferred
        work to come (pysoem's AL status polls after asking for OP: its next two LRW
        took the general path, 200-260 µs each for LOLA, against ~15 planned)."""
        return self._plan_work(should_yield)

    @property
    def firmware_pending(self) -> int:
        """How many pieces of firmware work (AL control requests, mailbox writes) the
        slaves have taken but not yet handled."""
        return len(self._pdi)

    def run_firmware(self, limit: int | None = None) -> None:
        """Handle up to ``limit`` (``None``: as many as are pending now) pieces of pending
        firmware work, oldest first; a piece's continuation (the rest of its work, see
        :meth:`~lolacli.emulator.esc.memory.EscMemory.continue_in_firmware`) comes next."""
        work = self._pdi
        n = len(work) if limit is None else min(limit, len(work))
        core = self._core
        for _ in range(n):
            if not work:
                return
            function, args = work.pop(0)
            if core is None:
                function(*args)
                continue
            if function == core.take_in_device:  # pieces of its own (see device_due)
                if function(*args):
                    work.insert(0, (function, args))
                continue
            core.release_owner(function)  # the firmware's slave: its ESC state back
            function(*args)
            due = core.device_due(function, len(self._active))
            if due is not None:
                work.append((core.take_in_device, (due,)))

    def _run_pdi(self) -> None:
        while self._pdi:
            self.run_firmware()

    def _run_deferred_dc(self) -> None:
        for work, args in self._deferred_dc:
            work(*args)
        self._deferred_dc.clear()

    def _stations(self) -> dict[int, int]:
        """Configured address -> first position answering it (station address or alias)."""
        out: dict[int, int] = {}
        for i, esc in enumerate(self._active):
            out.setdefault(esc.station_address, i)
            if esc.alias_enabled:
                out.setdefault(esc.station_alias, i)
        return dict(sorted(out.items(), key=lambda kv: kv[1]))

    def _parse(self, frame: bytes) -> list[_Slot] | None:
        """Datagram positions in the frame; a malformed frame counts as an RX error."""
        try:
            decoded = decode_frame(frame)
            _header, _etype, pos = decode_ethernet_header(frame)
        except WireError:
            self.stats.malformed += 1
            if self.slaves:
                self.slaves[0].count_invalid_frame(0)
            return None
        if decoded.ecat_type != ECAT_TYPE_COMMANDS:
            return []
        slots = []
        pos += ECAT_HEADER_BYTES
        for d in decoded.datagrams:
            slots.append(_Slot(pos, d.cmd, len(d.data), d.adp, d.ado))
            pos += DATAGRAM_HEADER_BYTES + len(d.data) + WKC_BYTES
        return slots
