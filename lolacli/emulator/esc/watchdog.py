"""The process-data watchdog (ET1100 datasheet §2.31): OP without new outputs for its time
falls back to SAFEOP with AL status code 0x001B."""

from __future__ import annotations

from lolacli.emulator import registers as r
from lolacli.emulator.esc.al import AlStateMachine
from lolacli.emulator.registers import AlState
from lolacli.wire.registers import AlStatusCode

_OP = int(AlState.OP)
_AL_STATUS = r.AL_STATUS


class ProcessDataWatchdog(AlStateMachine):
    _watchdog_ns: int | None  # -1: to be computed from the registers

    def watchdog_timeout_ns(self) -> int | None:
        """Process-data watchdog: (divider + 2) × 40 ns × 0x0420, when the output SM
        enables it (control bit 6) and the time is not 0 (ET1100 datasheet §2.31)."""
        time_ticks = self.u16(r.WD_TIME_PD)
        index = self.layout.outputs_sm
        if self._cache is None and index < self.config.sync_managers:
            sm = self.sync_manager(index)  # that one SM, not the whole configuration
        else:
            sm = self.configuration().sms[index]
        if not time_ticks or not sm.length or not sm.control & r.SM_CONTROL_WATCHDOG:
            return None
        return (self.u16(r.WATCHDOG_DIVIDER) + 2) * 40 * time_ticks

    def current_watchdog_timeout_ns(self) -> int | None:
        """:meth:`watchdog_timeout_ns` as :meth:`check_watchdog` uses it: worked out again
        only after a write to the registers it depends on."""
        timeout = self._watchdog_ns
        return self.watchdog_timeout_ns() if timeout == -1 else timeout

    def check_watchdog(self, t_ns: int) -> None:
        """In OP without new outputs for the watchdog time: back to SAFEOP, error 0x001B."""
        if self.mem[_AL_STATUS] != _OP:
            return
        if self._watchdog_ns == -1:
            self._watchdog_ns = self.watchdog_timeout_ns()
        timeout = self._watchdog_ns
        if timeout is None or t_ns - self.last_outputs_ns <= timeout:
            return
        self.mem[r.WD_STATUS_PD] &= ~0x01
        counter = r.WD_COUNTER_PD
        self.mem[counter] = min(0xFF, self.mem[counter] + 1)
        self._enter(AlState.SAFEOP)
        self._set_al(AlState.SAFEOP, AlStatusCode.SYNC_MANAGER_WATCHDOG, error=True)
