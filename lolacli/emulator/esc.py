"""One EtherCAT slave controller (ESC): register and process memory, datagram processing.

Pure: datagram bytes in, datagram bytes out; time comes in as integer nanoseconds.
The model follows ETG.1000.4 (data link layer: addressing, FMMU, sync managers, DC,
SII interface, error counters) and ETG.1000.6 (AL state machine, AL status codes). The
application behind the ESC (a device with its object dictionary and mailbox server) is
an :class:`EscApplication`; the ESC calls it on mailbox requests, state changes and
process-data cycles.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, Protocol

from lolacli.emulator import registers as r
from lolacli.emulator.registers import AlState
from lolacli.emulator.sii import SiiLayout, sii_layout
from lolacli.wire.commands import (
    AUTO_INCREMENT,
    BROADCAST,
    CONFIGURED,
    LOGICAL,
    READ_MULTIPLE_WRITES,
    READ_WRITES,
    READS,
    WRITES,
    Command,
    wkc_increment,
)
from lolacli.wire.mailbox import MAILBOX_HEADER_BYTES, decode_mailbox_header
from lolacli.wire.registers import (
    SYNC_MANAGER_LAYOUT,
    AlStatusCode,
    Fmmu,
    decode_fmmu,
    decode_system_time_difference,
    fmmu_address,
)

_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_I64 = struct.Struct("<q")
_SM = SYNC_MANAGER_LAYOUT

MAX_CORRECTION_NS = 1000
_TWICE_MAX_CORRECTION_NS = 2 * MAX_CORRECTION_NS
_MASK64 = (1 << 64) - 1
_DELAY = r.DC_SYSTEM_TIME_DELAY
_OFFSET = r.DC_SYSTEM_TIME_OFFSET
_DIFFERENCE = r.DC_SYSTEM_TIME_DIFFERENCE
_unpack_u32 = _U32.unpack_from
PLAN_FREE_REGISTERS = 0x0F00  # digital outputs and user RAM: no frame plan depends on them
_unpack_i64 = _I64.unpack_from
_pack_u32 = _U32.pack_into
_LOGICAL = frozenset({Command.LRD, Command.LWR, Command.LRW})
# command -> how it addresses and what it does, as plain ints (enum lookups are slow)
_BROADCAST, _AUTO_INCREMENT, _CONFIGURED, _LOGICAL_KIND, _OTHER = range(5)
_KIND: dict[int, int] = {
    **{int(c): _BROADCAST for c in BROADCAST},
    **{int(c): _AUTO_INCREMENT for c in AUTO_INCREMENT},
    **{int(c): _CONFIGURED for c in CONFIGURED},
    **{int(c): _LOGICAL_KIND for c in LOGICAL},
}
_READ, _WRITE, _READ_WRITE, _READ_MULTIPLE_WRITE = range(4)
_ACCESS: dict[int, int] = {
    **{int(c): _READ for c in READS - LOGICAL},
    **{int(c): _WRITE for c in WRITES - LOGICAL},
    **{int(c): _READ_WRITE for c in READ_WRITES - LOGICAL},
    **{int(c): _READ_MULTIPLE_WRITE for c in READ_MULTIPLE_WRITES},
}
_ARMW, _FRMW, _BRD, _BRW = int(Command.ARMW), int(Command.FRMW), int(Command.BRD), int(Command.BRW)
_SYSTEM_TIME = r.DC_SYSTEM_TIME
_SYSTEM_TIME_END = r.DC_SYSTEM_TIME + 8
_AL_STATUS = r.AL_STATUS
_PROCESS_RAM = r.PROCESS_RAM
_KNOWN_STATES = frozenset(int(s) for s in AlState)
_SAFEOP = int(AlState.SAFEOP)
_OP = int(AlState.OP)
# requested state -> states it may be reached from (ETG.1000.6 Figure 10)
_ALLOWED_FROM: dict[int, frozenset[int]] = {
    AlState.INIT: frozenset(_KNOWN_STATES),
    AlState.PREOP: frozenset({AlState.INIT, AlState.PREOP, AlState.SAFEOP, AlState.OP}),
    AlState.SAFEOP: frozenset({AlState.PREOP, AlState.SAFEOP, AlState.OP}),
    AlState.OP: frozenset({AlState.SAFEOP, AlState.OP}),
    AlState.BOOT: frozenset({AlState.INIT, AlState.BOOT}),
}


class EscApplication(Protocol):
    """What sits behind the PDI: a device with mailbox server and process data."""

    def mailbox_request(self, request: bytes) -> list[bytes]:
        """A complete mailbox written by the master -> mailbox messages to send back."""
        ...

    def process_data_bytes(self) -> tuple[int, int]:
        """(outputs, inputs) sizes the current PDO mapping needs, in bytes."""
        ...

    def state_changed(self, state: AlState) -> None: ...

    def cycle(self, outputs: bytes, t_ns: int) -> bytes:
        """Outputs from the master -> inputs for the master (one process-data cycle)."""
        ...


@dataclass(frozen=True, slots=True)
class EscConfig:
    """Identity of the ESC silicon (registers 0x0000–0x000F)."""

    esc_type: int = 0x11  # ET1100-like
    revision: int = 0x02
    build: int = 0x0003
    fmmus: int = 8
    sync_managers: int = 8
    ram_kib: int = 8
    port_descriptor: int = 0x0F  # ports 0 and 1: MII; 2 and 3 not implemented
    features: int = int(r.EscFeature.DISTRIBUTED_CLOCKS | r.EscFeature.DC_64_BIT)
    eeprom_8_byte_reads: bool = True
    pdi_control: int = 0x0005  # SPI
    watchdog_divider: int = 0x09C2  # 100 µs at 25 MHz
    watchdog_time_process_data: int = 1000  # 100 ms


@dataclass(slots=True)
class DcClock:
    """The slave's local clock: ``local = t × (1 + drift_ppm·1e-6) + start_ns + correction``."""

    start_ns: int = 0
    drift_ppb: int = 0
    correction_ns: int = 0

    def local_ns(self, t_ns: int) -> int:
        return t_ns + (t_ns * self.drift_ppb) // 1_000_000_000 + self.start_ns + self.correction_ns


@dataclass(slots=True)
class EscCounters:
    """What happened, for status lines and tests."""

    datagrams: int = 0
    mailbox_requests: int = 0
    cycles: int = 0
    refused_transitions: int = 0


@dataclass(slots=True)
class PortTimes:
    """When the frame reached this slave: port 0 on the way out, port 1 on the way back."""

    port0_ns: int
    port1_ns: int | None


class Esc:
    """The ESC of one slave: 64 KiB of registers and process RAM plus behaviour.

    What the chain's frame plans and its C core use besides :meth:`process`: ``mem`` (the
    memory, shared in place), ``clock``, ``counters``, ``epoch``, :meth:`configuration`
    (decoded SMs and FMMUs), :meth:`logical`, :meth:`outputs_written` (an output SM buffer
    completed), ``outputs_valid``/``pending_op``, ``now_ns`` (when the datagram being
    processed reached this slave), ``last_outputs_ns`` and
    :meth:`current_watchdog_timeout_ns` (the process-data watchdog),
    :meth:`process_data_starts` and :meth:`dc_offset_minus_delay_ns`.
    """

    def __init__(
        self,
        sii: bytes,
        *,
        config: EscConfig | None = None,
        app: EscApplication | None = None,
        clock: DcClock | None = None,
    ) -> None:
        self.config = config or EscConfig()
        self.sii = bytearray(sii)
        self.layout: SiiLayout = sii_layout(bytes(sii))
        self.app = app
        self.clock = clock or DcClock()
        self.mem = bytearray(r.MEMORY_BYTES)
        self.counters = EscCounters()
        self.outputs_valid = False
        self.pending_op = False
        self.refuse_op_code: int | None = None  # fault: stay in SAFEOP with this code
        self._mailbox_queue: list[bytes] = []
        self.last_port = True
        self.frame_t_ns = 0  # when the current frame left the master
        self.port_offsets: PortTimes | None = None  # its arrival at port 0 / port 1, relative
        self._cache: Configuration | None = None
        self._pd_starts: tuple[Configuration, SiiLayout, int, int] | None = None
        self._view = memoryview(self.mem)
        self.now_ns = 0
        self.last_outputs_ns = 0
        self._watchdog_ns: int | None = -1  # -1: to be computed from the registers
        self._last_mailbox_in: bytes | None = None
        # bumped whenever addressing or mapping may have changed (register writes, AL
        # states, topology): the chain's frame plans are valid for one value. A chain
        # shares one cell between its slaves.
        self.epoch: list[int] = [0]
        # bumped when a station address, alias or alias enable may have changed: the
        # chain's map of configured addresses is valid for one value (shared like epoch)
        self.addressing: list[int] = [0]
        # The slave's firmware side (the PDI): AL control requests and mailbox writes are
        # taken by the ESC at once (the frame is answered) and handled by the firmware
        # afterwards, as on hardware. ``None``: handled at once; a list (a chain's): work
        # queued there as (function, arguments), run by the chain after the answer.
        self.pdi: list[tuple[Callable[..., None], tuple[Any, ...]]] | None = None
        self._mailbox_write_counter = 0  # counter of the last mailbox service taken
        self._mailbox_pending = False  # the write mailbox waits for the firmware
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Power-on: registers to defaults, AL INIT, SII alias loaded."""
        cfg = self.config
        self.mem[:] = bytes(r.MEMORY_BYTES)
        m = self.mem
        m[r.TYPE], m[r.REVISION] = cfg.esc_type, cfg.revision
        _U16.pack_into(m, r.BUILD, cfg.build)
        m[r.FMMUS_SUPPORTED], m[r.SYNC_MANAGERS_SUPPORTED] = cfg.fmmus, cfg.sync_managers
        m[r.RAM_SIZE_KIB], m[r.PORT_DESCRIPTOR] = cfg.ram_kib, cfg.port_descriptor
        _U16.pack_into(m, r.FEATURES, cfg.features)
        _U16.pack_into(m, r.STATION_ALIAS, self.layout.station_alias)
        _U32.pack_into(m, r.DL_CONTROL, 0x00000001)
        # PDI control (0x0140) and ESC configuration (0x0141) come from SII word 0 at
        # power-on (ET1100 datasheet, EEPROM content); an image too short keeps the default
        sii_pdi = self.sii[0:2] if len(self.sii) >= 2 else b""
        _U16.pack_into(
            m, r.PDI_CONTROL, int.from_bytes(sii_pdi, "little") if sii_pdi else cfg.pdi_control
        )
        _U16.pack_into(m, r.WATCHDOG_DIVIDER, cfg.watchdog_divider)
        _U16.pack_into(m, r.WATCHDOG_TIME_PROCESS_DATA, cfg.watchdog_time_process_data)
        status = r.EEPROM_STATUS_READ_8_BYTES if cfg.eeprom_8_byte_reads else 0
        _U16.pack_into(m, r.EEPROM_CONTROL, status)
        self._mailbox_queue.clear()
        self._mailbox_write_counter = 0
        self._mailbox_pending = False
        self._cache = None
        self.epoch[0] += 1
        self.addressing[0] += 1
        self.outputs_valid = False
        self.pending_op = False
        self._set_al(AlState.INIT, AlStatusCode.NO_ERROR, error=False)
        self.set_topology(last=self.last_port)

    def set_topology(self, *, last: bool) -> None:
        """DL status 0x0110: port 0 link+communication, port 1 too unless last in line."""
        self.last_port = last
        self.epoch[0] += 1
        status = 0x0001 | 0x0010 | 0x0200  # PDI operational, link port 0, comm port 0
        status |= 0x0400 if last else (0x0020 | 0x0800)  # port 1 closed loop, or open+comm
        status |= 0x1000 | 0x4000  # ports 2 and 3: loop closed
        _U16.pack_into(self.mem, r.DL_STATUS, status)

    @property
    def station_address(self) -> int:
        return int(_U16.unpack_from(self.mem, r.STATION_ADDRESS)[0])

    @property
    def station_alias(self) -> int:
        return int(_U16.unpack_from(self.mem, r.STATION_ALIAS)[0])

    @property
    def al_state(self) -> int:
        return self.mem[r.AL_STATUS] & r.AL_STATE_MASK

    @property
    def al_error(self) -> bool:
        return bool(self.mem[r.AL_STATUS] & r.AL_ERROR_INDICATOR)

    @property
    def al_status_code(self) -> int:
        return int(_U16.unpack_from(self.mem, r.AL_STATUS_CODE)[0])

    def u16(self, address: int) -> int:
        return int(_U16.unpack_from(self.mem, address)[0])

    def u32(self, address: int) -> int:
        return int(_U32.unpack_from(self.mem, address)[0])

    # ------------------------------------------------------------- addressing
    @property
    def alias_enabled(self) -> bool:
        return bool(self.mem[r.DL_CONTROL_ALIAS_ENABLE_BYTE] & 0x01)

    def addressed_configured(self, adp: int) -> bool:
        if adp == self.mem[r.STATION_ADDRESS] | self.mem[r.STATION_ADDRESS + 1] << 8:
            return True
        return self.alias_enabled and adp == self.station_alias

    def process(self, cmd: int, adp: int, ado: int, data: memoryview, t_ns: int) -> tuple[int, int]:
        """Process one datagram passing through: returns (new ADP field, WKC increment).

        ``data`` is the datagram's data in the frame buffer, changed in place. ``adp``/
        ``ado`` are the two halves of the address field (for logical commands the
        32-bit address is ``adp | ado << 16``).
        """
        self.counters.datagrams += 1
        self.now_ns = t_ns
        kind = _KIND.get(cmd, _OTHER)
        if kind == _BROADCAST:
            return (adp + 1) & 0xFFFF, self._physical(cmd, ado, data, t_ns, addressed=True)
        if kind == _AUTO_INCREMENT:
            hit = adp == 0
            new_adp = (adp + 1) & 0xFFFF
            if not hit and cmd != _ARMW:
                return new_adp, 0
            return new_adp, self._physical(cmd, ado, data, t_ns, addressed=hit)
        if kind == _CONFIGURED:
            hit = self.addressed_configured(adp)
            if not hit and cmd != _FRMW:
                return adp, 0
            return adp, self._physical(cmd, ado, data, t_ns, addressed=hit)
        if kind == _LOGICAL_KIND:
            return adp, self.logical(cmd, adp | (ado << 16), data, t_ns)
        return adp, 0

    def read_addressed(self, cmd: int, adp: int, ado: int, data: memoryview, t_ns: int) -> int:
        """APRD/FPRD addressed to this slave (``adp`` as it sees it): the WKC increment.
        Registers other than the DC system time are copied straight; anything else goes
        through :meth:`process`."""
        end = ado + len(data)
        if end <= _SYSTEM_TIME or (_SYSTEM_TIME_END <= ado and end <= _PROCESS_RAM):
            self.counters.datagrams += 1
            self.now_ns = t_ns
            data[:] = self.mem[ado:end]
            return 1
        return self.process(cmd, adp, ado, data, t_ns)[1]

    # --------------------------------------------------------- physical access
    def _physical(self, cmd: int, ado: int, data: memoryview, t_ns: int, *, addressed: bool) -> int:
        n = len(data)
        if ado + n > r.MEMORY_BYTES:
            return 0
        access = _ACCESS[cmd]
        if access == _READ:
            return 1 if self._read(ado, data, t_ns, merge=cmd == _BRD) else 0
        if access == _WRITE:
            return 1 if self._write(ado, bytes(data), t_ns) else 0
        if access == _READ_MULTIPLE_WRITE:
            if ado == r.DC_SYSTEM_TIME and n in (4, 8):  # the DC distribution: hot path
                if addressed:
                    data[:] = (self.system_time_ns(t_ns) & _MASK64).to_bytes(8, "little")[:n]
                else:
                    self._system_time_written(ado, ado + n, bytes(data), t_ns)
                return 1
            if addressed:
                return 1 if self._read(ado, data, t_ns, merge=False) else 0
            return 1 if self._write(ado, bytes(data), t_ns) else 0
        incoming = bytes(data)  # APRW, FPRW, BRW
        read = self._read(ado, data, t_ns, merge=cmd == _BRW)
        return wkc_increment(cmd, read=read, write=self._write(ado, incoming, t_ns))

    def _read(self, address: int, data: memoryview, t_ns: int, *, merge: bool) -> bool:
        end = address + len(data)
        mem = self.mem
        if end > r.PROCESS_RAM:
            for sm in self._mailbox_sms(address, end, write=False):
                if not self._sm_full(sm):
                    return False
        if address < _SYSTEM_TIME_END and _SYSTEM_TIME < end:
            _U64.pack_into(mem, _SYSTEM_TIME, self.system_time_ns(t_ns) & _MASK64)
        if merge:
            merged = int.from_bytes(data, "little") | int.from_bytes(mem[address:end], "little")
            data[:] = merged.to_bytes(end - address, "little")
        else:
            data[:] = mem[address:end]
        if end > r.PROCESS_RAM:
            self._after_read(address, end)
        return True

    def _write(self, address: int, payload: bytes, t_ns: int) -> bool:
        end = address + len(payload)
        if end > r.PROCESS_RAM:
            for sm in self._mailbox_sms(address, end, write=True):
                if self._sm_full(sm):
                    return False  # a full write mailbox takes nothing (ETG.1000.4 §6.7.1)
        if address >= r.PROCESS_RAM:
            self.mem[address:end] = payload
            self._sm_written(address, end)
            return True
        self.epoch[0] += 1
        plan = _register_write(address, end)
        mem = self.mem
        for lo, hi in plan.segments:  # the writable bytes
            mem[lo:hi] = payload[lo - address : hi - address]
        if plan.effects:
            self._register_side_effects(plan, address, end, payload, t_ns)
        if end > r.PROCESS_RAM:
            self._sm_written(address, end)
        return True

    def _register_side_effects(
        self, plan: _RegisterWrite, start: int, end: int, payload: bytes, t_ns: int
    ) -> None:
        if plan.configuration:
            self._cache = None
            self._watchdog_ns = -1
        if plan.watchdog:
            self._watchdog_ns = -1
        if plan.addressing:
            self.addressing[0] += 1
        for lo, hi in plan.clear_groups:  # a write into a group clears all of it
            self.mem[lo:hi] = bytes(hi - lo)
        if plan.eeprom:
            self._eeprom_command()
        if plan.latch:
            self._latch_receive_times()
        if plan.system_time:
            self._system_time_written(start, end, payload, t_ns)
        if plan.sync_managers:
            self._sm_registers_written(start, end)
        if plan.al_control:
            self.hand_to_firmware(self._al_control_written)

    def hand_to_firmware(self, work: Callable[..., None], *args: Any) -> None:
        """Hand ``work`` to the slave's firmware: at once, or queued in ``pdi``."""
        if self.pdi is None:
            work(*args)
        else:
            self.pdi.append((work, args))

    # ------------------------------------------------------------ AL states
    def _set_al(self, state: int, code: int, *, error: bool) -> None:
        self.epoch[0] += 1
        self.mem[r.AL_STATUS] = (state & r.AL_STATE_MASK) | (r.AL_ERROR_INDICATOR if error else 0)
        _U16.pack_into(self.mem, r.AL_STATUS_CODE, code)

    def _refuse(self, code: int) -> None:
        self.counters.refused_transitions += 1
        self._set_al(self.al_state, code, error=True)

    def _al_control_written(self) -> None:
        control = self.mem[r.AL_CONTROL]
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
        self._enter(requested)

    def _transition_check(self, current: int, requested: int) -> int | None:
        if requested == AlState.BOOT:
            return AlStatusCode.BOOTSTRAP_NOT_SUPPORTED
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

    # ------------------------------------------------------------ watchdog
    def watchdog_timeout_ns(self) -> int | None:
        """Process-data watchdog: (divider + 2) × 40 ns × 0x0420, when the output SM
        enables it (control bit 6) and the time is not 0 (ET1100 datasheet §2.31)."""
        time_ticks = self.u16(r.WATCHDOG_TIME_PROCESS_DATA)
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
        self.mem[r.WATCHDOG_STATUS_PROCESS_DATA] &= ~0x01
        counter = r.WATCHDOG_COUNTER_PROCESS_DATA
        self.mem[counter] = min(0xFF, self.mem[counter] + 1)
        self._enter(AlState.SAFEOP)
        self._set_al(AlState.SAFEOP, AlStatusCode.SYNC_MANAGER_WATCHDOG, error=True)

    def _enter(self, state: int) -> None:
        if state == AlState.OP:
            self.last_outputs_ns = self.now_ns
            self.mem[r.WATCHDOG_STATUS_PROCESS_DATA] |= 0x01
        self.pending_op = False
        if state in (AlState.INIT, AlState.PREOP):
            self.outputs_valid = False
        if state == AlState.INIT:
            self._mailbox_queue.clear()
            self._mailbox_write_counter = 0
            self._mailbox_pending = False
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
        out = self.sync_manager(layout.mailbox_out_sm)
        inn = self.sync_manager(layout.mailbox_in_sm)
        ok = (
            out.enabled
            and inn.enabled
            and out.start == layout.mailbox_out_start
            and inn.start == layout.mailbox_in_start
            and out.mode == r.SM_MODE_MAILBOX
            and inn.mode == r.SM_MODE_MAILBOX
            and out.direction == r.SM_DIRECTION_WRITE
            and inn.direction == r.SM_DIRECTION_READ
            and out.length > 0
            and inn.length > 0
        )
        return None if ok else AlStatusCode.INVALID_MAILBOX_CONFIGURATION_PREOP

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

    # ------------------------------------------------------- sync managers
    @staticmethod
    def _sm_address(index: int) -> int:
        return r.SYNC_MANAGER_BASE + r.SYNC_MANAGER_BYTES * index

    def sync_manager(self, index: int) -> SmView:
        start, length, control, status, activate, pdi = _SM.unpack_from(
            self.mem, self._sm_address(index)
        )
        return SmView(index, start, length, control, status, activate, pdi)

    def configuration(self) -> Configuration:
        """SM and FMMU configuration, decoded once per register change."""
        if self._cache is None:
            sms = [self.sync_manager(i) for i in range(self.config.sync_managers)]
            fmmus = [self.fmmu(i) for i in range(self.config.fmmus)]
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
            and _overlaps(start, end, sm.start, sm.start + sm.length)
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
        first = max(0, (start - r.SYNC_MANAGER_BASE) // r.SYNC_MANAGER_BYTES)
        last = min(
            self.config.sync_managers, (end - 1 - r.SYNC_MANAGER_BASE) // r.SYNC_MANAGER_BYTES + 1
        )
        mem = self.mem
        for i in range(first, last):
            base = r.SYNC_MANAGER_BASE + r.SYNC_MANAGER_BYTES * i
            if not mem[base + 6] & 1:
                mem[base + 5] &= ~r.SM_STATUS_MAILBOX_FULL  # a disabled SM forgets its buffer
                if i == self.layout.mailbox_out_sm:
                    self._mailbox_pending = False
            elif i == self.layout.mailbox_in_sm:
                self._repeat_request(base)

    def _repeat_request(self, base: int) -> None:
        """Mailbox repeat (ETG.1000.4 §6.7.2): the master toggled activate bit 1 after a
        lost mailbox read; post the last message again and acknowledge in PDI bit 1."""
        requested = self.mem[base + 6] & 0x02
        if requested == self.mem[base + 7] & 0x02:
            return
        if self._last_mailbox_in is not None:
            index = self.layout.mailbox_in_sm
            if self._sm_full(index):  # a newer message is waiting: it goes back in line
                sm = self.sync_manager(index)
                self._mailbox_queue.insert(0, bytes(self.mem[sm.start : sm.start + sm.length]))
                self._set_sm_full(index, False)
            self._mailbox_queue.insert(0, self._last_mailbox_in)
            self._post_next_mailbox()
        self.mem[base + 7] = (self.mem[base + 7] & ~0x02) | requested

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
                    self._post_next_mailbox()
                    if self._mailbox_pending:
                        self.hand_to_firmware(self._take_mailbox)

    def outputs_written(self) -> None:
        self.outputs_valid = True
        self.last_outputs_ns = self.now_ns
        if self.pending_op and self.al_state == AlState.SAFEOP:
            self.hand_to_firmware(self._enter_requested_op)  # the firmware sees valid outputs

    def _enter_requested_op(self) -> None:
        """Firmware: OP, requested while the outputs were not yet valid, now that they are."""
        if self.pending_op and self.al_state == AlState.SAFEOP:
            self._enter(AlState.OP)

    # ------------------------------------------------------------- mailbox
    def _mailbox_written(self, sm: SmView) -> None:
        """The master wrote the last byte of the write mailbox: it is full until the
        firmware reads it (a second write meanwhile gets WKC 0 and is lost)."""
        self._set_sm_full(sm.index, True)
        self._mailbox_pending = True
        self.hand_to_firmware(self._take_mailbox)

    def _take_mailbox(self) -> None:
        """Firmware: read the write mailbox and serve it, once the read mailbox has room
        for the answer (the slave stack reads it only then). A write with the counter of
        the service taken last is the master's repeat of a write whose answer it lost:
        dropped, so the service runs once (counter 0: a master without counters)."""
        if not self._mailbox_pending:
            return
        if self._mailbox_queue or self._sm_full(self.layout.mailbox_in_sm):
            return  # again when the master has read the read mailbox
        index = self.layout.mailbox_out_sm
        sm = self.sync_manager(index)
        request = bytes(self.mem[sm.start : sm.start + sm.length])
        self._mailbox_pending = False
        self._set_sm_full(index, False)  # the PDI has read it
        counter = 0
        if len(request) >= MAILBOX_HEADER_BYTES:
            counter = decode_mailbox_header(request).counter
        if counter and counter == self._mailbox_write_counter:
            return
        self._mailbox_write_counter = counter
        self.counters.mailbox_requests += 1
        if self.app is not None:
            self._mailbox_queue.extend(self.app.mailbox_request(request))
        self._post_next_mailbox()

    def _post_next_mailbox(self) -> None:
        index = self.layout.mailbox_in_sm
        sm = self.sync_manager(index)
        if not self._mailbox_queue or self._sm_full(index) or not sm.enabled:
            return
        message = self._mailbox_queue.pop(0)[: sm.length]
        self._store(sm.start, message + bytes(sm.length - len(message)))
        self._last_mailbox_in = message
        self._set_sm_full(index, True)

    def post_mailbox(self, message: bytes) -> None:
        """Queue an unsolicited mailbox message (e.g. an emergency) for the master."""
        self._mailbox_queue.append(message)
        self._post_next_mailbox()

    # -------------------------------------------------------------- logical
    def fmmu(self, index: int) -> Fmmu:
        return decode_fmmu(self._view, fmmu_address(index))

    def logical(self, cmd: int, address: int, data: memoryview, t_ns: int) -> int:
        """LRD/LWR/LRW through the FMMUs (ETG.1000.4 §6.5): this slave's write FMMUs
        take from the datagram first, then its read FMMUs put into it; the WKC as
        :func:`~lolacli.wire.commands.wkc_increment` counts what it did."""
        end = address + len(data)
        config = self.configuration()
        wrote = read = False
        if cmd != Command.LRD:
            for f in config.write_fmmus:
                if f.logical_start < end and address < f.logical_start + f.length_bytes:
                    self._fmmu_write(f, address, data)
                    wrote = True
        if cmd != Command.LWR:
            for f in config.read_fmmus:
                if f.logical_start < end and address < f.logical_start + f.length_bytes:
                    self._fmmu_read(f, address, data)
                    read = True
        return wkc_increment(cmd, read=read, write=wrote)

    def _fmmu_write(self, f: Fmmu, address: int, incoming: memoryview) -> None:
        if f.physical_start < PLAN_FREE_REGISTERS:
            self.epoch[0] += 1  # a write into registers, bypassing their side effects
            self.addressing[0] += 1
        if byte_aligned(f):
            lo = max(address, f.logical_start)
            hi = min(address + len(incoming), f.logical_start + f.length_bytes)
            p = f.physical_start + (lo - f.logical_start)
            self.mem[p : p + hi - lo] = incoming[lo - address : hi - address]
            self._sm_written(p, p + hi - lo)
            return
        for lbit, pbit in _bit_pairs(f, address, len(incoming)):
            value = (incoming[lbit >> 3] >> (lbit & 7)) & 1
            byte = pbit >> 3
            self.mem[byte] = (self.mem[byte] & ~(1 << (pbit & 7))) | (value << (pbit & 7))
        self._sm_written(f.physical_start, f.physical_start + f.length_bytes)

    def _fmmu_read(self, f: Fmmu, address: int, data: memoryview) -> None:
        if byte_aligned(f):
            lo = max(address, f.logical_start)
            hi = min(address + len(data), f.logical_start + f.length_bytes)
            p = f.physical_start + (lo - f.logical_start)
            data[lo - address : hi - address] = self.mem[p : p + hi - lo]
            self._after_read(p, p + hi - lo)
            return
        for lbit, pbit in _bit_pairs(f, address, len(data)):
            value = (self.mem[pbit >> 3] >> (pbit & 7)) & 1
            i = lbit >> 3
            data[i] = (data[i] & ~(1 << (lbit & 7))) | (value << (lbit & 7))

    # ----------------------------------------------------- process data
    def cycle(self, t_ns: int) -> None:
        """One application cycle: outputs from the output SM to the device, inputs back."""
        app = self.app
        state = self.mem[r.AL_STATUS] & r.AL_STATE_MASK
        if app is None or (state != _SAFEOP and state != _OP):
            return
        self.counters.cycles += 1
        outputs_bytes, inputs_bytes = app.process_data_bytes()
        outputs_start, inputs_start = self.process_data_starts()
        outputs = b""
        if outputs_bytes and state == _OP:
            outputs = bytes(self._view[outputs_start : outputs_start + outputs_bytes])
        inputs = app.cycle(outputs, t_ns)
        if inputs_bytes:
            self._store(inputs_start, inputs)

    def _store(self, start: int, data: bytes) -> None:
        """``data`` into memory from ``start``, as far as the memory goes (a master may
        place an SM buffer across its end; the memory never grows)."""
        end = min(start + len(data), r.MEMORY_BYTES)
        if start < end:
            self.mem[start:end] = data[: end - start]

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

    # --------------------------------------------------------------- SII
    def _eeprom_command(self) -> None:
        control = self.u16(r.EEPROM_CONTROL)
        command = control & r.EEPROM_COMMAND_MASK
        word = self.u32(r.EEPROM_ADDRESS)
        status = control & ~(r.EEPROM_COMMAND_MASK | r.EEPROM_STATUS_BUSY | r.EEPROM_ERROR_COMMAND)
        if self.config.eeprom_8_byte_reads:
            status |= r.EEPROM_STATUS_READ_8_BYTES
        if command == r.EEPROM_COMMAND_READ:
            chunk = 8 if self.config.eeprom_8_byte_reads else 4
            raw = bytes(self.sii[2 * word : 2 * word + chunk])
            self.mem[r.EEPROM_DATA : r.EEPROM_DATA + 8] = (raw + b"\xff" * 8)[:8]
        elif command == r.EEPROM_COMMAND_WRITE:
            if 2 * word + 2 <= len(self.sii):
                self.sii[2 * word : 2 * word + 2] = self.mem[r.EEPROM_DATA : r.EEPROM_DATA + 2]
            else:
                status |= r.EEPROM_ERROR_COMMAND
        elif command == r.EEPROM_COMMAND_RELOAD:
            self.layout = sii_layout(bytes(self.sii))
            _U16.pack_into(self.mem, r.STATION_ALIAS, self.layout.station_alias)
        elif command:
            status |= r.EEPROM_ERROR_COMMAND
        _U16.pack_into(self.mem, r.EEPROM_CONTROL, status & 0xFFFF)

    # ---------------------------------------------------------------- DC
    def system_time_ns(self, t_ns: int) -> int:
        offset = int(_I64.unpack_from(self.mem, r.DC_SYSTEM_TIME_OFFSET)[0])
        return self.clock.local_ns(t_ns) + offset

    def _latch_receive_times(self) -> None:
        offsets = self.port_offsets
        if offsets is None:
            return
        local0 = self.clock.local_ns(self.frame_t_ns + offsets.port0_ns)
        _U32.pack_into(self.mem, r.DC_RECEIVE_TIME_PORT0, local0 & 0xFFFFFFFF)
        if offsets.port1_ns is not None:
            local1 = self.clock.local_ns(self.frame_t_ns + offsets.port1_ns)
            _U32.pack_into(self.mem, r.DC_RECEIVE_TIME_PORT0 + 4, local1 & 0xFFFFFFFF)
        _U64.pack_into(self.mem, r.DC_RECEIVE_TIME_PROCESSING_UNIT, local0 & (2**64 - 1))

    def _system_time_written(self, start: int, end: int, payload: bytes, t_ns: int) -> None:
        """A write to 0x0910 feeds the time control loop (ETG.1000.4 §6.8, ET1100 §9.2)."""
        lo = max(start, r.DC_SYSTEM_TIME)
        hi = min(end, r.DC_SYSTEM_TIME + 8)
        raw = bytearray(8)
        raw[lo - r.DC_SYSTEM_TIME : hi - r.DC_SYSTEM_TIME] = payload[lo - start : hi - start]
        self.system_time_received(int.from_bytes(raw, "little"), 8 * (hi - r.DC_SYSTEM_TIME), t_ns)

    def system_time_received(self, value: int, width_bits: int, t_ns: int) -> None:
        """The time control loop's step for a received system time of ``width_bits``."""
        system_time_loop(
            [(self.mem, self.clock, 0, self.dc_offset_minus_delay_ns())], value, width_bits, t_ns
        )

    def dc_offset_minus_delay_ns(self) -> int:
        """System time offset (0x0920) minus system time delay (0x0928): what the time
        control loop adds to the local time before comparing with a received time."""
        return int(_unpack_i64(self.mem, _OFFSET)[0]) - int(_unpack_u32(self.mem, _DELAY)[0])

    @property
    def system_time_difference_ns(self) -> int:
        return decode_system_time_difference(memoryview(self.mem), r.DC_SYSTEM_TIME_DIFFERENCE)

    # ------------------------------------------------------- error counters
    def count_invalid_frame(self, port: int = 0) -> None:
        address = r.RX_ERROR_COUNTER + 2 * port
        self.mem[address] = min(0xFF, self.mem[address] + 1)

    def count_rx_error(self, port: int = 0) -> None:
        """0x0301 + 2·port: physical layer (symbol) errors inside a frame on ``port``."""
        address = r.RX_ERROR_COUNTER + 2 * port + 1
        self.mem[address] = min(0xFF, self.mem[address] + 1)

    def count_forwarded_error(self, port: int = 0) -> None:
        """0x0308 + port: a frame arrived on ``port`` marked bad by an earlier ESC."""
        address = r.FORWARDED_RX_ERROR + port
        self.mem[address] = min(0xFF, self.mem[address] + 1)

    def count_lost_link(self, port: int) -> None:
        """0x0310 + port: the link of ``port`` went down."""
        address = r.LOST_LINK_COUNTER + port
        self.mem[address] = min(0xFF, self.mem[address] + 1)


# Error counters cleared together by a write to any of them (ESC datasheet section II,
# 0x0300-0x0313): RX and forwarded RX errors, processing unit, PDI, lost links.
_COUNTER_CLEAR_GROUPS = (
    (r.RX_ERROR_COUNTER, r.PROCESSING_UNIT_ERROR),
    (r.PROCESSING_UNIT_ERROR, r.PDI_ERROR),
    (r.PDI_ERROR, r.PDI_ERROR + 1),
    (r.LOST_LINK_COUNTER, r.ERROR_COUNTERS_END),
)


def system_time_loop(
    slaves: list[tuple[bytearray, DcClock, int, int]], value: int, width_bits: int, t_ns: int
) -> None:
    """One step of the time control loop (ETG.1000.4 §6.8, ET1100 §9.2) in every slave
    ``(memory, clock, time offset, offset minus delay registers)`` that receives the
    system time ``value`` at ``t_ns + time offset``: the difference of its own system time
    to the received one plus the delay goes to 0x092C, and the clock runs a little faster
    or slower. One loop for a whole line: the DC time distribution runs it for every
    slave in every cycle."""
    half = 1 << (width_bits - 1)
    mask = (1 << width_bits) - 1
    base = t_ns - value + half
    for mem, clock, offset_ns, registers_ns in slaves:
        # own system time - delay - received, as in Esc.system_time_ns, inlined
        x = base + offset_ns + clock.start_ns + clock.correction_ns + registers_ns
        if clock.drift_ppb:
            x += ((t_ns + offset_ns) * clock.drift_ppb) // 1_000_000_000
        diff = (x & mask) - half
        # 0x092C in sign and magnitude; the clock never jumps: half the error per write,
        # at most MAX_CORRECTION_NS (offsets are the master's job)
        if diff < 0:
            _pack_u32(mem, _DIFFERENCE, (-diff if diff > -0x7FFFFFFF else 0x7FFFFFFF) | 0x80000000)
            clock.correction_ns -= (
                diff >> 1 if diff > -_TWICE_MAX_CORRECTION_NS else -MAX_CORRECTION_NS
            )
        else:
            _pack_u32(mem, _DIFFERENCE, diff if diff < 0x7FFFFFFF else 0x7FFFFFFF)
            clock.correction_ns -= (
                diff >> 1 if diff < _TWICE_MAX_CORRECTION_NS else MAX_CORRECTION_NS
            )


def broadcast_read(
    escs: list[Esc], ports: list[PortTimes], ado: int, data: memoryview, t_ns: int
) -> int | None:
    """BRD of registers other than the DC system time through ``escs`` (``ports``: when
    the frame of time ``t_ns`` reaches each): each ORs its bytes into ``data``; the WKC
    increment, as :meth:`Esc.process` would give slave by slave. ``None`` for any other
    range (process RAM and the system time have side effects: :meth:`Esc.process` then)."""
    end = ado + len(data)
    if end > _PROCESS_RAM or (ado < _SYSTEM_TIME_END and _SYSTEM_TIME < end):
        return None
    merged = int.from_bytes(data, "little")
    for esc, port in zip(escs, ports, strict=False):
        esc.counters.datagrams += 1
        esc.now_ns = t_ns + port.port0_ns
        merged |= int.from_bytes(esc.mem[ado:end], "little")
    data[:] = merged.to_bytes(end - ado, "little")
    return len(escs)


def broadcast_write(
    escs: list[Esc], ports: list[PortTimes], ado: int, data: memoryview, t_ns: int
) -> int | None:
    """BWR of registers through ``escs``: the write worked out once for all
    (:func:`_register_write`), then stored and its side effects run slave by slave, as
    :meth:`Esc.process` would; the WKC increment. ``None`` for a write that reaches
    process RAM (sync manager buffers: :meth:`Esc.process` then)."""
    end = ado + len(data)
    if end > _PROCESS_RAM:
        return None
    payload = bytes(data)
    plan = _register_write(ado, end)
    segments = [(lo, hi, payload[lo - ado : hi - ado]) for lo, hi in plan.segments]
    effects = plan.effects
    for esc, port in zip(escs, ports, strict=False):
        t = t_ns + port.port0_ns
        esc.counters.datagrams += 1
        esc.now_ns = t
        esc.epoch[0] += 1
        mem = esc.mem
        for lo, hi, part in segments:
            mem[lo:hi] = part
        if effects:
            esc.frame_t_ns = t_ns
            esc.port_offsets = port
            esc._register_side_effects(plan, ado, end, payload, t)
    return len(escs)


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
        write = [f for f in usable if f.type & r.FMMU_TYPE_WRITE]
        read = [f for f in usable if f.type & r.FMMU_TYPE_READ]
        return Configuration(sms, active, write, read)


def _sm_open(f: Fmmu, sms: list[SmView]) -> bool:
    """FMMU access to a sync manager's buffer needs that SM enabled and PDI-active."""
    end = f.physical_start + f.length_bytes
    for sm in sms:
        if sm.length and _overlaps(f.physical_start, end, sm.start, sm.start + sm.length):
            return sm.enabled and not sm.pdi_deactivated
    return True


def _overlaps(a0: int, a1: int, b0: int, b1: int) -> bool:
    return a0 < b1 and b0 < a1


def byte_aligned(f: Fmmu) -> bool:
    return f.logical_start_bit == 0 and f.logical_stop_bit == 7 and f.physical_start_bit == 0


def _bit_pairs(f: Fmmu, address: int, n: int) -> list[tuple[int, int]]:
    """(datagram bit, memory bit) for every bit the FMMU maps inside the datagram."""
    first = f.logical_start * 8 + f.logical_start_bit
    last = (f.logical_start + f.length_bytes - 1) * 8 + f.logical_stop_bit
    lo = max(first, address * 8)
    hi = min(last, (address + n) * 8 - 1)
    base = f.physical_start * 8 + f.physical_start_bit - first
    return [(b - address * 8, b + base) for b in range(lo, hi + 1)]


def _readonly_mask() -> bytearray:
    """1 where the master cannot write a register byte (ETG.1000.4 register tables)."""
    mask = bytearray(r.PROCESS_RAM)
    ranges = [
        (0x0000, 0x0010),
        (r.STATION_ALIAS, r.STATION_ALIAS + 2),
        (r.DL_STATUS, r.DL_STATUS + 2),
        (r.AL_STATUS, r.AL_STATUS + 6),
        (r.PDI_CONTROL, r.PDI_CONTROL + 2),
        (r.EEPROM_PDI_ACCESS, r.EEPROM_PDI_ACCESS + 1),
        (r.WATCHDOG_STATUS_PROCESS_DATA, r.WATCHDOG_STATUS_PROCESS_DATA + 2),
        (r.DC_RECEIVE_TIME_PORT0, r.DC_SYSTEM_TIME),
        (r.DC_SYSTEM_TIME, r.DC_SYSTEM_TIME + 8),
        (r.DC_RECEIVE_TIME_PROCESSING_UNIT, r.DC_SYSTEM_TIME_OFFSET),
        (r.DC_SYSTEM_TIME_DIFFERENCE, r.DC_SYSTEM_TIME_DIFFERENCE + 4),
    ]
    for lo, hi in ranges:
        mask[lo:hi] = b"\x01" * (hi - lo)
    for sm in range(16):
        base = r.SYNC_MANAGER_BASE + r.SYNC_MANAGER_BYTES * sm
        mask[base + 5] = 1  # status
        mask[base + 7] = 1  # PDI control
    return mask


_READONLY = _readonly_mask()
_SM_REGISTERS_END = r.SYNC_MANAGER_BASE + 16 * r.SYNC_MANAGER_BYTES


@dataclass(frozen=True, slots=True)
class _RegisterWrite:
    """What a master's write to ``[start, end)`` does beyond storing bytes: worked out once
    per address range (:func:`_register_write`), the same for every ESC."""

    segments: tuple[tuple[int, int], ...]  # writable runs (read-only bytes keep their value)
    clear_groups: tuple[tuple[int, int], ...]
    configuration: bool  # FMMU or SM registers: decoded configuration stale
    watchdog: bool
    addressing: bool  # station address or alias enable
    eeprom: bool
    latch: bool
    system_time: bool
    sync_managers: bool
    al_control: bool

    effects: bool  # any of the above


@lru_cache(maxsize=4096)
def _register_write(start: int, end: int) -> _RegisterWrite:
    segments: list[tuple[int, int]] = []
    run: int | None = None
    for a in range(start, min(end, r.PROCESS_RAM)):
        if _READONLY[a]:
            if run is not None:
                segments.append((run, a))
                run = None
        elif run is None:
            run = a
    if run is not None:
        segments.append((run, min(end, r.PROCESS_RAM)))
    if end > r.PROCESS_RAM:
        if segments and segments[-1][1] == r.PROCESS_RAM:
            segments[-1] = (segments[-1][0], end)
        else:
            segments.append((r.PROCESS_RAM, end))

    def hit(lo: int, hi: int) -> bool:
        return _overlaps(start, end, lo, hi)

    clear_groups = tuple(g for g in _COUNTER_CLEAR_GROUPS if hit(*g))
    flags = (
        hit(r.FMMU_BASE, _SM_REGISTERS_END),
        hit(r.WATCHDOG_DIVIDER, r.WATCHDOG_TIME_PROCESS_DATA + 2),
        hit(r.STATION_ADDRESS, r.STATION_ADDRESS + 2)
        or hit(r.DL_CONTROL_ALIAS_ENABLE_BYTE, r.DL_CONTROL_ALIAS_ENABLE_BYTE + 1),
        hit(r.EEPROM_CONTROL, r.EEPROM_CONTROL + 2),
        hit(r.DC_RECEIVE_TIME_PORT0, r.DC_RECEIVE_TIME_PORT0 + 4),
        hit(r.DC_SYSTEM_TIME, r.DC_SYSTEM_TIME + 8),
        hit(r.SYNC_MANAGER_BASE, r.SYNC_MANAGER_BASE + 16 * 8),
        hit(r.AL_CONTROL, r.AL_CONTROL + 1),
    )
    return _RegisterWrite(tuple(segments), clear_groups, *flags, bool(clear_groups) or any(flags))


__all__ = ["DcClock", "Esc", "EscApplication", "EscConfig", "SmView", "field"]
