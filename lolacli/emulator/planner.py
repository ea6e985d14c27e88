"""The planning of cyclic frames: which layouts get a :class:`~lolacli.emulator.plan.FramePlan`,
when it is made, and the cache that keeps them for the chain's epoch.

The chain (:mod:`lolacli.emulator.chain`) asks :meth:`Planner.lookup` for a frame's plan
and runs it (in Python, :meth:`FramePlan.run`, or in the C core, :meth:`Planner.compiled`).
A plan holds while the chain's epoch (one cell every ESC bumps on a change a plan depends
on) keeps its value; a new epoch empties the cache.

When plans are made. A layout with logical datagrams is planned after :attr:`plan_after`
frames, one without (a start-up's register polls) only after :attr:`register_plan_after`
repeats in one epoch. In process the plan is made for the frame that asks; a real-time
server (``lookup(..., defer=True)``) answers first and makes it afterwards, in pieces
(:meth:`work`), so that a frame arriving meanwhile waits for one piece, not the plan. The
cyclic layouts of the last epoch are planned again unasked when an epoch ends
(:meth:`pending` says so), before their next frame comes.

Public interface: :meth:`Planner.set_line`, :meth:`lookup`, :meth:`compiled`,
:attr:`pending`, :meth:`work`, and for tests and reports :attr:`making`, :attr:`plans`,
:attr:`epoch`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from types import MappingProxyType
from typing import TYPE_CHECKING

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
from lolacli.wire.commands import LOGICAL

if TYPE_CHECKING:
    from lolacli.emulator.core import ChainCore, CompiledPlan
    from lolacli.emulator.esc import Esc, PortTimes

PLAN_CACHE_SIZE = 32
CYCLIC_LAYOUTS = 4  # logical layouts planned again unasked when an epoch ends
_PLANNABLE = frozenset(int(c) for c in PLANNABLE)
_LOGICAL = frozenset(int(c) for c in LOGICAL)


class Planner:
    """Frame plans of one chain (see the module docstring).

    ``epoch``: the chain's epoch cell; ``deferred``: the list the chain runs after the
    answer (a plan's deferred work goes there); ``round_trip_ns(lengths, slaves)``: the
    delay model; ``core``: the chain's C core (plans are compiled for it), or ``None``."""

    #: a logical layout is planned after its first frame (a server makes the plan after
    #: the answer; in process, without deferred cycles, it is made for the frame itself),
    #: so the cyclic frame's second comes planned: pysoem sends one LRW in SAFEOP before
    #: it asks for OP, which ends that plan's epoch (see _replan_key); 0: never plan
    plan_after = 1
    #: a layout without logical datagrams (a start-up's register polls) is planned only
    #: after this many repeats in one epoch: making a plan takes 40-170 µs after the answer
    #: (LOLA), which the master's next frame may wait for, and any register write starts
    #: a new epoch; such frames take 10-20 µs on the general path
    register_plan_after = 64

    def __init__(
        self,
        epoch: list[int],
        deferred: Deferred,
        round_trip_ns: Callable[[list[int], int], int],
        core: ChainCore | None = None,
    ) -> None:
        self._epoch = epoch
        self._deferred = deferred
        self._round_trip_ns = round_trip_ns
        self._core = core
        self._slaves: list[Esc] = []
        self._offsets: list[PortTimes] = []
        self._plans: dict[Key, FramePlan | None] = {}
        self._last: FramePlan | None = None  # the plan the last planned lookup found
        self._plans_epoch = -1
        self._seen: dict[Key, int] = {}  # layouts with logical datagrams: times seen
        self._seen_registers: dict[Key, int] = {}  # the others, in the current epoch
        self._later: dict[Key, None] = {}  # plans to make after the answer, in order
        # ... being made in pieces between frames: its layout, the epoch it is for, the work
        self._job: tuple[Key, int, Pieces] | None = None
        # the layouts of the last logical plans frames asked for, oldest first, planned
        # again unasked in a new epoch: each with its latest plan and whether a frame
        # asked for that one (a plan made unasked and never used ends it there)
        self._cyclic: dict[Key, tuple[FramePlan, bool]] = {}
        self._replanned: set[Key] = set()  # ... those of them planned again in the epoch
        self._replanned_epoch = -1  # ... it is
        # the epoch in which work found nothing to do, until a plan or a request comes
        # (the cyclic frame's every answer asks: this spares it the search)
        self._idle_epoch = -1

    # ------------------------------------------------------------------ the line
    def set_line(self, slaves: list[Esc], offsets: list[PortTimes]) -> None:
        """The slaves the frames reach and when the frame reaches each (relative to its
        start). The chain bumps the epoch with it, which retires the plans."""
        self._slaves = slaves
        self._offsets = offsets

    @property
    def epoch(self) -> int:
        return self._epoch[0]

    @property
    def making(self) -> int | None:
        """The epoch of the plan being made in pieces, ``None`` when none is."""
        return None if self._job is None else self._job[1]

    @property
    def plans(self) -> Mapping[Key, FramePlan | None]:
        """The plans of the current cache by layout (``None``: the general path)."""
        return MappingProxyType(self._plans)

    # ------------------------------------------------------------------ lookup
    def lookup(self, frame: bytes, defer: bool = False) -> FramePlan | None:
        """The frame's plan for the current epoch, made when its layout comes often;
        with ``defer``, made after the answer (this frame takes the general path)."""
        if not self.plan_after:
            return None
        last = self._last
        if last is not None and last.epoch == self._epoch[0] and last.fits(frame):
            return last  # the cyclic frame again: no key to work out
        if len(frame) > 16 and frame[16] not in _PLANNABLE:
            return None  # the first datagram takes the general path: so does the frame
        key = layout_key(frame)
        if key is None or not all(key[i] in _PLANNABLE for i in range(2, len(key), 4)):
            return None  # register frames: the general path, no plan to count towards
        if self._plans_epoch != self._epoch[0]:
            self._new_epoch()
        if key in self._plans:
            plan = self._last = self._plans[key]
            return plan
        logical = any(key[i] in _LOGICAL for i in range(2, len(key), 4))
        counts = self._seen if logical else self._seen_registers
        seen = counts.get(key, 0) + 1
        if len(counts) >= 1024:
            counts.clear()
        counts[key] = seen
        if seen < (self.plan_after if logical else max(self.plan_after, self.register_plan_after)):
            return None
        if defer:
            self._later[key] = None  # KickCAT's LRD and LWR come back to back
            self._idle_epoch = -1
            return None
        return finish(self._pieces(key, asked=True))  # type: ignore[no-any-return]

    def _new_epoch(self) -> None:
        self._plans.clear()
        self._seen_registers.clear()  # register layouts are counted per epoch
        self._plans_epoch = self._epoch[0]

    def compiled(self, plan: FramePlan) -> CompiledPlan | None:
        """The C core's program for ``plan`` (made on first use), or ``None``: the plan
        runs in Python (:meth:`FramePlan.run`)."""
        if plan.compiled is NOT_COMPILED:
            plan.compiled = None if self._core is None else self._core.compile(plan)
        return plan.compiled  # type: ignore[no-any-return]

    # ------------------------------------------------------------------ making plans
    @property
    def pending(self) -> bool:
        """Whether plans are to be made (:meth:`work`): asked for by a frame, begun, or
        of cyclic layouts whose plans' epoch has ended."""
        if self._idle_epoch == self._epoch[0]:
            return False
        return self._job is not None or bool(self._later) or self._replan_due()

    def work(self, should_yield: Callable[[], bool] | None = None) -> bool:
        """Make the plans :meth:`lookup` left for after the answer, in the order the
        frames asked, then those of cyclic layouts to plan again (:meth:`_replan_key`),
        a piece at a time while ``should_yield`` says no frame waits (at least one piece
        a call): LOLA's cyclic frame takes ~250 µs to plan, which a frame that comes
        meanwhile (pysoem's AL status poll after its first frame in OP) would otherwise
        wait for. The plan is used from the frame after the last piece on; a plan begun in
        an epoch that has ended meanwhile is dropped (the slaves it read may have
        changed), and a cyclic layout's is begun again for the new epoch. True when
        nothing is left to do."""
        if self._idle_epoch == self._epoch[0]:
            return True
        while True:
            if self._job is None:
                nxt = self._next_key()
                if nxt is None:
                    self._idle_epoch = self._epoch[0]
                    return True
                key, asked = nxt
                if key in self._plans and self._plans_epoch == self._epoch[0]:
                    continue
                self._job = (key, self._epoch[0], self._pieces(key, asked))
            key, epoch, pieces = self._job
            while epoch == self._epoch[0]:
                try:
                    next(pieces)
                except StopIteration:
                    break
                if should_yield is not None and should_yield():
                    return False
            self._job = None  # made, or begun in an epoch that has ended: dropped
            if should_yield is not None and should_yield():
                return False  # the next layout's plan, if any, after that frame

    def _next_key(self) -> tuple[Key, bool] | None:
        """The layout to plan next, and whether a frame asked for it: one a frame asked
        for, else a cyclic one to plan again (:meth:`_replan_key`)."""
        if self._later:
            key = next(iter(self._later))
            del self._later[key]
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
            for key in [k for k, (p, asked) in self._cyclic.items() if not (asked or p.used)]:
                del self._cyclic[key]
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
        for key in reversed(self._cyclic):
            plan, asked = self._cyclic[key]
            if started and key in self._replanned:
                continue
            if not started and not (asked or plan.used):
                continue  # forgotten when the epoch's first layout is asked for
            if self._plans_epoch != epoch or key not in self._plans:
                yield key

    def _pieces(self, key: Key, asked: bool) -> Pieces:
        """The plan of ``key`` and its C program in pieces, then both kept; it returns the
        plan (``None``: the layout takes the general path)."""
        lengths = [key[i] & 0x7FF for i in range(5, len(key), 4)]
        delay_ns = self._round_trip_ns(lengths, len(self._slaves))
        epoch = self._epoch[0]
        plan = yield from plan_pieces(
            key, self._slaves, self._offsets, epoch, delay_ns, self._deferred
        )
        if plan is not None and self._core is not None:
            plan.compiled = yield from self._core.compile_pieces(plan)
        if self._plans_epoch != epoch:
            self._new_epoch()  # as lookup does at an epoch's first frame
        if len(self._plans) >= PLAN_CACHE_SIZE:
            self._plans.clear()
        self._plans[key] = self._last = plan
        self._idle_epoch = -1
        cyclic = self._cyclic
        if plan is not None and plan.logical and (asked or key in cyclic):
            if asked:
                cyclic.pop(key, None)  # the most recent last
            cyclic[key] = (plan, asked)  # planned again: it keeps its place
            if len(cyclic) > CYCLIC_LAYOUTS:
                del cyclic[next(iter(cyclic))]
        return plan


__all__ = ["CYCLIC_LAYOUTS", "PLAN_CACHE_SIZE", "Planner"]
