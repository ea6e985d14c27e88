"""The ESC composed of its parts: datagram dispatch by command, physical (register and
process RAM) access, the application cycle; broadcasts worked out once for a line."""

from __future__ import annotations

import struct

from lolacli.emulator import registers as r
from lolacli.emulator.esc.counters import ErrorCounters, EscCounters
from lolacli.emulator.esc.dc import (
    DcClock,
    DistributedClock,
    PortTimes,
    system_time_loop,
    system_time_written,
)
from lolacli.emulator.esc.eeprom import SiiInterface
from lolacli.emulator.esc.fmmu import Fmmus
from lolacli.emulator.esc.memory import EscApplication, EscConfig, RegisterWrite, register_write
from lolacli.emulator.esc.watchdog import ProcessDataWatchdog
from lolacli.emulator.registers import AlState
from lolacli.emulator.sii import sii_layout
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
from lolacli.wire.registers import AlStatusCode, SiiStatus

_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_MASK64 = (1 << 64) - 1
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
_BWR = int(Command.BWR)
_SYSTEM_TIME = r.DC_SYSTEM_TIME
_SYSTEM_TIME_END = r.DC_SYSTEM_TIME + 8
_PROCESS_RAM = r.PROCESS_RAM
_SAFEOP = int(AlState.SAFEOP)
_OP = int(AlState.OP)


class Esc(ProcessDataWatchdog, Fmmus, DistributedClock, SiiInterface, ErrorCounters):
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
        self.layout = sii_layout(bytes(sii))
        self.app = app
        self.clock = clock or DcClock()
        self.mem = bytearray(r.MEMORY_BYTES)
        self.counters = EscCounters()
        self.outputs_valid = False
        self.pending_op = False
        self.refuse_op_code = None
        self._mailbox_queue = []
        self.last_port = True
        self.frame_t_ns = 0
        self.port_offsets = None
        self._cache = None
        self._pd_starts = None
        self._view = memoryview(self.mem)
        self.now_ns = 0
        self.last_outputs_ns = 0
        self._watchdog_ns = -1
        self._last_mailbox_in = None
        self.epoch = [0]
        self.addressing = [0]
        self.sii_version = [0]
        self.pdi = None
        self._mailbox_write_counter = 0
        self._mailbox_pending = False
        self.reset()

    def reset(self) -> None:
        """Power-on: registers to defaults, AL INIT, SII alias loaded."""
        cfg = self.config
        self.mem[:] = bytes(r.MEMORY_BYTES)
        m = self.mem
        m[r.TYPE], m[r.REVISION] = cfg.esc_type, cfg.revision
        _U16.pack_into(m, r.BUILD, cfg.build)
        m[r.FMMU_COUNT], m[r.SM_COUNT] = cfg.fmmus, cfg.sync_managers
        m[r.RAM_SIZE], m[r.PORT_DESCRIPTOR] = cfg.ram_kib, cfg.port_descriptor
        _U16.pack_into(m, r.ESC_FEATURES, cfg.features)
        _U16.pack_into(m, r.STATION_ALIAS, self.layout.station_alias)
        _U32.pack_into(m, r.DL_CONTROL, 0x00000001)
        # PDI control (0x0140) and ESC configuration (0x0141) come from SII word 0 at
        # power-on (ET1100 datasheet, EEPROM content); an image too short keeps the default
        sii_pdi = self.sii[0:2] if len(self.sii) >= 2 else b""
        _U16.pack_into(
            m, r.PDI_CONTROL, int.from_bytes(sii_pdi, "little") if sii_pdi else cfg.pdi_control
        )
        _U16.pack_into(m, r.WATCHDOG_DIVIDER, cfg.watchdog_divider)
        _U16.pack_into(m, r.WD_TIME_PD, cfg.watchdog_time_process_data)
        status = int(SiiStatus.READ_8_BYTES) if cfg.eeprom_8_byte_reads else 0
        _U16.pack_into(m, r.SII_CONTROL_STATUS, status)
        self._forget_mailbox()
        self._cache = None
        self.epoch[0] += 1
        self.addressing[0] += 1
        self.outputs_valid = False
        self.pending_op = False
        self._set_al(AlState.INIT, AlStatusCode.NO_ERROR, error=False)
        # the firmware starts in INIT with its mailbox sync managers deactivated on the
        # PDI side, as on entering INIT: a mailbox written before PREOP (a master whose
        # PREOP request was lost) reaches no protocol and gets no answer
        mailbox_sms = {self.layout.mailbox_out_sm, self.layout.mailbox_in_sm}
        for sm in mailbox_sms if self.layout.mailbox_out_bytes else ():
            if sm < self.config.sync_managers:
                self.mem[self._sm_address(sm) + 7] = r.SM_PDI_DEACTIVATE
        self.set_topology(last=self.last_port)

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

    def write_addressed(self, cmd: int, adp: int, ado: int, data: memoryview, t_ns: int) -> int:
        """APWR/FPWR addressed to this slave (``adp`` as it sees it): the WKC increment.
        Registers are stored straight, with what the write sets off (a start-up's SM and
        FMMU set-up is frames of them: ~0.5 µs a datagram less than :meth:`process`);
        process RAM goes through :meth:`process`."""
        end = ado + len(data)
        if end > _PROCESS_RAM:
            return self.process(cmd, adp, ado, data, t_ns)[1]
        self.counters.datagrams += 1
        self.now_ns = t_ns
        self.epoch[0] += 1
        plan = register_write(ado, end)
        payload = bytes(data)
        plan.store(self.mem, ado, payload)
        if plan.effects:
            self.register_side_effects(plan, ado, end, payload, t_ns)
        return 1

    def al_control_written(self, control: int) -> None:
        """The master wrote ``control`` into AL control: the request goes to the firmware
        as written (see ``AlStateMachine._al_control_written``)."""
        self.hand_to_firmware(self._al_control_written, control)

    def configuration_written(self) -> None:
        """The FMMU or SM registers were written: their decoded configuration and the
        process-data watchdog time that depends on it are worked out again when next used."""
        self._cache = None
        self._watchdog_ns = -1

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
        plan = register_write(address, end)
        plan.store(self.mem, address, payload)  # the writable bytes
        if plan.effects:
            self.register_side_effects(plan, address, end, payload, t_ns)
        if end > r.PROCESS_RAM:
            self._sm_written(address, end)
        return True

    def register_side_effects(
        self, plan: RegisterWrite, start: int, end: int, payload: bytes, t_ns: int
    ) -> None:
        if plan.configuration:
            self.configuration_written()
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
            self.al_control_written(self.mem[r.AL_CONTROL])

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


def broadcast_of_registers(cmd: int, ado: int, length: int) -> bool:
    """Whether :func:`broadcast_read` or :func:`broadcast_write` takes this BRD/BWR and it
    changes nothing of a slave but memory, the firmware's work and the time the frame
    reached it: a BRD of registers other than the DC system time, a BWR of registers whose
    write is :attr:`~lolacli.emulator.esc.memory.RegisterWrite.memory_only` (an AL control
    request to every slave, as a master's start and end of a session)."""
    end = ado + length
    if cmd == _BRD:
        return _registers_to_or(ado, end)
    return cmd == _BWR and end <= _PROCESS_RAM and register_write(ado, end).memory_only


def _registers_to_or(ado: int, end: int) -> bool:
    return end <= _PROCESS_RAM and not (ado < _SYSTEM_TIME_END and _SYSTEM_TIME < end)


def broadcast_read(
    escs: list[Esc], ports: list[PortTimes], ado: int, data: memoryview, t_ns: int
) -> int | None:
    """BRD of registers other than the DC system time through ``escs`` (``ports``: when
    the frame of time ``t_ns`` reaches each): each ORs its bytes into ``data``; the WKC
    increment, as :meth:`Esc.process` would give slave by slave. ``None`` for any other
    range (process RAM and the system time have side effects: :meth:`Esc.process` then)."""
    end = ado + len(data)
    if not _registers_to_or(ado, end):
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
    (:func:`register_write`), then stored and its side effects run slave by slave, as
    :meth:`Esc.process` would; the WKC increment. ``None`` for a write that reaches
    process RAM (sync manager buffers: :meth:`Esc.process` then)."""
    end = ado + len(data)
    if end > _PROCESS_RAM:
        return None
    payload = bytes(data)
    plan = register_write(ado, end)
    bits = plan.writable_bits(payload)
    effects = plan.effects
    # a write of the system time alone: one step of the time control loop for all slaves
    # after the stores, not one a slave (LOLA 70 -> 37 µs)
    loop: list[tuple[bytearray, DcClock, int, int]] | None = [] if plan.system_time_only else None
    for esc, port in zip(escs, ports, strict=False):
        t = t_ns + port.port0_ns
        esc.counters.datagrams += 1
        esc.now_ns = t
        esc.epoch[0] += 1
        plan.store_bits(esc.mem, ado, bits)
        if effects:
            esc.frame_t_ns = t_ns
            esc.port_offsets = port
            if loop is not None:
                loop.append((esc.mem, esc.clock, port.port0_ns, esc.dc_offset_minus_delay_ns()))
            else:
                esc.register_side_effects(plan, ado, end, payload, t)
    if loop:
        system_time_loop(loop, *system_time_written(ado, end, payload), t_ns)
    return len(escs)
