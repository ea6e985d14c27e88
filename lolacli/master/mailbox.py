"""Mailbox and CoE SDO client over the master's datagrams.

:class:`MailboxClient` writes a mailbox message into a slave's mailbox-out sync manager
(FPWR of the whole buffer) and reads the answer from its mailbox-in buffer (FPRD, which a
slave answers with WKC 0 while the buffer is empty: ETG.1000.4 §8.2.3, mailbox SM
"buffer full" rule), with the counter of ETG.1000.4 Table 29 (1..7). CoE emergencies that
come while an answer is awaited are kept in :attr:`MailboxClient.emergencies`.

:class:`SdoClient` speaks SDO (ETG.1000.6 §5.6.2) through it: upload and download,
expedited and segmented, complete access; an abort raises
:class:`~lolacli.errors.SdoAbortError` with the text of :func:`lolacli.wire.sdo.abort_text`.
The codecs are :mod:`lolacli.wire`'s; this module only runs the conversation.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

from lolacli.errors import SdoAbortError, TransportError, WireError
from lolacli.wire.coe import (
    COE_HEADER_BYTES,
    CoeService,
    Emergency,
    decode_emergency,
)
from lolacli.wire.commands import Command
from lolacli.wire.frame import Datagram
from lolacli.wire.mailbox import (
    MAILBOX_HEADER_BYTES,
    MailboxType,
    decode_mailbox_error,
    encode_mailbox_message,
    mailbox_type_and_payload,
    next_counter,
)
from lolacli.wire.sdo import (
    EXPEDITED_MAX_BYTES,
    SEGMENT_MIN_DATA_BYTES,
    SdoAbort,
    SdoDownloadRequest,
    SdoDownloadResponse,
    SdoDownloadSegmentRequest,
    SdoDownloadSegmentResponse,
    SdoUploadResponse,
    SdoUploadSegmentRequest,
    SdoUploadSegmentResponse,
    abort_text,
    decode_sdo,
    encode_sdo,
    expedited_upload_data,
    upload_request,
)

#: SDO bytes in front of the data of a normal initiate (command, index, subindex, size)
_INITIATE_BYTES = 8
_SEGMENT_HEADER_BYTES = 1


class DatagramPort(Protocol):
    """What a mailbox client needs of the master: one datagram out, its answer back, and
    a way to let time pass while it polls."""

    def exchange_one(self, datagram: Datagram) -> Datagram: ...

    def idle(self, duration_ns: int) -> None: ...

    def now_ns(self) -> int: ...


@dataclass(frozen=True, slots=True)
class MailboxLayout:
    """A slave's mailbox sync managers: station address, out (master → slave) and in."""

    station: int
    out_start: int
    out_bytes: int
    in_start: int
    in_bytes: int


@dataclass(slots=True)
class MailboxClient:
    """Mailbox conversations with one slave (see the module docstring)."""

    port: DatagramPort
    layout: MailboxLayout
    timeout_ns: int = 3_000_000_000
    poll_ns: int = 100_000
    counter: int = 0
    emergencies: list[Emergency] = field(default_factory=list)

    def request(self, mailbox_type: int, payload: bytes, *, timeout_ns: int | None = None) -> bytes:
        """Send ``payload`` as a mailbox of ``mailbox_type``; the payload of the answer of
        the same type. TransportError on timeout, WireError for a mailbox error reply."""
        deadline = self.send(mailbox_type, payload, timeout_ns=timeout_ns)
        return self._receive(mailbox_type, deadline)

    def send(self, mailbox_type: int, payload: bytes, *, timeout_ns: int | None = None) -> int:
        """Write ``payload`` as a mailbox of ``mailbox_type`` once the slave has taken the
        one before (a message without answer, as FoE's last ack); TransportError on
        timeout. The deadline of the wait (the answer's too) is returned."""
        self.counter = next_counter(self.counter)
        box = encode_mailbox_message(mailbox_type, payload, self.counter, self.layout.out_bytes)
        deadline = self.port.now_ns() + (self.timeout_ns if timeout_ns is None else timeout_ns)
        station = self.layout.station
        while True:  # the out buffer may still be full with an earlier message
            d = self.port.exchange_one(
                Datagram.physical(Command.FPWR, station, self.layout.out_start, box)
            )
            if d.wkc == 1:
                return deadline
            self._wait(deadline, "write the mailbox")

    def receive(self, mailbox_type: int, *, timeout_ns: int | None = None) -> bytes:
        """The payload of the next message of ``mailbox_type`` the slave posts, without
        sending anything: the further fragments of an answer that comes in several
        mailboxes (SDO Information). TransportError on timeout."""
        deadline = self.port.now_ns() + (self.timeout_ns if timeout_ns is None else timeout_ns)
        return self._receive(mailbox_type, deadline)

    def _receive(self, mailbox_type: int, deadline: int) -> bytes:
        while True:
            answer = self._read_once()
            if answer is not None:
                kind, body = answer
                if kind == MailboxType.ERR:
                    error = decode_mailbox_error(body)
                    raise WireError(f"station {self.layout.station}: mailbox error: {error.text}")
                if kind == mailbox_type and not self._is_emergency(kind, body):
                    return body
                continue
            self._wait(deadline, "answer the mailbox")

    def _read_once(self) -> tuple[int, bytes] | None:
        d = self.port.exchange_one(
            Datagram.physical(
                Command.FPRD, self.layout.station, self.layout.in_start, self.layout.in_bytes
            )
        )
        if d.wkc != 1:
            return None
        return mailbox_type_and_payload(d.data)

    def _is_emergency(self, kind: int, body: bytes) -> bool:
        if kind != MailboxType.CoE or len(body) < COE_HEADER_BYTES:
            return False
        if body[1] >> 4 != CoeService.EMERGENCY:  # the service: bits 12-15 of the CoE header
            return False
        self.emergencies.append(decode_emergency(body))
        return True

    def _wait(self, deadline_ns: int, what: str) -> None:
        if self.port.now_ns() >= deadline_ns:
            raise TransportError(
                f"station {self.layout.station}: mailbox timeout: the slave did not {what}"
            )
        self.port.idle(self.poll_ns)


class SdoClient:
    """CoE SDO upload/download with one slave (see the module docstring)."""

    def __init__(self, mailbox: MailboxClient) -> None:
        self.mailbox = mailbox

    @property
    def _segment_bytes(self) -> int:
        """Data bytes one segment carries in this slave's mailbox-out buffer."""
        room = self.mailbox.layout.out_bytes - MAILBOX_HEADER_BYTES - COE_HEADER_BYTES
        return max(SEGMENT_MIN_DATA_BYTES, room - _SEGMENT_HEADER_BYTES)

    def _ask(self, message: object, index: int, subindex: int) -> object:
        reply = decode_sdo(self.mailbox.request(MailboxType.CoE, encode_sdo(message)))  # type: ignore[arg-type]
        if isinstance(reply, SdoAbort):
            raise SdoAbortError(index, subindex, reply.code, abort_text(reply.code))
        return reply

    def upload(self, index: int, subindex: int, *, complete_access: bool = False) -> bytes:
        """Read an object (SDO upload): its bytes."""
        answer = self.mailbox.request(
            MailboxType.CoE, upload_request(index, subindex, complete_access=complete_access)
        )
        quick = expedited_upload_data(answer)  # the usual answer, read in place
        if quick is not None:
            return quick
        first = decode_sdo(answer)
        if isinstance(first, SdoAbort):
            raise SdoAbortError(index, subindex, first.code, abort_text(first.code))
        if not isinstance(first, SdoUploadResponse):
            raise WireError(f"SDO 0x{index:04X}:{subindex:02X}: unexpected answer {first!r}")
        if first.expedited:
            return first.data
        data = bytearray(first.data)
        toggle = False
        while len(data) < first.complete_size:
            seg = self._ask(SdoUploadSegmentRequest(toggle), index, subindex)
            if not isinstance(seg, SdoUploadSegmentResponse) or seg.toggle != toggle:
                raise WireError(f"SDO 0x{index:04X}:{subindex:02X}: bad upload segment {seg!r}")
            data += seg.data
            toggle = not toggle
            if seg.last:
                break
        return bytes(data[: first.complete_size])

    def download(
        self, index: int, subindex: int, data: bytes, *, complete_access: bool = False
    ) -> None:
        """Write an object (SDO download): expedited up to 4 bytes, else normal with as
        much as fits in the first mailbox and the rest in segments."""
        if 0 < len(data) <= EXPEDITED_MAX_BYTES and not complete_access:
            reply = self._ask(SdoDownloadRequest(index, subindex, data), index, subindex)
            self._expect(reply, SdoDownloadResponse, index, subindex)
            return
        room = (
            self.mailbox.layout.out_bytes
            - MAILBOX_HEADER_BYTES
            - COE_HEADER_BYTES
            - _INITIATE_BYTES
        )
        first, rest = data[:room], data[room:]
        request = SdoDownloadRequest(
            index, subindex, first, complete_access, expedited=False, complete_size=len(data)
        )
        self._expect(self._ask(request, index, subindex), SdoDownloadResponse, index, subindex)
        toggle = False
        step = self._segment_bytes
        while rest:
            chunk, rest = rest[:step], rest[step:]
            seg = SdoDownloadSegmentRequest(chunk, toggle=toggle, last=not rest)
            reply = self._ask(seg, index, subindex)
            self._expect(reply, SdoDownloadSegmentResponse, index, subindex)
            toggle = not toggle

    @staticmethod
    def _expect(reply: object, kind: type, index: int, subindex: int) -> None:
        if not isinstance(reply, kind):
            raise WireError(f"SDO 0x{index:04X}:{subindex:02X}: unexpected answer {reply!r}")
