"""The AL state machine (ETG.1000.6 §5.3, Figure 10): AL control requests, the checks of
each transition, entering a state (SM activation towards the PDI, the application told)."""

from __future__ import annotations

import struct

from lolacli.emulator import registers as r
from lolacli.emulator.esc.mailbox import Mailbox
from lolacli.emulator.registers import AlState
from lolacli.wire.registers import AlStatusCode

_U16 = struct.Struct("<H")
_KNOWN_STATES = frozenset(int(s) for s in AlState)
# requested state -> states it may be reached from (ETG.1000.6 Figure 10)
_ALLOWED_FROM: dict[int, frozenset[int]] = {
    AlState.INIT: frozenset(_KNOWN_STATES),
    AlState.PREOP: frozenset({AlState.INIT, AlState.PREOP, AlState.SAFEOP, AlState.OP}),
    AlState.SAFEOP: frozenset({AlState.PREOP, AlState.SAFEOP, AlState.OP}),
    AlState.OP: frozenset({AlState.SAFEOP, AlState.OP}),
    AlState.BOOT: frozenset({AlState.INIT, AlState.BOOT}),
}


class AlStateMachine(Mailbox):
    """AL control (0x0120) in, AL status and status code (0x0130, 0x0134) out."""

    outputs_valid: bool
    pending_op: bool  # OP requested, entered with the first valid outputs
    refuse_op_code: int | None  # fault: stay in SAFEOP with this code
    last_outputs_ns: int  # when the outputs were last written (the watchdog's start)

    @property
    def al_state(self) -> int:
        return self.mem[r.AL_STATUS] & r.AL_STATE_MASK

    @property
    def al_error(self) -> bool:
        return bool(self.mem[r.AL_STATUS] & r.AL_ERROR_INDICATOR)

    @property
    def al_status_code(self) -> int:
        return int(_U16.unpack_from(self.mem, r.AL_STATUS_CODE)[0])

    def _set_al(self, state: int, code: int, *, error: bool) -> None:
        self.epoch[0] += 1
        self.mem[r.AL_STATUS] = (state & r.AL_STATE_MASK) | (r.AL_ERROR_INDICATOR if error else 0)
        _U16.pack_into(self.mem, r.AL_STATUS_CODE, code)

    def _refuse(self, code: int) -> None:
        self.counters.refused_transitions += 1
        self._set_al(self.al_state, code, error=True)

    def _al_control_written(self, control: int) -> None:
        """Firmware: an AL control request, ``control`` as the master wrote it. Each
        write is handled in turn, even when the master wrote the next one before the
        firmware came to this one: each real slave has its own processor, while the
        emulator's firmware work for every slave of the chain waits its turn on one core
        (SOEM's ``config_map`` asks each slave for SAFEOP and a master may ask all for OP
        right after it)."""
        requested = control & r.AL_STATE_MASK
        if self.al_error:
            if not control & r.AL_ERROR_INDICATOR:
                return  # an error must be acknowledged before any other request
            self._set_al(self.al_state, AlStatusCode.NO_ERROR, error=False)
        if requested == 0:
            return
        self.request_state(requested)

    def request_state(self, requested: int) -> None:
        """Apply an AL control request (after an acknowledged error, if any)."""
        current = self.al_state
        if requested not in _KNOWN_STATES:
            self._refuse(AlStatusCode.UNKNOWN_REQUESTED_STATE)
            return
        if current not in _ALLOWED_FROM[requested]:
            self._refuse(AlStatusCode.INVALID_REQUESTED_STATE_CHANGE)
            return
        if requested == current:
            return
        code = self._transition_check(current, requested)
        if code is not None:
            self._refuse(code)
            return
        if requested == AlState.OP and not self._outputs_ready():
            # entered with the first valid outputs; frame plans (and the chain's C core,
            # which knows no AL state machine) treat such a slave's outputs event apart
            self.pending_op = True
            self.epoch[0] += 1
            return
        # checked; the state is entered as a piece of firmware work of its own, so a frame
        # that arrives between the two is answered without waiting for both
        self.continue_in_firmware(self._enter_checked, requested, current)

    def _enter_checked(self, requested: int, checked_in: int) -> None:
        """Firmware: enter ``requested``, checked while in ``checked_in``, unless another
        request has moved the slave meanwhile (then that request decides)."""
        if self.al_state == checked_in and not self.al_error:
            self._enter(requested)

    def _transition_check(self, current: int, requested: int) -> int | None:
        if requested == AlState.BOOT:
            return self._check_bootstrap_sms()
        if current == AlState.INIT and requested == AlState.PREOP:
            return self._check_mailbox_sms()
        if current == AlState.PREOP and requested == AlState.SAFEOP:
            return self._check_process_sms()
        if requested == AlState.OP and self.refuse_op_code is not None:
            return self.refuse_op_code
        return None

    def _outputs_ready(self) -> bool:
        outputs, _ = self._process_sizes()
        return outputs == 0 or self.outputs_valid

    def _enter(self, state: int) -> None:
        if state == AlState.OP:
            self.last_outputs_ns = self.now_ns
            self.mem[r.WD_STATUS_PD] |= 0x01
        self.pending_op = False
        if state in (AlState.INIT, AlState.PREOP):
            self.outputs_valid = False
        if state == AlState.INIT:
            self._forget_mailbox()
            for sm in range(self.config.sync_managers):
                self.mem[self._sm_address(sm) + 5] &= ~r.SM_STATUS_MAILBOX_FULL
        self._set_al(state, AlStatusCode.NO_ERROR, error=False)
        self._update_pdi_activation(state)
        if self.app is not None:
            self.app.state_changed(AlState(state))

    def _update_pdi_activation(self, state: int) -> None:
        layout = self.layout
        for sm in range(self.config.sync_managers):
            mailbox = sm in (layout.mailbox_out_sm, layout.mailbox_in_sm)
            on = state != AlState.INIT if mailbox else state in (AlState.SAFEOP, AlState.OP)
            base = self._sm_address(sm)
            self.mem[base + 7] = (self.mem[base + 7] & 0x02) | (0 if on else r.SM_PDI_DEACTIVATE)
        self._cache = None
        self.epoch[0] += 1
        self.configuration()  # decoded now, in the firmware's time, not in the next frame's

    def _check_mailbox_sms(self) -> int | None:
        layout = self.layout
        if layout.mailbox_out_bytes == 0:
            return None
        ok = self._mailbox_sms_at(layout.mailbox_out_start, 0xFFFF, layout.mailbox_in_start, 0xFFFF)
        return None if ok else AlStatusCode.INVALID_MAILBOX_CONFIGURATION_PREOP

    def _check_bootstrap_sms(self) -> int | None:
        """INIT → BOOT (ETG.1000.6 Table 9): SM0/SM1 set up as the SII's bootstrap
        mailbox; a slave whose SII states none has no bootloader."""
        layout = self.layout
        if not (layout.bootstrap_out_bytes and layout.bootstrap_in_bytes):
            return AlStatusCode.BOOTSTRAP_NOT_SUPPORTED
        ok = self._mailbox_sms_at(
            layout.bootstrap_out_start,
            layout.bootstrap_out_bytes,
            layout.bootstrap_in_start,
            layout.bootstrap_in_bytes,
        )
        return None if ok else AlStatusCode.INVALID_MAILBOX_CONFIGURATION_BOOT

    def _mailbox_sms_at(self, out_start: int, out_bytes: int, in_start: int, in_bytes: int) -> bool:
        """The mailbox SMs enabled as mailboxes, master → slave at ``out_start`` and back
        at ``in_start``, neither longer than the slave's buffer (``out_bytes``,
        ``in_bytes``)."""
        layout = self.layout
        out = self.sync_manager(layout.mailbox_out_sm)
        inn = self.sync_manager(layout.mailbox_in_sm)
        return (
            out.enabled
            and inn.enabled
            and out.start == out_start
            and inn.start == in_start
            and out.mode == r.SM_MODE_MAILBOX
            and inn.mode == r.SM_MODE_MAILBOX
            and out.direction == r.SM_DIRECTION_WRITE
            and inn.direction == r.SM_DIRECTION_READ
            and 0 < out.length <= out_bytes
            and 0 < inn.length <= in_bytes
        )

    def _process_sizes(self) -> tuple[int, int]:
        if self.app is not None:
            return self.app.process_data_bytes()
        return self.layout.outputs_bytes, self.layout.inputs_bytes

    def _check_process_sms(self) -> int | None:
        outputs, inputs = self._process_sizes()
        layout = self.layout
        if outputs:
            sm = self.sync_manager(layout.outputs_sm)
            if not (sm.enabled and sm.length == outputs and sm.direction == r.SM_DIRECTION_WRITE):
                return AlStatusCode.INVALID_OUTPUT_CONFIGURATION
        if inputs:
            sm = self.sync_manager(layout.inputs_sm)
            if not (sm.enabled and sm.length == inputs and sm.direction == r.SM_DIRECTION_READ):
                return AlStatusCode.INVALID_INPUT_CONFIGURATION
        return None

    def outputs_written(self) -> None:
        self.outputs_valid = True
        self.last_outputs_ns = self.now_ns
        if self.pending_op and self.al_state == AlState.SAFEOP:
            self.hand_to_firmware(self._enter_requested_op)  # the firmware sees valid outputs

    def _enter_requested_op(self) -> None:
        """Firmware: OP, requested while the outputs were not yet valid, now that they are."""
        if self.pending_op and self.al_state == AlState.SAFEOP:
            self._enter(AlState.OP)
