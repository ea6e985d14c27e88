"""The ENI-driven EtherCAT master: state transitions by InitCmds, cyclic frames, WKC.

:class:`Master` talks to a bus only through a :class:`~lolacli.master.transport.Transport`.
It walks INIT → PREOP → SAFEOP → OP by running, for each transition, the master's and
then each slave's ``<InitCmd>`` of that transition (ETG.2100): every command is sent in
a frame of its own (so ``<Requires>`` cycle/frame hold), repeated up to ``<Retries>``
times while its working counter differs from ``<Cnt>``, and — with ``<Validate>`` —
until the answer masked by ``<Mask>`` equals ``<Data>`` or ``<Timeout>`` runs out. A
slave's CoE InitCmds of a transition run just before the InitCmd that requests the
transition's target state in AL control (0x0120), when the mailbox is up. A check of AL
status (0x0130) that comes back with the error indicator set is a refused transition: the
master reads AL status code 0x0134 and reports it with its text
(:func:`lolacli.wire.registers.al_status_text`).

After INIT → PREOP it starts the distributed clocks (:meth:`Master.start_dc`); from SAFEOP
on it runs the ENI's cyclic frames every cycle time (:meth:`Master.cycle`), also while
later InitCmds wait, and checks every working counter against ``<Cnt>``.

The cycle follows the seed's Tables I/II (one thread here): RX (the frames of the last
cycle) → copy inputs to the Bus Variables → device abstractions (procData) → control
hooks (updateDes) → copy outputs → send → admin (acyclic frames, DC diagnosis).
"""

from __future__ import annotations

import struct
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

from lolacli.eni.model import Eni, InitCmd, Slave
from lolacli.errors import SdoAbortError, TransitionRefusedError, TransportError, WireError
from lolacli.master import dc
from lolacli.master.cyclic import FramePlan, image_sizes, plan_frame
from lolacli.master.mailbox import MailboxClient, MailboxLayout, SdoClient
from lolacli.master.transport import Received, Transport
from lolacli.master.variables import ProcessImage
from lolacli.wire.commands import AUTO_INCREMENT, Command
from lolacli.wire.frame import (
    DATAGRAM_HEADER_BYTES,
    ECAT_HEADER_BYTES,
    ECAT_TYPE_COMMANDS,
    ETH_HEADER_BYTES,
    ETHERTYPE_ECAT,
    FCS_BYTES,
    MAX_DATAGRAM_DATA,
    MIN_FRAME_BYTES,
    WKC_BYTES,
    Datagram,
    EthernetHeader,
    Frame,
    decode_ecat_payload,
    decode_frame,
    encode_frame,
    make_frame,
)
from lolacli.wire.registers import (
    AL_ERROR_INDICATOR,
    AlState,
    Register,
    al_state_name,
    al_status_text,
    decode_system_time_difference,
)

if TYPE_CHECKING:
    from lolacli.master.slaves import BusSlave

DEFAULT_SOURCE_MAC = b"\x01\x01\x01\x01\x01\x01"
#: datagram bytes one acyclic frame carries at most (1500-byte payload less the header)
MAX_FRAME_DATAGRAM_BYTES = 1400
#: ENI transition names -> the state they lead to
TRANSITION_TARGET: dict[str, AlState] = {
    "IP": AlState.PREOP,
    "PS": AlState.SAFEOP,
    "SO": AlState.OP,
    "OS": AlState.SAFEOP,
    "SP": AlState.PREOP,
    "OP": AlState.PREOP,
    "PI": AlState.INIT,
    "SI": AlState.INIT,
    "OI": AlState.INIT,
    "IB": AlState.BOOT,
    "BI": AlState.INIT,
}
UP = ("IP", "PS", "SO")
#: the seed's per-cycle sections (Tables I/II, Fig. 7), in cycle order, with their thread
SECTIONS: tuple[tuple[str, str], ...] = (
    ("rx", "bus"),
    ("copy_rx", "bus"),
    ("proc_data", "main"),
    ("control", "main"),
    ("copy_tx", "bus"),
    ("send", "bus"),
    ("admin", "bus"),
)
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_INDEX_AT = ETH_HEADER_BYTES + ECAT_HEADER_BYTES + 1
_DATAGRAM_HEAD = struct.Struct("<BBIHH")  # command, index, address, length word, IRQ
_ETHERTYPE_ECAT = ETHERTYPE_ECAT.to_bytes(2, "big")


@dataclass(slots=True)
class MasterOptions:
    """How the master behaves where the ENI says nothing."""

    cycle_time_ns: int | None = None  # default: the ENI's, else 1 ms
    frame_timeout_ns: int = 2_000_000  # an acyclic frame not back by then is lost
    frame_retries: int = 3  # lost acyclic frames are sent again this often
    poll_ns: int = 100_000  # between validation / mailbox polls
    validate_timeout_ms: int = 5000  # a <Validate> without <Timeout>
    dc_drift_frames: int = 1000  # static drift compensation: ARMW/FRMW frames
    dc_check_cycles: int = 200  # read every DC slave's 0x092C this often (0: never)
    sync_start_delay_ns: int = 100_000_000  # SYNC0 start: this far after "now"
    time_sections: bool = False  # time the cycle's sections (seed Fig. 7)
    # real time: a cyclic frame must be back when the next cycle is due (else its inputs
    # are late for it), and DC diagnosis answers are taken when they are there (no wait
    # inside a cycle). In both times a cycle that starts a whole cycle time late or more
    # drops the slots it missed instead of running them back to back (skipped_cycles), as
    # a master's cycle timer does when the bus cannot keep its rate
    realtime: bool = False
    source_mac: bytes | None = None  # default: the ENI's, if usable


@dataclass(slots=True)
class MasterStats:
    frames_sent: int = 0
    frames_lost: int = 0
    acyclic_frames: int = 0
    cycles: int = 0
    cyclic_frames: int = 0
    cyclic_lost: int = 0
    wkc_checked: int = 0
    wkc_mismatches: int = 0  # cyclic datagrams whose WKC differed from <Cnt>
    cycles_with_mismatch: int = 0
    round_trip_ns: list[int] = field(default_factory=list)  # of every cyclic frame
    dc_errors_ns: list[tuple[int, int]] = field(default_factory=list)  # (t, max |0x092C|)
    slaves_found: int | None = None
    skipped_cycles: int = 0  # slots dropped because the cycle before ran past them
    late_frames: int = 0  # cyclic frames that came back after the master stopped waiting
    late_acyclic: int = 0  # DC diagnosis frames likewise
    # the first few cycles where each went wrong (for findings)
    lost_at: list[int] = field(default_factory=list)
    late_at: list[int] = field(default_factory=list)
    mismatch_at: list[int] = field(default_factory=list)
    skipped_at: list[int] = field(default_factory=list)


#: cycle numbers kept per kind of trouble (MasterStats.*_at)
KEEP_CYCLES = 5


def _note(at: list[int], cycle: int) -> None:
    if len(at) < KEEP_CYCLES:
        at.append(cycle)


@dataclass(frozen=True, slots=True)
class Refusal:
    """A transition a slave did not make, and why."""

    position: int
    slave: str
    transition: str
    al_status_code: int | None
    text: str
    detail: str = ""

    def to_dict(self) -> dict[str, Any]:
        code = self.al_status_code
        return {
            "position": self.position,
            "slave": self.slave,
            "transition": self.transition,
            "al_status_code": None if code is None else f"0x{code:04X}",
            "text": self.text,
            "detail": self.detail,
        }


class Master:
    """An EtherCAT master for one ENI over one transport (see the module docstring)."""

    def __init__(
        self, eni: Eni, transport: Transport, *, options: MasterOptions | None = None
    ) -> None:
        self.eni = eni
        self.transport = transport
        self.options = options or MasterOptions()
        self.stats = MasterStats()
        self.state = AlState.INIT
        self.refusals: list[Refusal] = []
        self.cycle_time_ns = self.options.cycle_time_ns or eni.cycle_time_ns or 1_000_000
        inputs_bytes, outputs_bytes = image_sizes(
            eni.cyclic_frames, eni.process_image.inputs_bytes, eni.process_image.outputs_bytes
        )
        self.image = ProcessImage(eni.process_image, inputs_bytes, outputs_bytes, eni.slaves)
        self.devices: list[BusSlave] = []
        self.control: list[Callable[[Master], None]] = []
        self.admin: list[Callable[[Master], None]] = []
        self.sections_ns: dict[str, list[int]] = {name: [] for name, _ in SECTIONS}
        self.bus_emulation_ns: list[int] = []  # per timed cycle: time inside an in-process bus
        self._section_appends: tuple[Any, ...] | None = None  # see _bind_section_appends
        self.source_mac = self._source_mac()
        self._index = 0
        self.last_sent_ns = 0
        self._stray: dict[int, Received] = {}
        # frames of the cycle (its cyclic frames, DC diagnosis) not back when the master
        # stopped waiting: index -> (sent, cycle, cyclic); one that comes back later is
        # late, not lost
        self._overdue: dict[int, tuple[int, int, bool]] = {}
        self._plans: dict[AlState, list[FramePlan]] = {}
        self._pending: list[tuple[FramePlan, int, int]] = []  # (plan, index, sent ns)
        self._pending_dc: list[tuple[int, int]] = []  # DC diagnosis frames: (index, sent)
        self._cyclic = False
        self._in_cycle = False
        self._next_cycle_ns = 0
        self._failed: set[int] = set()  # positions that refused a transition
        self._mailboxes: dict[int, MailboxClient] = {}
        self.dc_slaves: list[Slave] = []
        self.dc_reference: Slave | None = None
        self._dc_frame: _DcCheckFrame | None = None  # the DC diagnosis frame, made once
        self._request_head: bytes | None = None  # an exchange's frame up to its EtherCAT header

    # --------------------------------------------------------------- frames
    def _source_mac(self) -> bytes:
        mac = self.options.source_mac or self.eni.master.source_mac
        if len(mac) != 6 or mac == bytes(6) or mac[0] & 0x02:
            return DEFAULT_SOURCE_MAC  # the chain's direction bit must be clear on the way out
        return mac

    def now_ns(self) -> int:
        return self.transport.now_ns()

    def new_index(self) -> int:
        self._index = index = (self._index + 1) & 0xFF
        if self._overdue:
            # a frame still not back when its index is used again stays lost: an answer
            # with this index from now on is the new frame's
            overdue = self._overdue.pop(index, None)
            if overdue is not None and overdue[2]:
                _note(self.stats.lost_at, overdue[1])
        return index

    def lost_cycles(self) -> list[int]:
        """The first cycles whose cyclic frames never came back (as far as known now)."""
        overdue = (c for _s, c, cyclic in self._overdue.values() if cyclic)
        return sorted({*self.stats.lost_at, *overdue})[:KEEP_CYCLES]

    def exchange(
        self, datagrams: Sequence[Datagram], *, retries: int | None = None
    ) -> tuple[Datagram, ...]:
        """Send ``datagrams`` in one frame and return them as they came back; a lost frame
        is sent again up to ``retries`` times (default :attr:`MasterOptions.frame_retries`),
        then TransportError."""
        self.run_due_cycles()
        tries = self.options.frame_retries if retries is None else retries
        last = len(datagrams) - 1
        for _ in range(tries + 1):
            index = self.new_index()
            frame = self._request(datagrams, index)
            if frame is None:
                # make_frame's Frame, without its copies of each datagram
                numbered = tuple(
                    Datagram(d.cmd, index, d.address, d.data, d.wkc, d.irq, d.circulating,
                             i < last, d.reserved)
                    for i, d in enumerate(datagrams)
                )  # fmt: skip
                header = EthernetHeader(src=self.source_mac, dst=self.eni.master.destination_mac)
                frame = encode_frame(Frame(header, numbered), pad=True)
            self.last_sent_ns = self.transport.send(frame)
            self.stats.frames_sent += 1
            self.stats.acyclic_frames += 1
            got = self.await_frame(index, self.options.frame_timeout_ns, self.last_sent_ns, frame)
            if got is not None:
                reply = got.frame
                if reply[12:14] == _ETHERTYPE_ECAT:  # decode_frame's datagrams, no VLAN tag
                    return decode_ecat_payload(reply, ETH_HEADER_BYTES)[2]
                return decode_frame(reply).datagrams
            self.stats.frames_lost += 1
        first = datagrams[0]
        raise TransportError(
            f"no answer to {first.mnemonic} 0x{first.adp:04X}:0x{first.ado:04X} "
            f"after {tries + 1} frames"
        )

    def _request(self, datagrams: Sequence[Datagram], index: int) -> bytes | None:
        """What :meth:`exchange` sends, ``datagrams`` numbered ``index`` with the M flag
        on all but the last (the bytes of ``encode_frame(make_frame(...), pad=True)``),
        packed in place: a start-up sends some 2,500 frames, and the Datagram, Frame and
        EthernetHeader objects cost more than the bytes. ``None`` for what encode_frame
        would refuse (it says why)."""
        last = len(datagrams) - 1
        body = bytearray()
        for i, d in enumerate(datagrams):
            data = d.data
            if len(data) > MAX_DATAGRAM_DATA:
                return None
            length_word = (
                len(data)
                | (d.reserved & 0x7) << 11
                | (0x4000 if d.circulating else 0)
                | (0x8000 if i < last else 0)
            )
            body += _DATAGRAM_HEAD.pack(
                d.cmd & 0xFF, index & 0xFF, d.address & 0xFFFFFFFF, length_word, d.irq
            )
            body += data
            body += _U16.pack(d.wkc & 0xFFFF)
        if len(body) > 0x7FF:
            return None
        head = self._request_head
        if head is None:
            head = self._request_head = (
                self.eni.master.destination_mac + self.source_mac + _ETHERTYPE_ECAT
            )
        out = head + _U16.pack(len(body) | ECAT_TYPE_COMMANDS << 12) + body
        short = MIN_FRAME_BYTES - FCS_BYTES - len(out)
        return out + bytes(short) if short > 0 else out

    def _send_repeatedly(self, datagrams: Sequence[Datagram], times: int) -> None:
        """``datagrams`` in a frame ``times`` times as :meth:`exchange` with no retry
        sends them (a lost one is just one fewer), the answers not read: the static drift
        compensation's 1,000 ARMW frames. The frame is encoded once; only its index
        changes."""
        header = EthernetHeader(src=self.source_mac, dst=self.eni.master.destination_mac)
        last = len(datagrams) - 1
        numbered = tuple(replace(d, index=0, more=i < last) for i, d in enumerate(datagrams))
        frame = bytearray(encode_frame(Frame(header, numbered), pad=True))
        places, at = [], ETH_HEADER_BYTES + ECAT_HEADER_BYTES
        for d in numbered:
            places.append(at + 1)  # the datagram header's index byte
            at += DATAGRAM_HEADER_BYTES + len(d.data) + WKC_BYTES
        stats, timeout = self.stats, self.options.frame_timeout_ns
        for _ in range(times):
            self.run_due_cycles()
            index = self.new_index()
            for place in places:
                frame[place] = index
            sent = bytes(frame)
            self.last_sent_ns = self.transport.send(sent)
            stats.frames_sent += 1
            stats.acyclic_frames += 1
            if self.await_frame(index, timeout, self.last_sent_ns, sent) is None:
                stats.frames_lost += 1

    def exchange_one(self, datagram: Datagram) -> Datagram:
        return self.exchange([datagram])[0]

    def exchange_many(self, datagrams: Sequence[Datagram]) -> list[Datagram]:
        """As many frames as the datagrams need; the answers in the same order."""
        out: list[Datagram] = []
        batch: list[Datagram] = []
        size = 0
        for d in datagrams:
            if batch and size + d.wire_bytes > MAX_FRAME_DATAGRAM_BYTES:
                out += self.exchange(batch)
                batch, size = [], 0
            batch.append(d)
            size += d.wire_bytes
        if batch:
            out += self.exchange(batch)
        return out

    def await_frame(
        self, index: int, timeout_ns: int, sent_ns: int = 0, like: bytes | bytearray | None = None
    ) -> Received | None:
        """The returned frame with ``index`` within ``timeout_ns``; other returned frames
        that come meanwhile are kept for whoever waits for them. A frame with ``index``
        that returned before ``sent_ns`` answers an earlier frame with the same index (a
        late one, in real time) and is dropped; so is one that is not shaped like the
        frame sent (``like``: its EtherCAT header and first command): a frame
        so late that its index came round again."""
        got = self._stray.pop(index, None)
        if got is not None and got.received_ns >= sent_ns and _alike(got.frame, like):
            return got
        deadline = self.transport.now_ns() + timeout_ns
        while True:
            r = self.transport.recv(max(0, deadline - self.transport.now_ns()))
            if r is None:
                return None
            frame_index = r.frame[_INDEX_AT] if len(r.frame) > _INDEX_AT else -1
            if self._overdue and self._late(frame_index, r):
                continue
            if frame_index == index:
                if r.received_ns >= sent_ns and _alike(r.frame, like):
                    return r
                continue
            self._stray[frame_index] = r

    def _late(self, index: int, r: Received) -> bool:
        """Whether ``r`` answers a frame of a cycle the master stopped waiting for: then it
        is counted late (no longer lost) and dropped."""
        overdue = self._overdue.get(index)
        if overdue is None or r.received_ns < overdue[0]:
            return False
        del self._overdue[index]
        stats = self.stats
        stats.frames_lost -= 1
        if overdue[2]:
            stats.round_trip_ns.append(r.received_ns - overdue[0])  # the bus's, late or not
            stats.late_frames += 1
            stats.cyclic_lost -= 1
            _note(stats.late_at, overdue[1])
        else:
            stats.late_acyclic += 1
        return True

    def fprd(self, station: int, ado: int, length: int) -> Datagram:
        return self.exchange_one(Datagram.physical(Command.FPRD, station, ado, length))

    def fpwr(self, station: int, ado: int, data: bytes) -> Datagram:
        return self.exchange_one(Datagram.physical(Command.FPWR, station, ado, data))

    # ------------------------------------------------------------- time
    def idle(self, duration_ns: int) -> None:
        """Let ``duration_ns`` pass, running every cycle that falls due meanwhile."""
        until = self.transport.now_ns() + duration_ns
        if self._cyclic and not self._in_cycle:
            while self._next_cycle_ns <= until:
                self.cycle()
        self.transport.wait_until(until)

    def run_due_cycles(self) -> None:
        """Run the cycles due by now (not those that fall due while they run: a bus that
        cannot keep the rate would never leave room for the frame that waits)."""
        if self._cyclic and not self._in_cycle:
            now = self.transport.now_ns()
            while self._next_cycle_ns <= now:
                self.cycle()

    # --------------------------------------------------------- transitions
    def bring_up(self, target: AlState = AlState.OP, *, strict: bool = True) -> list[Refusal]:
        """INIT → … → ``target`` as the ENI says. ``strict``: the first refusal raises
        TransitionRefusedError; else refusing slaves are left behind, the others go on,
        and the refusals are returned (also in :attr:`refusals`)."""
        for name in UP:
            if self.state >= target:
                break
            self.transition(name, strict=strict)
        return self.refusals

    def transition(self, name: str, *, strict: bool = True) -> None:
        """Run the InitCmds of transition ``name`` ("IP", "PS", "SO", ...)."""
        if name not in TRANSITION_TARGET:
            raise ValueError(f"unknown transition {name!r}")
        target = TRANSITION_TARGET[name]
        for cmd in self.eni.master.init_cmds:
            if name in cmd.transitions:
                got = self._run_init_cmd(cmd, None, name)
                self._note_master_cmd(cmd, got)
        for slave in self.eni.slaves:
            if slave.position in self._failed:
                continue
            try:
                self._slave_transition(slave, name, target)
            except (TransitionRefusedError, TransportError, SdoAbortError, WireError) as exc:
                refusal = _refusal(slave, name, exc)
                self.refusals.append(refusal)
                self._failed.add(slave.position)
                if strict:
                    if isinstance(exc, TransitionRefusedError):
                        raise
                    raise TransitionRefusedError(
                        slave.name, slave.position, name, None, refusal.text
                    ) from exc
        self.state = target
        if name == "IP" and self.eni_has_dc():
            self.start_dc()
        if target >= AlState.SAFEOP and not self._cyclic:
            self.start_cyclic()
        if target < AlState.SAFEOP:
            self._cyclic = False

    def _note_master_cmd(self, cmd: InitCmd, got: Datagram) -> None:
        if (
            cmd.cmd == Command.BRD
            and cmd.ado == Register.AL_STATUS
            and self.stats.slaves_found is None
        ):
            self.stats.slaves_found = got.wkc

    def _slave_transition(self, slave: Slave, name: str, target: AlState) -> None:
        cmds = [c for c in slave.init_cmds if name in c.transitions]
        coe_done = False
        for cmd in cmds:
            if not coe_done and _requests_state(cmd, target):
                self._coe_init(slave, name)
                coe_done = True
            self._run_init_cmd(cmd, slave, name)
        if not coe_done:
            self._coe_init(slave, name)

    def _coe_init(self, slave: Slave, name: str) -> None:
        mb = slave.mailbox
        if mb is None or not any(name in c.transitions for c in mb.coe_init_cmds):
            return
        sdo = self.sdo(slave)
        for c in mb.coe_init_cmds:
            if name not in c.transitions:
                continue
            try:
                if c.ccs == 2:
                    sdo.upload(c.index, c.subindex, complete_access=c.complete_access)
                else:
                    sdo.download(c.index, c.subindex, c.data, complete_access=c.complete_access)
            except SdoAbortError as exc:
                raise TransitionRefusedError(
                    slave.name,
                    slave.position,
                    name,
                    None,
                    f"CoE InitCmd {c.comment!r} (0x{c.index:04X}:{c.subindex:02X}): {exc}",
                ) from exc

    def _run_init_cmd(self, cmd: InitCmd, slave: Slave | None, name: str) -> Datagram:
        datagram = self._init_datagram(cmd, slave)
        validate = cmd.validate_data
        timeout_ms = cmd.validate_timeout_ms or cmd.timeout_ms or self.options.validate_timeout_ms
        deadline = self.transport.now_ns() + timeout_ms * 1_000_000
        attempts = 0
        while True:
            got = self.exchange_one(datagram)
            wkc_ok = cmd.expected_wkc is None or got.wkc == cmd.expected_wkc
            if wkc_ok and (validate is None or _masked(got.data, cmd.validate_mask) == validate):
                return got
            attempts += 1
            if wkc_ok and slave is not None and _al_refused(cmd, got):
                self._refused(cmd, slave, name, got)
            out_of_time = self.transport.now_ns() >= deadline
            if (validate is None and attempts > cmd.retries) or (
                validate is not None and out_of_time
            ):
                self._failed_cmd(cmd, slave, name, got)
            self.idle(self.options.poll_ns)

    def _init_datagram(self, cmd: InitCmd, slave: Slave | None) -> Datagram:
        data = cmd.data
        if (
            cmd.ado == Register.DC_START_TIME_CYCLIC
            and cmd.cmd in (Command.FPWR, Command.APWR)
            and len(data) == 8
        ):
            data = _U64.pack((_U64.unpack(data)[0] + self.sync_start_ns(slave)) & (2**64 - 1))
        if cmd.logical_address is not None:
            return Datagram.logical(cmd.cmd, cmd.logical_address, data)
        return Datagram.physical(cmd.cmd, cmd.adp, cmd.ado, data)

    def _refused(self, cmd: InitCmd, slave: Slave, name: str, got: Datagram) -> None:
        code = self._al_status_code(cmd)
        raise TransitionRefusedError(
            slave.name,
            slave.position,
            name,
            code,
            al_status_text(code) if code is not None else "",
            f"AL status {al_state_name(got.data[0])}",
        )

    def _failed_cmd(self, cmd: InitCmd, slave: Slave | None, name: str, got: Datagram) -> None:
        what = f"InitCmd {cmd.comment!r} ({got.mnemonic} 0x{cmd.ado:04X})"
        if cmd.expected_wkc is not None and got.wkc != cmd.expected_wkc:
            detail = f"working counter {got.wkc}, expected {cmd.expected_wkc}"
        else:
            wanted = cmd.validate_data.hex() if cmd.validate_data else ""
            detail = f"read {got.data.hex()}, expected {wanted}"
        if slave is None:
            raise TransitionRefusedError("master", 0, name, None, f"{what}: {detail}")
        code = self._al_status_code(cmd) if cmd.ado == Register.AL_STATUS else None
        text = al_status_text(code) if code else ""
        raise TransitionRefusedError(
            slave.name,
            slave.position,
            name,
            code or None,
            f"{what}: {detail}" + (f"; {text}" if text else ""),
        )

    def _al_status_code(self, cmd: InitCmd) -> int | None:
        """Register 0x0134 of the slave ``cmd`` addresses (same addressing)."""
        read = Command.APRD if cmd.cmd in AUTO_INCREMENT else Command.FPRD
        try:
            got = self.exchange_one(Datagram.physical(read, cmd.adp, Register.AL_STATUS_CODE, 2))
        except TransportError:
            return None
        return _U16.unpack(got.data)[0] if got.wkc == 1 else None

    # ------------------------------------------------------------- mailbox
    def mailbox(self, slave: Slave | int) -> MailboxClient:
        """The mailbox client of a slave (an ENI slave or its 1-based position)."""
        s = self.eni.slaves[slave - 1] if isinstance(slave, int) else slave
        if s.mailbox is None:
            raise WireError(f"slave {s.position} ({s.name}) has no mailbox in the ENI")
        client = self._mailboxes.get(s.position)
        if client is None:
            mb = s.mailbox
            layout = MailboxLayout(
                s.station_address,
                mb.out_start,
                mb.out_length_bytes,
                mb.in_start,
                mb.in_length_bytes,
            )
            client = MailboxClient(self, layout, poll_ns=self.options.poll_ns)
            self._mailboxes[s.position] = client
        return client

    def sdo(self, slave: Slave | int) -> SdoClient:
        """An SDO client for a slave (an ENI slave or its 1-based position)."""
        return SdoClient(self.mailbox(slave))

    # ------------------------------------------------------------------ DC
    def eni_has_dc(self) -> bool:
        return any(s.dc is not None for s in self.eni.slaves)

    def _reference(self, dc_slaves: list[Slave]) -> Slave:
        for s in dc_slaves:
            if s.dc is not None and s.dc.reference_clock:
                return s
        for frame in self.eni.cyclic_frames:
            for c in frame.commands:
                if c.cmd == Command.ARMW and c.ado == Register.DC_SYSTEM_TIME:
                    position = ((-(c.adp or 0)) & 0xFFFF) + 1
                    for s in dc_slaves:
                        if s.position == position:
                            return s
                if c.cmd == Command.FRMW and c.ado == Register.DC_SYSTEM_TIME:
                    for s in dc_slaves:
                        if s.station_address == c.adp:
                            return s
        return dc_slaves[0]

    def start_dc(self) -> None:
        """Propagation delays, offsets and static drift compensation (see
        :mod:`lolacli.master.dc`) for the DC slaves that reached PREOP."""
        line = [s for s in self.eni.slaves if s.position not in self._failed]
        dc_slaves = [s for s in line if s.dc is not None]
        if not dc_slaves:
            return
        self.exchange_one(Datagram.physical(Command.BWR, 0, Register.DC_RECEIVE_TIME_PORT0, 4))
        latched_at = self.last_sent_ns
        reads: list[Datagram] = []
        for s in line:
            reads.append(
                Datagram.physical(
                    Command.FPRD, s.station_address, Register.DC_RECEIVE_TIME_PORT0, 8
                )
            )
            reads.append(
                Datagram.physical(Command.FPRD, s.station_address, Register.DC_RECEIVE_TIME_PU, 8)
            )
            reads.append(Datagram.physical(Command.FPRD, s.station_address, Register.DL_STATUS, 2))
        got = self.exchange_many(reads)
        loops, locals_at_latch = [], []
        for i in range(len(line)):
            times, pu, status = got[3 * i : 3 * i + 3]
            port0, port1 = _U32.unpack_from(times.data, 0)[0], _U32.unpack_from(times.data, 4)[0]
            downstream = bool(_U16.unpack(status.data)[0] & 0x0800) and status.wkc == 1
            loops.append(dc.loop_time_ns(port0, port1 if downstream else None))
            locals_at_latch.append(_U64.unpack(pu.data)[0])
        delays = dc.propagation_delays(loops)
        reference = self._reference(dc_slaves)
        ref_i = line.index(reference)
        ref_offset = (latched_at - locals_at_latch[ref_i]) % (1 << 64)
        rel = [d - delays[ref_i] for d in delays]
        offsets = dc.system_time_offsets(locals_at_latch, rel, ref_i, ref_offset)
        writes: list[Datagram] = []
        synced = [s for s in dc_slaves if line.index(s) >= ref_i]
        for s in synced:
            i = line.index(s)
            writes.append(
                Datagram.physical(
                    Command.FPWR,
                    s.station_address,
                    Register.DC_SYSTEM_TIME_OFFSET,
                    _U64.pack(offsets[i]),
                )
            )
            writes.append(
                Datagram.physical(
                    Command.FPWR,
                    s.station_address,
                    Register.DC_SYSTEM_TIME_DELAY,
                    _U32.pack(max(0, rel[i]) & 0xFFFFFFFF),
                )
            )
        self.exchange_many(writes)
        self.dc_slaves, self.dc_reference = synced, reference
        compensate = Datagram.physical(
            Command.ARMW, (-(reference.position - 1)) & 0xFFFF, Register.DC_SYSTEM_TIME, 8
        )
        self._send_repeatedly([compensate], self.options.dc_drift_frames)
        self.check_dc()

    def system_time_ns(self) -> int:
        """The master's view of the DC system time (its clock; the reference clock's
        offset was set to it at start-up)."""
        return self.transport.now_ns()

    def sync_start_ns(self, slave: Slave | None) -> int:
        """Where SYNC0 starts: ``sync_start_delay_ns`` from now, on a cycle boundary (the
        ENI's value is added to it: ETG.2100 "the master adds its local time")."""
        cycle = self.cycle_time_ns
        if slave is not None and slave.dc is not None and slave.dc.cycle_time0_ns:
            cycle = slave.dc.cycle_time0_ns
        start = self.system_time_ns() + self.options.sync_start_delay_ns
        return -(-start // cycle) * cycle

    def check_dc(self) -> int | None:
        """Read 0x092C of every synchronised DC slave but the reference (its own value
        means nothing): the largest |difference| in ns."""
        reads = self._dc_check_datagrams()
        if not reads:
            return None
        worst = 0
        for d in self.exchange_many(reads):
            if d.wkc == 1:
                worst = max(worst, abs(decode_system_time_difference(d.data)))
        self.stats.dc_errors_ns.append((self.transport.now_ns(), worst))
        return worst

    # --------------------------------------------------------------- cyclic
    @property
    def cycling(self) -> bool:
        """Whether the cyclic frames run (from SAFEOP on, until :meth:`drain`)."""
        return self._cyclic

    def start_cyclic(self) -> None:
        self._cyclic = True
        self._next_cycle_ns = self.transport.now_ns()

    def _frame_plans(self) -> list[FramePlan]:
        plans = self._plans.get(self.state)
        if plans is None:
            plans = []
            for frame in self.eni.cyclic_frames:
                plan = plan_frame(
                    frame,
                    self.state.name,
                    inputs_bytes=len(self.image.inputs),
                    outputs_bytes=len(self.image.outputs),
                    source_mac=self.source_mac,
                    destination_mac=self.eni.master.destination_mac,
                )
                if plan is not None:
                    plans.append(plan)
            self._plans[self.state] = plans
        return plans

    def cycle(self) -> None:
        """One cycle at the next cycle time (see the module docstring)."""
        if self._in_cycle:
            return
        self._in_cycle = True
        try:
            if self.options.time_sections:
                self._timed_cycle()
            else:
                self._cycle()
        finally:
            self._in_cycle = False

    def _cycle(self) -> None:
        transport = self.transport
        transport.wait_until(self._next_cycle_ns)
        self._rx()
        self.image.publish(self.stats.cycles)
        for device in self.devices:
            device.process()
        for hook in self.control:
            hook(self)
        frames = self._build()
        for plan, index, frame in frames:
            self._pending.append((plan, index, transport.send(frame)))
        self._admin()
        self._finish_cycle()

    def _timed_cycle(self) -> None:
        """:meth:`_cycle` with each section timed; the time the transport spent in an
        in-process bus (the emulated chain answering) is taken out of the sections and
        kept as ``bus_emulation``: it is the bus, not the master's software."""
        clock = time.perf_counter_ns
        transport = self.transport
        self.transport.wait_until(self._next_cycle_ns)
        busy0 = getattr(transport, "processing_ns", 0)
        t0 = clock()
        self._rx()
        t1 = clock()
        self.image.publish(self.stats.cycles)
        t2 = clock()
        for device in self.devices:
            device.process()
        t3 = clock()
        for hook in self.control:
            hook(self)
        t4 = clock()
        frames = self._build()
        t5 = clock()
        busy5 = getattr(transport, "processing_ns", 0)
        for plan, index, frame in frames:
            self._pending.append((plan, index, transport.send(frame)))
        t6 = clock()
        busy6 = getattr(transport, "processing_ns", 0)
        self._admin()
        t7 = clock()
        busy7 = getattr(transport, "processing_ns", 0)
        appends = self._section_appends
        if appends is None or appends[0] is not self.sections_ns:
            appends = self._section_appends = self._bind_section_appends()
        _, rx, copy_rx, proc_data, control, copy_tx, send, admin, emulation = appends
        rx(t1 - t0)
        copy_rx(t2 - t1)
        proc_data(t3 - t2)
        control(t4 - t3)
        copy_tx(t5 - t4 - (busy5 - busy0))
        send(t6 - t5 - (busy6 - busy5))
        admin(t7 - t6 - (busy7 - busy6))
        emulation(busy7 - busy0)
        self._finish_cycle()

    def _bind_section_appends(self) -> tuple[Any, ...]:
        """The section lists' appends in :data:`SECTIONS` order, then the bus emulation's,
        after the dict they are of (looked up once, not eight times a cycle)."""
        sections = self.sections_ns
        lists = [sections[name] for name, _ in SECTIONS] + [self.bus_emulation_ns]
        return (sections, *(values.append for values in lists))

    def _finish_cycle(self) -> None:
        stats = self.stats
        stats.cycles += 1
        self._next_cycle_ns += self.cycle_time_ns
        missed = (self.transport.now_ns() - self._next_cycle_ns) // self.cycle_time_ns
        if missed > 0:
            self._next_cycle_ns += missed * self.cycle_time_ns
            stats.skipped_cycles += missed
            _note(stats.skipped_at, stats.cycles)

    @property
    def next_cycle_ns(self) -> int:
        """When the next cycle is due (during a cycle: when this one was due)."""
        return self._next_cycle_ns

    def _build(self) -> list[tuple[FramePlan, int, bytes]]:
        out = []
        now = self.system_time_ns()
        with self.image.lock:
            outputs = self.image.outputs
            for plan in self._frame_plans():
                index = self.new_index()
                out.append((plan, index, plan.build(index, outputs, now)))
        self.stats.cyclic_frames += len(out)
        self.stats.frames_sent += len(out)
        return out

    def _rx(self) -> None:
        """Take the returned cyclic frames of the last cycle: inputs, WKC, round trip."""
        if self._pending_dc:
            self._take_dc_checks()
        if not self._pending:
            return
        pending, self._pending = self._pending, []
        stats = self.stats
        inputs = self.image.inputs
        mismatched = False
        now = self.transport.now_ns()
        realtime = self.options.realtime
        for plan, index, sent in pending:
            # a frame gets one cycle time to come back from when it left (a frame that
            # waited behind others on the port left late: the master waits for it, as one
            # whose NIC queue is full waits); in real time no later than this cycle was due
            until = sent + self.cycle_time_ns
            if realtime and until > self._next_cycle_ns:
                until = self._next_cycle_ns
            got = self.await_frame(index, max(0, until - now), sent, plan.template)
            if got is None:
                stats.cyclic_lost += 1
                stats.frames_lost += 1
                self._overdue[index] = (sent, stats.cycles, True)
                continue
            stats.round_trip_ns.append(got.received_ns - sent)
            bad = plan.take(got.frame, inputs)
            stats.wkc_checked += len(plan.wkc)
            if bad:
                stats.wkc_mismatches += bad
                mismatched = True
        if mismatched:
            stats.cycles_with_mismatch += 1
            _note(stats.mismatch_at, stats.cycles)

    def _admin(self) -> None:
        every = self.options.dc_check_cycles
        if every and self.dc_slaves and self.stats.cycles % every == every - 1:
            self._send_dc_check()
        for hook in self.admin:
            hook(self)

    def _dc_check_datagrams(self) -> list[Datagram]:
        return [
            Datagram.physical(
                Command.FPRD, s.station_address, Register.DC_SYSTEM_TIME_DIFFERENCE, 4
            )
            for s in self.dc_slaves
            if s is not self.dc_reference
        ]

    def _dc_check_frame(self) -> _DcCheckFrame | None:
        """The DC diagnosis frame for the followers of now (index 0), made once for them;
        ``None`` when there are none or they do not fit in one frame."""
        followers = tuple(s.station_address for s in self.dc_slaves if s is not self.dc_reference)
        cached = self._dc_frame
        if cached is not None and cached.followers == followers:
            return cached
        reads = self._dc_check_datagrams()
        if not reads or sum(d.wire_bytes for d in reads) > MAX_FRAME_DATAGRAM_BYTES:
            self._dc_frame = None
            return None
        frame = encode_frame(
            make_frame(reads, src=self.source_mac, dst=self.eni.master.destination_mac), pad=True
        )
        at, places = ETH_HEADER_BYTES + ECAT_HEADER_BYTES, []
        for d in reads:
            places.append(at)
            at += DATAGRAM_HEADER_BYTES + len(d.data) + WKC_BYTES
        self._dc_frame = _DcCheckFrame(followers, bytearray(frame), tuple(places))
        return self._dc_frame

    def _send_dc_check(self) -> None:
        """Send the DC diagnosis (0x092C of every follower) without waiting: the answer is
        taken with the next cycle's frames, as a real master's acyclic traffic."""
        check = self._dc_check_frame()
        if check is None:
            return
        index = self.new_index()
        template = check.template
        for at in check.places:
            template[at + 1] = index  # the datagram header's index byte
        frame = bytes(template)
        sent = self.transport.send(frame)
        self.stats.frames_sent += 1
        self.stats.acyclic_frames += 1
        self._pending_dc.append((index, sent))

    def _take_dc_checks(self) -> None:
        """The answers to the DC diagnosis frames; in real time without waiting: one not
        back yet is looked for again next cycle (lost after the frame timeout)."""
        pending, self._pending_dc = self._pending_dc, []
        now = self.transport.now_ns()
        realtime = self.options.realtime
        for index, sent in pending:
            # the diagnosis is no reason to hold the cycle: at most until it was due
            wait = 0 if realtime else max(0, min(sent + self.cycle_time_ns,
                                                 self._next_cycle_ns) - now)
            got = self.await_frame(index, wait, sent)
            if got is None:
                if realtime and now - sent < self.options.frame_timeout_ns:
                    self._pending_dc.append((index, sent))
                    continue
                self.stats.frames_lost += 1
                self._overdue[index] = (sent, self.stats.cycles, False)
                continue
            self.stats.dc_errors_ns.append((sent, self._dc_worst(got.frame)))

    def _dc_worst(self, frame: bytes) -> int:
        """The largest |0x092C| among the datagrams of a DC diagnosis answer that one
        slave answered (WKC 1); read in place when the answer has the layout of the frame
        sent (it has, unless it is not that frame's answer), else decoded."""
        check = self._dc_frame
        worst = 0
        head = ETH_HEADER_BYTES
        sent = check.template if check is not None else b""
        if (
            check is not None
            and len(frame) >= len(sent)
            and frame[head : head + 2] == sent[head : head + 2]
            and all(frame[at + 6 : at + 8] == sent[at + 6 : at + 8] for at in check.places)
        ):
            for at in check.places:
                if frame[at + 14] | frame[at + 15] << 8 == 1:  # its WKC: after 4 bytes of data
                    worst = max(worst, abs(decode_system_time_difference(frame, at + 10)))
            return worst
        for d in decode_frame(frame).datagrams:
            if d.wkc == 1:
                worst = max(worst, abs(decode_system_time_difference(d.data)))
        return worst

    def drain(self) -> None:
        """Take the answers of the last cycle's frames (at the next cycle time) and stop
        cycling."""
        if self._pending or self._pending_dc:
            self.transport.wait_until(self._next_cycle_ns)
            self._in_cycle = True
            try:
                self._rx()
                self.image.publish(self.stats.cycles)
            finally:
                self._in_cycle = False
        self._cyclic = False

    def run(self, cycles: int, *, on_cycle: Callable[[int], None] | None = None) -> None:
        """Run ``cycles`` cycles from now (the bus must be in SAFEOP or OP)."""
        if not self._cyclic:
            self.start_cyclic()
        for k in range(cycles):
            self.cycle()
            if on_cycle is not None:
                on_cycle(k)

    # ------------------------------------------------------------ variables
    def link(self, name: str, variable: Any) -> Any:
        """Link a Bus Variable to the ENI variable ``name`` (see ProcessImage.link)."""
        return self.image.link(name, variable)

    def al_states(self) -> list[tuple[int, int | None]]:
        """(position, AL status byte or None when it does not answer) of every slave."""
        reads = [
            Datagram.physical(Command.FPRD, s.station_address, Register.AL_STATUS, 2)
            for s in self.eni.slaves
        ]
        got = self.exchange_many(reads)
        return [
            (s.position, d.data[0] if d.wkc == 1 else None)
            for s, d in zip(self.eni.slaves, got, strict=True)
        ]


@dataclass(frozen=True, slots=True)
class _DcCheckFrame:
    """The DC diagnosis frame of some followers: their station addresses, the frame
    with index 0 and where its datagrams start (their index byte is the second)."""

    followers: tuple[int, ...]
    template: bytearray
    places: tuple[int, ...]


def _alike(frame: bytes, like: bytes | bytearray | None) -> bool:
    """Whether ``frame`` can be the answer to ``like``: the same EtherCAT header (the
    datagrams' length) and first command (a slave changes data and working counters,
    never these)."""
    if like is None:
        return True
    head = ETH_HEADER_BYTES
    return frame[head : head + 3] == like[head : head + 3]


def _masked(data: bytes, mask: bytes | None) -> bytes:
    if mask is None:
        return data
    return bytes(a & m for a, m in zip(data, mask, strict=False))


def _requests_state(cmd: InitCmd, target: AlState) -> bool:
    """Whether ``cmd`` writes AL control with the request for ``target``."""
    return (
        cmd.ado == Register.AL_CONTROL
        and cmd.cmd in (Command.APWR, Command.FPWR, Command.BWR)
        and bool(cmd.data)
        and cmd.data[0] & 0x0F == target
    )


def _al_refused(cmd: InitCmd, got: Datagram) -> bool:
    """An AL status check answered with the error indicator the check did not expect."""
    if cmd.ado != Register.AL_STATUS or cmd.cmd not in (Command.APRD, Command.FPRD) or not got.data:
        return False
    if not got.data[0] & AL_ERROR_INDICATOR:
        return False
    expected = cmd.validate_data[0] if cmd.validate_data else 0
    return not expected & AL_ERROR_INDICATOR


def _refusal(slave: Slave, name: str, exc: Exception) -> Refusal:
    if isinstance(exc, TransitionRefusedError):
        return Refusal(slave.position, slave.name, name, exc.al_status_code, exc.text, exc.detail)
    return Refusal(slave.position, slave.name, name, None, str(exc))


__all__ = [
    "SECTIONS",
    "TRANSITION_TARGET",
    "UP",
    "Master",
    "MasterOptions",
    "MasterStats",
    "Refusal",
]
