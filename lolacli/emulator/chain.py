"""A line of emulated slaves: a frame passes every ESC on the way out and comes back.

``Chain.process(frame_bytes, t_ns) -> (reply_bytes | None, delay_ns)`` is the in-process
transport: the master's frame in, the frame as it returns to the master out, with the
time it spent on the wire and in the slaves. Each ESC processes every datagram of the
frame in the order the frame reaches it (slave-major, as on the wire), and the first ESC
sets the locally administered bit of the source MAC (DESIGN.md "Direction").

A frame layout that repeats (the cyclic frame) is answered through a frame plan
(:mod:`lolacli.emulator.plan`, made and kept by the chain's
:class:`~lolacli.emulator.planner.Planner`): the same bytes, a fraction of the work. With
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

from collections.abc import Callable
from typing import Any

from lolacli.emulator.core import ENGINE_VARIABLE, ENGINES, ChainCore, chain_engine
from lolacli.emulator.datagrams import Slot, parse, run_slots, slots, touches_process_data
from lolacli.emulator.esc import Esc
from lolacli.emulator.line import ChainStats, ChainTiming, Faults
from lolacli.emulator.plan import NOT_COMPILED, Deferred, FramePlan
from lolacli.emulator.planner import Planner
from lolacli.emulator.registers import AL_STATUS, PROCESS_RAM, AlState
from lolacli.emulator.sii import sii_layout
from lolacli.errors import UsageError
from lolacli.wire.registers import AlStatusCode

SOURCE_MAC_LOCAL_BIT = 0x02
_OP = int(AlState.OP)


class Chain:
    """Slaves in line order; ``process`` runs a frame through all of them.

    Its :attr:`planner` gives a frame layout that repeats a
    :class:`~lolacli.emulator.plan.FramePlan`, the fast path for cyclic frames; it gives
    the same bytes as the general path.

    ``engine`` (see :func:`chain_engine`): with ``c`` the planned frames, their deferred
    work, the watchdogs and the device cycles run in the C core (:mod:`.core`), which holds
    the slaves' cyclic state between frames and gives it back before Python code touches
    it; ``python`` runs the reference code only."""

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
        self._deferred_dc: Deferred = []  # what a plan left for after the answer
        self._held: int | None = None  # a late application cycle's time
        self._held_from = 0  # ... and the position it goes on from
        self.planner = Planner(
            self._epoch, self._deferred_dc, self.timing.round_trip_ns, self._core
        )
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
        self.planner.set_line(self._active, self._port_offsets)
        if self._core is not None:  # the C core's line now, not in a frame's answer
            self._set_core_line(self._core)
        for i, esc in enumerate(self.slaves):
            esc.set_topology(last=i >= self.reachable - 1)

    def break_link(self, after: int) -> None:
        """Fault: the cable after 1-based position ``after`` is cut; the slave there closes
        its port 1 and returns the frames, the slaves behind it see nothing (0: no slave)."""
        self._check_link(after)
        self.reachable = after
        self._line_changed()

    def schedule_link_loss(self, after: int, at_ns: int) -> None:
        """Fault: the cable after 1-based position ``after`` is cut at ``at_ns`` (the time
        base of :meth:`process` and :meth:`tick`). From then on, the slave
        there shows port 1 closed without link in DL status 0x0110 and its lost link
        counter 0x0311 (port 1) has counted one; the slave behind it (out of reach)
        counts one on port 0 (0x0310)."""
        self._check_link(after)
        self._link_loss = (after, at_ns)

    def _check_link(self, after: int) -> None:
        if not 0 <= after <= len(self._slaves):
            raise UsageError(
                f"link after slave {after}: the chain has slaves 1..{len(self._slaves)}"
            )

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
        if self._link_loss is not None:
            self._due_link_loss(t_ns)
        if self._pdi and not defer_cycles:
            self._run_pdi()  # in-process: the firmware has kept up
        faults = self.faults
        # a damaged frame never takes a plan
        damaged = faults.corrupt(len(self._active)) if faults.corrupt_probability > 0 else None
        discarded = False  # a bad link's frame: the master's NIC drops its bad FCS
        if damaged is None and faults.bad_link is not None:
            damaged = faults.bad_link_hit(len(self._active))
            discarded = damaged is not None
        plan = self.planner.lookup(frame, defer_cycles) if damaged is None else None
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
        found = slots(frame)
        if found is None:
            found = self._parse(frame)  # tagged, another EtherCAT type, or malformed
        if self._held is not None and (found is None or touches_process_data(found)):
            self._run_held()  # the held cycle reads and writes what this frame touches
        if self._deferred_dc:
            self._run_deferred_dc()
        if found is None:
            return None, 0
        if self.faults.drop():
            self._lost_on_cable()
            return None, 0
        if not self._active:
            self.stats.dropped += 1  # the link is down at the master: nothing comes back
            return None, 0
        buf = bytearray(frame)
        logical = self._run_slots(buf, found, t_ns, damaged)
        if damaged is not None:
            self.stats.corrupted += 1
            self.faults.count_damaged(self._active, damaged)
        self.tick(t_ns)
        if logical:
            self._deferred_t_ns = t_ns
            self.stats.logical_frames += 1
            if not defer_cycles:
                self.run_deferred_cycles()
        elif self._pdi and not defer_cycles:
            self._run_pdi()
        if discarded:
            self.stats.dropped += 1
            return None, 0
        buf[6] |= SOURCE_MAC_LOCAL_BIT
        self.stats.replies += 1
        return bytes(buf), self._delay_ns(tuple(slot.length for slot in found))

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

    def _run_slots(self, buf: bytearray, found: list[Slot], t_ns: int, damaged: int | None) -> bool:
        """The general path through the slaves the frame reaches (``damaged``: only that
        many process it): :func:`~lolacli.emulator.datagrams.run_slots`."""
        processing = self._active if damaged is None else self._active[:damaged]
        return run_slots(
            buf, found, processing, self._port_offsets, self._core, self._station_position, t_ns
        )

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
        return self.timing.delay_ns(lengths, len(self._active))

    def _run_plan(
        self, plan: FramePlan, frame: bytes, t_ns: int, defer_cycles: bool
    ) -> tuple[bytes | None, int]:
        if self.faults.drop_probability > 0 and self.faults.drop():
            self._lost_on_cable()
            return None, 0
        plan.used = True
        compiled = plan.compiled
        if compiled is NOT_COMPILED:
            compiled = self.planner.compiled(plan)
        answer = None
        if not compiled:
            pass
        elif (
            plan.logical
            and not defer_cycles
            and self._held is None
            and not self._pdi
            and not self._deferred_dc
        ):
            # what run_deferred_cycles would do next (the plan's deferred work, the
            # slaves' cycle) in the answer's kernel call when that is all it would do
            answer, cycled = compiled.answer_cycles(
                frame, t_ns, self._deferred_dc, len(self._active)
            )
            if cycled:
                assert answer is not None
                self._deferred_t_ns = None
                self.stats.logical_frames += 1
                self.planner.work()
                self.stats.replies += 1
                self.stats.planned_frames += 1
                return answer[0], plan.delay_ns
        else:
            answer = compiled.answer(frame, t_ns, self._deferred_dc)
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

    def _lost_on_cable(self) -> None:
        """A dropped frame: destroyed between the master and the first slave (see Faults)."""
        self.stats.dropped += 1
        self.faults.count_lost(self._active)

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
            if esc.mem[AL_STATUS] == _OP:  # only a slave in OP has a watchdog to run out
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
        return self.planner.work(should_yield)

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

    def _parse(self, frame: bytes) -> list[Slot] | None:
        """Datagram positions in the frame; a malformed frame counts as an RX error."""
        found = parse(frame)
        if found is None:
            self.stats.malformed += 1
            if self.slaves:
                self.slaves[0].count_invalid_frame(0)
        return found


__all__ = [
    "ENGINES",
    "ENGINE_VARIABLE",
    "SOURCE_MAC_LOCAL_BIT",
    "Chain",
    "ChainStats",
    "ChainTiming",
    "Faults",
    "chain_engine",
]
