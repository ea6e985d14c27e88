"""FoE (file access over EtherCAT, ETG.1000.6 §5.9) through the master: a firmware
written to a slave's bootloader and read back.

A bootloader runs in BOOT and has a mailbox of its own, the *bootstrap mailbox* whose
offsets and sizes the SII states (words 0x14–0x17). :func:`enter_boot` takes one slave
there as ETG.1000.6 Figure 10 allows (INIT → BOOT): station address, INIT (errors
acknowledged), SM0/SM1 set to the bootstrap mailbox read from the SII, BOOT requested and
checked; :func:`leave_boot` takes it back to INIT (the bootloader hands over to the
firmware written). :class:`FoeClient` then runs the transfers over a
:class:`~lolacli.master.mailbox.MailboxClient` on that mailbox:

* write: write request (password, file name) → ack 0; data packets 1, 2, … of as many
  bytes as the slave's mailbox carries, each acknowledged by its number; a *busy* answer
  sends the packet again; the file ends with a packet shorter than that (an empty one
  after a file of whole packets);
* read: read request → data 1; each data packet acknowledged, the next one comes, until a
  shorter one (its ack gets no answer).

An FoE error packet from the slave raises :class:`~lolacli.errors.FoeError` (its code and
the meaning of :func:`lolacli.wire.foe.foe_error_text`); no answer and a mailbox error
reply are :class:`~lolacli.errors.TransportError`.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass

from lolacli.errors import FoeError, TransitionRefusedError, TransportError, UsageError, WireError
from lolacli.master import eeprom
from lolacli.master.core import Master
from lolacli.master.mailbox import DatagramPort, MailboxClient, MailboxLayout
from lolacli.wire.commands import Command
from lolacli.wire.foe import (
    FoeAck,
    FoeBusy,
    FoeData,
    FoeMessage,
    FoeReadRequest,
    FoeWriteRequest,
    data_bytes_per_packet,
    decode_foe,
    encode_foe,
    foe_error_text,
)
from lolacli.wire.foe import FoeError as FoeErrorPacket
from lolacli.wire.frame import Datagram
from lolacli.wire.mailbox import MailboxType
from lolacli.wire.registers import (
    SM_ACTIVATE_ENABLE,
    SM_CONTROL_MAILBOX_IN,
    SM_CONTROL_MAILBOX_OUT,
    AlState,
    Register,
    SyncManager,
    al_status_text,
    encode_sync_manager,
    sync_manager_address,
)

_U16 = struct.Struct("<H")
_ACK_ERROR = 0x10
_STATE_MASK = 0x0F
_ERROR_FLAG = 0x10
#: the longest a slave may take to enter a state (ETG.1000.6 leaves it to the device; 5 s
#: is what ENIs give an IB transition)
STATE_TIMEOUT_NS = 5_000_000_000
POLL_NS = 1_000_000
#: how often a slave may answer one packet busy before the transfer gives up
MAX_BUSY = 1000


@dataclass(frozen=True, slots=True)
class FoeTransfer:
    """What one transfer moved: the file's name and bytes, the data packets and the
    busy answers among them, and how long it took (the transport's clock)."""

    name: str
    bytes: int
    packets: int
    busy: int
    elapsed_ns: int


def _fpwr(port: DatagramPort, station: int, ado: int, data: bytes) -> None:
    d = port.exchange_one(Datagram.physical(Command.FPWR, station, ado, data))
    if d.wkc != 1:
        raise TransportError(f"station 0x{station:04X}: write of 0x{ado:04X} not taken")


@dataclass(frozen=True, slots=True)
class SlaveAt:
    """The slave FoE talks to: 1-based position, station address, name, and how errors
    name it ("slave 3 (Drive) on eth0")."""

    position: int
    station: int
    name: str
    where: str


def _request_state(port: DatagramPort, slave: SlaveAt, state: int, timeout_ns: int) -> None:
    """Request ``state`` (an error acknowledged with it) and wait until the slave is
    there: TransitionRefusedError with its AL status code when it refuses."""
    station, where = slave.station, slave.where
    control = state | (_ACK_ERROR if state == AlState.INIT else 0)
    _fpwr(port, station, Register.AL_CONTROL, _U16.pack(control))
    deadline = port.now_ns() + timeout_ns
    name = {AlState.INIT: "BI", AlState.BOOT: "IB"}.get(AlState(state), f"to 0x{state:X}")
    while True:
        d = port.exchange_one(Datagram.physical(Command.FPRD, station, Register.AL_STATUS, 6))
        if d.wkc == 1:
            status = d.data[0]
            if status & _STATE_MASK == state and not status & _ERROR_FLAG:
                return
            if status & _ERROR_FLAG and state != AlState.INIT:
                code = _U16.unpack_from(d.data, 4)[0]
                raise TransitionRefusedError(
                    slave.name, slave.position, name, code, al_status_text(code)
                )
        if port.now_ns() >= deadline:
            raise TransportError(f"{where}: did not reach {AlState(state).name} in time")
        port.idle(POLL_NS)


def bootstrap_layout(master: Master, station: int, where: str) -> MailboxLayout:
    """The bootstrap mailbox of the slave at ``station`` as its SII states it;
    UsageError when it states none (no bootloader to talk to)."""
    (got,) = eeprom.read_sii(master, [station], auto_increment=False)
    if got.info is None:
        raise TransportError(f"{where}: SII not readable: {got.error}")
    h = got.info.header
    if not (h.bootstrap_rx_mailbox_bytes and h.bootstrap_tx_mailbox_bytes):
        raise UsageError(f"{where}: its SII states no bootstrap mailbox (no bootloader): no FoE")
    return MailboxLayout(
        station,
        h.bootstrap_rx_mailbox_offset,
        h.bootstrap_rx_mailbox_bytes,
        h.bootstrap_tx_mailbox_offset,
        h.bootstrap_tx_mailbox_bytes,
    )


def enter_boot(
    master: Master, slave: SlaveAt, *, timeout_ns: int = STATE_TIMEOUT_NS
) -> MailboxLayout:
    """``slave`` in BOOT with its bootstrap mailbox (see the module docstring); the
    mailbox's layout. TransitionRefusedError when it refuses BOOT."""
    position, station, where = slave.position, slave.station, slave.where
    auto = (-(position - 1)) & 0xFFFF
    d = master.exchange_one(
        Datagram.physical(Command.APWR, auto, Register.STATION_ADDRESS, _U16.pack(station))
    )
    if d.wkc != 1:
        raise TransportError(f"{where}: no slave at position {position} takes its address")
    _request_state(master, slave, AlState.INIT, timeout_ns)
    layout = bootstrap_layout(master, station, where)
    sm0 = SyncManager(
        layout.out_start, layout.out_bytes, SM_CONTROL_MAILBOX_OUT, activate=SM_ACTIVATE_ENABLE
    )
    sm1 = SyncManager(
        layout.in_start, layout.in_bytes, SM_CONTROL_MAILBOX_IN, activate=SM_ACTIVATE_ENABLE
    )
    _fpwr(master, station, sync_manager_address(0), bytes(16))
    _fpwr(master, station, sync_manager_address(0), encode_sync_manager(sm0))
    _fpwr(master, station, sync_manager_address(1), encode_sync_manager(sm1))
    _request_state(master, slave, AlState.BOOT, timeout_ns)
    return layout


def leave_boot(port: DatagramPort, slave: SlaveAt, *, timeout_ns: int = STATE_TIMEOUT_NS) -> None:
    """BOOT → INIT: the bootloader hands over to the firmware."""
    _request_state(port, slave, AlState.INIT, timeout_ns)


class FoeClient:
    """FoE transfers with one slave over its (bootstrap) mailbox; ``where`` names it in
    errors ("slave 3 (Drive) on eth0")."""

    def __init__(self, mailbox: MailboxClient, where: str) -> None:
        self.mailbox = mailbox
        self.where = where

    @property
    def packet_bytes(self) -> int:
        """File bytes in one data packet: what the smaller of the two mailboxes carries."""
        layout = self.mailbox.layout
        return data_bytes_per_packet(min(layout.out_bytes, layout.in_bytes))

    def _ask(self, message: FoeMessage) -> FoeMessage:
        try:
            answer = decode_foe(self.mailbox.request(MailboxType.FoE, encode_foe(message)))
        except WireError as exc:
            raise TransportError(f"{self.where}: {exc}") from None
        if isinstance(answer, FoeErrorPacket):
            raise FoeError(self.where, int(answer.code), foe_error_text(answer.code), answer.text)
        return answer

    def _more(self) -> FoeMessage:
        """The slave's next answer, sending nothing (after a busy answer to a request)."""
        try:
            answer = decode_foe(self.mailbox.receive(MailboxType.FoE))
        except WireError as exc:
            raise TransportError(f"{self.where}: {exc}") from None
        if isinstance(answer, FoeErrorPacket):
            raise FoeError(self.where, int(answer.code), foe_error_text(answer.code), answer.text)
        return answer

    def _unexpected(self, answer: FoeMessage, wanted: str) -> TransportError:
        return TransportError(f"{self.where}: FoE: {wanted} expected, the slave sent {answer}")

    def write(
        self,
        name: str,
        data: bytes,
        password: int = 0,
        *,
        progress: Callable[[int], None] | None = None,
    ) -> FoeTransfer:
        """Write ``data`` as file ``name``; ``progress`` is told the bytes acknowledged."""
        start = self.mailbox.port.now_ns()
        answer = self._ask(FoeWriteRequest(name, password))
        while isinstance(answer, FoeBusy):
            answer = self._more()
        if answer != FoeAck(0):
            raise self._unexpected(answer, "ack of packet 0")
        step = self.packet_bytes
        if step <= 0:
            raise UsageError(f"{self.where}: its mailbox is too small for FoE data")
        offset, packet, busy = 0, 1, 0
        while True:
            piece = data[offset : offset + step]
            answer = self._ask(FoeData(packet, piece))
            if isinstance(answer, FoeBusy):
                busy += 1
                if busy > MAX_BUSY:
                    raise TransportError(f"{self.where}: FoE: busy {busy} times")
                continue
            if answer != FoeAck(packet):
                raise self._unexpected(answer, f"ack of packet {packet}")
            offset += len(piece)
            if progress is not None:
                progress(offset)
            if len(piece) < step:
                elapsed = self.mailbox.port.now_ns() - start
                return FoeTransfer(name, len(data), packet, busy, elapsed)
            packet += 1

    def read(
        self,
        name: str,
        password: int = 0,
        *,
        max_bytes: int | None = None,
        progress: Callable[[int], None] | None = None,
    ) -> tuple[bytes, FoeTransfer]:
        """The file ``name``; TransportError when it grows past ``max_bytes``."""
        start = self.mailbox.port.now_ns()
        step = self.packet_bytes
        answer = self._ask(FoeReadRequest(name, password))
        data = bytearray()
        packet, busy = 0, 0
        while True:
            if isinstance(answer, FoeBusy):
                busy += 1
                answer = self._more()
                continue
            if not isinstance(answer, FoeData) or answer.packet != packet + 1:
                raise self._unexpected(answer, f"data packet {packet + 1}")
            packet = answer.packet
            data += answer.data
            if max_bytes is not None and len(data) > max_bytes:
                raise TransportError(f"{self.where}: FoE: {name!r} is over {max_bytes} bytes")
            if progress is not None:
                progress(len(data))
            if len(answer.data) < step:
                self.mailbox.send(MailboxType.FoE, encode_foe(FoeAck(packet)))
                elapsed = self.mailbox.port.now_ns() - start
                return bytes(data), FoeTransfer(name, len(data), packet, busy, elapsed)
            answer = self._ask(FoeAck(packet))


__all__ = [
    "FoeClient",
    "SlaveAt",
    "FoeTransfer",
    "bootstrap_layout",
    "enter_boot",
    "leave_boot",
]
