"""Sync managers (ETG.1000.4 §6.7): their registers, the buffer events a master's reads and
writes set off, and the SM/FMMU configuration decoded once per register change."""

from __future__ import annotations

from dataclasses import dataclass

from lolacli.emulator import registers as r
from lolacli.emulator.esc.memory import EscMemory, overlaps
from lolacli.emulator.sii import SiiLayout
from lolacli.wire.registers import (
    SYNC_MANAGER_LAYOUT,
    Fmmu,
    FmmuType,
    decode_fmmu,
    fmmu_address,
)

_SM = SYNC_MANAGER_LAYOUT


_SM_BASE, _SM_BYTES = r.SM, r.SYNC_MANAGER_BYTES
_NOT_FULL = ~r.SM_STATUS_MAILBOX_FULL & 0xFF


@dataclass(frozen=True, slots=True)
class SmView:
    """A sync manager's registers (ETG.1000.4 Table 58)."""

    index: int
    start: int
    length: int
    control: int
    status: int
    activate: int
    pdi_control: int

    @property
    def enabled(self) -> bool:
        return bool(self.activate & r.SM_ACTIVATE_ENABLE)

    @property
    def pdi_deactivated(self) -> bool:
        return bool(self.pdi_control & r.SM_PDI_DEACTIVATE)

    @property
    def mode(self) -> int:
        return self.control & r.SM_CONTROL_MODE_MASK

    @property
    def direction(self) -> int:
        return self.control & r.SM_CONTROL_DIRECTION_MASK


@dataclass(frozen=True, slots=True)
class Configuration:
    """Decoded SM/FMMU registers: active SMs and the FMMUs whose buffers are open."""

    sms: list[SmView]
    active: list[SmView]
    write_fmmus: list[Fmmu]
    read_fmmus: list[Fmmu]

    @staticmethod
    def build(sms: list[SmView], fmmus: list[Fmmu]) -> Configuration:
        active = [sm for sm in sms if sm.enabled and sm.length and not sm.pdi_deactivated]
        usable = [f for f in fmmus if f.enabled and f.length_bytes and _sm_open(f, sms)]
        write = [f for f in usable if f.type & FmmuType.WRITE]
        read = [f for f in usable if f.type & FmmuType.READ]
        return Configuration(sms, active, write, read)


def _sm_open(f: Fmmu, sms: list[SmView]) -> bool:
    """FMMU access to a sync manager's buffer needs that SM enabled and PDI-active."""
    end = f.physical_start + f.length_bytes
    for sm in sms:
        if sm.length and overlaps(f.physical_start, end, sm.start, sm.start + sm.length):
            return sm.enabled and not sm.pdi_deactivated
    return True


class SyncManagers(EscMemory):
    """The SM registers and buffer events; what the events do is the mailbox's and the AL
    state machine's (the hooks at the end, implemented there)."""

    _cache: Configuration | None
    _pd_starts: tuple[Configuration, SiiLayout, int, int] | None

    @staticmethod
    def _sm_address(index: int) -> int:
        return r.SM + r.SYNC_MANAGER_BYTES * index

    def sync_manager(self, index: int) -> SmView:
        start, length, control, status, activate, pdi = _SM.unpack_from(
            self.mem, self._sm_address(index)
        )
        return SmView(index, start, length, control, status, activate, pdi)

    def configuration(self) -> Configuration:
        """SM and FMMU configuration, decoded once per register change."""
        if self._cache is None:
            sms = [self.sync_manager(i) for i in range(self.config.sync_managers)]
            fmmus = [decode_fmmu(self._view, fmmu_address(i)) for i in range(self.config.fmmus)]
            self._cache = Configuration.build(sms, fmmus)
        return self._cache

    def _active_sms(self) -> list[SmView]:
        return self.configuration().active

    def _mailbox_sms(self, start: int, end: int, *, write: bool) -> list[int]:
        if end <= r.PROCESS_RAM:
            return []
        want = r.SM_DIRECTION_WRITE if write else r.SM_DIRECTION_READ
        return [
            sm.index
            for sm in self._active_sms()
            if sm.mode == r.SM_MODE_MAILBOX
            and sm.direction == want
            and overlaps(start, end, sm.start, sm.start + sm.length)
        ]

    def _sm_full(self, index: int) -> bool:
        return bool(self.mem[self._sm_address(index) + 5] & r.SM_STATUS_MAILBOX_FULL)

    def _set_sm_full(self, index: int, full: bool) -> None:
        addr = self._sm_address(index) + 5
        if full:
            self.mem[addr] |= r.SM_STATUS_MAILBOX_FULL
        else:
            self.mem[addr] &= ~r.SM_STATUS_MAILBOX_FULL

    def _sm_registers_written(self, start: int, end: int) -> None:
        """The master wrote the SM registers in ``[start, end)``: a disabled SM forgets its
        buffer, the mailbox's SMs do their work (:meth:`mailbox_sm_written`)."""
        first = max(0, (start - r.SM) // r.SYNC_MANAGER_BYTES)
        last = min(
            self.config.sync_managers, (end - 1 - r.SM) // r.SYNC_MANAGER_BYTES + 1
        )
        mem = self.mem
        layout = self.layout
        mailbox_out, mailbox_in = layout.mailbox_out_sm, layout.mailbox_in_sm
        for i in range(first, last):
            base = _SM_BASE + _SM_BYTES * i
            if not mem[base + 6] & 1:
                mem[base + 5] &= _NOT_FULL  # a disabled SM forgets its buffer
            if i == mailbox_out or i == mailbox_in:
                self.mailbox_sm_written(i)

    def mailbox_sm_written(self, index: int) -> None:
        """The master wrote the registers of mailbox SM ``index``: disabled, the write
        mailbox drops its pending message; enabled, the read mailbox answers a repeat
        request. The C core's register path, which stores the bytes and clears the full
        flags itself, has this run after the frame (no later datagram of the frame
        reaches the slave's SM registers)."""
        base = _SM_BASE + _SM_BYTES * index
        if not self.mem[base + 6] & 1:
            if index == self.layout.mailbox_out_sm:
                self._write_mailbox_disabled()
        elif index == self.layout.mailbox_in_sm:
            self._repeat_request(base)

    def _sm_written(self, start: int, end: int) -> None:
        for sm in self._active_sms():
            last = sm.start + sm.length - 1
            if not start <= last < end or sm.direction != r.SM_DIRECTION_WRITE:
                continue
            if sm.mode == r.SM_MODE_MAILBOX:
                self._mailbox_written(sm)
            else:
                self.outputs_written()

    def _after_read(self, start: int, end: int) -> None:
        if end <= r.PROCESS_RAM:
            return
        for sm in self._active_sms():
            last = sm.start + sm.length - 1
            if sm.mode == r.SM_MODE_MAILBOX and sm.direction == r.SM_DIRECTION_READ:
                if start <= last < end:
                    self._set_sm_full(sm.index, False)
                    self._mailbox_read()

    def process_data_starts(self) -> tuple[int, int]:
        """Where the output and input SM buffers start (cached with the SM configuration)."""
        config = self._cache or self.configuration()
        cached = self._pd_starts
        if cached is not None and cached[0] is config and cached[1] is self.layout:
            return cached[2], cached[3]
        layout = self.layout
        starts = (config.sms[layout.outputs_sm].start, config.sms[layout.inputs_sm].start)
        self._pd_starts = (config, layout, *starts)
        return starts

    # hooks: the buffer events' consequences
    def outputs_written(self) -> None:
        """An output SM buffer was completed by the master."""
        raise NotImplementedError

    def _mailbox_written(self, sm: SmView) -> None:
        raise NotImplementedError

    def _mailbox_read(self) -> None:
        """The master read the read mailbox (it is empty now)."""
        raise NotImplementedError

    def _write_mailbox_disabled(self) -> None:
        raise NotImplementedError

    def _repeat_request(self, base: int) -> None:
        raise NotImplementedError
