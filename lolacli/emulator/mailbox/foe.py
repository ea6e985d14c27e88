"""FoE in the mailbox: a bootloader's file read and write (ETG.1000.6 §5.9).

A slave keeps its files in a :class:`FileStore` of its own that lives as long as the
slave (flash: it survives every state change, a return from BOOT to INIT too). The
:class:`FoeServer` serves it:

* in BOOT only: a read or write request in any other state gets the FoE error
  0x8008 "bootstrap only", as a drive whose firmware is written by its bootloader answers;
* with the slave's password: a request with another one gets 0x800A "no rights";
* a write request is acknowledged with packet 0; the first data packet is answered
  *busy* once (the bootloader erases the flash meanwhile) and taken when the master sends
  it again; each data packet is acknowledged by its number; a packet shorter than the
  most the master's mailbox carries ends the file, which is stored under its name
  (a file as large as ``max_file_bytes`` — :data:`MAX_FILE_BYTES` — and more gets 0x8003
  "disk full");
* a read request of a stored file is answered with data packet 1 of as many bytes as the
  smaller mailbox carries, each ack with the next packet, until a shorter one (an empty
  one after a file of whole packets); a name not stored gets 0x8001 "not found";
* a packet out of turn gets 0x8005 "packet number wrong", a data or ack packet without a
  transfer 0x8004 "illegal"; an error packet from the master ends the transfer.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from lolacli.emulator.mailbox.dispatch import MailboxContext
from lolacli.errors import WireError
from lolacli.wire.foe import (
    FOE_HEADER_BYTES,
    FoeAck,
    FoeBusy,
    FoeData,
    FoeError,
    FoeErrorCode,
    FoeMessage,
    FoeReadRequest,
    FoeWriteRequest,
    decode_foe,
    encode_foe,
)
from lolacli.wire.mailbox import MAILBOX_HEADER_BYTES, MailboxType, encode_mailbox_message
from lolacli.wire.registers import AlState

#: the largest file a slave stores (its flash)
MAX_FILE_BYTES = 16 * 1024 * 1024
#: FoE requests are answered in every state with a mailbox (with an error outside BOOT)
FOE_STATES = frozenset({AlState.PREOP, AlState.SAFEOP, AlState.OP, AlState.BOOT})


@dataclass
class FileStore:
    """A slave's files by name: its flash."""

    files: dict[str, bytes] = field(default_factory=dict)


@dataclass
class _Write:
    name: str
    data: bytearray
    packet: int = 0  # the last packet taken
    busy_sent: bool = False


@dataclass
class _Read:
    data: bytes
    chunk: int
    packet: int = 0  # the last packet sent
    offset: int = 0
    done: bool = False


class FoeServer:
    """One slave's FoE server (see the module docstring)."""

    mailbox_type = MailboxType.FoE
    states = FOE_STATES

    def __init__(self, store: FileStore | None = None, *, password: int = 0) -> None:
        self.store = store if store is not None else FileStore()
        self.password = password
        self.busy_once = True
        self.max_file_bytes = MAX_FILE_BYTES
        self._write: _Write | None = None
        self._read: _Read | None = None
        self.errors: list[int] = []  # FoE error codes sent, in order

    # ------------------------------------------------------------------ dispatch
    def handle(self, request: bytes, context: MailboxContext) -> list[bytes]:
        length = request[0] | request[1] << 8
        payload = request[MAILBOX_HEADER_BYTES : MAILBOX_HEADER_BYTES + length]
        try:
            message = decode_foe(payload)
        except WireError:
            return self._error(FoeErrorCode.ILLEGAL)
        answer = self._serve(message, context)
        return [self._mailbox(m) for m in answer]

    def state_changed(self, state: int) -> None:
        """Leaving BOOT ends any transfer; a file half written is not stored."""
        if state != AlState.BOOT:
            self._write = None
            self._read = None

    def _serve(self, message: FoeMessage, context: MailboxContext) -> list[FoeMessage]:
        if isinstance(message, FoeWriteRequest | FoeReadRequest):
            self._write = self._read = None
            refused = self._refusal(message.password, context.al_state)
            if refused is not None:
                return self._refuse(refused)
            if isinstance(message, FoeWriteRequest):
                self._write = _Write(message.name, bytearray())
                return [FoeAck(0)]
            return self._start_read(message.name, context)
        if isinstance(message, FoeData):
            return self._data(message, context)
        if isinstance(message, FoeAck):
            return self._ack(message)
        if isinstance(message, FoeError):
            self._write = self._read = None
            return []
        return self._refuse(FoeErrorCode.ILLEGAL)  # busy from the master

    def _refusal(self, password: int, al_state: int) -> int | None:
        if al_state != AlState.BOOT:
            return FoeErrorCode.BOOTSTRAP_ONLY
        if password != self.password:
            return FoeErrorCode.NO_RIGHTS
        return None

    # ------------------------------------------------------------------ write
    def _data(self, message: FoeData, context: MailboxContext) -> list[FoeMessage]:
        w = self._write
        if w is None:
            return self._refuse(FoeErrorCode.ILLEGAL)
        if message.packet != w.packet + 1:
            self._write = None
            return self._refuse(FoeErrorCode.PACKET_NUMBER_WRONG)
        if self.busy_once and not w.busy_sent:
            w.busy_sent = True  # the flash is erased: send this packet again
            return [FoeBusy(0, 100, "erasing flash")]
        if len(w.data) + len(message.data) >= self.max_file_bytes:
            self._write = None
            return self._refuse(FoeErrorCode.DISK_FULL)
        w.data += message.data
        w.packet = message.packet
        full = context.write_bytes - MAILBOX_HEADER_BYTES - FOE_HEADER_BYTES
        if len(message.data) < full:
            self.store.files[w.name] = bytes(w.data)
            self._write = None
        return [FoeAck(message.packet)]

    # ------------------------------------------------------------------ read
    def _start_read(self, name: str, context: MailboxContext) -> list[FoeMessage]:
        data = self.store.files.get(name)
        if data is None:
            return self._refuse(FoeErrorCode.NOT_FOUND)
        room = min(context.write_bytes, context.read_bytes)
        chunk = room - MAILBOX_HEADER_BYTES - FOE_HEADER_BYTES
        if chunk <= 0:
            return self._refuse(FoeErrorCode.ILLEGAL)
        self._read = _Read(data, chunk)
        return [self._next_packet(self._read)]

    def _ack(self, message: FoeAck) -> list[FoeMessage]:
        r = self._read
        if r is None:
            return self._refuse(FoeErrorCode.ILLEGAL)
        if message.packet != r.packet:
            self._read = None
            return self._refuse(FoeErrorCode.PACKET_NUMBER_WRONG)
        if r.done:
            self._read = None
            return []
        return [self._next_packet(r)]

    @staticmethod
    def _next_packet(r: _Read) -> FoeData:
        piece = r.data[r.offset : r.offset + r.chunk]
        r.offset += len(piece)
        r.packet += 1
        r.done = len(piece) < r.chunk
        return FoeData(r.packet, piece)

    # ------------------------------------------------------------------ framing
    def _refuse(self, code: int) -> list[FoeMessage]:
        self.errors.append(code)
        return [FoeError(code, "")]

    def _error(self, code: int) -> list[bytes]:
        return [self._mailbox(m) for m in self._refuse(code)]

    @staticmethod
    def _mailbox(message: FoeMessage) -> bytes:
        body = encode_foe(message)
        return encode_mailbox_message(MailboxType.FoE, body, 0, MAILBOX_HEADER_BYTES + len(body))
